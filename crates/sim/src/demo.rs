//! `topspin demo`: all of it on loopback in one process — the simulated
//! tracker streaming launcher balls (TTB1 over UDP), the real daemon threads,
//! and the mock KR C4 answering every 4 ms — then each stroke judged
//! against the ground truth: the bat centre (the mock's actual TCP path, in
//! the table frame) must pass within [`HIT_RADIUS`] of the true ball centre
//! within ±[`HIT_WINDOW`] of the true crossing of the hitting plane.
//!
//! With `runtime.logo` set, the ceiling camera is simulated too: each
//! ball's crossing of the camera's strip is rendered beforehand and its
//! crops are streamed as TTI1 datagrams, interleaved in time with the
//! tracker's, to the daemon's logo thread.
//!
//! Each stroke is also judged as a return ([`crate::returns`]): where the
//! bat's face first meets the true ball, the rubber's contact model sends
//! it back, and the simulator's physics says whether it clears the net and
//! lands on the opponent's half (`return_rate`), or why not.
//!
//! Balls whose true hitting point lies outside the hitting window
//! (`calib/strike.toml`) cannot be reached; they are reported, and the hit
//! and return rates are over the reachable ones.

use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use serde::Serialize;

use crate::faults::{InjectedCounts, TrackerFaults, inject, plan_datagrams, send_planned};
use crate::launcher::Launch;
use crate::mock_krc::{self, MockKrcConfig};
use crate::render::{BallColour, Scene, Sequence, SequenceOptions, render_sequence};
use crate::return_feed::ReturnFeed;
use crate::returns::{BatPath, ContactReport, ReturnFail, ReturnFails, judge_return, timing_window};
use crate::truth::{Flight, HitTruth};
use crate::udp_tracker::{capture_time, stream};
use crate::{Redraws, SimBall, Strokes, TrackerModel, schedule};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::ingest::IngestCounters;
use topspin_core::logo::LogoCounters;
use topspin_core::physics::{Propagator, Vec3, rad_to_rps};
use topspin_core::plan::StrikePlan;
use topspin_core::stats::Summary;
use topspin_core::time::{Duration, Instant};
use topspin_core::wire::CROP_MAX_LEN;
use topspin_daemon::clock;
use topspin_daemon::runtime::rt::RtWarning;
use topspin_daemon::runtime::{Daemon, DaemonSummary, LinkState, RuntimeConfig, ThreadSpec};
pub use topspin_daemon::runtime::{Latencies, Latency};

pub use topspin_core::plan::{HIT_RADIUS, HIT_WINDOW};
/// Time from the daemon's start to the first launch, s.
pub(crate) const LEAD_IN: f64 = 0.5;

/// How the demo runs.
#[derive(Clone, Debug, PartialEq)]
pub struct DemoConfig {
    /// Balls to launch.
    pub balls: usize,
    /// Seed of every random stream of the run (flights, tracker, faults).
    pub seed: u64,
    /// The simulated tracker: sampling, noise, latency, dropouts and false detections.
    pub tracker: TrackerModel,
    /// Launch-to-launch gap, s.
    pub gap: f64,
    /// The daemon's runtime configuration (addresses, threads, estimator, logo).
    pub runtime: RuntimeConfig,
    /// The mock's answer deadline; `None`: the controller's (one cycle).
    /// Tests on a shared machine stretch it so that the machine's own
    /// scheduling noise is counted (`answers_after_cycle`), not failed.
    pub answer_deadline: Option<Duration>,
    /// Serve the live Foxglove view here (see [`topspin_daemon::viewer`]).
    pub live: Option<SocketAddr>,
    /// Before the first ball, wait up to this long for a live client (then
    /// `LIVE_SETTLE` for its subscriptions).
    pub live_wait: Duration,
    /// Record the session (MCAP, with the viewer's channels) to this file.
    pub record: Option<PathBuf>,
    /// The mock's late-answer limit before it stops RSI; `None`: the
    /// controller's (the context's Timeout). A soak raises it so that a
    /// long run counts every late answer instead of stopping at the limit.
    pub late_limit: Option<u64>,
    /// Tracker-side faults injected into the stream (`sim::faults`); the
    /// foreign ball comes from 127.0.0.2.
    pub tracker_faults: Option<TrackerFaults>,
    /// The mock KR C4 thread's core and SCHED_FIFO priority (default:
    /// neither, the scheduler's choice).
    pub mock_thread: ThreadSpec,
    /// The simulated tracker's: set, it streams from a thread of its own
    /// with these; default, from the calling thread as it is.
    pub tracker_thread: ThreadSpec,
    /// Where the arm stands when RSI starts, joints A1..A6 in degrees
    /// (`None`: home); the daemon takes it home at the commissioning speed
    /// first, or holds where that way is unsafe.
    pub start_joints: Option<[f64; 6]>,
    /// How long the loop runs on after the last ball's flight before the
    /// bat is brought home and the run ends, s (with no balls: the whole
    /// run, the arm idle at home).
    pub tail_s: f64,
    /// The world the balls fly in ([`crate::worlds`]: air and table other
    /// than the calibration's, each ball its own); `None`: the
    /// calibration's physics. The daemon still knows only the calibration.
    pub world: Option<crate::worlds::World>,
    /// Where the balls come from: the launcher or human strokes.
    pub strokes: Strokes,
}

