//! The demo's whole cell on a virtual clock: the simulated tracker's TTB1
//! datagrams (optionally through the tracker-side fault injector) into the
//! daemon's sans-IO ingest and estimator, their plans through the
//! latest-value slot into the RSI session, and the session against the
//! mock KR C4 ([`Pair`]) — the same cores the daemon's threads own, in one
//! thread, with no socket, sleep or clock read. Strokes are judged on the
//! truth exactly as the loopback demo judges them
//! (`crate::demo::judge_strokes`), so a run is a deterministic function
//! of its configuration and seed.
//!
//! What it leaves out of the daemon: the threads' own processing time (the
//! estimator's plan is ready when its observation arrives, the logo's spin
//! when its last crop does; the benches measure those times) and the
//! telemetry thread.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};

use crate::demo::{BallVerdict, DemoConfig, LEAD_IN, demo_daemon_config, judge_strokes, judged, render_crops};
use crate::faults::{InjectedCounts, Sender, inject, plan_datagrams};
use crate::mock_krc::{Faults, MockKrcConfig, MockResult};
use crate::pair::Pair;
use crate::render::Sequence;
use crate::return_feed::ReturnFeed;
use crate::udp_tracker::capture_time;
use crate::{SimBall, schedule, simulate_in};
use topspin_core::calib::Calibration;
use topspin_core::estimator::{Estimator, EstimatorEvent};
use topspin_core::ingest::{Ingest, IngestCounters};
use topspin_core::logo::{LogoCounters, LogoStream};
use topspin_core::motion::Phase;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{RsiSession, SessionConfig, SessionStats};
use topspin_core::time::{Duration, Instant};

/// Where the virtual tracker's datagrams come from.
const TRACKER: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::new(127, 0, 0, 1)), 40_001);
/// A second device on the tracker's network (the foreign ball).
const FOREIGN: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2)), 40_001);
/// The virtual clock's origin (the daemon's start).
const START: Instant = Instant(1_000_000_000);

/// What one virtual session produced.
#[derive(Debug)]
pub struct VirtualRun {
    /// The simulated balls, with their truth.
    pub balls: Vec<SimBall>,
    /// Launch of ball k, s after `t0`.
    pub starts: Vec<f64>,
    /// The first launch's reference time.
    pub t0: Instant,
    /// The controller's counters and TCP path.
    pub mock: MockResult,
    /// The RSI session's counters.
    pub session: SessionStats,
    /// The ingest's counters.
    pub ingest: IngestCounters,
    /// The last plan of every trajectory, in order.
    pub last_plans: Vec<StrikePlan>,
    /// What the tracker-side fault injector did, if it ran.
    pub injected: Option<InjectedCounts>,
    /// The logo stream's counters (with `runtime.logo`).
    pub logo: Option<LogoCounters>,
    /// Logo spins the estimator fused into a track.
    pub logo_spins_fused: u64,
    /// Logo spins the estimator's χ² gate refused.
    pub logo_spins_gated: u64,
    /// Every stroke judged on the truth.
    pub per_ball: Vec<BallVerdict>,
    /// Returns the tracker followed (`tracker.follows_returns`).
    pub returns_seen: usize,
    /// The frames it sent of them.
    pub return_frames: usize,
    /// Balls whose spin the estimator read from their return.
    pub returns_read: u32,
}

impl VirtualRun {
    /// Reachable balls.
    pub fn reachable(&self) -> usize {
        self.per_ball.iter().filter(|b| b.reachable).count()
    }

    /// Reachable balls hit.
    pub fn hits(&self) -> usize {
        self.per_ball.iter().filter(|b| b.reachable && b.hit).count()
    }

    /// Reachable balls returned.
    pub fn returned(&self) -> usize {
        self.per_ball.iter().filter(|b| b.reachable && b.returned).count()
    }
}

/// How long the bat rests home before a virtual run ends (as the
/// wall-clock demo's drain waits).
const HOME_SETTLE: Duration = Duration(200_000_000);
/// How long past `tail_s` a virtual run waits at most for the bat to come
/// home (as the wall-clock demo's drain).
const DRAIN_MAX: Duration = Duration(5_000_000_000);

