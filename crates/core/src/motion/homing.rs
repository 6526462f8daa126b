//! The way home at commissioning speed: from wherever the arm stands at
//! RSI start (or where a stopped arm came to rest) to the calibrated home,
//! as a KRL PTP would go (a straight line in joint space), timed so that
//! the TCP never moves faster than the commissioning speed and the bat
//! never turns faster than the commissioning rate (`robot.toml [start]`,
//! within KUKA's T1 limit of 250 mm/s).
//!
//! [`HomingPath::plan`] checks the whole way before the first step
//! ([`PATH_SAMPLES`] poses along it), against what would stop a KR C4 or
//! put the bat where a person may stand:
//!
//! - an axis at or through the singular wrist (|A5| below its threshold
//!   anywhere on the way, the start included);
//! - the TCP further outside the workspace box than it already stands;
//! - a correction (pose − RSI start pose, as the controller adds it) past
//!   POSCORR's limits or POSCORRMON's totals.
//!
//! Any of them refuses the way ([`WayHomeBlocked`]); the session then holds
//! and says how to fix it. The timing: the path parameter s runs 0 → 1 with
//! a cosine ramp up and down ([`RAMP_S`]) around a constant rate, set by the
//! path's fastest stretch; speed and acceleration are continuous, and the
//! bound holds on every cycle (sampled fine, with a margin for the curve
//! between samples). Planning is bounded work on the stack; sampling is one
//! forward kinematics. No allocation, no clock.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use crate::calib::RobotFile;
use crate::geometry::{Pose6, unwrap_near};
use crate::kinematics::{AXES, Arm, Joints, LimitViolation};

/// Poses checked along the way (the start and home included).
pub(crate) const PATH_SAMPLES: usize = 129;
/// Length of the speed's ramp up (and down), s.
pub(crate) const RAMP_S: f64 = 0.4;
/// The path between two samples may run this much faster than its chord.
const CHORD_MARGIN: f64 = 1.05;
/// The TCP may stand this much further outside the box than at the start, m.
const BOX_SLACK_M: f64 = 0.001;

/// What the way home must respect: the commissioning speed and rate, the
/// box, and the controller's correction limits relative to the RSI start.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HomingLimits {
    /// Fastest TCP speed, m/s.
    pub speed: f64,
    /// Fastest turn of the bat, rad/s.
    pub rate: f64,
    /// The workspace box (x, y, z in B), m.
    pub box_lo: [f64; 3],
    /// The workspace box's upper corner, m.
    pub box_hi: [f64; 3],
    /// POSCORR: per-axis translation limits of the correction, mm.
    pub poscorr_lower_mm: [f64; 3],
    /// POSCORR: upper translation limits, mm.
    pub poscorr_upper_mm: [f64; 3],
    /// POSCORR: rotation limit (root sum of squares of A, B, C), degrees.
    pub poscorr_rot_deg: f64,
    /// POSCORRMON: total translation, mm.
    pub mon_trans_mm: f64,
    /// POSCORRMON: total rotation, degrees.
    pub mon_rot_deg: f64,
}

impl HomingLimits {
    /// From a validated `robot.toml`: `[start]`'s speed and rate, the
    /// workspace box, `[poscorr]`.
    pub fn from_robot(r: &RobotFile) -> Self {
        let p = &r.poscorr;
        HomingLimits {
            speed: r.start.speed_mm_s * 1e-3,
            rate: r.start.rate_deg_s.to_radians(),
            box_lo: r.workspace.min_xyz_m,
            box_hi: r.workspace.max_xyz_m,
            poscorr_lower_mm: p.lower_xyz_mm,
            poscorr_upper_mm: p.upper_xyz_mm,
            poscorr_rot_deg: p.max_rot_angle_deg,
            mon_trans_mm: p.mon_max_trans_mm,
            mon_rot_deg: p.mon_max_rot_deg,
        }
    }
}

/// Why the way home is refused.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum WayHomeBlocked {
    /// The way passes (or starts at) the singular wrist.
    #[error("the way home passes the singular wrist (A5 {a5_deg:.1}°)")]
    SingularWrist {
        /// A5 where the way is singular, degrees (0 where it passes through).
        a5_deg: f64,
    },
    /// An axis outside its software limits on the way.
    #[error("the way home breaks {0}")]
    Limit(LimitViolation),
    /// The TCP would leave the workspace box (further than it stands).
    #[error("the way home leaves the workspace by {by_mm:.0} mm along {axis}")]
    LeavesWorkspace {
        /// `x`, `y` or `z` of B.
        axis: char,
        /// How far beyond the box (or beyond where the arm stood), mm.
        by_mm: f64,
    },
    /// A step of the way beyond the commissioning speed or rate (the
    /// session's last check on every cycle; the plan keeps within them).
    #[error("a step of the way home of {mm:.2} mm and {deg:.2}° exceeds the commissioning speed")]
    StepTooLarge {
        /// The step, mm …
        mm: f64,
        /// … and degrees.
        deg: f64,
    },
    /// The correction would pass POSCORR or POSCORRMON.
    #[error("the way home needs a correction of {trans_mm:.0} mm and {rot_deg:.0}°, past {limit}")]
    PosCorr {
        /// Translation of the worst correction, mm (Euclidean).
        trans_mm: f64,
        /// Its rotation (root sum of squares of A, B, C), degrees.
        rot_deg: f64,
        /// Which limit: `POSCORR` or `POSCORRMON`.
        limit: &'static str,
    },
}

