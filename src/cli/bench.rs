//! `topspin bench latency`: the daemon threads against the mock KR C4
//! (4 ms) and a full-rate simulated tracker stream for a set duration, with
//! an optional CPU hog; reports the two latency histograms (RSI answer,
//! observation → plan) and the late RSI answers.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Args, Subcommand};
use serde_json::json;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_daemon::rsi_server::WaitStrategy;
use topspin_sim::demo::{DemoConfig, Latencies, run_loopback};
use topspin_sim::probe;

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// End-to-end latency on loopback.
    Latency(LatencyArgs),
}

#[derive(Debug, Args)]
pub struct LatencyArgs {
    /// How long to stream balls, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Busy threads loading the CPU meanwhile (0: none).
    #[arg(long, default_value_t = 0)]
    pub load: usize,
    /// The RSI loop's wait strategy.
    #[arg(long, value_enum, default_value_t = WaitStrategy::Blocking)]
    pub rsi_wait: WaitStrategy,
    /// The estimator spins on its ring instead of parking.
    #[arg(long)]
    pub estimator_busy_poll: bool,
    #[arg(long)]
    pub json: bool,
    /// Serve the live Foxglove view on ADDR meanwhile (default 127.0.0.1:8765),
    /// with a built-in client subscribed to every channel (as Foxglove would be).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = topspin_daemon::viewer::DEFAULT_LIVE_ADDR)]
    pub live: Option<std::net::SocketAddr>,
    /// With --live: no built-in client (the server idles unless Foxglove connects).
    #[arg(long)]
    pub no_live_client: bool,
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Latency(a) => latency(a),
    }
}

/// Loads the CPU until `stop`: floating-point work with no memory traffic.
fn hog(stop: Arc<AtomicBool>) {
    let mut x = 1.0f64;
    while !stop.load(Ordering::Relaxed) {
        for _ in 0..10_000 {
            x = (x * 1.000_001).sin() + 1.0;
        }
        std::hint::black_box(x);
    }
}

fn latency(a: LatencyArgs) -> anyhow::Result<()> {
    if !(a.duration.is_finite() && a.duration >= 2.0) {
        return Err(BadInput(format!("--duration {} must be at least 2 s", a.duration)).into());
    }
    let gap = 1.2;
    let mut cfg = DemoConfig { balls: (a.duration / gap).ceil() as usize, gap, ..DemoConfig::default() };
    cfg.runtime.rsi_wait = a.rsi_wait;
    cfg.runtime.estimator_busy_poll = a.estimator_busy_poll;
    let probe_stop = Arc::new(AtomicBool::new(false));
    let probe = match a.live {
        Some(addr) if !a.no_live_client => {
            if addr.port() == 0 {
                return Err(BadInput("--live needs a port for the built-in client (or --no-live-client)".into()).into());
            }
            cfg.live_wait = topspin_core::time::Duration::from_millis(10_000);
            Some(probe::spawn(addr, probe_stop.clone(), std::time::Duration::from_secs(10)))
        }
        _ => None,
    };
    cfg.live = a.live;
    let stop = Arc::new(AtomicBool::new(false));
    let hogs: Vec<_> = (0..a.load)
        .map(|_| {
            let s = stop.clone();
            std::thread::spawn(move || hog(s))
        })
        .collect();
    if !a.json {
        eprintln!(
            "topspin bench latency: {} s of balls every {gap} s at 150 Hz, RSI 4 ms, {} CPU hog thread(s), RSI wait {:?}, live view {}",
            a.duration,
            a.load,
            a.rsi_wait,
            a.live.map_or("off".to_string(), |x| format!("on ws://{x}"))
        );
    }
    let r = run_loopback(&cfg, &Calibration::default_cell());
    stop.store(true, Ordering::Relaxed);
    for h in hogs {
        let _ = h.join();
    }
    probe_stop.store(true, Ordering::Relaxed);
    let seen = match probe.map(|p| p.join()) {
        Some(Ok(Ok(report))) => Some(report),
        Some(Ok(Err(e))) => return Err(anyhow::anyhow!("live client: {e}")),
        Some(Err(_)) => return Err(anyhow::anyhow!("live client panicked")),
        None => None,
    };
    let r = r?;
    let live_json = seen.as_ref().map(|s| {
        json!({
            "messages": s.messages(),
            "bytes": s.channels.values().map(|c| c.bytes).sum::<u64>(),
            "per_topic": s.channels.iter().map(|(t, c)| (t.clone(), c.messages)).collect::<std::collections::BTreeMap<_, _>>(),
        })
    });
    let lat = Latencies::of(&r.daemon.telemetry);
    if a.json {
        println!(
            "{}",
            json!({
                "duration_s": a.duration,
                "load_threads": a.load,
                "rsi_wait": format!("{:?}", a.rsi_wait),
                "rsi_cycles": r.mock.cycles,
                "late_rsi_answers": r.mock.late,
                "observations": r.daemon.ingest.accepted,
                "plans": r.daemon.telemetry.plans,
                "live": a.live.map(|x| x.to_string()),
                "live_client": live_json,
                "telemetry_dropped": r.daemon.telemetry.telemetry_dropped,
                "latency_us": lat,
                "warnings": r.daemon.warnings.iter().map(|w| w.to_string()).collect::<Vec<_>>(),
            })
        );
        return Ok(());
    }
    println!(
        "RSI cycles {}, late answers {}, observations {}, plans {}",
        r.mock.cycles, r.mock.late, r.daemon.ingest.accepted, r.daemon.telemetry.plans
    );
    println!("latency µs          p50    p99  p99.9    max");
    for (name, l) in [("RSI answer", lat.rsi_answer), ("observation→plan", lat.obs_to_plan)] {
        println!("{name:16} {:6} {:6} {:6} {:6}", l.p50, l.p99, l.p999, l.max);
    }
    if let Some(s) = &seen {
        println!("live client ({}): {} messages", s.server_name, s.messages());
        for (topic, c) in &s.channels {
            println!("  {topic:24} {:7} messages {:9} bytes  {}", c.messages, c.bytes, c.schema_name);
        }
    }
    for w in &r.daemon.warnings {
        println!("warning: {w}");
    }
    Ok(())
}