/// Runs `cfg.balls` balls through the cell on the virtual clock until the
/// last stroke is done and the bat has rested home (`cfg.tracker_faults` applied;
/// the live view and recording of `cfg` are not part of it).
///
/// # Panics
///
/// If `runtime.logo` names a CNN whose model does not load.
pub fn run_virtual(cfg: &DemoConfig, cal: &Calibration) -> VirtualRun {
    let (balls, _) = simulate_in(cfg.world.as_ref(), cfg.strokes, cal, cfg.seed, cfg.balls, &cfg.tracker);
    let ends: Vec<f64> = balls.iter().map(|b| b.truth.end_t).collect();
    let starts = schedule(&ends, cfg.gap);
    let t0 = START + Duration::from_nanos((LEAD_IN * 1e9) as u64);
    let clean = plan_datagrams(&balls, &starts, cfg.tracker.latency, t0);
    let (datagrams, injected) = match &cfg.tracker_faults {
        Some(f) => {
            let (d, counts) = inject(&clean, f, cfg.seed);
            (d, Some(counts))
        }
        None => (clean, None),
    };

    let dcfg = demo_daemon_config(cfg);
    let mut ingest = Ingest::new(cfg.runtime.tracker_source, dcfg.fixed_latency_ns());
    let mut estimator = Estimator::new(cal, dcfg.estimator_config());
    let mut session_cfg = SessionConfig::from_calibration(cal, &cfg.runtime.sentype);
    session_cfg.correction = cfg.runtime.correction;
    let session = RsiSession::new(session_cfg).expect("the calibration's session configuration is valid");
    let mut controller =
        MockKrcConfig::default_cell_for(cfg.runtime.correction).expect("the compiled-in rsi/ files parse").controller;
    if let Some(n) = cfg.late_limit {
        controller.late_limit = n;
    }
    if let Some(q) = cfg.start_joints {
        controller.stand_at(topspin_core::kinematics::Joints::from_degrees(q));
    }
    let mut pair = Pair::new(session, controller, Faults::default(), cfg.seed, START);
    if let Some(d) = cfg.answer_deadline {
        pair.timing.deadline = d;
    }

    let last_end = starts.last().copied().unwrap_or(0.0) + ends.last().copied().unwrap_or(0.0);
    let end = t0 + Duration::from_nanos(((last_end + cfg.tail_s).max(0.0) * 1e9) as u64);
    let mut camera = cfg.runtime.logo.as_ref().map(|l| {
        let latency = Duration::from_nanos((cfg.tracker.latency * 1e9) as u64);
        let method = l.method.load().expect("the logo method loads");
        Camera::new(
            render_crops(&l.camera, cfg.seed, &balls),
            &starts,
            t0,
            latency,
            LogoStream::new(l.camera.clone(), method),
        )
    });
    let mut logo_spins = LogoSpins::default();
    let mut returns = ReturnFeed::new(cfg.seed, cfg.tracker);
    let mut last_plans: Vec<StrikePlan> = Vec::new();
    let mut next = 0;
    let mut home_since: Option<Instant> = None;
    loop {
        // Past the tail, on until the bat has rested home (the wall-clock
        // demo's drain): the last stroke is never cut short.
        let now = pair.now();
        if now >= end {
            if pair.session.generator().phase() == Phase::Hold {
                if now - *home_since.get_or_insert(now) >= HOME_SETTLE {
                    break;
                }
            } else {
                home_since = None;
            }
            if now >= end + DRAIN_MAX {
                break;
            }
        }
        // Everything that reaches the daemon before this cycle's request
        // does: its plan is in the slot when the session takes it. Crops
        // and datagrams in the order they arrive.
        let request_arrives = pair.now() + pair.timing.request_latency;
        while cfg.tracker.follows_returns && returns.due(&balls, &starts, t0).is_some_and(|t| t <= pair.now()) {
            let k = returns.next_ball();
            let crossing = judged(cal, &balls[k], t0, starts[k], &last_plans).map(|j| j.hit.t);
            returns.find(cal, &balls, &starts, t0, pair.path(), crossing, pair.now());
        }
        loop {
            // The tracker's next datagram: a ball's flight or a return's.
            let (return_at, flight_at) = (returns.next_arrival(), datagrams.get(next).map(|d| d.at));
            let from_return = return_at.is_some_and(|r| flight_at.is_none_or(|f| r < f));
            let tracker_at = if from_return { return_at } else { flight_at }.filter(|t| *t <= request_arrives);
            let crop_at = camera.as_ref().and_then(Camera::next_arrival).filter(|t| *t <= request_arrives);
            if let (Some(c), Some(cam)) = (crop_at, camera.as_mut())
                && tracker_at.is_none_or(|t| c < t)
            {
                if let Some(spin) = cam.deliver_next() {
                    logo_spins.count(estimator.observe_logo_spin(&spin));
                }
                continue;
            }
            if tracker_at.is_none() {
                break;
            }
            let d = if from_return {
                returns.pop().expect("a queued return")
            } else {
                next += 1;
                datagrams[next - 1]
            };
            let from = match d.from {
                Sender::Tracker => TRACKER,
                Sender::Foreign => FOREIGN,
            };
            let Ok(accepted) = ingest.accept(d.bytes(), from, d.at) else { continue };
            if let Some(plan) = estimator.observe(accepted.capture, accepted.pos).plan {
                pair.publish(plan);
                match last_plans.last_mut() {
                    Some(last) if last.trajectory == plan.trajectory => *last = plan,
                    _ => last_plans.push(plan),
                }
            }
        }
        // A sequence gone quiet ends (the logo thread's receive timeout).
        if let Some(spin) = camera.as_mut().and_then(|c| c.stream.poll(request_arrives)) {
            logo_spins.count(estimator.observe_logo_spin(&spin));
        }
        if pair.step().is_none() {
            break; // RSI stopped: the controller would need a restart
        }
    }
    let mock = pair.result();
    let per_ball = judge_strokes(cal, &balls, &starts, t0, &mock.path, &last_plans);
    VirtualRun {
        balls,
        starts,
        t0,
        mock,
        session: *pair.session.stats(),
        ingest: ingest.counters(),
        last_plans,
        injected,
        logo: camera.map(|c| c.stream.counters()),
        logo_spins_fused: logo_spins.fused,
        logo_spins_gated: logo_spins.gated,
        per_ball,
        returns_seen: returns.seen,
        return_frames: returns.frames,
        returns_read: estimator.session().returns_read,
    }
}

