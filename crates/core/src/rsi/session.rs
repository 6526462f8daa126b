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
//!
//! Where the arm stands at RSI start (and every restart) decides what the
//! session does ([`ArmMode`], `calib/robot.toml [start]`): within the
//! home tolerance it plays; else it goes home first on a PTP-like way at
//! the commissioning speed and rate (`motion::homing`), refusing plans
//! until the arm is home; where that way is unsafe, or `RIst` is not the
//! kinematics of `AIPos` under the calibration's tool and base
//! ([`super::start`]), or the pose is unusable, it holds with zero
//! corrections and says why once. Every cycle `RIst` is checked against
//! what the servo model predicts for the commands sent ([`super::follow`]):
//! an arm that stops following (brakes, an operator stop, a KSS error) ends
//! the stroke; the session holds, brings its command onto where the arm
//! stands (so that nothing jumps when the arm moves again) and, once the
//! arm has stood still for `still_s`, goes home at commissioning speed.
//!
//! Two corrections, as the controller's RSI context is built
//! ([`Correction`], `[rsi] correction`): Cartesian `<RKorr>` (POSCORR,
//! BASE; the controller's own inverse kinematics turns it into joints) or
//! axis `<AKorr>` (AXISCORR): the same fed-forward pose turned into joints
//! by our inverse kinematics, nearest the joints last sent (the first:
//! `AIPos` at RSI start), sent as those joints minus the joints at RSI
//! start, in degrees. A pose with no solution within the software limit
//! switches (or on the singular wrist) is never sent: the last correction
//! holds, counted (`axis_held`) and reported ([`SessionEvent::AxisHeld`]).

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use heapless::Deque;

use super::codec::{Axes, CodecError, KukaPose, RobFrame, SenFrame, check_text};
use super::follow::FollowMonitor;
use super::start::{StartRefused, Verdict, assess, from_home};
use crate::calib::Calibration;
use crate::calib::robot::StartPolicy;
use crate::geometry::{Pose6, unwrap_near};
use crate::kinematics::{Joints, Pose, Unreachable};
use crate::motion::generator::Phase;
use crate::motion::homing::{HomingLimits, HomingPath, WayHomeBlocked, correction};
use crate::motion::{MotionLimits, PlanRejected, SafetyFilter, StrokeGenerator};
use crate::plan::StrikePlan;
use crate::time::{Duration, Instant};

/// Events kept until polled; older ones are dropped (and counted) beyond.
pub(crate) const EVENT_CAPACITY: usize = 64;
/// Cycles per block of the IPOC → clock offset minimum filter.
pub(crate) const CLOCK_WINDOW_CYCLES: u32 = 1024;
/// The largest answer [`RsiSession::handle_datagram`] writes, bytes.
pub const MAX_ANSWER_LEN: usize = 512;

/// Which correction the session sends (`[rsi] correction`); it must match
/// the controller's RSI context (`rsi/topspin.rsi.xml` for Cartesian,
/// `rsi/topspin_axis.rsi.xml` for axis).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Correction {
    /// `<RKorr X Y Z A B C>`: commanded TCP pose − pose at RSI start (mm,
    /// degrees; POSCORR in BASE).
    #[default]
    Cartesian,
    /// `<AKorr A1..A6>`: commanded joints (our inverse kinematics) − joints
    /// at RSI start (degrees; AXISCORR).
    Axis,
}

impl Correction {
    /// Both, in the order of their keys.
    pub const ALL: [Correction; 2] = [Correction::Cartesian, Correction::Axis];

    /// The configuration's word: `cartesian` or `axis`.
    pub fn key(self) -> &'static str {
        match self {
            Correction::Cartesian => "cartesian",
            Correction::Axis => "axis",
        }
    }
}

impl core::fmt::Display for Correction {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.key())
    }
}

impl core::str::FromStr for Correction {
    type Err = UnknownCorrection;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Correction::ALL.into_iter().find(|c| c.key() == s).ok_or(UnknownCorrection)
    }
}

/// A correction name other than `cartesian` or `axis`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("not \"cartesian\" or \"axis\"")]
pub struct UnknownCorrection;

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
    /// Cartesian (`RKorr`) or axis (`AKorr`) correction.
    pub correction: Correction,
    /// Where the arm may start, the way home, and the follow check
    /// (`robot.toml [start]`).
    pub start: StartPolicy,
    /// What the way home must respect (speed, rate, box, POSCORR).
    pub homing: HomingLimits,
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
            correction: Correction::Cartesian,
            start: c.robot.start.clone(),
            homing: HomingLimits::from_robot(&c.robot),
        }
    }
}

