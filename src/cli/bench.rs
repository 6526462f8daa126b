//! `topspin bench latency`: the daemon threads against the mock KR C4
//! (4 ms) and a full-rate simulated tracker stream for a set duration, with
//! an optional CPU hog; reports the two latency histograms (RSI answer,
//! observation → plan) and the late RSI answers. `--layout` says where the
//! threads run ([`super::bench_layout`]). `--floor` then runs the floor
//! ([`topspin_daemon::rsi_floor`]: the IPOC copied into a constant answer)
//! on the RSI thread's core and priority against the same mock for as
//! long, and gives each RSI answer figure as a ratio over it.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Args, Subcommand};
use serde_json::json;

use super::BadInput;
use super::bench_layout::{self, HELPER_PRIORITY, Layout, Placement};
use topspin_core::calib::Calibration;
use topspin_daemon::rsi_floor::FloorServer;
use topspin_daemon::rsi_server::WaitStrategy;
use topspin_daemon::runtime::ThreadSpec;
use topspin_daemon::runtime::rt::{self, RtRefused, RtWarning};
use topspin_sim::demo::{DemoConfig, Latencies, run_loopback};
use topspin_sim::mock_krc::{self, MockKrcConfig};
use topspin_sim::probe;

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// End-to-end latency on loopback.
    Latency(LatencyArgs),
}

const LATENCY_HELP: &str = "\
Examples:
  topspin bench latency --duration 600 --load 1            # the shared layout: any core, normal scheduling
  topspin bench latency --duration 30 --floor             # and the floor for 30 s: each RSI figure over it
  topspin bench latency --duration 30 --idle --floor      # the same with the arm idle at home (no balls)
  sudo topspin bench latency --layout dedicated --duration 600 --json
                                                           # a core and SCHED_FIFO each for RSI, estimator,
                                                           # ingest, mock KR C4 and tracker (6 physical cores)

--layout dedicated exits 2 with one line where this process may use fewer
than 6 physical cores (taskset, cpuset, SMT siblings count once) or may not
use SCHED_FIFO (root, or CAP_SYS_NICE with an RLIMIT_RTPRIO).";

#[derive(Debug, Args)]
#[command(after_help = LATENCY_HELP)]
pub struct LatencyArgs {
    /// How long to stream balls, s.
    #[arg(long, default_value_t = 60.0)]
    pub duration: f64,
    /// Busy threads loading the CPU meanwhile (0: none); with `--layout
    /// dedicated` they run on the leftover cores.
    #[arg(long, default_value_t = 0)]
    pub load: usize,
    /// Where the threads run: `shared` (any core, normal scheduling) or
    /// `dedicated` (RSI, estimator, ingest, mock KR C4 and tracker each on
    /// a physical core of its own with SCHED_FIFO; RSI and estimator busy-poll).
    #[arg(long, value_enum, default_value_t = Layout::Shared)]
    pub layout: Layout,
    /// The RSI loop's wait strategy [default: blocking; busy-poll with
    /// `--layout dedicated`].
    #[arg(long, value_enum)]
    pub rsi_wait: Option<WaitStrategy>,
    /// The estimator spins on its ring instead of parking (always with
    /// `--layout dedicated`).
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
    /// No balls: the arm idles at home for the whole --duration (the RSI
    /// loop's floor case).
    #[arg(long)]
    pub idle: bool,
    /// Then, for as long, the floor against the same mock: a server that
    /// only copies the IPOC into a constant answer, on the RSI thread's
    /// core, priority and wait; the RSI answer figures as ratios over it.
    #[arg(long)]
    pub floor: bool,
}

