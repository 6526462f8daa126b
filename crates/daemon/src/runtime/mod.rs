//! The runtime layer: the daemon's threads ([`daemon`]), their real-time
//! set-up ([`rt`]) and telemetry ([`telemetry`]). The clock they read is
//! [`crate::clock`]; sockets live here and in the thin loop
//! [`crate::rsi_server`].

pub mod daemon;
pub mod rt;
pub mod telemetry;
