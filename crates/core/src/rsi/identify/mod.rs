//! `topspin identify`, sans IO: answers the controller's requests with a
//! short, safe excitation and fits the robot's dead time and servo lag
//! from the `RIst` it reports.
//!
//! - [`excitation`]: the correction per cycle index (a few mm, one axis at
//!   a time, bounded speed and acceleration, zero at both ends).
//! - [`fit`]: the model x[n+1] = a·x\[n\] + (1 − a)·u[n − d] fitted by
//!   output-error least squares for each dead time d, τ = −T / ln a.
//! - [`Identifier`] (here): the protocol side, built like
//!   [`crate::rsi::session::RsiSession`]: one
//!   [`Identifier::handle_datagram`] per `<Rob>`, the `<Sen>` answer
//!   written into the caller's buffer, `now` passed in, no clock, no
//!   socket, no allocation after construction. IPOC rules are the
//!   session's: every well-formed request is answered, echoing its IPOC; a
//!   repeated IPOC gets the same correction again; only bytes that are not
//!   a `<Rob>` get no answer. Cycle n is (IPOC − first IPOC) / cycle.
//!
//! What the controller applied is rebuilt afterwards, cycle by cycle
//! ([`Identifier::trace`]): an answer the controller did not take (late,
//! or its request never reached us) leaves the previous correction in
//! place (HOLDON), and which answers were late is read from the `<Delay>`
//! counter the controller sends (its increase between two requests counts
//! the late cycles in between), or — where the SEND list lacks `<Delay>` —
//! from our own arrival times against the IPOC clock. Requests that arrive
//! out of order still give their RIst; their answers, which the controller
//! can no longer take, repeat the last correction and count for nothing.
//!
//! Every answer moves at most [`Excitation::max_step_mm`] from the one
//! before, so even after a gap the correction never jumps.

pub mod excitation;
pub mod fit;

pub use excitation::{AxisChoice, Excitation, ExcitationConfig, ExcitationError};
pub use fit::{ServoFit, ServoFitError, Trace};

use super::codec::{KukaPose, RobFrame, SenFrame, check_text};
use super::session::{ConfigError, SessionError};
use crate::calib::Calibration;
use crate::time::{Duration, Instant};

/// An IPOC this far past the last one means RSI was started again, s.
pub const RESTART_JUMP_S: f64 = 1.0;
/// The run must reach this share of the excitation's cycles.
pub const MIN_COVERAGE: f64 = 0.9;
/// At least this share of the cycles must bring a RIst.
pub const MIN_SEEN: f64 = 0.5;
/// RIst must move at least this share of the correction (RMS) on every
/// excited axis, or the robot did not move.
pub const MIN_MOTION_RATIO: f64 = 0.2;
/// The fitted gain from correction to RIst must lie within this range.
pub const GAIN_RANGE: (f64, f64) = (0.8, 1.25);
/// A fit below this (100 · (1 − ‖residual‖ / ‖RIst spread‖)) is refused, %.
pub const MIN_FIT_PERCENT: f64 = 80.0;
/// An arrival this close to the end of its cycle counts as late when the
/// controller does not send `<Delay>`.
pub const LATE_MARGIN: Duration = Duration(500_000);
/// A start pose farther than this from the calibrated home is reported, mm.
pub const OFF_HOME_MM: f64 = 5.0;

/// How the identifier is set up.
#[derive(Clone, Debug, PartialEq)]
pub struct IdentifierConfig {
    /// `Type` of `<Sen>`: SENTYPE of the Ethernet configuration.
    pub sentype: String,
    /// Optional `<EStr>` text.
    pub estr: Option<String>,
    /// Decimals of RKorr: `Precision` of the ETHERNET object.
    pub precision: u8,
    /// Sensor cycle, ms (4 or 12).
    pub cycle_ms: u32,
    /// The calibrated home (the RSI start pose), mm in BASE.
    pub home_mm: [f64; 3],
    /// The longest dead time fitted, cycles.
    pub max_dead_time_cycles: usize,
    /// The arm (tool included) `RIst` is checked against at the first
    /// request (`AIPos`'s forward kinematics), and the tolerance (mm,
    /// degrees) past which the run is refused: the KRL program's TOOL_DATA
    /// or BASE_DATA is not the calibration's.
    pub arm: crate::kinematics::Arm,
    /// See `arm`.
    pub frames_tolerance: (f64, f64),
}

