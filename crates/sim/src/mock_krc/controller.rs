//! The controller model, sans-IO: one [`MockController::request`] per cycle,
//! answers offered with [`MockController::answer`], and
//! [`MockController::end_cycle`] at the cycle's deadline.
//!
//! Units are KUKA's (mm, degrees). The correction passes POSCORR (per-axis
//! translation limits, one total rotation limit) and POSCORRMON (total
//! translation/rotation: exceeding it stops RSI). The commanded pose then
//! goes through the KR 6 R900's inverse kinematics (the solution nearest
//! the last commanded joints: the configuration stays continuous) and the
//! software limit switches; it reaches the drives after the dead time
//! (whole cycles) and each axis follows it with a first-order lag
//! (`AIPos`); the actual TCP (`RIst`) is the forward kinematics of the
//! actual joints. A late cycle keeps the last correction (HOLDON).
//!
//! It stops as a KR C4 does, naming the reason ([`StopReason`]): a
//! commanded pose out of reach or past a software limit switch, a wrist
//! through its singularity, an axis turning or accelerating beyond its
//! limits (checked on the actual joints: what the drives and gears must
//! deliver, so a command that jumps, e.g. HOLDON mid-stroke, stops the
//! robot through the lag as "command gear torque" does), POSCORRMON, or
//! too many late answers. After a stop the robot stands and RSI sends
//! nothing more.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use std::collections::VecDeque;
use std::fmt;

use topspin_core::kinematics::{AXES, Arm, Joints, LimitKind, LimitViolation, Pose, Unreachable};
use topspin_core::motion::limits::unwrap_near;
use topspin_core::rsi::codec::{CodecError, KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::time::Instant;

/// The longest dead time the mock models, cycles.
pub const MAX_DEAD_TIME_CYCLES: usize = 32;

/// A pose in KUKA's units (mm, degrees A/B/C) as a kinematics pose (m, rad).
fn kuka_pose(p: &[f64; 6]) -> Pose {
    Pose::from_xyz_abc([p[0], p[1], p[2]].map(|x| x * 1e-3), [p[3], p[4], p[5]].map(f64::to_radians))
}

/// How RKorr is applied.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CorrMode {
    /// RKorr = commanded pose − pose at RSI start.
    Absolute,
    /// RKorr = increment added each cycle.
    Relative,
}

/// Why RSI stopped.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum StopReason {
    /// More late answers than the Timeout allows.
    LateLimit,
    /// POSCORRMON: total correction too large.
    Monitor,
    /// The commanded pose has no joint solution (out of the arm's reach).
    OutOfReach,
    /// A commanded or actual axis broke a limit: software limit switch,
    /// singular wrist, axis speed, or acceleration ("command gear
    /// torque").
    Axis(LimitViolation),
}

impl StopReason {
    /// A short key for counting stops by reason (`late_limit`, `monitor`,
    /// `out_of_reach`, `software_limit_a3`, `singular_wrist`,
    /// `speed_a1`, `gear_torque_a2`).
    pub fn key(&self) -> String {
        match self {
            StopReason::LateLimit => "late_limit".into(),
            StopReason::Monitor => "monitor".into(),
            StopReason::OutOfReach => "out_of_reach".into(),
            StopReason::Axis(v) => {
                let axis = v.axis.to_string().to_lowercase();
                match v.kind {
                    LimitKind::Position => format!("software_limit_{axis}"),
                    LimitKind::SingularWrist => "singular_wrist".into(),
                    LimitKind::Speed => format!("speed_{axis}"),
                    LimitKind::Acceleration => format!("gear_torque_{axis}"),
                }
            }
        }
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StopReason::LateLimit => write!(f, "RSI timeout: too many late answers"),
            StopReason::Monitor => write!(f, "correction monitor (POSCORRMON)"),
            StopReason::OutOfReach => write!(f, "commanded pose out of the arm's reach"),
            StopReason::Axis(v) if v.kind == LimitKind::Acceleration => write!(f, "command gear torque: {v}"),
            StopReason::Axis(v) => write!(f, "{v}"),
        }
    }
}