/// A planned way home (see the module doc).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HomingPath {
    from: Joints,
    to: Joints,
    /// Start of the way, s (the caller's time base).
    t0: f64,
    /// The path parameter's cruise rate, 1/s.
    rate: f64,
    /// Ramp length, s.
    ramp: f64,
    /// Total duration, s.
    duration: f64,
}

impl HomingPath {
    /// The way from joints `from` to joints `to`, starting at `t0` s, with
    /// the controller's corrections relative to `correction_start` (the RSI
    /// start pose); refused where it is unsafe (module doc).
    pub fn plan(
        arm: &Arm,
        lim: &HomingLimits,
        correction_start: &Pose6,
        from: &Joints,
        to: &Joints,
        t0: f64,
    ) -> Result<Self, WayHomeBlocked> {
        let at = |s: f64| Joints(core::array::from_fn(|i| from.0[i] + s * (to.0[i] - from.0[i])));
        let mut last = arm.tcp(from);
        let p_from = last.to_pose6();
        let excess = |p: &Pose6, i: usize| (lim.box_lo[i] - p[i]).max(p[i] - lim.box_hi[i]).max(0.0);
        let mut last6 = p_from;
        // The path's fastest stretch: metres and radians per unit of s.
        let (mut dp_ds, mut dth_ds) = (0.0f64, 0.0f64);
        let n = PATH_SAMPLES - 1;
        for k in 0..=n {
            let s = k as f64 / n as f64;
            let q = at(s);
            arm.limits.check_position(&q).map_err(|v| match v.kind {
                crate::kinematics::LimitKind::SingularWrist => {
                    WayHomeBlocked::SingularWrist { a5_deg: q.0[4].to_degrees() }
                }
                _ => WayHomeBlocked::Limit(v),
            })?;
            let pose = arm.tcp(&q);
            let mut p6 = pose.to_pose6();
            for i in 3..6 {
                p6[i] = unwrap_near(p6[i], last6[i]);
            }
            for i in 0..3 {
                let by = excess(&p6, i) - excess(&p_from, i);
                if by > BOX_SLACK_M {
                    return Err(WayHomeBlocked::LeavesWorkspace { axis: ['x', 'y', 'z'][i], by_mm: by * 1e3 });
                }
            }
            check_poscorr(lim, correction_start, &p6)?;
            if k > 0 {
                let (dp, dth) = pose.distance(&last);
                dp_ds = dp_ds.max(dp * n as f64);
                dth_ds = dth_ds.max(dth * n as f64);
            }
            last = pose;
            last6 = p6;
        }
        // Every sample is off the singular wrist (checked above); between
        // two, A5 (a straight line) passes it only where it changes sign.
        if (from.0[4] < 0.0) != (to.0[4] < 0.0) {
            return Err(WayHomeBlocked::SingularWrist { a5_deg: 0.0 });
        }
        // The cruise rate: the fastest stretch at the speed, the turn at the
        // rate, and no axis over a tenth of its own speed.
        let mut rate = f64::INFINITY;
        if dp_ds > 0.0 {
            rate = rate.min(lim.speed / (dp_ds * CHORD_MARGIN));
        }
        if dth_ds > 0.0 {
            rate = rate.min(lim.rate / (dth_ds * CHORD_MARGIN));
        }
        for i in 0..AXES {
            let dq = (to.0[i] - from.0[i]).abs();
            if dq > 0.0 {
                rate = rate.min(0.1 * arm.limits.speed[i] / dq);
            }
        }
        // A short way never reaches its cruise: ramp up and straight down.
        let rate = rate.min(1.0 / RAMP_S);
        let duration = if rate.is_finite() { RAMP_S + 1.0 / rate } else { 0.0 };
        Ok(HomingPath { from: *from, to: *to, t0, rate, ramp: RAMP_S, duration })
    }