/// After a live client connects, time given it to subscribe.
pub(crate) const LIVE_SETTLE: Duration = Duration::from_millis(500);

impl Default for DemoConfig {
    fn default() -> Self {
        DemoConfig {
            balls: 9,
            seed: 1,
            tracker: TrackerModel::default(),
            gap: 1.5,
            runtime: RuntimeConfig::loopback(),
            answer_deadline: None,
            live: None,
            live_wait: Duration::from_nanos(0),
            record: None,
            late_limit: None,
            tracker_faults: None,
            mock_thread: ThreadSpec::default(),
            tracker_thread: ThreadSpec::default(),
            start_joints: None,
            tail_s: 0.6,
            world: None,
            strokes: Strokes::Launcher,
        }
    }
}

/// The verdict on one ball.
#[derive(Clone, Debug, Serialize)]
pub struct BallVerdict {
    /// The ball's position in the run's list of balls (0-based).
    pub ball: usize,
    /// The launcher setting the ball was launched with or resembles (e.g. `topspin-low`).
    pub setting: String,
    /// The true spin before the bounce, rps, table frame.
    pub true_spin_rps: [f64; 3],
    /// The spin of the last plan matched to this ball, rps (`None`: no plan).
    pub estimated_spin_rps: Option<[f64; 3]>,
    /// Error of that spin, |estimated − true| / |true|, % (`None`: no plan).
    pub spin_err_pct: Option<f64>,
    /// Closest approach of the bat centre to the ball within the window, mm.
    pub hit_err_mm: Option<f64>,
    /// Where a miss comes from: the last plan's hitting point against the
    /// true one (mm) and its hitting time against the true one (ms) —
    /// estimation; and the bat at the plan's hitting time against the
    /// plan's point (mm) — execution.
    pub plan_err_mm: Option<f64>,
    /// The last plan's hitting time minus the true one, ms (> 0: the plan late).
    pub plan_dt_ms: Option<f64>,
    /// Distance from the bat centre at the plan's hitting time to the plan's hitting point, mm.
    pub tracking_err_mm: Option<f64>,
    /// The true hitting point lies inside the hitting window.
    pub reachable: bool,
    /// The bat centre came within [`HIT_RADIUS`] of the ball within ±[`HIT_WINDOW`] of its crossing.
    pub hit: bool,
    /// The return: over the net onto the opponent's half, judged on the
    /// bat's actual pose and velocity where it met the ball.
    pub returned: bool,
    /// Why not (`None` when returned), and what was wrong: the bat's
    /// angle, speed, timing or position.
    pub return_fail: Option<ReturnFail>,
    /// The failure in words (`None` when returned).
    pub return_why: Option<String>,
    /// The bat and the ball at their contact (`None`: no contact).
    pub contact: Option<ContactReport>,
    /// Where the return first came down to the table's height (x, y), m.
    pub landing_xy: Option<[f64; 2]>,
    /// The arrival shifts (ms, > 0: the ball later) over which the same
    /// bat path returns the ball ([`timing_window`]): it holds 0 for a
    /// returned ball, its ends are the stroke's timing tolerance.
    pub timing_window_ms: Option<[f64; 2]>,
}

