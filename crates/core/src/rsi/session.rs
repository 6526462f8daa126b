//! The sans-IO RSI session: one [`RsiSession::handle_datagram`] per
//! controller request, answering into the caller's buffer.
//!
//! It owns the protocol state (start pose, IPOC continuity, the
//! controller's `<Delay>` counter, its own answer latency, the map from the
//! controller's IPOC clock to ours) and the motion pipeline (stroke
//! generator → safety filter → RKorr in #ABSOLUTE mode: commanded pose
//! minus the pose at RSI start, in mm and degrees). Plans come in with
//! [`RsiSession::set_plan`]; state changes come out of
//! [`RsiSession::poll_event`]. It never reads a clock (time is passed in),
//! never touches a socket, and does not allocate after construction.
//!
//! Every well-formed request is answered: with the generator's setpoint
//! after the safety filter, or — should that ever not be finite — the last
//! correction sent (zero before the first). Only bytes that are not a
//! `<Rob>` datagram (no IPOC to echo) get no answer, and are counted.
//!
//! Timing: the setpoint answered for IPOC k is the pose for the time the
//! robot will be there, t = (IPOC k on our clock) + lead (+ the servo's
//! dead time, when compensated). With the servo's lag compensated, the
//! correction sent is the setpoint fed forward through the inverse of the
//! drives' first-order lag (exact for the discrete lag the robot runs):
//! u = r(t) + (1/α − 1)·(r(t) − r(t − T)), α = 1 − e^(−T/τ), so the axes
//! arrive at r(t) at t. IPOC (ms) is the
//! controller's own clock; its offset to ours is the minimum of
//! (arrival − IPOC) over a sliding window, so arrival jitter does not shake
//! the path. Only #ABSOLUTE mode is produced.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use heapless::Deque;

use super::codec::{CodecError, KukaPose, RobFrame, SenFrame, check_text};
use crate::calib::Calibration;
use crate::kinematics::Joints;
use crate::motion::generator::Phase;
use crate::motion::limits::unwrap_near;
use crate::motion::{MotionLimits, PlanRejected, Pose6, SafetyFilter, StrokeGenerator};
use crate::plan::StrikePlan;
use crate::time::{Duration, Instant};

/// Events kept until polled; older ones are dropped (and counted) beyond.
pub(crate) const EVENT_CAPACITY: usize = 64;
/// Cycles per block of the IPOC → clock offset minimum filter.
pub(crate) const CLOCK_WINDOW_CYCLES: u32 = 1024;
/// The largest answer [`RsiSession::handle_datagram`] writes, bytes.
pub const MAX_ANSWER_LEN: usize = 512;

/// How the session is set up.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionConfig {
    /// `Type` of `<Sen>`: SENTYPE of the Ethernet configuration.
    pub sentype: String,
    /// Optional `<EStr>` text.
    pub estr: Option<String>,
    /// Decimals of RKorr: `Precision` of the ETHERNET object.
    pub precision: u8,
    /// Sensor cycle, ms (4 or 12).
    pub cycle_ms: u32,
    /// Request → the robot at the answered pose.
    pub lead: Duration,
    /// An answer slower than this (datagram in → answer sent) is an event.
    pub latency_budget: Duration,
    /// No request for this long: the robot is silent.
    pub silence: Duration,
    /// The cell's motion limits (workspace, velocity, acceleration, jerk,
    /// home) for the generator and the safety filter.
    pub limits: MotionLimits,
    /// The robot's servo, as calibrated (`[servo]`), and whether to
    /// compensate it (command ahead of the dead time, feed the lag
    /// forward).
    pub servo: ServoCompensation,
}

/// The servo the session commands through.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ServoCompensation {
    /// Dead time beyond `lead`.
    pub dead_time: Duration,
    /// First-order lag time constant, s.
    pub lag_s: f64,
    /// Compensate them (false: command as if the robot were ideal).
    pub enabled: bool,
}

impl ServoCompensation {
    /// The feed-forward gain 1/α − 1 for a cycle of `dt` s (0 when off).
    pub fn feed_forward_gain(&self, dt: f64) -> f64 {
        if !self.enabled || self.lag_s <= 0.0 {
            return 0.0;
        }
        1.0 / crate::calib::robot::lag_step(dt, self.lag_s) - 1.0
    }
}