    /// The path parameter at time `t` (s in the caller's time base), 0..1.
    fn s_at(&self, t: f64) -> f64 {
        if self.duration <= 0.0 {
            return 1.0;
        }
        let (r, tr) = (self.rate, self.ramp);
        let up = |tau: f64| {
            let tau = tau.clamp(0.0, tr);
            0.5 * r * (tau - tr / core::f64::consts::PI * (core::f64::consts::PI * tau / tr).sin())
        };
        let tau = (t - self.t0).clamp(0.0, self.duration);
        let s = if tau <= tr {
            up(tau)
        } else if tau <= self.duration - tr {
            0.5 * r * tr + r * (tau - tr)
        } else {
            1.0 - up(self.duration - tau)
        };
        s.clamp(0.0, 1.0)
    }

    /// How far along the way the arm is commanded at time `t`, 0..1.
    pub fn progress(&self, t: f64) -> f64 {
        self.s_at(t)
    }

    /// The joints at time `t`.
    pub fn joints_at(&self, t: f64) -> Joints {
        let s = self.s_at(t);
        Joints(core::array::from_fn(|i| self.from.0[i] + s * (self.to.0[i] - self.from.0[i])))
    }

    /// True once the way is done at time `t` (the arm commanded home, at rest).
    pub fn done(&self, t: f64) -> bool {
        t - self.t0 >= self.duration
    }

    /// How long the way takes, s.
    pub fn duration(&self) -> f64 {
        self.duration
    }
}

/// The correction `pose − start` as the controller adds it (mm, degrees,
/// angles within ±180°) within POSCORR and POSCORRMON.
pub(crate) fn check_poscorr(lim: &HomingLimits, start: &Pose6, pose: &Pose6) -> Result<(), WayHomeBlocked> {
    let k = correction(start, pose);
    let trans = (k[0] * k[0] + k[1] * k[1] + k[2] * k[2]).sqrt();
    let rot = (k[3] * k[3] + k[4] * k[4] + k[5] * k[5]).sqrt();
    let clamped =
        (0..3).any(|i| k[i] < lim.poscorr_lower_mm[i] || k[i] > lim.poscorr_upper_mm[i]) || rot > lim.poscorr_rot_deg;
    if trans > lim.mon_trans_mm || rot > lim.mon_rot_deg {
        return Err(WayHomeBlocked::PosCorr { trans_mm: trans, rot_deg: rot, limit: "POSCORRMON" });
    }
    if clamped {
        return Err(WayHomeBlocked::PosCorr { trans_mm: trans, rot_deg: rot, limit: "POSCORR" });
    }
    Ok(())
}