/// The demo's result.
#[derive(Clone, Debug, Serialize)]
pub struct DemoReport {
    /// Balls launched in the run.
    pub balls: usize,
    /// Balls judged reachable ([`BallVerdict::reachable`]).
    pub reachable: usize,
    /// Reachable balls the bat hit ([`BallVerdict::hit`]).
    pub hits: usize,
    /// Hits over reachable balls.
    pub hit_rate: f64,
    /// Reachable balls returned over the net onto the opponent's half.
    pub returns: usize,
    /// Returns over reachable balls.
    pub return_rate: f64,
    /// The reachable balls not returned, by reason.
    pub return_fails: ReturnFails,
    /// Returns over all balls (each bounced on the robot's half), as a
    /// match counts them.
    pub return_rate_all: f64,
    /// The balls out of reach, by where they passed the window.
    pub out_of_reach: OutOfReach,
    /// The same per stroke type and speed band (the setting a ball is or
    /// resembles, e.g. `topspin-low`).
    pub by_setting: std::collections::BTreeMap<String, SettingTally>,
    /// Cycles the mock KR C4 closed without a valid answer by its deadline.
    pub late_rsi_answers: u64,
    /// Answers accepted under a stretched deadline that came later than
    /// one cycle (0 unless `answer_deadline` was stretched).
    pub answers_after_cycle: u64,
    /// RSI cycles the mock KR C4 ran.
    pub rsi_cycles: u64,
    /// Median spin error over the reachable balls with a plan, %.
    pub spin_err_pct_median: f64,
    /// Median closest approach of the bat centre to the ball over the reachable balls, mm.
    pub hit_err_mm_median: f64,
    /// How much earlier and later the returned balls could have come and
    /// still been returned by the same strokes, ms (medians; each side
    /// capped at [`crate::returns::TIMING_SPAN_MS`]).
    pub timing_tolerance_ms_median: [f64; 2],
    /// The least and most spin, as multiples of each returned ball's true
    /// spin at the contact, with which the same strokes still return it
    /// (medians; [`crate::returns::spin_window`], ×0.5 to ×2 at most).
    pub spin_tolerance_median: [f64; 2],
    /// The daemon's latency percentiles (RSI answer, observation to plan), µs.
    pub latency_us: Latencies,
    /// The RSI loop ended with the bat home (or no robot was there).
    pub ended_home: bool,
    /// Plans the RSI loop took that arrive late (and the worst, ms), and
    /// plans it refused.
    pub plans_late: u64,
    /// How late the latest of those plans arrived, ms.
    pub late_by_max_ms: f64,
    /// Plans the RSI loop refused.
    pub plans_rejected: u64,
    /// The logo thread's counters (with `runtime.logo`), and the logo
    /// spins the estimator fused or refused.
    pub logo: Option<LogoCounters>,
    /// Logo spins the estimator fused into a track.
    pub logo_spins_fused: u64,
    /// Logo spins the estimator's χ² gate refused.
    pub logo_spins_gated: u64,
    /// The real-time requests the OS refused the daemon's threads, in words.
    pub warnings: Vec<String>,
    /// The daemon's tracker ingest counters (foreign, malformed, …).
    pub ingest: IngestCounters,
    /// What the tracker fault injector did (`None`: a clean stream).
    pub tracker_faults: Option<InjectedCounts>,
    /// Returns the tracker followed back over the table (the estimator
    /// reads each ball's spin from its return).
    pub returns_followed: usize,
    /// Where the balls came from, and the human strokes passed over
    /// because they never reached the robot's half (not balls of the run).
    pub strokes: Strokes,
    /// The human strokes passed over, by reason.
    pub strokes_out_of_play: Redraws,
    /// Corrections the mock KR C4 had to clamp (POSCORR), and whether its
    /// monitor stopped RSI: zero and false unless the daemon commanded
    /// something out of bounds.
    pub poscorr_clamped: u64,
    /// The mock's correction monitor (POSCORRMON) stopped RSI.
    pub stopped_by_monitor: bool,
    /// The robot: its servo, whether the daemon compensated it, how it
    /// stopped (if it did) and the balls the planner skipped.
    pub robot: RobotReport,
    /// The verdict on each ball, in run order.
    pub per_ball: Vec<BallVerdict>,
}

/// What the robot did in a demo.
#[derive(Clone, Debug, Serialize)]
pub struct RobotReport {
    /// The mock's dead time and lag (`calib/robot.toml` `[servo]`).
    pub dead_time_ms: f64,
    /// The mock's first-order lag time constant, ms.
    pub lag_ms: f64,
    /// The daemon compensated them.
    pub compensation: bool,
    /// The correction sent (`cartesian`: RKorr, `axis`: AKorr) and the
    /// cycles AXISCORR clamped (axis).
    pub correction: &'static str,
    /// Cycles whose AKorr the mock's AXISCORR clamped (axis correction).
    pub axiscorr_clamped: u64,
    /// The smallest and largest AKorr per axis A1..A6, degrees (axis).
    pub akorr_range_deg: [[f64; 2]; 6],
    /// Controller stops (0 or 1: RSI ends with the first) and why.
    pub stops: u64,
    /// Why the controller stopped, in words (`None`: it did not).
    pub stop_reason: Option<String>,
    /// Balls whose stroke the planner refused, by reason.
    pub skipped: std::collections::BTreeMap<String, u64>,
    /// The fastest and hardest any axis moved, as shares of its limits,
    /// and the cycles with an axis over either (the mock counts them; a
    /// KR C4 would stop).
    pub peak_speed_share: f64,
    /// The hardest any axis accelerated, as a share of its acceleration limit.
    pub peak_acceleration_share: f64,
    /// Cycles with an axis over its speed or acceleration limit.
    pub rates_over: u64,
}

/// The ball's true hitting point on the hitting plane lies in the window.
pub fn reachable(cal: &Calibration, ball: &SimBall) -> bool {
    ball.truth.hit.as_ref().is_some_and(|h| cal.strike.in_window(h.pos[1], h.pos[2]))
}

/// Where the ball can be met, as the estimator would choose with the truth
/// in hand: its crossing of the hitting plane where that lies in the
/// window, else of the nearest other plane of the hitting volume
/// (`strike.hit_depth_x`; the later of two) where that does. `None`: out
/// of reach.
pub fn meeting(cal: &Calibration, ball: &SimBall) -> Option<HitTruth> {
    ball.truth.meeting_in(&cal.strike, &ball.physics)
}

/// The ball's true crossing of each plane of the hitting volume (in the
/// order of [`topspin_core::calib::StrikeCalib::hitting_planes`]).
fn crossings(cal: &Calibration, ball: &SimBall) -> Vec<(f64, Option<HitTruth>)> {
    cal.strike.hitting_planes().iter().map(|x| (*x, ball.truth.crossing_at(&ball.physics, *x))).collect()
}

/// [`meeting`] from the ball's [`crossings`].
fn meeting_among(cal: &Calibration, crossings: &[(f64, Option<HitTruth>)]) -> Option<HitTruth> {
    cal.strike.planes_outwards().find_map(|k| {
        let (x, h) = crossings[k];
        h.filter(|h| cal.strike.in_window_at(x, h.pos[1], h.pos[2]))
    })
}