/// Logo spins the estimator fused, and refused at its gate.
#[derive(Default)]
struct LogoSpins {
    fused: u64,
    gated: u64,
}

impl LogoSpins {
    fn count(&mut self, event: Option<EstimatorEvent>) {
        if let Some(EstimatorEvent::LogoSpin { accepted, .. }) = event {
            *(if accepted { &mut self.fused } else { &mut self.gated }) += 1;
        }
    }
}

/// The ceiling camera on the virtual clock: every rendered crop with the
/// time it reaches the logo stream, in that order.
struct Camera {
    sequences: Vec<Sequence>,
    /// (arrival, capture, sequence, frame), by arrival.
    crops: Vec<(Instant, Instant, usize, usize)>,
    next: usize,
    stream: LogoStream,
}

impl Camera {
    fn new(sequences: Vec<Sequence>, starts: &[f64], t0: Instant, latency: Duration, stream: LogoStream) -> Self {
        let mut crops: Vec<_> = sequences
            .iter()
            .zip(starts)
            .enumerate()
            .flat_map(|(k, (s, &start))| {
                s.frames.iter().enumerate().map(move |(i, f)| {
                    let capture = capture_time(t0, start, f.label.t);
                    (capture + latency, capture, k, i)
                })
            })
            .collect();
        crops.sort_by_key(|c| c.0.0);
        Camera { sequences, crops, next: 0, stream }
    }

    fn next_arrival(&self) -> Option<Instant> {
        self.crops.get(self.next).map(|c| c.0)
    }

    /// The next crop into the logo stream, and the spin it completes.
    fn deliver_next(&mut self) -> Option<topspin_core::estimator::LogoSpin> {
        let (_, capture, k, i) = *self.crops.get(self.next)?;
        self.next += 1;
        self.stream.crop(&self.sequences[k].frames[i].wire_crop(self.next as u32, capture))
    }
}