impl IdentifierConfig {
    /// From the calibration, with SENTYPE `sentype`, 4 decimals and
    /// [`EStr`](SenFrame::estr) `topspin identify`.
    pub fn from_calibration(c: &Calibration, sentype: &str) -> Self {
        let cycle_ms = c.robot.rsi.cycle_ms;
        IdentifierConfig {
            sentype: sentype.to_owned(),
            estr: Some("topspin identify".to_owned()),
            precision: 4,
            cycle_ms,
            home_mm: c.robot.home.xyz_m.map(|x| x * 1e3),
            max_dead_time_cycles: (fit::MAX_DEAD_TIME_S * 1e3 / cycle_ms as f64).floor() as usize,
            arm: c.robot.arm(),
            frames_tolerance: (c.robot.start.frames_tolerance_mm, c.robot.start.frames_tolerance_deg),
        }
    }
}

/// Where the identifier stands.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum IdentifierState {
    /// No request yet: the next one sets the start pose and cycle 0.
    WaitingForRobot,
    /// Answering the excitation.
    Exciting,
    /// Past the excitation (or the robot sends no RIst): answering zero.
    Done,
}

/// Counters since the (last) start.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct IdentifierStats {
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
    /// Requests older than one already answered.
    pub stale: u64,
    /// Requests without `<RIst>`.
    pub no_rist: u64,
    /// RSI started again (IPOC backwards before the start, or far ahead).
    pub restarts: u64,
    /// Requests after the first in IPOC order.
    pub steps: u64,
    /// Of those, the ones whose IPOC step was not one cycle (gaps included).
    pub odd_steps: u64,
    /// The last such step, ms.
    pub last_odd_step_ms: u64,
    /// The slowest answer (datagram in → answer sent).
    pub max_latency: Duration,
}

/// One cycle of the log.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
struct Cycle {
    rist: Option<[f64; 3]>,
    sent: Option<[f64; 3]>,
    delay: Option<u64>,
    arrival: Option<Instant>,
}

/// The result of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Identification {
    /// The fitted model.
    pub fit: ServoFit,
    /// The sensor cycle, ms.
    pub cycle_ms: u32,
    /// Dead time beyond the one-cycle pipeline, ms (`[servo] dead_time_ms`).
    pub dead_time_ms: f64,
    /// Its standard deviation, ms.
    pub dead_time_std_ms: f64,
    /// The servo lag τ, ms (`[servo] lag_ms`).
    pub lag_ms: f64,
    /// Its standard deviation, ms.
    pub lag_std_ms: f64,
    /// Cycles from the first request to the last used.
    pub cycles: usize,
    /// Cycles that brought no RIst (IPOC gaps).
    pub gaps: usize,
    /// Cycles whose answer the controller did not apply (late or missing).
    pub late: usize,
    /// RMS of RIst about its mean during the quiet lead-in, mm.
    pub rist_noise_mm: f64,
    /// RIst at the first request, mm and degrees.
    pub start_pose: KukaPose,
    /// The start pose is more than [`OFF_HOME_MM`] from the calibrated home.
    pub off_home: bool,
    /// Counters of the run.
    pub stats: IdentifierStats,
}

