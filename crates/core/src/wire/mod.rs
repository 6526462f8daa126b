//! Datagram codecs, each in two layers (smoltcp style): a checked view over
//! the bytes and a validated value with `parse` and `emit`. No I/O here;
//! sockets belong to the runtime.

pub mod crop;
pub mod observation;