/// RKorr for `pose` from `start`: mm and degrees, each angle within ±180°.
pub(crate) fn correction(start: &Pose6, pose: &Pose6) -> [f64; 6] {
    core::array::from_fn(|i| {
        if i < 3 {
            (pose[i] - start[i]) * 1e3
        } else {
            let d = (pose[i] - start[i]).to_degrees();
            d - (d / 360.0).round() * 360.0
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::kinematics::Pose;
    use crate::motion::MotionLimits;

    fn setup() -> (MotionLimits, HomingLimits) {
        let robot = Calibration::default_cell().robot;
        (MotionLimits::from_robot(&robot), HomingLimits::from_robot(&robot))
    }

    /// Steps of a way sampled every 4 ms: the largest TCP step (m) and turn
    /// (rad), and the largest change of step (m).
    fn steps(arm: &Arm, path: &HomingPath) -> (f64, f64, f64, usize) {
        let mut last = arm.tcp(&path.joints_at(0.0));
        let (mut dp_max, mut dth_max, mut ddp_max, mut dp_prev) = (0.0f64, 0.0f64, 0.0f64, 0.0);
        let mut k = 0;
        while !path.done(k as f64 * 0.004) {
            k += 1;
            let now = arm.tcp(&path.joints_at(k as f64 * 0.004));
            let (dp, dth) = now.distance(&last);
            dp_max = dp_max.max(dp);
            dth_max = dth_max.max(dth);
            ddp_max = ddp_max.max((dp - dp_prev).abs());
            dp_prev = dp;
            last = now;
        }
        (dp_max, dth_max, ddp_max, k)
    }

    #[test]
    fn the_way_home_keeps_to_the_commissioning_speed_and_rate() {
        let (ml, hl) = setup();
        let arm = &ml.arm;
        // 80 mm forward, 60 mm up and the bat turned 25° about B.
        let mut start = ml.home;
        start[0] += 0.08;
        start[2] += 0.06;
        start[4] += 25f64.to_radians();
        let from = arm.inverse_near(&Pose::from_pose6(&start), &ml.home_joints).unwrap();
        let path = HomingPath::plan(arm, &hl, &start, &from, &ml.home_joints, 0.0).unwrap();
        let (dp, dth, ddp, cycles) = steps(arm, &path);
        assert!(dp <= hl.speed * 0.004, "step {:.3} mm", dp * 1e3);
        assert!(dth <= hl.rate * 0.004, "turn {:.3}°", dth.to_degrees());
        assert!(dp > 0.5 * hl.speed * 0.004 || dth > 0.5 * hl.rate * 0.004, "it goes at the bound, not far below");
        assert!(ddp < 0.05e-3, "no step in speed ({:.4} mm)", ddp * 1e3);
        assert_eq!(cycles as f64, (path.duration() / 0.004).ceil());
        // It ends at home, exactly.
        assert!(path.joints_at(path.duration()).max_abs_diff(&ml.home_joints) < 1e-12);
        assert!(path.joints_at(-1.0).max_abs_diff(&from) < 1e-12, "before its start it stands");
    }

    #[test]
    fn an_unsafe_way_is_refused_with_its_reason() {
        let (ml, hl) = setup();
        let arm = &ml.arm;
        // The wrist flipped (A5 < 0, A4 and A6 half a turn on): the same
        // TCP pose, but the way to home's joints turns the bat past POSCORR
        // and through the singular wrist.
        let mut q = ml.home_joints;
        q.0[3] -= core::f64::consts::PI;
        q.0[4] = -q.0[4];
        q.0[5] += core::f64::consts::PI;
        let p = arm.tcp(&q).to_pose6();
        let r = HomingPath::plan(arm, &hl, &p, &q, &ml.home_joints, 0.0);
        assert!(matches!(r, Err(WayHomeBlocked::SingularWrist { .. } | WayHomeBlocked::PosCorr { .. })), "{r:?}");
        let mut wide = hl;
        (wide.poscorr_rot_deg, wide.mon_rot_deg) = (360.0, 360.0);
        let r = HomingPath::plan(arm, &wide, &p, &q, &ml.home_joints, 0.0);
        assert!(matches!(r, Err(WayHomeBlocked::SingularWrist { .. })), "{r:?}");
        // Starting at the singular wrist.
        let mut q = ml.home_joints;
        q.0[4] = 0.2f64.to_radians();
        let p = arm.tcp(&q).to_pose6();
        let r = HomingPath::plan(arm, &hl, &p, &q, &ml.home_joints, 0.0);
        assert!(matches!(r, Err(WayHomeBlocked::SingularWrist { .. })), "{r:?}");
        // A1 turned 120°: the correction home is past POSCORRMON.
        let mut q = ml.home_joints;
        q.0[0] += 120f64.to_radians();
        let p = arm.tcp(&q).to_pose6();
        let r = HomingPath::plan(arm, &hl, &p, &q, &ml.home_joints, 0.0);
        assert!(matches!(r, Err(WayHomeBlocked::PosCorr { .. } | WayHomeBlocked::LeavesWorkspace { .. })), "{r:?}");
        // Inside the box and the limits, a way that dips below the box.
        let mut q = ml.home_joints;
        q.0[1] += 25f64.to_radians();
        q.0[2] -= 40f64.to_radians();
        let p = arm.tcp(&q).to_pose6();
        let mid = arm.tcp(&Joints(core::array::from_fn(|i| 0.5 * (q.0[i] + ml.home_joints.0[i])))).to_pose6();
        let r = HomingPath::plan(arm, &hl, &p, &q, &ml.home_joints, 0.0);
        if (0..3).any(|i| mid[i] < ml.lo[i] - 0.002) {
            assert!(matches!(r, Err(WayHomeBlocked::LeavesWorkspace { .. } | WayHomeBlocked::PosCorr { .. })), "{r:?}");
        }
    }

    #[test]
    fn the_correction_is_wrapped_and_checked_against_both_limits() {
        let (_, hl) = setup();
        let start = [0.35, 0.0, 0.45, 170f64.to_radians(), 0.0, 0.0];
        let mut p = start;
        p[3] = -170f64.to_radians();
        let k = correction(&start, &p);
        assert!((k[3] - 20.0).abs() < 1e-9, "{k:?}");
        assert_eq!(check_poscorr(&hl, &start, &p), Ok(()));
        p[0] += 0.5; // 500 mm in x: past POSCORR's +450
        assert!(matches!(check_poscorr(&hl, &start, &p), Err(WayHomeBlocked::PosCorr { limit: "POSCORR", .. })));
        let mut p = start;
        p[4] = 95f64.to_radians();
        p[5] = 40f64.to_radians();
        assert!(matches!(check_poscorr(&hl, &start, &p), Err(WayHomeBlocked::PosCorr { limit: "POSCORRMON", .. })));
    }
}