/// Why a run gave no identification. Display is one line for the operator.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// No `<Rob>` was received.
    #[error("no request from the controller")]
    NoRequests,
    /// The requests carry no `<RIst>`.
    #[error("the controller's requests carry no <RIst>: add DEF_RIst to the SEND list of the Ethernet configuration")]
    NoRist,
    /// IPOC advanced by another step than the configured cycle.
    #[error(
        "IPOC advanced by {step_ms} ms per request, but rsi.cycle_ms is {cycle_ms}: set the cycle to the controller's"
    )]
    IpocStep {
        /// The step seen, ms.
        step_ms: u64,
        /// The configured cycle, ms.
        cycle_ms: u32,
    },
    /// `RIst` is not the forward kinematics of `AIPos` under the
    /// calibration: another TOOL_DATA or BASE_DATA (the robot was not moved).
    #[error("{0}")]
    Frames(crate::rsi::start::FramesMismatch),
    /// The controller stopped before the excitation was done.
    #[error("the controller stopped sending after {cycles} of {expected} cycles")]
    Truncated {
        /// Cycles covered.
        cycles: usize,
        /// Cycles of the excitation.
        expected: usize,
    },
    /// Too many cycles without a RIst.
    #[error("only {seen} of {cycles} cycles brought a RIst (lost requests)")]
    TooManyMissing {
        /// Cycles with a RIst.
        seen: usize,
        /// Cycles covered.
        cycles: usize,
    },
    /// RIst did not follow the correction on an axis.
    #[error(
        "the robot did not move on {axis}: RIst spanned {moved_mm:.3} mm for a {commanded_mm:.1} mm correction (drives off, override 0, or RSI not correcting)"
    )]
    DidNotMove {
        /// `x`, `y` or `z`.
        axis: char,
        /// Peak-to-peak of RIst, mm.
        moved_mm: f64,
        /// Peak-to-peak of the applied correction, mm.
        commanded_mm: f64,
    },
    /// The fit could not run.
    #[error("fit: {0}")]
    Fit(#[from] ServoFitError),
    /// RIst follows the correction with a gain far from one.
    #[error(
        "RIst follows the correction with gain {gain:.2} on {axis}: check that RIst and POSCORR use the same BASE (RefCorrSys) and TOOL"
    )]
    Gain {
        /// `x`, `y` or `z`.
        axis: char,
        /// The fitted gain.
        gain: f64,
    },
    /// The model does not describe the robot.
    #[error(
        "poor fit: {fit_percent:.1} % (rms {rms_mm:.3} mm); the robot does not follow a dead time and a first-order lag"
    )]
    PoorFit {
        /// 100 · (1 − ‖residual‖ / ‖spread‖).
        fit_percent: f64,
        /// RMS residual, mm.
        rms_mm: f64,
    },
    /// The best fit lies at the edge of the range searched.
    #[error("the {what} is at the end of the range searched ({value_ms:.0} ms): not identified")]
    AtRangeEdge {
        /// `dead time` or `lag`.
        what: &'static str,
        /// The value at the edge, ms.
        value_ms: f64,
    },
}

const AXIS_NAMES: [char; 3] = ['x', 'y', 'z'];

/// The protocol side of `topspin identify` (see the module doc).
#[derive(Debug)]
pub struct Identifier {
    cfg: IdentifierConfig,
    excitation: Excitation,
    state: IdentifierState,
    ipoc0: u64,
    last_n: u64,
    last_sent: [f64; 3],
    start: KukaPose,
    log: Vec<Cycle>,
    last_rx: Option<Instant>,
    stats: IdentifierStats,
    /// The first request's tool/base mismatch, if any (nothing moved).
    frames: Option<crate::rsi::start::FramesMismatch>,
}

impl Identifier {
    /// An identifier waiting for the controller's first request.
    pub fn new(cfg: IdentifierConfig, excitation: Excitation) -> Result<Self, ConfigError> {
        check_text(&cfg.sentype).map_err(|_| ConfigError::BadText)?;
        if let Some(e) = &cfg.estr {
            check_text(e).map_err(|_| ConfigError::BadText)?;
        }
        if cfg.precision > super::codec::MAX_PRECISION {
            return Err(ConfigError::BadPrecision);
        }
        if (cfg.cycle_ms != 4 && cfg.cycle_ms != 12) || cfg.cycle_ms != excitation.config().cycle_ms {
            return Err(ConfigError::BadCycle);
        }
        let log = vec![Cycle::default(); excitation.len()];
        Ok(Identifier {
            cfg,
            excitation,
            state: IdentifierState::WaitingForRobot,
            ipoc0: 0,
            last_n: 0,
            last_sent: [0.0; 3],
            start: KukaPose::default(),
            log,
            last_rx: None,
            stats: IdentifierStats::default(),
            frames: None,
        })
    }

    /// Where it stands.
    pub fn state(&self) -> IdentifierState {
        self.state
    }

    /// Counters since the (last) start.
    pub fn stats(&self) -> &IdentifierStats {
        &self.stats
    }

    /// The excitation it answers.
    pub fn excitation(&self) -> &Excitation {
        &self.excitation
    }

    /// The last correction answered, mm (x, y, z).
    pub fn last_correction(&self) -> [f64; 3] {
        self.last_sent
    }

    /// The cycle index of the newest request (0 before the first).
    pub fn cycle(&self) -> u64 {
        self.last_n
    }