/// Balls out of the hitting window, by where they pass it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct OutOfReach {
    /// Never crossed the hitting plane after the bounce (a second bounce,
    /// or too slow to get there).
    pub no_crossing: usize,
    /// Crossed the hitting plane beside the window (|y| too large), and no
    /// other plane of the volume in it either.
    pub wide: usize,
    /// Crossed it below the window.
    pub low: usize,
    /// Crossed it above the window.
    pub high: usize,
}

/// One setting's balls in a run: how many, how many reachable, returned.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SettingTally {
    /// Balls of this setting.
    pub balls: usize,
    /// Of them, the reachable ones.
    pub reachable: usize,
    /// Returned, of all balls.
    pub returned: usize,
}

/// [`SettingTally`] per setting over `balls` and their verdicts.
pub fn by_setting(balls: &[SimBall], per_ball: &[BallVerdict]) -> std::collections::BTreeMap<String, SettingTally> {
    let mut out = std::collections::BTreeMap::<String, SettingTally>::new();
    for b in balls {
        out.entry(b.truth.setting.to_string()).or_default().balls += 1;
    }
    for v in per_ball {
        let t = out.entry(v.setting.clone()).or_default();
        t.reachable += v.reachable as usize;
        t.returned += v.returned as usize;
    }
    out
}

impl OutOfReach {
    /// Counts the balls of `balls` outside the window of `cal`.
    pub fn of(cal: &Calibration, balls: &[SimBall]) -> OutOfReach {
        let w = &cal.strike;
        let mut o = OutOfReach::default();
        for b in balls.iter().filter(|b| meeting(cal, b).is_none()) {
            *match &b.truth.hit {
                None => &mut o.no_crossing,
                Some(h) if !(w.window_y[0]..=w.window_y[1]).contains(&h.pos[1]) => &mut o.wide,
                Some(h) if h.pos[2] < w.window_z[0] => &mut o.low,
                Some(_) => &mut o.high,
            } += 1;
        }
        o
    }

    /// All balls out of reach.
    pub fn total(&self) -> usize {
        self.no_crossing + self.wide + self.low + self.high
    }
}

/// What one loopback session produced, before judging.
#[derive(Debug)]
pub struct LoopbackRun {
    /// The simulated balls, in launch order.
    pub balls: Vec<SimBall>,
    /// Launch of ball k, s after `t0`.
    pub starts: Vec<f64>,
    /// The instant the launch times count from (process clock).
    pub t0: Instant,
    /// The mock KR C4's result: its counters and the logged path.
    pub mock: mock_krc::MockResult,
    /// The daemon's summary at its end.
    pub daemon: DaemonSummary,
    /// What the tracker fault injector did (`None`: a clean stream).
    pub injected: Option<InjectedCounts>,
    /// Human strokes passed over (see [`DemoReport::strokes_out_of_play`]).
    pub redraws: Redraws,
    /// What the OS refused of [`DemoConfig::tracker_thread`].
    pub tracker_warnings: Vec<RtWarning>,
    /// Returns the tracker followed back over the table
    /// (`tracker.follows_returns`).
    pub returns_followed: usize,
}

/// Runs the demo end to end and judges every stroke.
pub fn run(cfg: &DemoConfig, cal: &Calibration) -> std::io::Result<DemoReport> {
    let r = run_loopback(cfg, cal)?;
    let mut report = judge(cal, &cfg.runtime, &r.balls, &r.starts, r.t0, &r.mock, &r.daemon);
    report.tracker_faults = r.injected;
    report.returns_followed = r.returns_followed;
    report.strokes = cfg.strokes;
    report.strokes_out_of_play = r.redraws;
    Ok(report)
}

