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
//! With an axis context (`ControllerConfig::correction` = axis) it takes
//! `<AKorr A1..A6>` instead (degrees, #ABSOLUTE: from the joints at RSI
//! start): AXISCORR clamps each axis's correction to its limits (counted,
//! `axiscorr_clamped`), AXISCORRMON stops RSI when a clamped total exceeds
//! its maximum, and the commanded joints go through the software limit
//! switches, the dead time and the lag as above; `RSol` is their forward
//! kinematics. An answer that carries only the other correction (RKorr to
//! an axis context, AKorr to a Cartesian one) is on time but the context
//! finds none of its RECEIVE tags in it: every correction holds (HOLDON),
//! as for an answer with no correction at all, and it is counted
//! (`wrong_kind`).
//!
//! The program around RSI may run other frames than the sensor's
//! calibration: `ControllerConfig::base` is its BASE_DATA (poses, `RIst`
//! and the commanded pose, are in that frame), and the arm's tool its
//! TOOL_DATA. Brakes ([`Brakes`]: an operator stop, the enabling switch,
//! the load check) hold the axes where they are for a while, as RSI goes
//! on; when they open, the drives take up the command from where the axes
//! stand, through the lag, and a command far from them stops the robot
//! through the gear-torque check.
//!
//! It stops as a KR C4 does, naming the reason ([`StopReason`]): a
//! commanded pose out of reach or past a software limit switch, a wrist
//! through its singularity, an axis turning or accelerating beyond its
//! limits (checked on the actual joints: what the drives and gears must
//! deliver, so a command that jumps, e.g. HOLDON mid-stroke, stops the
//! robot through the lag as "command gear torque" does), POSCORRMON,
//! AXISCORRMON, or too many late answers. After a stop the robot stands and RSI sends
//! nothing more.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use std::collections::VecDeque;
use std::fmt;

use topspin_core::geometry::unwrap_near;
use topspin_core::kinematics::{AXES, Arm, Axis, Joints, LimitKind, LimitViolation, Pose, Unreachable};
use topspin_core::rsi::Correction;
use topspin_core::rsi::{CodecError, KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::time::Instant;

/// The longest dead time the mock models, cycles.
pub(crate) const MAX_DEAD_TIME_CYCLES: usize = 32;

/// Brakes applied at a cycle for a number of cycles.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Brakes {
    /// The first braked cycle (0: the first cycle of the run).
    pub at_cycle: u64,
    /// How many cycles they hold.
    pub cycles: u64,
}