impl SessionConfig {
    /// From the calibration, with SENTYPE `sentype` and 4 decimals.
    pub fn from_calibration(c: &Calibration, sentype: &str) -> Self {
        SessionConfig {
            sentype: sentype.to_owned(),
            estr: None,
            precision: 4,
            cycle_ms: c.robot.rsi.cycle_ms,
            lead: Duration::from_millis(c.robot.rsi.lead_ms as u64),
            latency_budget: Duration::from_micros(1000),
            silence: Duration::from_millis(100),
            limits: MotionLimits::from_robot(&c.robot),
            servo: ServoCompensation {
                dead_time: Duration::from_millis(
                    (c.robot.servo.dead_time_cycles(c.robot.rsi.cycle_ms) * c.robot.rsi.cycle_ms) as u64,
                ),
                lag_s: c.robot.servo.lag_s(),
                enabled: true,
            },
        }
    }
}

/// Where the session stands.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum SessionState {
    /// No request yet (or the robot was silent): the next one sets the
    /// start pose.
    WaitingForRobot,
    /// Requests arriving and answered.
    Running,
    /// No request for longer than `silence`.
    Silent,
}

/// Something the owner (log, telemetry) should know.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum SessionEvent {
    /// First request: RSI started at this IPOC; `off_home` if the robot's
    /// start pose differs from the calibrated home by > 5 mm or 1°.
    Started {
        /// The first request's IPOC.
        ipoc: u64,
        /// The start pose (`RIst`) is off the calibrated home.
        off_home: bool,
    },
    /// Bytes that are not a `<Rob>` datagram (not answered).
    Malformed(CodecError),
    /// IPOC jumped: cycles were missed.
    IpocGap {
        /// The IPOC one cycle after the last one.
        expected: u64,
        /// The IPOC received.
        got: u64,
    },
    /// The same IPOC again (answered with the same correction).
    IpocRepeated {
        /// The repeated IPOC.
        ipoc: u64,
    },
    /// IPOC went backwards: the clock map restarts.
    IpocBackwards {
        /// The previous request's IPOC.
        last: u64,
        /// The (smaller) IPOC received.
        got: u64,
    },
    /// The controller counted more late answers.
    ControllerLate {
        /// The controller's new `<Delay>` count of late answers.
        delay: u64,
    },
    /// A plan became the target.
    PlanAccepted {
        /// The plan's sequence number.
        seq: u32,
        /// Whether the plan had to be clamped to fit the cell.
        clamped: bool,
        /// How late the stroke will reach the hitting pose (0 if on time).
        late_by: Duration,
    },
    /// A plan was refused.
    PlanRejected {
        /// The plan's sequence number.
        seq: u32,
        /// Why the generator refused it.
        reason: PlanRejected,
    },
    /// The safety filter changed a setpoint (first cycle of a run of them).
    SafetyClamped {
        /// The IPOC of the first clamped cycle.
        ipoc: u64,
    },
    /// Datagram in → answer sent took longer than the budget.
    SlowAnswer {
        /// Datagram in → answer sent.
        latency: Duration,
    },
    /// No request for `silence`.
    RobotSilent,
    /// The stroke moved to another phase.
    PhaseChanged(Phase),
}

/// Counters since construction.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SessionStats {
    /// `<Rob>` datagrams parsed.
    pub requests: u64,
    /// `<Sen>` answers written.
    pub answers: u64,
    /// Datagrams that were not a `<Rob>` (not answered).
    pub malformed: u64,
    /// Requests whose IPOC skipped cycles.
    pub ipoc_gaps: u64,
    /// Requests that repeated the previous IPOC.
    pub ipoc_repeats: u64,
    /// The controller's latest `<Delay>`.
    pub controller_delay: u64,
    /// Plans the generator took.
    pub plans_accepted: u64,
    /// Plans the generator refused.
    pub plans_rejected: u64,
    /// Cycles on which the safety filter changed the setpoint.
    pub safety_clamped: u64,
    /// Answers slower than the latency budget.
    pub slow_answers: u64,
    /// The slowest answer seen (datagram in → answer sent).
    pub max_latency: Duration,
    /// Events dropped because the queue was full.
    pub events_dropped: u64,
}