/// The simulated tracker, the daemon threads and the mock KR C4 on
/// loopback for `cfg.balls` balls; the bat brought home at the end.
pub fn run_loopback(cfg: &DemoConfig, cal: &Calibration) -> std::io::Result<LoopbackRun> {
    let (balls, redraws) = crate::simulate_in(cfg.world.as_ref(), cfg.strokes, cal, cfg.seed, cfg.balls, &cfg.tracker);
    let ends: Vec<f64> = balls.iter().map(|b| b.truth.end_t).collect();
    let starts = schedule(&ends, cfg.gap);

    let mut rcfg = cfg.runtime.clone();
    let crops = rcfg.logo.as_mut().map(|l| {
        l.camera_latency = Duration::from_nanos((cfg.tracker.latency * 1e9) as u64);
        render_crops(&l.camera, cfg.seed, &balls)
    });
    // The simulated tracker's capture-to-arrival latency is known here; on
    // the robot it is measured once and configured (tracker.fixed_latency_ms).
    // Through the daemon configuration (what a recording carries), so that
    // `topspin replay` of a demo recording sets up the same estimator.
    let dcfg = demo_daemon_config(cfg);
    rcfg.tracker_noise = dcfg.tracker_noise_m();
    rcfg.tracker_fixed_latency = Duration::from_nanos(dcfg.fixed_latency_ns());
    let truth = topspin_daemon::viewer::DemoTruth::default();
    let sink = viewer_sink(cfg, &mut rcfg, cal, &truth)?;
    let daemon = Daemon::start(&rcfg, cal, sink)?;
    let mut mcfg =
        MockKrcConfig::default_cell_for(cfg.runtime.correction).map_err(|e| std::io::Error::other(e.to_string()))?;
    mcfg.sensor = daemon.rsi_addr;
    mcfg.bind = "127.0.0.1:0".parse().expect("literal");
    mcfg.cycles = None;
    mcfg.seed = cfg.seed;
    mcfg.thread = cfg.mock_thread;
    if let Some(d) = cfg.answer_deadline {
        mcfg.answer_deadline = d;
    }
    if let Some(n) = cfg.late_limit {
        mcfg.controller.late_limit = n;
    }
    if let Some(q) = cfg.start_joints {
        mcfg.controller.stand_at(topspin_core::kinematics::Joints::from_degrees(q));
    }
    let mock = mock_krc::spawn(mcfg)?;

    let tracker = UdpSocket::bind("127.0.0.1:0")?;
    tracker.connect(daemon.tracker_addr)?;
    let t0 = clock::now() + Duration::from_nanos((LEAD_IN * 1e9) as u64);
    let _ = truth.set(
        balls
            .iter()
            .zip(&starts)
            .filter_map(|(b, &start)| {
                let h = b.truth.hit.as_ref()?;
                Some(topspin_daemon::viewer::TrueHit {
                    ball: b.index,
                    t: capture_time(t0, start, h.t),
                    pos: Vec3::from(h.pos),
                    vel: Vec3::from(h.vel),
                    reachable: meeting(cal, b).is_some(),
                })
            })
            .collect(),
    );
    let camera = match (daemon.crops_addr, &crops) {
        (Some(addr), Some(seqs)) => {
            let socket = UdpSocket::bind("127.0.0.1:0")?;
            socket.connect(addr)?;
            let (starts, latency, seqs) = (starts.clone(), cfg.tracker.latency, seqs.clone());
            Some(std::thread::spawn(move || stream_crops(&socket, &seqs, &starts, latency, t0)))
        }
        _ => None,
    };
    let never = AtomicBool::new(false);
    let tracker_addr = daemon.tracker_addr;
    let send = || -> std::io::Result<Option<InjectedCounts>> {
        match &cfg.tracker_faults {
            None => {
                stream(&tracker, &balls, &starts, cfg.tracker.latency, t0, &never)?;
                Ok(None)
            }
            Some(f) => {
                let clean = plan_datagrams(&balls, &starts, cfg.tracker.latency, t0);
                let (plan, counts) = inject(&clean, f, cfg.seed);
                // Another loopback address: not the configured tracker source.
                let foreign = UdpSocket::bind("127.0.0.2:0")?;
                foreign.connect(tracker_addr)?;
                send_planned(&tracker, Some(&foreign), &plan, &never)?;
                Ok(Some(counts))
            }
        }
    };
    let send_all = || -> std::io::Result<_> {
        if cfg.tracker_thread == ThreadSpec::default() {
            return Ok((send()?, Vec::new()));
        }
        let spec = cfg.tracker_thread;
        std::thread::scope(|s| {
            let h = std::thread::Builder::new().name("tracker".into()).spawn_scoped(s, || {
                let refused = topspin_daemon::runtime::rt::setup_current("tracker", spec.core, spec.priority);
                send().map(|i| (i, refused))
            })?;
            h.join().map_err(|_| std::io::Error::other("tracker stream panicked"))?
        })
    };
    // The same tracker follows each return back, on its own thread.
    let returns_socket = tracker.try_clone()?;
    let follow = cfg.tracker.follows_returns;
    let ((injected, tracker_warnings), returns_followed) = std::thread::scope(|s| -> std::io::Result<_> {
        let returns = follow.then(|| s.spawn(|| follow_returns(&returns_socket, cfg, cal, &balls, &starts, t0, &mock)));
        let sent = send_all()?;
        let followed = match returns {
            Some(h) => h.join().map_err(|_| std::io::Error::other("return stream panicked"))??,
            None => 0,
        };
        Ok((sent, followed))
    })?;
    if let Some(c) = camera {
        c.join().map_err(|_| std::io::Error::other("crop stream panicked"))??;
    }
    // Let the last stroke finish and the bat come home.
    let last_end = starts.last().copied().unwrap_or(0.0) + ends.last().copied().unwrap_or(0.0);
    let until = capture_time(t0, last_end, cfg.tail_s);
    clock::sleep_until(until, Duration::from_micros(0));
    daemon.request_stop();
    let drain_start = clock::now();
    let mut home_since: Option<Instant> = None;
    loop {
        let now = clock::now();
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
    Ok(LoopbackRun { balls, starts, t0, mock, daemon, injected, redraws, tracker_warnings, returns_followed })
}

/// The daemon configuration the demo amounts to (tracker noise and latency).
pub(crate) fn demo_daemon_config(cfg: &DemoConfig) -> topspin_daemon::config::DaemonConfig {
    let mut d = topspin_daemon::config::DaemonConfig::default();
    d.tracker.noise_mm = cfg.tracker.noise_sigma.max(1e-4) * 1e3;
    d.tracker.fixed_latency_ms = cfg.tracker.latency * 1e3;
    d
}

/// The telemetry sink for `--live` and/or `--record`: the viewer (with
/// the demo's truth for its verdicts) and the recording; RSI bytes are
/// pushed to telemetry then (the TCP in the view).
fn viewer_sink(
    cfg: &DemoConfig,
    rcfg: &mut RuntimeConfig,
    cal: &Calibration,
    truth: &topspin_daemon::viewer::DemoTruth,
) -> std::io::Result<Option<Box<dyn topspin_daemon::runtime::TelemetrySink>>> {
    if cfg.live.is_none() && cfg.record.is_none() {
        return Ok(None);
    }
    rcfg.record_rsi = true;
    let live = match cfg.live {
        Some(addr) => {
            let server =
                topspin_daemon::viewer::LiveServer::start(addr, rcfg.telemetry.core).map_err(std::io::Error::other)?;
            tracing::info!(target: "topspin::viewer", "live view on ws://{}", server.addr());
            if cfg.live_wait.0 > 0 {
                let until = clock::now() + cfg.live_wait;
                while server.clients() == 0 && clock::now() < until {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                }
                if server.clients() > 0 {
                    std::thread::sleep(std::time::Duration::from_nanos(LIVE_SETTLE.0));
                }
            }
            Some(server)
        }
        None => None,
    };
    let recording = match &cfg.record {
        Some(path) => {
            let files = topspin_daemon::calib_files::calibration_texts(None).map_err(std::io::Error::other)?;
            let rec = topspin_daemon::record::Recorder::create(path, &demo_daemon_config(cfg), &files)
                .map_err(std::io::Error::other)?;
            Some(topspin_daemon::record::RecordingSink::new(rec))
        }
        None => None,
    };
    Ok(Some(Box::new(topspin_daemon::viewer::ViewerSink::new(cal, live, recording, Some(truth.clone())))))
}

/// How far a plan's hit time may lie from the ball's true crossing of its
/// plane for the plan to be this ball's.
const PLAN_MATCH: Duration = Duration::from_millis(50);

fn judge(
    cal: &Calibration,
    runtime: &RuntimeConfig,
    balls: &[SimBall],
    starts: &[f64],
    t0: Instant,
    mock: &mock_krc::MockResult,
    summary: &DaemonSummary,
) -> DemoReport {
    let per_ball = judge_strokes(cal, balls, starts, t0, &mock.path, &summary.telemetry.last_plans);

    let reach: Vec<&BallVerdict> = per_ball.iter().filter(|b| b.reachable).collect();
    let hits = reach.iter().filter(|b| b.hit).count();
    let returns = reach.iter().filter(|b| b.returned).count();
    let mut return_fails = ReturnFails::default();
    for f in reach.iter().filter_map(|b| b.return_fail) {
        return_fails.add(f);
    }
    let spin: Vec<f64> = reach.iter().filter_map(|b| b.spin_err_pct).collect();
    let hit_err: Vec<f64> = reach.iter().filter_map(|b| b.hit_err_mm).collect();
    let windows: Vec<[f64; 2]> = reach.iter().filter(|b| b.returned).filter_map(|b| b.timing_window_ms).collect();
    let tolerance = |side: fn(&[f64; 2]) -> f64| Summary::of(&windows.iter().map(side).collect::<Vec<_>>()).median;
    let spins: Vec<[f64; 2]> =
        reach.iter().filter(|b| b.returned).filter_map(|b| b.contact.and_then(|c| c.spin_window)).collect();
    let spin_end = |end: usize| Summary::of(&spins.iter().map(|w| w[end]).collect::<Vec<_>>()).median;
    DemoReport {
        balls: balls.len(),
        reachable: reach.len(),
        hits,
        hit_rate: if reach.is_empty() { 0.0 } else { hits as f64 / reach.len() as f64 },
        returns,
        return_rate: if reach.is_empty() { 0.0 } else { returns as f64 / reach.len() as f64 },
        return_fails,
        return_rate_all: if balls.is_empty() {
            0.0
        } else {
            per_ball.iter().filter(|b| b.returned).count() as f64 / balls.len() as f64
        },
        out_of_reach: OutOfReach::of(cal, balls),
        by_setting: by_setting(balls, &per_ball),
        late_rsi_answers: mock.late,
        answers_after_cycle: mock.answers_after_cycle,
        rsi_cycles: mock.cycles,
        spin_err_pct_median: Summary::of(&spin).median,
        hit_err_mm_median: Summary::of(&hit_err).median,
        timing_tolerance_ms_median: [tolerance(|w| -w[0]), tolerance(|w| w[1])],
        spin_tolerance_median: [spin_end(0), spin_end(1)],
        latency_us: Latencies::of(&summary.telemetry),
        ended_home: summary.ended_home,
        plans_late: summary.telemetry.plans_late,
        late_by_max_ms: summary.telemetry.late_by_max_ms,
        plans_rejected: summary.telemetry.plans_rejected,
        logo: summary.logo,
        logo_spins_fused: summary.telemetry.logo_spins_fused,
        logo_spins_gated: summary.telemetry.logo_spins_gated,
        warnings: summary.warnings.iter().map(|w| w.to_string()).collect(),
        ingest: summary.ingest,
        tracker_faults: None,
        returns_followed: 0,
        strokes: Strokes::Launcher,
        strokes_out_of_play: Redraws::default(),
        poscorr_clamped: mock.poscorr_clamped,
        stopped_by_monitor: mock.stopped_by_monitor,
        robot: RobotReport {
            dead_time_ms: cal.robot.servo.dead_time_ms,
            lag_ms: cal.robot.servo.lag_ms,
            compensation: runtime.servo_compensation,
            correction: runtime.correction.key(),
            axiscorr_clamped: mock.axiscorr_clamped,
            akorr_range_deg: mock.akorr_range_deg,
            stops: mock.stopped.is_some() as u64,
            stop_reason: mock.stopped.map(|r| r.to_string()),
            skipped: summary.telemetry.skipped.clone(),
            peak_speed_share: mock.peak_speed_share,
            peak_acceleration_share: mock.peak_acceleration_share,
            rates_over: mock.rates_over,
        },
        per_ball,
    }
}

/// The tracker following each ball's return back over the table on the
/// wall clock ([`ReturnFeed`]: the contact found on the mock's path so
/// far), sent over `socket` as each frame arrives; the returns followed.
fn follow_returns(
    socket: &UdpSocket,
    cfg: &DemoConfig,
    cal: &Calibration,
    balls: &[SimBall],
    starts: &[f64],
    t0: Instant,
    mock: &mock_krc::MockHandle,
) -> std::io::Result<usize> {
    let mut feed = ReturnFeed::new(cfg.seed, cfg.tracker);
    while let Some(due) = feed.due(balls, starts, t0) {
        clock::sleep_until(due, Duration::from_micros(0));
        // The daemon's plans are its own: where the ball meets the window.
        let k = feed.next_ball();
        let crossing = judged(cal, &balls[k], t0, starts[k], &[]).map(|j| j.hit.t);
        feed.find(cal, balls, starts, t0, &mock.recent_path(), crossing, clock::now());
        while let Some(d) = feed.pop() {
            clock::sleep_until(d.at, Duration::from_micros(0));
            match socket.send(d.bytes()) {
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(e),
            }
        }
    }
    Ok(feed.seen)
}

/// Where a ball is judged ([`judged`]).
pub(crate) struct Judged<'a> {
    /// It crosses the hitting volume's window.
    pub reachable: bool,
    /// The last plan that answered it.
    pub plan: Option<&'a StrikePlan>,
    /// Its true crossing of that plan's plane (else of the plane it meets
    /// the window on, the hitting plane, the first plane it crosses).
    pub hit: HitTruth,
}