/// What became of an offered answer.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Right IPOC and type: this cycle's correction.
    Accepted,
    /// An IPOC other than this cycle's (stale, duplicate or invented).
    WrongIpoc,
    /// `Type` other than SENTYPE.
    WrongType,
    /// Not a `<Sen>` datagram.
    Malformed(CodecError),
    /// This cycle already has its answer.
    Extra,
}

/// The controller's fixed setup.
#[derive(Clone, Debug, PartialEq)]
pub struct ControllerConfig {
    pub cycle_ms: u32,
    pub mode: CorrMode,
    pub sentype: String,
    pub precision: u8,
    pub send: Vec<RobElement>,
    /// Late answers before RSI stops.
    pub late_limit: u64,
    /// The pose at RSI start (mm, deg, BASE).
    pub start: [f64; 6],
    /// The joints at RSI start (the solution for `start` the robot stands
    /// in).
    pub start_joints: Joints,
    /// The arm: kinematics and axis limits.
    pub arm: Arm,
    /// Whole cycles between the correction's cycle and the drives
    /// (`calib/robot.toml` `[servo]`).
    pub dead_time_cycles: u32,
    /// First-order lag time constant per axis, s (0: none).
    pub lag_s: f64,
    /// Stop on an axis over its speed or acceleration limit ("command
    /// gear torque"); off: such cycles are counted (`rates_over`).
    pub stop_on_axis_rates: bool,
    /// POSCORR and POSCORRMON.
    pub lower_mm: [f64; 3],
    pub upper_mm: [f64; 3],
    pub max_rot_deg: f64,
    pub mon_max_trans_mm: f64,
    pub mon_max_rot_deg: f64,
    /// First IPOC.
    pub first_ipoc: u64,
}

/// One cycle of the logged TCP path.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PathSample {
    /// When the robot is at `actual`.
    pub t: Instant,
    pub ipoc: u64,
    /// Commanded pose after POSCORR (mm, deg, BASE).
    pub commanded: [f64; 6],
    /// Where the robot is: the forward kinematics of `joints`.
    pub actual: [f64; 6],
    /// The actual joints (`AIPos`), degrees.
    pub joints: [f64; 6],
    /// This cycle's answer came on time.
    pub on_time: bool,
}

/// The controller (see the module doc).
#[derive(Clone, Debug)]
pub struct MockController {
    cfg: ControllerConfig,
    ipoc: u64,
    correction: [f64; 6],
    commanded: [f64; 6],
    actual: [f64; 6],
    /// Commanded joints (`ASPos`), rad, and the dead-time line: the
    /// commands of the last `dead_time_cycles` cycles, oldest first.
    q_cmd: Joints,
    line: VecDeque<Joints>,
    /// Actual joints, their speed and acceleration (rad, /s, /s²).
    q_act: Joints,
    qd_act: [f64; AXES],
    /// Fraction of the gap the lag closes per cycle.
    lag_step: f64,
    answered: Option<[f64; 6]>,
    pub late: u64,
    pub wrong_ipoc: u64,
    pub wrong_type: u64,
    pub malformed: u64,
    pub poscorr_clamped: u64,
    pub cycles: u64,
    /// The fastest any axis turned, as a share of its limit (its peak).
    pub peak_speed_share: f64,
    /// The hardest any axis accelerated, as a share of its limit.
    pub peak_acceleration_share: f64,
    /// Cycles with an axis over its speed or acceleration limit (not
    /// stopped: `stop_on_axis_rates` off).
    pub rates_over: u64,
    pub stopped: Option<StopReason>,
}