/// The floor's answer time (recvfrom returned → sendto returned), µs, and
/// the mock's counters, for `seconds` against a fresh mock KR C4.
fn floor_phase(cfg: &DemoConfig, seconds: f64) -> anyhow::Result<(FloorLatency, u64, u64, Vec<RtWarning>)> {
    let mut server = FloorServer::bind("127.0.0.1:0".parse().expect("literal"), cfg.runtime.rsi_wait)?;
    let addr = server.local_addr()?;
    let spec = cfg.runtime.rsi;
    let priority = spec.priority.filter(|_| cfg.runtime.realtime);
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    let thread = std::thread::spawn(move || {
        let refused = rt::setup_current("rsi-floor", spec.core, priority);
        server.run(&s).map(|()| (server, refused))
    });
    let mut mcfg = MockKrcConfig::default_cell().map_err(|e| anyhow::anyhow!("{e}"))?;
    mcfg.sensor = addr;
    mcfg.bind = "127.0.0.1:0".parse().expect("literal");
    mcfg.thread = cfg.mock_thread;
    let mock = mock_krc::spawn(mcfg)?;
    std::thread::sleep(std::time::Duration::from_secs_f64(seconds));
    let m = mock.stop()?;
    stop.store(true, Ordering::Relaxed);
    let (server, mut refused) = thread.join().map_err(|_| anyhow::anyhow!("floor thread panicked"))??;
    refused.extend(m.rt_warnings.iter().cloned());
    Ok((FloorLatency::of(&server.answer_ns), m.cycles, m.late, refused))
}

/// Quantiles of the floor's answer time, µs.
#[derive(Copy, Clone, Debug, serde::Serialize)]
struct FloorLatency {
    p50: f64,
    p99: f64,
    p999: f64,
    max: f64,
    n: u64,
}

impl FloorLatency {
    fn of(h: &hdrhistogram::Histogram<u64>) -> Self {
        let us = |ns: u64| ns as f64 * 1e-3;
        FloorLatency {
            p50: us(h.value_at_quantile(0.5)),
            p99: us(h.value_at_quantile(0.99)),
            p999: us(h.value_at_quantile(0.999)),
            max: us(h.max()),
            n: h.len(),
        }
    }

