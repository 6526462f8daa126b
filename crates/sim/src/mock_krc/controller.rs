//! The controller model, sans-IO: one [`MockController::request`] per cycle,
//! answers offered with [`MockController::answer`], and
//! [`MockController::end_cycle`] at the cycle's deadline.
//!
//! Units are KUKA's (mm, degrees). The correction passes POSCORR (per-axis
//! translation limits, one total rotation limit), POSCORRMON (total
//! translation/rotation: exceeding it stops RSI), then the robot follows
//! the commanded pose within its own per-axis velocity and acceleration
//! limits. A late cycle keeps the last correction (HOLDON).
//!
//! Optionally (`dead_time_cycles`, `lag_s`; zero by default, the ideal
//! robot) the commanded pose reaches the robot after a dead time of whole
//! cycles and the robot follows it through a first-order lag per axis, for
//! `topspin identify` and `topspin mock-krc --dead-time-ms --lag-ms`: with
//! no lag, the pose answered for request k is the `RIst` of request
//! k + 1 + `dead_time_cycles`.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use topspin_core::rsi::codec::{CodecError, KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::time::Instant;

/// How RKorr is applied.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CorrMode {
    /// RKorr = commanded pose − pose at RSI start.
    Absolute,
    /// RKorr = increment added each cycle.
    Relative,
}

/// Why RSI stopped.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// More late answers than the Timeout allows.
    LateLimit,
    /// POSCORRMON: total correction too large.
    Monitor,
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
    /// The robot's own limits per Cartesian axis (mm/s, deg/s; /s²).
    pub vmax: [f64; 6],
    pub amax: [f64; 6],
    /// POSCORR and POSCORRMON.
    pub lower_mm: [f64; 3],
    pub upper_mm: [f64; 3],
    pub max_rot_deg: f64,
    pub mon_max_trans_mm: f64,
    pub mon_max_rot_deg: f64,
    /// First IPOC.
    pub first_ipoc: u64,
    /// Whole cycles between a correction and the robot moving to it.
    pub dead_time_cycles: u32,
    /// First-order lag of the robot behind the (delayed) command, s.
    pub lag_s: f64,
}

/// One cycle of the logged TCP path.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PathSample {
    /// When the robot is at `actual`.
    pub t: Instant,
    pub ipoc: u64,
    /// Commanded pose after POSCORR (mm, deg, BASE).
    pub commanded: [f64; 6],
    /// Where the robot is (after its own limits).
    pub actual: [f64; 6],
    /// This cycle's answer came on time.
    pub on_time: bool,
    /// The robot's own velocity/acceleration limits bent the command.
    pub robot_limited: bool,
}

/// The controller (see the module doc).
#[derive(Clone, Debug)]
pub struct MockController {
    cfg: ControllerConfig,
    ipoc: u64,
    correction: [f64; 6],
    commanded: [f64; 6],
    actual: [f64; 6],
    velocity: [f64; 6],
    /// The commands of the last `dead_time_cycles` cycles, oldest first,
    /// and the lagged command the robot follows.
    delayed: std::collections::VecDeque<[f64; 6]>,
    lagged: [f64; 6],
    answered: Option<[f64; 6]>,
    pub late: u64,
    pub wrong_ipoc: u64,
    pub wrong_type: u64,
    pub malformed: u64,
    pub poscorr_clamped: u64,
    pub robot_limited: u64,
    pub cycles: u64,
    pub stopped: Option<StopReason>,
}

impl MockController {
    pub fn new(cfg: ControllerConfig) -> Self {
        MockController {
            ipoc: cfg.first_ipoc,
            correction: [0.0; 6],
            commanded: cfg.start,
            actual: cfg.start,
            velocity: [0.0; 6],
            delayed: std::collections::VecDeque::from(vec![cfg.start; cfg.dead_time_cycles as usize]),
            lagged: cfg.start,
            answered: None,
            late: 0,
            wrong_ipoc: 0,
            wrong_type: 0,
            malformed: 0,
            poscorr_clamped: 0,
            robot_limited: 0,
            cycles: 0,
            stopped: None,
            cfg,
        }
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
        let axes = [0.0, -90.0, 90.0, 0.0, 0.0, 0.0];
        RobFrame {
            ipoc: self.ipoc,
            rist: Some(pose),
            rsol: Some(KukaPose::from_array(self.commanded)),
            aipos: Some(axes),
            aspos: Some(axes),
            delay: Some(self.late),
        }
        .emit(&self.cfg.send, self.cfg.precision, buf)
    }