impl MockController {
    /// A controller at its start pose. Panics if the dead time exceeds
    /// [`MAX_DEAD_TIME_CYCLES`] (configurations are checked before).
    pub fn new(cfg: ControllerConfig) -> Self {
        assert!((cfg.dead_time_cycles as usize) < MAX_DEAD_TIME_CYCLES, "dead time too long");
        // The joints of the start pose: the solution nearest `start_joints`
        // (a robot restarted off home stands where it stopped).
        let q0 = cfg.arm.inverse_near(&kuka_pose(&cfg.start), &cfg.start_joints).unwrap_or(cfg.start_joints);
        let line = VecDeque::from(vec![q0; cfg.dead_time_cycles as usize]);
        let dt = cfg.cycle_ms as f64 * 1e-3;
        let lag_step = topspin_core::calib::robot::lag_step(dt, cfg.lag_s);
        MockController {
            ipoc: cfg.first_ipoc,
            correction: [0.0; 6],
            commanded: cfg.start,
            actual: cfg.start,
            q_cmd: q0,
            line,
            q_act: q0,
            qd_act: [0.0; AXES],
            lag_step,
            answered: None,
            late: 0,
            wrong_ipoc: 0,
            wrong_type: 0,
            malformed: 0,
            poscorr_clamped: 0,
            cycles: 0,
            peak_speed_share: 0.0,
            peak_acceleration_share: 0.0,
            rates_over: 0,
            stopped: None,
            cfg,
        }
    }

    /// The actual joints, rad.
    pub fn joints(&self) -> Joints {
        self.q_act
    }

    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    pub fn ipoc(&self) -> u64 {
        self.ipoc
    }

    pub fn actual(&self) -> [f64; 6] {
        self.actual
    }

    /// Writes this cycle's `<Rob>` into `buf`.
    pub fn request(&self, buf: &mut [u8]) -> Result<usize, CodecError> {
        let pose = KukaPose::from_array(self.actual);
        RobFrame {
            ipoc: self.ipoc,
            rist: Some(pose),
            rsol: Some(KukaPose::from_array(self.commanded)),
            aipos: Some(self.q_act.degrees()),
            aspos: Some(self.q_cmd.degrees()),
            delay: Some(self.late),
        }
        .emit(&self.cfg.send, self.cfg.precision, buf)
    }

    /// Moves the robot by something other than RSI (its program or the
    /// jog keys, as for touching a point while RSI answers zero): the pose
    /// RSI corrects from becomes `start` (mm, degrees), and the axes go
    /// there through the dead time and the lag.
    pub fn move_start(&mut self, start: [f64; 6]) {
        self.cfg.start = start;
    }

    /// Offers an answer received before this cycle's deadline.
    pub fn answer(&mut self, bytes: &[u8]) -> Verdict {
        let sen = match SenFrame::parse(bytes) {
            Ok(s) => s,
            Err(e) => {
                self.malformed += 1;
                return Verdict::Malformed(e);
            }
        };
        if sen.ipoc != self.ipoc {
            self.wrong_ipoc += 1;
            return Verdict::WrongIpoc;
        }
        if sen.sentype != self.cfg.sentype.as_bytes() {
            self.wrong_type += 1;
            return Verdict::WrongType;
        }
        if self.answered.is_some() {
            return Verdict::Extra;
        }
        // No RKorr in the answer: the correction holds (HOLDON).
        self.answered = Some(sen.rkorr.map(KukaPose::to_array).unwrap_or(self.correction));
        Verdict::Accepted
    }

    /// Closes the cycle at its deadline: counts a missing answer as late,
    /// applies the correction, moves the robot one cycle (unless it
    /// stopped) and advances IPOC. Returns the path sample at the start of
    /// the next cycle.
    pub(crate) fn end_cycle(&mut self, next_t: Instant) -> PathSample {
        let on_time = self.answered.is_some();
        match self.answered.take() {
            Some(k) => match self.cfg.mode {
                CorrMode::Absolute => self.correction = k,
                CorrMode::Relative => {
                    for i in 0..6 {
                        self.correction[i] += k[i];
                    }
                }
            },
            None => {
                self.late += 1;
                if self.late >= self.cfg.late_limit {
                    self.stopped = Some(StopReason::LateLimit);
                }
            }
        }
        if self.stopped.is_none() {
            self.apply_poscorr();
        }
        if self.stopped.is_none() {
            self.command_joints();
        }
        if self.stopped.is_none() {
            self.follow();
        }
        self.cycles += 1;
        self.ipoc += self.cfg.cycle_ms as u64;
        PathSample {
            t: next_t,
            ipoc: self.ipoc,
            commanded: self.commanded,
            actual: self.actual,
            joints: self.q_act.degrees(),
            on_time,
        }
    }

