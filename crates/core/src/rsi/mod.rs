//! KUKA RSI (DESIGN §5.3): the XML scanner, the datagram codec and the
//! sans-IO session that answers the controller every cycle.
//!
//! - [`xml`]: a tolerant, zero-allocation scanner.
//! - [`codec`]: `<Rob>` and `<Sen>` parse/emit in KUKA units.

pub mod codec;
pub mod session;
pub mod xml;