/// What the session does with the arm (see the module doc).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum ArmMode {
    /// Home (or within its tolerance) and following: strokes are planned.
    Playing,
    /// On the way home at the commissioning speed; plans are refused.
    Homing,
    /// Held where it stands until RSI restarts: the start was refused.
    Held,
    /// The arm stopped following: the command is brought onto where it
    /// stands; once it stands still, the way home is tried.
    Stopped,
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
    /// A `<Rob>` with a value that cannot be read (left out; answered).
    BadValue(CodecError),
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
    /// The start cannot be used (or, after a stop, the way home is
    /// unsafe): the session holds, nothing moves until RSI restarts.
    StartRefused {
        /// Why.
        reason: StartRefused,
        /// How far the arm stands from home, mm …
        from_mm: f64,
        /// … and degrees.
        from_deg: f64,
    },
    /// The arm goes home at the commissioning speed.
    GoingHome {
        /// How far it stands from home, mm …
        from_mm: f64,
        /// … and degrees.
        from_deg: f64,
        /// How long the way takes.
        duration: Duration,
    },
    /// The arm is home and following: plans are taken.
    Home,
    /// `RIst` left the servo model's prediction for `follow_cycles` cycles:
    /// the arm stopped following.
    ArmStopped {
        /// The last error, mm …
        error_mm: f64,
        /// … and degrees.
        error_deg: f64,
        /// A stroke was under way (it is abandoned).
        stroke_abandoned: bool,
    },
    /// Axis mode: the commanded pose has no joint solution within the
    /// software limits (first cycle of a run of them); the last axis
    /// correction holds.
    AxisHeld {
        /// The IPOC of the first held cycle.
        ipoc: u64,
        /// Why there are no joints to send.
        reason: Unreachable,
    },
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
    /// Axis mode: cycles whose pose had no joints within the limits (the
    /// last correction held).
    pub axis_held: u64,
    /// Requests with a value that could not be read (answered without it).
    pub bad_values: u64,
    /// Starts refused (held until RSI restarts).
    pub starts_refused: u64,
    /// Ways home at the commissioning speed begun.
    pub ways_home: u64,
    /// Times the arm stopped following.
    pub arm_stops: u64,
    /// Strokes abandoned because the arm stopped following.
    pub strokes_abandoned: u64,
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
///
/// Build it from the calibration, feed it each `<Rob>` with the time it
/// arrived, and send the `<Sen>` it writes:
///
/// ```
/// use topspin_core::calib::Calibration;
/// use topspin_core::motion::MotionLimits;
/// use topspin_core::rsi::{KukaPose, RobElement, RobFrame, SenFrame};
/// use topspin_core::rsi::{RsiSession, SessionConfig};
/// use topspin_core::time::Instant;
///
/// let cal = Calibration::default_cell();
/// let mut session = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
///
/// // The controller's first request: the arm at home, IPOC 1000.
/// let home_joints = MotionLimits::from_robot(&cal.robot).home_joints.degrees();
/// let rob = RobFrame {
///     ipoc: 1000,
///     rist: Some(KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0])),
///     aipos: Some(home_joints),
///     ..Default::default()
/// };
/// let mut request = [0u8; 1024];
/// let n = rob.emit(&[RobElement::RIst, RobElement::AIPos], 4, &mut request).unwrap();
///
/// // The answer goes into our buffer; no clock, no socket.
/// let mut answer = [0u8; 1024];
/// let len = session.handle_datagram(Instant(1_000_000), &request[..n], &mut answer).unwrap();
/// let sen = SenFrame::parse(&answer[..len]).unwrap();
/// assert_eq!(sen.ipoc, 1000);
/// assert_eq!(sen.sentype, b"ImFree");
/// // Home, no plan: no correction.
/// assert_eq!(sen.rkorr.unwrap().to_array(), [0.0; 6]);
/// ```
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
    /// Axis mode: the joints at RSI start, the joints last sent, and the
    /// last AKorr (degrees).
    start_joints: Joints,
    last_sent_joints: Joints,
    last_axis_correction: Axes,
    holding: bool,
    last_command: Pose6,
    /// The generator's joints at the last setpoint (for the feed-forward).
    last_joints: Joints,
    last_joints_valid: bool,
    last_phase: Phase,
    clamping: bool,
    pending: Option<StrikePlan>,
    mode: ArmMode,
    homing: Option<HomingPath>,
    /// The way home's start pose as commanded, and the offset of that
    /// pose from the kinematics of the way's first joints (blended out
    /// along the way, so its first step is no jump).
    homing_offset: Pose6,
    follow: FollowMonitor,
    /// The joints of the correction sent last (feed-forward included).
    sent_joints: Joints,
    /// Stopped: the last `RIst` and how long the arm has stood still.
    last_rist: Pose6,
    still_cycles: u32,
    clock_cur: i128,
    clock_prev: i128,
    clock_count: u32,
    events: Deque<SessionEvent, EVENT_CAPACITY>,
    stats: SessionStats,
}

