//! Datagram codecs.