    fn apply_poscorr(&mut self) {
        let c = &self.cfg;
        let mut k = self.correction;
        let mut clamped = false;
        for (i, x) in k.iter_mut().enumerate() {
            if !x.is_finite() {
                *x = 0.0;
                clamped = true;
            }
            if i < 3 {
                let y = x.clamp(c.lower_mm[i], c.upper_mm[i]);
                clamped |= y != *x;
                *x = y;
            }
        }
        let rot = (k[3] * k[3] + k[4] * k[4] + k[5] * k[5]).sqrt();
        if rot > c.max_rot_deg {
            for x in &mut k[3..] {
                *x *= c.max_rot_deg / rot;
            }
            clamped = true;
        }
        if clamped {
            self.poscorr_clamped += 1;
        }
        let trans = (k[0] * k[0] + k[1] * k[1] + k[2] * k[2]).sqrt();
        let rot = (k[3] * k[3] + k[4] * k[4] + k[5] * k[5]).sqrt();
        if trans > c.mon_max_trans_mm || rot > c.mon_max_rot_deg {
            self.stopped = Some(StopReason::Monitor);
        }
        for i in 0..6 {
            self.commanded[i] = c.start[i] + k[i];
        }
    }

    /// The commanded pose to joints: the solution nearest the last
    /// commanded joints, within the software limit switches and off the
    /// singular wrist; else the robot stops.
    fn command_joints(&mut self) {
        match self.cfg.arm.inverse_near(&kuka_pose(&self.commanded), &self.q_cmd) {
            Ok(q) => match self.cfg.arm.limits.check_position(&q) {
                Ok(()) => self.q_cmd = q,
                Err(v) => self.stopped = Some(StopReason::Axis(v)),
            },
            Err(Unreachable::OutOfReach) => self.stopped = Some(StopReason::OutOfReach),
            Err(Unreachable::Limit(v)) => self.stopped = Some(StopReason::Axis(v)),
        }
    }