impl Brakes {
    fn hold(&self, cycle: u64) -> bool {
        cycle >= self.at_cycle && cycle - self.at_cycle < self.cycles
    }
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
    /// AXISCORRMON: this axis's total correction too large.
    AxisMonitor(Axis),
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
    /// `speed_a1`, `gear_torque_a2`, `axis_monitor_a4`).
    pub fn key(&self) -> String {
        match self {
            StopReason::LateLimit => "late_limit".into(),
            StopReason::Monitor => "monitor".into(),
            StopReason::AxisMonitor(a) => format!("axis_monitor_{}", a.to_string().to_lowercase()),
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
            StopReason::AxisMonitor(a) => write!(f, "axis correction monitor (AXISCORRMON): {a}"),
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
    /// The RSI cycle, ms (4 or 12).
    pub cycle_ms: u32,
    /// How RKorr is applied (#ABSOLUTE or #RELATIVE).
    pub mode: CorrMode,
    /// Which correction the RSI context takes: RKorr (POSCORR) or AKorr
    /// (AXISCORR).
    pub correction: Correction,
    /// The sensor type an answer must carry as `Type` (SENTYPE).
    pub sentype: String,
    /// Decimals of the numbers in `<Rob>` (ETHERNET `Precision`).
    pub precision: u8,
    /// The elements `<Rob>` carries, in the SEND list's order.
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
    /// POSCORR: upper translation limits x, y, z, mm.
    pub upper_mm: [f64; 3],
    /// POSCORR: one total rotation limit, deg.
    pub max_rot_deg: f64,
    /// POSCORRMON: total translation that stops RSI, mm.
    pub mon_max_trans_mm: f64,
    /// POSCORRMON: total rotation that stops RSI, deg.
    pub mon_max_rot_deg: f64,
    /// AXISCORR (per-axis correction limits, degrees) and AXISCORRMON
    /// (|total| per axis that stops RSI, degrees).
    pub axis_lower_deg: [f64; 6],
    /// AXISCORR: upper correction limit per axis A1..A6, degrees.
    pub axis_upper_deg: [f64; 6],
    /// AXISCORRMON: |total correction| per axis A1..A6 that stops RSI, degrees.
    pub axis_mon_max_deg: [f64; 6],
    /// First IPOC.
    pub first_ipoc: u64,
    /// The program's BASE_DATA relative to the robot's foot ($ROBROOT):
    /// the frame of `RIst`, `RSol`, `start` and the commanded pose.
    pub base: Pose,
    /// Brakes applied during the run, if any.
    pub brakes: Option<Brakes>,
}

impl ControllerConfig {
    /// The arm standing at joints `q` (rad) at RSI start: `start` is their
    /// TCP in `base`.
    pub fn stand_at(&mut self, q: Joints) {
        self.start = KukaPose::from_pose(&self.base.inverse().compose(&self.arm.tcp(&q))).to_array();
        self.start_joints = q;
    }
}

/// One cycle of the logged TCP path.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PathSample {
    /// When the robot is at `actual`.
    pub t: Instant,
    /// The IPOC of the cycle starting at `t`.
    pub ipoc: u64,
    /// Commanded pose after POSCORR (mm, deg, BASE); with AXISCORR the
    /// forward kinematics of the commanded joints.
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
    /// The commanded joints at RSI start (AKorr's zero).
    q_start: Joints,
    /// Actual joints, their speed and acceleration (rad, /s, /s²).
    q_act: Joints,
    qd_act: [f64; AXES],
    /// Fraction of the gap the lag closes per cycle.
    lag_step: f64,
    answered: Option<[f64; 6]>,
    /// Cycles without a valid answer by the deadline (sent as `<Delay>`).
    pub late: u64,
    /// Answers refused for an IPOC other than the cycle's.
    pub wrong_ipoc: u64,
    /// Answers refused for a `Type` other than SENTYPE.
    pub wrong_type: u64,
    /// Datagrams that did not parse as `<Sen>`.
    pub malformed: u64,
    /// Cycles whose RKorr POSCORR clamped (a non-finite component counts, set to 0).
    pub poscorr_clamped: u64,
    /// Cycles whose AKorr AXISCORR clamped.
    pub axiscorr_clamped: u64,
    /// On-time answers with only the other kind of correction (held).
    pub wrong_kind: u64,
    /// The smallest and largest AKorr asked per axis (before AXISCORR),
    /// degrees: the range the axis context's limits must cover.
    pub akorr_range_deg: [[f64; 2]; 6],
    /// Cycles closed.
    pub cycles: u64,
    /// The fastest any axis turned, as a share of its limit (its peak).
    pub peak_speed_share: f64,
    /// The hardest any axis accelerated, as a share of its limit.
    pub peak_acceleration_share: f64,
    /// Cycles with an axis over its speed or acceleration limit (not
    /// stopped: `stop_on_axis_rates` off).
    pub rates_over: u64,
    /// Cycles the brakes held the axes.
    pub braked_cycles: u64,
    /// Why RSI stopped (`None`: it runs).
    pub stopped: Option<StopReason>,
}

impl MockController {
    /// A controller at its start pose. Panics if the dead time exceeds
    /// `MAX_DEAD_TIME_CYCLES` (configurations are checked before).
    pub fn new(cfg: ControllerConfig) -> Self {
        assert!((cfg.dead_time_cycles as usize) < MAX_DEAD_TIME_CYCLES, "dead time too long");
        // The joints of the start pose: the solution nearest `start_joints`
        // (a robot restarted off home stands where it stopped).
        let q0 = cfg
            .arm
            .inverse_near(&cfg.base.compose(&KukaPose::from_array(cfg.start).to_pose()), &cfg.start_joints)
            .unwrap_or(cfg.start_joints);
        let line = VecDeque::from(vec![q0; cfg.dead_time_cycles as usize]);
        let dt = cfg.cycle_ms as f64 * 1e-3;
        let lag_step = topspin_core::calib::lag_step(dt, cfg.lag_s);
        MockController {
            ipoc: cfg.first_ipoc,
            correction: [0.0; 6],
            commanded: cfg.start,
            actual: cfg.start,
            q_cmd: q0,
            line,
            q_start: q0,
            q_act: q0,
            qd_act: [0.0; AXES],
            lag_step,
            answered: None,
            late: 0,
            wrong_ipoc: 0,
            wrong_type: 0,
            malformed: 0,
            poscorr_clamped: 0,
            axiscorr_clamped: 0,
            wrong_kind: 0,
            akorr_range_deg: [[0.0; 2]; 6],
            cycles: 0,
            peak_speed_share: 0.0,
            peak_acceleration_share: 0.0,
            rates_over: 0,
            braked_cycles: 0,
            stopped: None,
            cfg,
        }
    }

