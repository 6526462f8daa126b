//! `topspin check tracker`: listens on the tracker port (without the rest
//! of the daemon) and says what the tracker sends: sources, rate, gaps,
//! duplicates, capture-to-arrival jitter, the clock mapping, whether the
//! positions look like the table frame, bad datagrams by kind
//! ([`topspin_daemon::tracker_check`]).

use std::fmt::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::BadInput;
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::tracker_check::{TrackerReport, listen};

/// What to check.
#[derive(Debug, Subcommand)]
pub enum CheckCommand {
    /// Listen on the tracker port and describe what arrives.
    ///
    /// Example: `topspin check tracker --seconds 10` (the configured
    /// `network.tracker_bind`), or `--bind 0.0.0.0:41000 --json`.
    Tracker(TrackerArgs),
}

/// `topspin check tracker`.
#[derive(Debug, Args)]
pub struct TrackerArgs {
    /// Configuration file (its `network.tracker_bind`); layered as `topspin run`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Listen here instead of the configured `network.tracker_bind`.
    #[arg(long)]
    pub bind: Option<SocketAddr>,
    /// How long to listen, s.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// One JSON object instead of the text report.
    #[arg(long)]
    pub json: bool,
}

/// Runs `topspin check …`.
pub fn run(c: CheckCommand) -> anyhow::Result<()> {
    match c {
        CheckCommand::Tracker(a) => tracker(a),
    }
}

fn tracker(a: TrackerArgs) -> anyhow::Result<()> {
    if !(a.seconds.is_finite() && a.seconds > 0.0) {
        return Err(BadInput(format!("--seconds {}: must be a positive number", a.seconds)).into());
    }
    let bind = match a.bind {
        Some(b) => b,
        None => DaemonConfig::load(a.config.as_deref()).map_err(|e| BadInput(e.to_string()))?.network.tracker_bind,
    };
    let report = listen(bind, a.seconds, topspin_daemon::clock::now)
        .map_err(|e| BadInput(format!("tracker port {bind}: {e}")))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", text(bind, a.seconds, &report));
    }
    Ok(())
}

fn text(bind: SocketAddr, seconds: f64, r: &TrackerReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "tracker port {bind}, {seconds} s:");
    let opt = |x: Option<f64>, unit: &str| x.map_or("-".to_owned(), |v| format!("{v:.1} {unit}"));
    let _ = writeln!(s, "  sources: {:?}", r.sources);
    let _ = writeln!(s, "  accepted: {} observations, rate {}", r.accepted, opt(r.rate_hz, "Hz"));
    let _ = writeln!(
        s,
        "  sequence: {} gaps ({} missing), {} duplicates, {} behind the last",
        r.seq_gaps, r.seq_missing, r.duplicates, r.reordered
    );
    let _ = writeln!(
        s,
        "  clock: offset {} ns (ours − the tracker's, minimum), drift {}",
        r.clock_offset_ns.map_or("-".to_owned(), |v| v.to_string()),
        opt(r.clock_drift_ppm, "ppm")
    );
    let _ = match r.jitter_us {
        Some([p50, p99, max]) => {
            writeln!(
                s,
                "  capture → arrival jitter above the minimum: p50 {p50:.0} µs, p99 {p99:.0} µs, max {max:.0} µs"
            )
        }
        None => writeln!(s, "  capture → arrival jitter: -"),
    };
    let _ = writeln!(
        s,
        "  table frame: median z {}, {:.0} % at rest height (z ≈ 0.02 m), {} below the table",
        opt(r.z_median_m.map(|z| z * 1e3), "mm"),
        r.at_rest_share * 100.0,
        r.below_table
    );
    let _ = writeln!(s, "  bad datagrams: {:?}", r.bad);
    for f in &r.findings {
        let _ = writeln!(s, "  ! {f}");
    }
    s
}