    /// One cycle of the axes: the command from `dead_time_cycles` ago
    /// reaches the drives, each axis closes `lag_step` of its gap, and the
    /// actual speed and acceleration are checked against the limits.
    fn follow(&mut self) {
        let dt = self.cfg.cycle_ms as f64 * 1e-3;
        let target = if self.cfg.dead_time_cycles == 0 {
            self.q_cmd
        } else {
            let oldest = self.line.pop_front().unwrap_or(self.q_cmd);
            self.line.push_back(self.q_cmd); // one out, one in: no allocation
            oldest
        };
        let mut q = self.q_act;
        let mut qd = [0.0; AXES];
        let mut qdd = [0.0; AXES];
        let lim = &self.cfg.arm.limits;
        for i in 0..AXES {
            q.0[i] += self.lag_step * (target.0[i] - q.0[i]);
            qd[i] = (q.0[i] - self.q_act.0[i]) / dt;
            qdd[i] = (qd[i] - self.qd_act[i]) / dt;
            self.peak_speed_share = self.peak_speed_share.max(qd[i].abs() / lim.speed[i]);
            self.peak_acceleration_share = self.peak_acceleration_share.max(qdd[i].abs() / lim.acceleration[i]);
        }
        let checked = if self.cfg.stop_on_axis_rates {
            self.cfg.arm.check(&q, &qd, &qdd)
        } else {
            self.cfg.arm.limits.check_position(&q)
        };
        if let Err(v) = checked {
            self.stopped = Some(StopReason::Axis(v));
            return;
        }
        if (0..AXES).any(|i| qd[i].abs() > lim.speed[i] || qdd[i].abs() > lim.acceleration[i]) {
            self.rates_over += 1;
        }
        self.q_act = q;
        self.qd_act = qd;
        let tcp = self.cfg.arm.tcp(&q);
        let p = tcp.to_pose6();
        for i in 0..3 {
            self.actual[i] = p[i] * 1e3;
        }
        for i in 3..6 {
            self.actual[i] = unwrap_near(p[i], self.actual[i].to_radians()).to_degrees();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mock_krc::MockKrcConfig;

    /// Holds a 0.05 mm correction on x from the first cycle; the actual x
    /// after each cycle, relative to the start, in units of the correction.
    fn response(dead_time_cycles: u32, lag_s: f64, cycles: usize) -> Vec<f64> {
        let mut cfg = MockKrcConfig::default_cell().unwrap().controller;
        cfg.dead_time_cycles = dead_time_cycles;
        cfg.lag_s = lag_s;
        let x0 = cfg.start[0];
        let mut c = MockController::new(cfg);
        (0..cycles)
            .map(|k| {
                c.answered = Some([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]);
                ((c.end_cycle(Instant(k as u64 * 4_000_000)).actual[0] - x0) / 0.05 * 1e6).round() / 1e6
            })
            .collect()
    }

    #[test]
    fn the_ideal_robot_is_there_one_cycle_later() {
        assert_eq!(response(0, 0.0, 3), vec![1.0, 1.0, 1.0]);
    }

    #[test]
    fn dead_time_delays_by_whole_cycles() {
        assert_eq!(response(3, 0.0, 6), vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn the_axes_close_their_share_of_the_gap_each_cycle() {
        // Per axis in joint space; over 0.05 mm the forward kinematics is
        // linear to 1e-6 of the step.
        let r = response(2, 0.015, 6);
        let step = 1.0 - (-0.004f64 / 0.015).exp();
        let expect =
            [0.0, 0.0, step, 1.0 - (1.0 - step).powi(2), 1.0 - (1.0 - step).powi(3), 1.0 - (1.0 - step).powi(4)];
        for (k, (a, b)) in r.iter().zip(expect).enumerate() {
            assert!((a - b).abs() < 1e-5, "cycle {k}: {a} vs {b}");
        }
    }

    #[test]
    fn a_moved_start_is_followed_with_no_correction() {
        let mut cfg = MockKrcConfig::default_cell().unwrap().controller;
        cfg.dead_time_cycles = 0;
        cfg.lag_s = 0.0;
        let mut to = cfg.start;
        to[0] += 0.05;
        let mut c = MockController::new(cfg);
        c.move_start(to);
        c.answered = Some([0.0; 6]);
        let got = c.end_cycle(Instant(4_000_000)).actual;
        assert!(got.iter().zip(&to).all(|(a, b)| (a - b).abs() < 1e-9), "{got:?} {to:?}");
    }

    #[test]
    fn it_stops_naming_the_axis_limit_it_broke() {
        let cfg = MockKrcConfig::default_cell().unwrap().controller;
        // Out of reach: 2 m in front of the robot.
        let mut c = MockController::new(cfg.clone());
        c.answered = Some([2000.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let mut far = cfg.clone();
        far.lower_mm = [-5000.0; 3];
        far.upper_mm = [5000.0; 3];
        far.mon_max_trans_mm = 1e6;
        let mut c2 = MockController::new(far.clone());
        c2.answered = Some([2000.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        c2.end_cycle(Instant(4_000_000));
        assert_eq!(c2.stopped, Some(StopReason::OutOfReach));
        // A jump of 10 cm in one cycle: the axes over their speed.
        let mut rates = far.clone();
        rates.stop_on_axis_rates = true;
        rates.lag_s = 0.0;
        rates.dead_time_cycles = 0;
        let mut c3 = MockController::new(rates);
        c3.answered = Some([0.0, 100.0, 0.0, 0.0, 0.0, 0.0]);
        c3.end_cycle(Instant(4_000_000));
        let Some(StopReason::Axis(v)) = c3.stopped else { panic!("{:?}", c3.stopped) };
        assert_eq!(v.kind, LimitKind::Speed);
        assert!(StopReason::Axis(v).key().starts_with("speed_a"));
        // Counted, not stopped, with the rate stop off.
        far.lag_s = 0.0;
        far.dead_time_cycles = 0;
        let mut c4 = MockController::new(far);
        c4.answered = Some([0.0, 100.0, 0.0, 0.0, 0.0, 0.0]);
        c4.end_cycle(Instant(4_000_000));
        assert_eq!((c4.stopped, c4.rates_over), (None, 1));
        drop(c);
    }
}
