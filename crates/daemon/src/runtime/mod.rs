//! The runtime layer: the daemon's threads (`daemon`), their real-time
//! set-up ([`rt`]) and telemetry (`telemetry`). The clock they read is
//! [`crate::clock`]; sockets live here and in the thin loop
//! [`crate::rsi_server`].

pub(crate) mod daemon;
pub mod rt;
pub(crate) mod telemetry;
pub use daemon::{
    Daemon, DaemonSummary, LinkState, LogoMethodChoice, LogoRuntime, RuntimeConfig, THREAD_START_HOOK, ThreadSpec,
};
pub use telemetry::{
    DatagramRecord, Latencies, Latency, LogoRecord, QueueDepths, RsiRecord, Telemetry, TelemetrySink, TelemetrySummary,
    TelemetryTx,
};