const NS_PER_MS: i128 = 1_000_000;
/// A stopped arm stands still when `RIst` moves less than this per cycle
/// (m, rad), and the command is on it within the same.
const STILL_M: f64 = 0.0002;
const STILL_RAD: f64 = 0.001;

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
        let home_joints = cfg.limits.home_joints;
        let dt = cfg.limits.dt;
        let alpha = if cfg.servo.lag_s > 0.0 { crate::calib::robot::lag_step(dt, cfg.servo.lag_s) } else { 1.0 };
        let dead = (cfg.servo.dead_time.as_secs_f64() / dt).round() as usize;
        let st = &cfg.start;
        let follow = FollowMonitor::new(
            alpha,
            dead,
            st.follow_tolerance_mm * 1e-3,
            st.follow_tolerance_deg.to_radians(),
            st.follow_cycles,
        );
        Ok(RsiSession {
            generator: StrokeGenerator::new(cfg.limits.clone(), Instant(0), home),
            safety: SafetyFilter::new(&cfg.limits, home),
            cfg,
            state: SessionState::WaitingForRobot,
            start: home,
            last_ipoc: 0,
            last_rx: None,
            last_correction: KukaPose::default(),
            start_joints: home_joints,
            last_sent_joints: home_joints,
            last_axis_correction: [0.0; 6],
            holding: false,
            last_command: home,
            last_joints: Joints([0.0; 6]),
            last_joints_valid: false,
            last_phase: Phase::Hold,
            clamping: false,
            pending: None,
            mode: ArmMode::Playing,
            homing: None,
            homing_offset: [0.0; 6],
            follow,
            sent_joints: home_joints,
            last_rist: home,
            still_cycles: 0,
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

    /// The last RKorr sent (mm, degrees; Cartesian mode).
    pub fn last_correction(&self) -> KukaPose {
        self.last_correction
    }

    /// The last AKorr sent (degrees; axis mode).
    pub fn last_axis_correction(&self) -> Axes {
        self.last_axis_correction
    }

    /// The joints at RSI start (rad): `AIPos` of the first request (axis
    /// mode; else, or without `AIPos`, the solution for the start pose
    /// nearest the calibrated home joints).
    pub fn start_joints(&self) -> Joints {
        self.start_joints
    }

    /// The joints last sent (rad; axis mode: start joints + AKorr).
    pub fn last_sent_joints(&self) -> Joints {
        self.last_sent_joints
    }

    /// What the session does with the arm.
    pub fn arm_mode(&self) -> ArmMode {
        self.mode
    }

    /// The follow check (its last and largest errors).
    pub fn follow_monitor(&self) -> &FollowMonitor {
        &self.follow
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
        let (rob, bad) = match RobFrame::parse_lenient(bytes) {
            Ok(r) => r,
            Err(e) => {
                self.stats.malformed += 1;
                self.push(SessionEvent::Malformed(e));
                return Err(SessionError::Malformed(e));
            }
        };
        self.stats.requests += 1;
        self.last_rx = Some(now);
        if let Some(e) = bad {
            // A value that cannot be read: the request is still answered.
            self.stats.bad_values += 1;
            self.push(SessionEvent::BadValue(e));
        }
        let mut step = true;
        let first = self.state != SessionState::Running;
        if first {
            self.begin(now, &rob, bad);
        } else {
            let expected = self.last_ipoc.wrapping_add(self.cfg.cycle_ms as u64);
            if rob.ipoc == self.last_ipoc {
                self.stats.ipoc_repeats += 1;
                self.push(SessionEvent::IpocRepeated { ipoc: rob.ipoc });
                step = false;
            } else if rob.ipoc < self.last_ipoc {
                self.push(SessionEvent::IpocBackwards { last: self.last_ipoc, got: rob.ipoc });
                self.reset_clock();
                self.resync_follow(&rob);
            } else if rob.ipoc != expected {
                self.stats.ipoc_gaps += 1;
                self.push(SessionEvent::IpocGap { expected, got: rob.ipoc });
                self.resync_follow(&rob);
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
            if !first && self.watch(&rob) {
                self.arm_stopped();
                self.step_stopped(t, &rob);
            } else {
                self.take_plan();
                match self.mode {
                    ArmMode::Playing => self.step(t, rob.ipoc),
                    ArmMode::Homing => self.step_homing(t),
                    ArmMode::Stopped => self.step_stopped(t, &rob),
                    ArmMode::Held => {}
                }
            }
            self.follow.commanded(&self.sent_joints);
        }
        let axis = self.cfg.correction == Correction::Axis;
        let answer = SenFrame {
            sentype: &self.cfg.sentype,
            estr: self.cfg.estr.as_deref(),
            rkorr: (!axis).then_some(self.last_correction),
            akorr: axis.then_some(self.last_axis_correction),
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

    fn begin(&mut self, now: Instant, rob: &RobFrame, bad: Option<CodecError>) {
        self.reset_clock();
        let t = self.setpoint_time(now, rob.ipoc);
        let c = &self.cfg;
        let start = assess(&c.limits, &c.start, &c.homing, rob.rist, rob.aipos, bad, t.as_secs_f64());
        self.start = start.pose;
        self.start_joints = start.joints;
        // The first setpoint is one cycle after the generator's start.
        let t_start = Instant(t.0.saturating_sub(self.cfg.cycle_ms as u64 * 1_000_000));
        self.generator.reset(t_start, self.start);
        self.safety.reset(self.start);
        self.last_sent_joints = self.start_joints;
        self.last_axis_correction = [0.0; 6];
        self.holding = false;
        self.last_correction = KukaPose::default();
        self.last_command = self.start;
        self.sent_joints = self.start_joints;
        self.last_joints_valid = false;
        self.clamping = false;
        self.homing = None;
        self.follow.reset(self.start_joints);
        self.fit_box();
        self.state = SessionState::Running;
        self.mode = ArmMode::Playing;
        let off_home = !self.cfg.start.is_home(start.from_mm, start.from_deg);
        self.push(SessionEvent::Started { ipoc: rob.ipoc, off_home });
        match start.verdict {
            Verdict::Refused(r) => self.refuse(r),
            Verdict::GoHome(path) => {
                let (q, p) = (self.start_joints, self.start);
                self.take_way_home(path, q, p);
            }
            Verdict::Home => self.push(SessionEvent::Home),
        }
    }

    /// The stroke box: the workspace within what POSCORR lets through from
    /// this start, per axis and in total (POSCORR's rotation and
    /// POSCORRMON's totals, as root sums of squares over the box's farthest
    /// corner; the box shrinks about the start until they hold). The same
    /// box when the start is home (`robot.toml` validates it).
    fn fit_box(&mut self) {
        let h = &self.cfg.homing;
        let (mut lo, mut hi) = (self.cfg.limits.lo, self.cfg.limits.hi);
        let s = self.start;
        for i in 0..3 {
            lo[i] = lo[i].max(s[i] + h.poscorr_lower_mm[i] * 1e-3);
            hi[i] = hi[i].min(s[i] + h.poscorr_upper_mm[i] * 1e-3).max(lo[i]);
        }
        // Translation (m) and rotation (rad) totals, 1 % inside the limits.
        let totals = [(0..3, h.mon_trans_mm * 1e-3), (3..6, h.poscorr_rot_deg.min(h.mon_rot_deg).to_radians())];
        for (axes, limit) in totals {
            let far = axes.clone().map(|i| (s[i] - lo[i]).abs().max((hi[i] - s[i]).abs()).powi(2)).sum::<f64>().sqrt();
            let k = 0.99 * limit / far;
            if far > 0.0 && k < 1.0 {
                for i in axes {
                    lo[i] = lo[i].max(s[i] - k * (s[i] - lo[i]).abs());
                    hi[i] = hi[i].min(s[i] + k * (hi[i] - s[i]).abs()).max(lo[i]);
                }
            }
        }
        self.generator.set_box(lo, hi);
        self.safety.set_box(lo, hi);
    }

    /// Holds where the arm stands, said once.
    fn refuse(&mut self, reason: StartRefused) {
        self.mode = ArmMode::Held;
        self.homing = None;
        self.stats.starts_refused += 1;
        let (from_mm, from_deg) = from_home(&self.cfg.limits, &self.last_command);
        self.push(SessionEvent::StartRefused { reason, from_mm, from_deg });
    }

    /// The way home from joints `q` (commanded pose `p`), starting at `t`;
    /// held where it is unsafe.
    fn go_home_from(&mut self, t: Instant, q: Joints, p: Pose6) {
        let c = &self.cfg;
        match HomingPath::plan(&c.limits.arm, &c.homing, &self.start, &q, &c.limits.home_joints, t.as_secs_f64()) {
            Ok(path) => self.take_way_home(path, q, p),
            Err(e) => self.refuse(StartRefused::WayHome(e)),
        }
    }

    /// Goes home on `path` from joints `q`, commanded at pose `p`.
    fn take_way_home(&mut self, path: HomingPath, q: Joints, p: Pose6) {
        let fk = self.cfg.limits.arm.tcp(&q).to_pose6();
        self.homing_offset =
            core::array::from_fn(|i| if i < 3 { p[i] - fk[i] } else { unwrap_near(p[i], fk[i]) - fk[i] });
        let (from_mm, from_deg) = from_home(&self.cfg.limits, &p);
        self.stats.ways_home += 1;
        self.push(SessionEvent::GoingHome { from_mm, from_deg, duration: Duration((path.duration() * 1e9) as u64) });
        self.homing = Some(path);
        self.mode = ArmMode::Homing;
        self.last_joints_valid = false;
    }

    /// One cycle of the way home: the path's joints (their pose, with the
    /// start's offset blended out) become the correction.
    fn step_homing(&mut self, t: Instant) {
        let Some(path) = self.homing else {
            self.mode = ArmMode::Held;
            return;
        };
        let ts = t.as_secs_f64();
        let q = path.joints_at(ts);
        let arm = &self.cfg.limits.arm;
        let fk = arm.tcp(&q).to_pose6();
        let s_left = 1.0 - path.progress(ts);
        let mut p: Pose6 = core::array::from_fn(|i| fk[i] + s_left * self.homing_offset[i]);
        for i in 3..6 {
            p[i] = unwrap_near(p[i], self.last_command[i]);
        }
        // The last line: no step beyond the commissioning speed and rate
        // (the way is planned within them; a step past them holds).
        let (d, a) = Pose::from_pose6(&p).distance(&Pose::from_pose6(&self.last_command));
        let dt = self.cfg.limits.dt;
        let h = &self.cfg.homing;
        if d > h.speed * dt * 1.01 + 1e-6 || a > h.rate * dt * 1.01 + 1e-6 {
            self.refuse(StartRefused::WayHome(WayHomeBlocked::StepTooLarge { mm: d * 1e3, deg: a.to_degrees() }));
            return;
        }
        self.safety.track(&p);
        match self.cfg.correction {
            Correction::Cartesian => self.cartesian_correction(&p, &p, q),
            Correction::Axis => self.send_joints(q, &p),
        }
        if path.done(ts) {
            self.play_from(t, self.cfg.limits.home);
        }
    }

    /// Home (or within its tolerance) at rest at `p`, at setpoint time `t`:
    /// the generator and the filter start from there, plans are taken.
    fn play_from(&mut self, t: Instant, p: Pose6) {
        let t_start = Instant(t.0.saturating_sub(self.cfg.cycle_ms as u64 * 1_000_000));
        self.generator.reset(t_start, p);
        self.safety.reset(p);
        self.last_command = p;
        self.last_joints_valid = false;
        self.mode = ArmMode::Playing;
        self.push(SessionEvent::Home);
    }

    /// Stopped: the command goes onto where the arm stands (at the
    /// commissioning speed and rate); once the arm has stood still for
    /// `still_s`, the way home from there.
    fn step_stopped(&mut self, t: Instant, rob: &RobFrame) {
        let Some(rist) = rob.rist.map(|k| self.pose_of(k)).filter(|p| p.iter().all(|x| x.is_finite())) else {
            return; // nothing to go by: hold
        };
        let dt = self.cfg.limits.dt;
        let h = &self.cfg.homing;
        let mut cmd = self.last_command;
        let gap = (0..3).map(|i| (rist[i] - cmd[i]).powi(2)).sum::<f64>().sqrt();
        let step = if gap > h.speed * dt { h.speed * dt / gap } else { 1.0 };
        for i in 0..3 {
            cmd[i] += step * (rist[i] - cmd[i]);
        }
        for i in 3..6 {
            let d = unwrap_near(rist[i], cmd[i]) - cmd[i];
            cmd[i] += d.clamp(-h.rate * dt, h.rate * dt);
        }
        // Through the filter: a command that was moving brakes within the
        // cell's limits before it turns onto the arm.
        let (cmd, _) = self.safety.filter(&cmd);
        match self.cfg.correction {
            Correction::Cartesian => {
                let arm = &self.cfg.limits.arm;
                let q = arm.inverse_near(&Pose::from_pose6(&cmd), &self.sent_joints).unwrap_or(self.sent_joints);
                self.cartesian_correction(&cmd, &cmd, q)
            }
            Correction::Axis => self.axis_correction(&cmd, &cmd, rob.ipoc),
        }
        let moved = (0..3).map(|i| (rist[i] - self.last_rist[i]).abs()).fold(0.0, f64::max);
        let turned =
            (3..6).map(|i| (unwrap_near(rist[i], self.last_rist[i]) - self.last_rist[i]).abs()).fold(0.0, f64::max);
        let on_arm = (0..3).all(|i| (rist[i] - cmd[i]).abs() < STILL_M)
            && (3..6).all(|i| (unwrap_near(rist[i], cmd[i]) - cmd[i]).abs() < STILL_RAD);
        self.last_rist = rist;
        if moved < STILL_M && turned < STILL_RAD && on_arm {
            self.still_cycles += 1;
        } else {
            self.still_cycles = 0;
        }
        if self.still_cycles as f64 * dt >= self.cfg.start.still_s {
            let q = self.arm_joints(rob, &self.last_sent_joints).unwrap_or(self.last_sent_joints);
            self.follow.resync(q);
            let (mm, deg) = from_home(&self.cfg.limits, &cmd);
            if self.cfg.start.is_home(mm, deg) { self.play_from(t, cmd) } else { self.go_home_from(t, q, cmd) }
        }
    }

    /// The arm's joints from a request: `AIPos`, else the solution for
    /// `RIst` nearest `near`; `None` when neither gives any.
    fn arm_joints(&self, rob: &RobFrame, near: &Joints) -> Option<Joints> {
        match (rob.aipos.map(Joints::from_degrees), rob.rist) {
            (Some(q), _) if q.0.iter().all(|x| x.is_finite()) => Some(q),
            (_, Some(k)) => self.cfg.limits.arm.inverse_near(&Pose::from_pose6(&self.pose_of(k)), near).ok(),
            _ => None,
        }
    }

    /// `RIst` in the session's units (m, rad; angles near the last command).
    fn pose_of(&self, k: KukaPose) -> Pose6 {
        let mut p = [k.x * 1e-3, k.y * 1e-3, k.z * 1e-3, k.a.to_radians(), k.b.to_radians(), k.c.to_radians()];
        for i in 3..6 {
            p[i] = unwrap_near(p[i], self.last_command[i]);
        }
        p
    }

    /// Does the arm follow? True when it stopped (checked while playing or
    /// going home: the way home with a third of the tolerance).
    fn watch(&mut self, rob: &RobFrame) -> bool {
        let scale = match self.mode {
            ArmMode::Playing => 1.0,
            ArmMode::Homing => 1.0 / 3.0,
            ArmMode::Held | ArmMode::Stopped => return false,
        };
        let Some(k) = rob.rist else { return false };
        let p = Pose::from_pose6(&self.pose_of(k));
        self.follow.observe(&p, &self.cfg.limits.arm, scale)
    }

    /// The model restarts from the arm's pose (cycles were missed).
    fn resync_follow(&mut self, rob: &RobFrame) {
        if let Some(q) = self.arm_joints(rob, &self.follow.predicted()) {
            self.follow.resync(q);
        }
    }

    /// The arm stopped following: the stroke ends, the last command holds.
    fn arm_stopped(&mut self) {
        let abandoned = self.mode == ArmMode::Playing && self.generator.phase() != Phase::Hold;
        self.stats.arm_stops += 1;
        if abandoned {
            self.stats.strokes_abandoned += 1;
        }
        let (e, a) = self.follow.error;
        self.push(SessionEvent::ArmStopped {
            error_mm: e * 1e3,
            error_deg: a.to_degrees(),
            stroke_abandoned: abandoned,
        });
        self.mode = ArmMode::Stopped;
        self.homing = None;
        self.still_cycles = 0;
        self.last_rist = [f64::NAN; 6];
    }

    /// Axis mode: joints `q` (pose `p`) sent as they are.
    fn send_joints(&mut self, q: Joints, p: &Pose6) {
        let start = self.start_joints;
        let a: Axes = core::array::from_fn(|i| (q.0[i] - start.0[i]).to_degrees());
        if a.iter().all(|x| x.is_finite()) {
            self.last_sent_joints = q;
            self.last_axis_correction = a;
            self.last_command = *p;
            self.sent_joints = q;
        }
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
            if self.mode != ArmMode::Playing {
                self.stats.plans_rejected += 1;
                self.push(SessionEvent::PlanRejected { seq: plan.seq, reason: PlanRejected::NotHome });
                return;
            }
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
        // generator's joints). Where the safety filter changed the setpoint
        // the generator took the filtered pose's joints: still joint space
        // while those are the filtered pose (a switch to Cartesian and back
        // is a step the gain rings into the axes); the Cartesian pose only
        // where they are not (no joints for it).
        let gain = self.cfg.servo.feed_forward_gain(self.cfg.limits.dt);
        let q = self.generator.joints();
        let consistent = !changed || {
            let p = self.cfg.limits.arm.tcp(&q).to_pose6();
            (0..3).all(|i| (p[i] - cmd[i]).abs() < 1e-6)
        };
        let (sent, sent_joints): (Pose6, Option<Joints>) = if gain > 0.0 && consistent && self.last_joints_valid {
            let lead = Joints(core::array::from_fn(|i| q.0[i] + gain * (q.0[i] - self.last_joints.0[i])));
            // At rest the lead is the setpoint itself: its pose is known.
            let p = if lead == q { self.generator.pose() } else { self.cfg.limits.arm.tcp(&lead).to_pose6() };
            (core::array::from_fn(|i| if i < 3 { p[i] } else { unwrap_near(p[i], cmd[i]) }), Some(lead))
        } else {
            let sent = core::array::from_fn(|i| cmd[i] + gain * (cmd[i] - self.last_command[i]));
            (sent, (gain == 0.0 && consistent).then_some(q))
        };
        self.last_joints = q;
        self.last_joints_valid = consistent;
        match self.cfg.correction {
            Correction::Cartesian => {
                let arm = &self.cfg.limits.arm;
                let qs = sent_joints.unwrap_or_else(|| arm.inverse_near(&Pose::from_pose6(&sent), &q).unwrap_or(q));
                self.cartesian_correction(&sent, &cmd, qs)
            }
            Correction::Axis => self.axis_correction(&sent, &cmd, ipoc),
        }
    }

    /// RKorr: `sent` − the start pose, mm and degrees (angles within ±180°).
    fn cartesian_correction(&mut self, sent: &Pose6, cmd: &Pose6, q: Joints) {
        let k = correction(&self.start, sent);
        if k.iter().all(|x| x.is_finite()) {
            self.last_correction = KukaPose::from_array(k);
            self.last_command = *cmd;
            self.sent_joints = q;
        }
    }

    /// AKorr: the joints of `sent` nearest the joints last sent, within the
    /// software limits and off the singular wrist, − the start joints, in
    /// degrees; else the last AKorr holds (counted, reported).
    fn axis_correction(&mut self, sent: &Pose6, cmd: &Pose6, ipoc: u64) {
        let arm = &self.cfg.limits.arm;
        let joints = arm
            .inverse_near(&Pose::from_pose6(sent), &self.last_sent_joints)
            .and_then(|q| arm.limits.check_position(&q).map(|()| q).map_err(Unreachable::Limit));
        let start = self.start_joints;
        let sendable = joints.and_then(|q| {
            let a: Axes = core::array::from_fn(|i| (q.0[i] - start.0[i]).to_degrees());
            if a.iter().all(|x| x.is_finite()) { Ok((q, a)) } else { Err(Unreachable::OutOfReach) }
        });
        match sendable {
            Ok((q, a)) => {
                self.last_sent_joints = q;
                self.last_axis_correction = a;
                self.last_command = *cmd;
                self.sent_joints = q;
                self.holding = false;
            }
            Err(reason) => {
                self.stats.axis_held += 1;
                if !self.holding {
                    self.push(SessionEvent::AxisHeld { ipoc, reason });
                }
                self.holding = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::EulerZyx;
    use crate::kinematics::{Axis, LimitKind};
    use crate::physics::Vec3;
    use crate::rsi::codec::{RobElement, SenView};

    const T0: u64 = 1_000_000_000;
    const CYCLE_NS: u64 = 4_000_000;

    fn cal() -> Calibration {
        Calibration::default_cell()
    }

    fn session(correction: Correction) -> RsiSession {
        let mut cfg = SessionConfig::from_calibration(&cal(), "ImFree");
        cfg.correction = correction;
        RsiSession::new(cfg).unwrap()
    }

    /// The calibrated home pose in KUKA units and its joints in degrees.
    fn home() -> (KukaPose, Axes) {
        let lim = MotionLimits::from_robot(&cal().robot);
        let h = lim.home;
        let p = [h[0] * 1e3, h[1] * 1e3, h[2] * 1e3, h[3].to_degrees(), h[4].to_degrees(), h[5].to_degrees()];
        (KukaPose::from_array(p), lim.home_joints.degrees())
    }

    /// Request k of a run (IPOC 100 + 4k at T0 + 4 ms·k), answered.
    fn cycle(s: &mut RsiSession, k: u64, rist: KukaPose, aipos: Option<Axes>) -> (Option<KukaPose>, Option<Axes>) {
        let mut req = [0u8; 1024];
        let mut out = [0u8; MAX_ANSWER_LEN];
        let elements = [RobElement::RIst, RobElement::AIPos, RobElement::Delay];
        let rob = RobFrame { ipoc: 100 + 4 * k, rist: Some(rist), aipos, delay: Some(0), ..RobFrame::default() };
        let n = rob.emit(&elements, 4, &mut req).unwrap();
        let m = s.handle_datagram(Instant(T0 + k * CYCLE_NS), &req[..n], &mut out).unwrap();
        let v: SenView = SenFrame::parse(&out[..m]).unwrap();
        assert_eq!(v.ipoc, 100 + 4 * k);
        (v.rkorr, v.akorr)
    }

    fn plan(seq: u32, k: u64) -> StrikePlan {
        StrikePlan {
            seq,
            trajectory: 1,
            made_at: Instant(T0 + k * CYCLE_NS),
            hit_time: Instant(T0 + 100 * CYCLE_NS),
            position: Vec3::new(1.6, 0.2, 0.3),
            velocity: Vec3::new(-1.0, 0.0, 0.1),
            orientation: EulerZyx { a: 0.1, b: 0.3, c: 0.0 },
            spin: Vec3::zeros(),
            confidence: 1.0,
        }
    }

    #[test]
    fn the_correction_names_parse_and_default_to_cartesian() {
        assert_eq!("axis".parse(), Ok(Correction::Axis));
        assert_eq!("cartesian".parse(), Ok(Correction::Cartesian));
        assert_eq!("Axis".parse::<Correction>(), Err(UnknownCorrection));
        assert_eq!("".parse::<Correction>(), Err(UnknownCorrection));
        assert_eq!(Correction::Axis.to_string(), "axis");
        assert_eq!(SessionConfig::from_calibration(&cal(), "ImFree").correction, Correction::Cartesian);
    }

    #[test]
    fn each_mode_answers_its_own_correction_only() {
        let (rist, aipos) = home();
        let mut c = session(Correction::Cartesian);
        let (r, a) = cycle(&mut c, 0, rist, Some(aipos));
        assert_eq!((r, a), (Some(KukaPose::default()), None));
        let mut s = session(Correction::Axis);
        let (r, a) = cycle(&mut s, 0, rist, Some(aipos));
        assert_eq!((r, a), (None, Some([0.0; 6])));
        // At rest at home the joints sent are the start joints: AKorr stays zero.
        for k in 1..50 {
            assert_eq!(cycle(&mut s, k, rist, Some(aipos)), (None, Some([0.0; 6])), "cycle {k}");
        }
        assert_eq!(s.stats().axis_held, 0);
    }

    #[test]
    fn the_start_joints_are_aipos_at_the_first_request() {
        let (rist, aipos) = home();
        // The controller's own joints, a little off our solution for RIst:
        // the correction is from where the robot says it stands.
        let mut off = aipos;
        off[0] += 0.25;
        off[5] -= 0.5;
        let mut s = session(Correction::Axis);
        let (_, a) = cycle(&mut s, 0, rist, Some(off));
        // (AIPos as sent: 4 decimals of a degree.)
        assert!(s.start_joints().max_abs_diff(&Joints::from_degrees(off)) <= 0.5e-4f64.to_radians() + 1e-12);
        // The first answer brings the axes to our joints for the home pose
        // (the generator holds home): AKorr = home joints − AIPos, to the
        // 4 decimals sent and AIPos's rounding.
        let a = a.unwrap();
        let expect = [-0.25, 0.0, 0.0, 0.0, 0.0, 0.5];
        assert!(a.iter().zip(expect).all(|(x, e)| (x - e).abs() <= 1e-4 + 1e-12), "{a:?}");
        // Without AIPos in the SEND list: held (the tool and base cannot be
        // checked), zero corrections, the start joints the solution for
        // RIst nearest home.
        let mut s = session(Correction::Axis);
        let (_, a) = cycle(&mut s, 0, rist, None);
        assert_eq!(a, Some([0.0; 6]));
        assert!(s.start_joints().max_abs_diff(&Joints::from_degrees(aipos)) < 1e-6);
    }

    #[test]
    fn a_stroke_is_sent_as_the_joints_of_the_cartesian_correction() {
        // The same stroke in both modes: the joints sent in axis mode are the
        // joints of the pose sent in Cartesian mode, and AKorr their offset
        // from the start joints.
        let (rist, aipos) = home();
        let arm = MotionLimits::from_robot(&cal().robot).arm;
        let mut c = session(Correction::Cartesian);
        let mut s = session(Correction::Axis);
        let mut moved = 0.0f64;
        for k in 0..90 {
            if k % 5 == 1 {
                c.set_plan(plan(k as u32, k));
                s.set_plan(plan(k as u32, k));
            }
            let (r, _) = cycle(&mut c, k, rist, Some(aipos));
            let (_, a) = cycle(&mut s, k, rist, Some(aipos));
            let (r, a) = (r.unwrap().to_array(), a.unwrap());
            let q = s.last_sent_joints();
            for i in 0..6 {
                let expect = (q.0[i] - s.start_joints().0[i]).to_degrees();
                assert_eq!((a[i] * 1e4).round(), (expect * 1e4).round(), "cycle {k} A{}", i + 1);
            }
            // FK of the joints sent = the Cartesian pose sent (RKorr + start).
            let p = arm.tcp(&q).to_pose6();
            let start = c.start_pose();
            for i in 0..3 {
                assert!((p[i] * 1e3 - (start[i] * 1e3 + r[i])).abs() < 2e-4, "cycle {k} axis {i}");
            }
            moved = moved.max(a.iter().fold(0.0f64, |m, x| m.max(x.abs())));
            assert_eq!(c.last_command(), s.last_command(), "cycle {k}: the same commanded pose");
        }
        assert!(moved > 5.0, "the stroke moved the axes ({moved:.2}° at most)");
        assert_eq!((s.stats().plans_accepted, s.stats().axis_held), (c.stats().plans_accepted, 0));
    }

    #[test]
    fn a_pose_without_joints_is_held_counted_and_reported() {
        let (rist, aipos) = home();
        let mut s = session(Correction::Axis);
        for k in 0..3 {
            cycle(&mut s, k, rist, Some(aipos));
        }
        while s.poll_event().is_some() {}
        let before = (s.last_axis_correction(), s.last_sent_joints(), s.last_command());
        // Out of reach: 3 m in front of the robot.
        let far = [3.0, 0.0, 0.4, 0.0, 0.0, 0.0];
        s.axis_correction(&far, &far, 77);
        s.axis_correction(&far, &far, 81);
        assert_eq!(s.stats().axis_held, 2);
        assert_eq!(s.poll_event(), Some(SessionEvent::AxisHeld { ipoc: 77, reason: Unreachable::OutOfReach }));
        assert_eq!(s.poll_event(), None, "one event per run of held cycles");
        assert_eq!((s.last_axis_correction(), s.last_sent_joints(), s.last_command()), before);
        // The singular wrist: a pose whose nearest joints have A5 = 0.5°.
        let arm = MotionLimits::from_robot(&cal().robot).arm;
        let mut q = Joints::from_degrees(aipos);
        q.0[4] = 0.5f64.to_radians();
        let singular = arm.tcp(&q).to_pose6();
        s.axis_correction(&singular, &singular, 85);
        assert_eq!(s.stats().axis_held, 3);
        assert_eq!(s.poll_event(), None, "still the same run");
        // A reachable pose ends the run; the next unreachable one starts another.
        let mut q = Joints::from_degrees(aipos);
        q.0[0] += 0.01;
        let near = arm.tcp(&q).to_pose6();
        s.axis_correction(&near, &near, 89);
        assert_eq!(s.stats().axis_held, 3);
        assert!(s.last_sent_joints().max_abs_diff(&q) < 1e-9);
        assert_eq!((s.last_axis_correction()[0] * 1e6).round(), (0.01f64.to_degrees() * 1e6).round());
        s.axis_correction(&singular, &singular, 93);
        let Some(SessionEvent::AxisHeld { ipoc: 93, reason: Unreachable::Limit(v) }) = s.poll_event() else {
            panic!("no AxisHeld for the singular wrist")
        };
        assert_eq!((v.axis, v.kind), (Axis::A5, LimitKind::SingularWrist));
        // The answer carries the held correction.
        let held = s.last_axis_correction();
        assert!(held[0] > 0.5);
        let (_, a) = cycle(&mut s, 3, rist, Some(aipos));
        assert!(a.is_some());
    }

    /// The first request of a run with these RIst and AIPos (written as
    /// Rust prints them: NaN, inf); the events.
    fn start_with(rist: Option<[f64; 6]>, aipos: Option<Axes>) -> (RsiSession, Vec<SessionEvent>, Option<KukaPose>) {
        let mut s = session(Correction::Cartesian);
        let mut out = [0u8; MAX_ANSWER_LEN];
        let mut req = String::from("<Rob Type=\"KUKA\">");
        if let Some(r) = rist {
            req += &format!(
                "<RIst X=\"{}\" Y=\"{}\" Z=\"{}\" A=\"{}\" B=\"{}\" C=\"{}\"/>",
                r[0], r[1], r[2], r[3], r[4], r[5]
            );
        }
        if let Some(a) = aipos {
            req += &format!(
                "<AIPos A1=\"{}\" A2=\"{}\" A3=\"{}\" A4=\"{}\" A5=\"{}\" A6=\"{}\"/>",
                a[0], a[1], a[2], a[3], a[4], a[5]
            );
        }
        req += "<IPOC>100</IPOC></Rob>";
        let m = s.handle_datagram(Instant(T0), req.as_bytes(), &mut out).unwrap();
        let rkorr = SenFrame::parse(&out[..m]).unwrap().rkorr;
        let mut ev = Vec::new();
        while let Some(e) = s.poll_event() {
            ev.push(e);
        }
        (s, ev, rkorr)
    }

    fn refusal(ev: &[SessionEvent]) -> Option<StartRefused> {
        ev.iter().find_map(|e| match e {
            SessionEvent::StartRefused { reason, .. } => Some(*reason),
            _ => None,
        })
    }

    #[test]
    fn an_unusable_start_is_answered_held_and_named() {
        let (rist, aipos) = home();
        let r = rist.to_array();
        // Non-finite RIst, non-finite AIPos, AIPos past A1's limit, no RIst.
        let mut nan = r;
        nan[2] = f64::NAN;
        let mut inf = aipos;
        inf[3] = f64::INFINITY;
        let mut past = aipos;
        past[0] = 175.0;
        for (rist, aipos, key) in [
            (Some(nan), Some(aipos), "unreadable"),
            (Some(r), Some(inf), "unreadable"),
            (Some(r), Some(past), "joint_limit"),
            (None, Some(aipos), "missing"),
        ] {
            let (mut s, ev, rkorr) = start_with(rist, aipos);
            assert_eq!(rkorr, Some(KukaPose::default()), "answered with zero corrections");
            assert_eq!(refusal(&ev).map(|r| r.key()), Some(key), "{ev:?}");
            assert_eq!(s.arm_mode(), ArmMode::Held);
            // Later requests: still zero, no more refusals, plans refused.
            s.set_plan(plan(1, 1));
            for k in 1..20 {
                let (rk, _) = cycle(&mut s, k, home().0, Some(home().1));
                assert_eq!(rk, Some(KukaPose::default()), "cycle {k}");
            }
            let mut later = Vec::new();
            while let Some(e) = s.poll_event() {
                later.push(e);
            }
            assert_eq!(refusal(&later), None, "said once");
            assert!(later.contains(&SessionEvent::PlanRejected { seq: 1, reason: PlanRejected::NotHome }));
            assert_eq!(s.stats().starts_refused, 1);
            assert_eq!(s.stats().bad_values, (key == "unreadable") as u64, "counted");
        }
    }

    #[test]
    fn the_pose_of_the_design_example_is_refused_as_another_tool() {
        // DESIGN §5.3's example: RIst {445, 0, 900, 0, 90, 0} with AIPos
        // {0, -90, 90, 0, 0, 0}. Under calib/robot.toml's bat those joints
        // put the TCP 280 mm further out: RIst is near the wrist, not the
        // bat (another TOOL_DATA).
        let rist = [445.0, 0.0, 900.0, 0.0, 90.0, 0.0];
        let (_, ev, rkorr) = start_with(Some(rist), Some([0.0, -90.0, 90.0, 0.0, 0.0, 0.0]));
        assert_eq!(rkorr, Some(KukaPose::default()));
        let Some(StartRefused::Frames(m)) = refusal(&ev) else { panic!("{ev:?}") };
        assert!(m.mm > 200.0, "{m:?}");
        assert_eq!(m.likely, crate::rsi::start::LikelyFrame::Tool);
        // Without AIPos nothing can be checked: held, naming what is missing.
        let (_, ev, rkorr) = start_with(Some(rist), None);
        assert_eq!(rkorr, Some(KukaPose::default()));
        assert_eq!(refusal(&ev), Some(StartRefused::Missing("AIPos")), "{ev:?}");
    }
}