    /// Handles one datagram received at `now`; writes the answer into
    /// `out` and returns its length.
    pub fn handle_datagram(&mut self, now: Instant, bytes: &[u8], out: &mut [u8]) -> Result<usize, SessionError> {
        let rob = match RobFrame::parse(bytes) {
            Ok(r) => r,
            Err(e) => {
                self.stats.malformed += 1;
                return Err(SessionError::Malformed(e));
            }
        };
        self.stats.requests += 1;
        self.last_rx = Some(now);
        let cycle = self.cfg.cycle_ms as u64;
        let restart_jump = (RESTART_JUMP_S * 1e3) as u64;
        let last_ipoc = self.ipoc0.wrapping_add(self.last_n * cycle);
        // A new RSI start during the excitation begins it again; after it,
        // nothing does.
        if self.state == IdentifierState::Exciting
            && (rob.ipoc < self.ipoc0 || rob.ipoc > last_ipoc.saturating_add(restart_jump))
        {
            self.stats.restarts += 1;
            self.state = IdentifierState::WaitingForRobot;
        }
        if rob.rist.is_none() {
            self.stats.no_rist += 1;
        }
        let n = rob.ipoc.checked_sub(self.ipoc0).map(|dt| (dt + cycle / 2) / cycle);
        let answer = if self.state == IdentifierState::WaitingForRobot {
            self.begin(now, &rob)
        } else if rob.ipoc == last_ipoc {
            self.stats.ipoc_repeats += 1;
            self.log_at(self.last_n).and_then(|c| c.sent).unwrap_or(self.last_sent)
        } else if let Some(n) = n.filter(|n| *n > self.last_n && rob.ipoc > last_ipoc) {
            let step = rob.ipoc - last_ipoc;
            self.stats.steps += 1;
            if step != cycle {
                self.stats.odd_steps += 1;
                self.stats.last_odd_step_ms = step;
            }
            if n > self.last_n + 1 {
                self.stats.ipoc_gaps += 1;
            }
            self.step(n, now, &rob)
        } else {
            // Older than one answered: its RIst still counts; its answer
            // cannot be taken any more and repeats the last correction.
            self.stats.stale += 1;
            if let Some(c) = n.and_then(|n| self.log_at_mut(n))
                && c.rist.is_none()
            {
                c.rist = rob.rist.map(|p| [p.x, p.y, p.z]);
                c.delay = rob.delay;
                c.arrival = Some(now);
            }
            self.last_sent
        };
        let frame = SenFrame {
            sentype: &self.cfg.sentype,
            estr: self.cfg.estr.as_deref(),
            rkorr: Some(KukaPose { x: answer[0], y: answer[1], z: answer[2], ..KukaPose::default() }),
            akorr: None,
            ipoc: rob.ipoc,
        };
        let len = frame.emit(self.cfg.precision, out).map_err(SessionError::Emit)?;
        self.stats.answers += 1;
        Ok(len)
    }

    /// Tells it the answer left at `now` (for the latency record).
    pub fn answer_sent(&mut self, now: Instant) {
        if let Some(rx) = self.last_rx {
            self.stats.max_latency = self.stats.max_latency.max(now - rx);
        }
    }

    fn log_at(&self, n: u64) -> Option<&Cycle> {
        usize::try_from(n).ok().and_then(|i| self.log.get(i))
    }

    fn log_at_mut(&mut self, n: u64) -> Option<&mut Cycle> {
        usize::try_from(n).ok().and_then(|i| self.log.get_mut(i))
    }

    fn begin(&mut self, now: Instant, rob: &RobFrame) -> [f64; 3] {
        self.ipoc0 = rob.ipoc;
        self.last_n = 0;
        self.last_sent = [0.0; 3];
        self.log.fill(Cycle::default());
        let restarts = self.stats.restarts;
        self.stats =
            IdentifierStats { restarts, requests: 1, no_rist: rob.rist.is_none() as u64, ..Default::default() };
        self.frames = None;
        match rob.rist {
            Some(p) => {
                self.start = p;
                self.state = IdentifierState::Exciting;
                // Another TOOL or BASE than the calibration: do not move.
                if let (Ok((pose, q)), (mm, deg)) =
                    (crate::rsi::start::read_start(&self.cfg.arm, Some(p), rob.aipos, None), self.cfg.frames_tolerance)
                    && let Some(m) = crate::rsi::start::check_frames(&self.cfg.arm, &pose, &q, mm, deg)
                {
                    self.frames = Some(m);
                    self.state = IdentifierState::Done;
                }
            }
            // Nothing to measure with: do not move the robot.
            None => self.state = IdentifierState::Done,
        }
        self.record(0, now, rob, [0.0; 3]);
        [0.0; 3]
    }