/// Where `ball` (launched `start` s after `t0`) is judged: the true crossings of
/// the volume's planes, and the last of `last_plans` whose hit is nearest
/// the ball's true crossing of the plan's own plane; `None` where it
/// crosses none.
pub(crate) fn judged<'a>(
    cal: &Calibration,
    ball: &SimBall,
    t0: Instant,
    start: f64,
    last_plans: &'a [StrikePlan],
) -> Option<Judged<'a>> {
    let all = crossings(cal, ball);
    let meet = meeting_among(cal, &all);
    let crossings: Vec<(f64, HitTruth)> = all.iter().filter_map(|(x, h)| h.map(|h| (*x, h))).collect();
    let reference = meet.or(ball.truth.hit).or(crossings.first().map(|c| c.1))?;
    let on_plans_plane = |p: &StrikePlan| {
        let dx = |c: &&(f64, HitTruth)| (c.0 - p.position.x).abs();
        crossings.iter().min_by(|a, b| dx(a).total_cmp(&dx(b))).map(|c| c.1)
    };
    let matched = last_plans
        .iter()
        .filter_map(|p| {
            let c = on_plans_plane(p)?;
            let off = p.hit_time.0.abs_diff(capture_time(t0, start, c.t).0);
            (off < PLAN_MATCH.0).then_some((p, c, off))
        })
        .min_by_key(|m| m.2);
    Some(Judged { reachable: meet.is_some(), plan: matched.map(|m| m.0), hit: matched.map_or(reference, |m| m.1) })
}

