//! Datagram codecs, each in two layers (smoltcp style): a checked view over
//! the bytes and a validated value with `parse` and `emit`. No I/O here;
//! sockets belong to the runtime.

pub(crate) mod crop;
pub(crate) mod observation;
pub use crop::{CROP_MAX_LEN, Crop, CropError, CropPacket, crop_origin};
pub use observation::{OBSERVATION_LEN, Observation, ObservationPacket, WireError};
