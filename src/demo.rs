//! `topspin demo`: all of it on loopback in one process — the simulated
//! tracker streaming launcher balls (TTB1 over UDP), the real daemon threads,
//! and the mock KR C4 answering every 4 ms — then each stroke judged
//! against the ground truth: the bat centre (the mock's actual TCP path, in
//! the table frame) must pass within [`HIT_RADIUS`] of the true ball centre
//! within ±[`HIT_WINDOW`] of the true crossing of the hitting plane.
//!
//! Balls whose true hitting point lies outside the hitting window
//! (`calib/strike.toml`) cannot be reached; they are reported, and the hit
//! rate is over the reachable ones.

use std::net::UdpSocket;
use std::sync::atomic::AtomicBool;

use serde::Serialize;

use crate::calib::Calibration;
use crate::eval::stats::Summary;
use crate::ingest::IngestCounters;
use crate::mock_krc::{self, MockKrcConfig};
use crate::physics::{Vec3, rad_to_rps};
use crate::plan::StrikePlan;
use crate::runtime::daemon::{Daemon, DaemonSummary, LinkState, RuntimeConfig};
pub use crate::runtime::telemetry::{Latencies, Latency};
use crate::runtime::{self};
use crate::sim::faults::{InjectedCounts, TrackerFaults, inject, plan_datagrams, send_planned};
use crate::sim::stream::{capture_time, stream};
use crate::sim::{SimBall, TrackerModel, schedule, true_state_at};
use crate::time::{Duration, Instant};

/// A stroke hits when the bat centre passes this close to the ball, m.
pub const HIT_RADIUS: f64 = 0.040;
/// ... within this much of the true crossing of the hitting plane.
pub const HIT_WINDOW: Duration = Duration::from_millis(4);
/// Time from the daemon's start to the first launch, s.
pub const LEAD_IN: f64 = 0.5;

/// How the demo runs.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoConfig {
    pub balls: usize,
    pub seed: u64,
    pub tracker: TrackerModel,
    /// Launch-to-launch gap, s.
    pub gap: f64,
    pub runtime: RuntimeConfig,
    /// The mock's answer deadline; `None`: the controller's (one cycle).
    /// Tests on a shared machine stretch it so that the machine's own
    /// scheduling noise is counted (`answers_after_cycle`), not failed.
    pub answer_deadline: Option<Duration>,
    /// The mock's late-answer limit before it stops RSI; `None`: the
    /// controller's (the context's Timeout). A soak raises it so that a
    /// long run counts every late answer instead of stopping at the limit.
    pub late_limit: Option<u64>,
    /// Tracker-side faults injected into the stream (`sim::faults`); the
    /// foreign ball comes from 127.0.0.2.
    pub tracker_faults: Option<TrackerFaults>,
}

impl Default for DemoConfig {
    fn default() -> Self {
        DemoConfig {
            balls: 9,
            seed: 1,
            tracker: TrackerModel::default(),
            gap: 1.5,
            runtime: RuntimeConfig::loopback(),
            answer_deadline: None,
            late_limit: None,
            tracker_faults: None,
        }
    }
}

/// The verdict on one ball.
#[derive(Clone, Debug, Serialize)]
pub struct BallVerdict {
    pub ball: usize,
    pub setting: String,
    pub true_spin_rps: [f64; 3],
    pub estimated_spin_rps: Option<[f64; 3]>,
    pub spin_err_pct: Option<f64>,
    /// Closest approach of the bat centre to the ball within the window, mm.
    pub hit_err_mm: Option<f64>,
    /// Where a miss comes from: the last plan's hitting point against the
    /// true one (mm) and its hitting time against the true one (ms) —
    /// estimation; and the bat at the plan's hitting time against the
    /// plan's point (mm) — execution.
    pub plan_err_mm: Option<f64>,
    pub plan_dt_ms: Option<f64>,
    pub tracking_err_mm: Option<f64>,
    /// The true hitting point lies inside the hitting window.
    pub reachable: bool,
    pub hit: bool,
}

/// The demo's result.
#[derive(Clone, Debug, Serialize)]
pub struct DemoReport {
    pub balls: usize,
    pub reachable: usize,
    pub hits: usize,
    /// Hits over reachable balls.
    pub hit_rate: f64,
    pub late_rsi_answers: u64,
    /// Answers accepted under a stretched deadline that came later than
    /// one cycle (0 unless `answer_deadline` was stretched).
    pub answers_after_cycle: u64,
    pub rsi_cycles: u64,
    pub spin_err_pct_median: f64,
    pub hit_err_mm_median: f64,
    pub latency_us: Latencies,
    pub ended_home: bool,
    /// Plans the RSI loop took that arrive late (and the worst, ms), and
    /// plans it refused.
    pub plans_late: u64,
    pub late_by_max_ms: f64,
    pub plans_rejected: u64,
    pub warnings: Vec<String>,
    /// The daemon's tracker ingest counters (foreign, malformed, …).
    pub ingest: IngestCounters,
    /// What the tracker fault injector did (`None`: a clean stream).
    pub tracker_faults: Option<InjectedCounts>,
    /// Corrections the mock KR C4 had to clamp (POSCORR) or slow down to
    /// the robot's limits, and whether its monitor stopped RSI: all zero
    /// and false unless the daemon commanded something out of bounds.
    pub poscorr_clamped: u64,
    pub robot_limited: u64,
    pub stopped_by_monitor: bool,
    pub per_ball: Vec<BallVerdict>,
}