/// Judges every stroke on the truth: the bat's actual TCP (`path`, the
/// controller's log) against the ball's true position within ±[`HIT_WINDOW`]
/// of its true crossing of the hitting plane, the last plan of each
/// trajectory (`last_plans`) against the true hit, and the return
/// ([`judge_return`]).
pub(crate) fn judge_strokes(
    cal: &Calibration,
    balls: &[SimBall],
    starts: &[f64],
    t0: Instant,
    path: &[mock_krc::PathSample],
    last_plans: &[StrikePlan],
) -> Vec<BallVerdict> {
    let robot = &cal.robot;
    let bat_path = BatPath::new(robot, path);
    let mut per_ball = Vec::new();
    for (k, ball) in balls.iter().enumerate() {
        let truth = &ball.truth;
        let true_spin = Vec3::new(truth.spin[0], truth.spin[1], truth.spin[2]);
        let Some(Judged { reachable, plan, hit }) = judged(cal, ball, t0, starts[k], last_plans) else { continue };
        let hit = &hit;
        let t_hit = capture_time(t0, starts[k], hit.t);
        let launch = truth.to_launch();
        let launched = capture_time(t0, starts[k], 0.0);
        let closest = closest_approach(&bat_path, &launch, &ball.physics, launched, t_hit);
        let est = plan.map(|p| p.spin);
        let true_hit = Vec3::new(hit.pos[0], hit.pos[1], hit.pos[2]);
        let tracking_err_mm = plan.and_then(|p| bat_path.at(p.hit_time).map(|b| (b.centre - p.position).norm() * 1e3));
        let ret = judge_return(cal, &ball.physics, &launch, launched, hit.t, &bat_path);
        let timing_window_ms =
            reachable.then(|| timing_window(cal, &ball.physics, &launch, launched, hit.t, &bat_path)).flatten();
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
            returned: ret.returned(),
            return_fail: ret.fail,
            return_why: ret.why,
            contact: ret.contact,
            landing_xy: ret.landing,
            timing_window_ms,
        });
    }
    per_ball
}