    fn step(&mut self, n: u64, now: Instant, rob: &RobFrame) -> [f64; 3] {
        self.last_n = n;
        if n as usize >= self.log.len() {
            self.state = IdentifierState::Done;
        }
        let target = if self.state == IdentifierState::Exciting { self.excitation.at(n) } else { [0.0; 3] };
        let max = self.excitation.max_step_mm();
        // As the controller will read it: at the answer's precision.
        let scale = 10f64.powi(self.cfg.precision as i32);
        let answer: [f64; 3] = core::array::from_fn(|i| {
            let x = self.last_sent[i] + (target[i] - self.last_sent[i]).clamp(-max, max);
            (x * scale).round() / scale
        });
        self.last_sent = answer;
        self.record(n, now, rob, answer);
        answer
    }

    fn record(&mut self, n: u64, now: Instant, rob: &RobFrame, sent: [f64; 3]) {
        if let Some(c) = self.log_at_mut(n) {
            *c = Cycle {
                rist: rob.rist.map(|p| [p.x, p.y, p.z]),
                sent: Some(sent),
                delay: rob.delay,
                arrival: Some(now),
            };
        }
    }

    /// Whether every cycle of the excitation has had its request.
    pub fn is_done(&self) -> bool {
        self.state == IdentifierState::Done
    }

    /// The corrections the controller applied and the RIst it reported
    /// (relative to the start pose), one entry per cycle from the first
    /// request to the newest one within the excitation; and how many of
    /// those cycles' answers the controller did not apply.
    pub fn trace(&self) -> (Trace, usize) {
        let cycles = if self.state == IdentifierState::WaitingForRobot {
            0
        } else {
            (self.last_n as usize + 1).min(self.log.len())
        };
        let log = &self.log[..cycles];
        let cycle_ns = self.cfg.cycle_ms as u64 * 1_000_000;
        // Our clock minus the IPOC clock, the fastest arrival.
        let offset = log
            .iter()
            .enumerate()
            .filter_map(|(n, c)| c.arrival.map(|a| a.0 as i128 - n as i128 * cycle_ns as i128))
            .min()
            .unwrap_or(0);
        let late_by_clock = |n: usize, c: &Cycle| {
            c.arrival.is_some_and(|a| {
                a.0 as i128 - n as i128 * cycle_ns as i128 - offset > (cycle_ns - LATE_MARGIN.0) as i128
            })
        };
        // The next cycle after n whose request brought a <Delay>.
        let mut next_delay = vec![None; cycles];
        let mut next: Option<usize> = None;
        for n in (0..cycles).rev() {
            next_delay[n] = next;
            if log[n].delay.is_some() {
                next = Some(n);
            }
        }
        let mut u = Vec::with_capacity(cycles);
        let mut applied = [0.0; 3];
        let mut late = 0;
        for n in 0..cycles {
            let c = &log[n];
            let accepted = match c.sent {
                None => false,
                Some(_) => match (c.delay, next_delay[n]) {
                    (Some(d0), Some(m)) => {
                        let d1 = log[m].delay.unwrap_or(d0);
                        // Cycles n+1..m were not answered in order: late.
                        let unanswered = (n + 1..m).filter(|k| log[*k].sent.is_none()).count() as u64;
                        d1.saturating_sub(d0) <= unanswered
                    }
                    _ => !late_by_clock(n, c),
                },
            };
            if accepted {
                applied = c.sent.unwrap_or(applied);
            } else {
                late += 1;
            }
            u.push(applied);
        }
        let s = [self.start.x, self.start.y, self.start.z];
        let y = log.iter().map(|c| c.rist.map(|p| [p[0] - s[0], p[1] - s[1], p[2] - s[2]])).collect();
        let trace = Trace { cycle_s: self.cfg.cycle_ms as f64 * 1e-3, u, y, excited: self.excitation.excited() };
        (trace, late)
    }