/// Why a datagram got no answer.
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SessionError {
    /// Not a `<Rob>` datagram; nothing to answer.
    #[error("malformed request: {0}")]
    Malformed(CodecError),
    /// The answer could not be written (buffer too small).
    #[error("cannot write answer: {0}")]
    Emit(CodecError),
}

/// Invalid session configuration.
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// SENTYPE or EStr is too long or contains characters RSI XML cannot
    /// carry unescaped.
    #[error("SENTYPE or EStr not usable in RSI XML")]
    BadText,
    /// `precision` exceeds the codec's maximum (9).
    #[error("precision above 9")]
    BadPrecision,
    /// `cycle_ms` is neither 4 nor 12.
    #[error("cycle must be 4 or 12 ms")]
    BadCycle,
}

/// The sans-IO RSI session (see the module doc).
#[derive(Debug)]
pub struct RsiSession {
    cfg: SessionConfig,
    generator: StrokeGenerator,
    safety: SafetyFilter,
    state: SessionState,
    start: Pose6,
    last_ipoc: u64,
    last_rx: Option<Instant>,
    last_correction: KukaPose,
    last_command: Pose6,
    /// The generator's joints at the last setpoint (for the feed-forward).
    last_joints: Joints,
    last_joints_valid: bool,
    last_phase: Phase,
    clamping: bool,
    pending: Option<StrikePlan>,
    clock_cur: i128,
    clock_prev: i128,
    clock_count: u32,
    events: Deque<SessionEvent, EVENT_CAPACITY>,
    stats: SessionStats,
}

const NS_PER_MS: i128 = 1_000_000;

impl RsiSession {
    /// A session waiting for the controller's first request.
    pub fn new(cfg: SessionConfig) -> Result<Self, ConfigError> {
        check_text(&cfg.sentype).map_err(|_| ConfigError::BadText)?;
        if let Some(e) = &cfg.estr {
            check_text(e).map_err(|_| ConfigError::BadText)?;
        }
        if cfg.precision > super::codec::MAX_PRECISION {
            return Err(ConfigError::BadPrecision);
        }
        if cfg.cycle_ms != 4 && cfg.cycle_ms != 12 {
            return Err(ConfigError::BadCycle);
        }
        let home = cfg.limits.home;
        Ok(RsiSession {
            generator: StrokeGenerator::new(cfg.limits.clone(), Instant(0), home),
            safety: SafetyFilter::new(&cfg.limits, home),
            cfg,
            state: SessionState::WaitingForRobot,
            start: home,
            last_ipoc: 0,
            last_rx: None,
            last_correction: KukaPose::default(),
            last_command: home,
            last_joints: Joints([0.0; 6]),
            last_joints_valid: false,
            last_phase: Phase::Hold,
            clamping: false,
            pending: None,
            clock_cur: i128::MAX,
            clock_prev: i128::MAX,
            clock_count: 0,
            events: Deque::new(),
            stats: SessionStats::default(),
        })
    }

    /// The latest plan; taken on the next request (a newer one replaces it).
    pub fn set_plan(&mut self, plan: StrikePlan) {
        self.pending = Some(plan);
    }

    /// Where the session stands.
    pub fn state(&self) -> SessionState {
        self.state
    }