/// The ball's true hitting point lies in the hitting window.
pub fn reachable(cal: &Calibration, ball: &SimBall) -> bool {
    ball.truth.hit.as_ref().is_some_and(|h| cal.strike.in_window(h.pos[1], h.pos[2]))
}

/// What one loopback session produced, before judging.
#[derive(Debug)]
pub struct LoopbackRun {
    pub balls: Vec<SimBall>,
    /// Launch of ball k, s after `t0`.
    pub starts: Vec<f64>,
    pub t0: Instant,
    pub mock: mock_krc::MockResult,
    pub daemon: DaemonSummary,
    pub injected: Option<InjectedCounts>,
}

/// Runs the demo end to end and judges every stroke.
pub fn run(cfg: &DemoConfig, cal: &Calibration) -> std::io::Result<DemoReport> {
    let r = run_loopback(cfg, cal)?;
    let mut report = judge(cal, &r.balls, &r.starts, r.t0, &r.mock, &r.daemon);
    report.tracker_faults = r.injected;
    Ok(report)
}

/// The simulated tracker, the daemon threads and the mock KR C4 on
/// loopback for `cfg.balls` balls; the bat brought home at the end.
pub fn run_loopback(cfg: &DemoConfig, cal: &Calibration) -> std::io::Result<LoopbackRun> {
    let balls = crate::eval::simulate_set(cal, cfg.seed, cfg.balls, &cfg.tracker);
    let ends: Vec<f64> = balls.iter().map(|b| b.truth.end_t).collect();
    let starts = schedule(&ends, cfg.gap);

    let mut rcfg = cfg.runtime.clone();
    rcfg.tracker_noise = cfg.tracker.noise_sigma.max(1e-4);
    // The simulated tracker's capture-to-arrival latency is known here; on
    // the robot it is measured once and configured (tracker.fixed_latency_ms).
    rcfg.tracker_fixed_latency = Duration::from_nanos((cfg.tracker.latency * 1e9) as u64);
    let daemon = Daemon::start(&rcfg, cal, None)?;
    let mut mcfg = MockKrcConfig::default_cell().map_err(|e| std::io::Error::other(e.to_string()))?;
    mcfg.sensor = daemon.rsi_addr;
    mcfg.bind = "127.0.0.1:0".parse().expect("literal");
    mcfg.cycles = None;
    mcfg.seed = cfg.seed;
    if let Some(d) = cfg.answer_deadline {
        mcfg.answer_deadline = d;
    }
    if let Some(n) = cfg.late_limit {
        mcfg.controller.late_limit = n;
    }
    let mock = mock_krc::spawn(mcfg)?;

    let tracker = UdpSocket::bind("127.0.0.1:0")?;
    tracker.connect(daemon.tracker_addr)?;
    let t0 = runtime::now() + Duration::from_nanos((LEAD_IN * 1e9) as u64);
    let never = AtomicBool::new(false);
    let injected = match &cfg.tracker_faults {
        None => {
            stream(&tracker, &balls, &starts, cfg.tracker.latency, t0, &never)?;
            None
        }
        Some(f) => {
            let clean = plan_datagrams(&balls, &starts, cfg.tracker.latency, t0);
            let (plan, counts) = inject(&clean, f, cfg.seed);
            // Another loopback address: not the configured tracker source.
            let foreign = UdpSocket::bind("127.0.0.2:0")?;
            foreign.connect(daemon.tracker_addr)?;
            send_planned(&tracker, Some(&foreign), &plan, &never)?;
            Some(counts)
        }
    };
    // Let the last stroke finish and the bat come home.
    let last_end = starts.last().copied().unwrap_or(0.0) + ends.last().copied().unwrap_or(0.0);
    let until = capture_time(t0, last_end, 0.6);
    runtime::sleep_until(until, Duration::from_micros(0));
    daemon.request_stop();
    let drain_start = runtime::now();
    let mut home_since: Option<Instant> = None;
    loop {
        let now = runtime::now();
        if daemon.link_state() == LinkState::Home {
            if now - *home_since.get_or_insert(now) >= Duration::from_millis(200) {
                break;
            }
        } else {
            home_since = None;
        }
        if now - drain_start > Duration::from_millis(5000) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let mock = mock.stop()?;
    let daemon = daemon.join()?;
    Ok(LoopbackRun { balls, starts, t0, mock, daemon, injected })
}

/// The last plan of the trajectory whose hit is nearest the true one.
fn matching_plan(plans: &[StrikePlan], t_hit: Instant) -> Option<&StrikePlan> {
    plans.iter().filter(|p| p.hit_time.0.abs_diff(t_hit.0) < 50_000_000).min_by_key(|p| p.hit_time.0.abs_diff(t_hit.0))
}

fn judge(
    cal: &Calibration,
    balls: &[SimBall],
    starts: &[f64],
    t0: Instant,
    mock: &mock_krc::MockResult,
    summary: &DaemonSummary,
) -> DemoReport {
    let prop = cal.propagator();
    let robot = &cal.robot;
    let mut per_ball = Vec::new();
    for (k, ball) in balls.iter().enumerate() {
        let truth = &ball.truth;
        let true_spin = Vec3::new(truth.spin[0], truth.spin[1], truth.spin[2]);
        let reachable = reachable(cal, ball);
        let Some(hit) = truth.hit.as_ref() else { continue };
        let t_hit = capture_time(t0, starts[k], hit.t);
        let launch = truth.to_launch();
        let closest = mock
            .path
            .iter()
            .filter(|s| s.t.0.abs_diff(t_hit.0) <= HIT_WINDOW.0)
            .map(|s| {
                let bat = robot.b_to_t(Vec3::new(s.actual[0], s.actual[1], s.actual[2]) * 1e-3);
                let ball_at = true_state_at(&launch, &prop, s.t.secs_since(t0) - starts[k]).pos;
                (bat - ball_at).norm()
            })
            .min_by(f64::total_cmp);
        let plan = matching_plan(&summary.telemetry.last_plans, t_hit);
        let est = plan.map(|p| p.spin);
        let true_hit = Vec3::new(hit.pos[0], hit.pos[1], hit.pos[2]);
        let bat_at = |t: Instant| {
            mock.path
                .iter()
                .min_by_key(|s| s.t.0.abs_diff(t.0))
                .map(|s| robot.b_to_t(Vec3::new(s.actual[0], s.actual[1], s.actual[2]) * 1e-3))
        };
        let tracking_err_mm = plan.and_then(|p| bat_at(p.hit_time).map(|b| (b - p.position).norm() * 1e3));
        per_ball.push(BallVerdict {
            ball: k,
            setting: truth.setting.to_string(),
            true_spin_rps: true_spin.map(rad_to_rps).into(),
            estimated_spin_rps: est.map(|w| w.map(rad_to_rps).into()),
            spin_err_pct: est.map(|w| (w - true_spin).norm() / true_spin.norm() * 100.0),
            hit_err_mm: closest.map(|d| d * 1e3),
            plan_err_mm: plan.map(|p| (p.position - true_hit).norm() * 1e3),
            plan_dt_ms: plan.map(|p| p.hit_time.secs_since(t_hit) * 1e3),
            tracking_err_mm,
            reachable,
            hit: closest.is_some_and(|d| d <= HIT_RADIUS),
        });
    }
    let reach: Vec<&BallVerdict> = per_ball.iter().filter(|b| b.reachable).collect();
    let hits = reach.iter().filter(|b| b.hit).count();
    let spin: Vec<f64> = reach.iter().filter_map(|b| b.spin_err_pct).collect();
    let hit_err: Vec<f64> = reach.iter().filter_map(|b| b.hit_err_mm).collect();
    DemoReport {
        balls: balls.len(),
        reachable: reach.len(),
        hits,
        hit_rate: if reach.is_empty() { 0.0 } else { hits as f64 / reach.len() as f64 },
        late_rsi_answers: mock.late,
        answers_after_cycle: mock.answers_after_cycle,
        rsi_cycles: mock.cycles,
        spin_err_pct_median: Summary::of(&spin).median,
        hit_err_mm_median: Summary::of(&hit_err).median,
        latency_us: Latencies::of(&summary.telemetry),
        ended_home: summary.ended_home,
        plans_late: summary.telemetry.plans_late,
        late_by_max_ms: summary.telemetry.late_by_max_ms,
        plans_rejected: summary.telemetry.plans_rejected,
        warnings: summary.warnings.iter().map(|w| w.to_string()).collect(),
        ingest: summary.ingest,
        tracker_faults: None,
        poscorr_clamped: mock.poscorr_clamped,
        robot_limited: mock.robot_limited,
        stopped_by_monitor: mock.stopped_by_monitor,
        per_ball,
    }
}