    /// Moves the robot by something other than RSI (its program or the
    /// jog keys, as for touching a point while RSI answers zero): the pose
    /// RSI corrects from becomes `start` (mm, degrees), and the robot goes
    /// there within its own velocity and acceleration limits.
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
    /// applies the correction, moves the robot one cycle and advances IPOC.
    /// Returns the path sample at the start of the next cycle.
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
        self.apply_poscorr();
        let robot_limited = self.follow();
        self.cycles += 1;
        self.ipoc += self.cfg.cycle_ms as u64;
        PathSample {
            t: next_t,
            ipoc: self.ipoc,
            commanded: self.commanded,
            actual: self.actual,
            on_time,
            robot_limited,
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

    /// One cycle of the robot towards the command (after the dead time
    /// and the lag); true where its limits acted.
    fn follow(&mut self) -> bool {
        let dt = self.cfg.cycle_ms as f64 * 1e-3;
        let target = match self.delayed.pop_front() {
            Some(old) => {
                self.delayed.push_back(self.commanded); // one out, one in: no allocation
                old
            }
            None => self.commanded,
        };
        let step = if self.cfg.lag_s > 0.0 { 1.0 - (-dt / self.cfg.lag_s).exp() } else { 1.0 };
        for i in 0..6 {
            self.lagged[i] += step * (target[i] - self.lagged[i]);
        }
        let mut limited = false;
        for i in 0..6 {
            let vd = (self.lagged[i] - self.actual[i]) / dt;
            let u = self.cfg.amax[i] * dt;
            let v = vd.clamp(self.velocity[i] - u, self.velocity[i] + u).clamp(-self.cfg.vmax[i], self.cfg.vmax[i]);
            limited |= (v - vd).abs() > 1e-9 * (1.0 + vd.abs());
            self.velocity[i] = v;
            self.actual[i] += v * dt;
        }
        if limited {
            self.robot_limited += 1;
        }
        limited
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mock_krc::MockKrcConfig;

    /// Holds a 0.05 mm correction on x from the first cycle (within the
    /// robot's own acceleration limit in one cycle); the actual x after
    /// each cycle, relative to the start, in units of the correction.
    fn response(dead_time_cycles: u32, lag_s: f64, cycles: usize) -> Vec<f64> {
        let mut cfg = MockKrcConfig::default_cell().unwrap().controller;
        cfg.dead_time_cycles = dead_time_cycles;
        cfg.lag_s = lag_s;
        let x0 = cfg.start[0];
        let mut c = MockController::new(cfg);
        (0..cycles)
            .map(|k| {
                c.answered = Some([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]);
                ((c.end_cycle(Instant(k as u64 * 4_000_000)).actual[0] - x0) / 0.05 * 1e9).round() / 1e9
            })
            .collect()
    }

    #[test]
    fn a_moved_start_is_followed_with_no_correction() {
        let cfg = MockKrcConfig::default_cell().unwrap().controller;
        let mut to = cfg.start;
        to[0] += 0.05;
        let mut c = MockController::new(cfg);
        c.move_start(to);
        c.answered = Some([0.0; 6]);
        let got = c.end_cycle(Instant(4_000_000)).actual;
        assert!(got.iter().zip(&to).all(|(a, b)| (a - b).abs() < 1e-9), "{got:?} {to:?}");
    }

    #[test]
    fn the_ideal_robot_is_there_one_cycle_later() {
        assert_eq!(response(0, 0.0, 3), vec![1.0, 1.0, 1.0]);
    }

    #[test]
    fn dead_time_delays_by_whole_cycles() {
        let r = response(3, 0.0, 6);
        assert_eq!(r, vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn the_lag_closes_its_share_of_the_gap_each_cycle() {
        let r = response(2, 0.015, 6);
        let step = 1.0 - (-0.004f64 / 0.015).exp();
        let expect =
            [0.0, 0.0, step, 1.0 - (1.0 - step).powi(2), 1.0 - (1.0 - step).powi(3), 1.0 - (1.0 - step).powi(4)];
        for (k, (a, b)) in r.iter().zip(expect).enumerate() {
            assert!((a - b).abs() < 1e-8, "cycle {k}: {a} vs {b}");
        }
    }
}