    /// Counters since construction.
    pub fn stats(&self) -> &SessionStats {
        &self.stats
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &SessionConfig {
        &self.cfg
    }

    /// The pose at RSI start (B, m and rad).
    pub fn start_pose(&self) -> Pose6 {
        self.start
    }

    /// The last commanded pose (B, m and rad): where the bat is to be, within
    /// the cell's limits (the correction sent adds the lag's feed-forward).
    pub fn last_command(&self) -> Pose6 {
        self.last_command
    }

    /// The last RKorr sent (mm, degrees).
    pub fn last_correction(&self) -> KukaPose {
        self.last_correction
    }

    /// The stroke generator (phase, target, lateness).
    pub fn generator(&self) -> &StrokeGenerator {
        &self.generator
    }

    /// The oldest event not yet polled.
    pub fn poll_event(&mut self) -> Option<SessionEvent> {
        self.events.pop_front()
    }

    fn push(&mut self, e: SessionEvent) {
        if self.events.is_full() {
            self.events.pop_front();
            self.stats.events_dropped += 1;
        }
        let _ = self.events.push_back(e);
    }

    /// Handles one datagram received at `now`; writes the answer into
    /// `out` and returns its length.
    pub fn handle_datagram(&mut self, now: Instant, bytes: &[u8], out: &mut [u8]) -> Result<usize, SessionError> {
        let rob = match RobFrame::parse(bytes) {
            Ok(r) => r,
            Err(e) => {
                self.stats.malformed += 1;
                self.push(SessionEvent::Malformed(e));
                return Err(SessionError::Malformed(e));
            }
        };
        self.stats.requests += 1;
        self.last_rx = Some(now);
        let mut step = true;
        if self.state != SessionState::Running {
            self.begin(now, &rob);
        } else {
            let expected = self.last_ipoc.wrapping_add(self.cfg.cycle_ms as u64);
            if rob.ipoc == self.last_ipoc {
                self.stats.ipoc_repeats += 1;
                self.push(SessionEvent::IpocRepeated { ipoc: rob.ipoc });
                step = false;
            } else if rob.ipoc < self.last_ipoc {
                self.push(SessionEvent::IpocBackwards { last: self.last_ipoc, got: rob.ipoc });
                self.reset_clock();
            } else if rob.ipoc != expected {
                self.stats.ipoc_gaps += 1;
                self.push(SessionEvent::IpocGap { expected, got: rob.ipoc });
            }
        }
        if let Some(d) = rob.delay {
            if d > self.stats.controller_delay {
                self.push(SessionEvent::ControllerLate { delay: d });
            }
            self.stats.controller_delay = d;
        }
        self.last_ipoc = rob.ipoc;
        if step {
            let t = self.setpoint_time(now, rob.ipoc);
            self.take_plan();
            self.step(t, rob.ipoc);
        }
        let answer = SenFrame {
            sentype: &self.cfg.sentype,
            estr: self.cfg.estr.as_deref(),
            rkorr: Some(self.last_correction),
            ipoc: rob.ipoc,
        };
        let n = answer.emit(self.cfg.precision, out).map_err(SessionError::Emit)?;
        self.stats.answers += 1;
        Ok(n)
    }

    /// Tells the session its answer left at `now` (for latency tracking).
    pub fn answer_sent(&mut self, now: Instant) {
        if let Some(rx) = self.last_rx {
            let latency = now - rx;
            if latency > self.stats.max_latency {
                self.stats.max_latency = latency;
            }
            if latency > self.cfg.latency_budget {
                self.stats.slow_answers += 1;
                self.push(SessionEvent::SlowAnswer { latency });
            }
        }
    }

    /// Call when no datagram came for a while: notices a silent robot.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.state == SessionState::Running
            && let Some(rx) = self.last_rx
            && now - rx > self.cfg.silence
        {
            self.state = SessionState::Silent;
            self.push(SessionEvent::RobotSilent);
        }
    }

    fn begin(&mut self, now: Instant, rob: &RobFrame) {
        let home = self.cfg.limits.home;
        let mut off_home = false;
        self.start = match rob.rist {
            Some(p) => {
                let mut s = [p.x * 1e-3, p.y * 1e-3, p.z * 1e-3, p.a.to_radians(), p.b.to_radians(), p.c.to_radians()];
                for i in 3..6 {
                    s[i] = unwrap_near(s[i], home[i]);
                }
                off_home = (0..3).any(|i| (s[i] - home[i]).abs() > 0.005)
                    || (3..6).any(|i| (s[i] - home[i]).abs() > 1f64.to_radians());
                s
            }
            None => home,
        };
        self.reset_clock();
        let t = self.setpoint_time(now, rob.ipoc);
        // The first setpoint is one cycle after the generator's start.
        let t_start = Instant(t.0.saturating_sub(self.cfg.cycle_ms as u64 * 1_000_000));
        self.generator.reset(t_start, self.start);
        self.safety.reset(self.start);
        self.last_correction = KukaPose::default();
        self.last_command = self.start;
        self.last_joints_valid = false;
        self.clamping = false;
        self.state = SessionState::Running;
        self.push(SessionEvent::Started { ipoc: rob.ipoc, off_home });
    }