    /// `l` (µs) over the floor, per quantile.
    fn ratios(&self, l: &topspin_daemon::runtime::Latency) -> serde_json::Value {
        let r = |x: u64, f: f64| if f > 0.0 { (x as f64 / f * 100.0).round() / 100.0 } else { f64::NAN };
        json!({ "p50": r(l.p50, self.p50), "p99": r(l.p99, self.p99), "p999": r(l.p999, self.p999) })
    }
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

/// The dedicated layout's cores on this machine, or the one line why not:
/// too few physical cores, or no SCHED_FIFO.
fn dedicated_placement() -> Result<Placement, BadInput> {
    let cpus = bench_layout::read_topology(&rt::allowed_cpus());
    let placement = bench_layout::plan(&cpus).map_err(|e| BadInput(e.to_string()))?;
    rt::fifo_permitted().map_err(|errno| {
        BadInput(format!(
            "--layout dedicated needs SCHED_FIFO (root, or CAP_SYS_NICE with an RLIMIT_RTPRIO): refused with errno {errno}"
        ))
    })?;
    Ok(placement)
}

/// What each thread got: its core (none where pinning was refused) and
/// its policy (SCHED_FIFO unless asked for none or refused).
fn obtained(
    threads: &[(&'static str, ThreadSpec)],
    refused: &[&RtWarning],
) -> serde_json::Map<String, serde_json::Value> {
    threads
        .iter()
        .map(|(name, spec)| {
            let mine = |f: fn(&RtRefused) -> bool| refused.iter().any(|w| w.thread == *name && f(&w.what));
            let core = spec.core.filter(|_| !mine(|r| matches!(r, RtRefused::Pin { .. })));
            let sched = match spec.priority {
                Some(p) if !mine(|r| matches!(r, RtRefused::Fifo { .. })) => format!("SCHED_FIFO {p}"),
                _ => "SCHED_OTHER".to_owned(),
            };
            (name.to_string(), json!({ "core": core, "sched": sched }))
        })
        .collect()
}

fn latency(a: LatencyArgs) -> anyhow::Result<()> {
    if !(a.duration.is_finite() && a.duration >= 2.0) {
        return Err(BadInput(format!("--duration {} must be at least 2 s", a.duration)).into());
    }
    let placement = match a.layout {
        Layout::Shared => None,
        Layout::Dedicated => Some(dedicated_placement()?),
    };
    let gap = 1.2;
    let mut cfg = DemoConfig { balls: (a.duration / gap).ceil() as usize, gap, ..DemoConfig::default() };
    if a.idle {
        (cfg.balls, cfg.tail_s) = (0, a.duration);
    }
    cfg.runtime.rsi_wait = a.rsi_wait.unwrap_or(match a.layout {
        Layout::Shared => WaitStrategy::Blocking,
        Layout::Dedicated => WaitStrategy::BusyPoll,
    });
    cfg.runtime.estimator_busy_poll = a.estimator_busy_poll || placement.is_some();
    if let Some(p) = &placement {
        let r = &mut cfg.runtime;
        r.realtime = true;
        r.rsi.core = Some(p.rsi);
        r.estimator.core = Some(p.estimator);
        r.ingest.core = Some(p.ingest);
        r.telemetry.core = Some(p.rest[0]);
        cfg.mock_thread = ThreadSpec { core: Some(p.mock_krc), priority: Some(HELPER_PRIORITY) };
        cfg.tracker_thread = ThreadSpec { core: Some(p.tracker), priority: Some(HELPER_PRIORITY) };
    }
    let rsi_wait = cfg.runtime.rsi_wait;
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
    let rest = placement.as_ref().map(|p| p.rest.clone());
    let hogs: Vec<_> = (0..a.load)
        .map(|i| {
            let s = stop.clone();
            let core = rest.as_ref().map(|r| r[i % r.len()]);
            std::thread::spawn(move || {
                if let Some(c) = core {
                    // Off the hot cores; a refusal only moves the load.
                    let _ = rt::pin_current("hog", c);
                }
                hog(s)
            })
        })
        .collect();
    if !a.json {
        eprintln!(
            "topspin bench latency: {} s {}, RSI 4 ms, {} CPU hog thread(s), RSI wait {:?}, estimator busy-poll {}, live view {}",
            a.duration,
            if a.idle { "idle at home".to_owned() } else { format!("of balls every {gap} s at 150 Hz") },
            a.load,
            rsi_wait,
            cfg.runtime.estimator_busy_poll,
            a.live.map_or("off".to_string(), |x| format!("on ws://{x}"))
        );
        if let Some(p) = &placement {
            eprintln!(
                "layout dedicated: RSI on CPU {}, estimator {}, ingest {}, mock KR C4 {}, tracker {}, the rest on {} (idle SMT siblings: {})",
                p.rsi,
                p.estimator,
                p.ingest,
                p.mock_krc,
                p.tracker,
                bench_layout::cpu_list(&p.rest),
                bench_layout::cpu_list(&p.idle)
            );
        }
    }
    let r = run_loopback(&cfg, &Calibration::default_cell());
    // The floor under the same load and placement, before the hogs stop.
    let floor = match (&r, a.floor) {
        (Ok(_), true) => Some(floor_phase(&cfg, a.duration)),
        _ => None,
    };
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
    let floor = floor.transpose()?;
    let live_json = seen.as_ref().map(|s| {
        json!({
            "messages": s.messages(),
            "bytes": s.channels.values().map(|c| c.bytes).sum::<u64>(),
            "per_topic": s.channels.iter().map(|(t, c)| (t.clone(), c.messages)).collect::<std::collections::BTreeMap<_, _>>(),
        })
    });
    let lat = Latencies::of(&r.daemon.telemetry);
    let rt_cfg = &cfg.runtime;
    let hot = |s: ThreadSpec| ThreadSpec { priority: s.priority.filter(|_| rt_cfg.realtime), ..s };
    let threads = [
        ("rsi", hot(rt_cfg.rsi)),
        ("estimator", hot(rt_cfg.estimator)),
        ("ingest", hot(rt_cfg.ingest)),
        ("telemetry", ThreadSpec { priority: None, ..rt_cfg.telemetry }),
        ("mock-krc", cfg.mock_thread),
        ("tracker", cfg.tracker_thread),
    ];
    let floor_refused = floor.as_ref().map(|f| f.3.as_slice()).unwrap_or_default();
    let refused: Vec<&RtWarning> =
        r.daemon.warnings.iter().chain(&r.mock.rt_warnings).chain(&r.tracker_warnings).chain(floor_refused).collect();
    let floor_json = floor.as_ref().map(|(f, cycles, late, _)| {
        json!({ "answer_us": f, "rsi_cycles": cycles, "late_rsi_answers": late, "rsi_answer_over_floor": f.ratios(&lat.rsi_answer) })
    });
    let got = obtained(&threads, &refused);
    if a.json {
        println!(
            "{}",
            json!({
                "duration_s": a.duration,
                "idle": a.idle,
                "layout": a.layout,
                "cpus_allowed": rt::allowed_cpus(),
                "cores": placement,
                "threads": got,
                "load_threads": a.load,
                "rsi_wait": format!("{:?}", rsi_wait),
                "estimator_busy_poll": cfg.runtime.estimator_busy_poll,
                "rsi_cycles": r.mock.cycles,
                "late_rsi_answers": r.mock.late,
                "observations": r.daemon.ingest.accepted,
                "plans": r.daemon.telemetry.plans,
                "live": a.live.map(|x| x.to_string()),
                "live_client": live_json,
                "telemetry_dropped": r.daemon.telemetry.telemetry_dropped,
                "latency_us": lat,
                "floor": floor_json,
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
    if let Some((f, cycles, late, _)) = &floor {
        println!(
            "{:16} {:6.1} {:6.1} {:6.1} {:6.1}   ({cycles} cycles, {late} late)",
            "floor", f.p50, f.p99, f.p999, f.max
        );
        let x = f.ratios(&lat.rsi_answer);
        println!("RSI answer over the floor: p50 {}×, p99 {}×, p99.9 {}×", x["p50"], x["p99"], x["p999"]);
    }
    if let Some(s) = &seen {
        println!("live client ({}): {} messages", s.server_name, s.messages());
        for (topic, c) in &s.channels {
            println!("  {topic:24} {:7} messages {:9} bytes  {}", c.messages, c.bytes, c.schema_name);
        }
    }
    for (name, t) in &got {
        println!("thread {name:10} core {:5} {}", t["core"].to_string(), t["sched"].as_str().unwrap_or(""));
    }
    for w in &refused {
        println!("warning: {w}");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_thread_reports_what_it_got_not_what_it_asked() {
        let fifo = |core, p| ThreadSpec { core: Some(core), priority: Some(p) };
        let threads = [
            ("rsi", fifo(5, 80)),
            ("estimator", fifo(4, 60)),
            ("mock-krc", fifo(2, 50)),
            ("telemetry", ThreadSpec { core: Some(0), priority: None }),
            ("tracker", ThreadSpec::default()),
        ];
        let refused = [
            RtWarning { thread: "estimator", what: RtRefused::Fifo { priority: 60, errno: 1 } },
            RtWarning { thread: "mock-krc", what: RtRefused::Pin { core: 2 } },
            RtWarning { thread: "process", what: RtRefused::Mlock { errno: 12 } },
        ];
        let got = obtained(&threads, &refused.iter().collect::<Vec<_>>());
        assert_eq!(
            serde_json::Value::Object(got),
            json!({
                "rsi": { "core": 5, "sched": "SCHED_FIFO 80" },
                "estimator": { "core": 4, "sched": "SCHED_OTHER" },
                "mock-krc": { "core": null, "sched": "SCHED_FIFO 50" },
                "telemetry": { "core": 0, "sched": "SCHED_OTHER" },
                "tracker": { "core": null, "sched": "SCHED_OTHER" },
            })
        );
    }
}