    /// Fits the run: the identification, or why there is none.
    pub fn finish(&self) -> Result<Identification, IdentifyError> {
        if self.state == IdentifierState::WaitingForRobot {
            return Err(IdentifyError::NoRequests);
        }
        if self.log.first().is_some_and(|c| c.rist.is_none()) {
            return Err(IdentifyError::NoRist);
        }
        if let Some(m) = self.frames {
            return Err(IdentifyError::Frames(m));
        }
        let (trace, late) = self.trace();
        let cycles = trace.u.len();
        if self.stats.odd_steps * 2 > self.stats.steps {
            return Err(IdentifyError::IpocStep { step_ms: self.stats.last_odd_step_ms, cycle_ms: self.cfg.cycle_ms });
        }
        let expected = self.excitation.len();
        if (cycles as f64) < MIN_COVERAGE * expected as f64 {
            return Err(IdentifyError::Truncated { cycles, expected });
        }
        let seen = trace.y.iter().filter(|y| y.is_some()).count();
        if (seen as f64) < MIN_SEEN * cycles as f64 {
            return Err(IdentifyError::TooManyMissing { seen, cycles });
        }
        for axis in (0..3).filter(|i| trace.excited[*i]) {
            let (u_ptp, u_rms) = spread(trace.u.iter().map(|v| v[axis]));
            let (y_ptp, y_rms) = spread(trace.y.iter().flatten().map(|v| v[axis]));
            if y_rms.is_nan() || y_rms < MIN_MOTION_RATIO * u_rms {
                return Err(IdentifyError::DidNotMove { axis: AXIS_NAMES[axis], moved_mm: y_ptp, commanded_mm: u_ptp });
            }
        }
        let f = fit::fit(&trace, self.cfg.max_dead_time_cycles)?;
        for (axis, g) in f.gain.iter().enumerate() {
            if let Some(g) = *g
                && !(GAIN_RANGE.0..=GAIN_RANGE.1).contains(&g)
            {
                return Err(IdentifyError::Gain { axis: AXIS_NAMES[axis], gain: g });
            }
        }
        if f.fit_percent.is_nan() || f.fit_percent < MIN_FIT_PERCENT {
            return Err(IdentifyError::PoorFit { fit_percent: f.fit_percent, rms_mm: f.rms_mm });
        }
        let cycle_ms = self.cfg.cycle_ms as f64;
        if f.dead_time_cycles + 1 == f.rss_by_dead_time.len() {
            return Err(IdentifyError::AtRangeEdge {
                what: "dead time",
                value_ms: f.dead_time_cycles as f64 * cycle_ms,
            });
        }
        if f.lag_s >= 0.99 * fit::MAX_LAG_S {
            return Err(IdentifyError::AtRangeEdge { what: "lag", value_ms: f.lag_s * 1e3 });
        }
        let lead_in = self.excitation.lead_in_cycles().min(cycles);
        let quiet: Vec<[f64; 3]> = trace.y[..lead_in].iter().flatten().copied().collect();
        let rist_noise_mm = if quiet.len() > 1 {
            let m: [f64; 3] = core::array::from_fn(|i| quiet.iter().map(|p| p[i]).sum::<f64>() / quiet.len() as f64);
            let ss: f64 = quiet.iter().map(|p| (0..3).map(|i| (p[i] - m[i]).powi(2)).sum::<f64>()).sum();
            (ss / (3 * quiet.len()) as f64).sqrt()
        } else {
            0.0
        };
        let s = [self.start.x, self.start.y, self.start.z];
        let off_home = (0..3).any(|i| (s[i] - self.cfg.home_mm[i]).abs() > OFF_HOME_MM);
        Ok(Identification {
            cycle_ms: self.cfg.cycle_ms,
            dead_time_ms: f.dead_time_cycles as f64 * cycle_ms,
            dead_time_std_ms: f.dead_time_std_cycles * cycle_ms,
            lag_ms: f.lag_s * 1e3,
            lag_std_ms: f.lag_std_s * 1e3,
            cycles,
            gaps: cycles - seen,
            late,
            rist_noise_mm,
            start_pose: self.start,
            off_home,
            stats: self.stats,
            fit: f,
        })
    }
}

/// Peak-to-peak and RMS about the mean.
fn spread(v: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let (mut lo, mut hi, mut s, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0.0);
    for x in v.clone() {
        lo = lo.min(x);
        hi = hi.max(x);
        s += x;
        n += 1.0;
    }
    if n == 0.0 {
        return (0.0, 0.0);
    }
    let m = s / n;
    let ss: f64 = v.map(|x| (x - m) * (x - m)).sum();
    (hi - lo, (ss / n).sqrt())
}

#[cfg(test)]
mod tests;