    fn reset_clock(&mut self) {
        self.clock_cur = i128::MAX;
        self.clock_prev = i128::MAX;
        self.clock_count = 0;
    }

    /// Our time at which the robot will be at the pose answered for `ipoc`.
    fn setpoint_time(&mut self, now: Instant, ipoc: u64) -> Instant {
        let robot_ns = ipoc as i128 * NS_PER_MS;
        let off = now.0 as i128 - robot_ns;
        self.clock_cur = self.clock_cur.min(off);
        self.clock_count += 1;
        if self.clock_count >= CLOCK_WINDOW_CYCLES {
            self.clock_prev = self.clock_cur;
            self.clock_cur = i128::MAX;
            self.clock_count = 0;
        }
        let off = self.clock_cur.min(self.clock_prev);
        let dead = if self.cfg.servo.enabled { self.cfg.servo.dead_time.0 } else { 0 };
        let t = robot_ns + off + self.cfg.lead.0 as i128 + dead as i128;
        Instant(t.clamp(0, u64::MAX as i128) as u64)
    }

    fn take_plan(&mut self) {
        if let Some(plan) = self.pending.take() {
            match self.generator.set_plan(&plan) {
                Ok(t) => {
                    let clamped = t.clamped;
                    let late_by = Duration((self.generator.late_by() * 1e9) as u64);
                    self.stats.plans_accepted += 1;
                    self.push(SessionEvent::PlanAccepted { seq: plan.seq, clamped, late_by });
                }
                Err(reason) => {
                    self.stats.plans_rejected += 1;
                    self.push(SessionEvent::PlanRejected { seq: plan.seq, reason });
                }
            }
        }
    }

    fn step(&mut self, t: Instant, ipoc: u64) {
        let desired = self.generator.next(t);
        let v_before = self.safety.velocity();
        let (cmd, changed) = self.safety.filter(&desired);
        if changed {
            self.stats.safety_clamped += 1;
            if !self.clamping {
                self.push(SessionEvent::SafetyClamped { ipoc });
            }
            let v = self.safety.velocity();
            let dt = self.cfg.limits.dt;
            let a = core::array::from_fn(|i| (v[i] - v_before[i]) / dt);
            self.generator.override_state(cmd, v, a);
        }
        self.clamping = changed;
        let phase = self.generator.phase();
        if phase != self.last_phase {
            self.last_phase = phase;
            self.push(SessionEvent::PhaseChanged(phase));
        }
        // The lag's feed-forward, in joint space where the drives lag (the
        // generator's joints; the Cartesian pose where the safety filter
        // changed the setpoint).
        let gain = self.cfg.servo.feed_forward_gain(self.cfg.limits.dt);
        let q = self.generator.joints();
        let sent: Pose6 = if gain > 0.0 && !changed && self.last_joints_valid {
            let lead = Joints(core::array::from_fn(|i| q.0[i] + gain * (q.0[i] - self.last_joints.0[i])));
            let p = self.cfg.limits.arm.tcp(&lead).to_pose6();
            core::array::from_fn(|i| if i < 3 { p[i] } else { unwrap_near(p[i], cmd[i]) })
        } else {
            core::array::from_fn(|i| cmd[i] + gain * (cmd[i] - self.last_command[i]))
        };
        self.last_joints = q;
        self.last_joints_valid = !changed;
        let mut k = [0.0; 6];
        for i in 0..3 {
            k[i] = (sent[i] - self.start[i]) * 1e3;
        }
        for i in 3..6 {
            let d = (sent[i] - self.start[i]).to_degrees();
            k[i] = d - (d / 360.0).round() * 360.0;
        }
        if k.iter().all(|x| x.is_finite()) {
            self.last_correction = KukaPose::from_array(k);
            self.last_command = cmd;
        }
    }
}