    /// The actual joints, rad.
    pub fn joints(&self) -> Joints {
        self.q_act
    }

    /// The controller's setup (`start` as [`Self::move_start`] last set it).
    pub fn config(&self) -> &ControllerConfig {
        &self.cfg
    }

    /// This cycle's IPOC.
    pub fn ipoc(&self) -> u64 {
        self.ipoc
    }

    /// The actual TCP pose (`RIst`): mm, degrees, BASE.
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
        if let Ok(q) =
            self.cfg.arm.inverse_near(&self.cfg.base.compose(&KukaPose::from_array(start).to_pose()), &self.q_cmd)
        {
            self.q_start = q;
        }
    }

    /// Brakes from the next cycle on, for `cycles` cycles.
    pub fn apply_brakes(&mut self, cycles: u64) {
        self.cfg.brakes = Some(Brakes { at_cycle: self.cycles, cycles });
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
        // None of the context's RECEIVE tags in the answer: the correction
        // holds (HOLDON).
        let (k, other) = match self.cfg.correction {
            Correction::Cartesian => (sen.rkorr.map(KukaPose::to_array), sen.akorr.is_some()),
            Correction::Axis => (sen.akorr, sen.rkorr.is_some()),
        };
        if k.is_none() && other {
            self.wrong_kind += 1;
        }
        self.answered = Some(k.unwrap_or(self.correction));
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
        match self.cfg.correction {
            Correction::Cartesian => {
                if self.stopped.is_none() {
                    self.apply_poscorr();
                }
                if self.stopped.is_none() {
                    self.command_joints();
                }
            }
            Correction::Axis => {
                if self.stopped.is_none() {
                    self.apply_axiscorr();
                }
            }
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

    /// AXISCORR: each axis's correction clamped to its limits (a
    /// non-finite one to 0), AXISCORRMON on the clamped total; the
    /// commanded joints (start + correction) within the software limit
    /// switches and off the singular wrist, else the robot stops.
    fn apply_axiscorr(&mut self) {
        let c = &self.cfg;
        let mut k = self.correction;
        let mut clamped = false;
        for (i, x) in k.iter_mut().enumerate() {
            if x.is_finite() {
                let r = &mut self.akorr_range_deg[i];
                *r = [r[0].min(*x), r[1].max(*x)];
            }
            let y = if x.is_finite() { x.clamp(c.axis_lower_deg[i], c.axis_upper_deg[i]) } else { 0.0 };
            clamped |= y != *x;
            *x = y;
        }
        if clamped {
            self.axiscorr_clamped += 1;
        }
        if let Some(i) = (0..AXES).find(|&i| k[i].abs() > c.axis_mon_max_deg[i]) {
            self.stopped = Some(StopReason::AxisMonitor(Axis::ALL[i]));
            return;
        }
        let q = Joints(core::array::from_fn(|i| self.q_start.0[i] + k[i].to_radians()));
        if let Err(v) = c.arm.limits.check_position(&q) {
            self.stopped = Some(StopReason::Axis(v));
            return;
        }
        self.q_cmd = q;
        let p = c.base.inverse().compose(&c.arm.tcp(&q)).to_pose6();
        for i in 0..3 {
            self.commanded[i] = p[i] * 1e3;
        }
        for i in 3..6 {
            self.commanded[i] = unwrap_near(p[i], self.commanded[i].to_radians()).to_degrees();
        }
    }

    /// The commanded pose to joints: the solution nearest the last
    /// commanded joints, within the software limit switches and off the
    /// singular wrist; else the robot stops.
    fn command_joints(&mut self) {
        match self
            .cfg
            .arm
            .inverse_near(&self.cfg.base.compose(&KukaPose::from_array(self.commanded).to_pose()), &self.q_cmd)
        {
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
        if self.cfg.brakes.is_some_and(|b| b.hold(self.cycles)) {
            // The axes stand; the drives start from rest when they open.
            self.qd_act = [0.0; AXES];
            self.braked_cycles += 1;
            return;
        }
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
        let tcp = self.cfg.base.inverse().compose(&self.cfg.arm.tcp(&q));
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

    fn axis_controller() -> MockController {
        let mut cfg = MockKrcConfig::default_cell_for(Correction::Axis).unwrap().controller;
        cfg.dead_time_cycles = 0;
        cfg.lag_s = 0.0;
        MockController::new(cfg)
    }

    fn sen(ipoc: u64, rkorr: Option<[f64; 6]>, akorr: Option<[f64; 6]>) -> Vec<u8> {
        let mut buf = [0u8; 512];
        let n = SenFrame { sentype: "ImFree", estr: None, rkorr: rkorr.map(KukaPose::from_array), akorr, ipoc }
            .emit(4, &mut buf)
            .unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn an_axis_context_moves_the_joints_by_akorr_from_the_start_joints() {
        let mut c = axis_controller();
        assert_eq!(c.config().correction, Correction::Axis);
        let q0 = c.joints().degrees();
        let k = [1.5, -2.0, 0.25, 3.0, -1.0, 10.0];
        assert_eq!(c.answer(&sen(c.ipoc(), None, Some(k))), Verdict::Accepted);
        let s = c.end_cycle(Instant(4_000_000));
        for i in 0..6 {
            assert!((s.joints[i] - (q0[i] + k[i])).abs() < 1e-9, "A{}: {} vs {}", i + 1, s.joints[i], q0[i] + k[i]);
        }
        // RSol / RIst: the forward kinematics of the commanded joints.
        let p = c.config().arm.tcp(&Joints::from_degrees(s.joints)).to_pose6();
        assert!((0..3).all(|i| (s.commanded[i] - p[i] * 1e3).abs() < 1e-9 && (s.actual[i] - p[i] * 1e3).abs() < 1e-9));
        // #ABSOLUTE: the same AKorr again leaves the axes where they are.
        assert_eq!(c.answer(&sen(c.ipoc(), None, Some(k))), Verdict::Accepted);
        let s2 = c.end_cycle(Instant(8_000_000));
        assert_eq!(s2.joints, s.joints);
        assert_eq!((c.axiscorr_clamped, c.poscorr_clamped, c.wrong_kind, c.stopped), (0, 0, 0, None));
    }

    #[test]
    fn axiscorr_clamps_and_axiscorrmon_stops_naming_the_axis() {
        // AXISCORR: A1 at +120° is held at its +90° limit, counted.
        let mut c = axis_controller();
        let q0 = c.joints().degrees();
        c.answered = Some([120.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let s = c.end_cycle(Instant(4_000_000));
        assert!((s.joints[0] - (q0[0] + 90.0)).abs() < 1e-9);
        assert_eq!((c.axiscorr_clamped, c.stopped), (1, None));
        // AXISCORRMON below the clamp: the total past it stops RSI.
        let mut cfg = axis_controller().config().clone();
        cfg.axis_mon_max_deg[3] = 20.0;
        let mut c = MockController::new(cfg);
        c.answered = Some([0.0, 0.0, 0.0, 19.9, 0.0, 0.0]);
        c.end_cycle(Instant(4_000_000));
        assert_eq!(c.stopped, None);
        c.answered = Some([0.0, 0.0, 0.0, -20.1, 0.0, 0.0]);
        c.end_cycle(Instant(8_000_000));
        assert_eq!(c.stopped, Some(StopReason::AxisMonitor(Axis::A4)));
        assert_eq!(c.stopped.unwrap().key(), "axis_monitor_a4");
        assert_eq!(c.stopped.unwrap().to_string(), "axis correction monitor (AXISCORRMON): A4");
        // Through the wrist singularity (A5 to 0°): the robot stops.
        let mut c = axis_controller();
        let a5 = c.joints().degrees()[4];
        let mut cfg = c.config().clone();
        cfg.axis_lower_deg[4] = -180.0;
        cfg.axis_mon_max_deg[4] = 180.0;
        c = MockController::new(cfg);
        c.answered = Some([0.0, 0.0, 0.0, 0.0, -a5, 0.0]);
        c.end_cycle(Instant(4_000_000));
        let Some(StopReason::Axis(v)) = c.stopped else { panic!("{:?}", c.stopped) };
        assert_eq!((v.axis, v.kind), (Axis::A5, LimitKind::SingularWrist));
        // A non-finite correction is clamped to zero, never applied.
        let mut c = axis_controller();
        let q0 = c.joints();
        c.answered = Some([f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]);
        c.end_cycle(Instant(4_000_000));
        assert_eq!((c.joints(), c.axiscorr_clamped, c.stopped), (q0, 1, None));
    }

    #[test]
    fn the_wrong_kind_of_correction_is_held_and_counted() {
        // RKorr to an axis context: on time, but no AKorr: the last one holds.
        let mut c = axis_controller();
        let k = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(c.answer(&sen(c.ipoc(), None, Some(k))), Verdict::Accepted);
        let held = c.end_cycle(Instant(4_000_000)).joints;
        assert_eq!(c.answer(&sen(c.ipoc(), Some([50.0, 0.0, 0.0, 0.0, 0.0, 0.0]), None)), Verdict::Accepted);
        let s = c.end_cycle(Instant(8_000_000));
        assert_eq!((s.joints, s.on_time, c.wrong_kind, c.late), (held, true, 1, 0));
        // AKorr to a Cartesian context: the same.
        let mut cfg = MockKrcConfig::default_cell().unwrap().controller;
        cfg.dead_time_cycles = 0;
        cfg.lag_s = 0.0;
        let mut c = MockController::new(cfg);
        let x0 = c.actual()[0];
        assert_eq!(c.answer(&sen(c.ipoc(), Some([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), None)), Verdict::Accepted);
        c.end_cycle(Instant(4_000_000));
        assert_eq!(c.answer(&sen(c.ipoc(), None, Some([30.0, 0.0, 0.0, 0.0, 0.0, 0.0]))), Verdict::Accepted);
        let s = c.end_cycle(Instant(8_000_000));
        assert!((s.actual[0] - (x0 + 1.0)).abs() < 1e-9);
        assert_eq!((c.wrong_kind, c.stopped), (1, None));
    }
}