/// Step of the judge's search for the closest approach, s.
const CLOSEST_STEP_S: f64 = 1e-4;

/// The bat centre's closest approach to the true ball (launched at
/// `launched`) within ±[`HIT_WINDOW`] of `t_hit`, m. The controller logs
/// the bat once a cycle (4 ms) while bat and ball close at 5–7 m/s, so the
/// distance at the logged instants alone overstates the miss by up to
/// ~14 mm; the bat is taken between them as [`BatPath`] interpolates it
/// (as the return's contact is) and the distance every
/// [`CLOSEST_STEP_S`].
fn closest_approach(
    bat: &BatPath,
    launch: &Launch,
    prop: &Propagator,
    launched: Instant,
    t_hit: Instant,
) -> Option<f64> {
    let window = HIT_WINDOW.0 as f64 * 1e-9;
    let mut flight = Flight::new(launch, prop);
    let steps = (2.0 * window / CLOSEST_STEP_S).round() as usize;
    (0..=steps)
        .filter_map(|i| {
            let t = t_hit.secs_since(launched) - window + i as f64 * CLOSEST_STEP_S;
            let at = launched + Duration::from_nanos((t.max(0.0) * 1e9).round() as u64);
            bat.at(at).map(|b| (b.centre - flight.at(t).pos).norm())
        })
        .min_by(f64::total_cmp)
}

/// Renders each ball's pass through the ceiling camera's strip (orange
/// ball, the frames before the bounce).
pub(crate) fn render_crops(cam: &CameraCalib, seed: u64, balls: &[SimBall]) -> Vec<Sequence> {
    let scene = Scene::new(cam.clone(), BallColour::Orange);
    let opts = SequenceOptions { frames: topspin_core::logo::SEQUENCE_LEN };
    let render = |b: &SimBall| render_sequence(&scene, &b.truth, &b.physics, seed, b.index, &opts);
    // One chunk of balls per core, in order (no thread pool in the sim crate).
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = balls.len().div_ceil(workers).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> =
            balls.chunks(chunk).map(|part| s.spawn(move || part.iter().map(render).collect::<Vec<_>>())).collect();
        handles.into_iter().flat_map(|h| h.join().expect("render thread")).collect()
    })
}

/// Sends every rendered crop as a TTI1 datagram at capture + `latency`.
fn stream_crops(
    socket: &UdpSocket,
    seqs: &[Sequence],
    starts: &[f64],
    latency: f64,
    t0: Instant,
) -> std::io::Result<u64> {
    let mut items: Vec<(Instant, &crate::render::Frame)> = seqs
        .iter()
        .zip(starts)
        .flat_map(|(s, &start)| s.frames.iter().map(move |f| (capture_time(t0, start, f.label.t), f)))
        .collect();
    items.sort_by_key(|(t, _)| t.0);
    let latency = Duration::from_nanos((latency.max(0.0) * 1e9) as u64);
    let mut buf = vec![0u8; CROP_MAX_LEN];
    let mut sent = 0;
    for (seq, (capture, f)) in items.into_iter().enumerate() {
        clock::sleep_until(capture + latency, Duration::from_micros(0));
        let n = f.wire_crop(seq as u32, capture).emit(&mut buf).map_err(|e| std::io::Error::other(e.to_string()))?;
        if socket.send(&buf[..n]).is_ok() {
            sent += 1;
        }
    }
    Ok(sent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launcher::Setting;
    use topspin_core::geometry::EulerZyx;
    use topspin_core::physics::BallState;

    /// A bat logged every 4 ms that stands still where the ball passes
    /// 2 ms after a sample: the distance at the samples is the ball's
    /// 2 ms of flight (about 14 mm at 7 m/s), the closest approach 0.
    #[test]
    fn the_closest_approach_is_taken_between_the_controllers_samples() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let ball = BallState::new(Vec3::new(0.5, 0.1, 0.3), Vec3::new(7.0, 0.0, 0.5), Vec3::zeros());
        let launch = Launch { setting: Setting::ALL[0], state: ball };
        let launched = Instant(1_000_000_000);
        let t_hit = launched + Duration::from_millis(102);
        let at = crate::true_state_at(&launch, &prop, 0.102).pos;
        let times: Vec<Instant> = (0..60).map(|k| launched + Duration::from_millis(4 * k)).collect();
        let bat = BatPath::from_poses(&times, &vec![at; times.len()], &vec![EulerZyx::default(); times.len()]);
        let sampled = times
            .iter()
            .filter(|t| t.0.abs_diff(t_hit.0) <= HIT_WINDOW.0)
            .map(|t| (at - crate::true_state_at(&launch, &prop, t.secs_since(launched)).pos).norm())
            .fold(f64::INFINITY, f64::min);
        let closest = closest_approach(&bat, &launch, &prop, launched, t_hit).expect("the bat is logged there");
        assert!(sampled > 0.012, "{sampled}");
        assert!(closest < 0.0005, "{closest}");
    }
}
