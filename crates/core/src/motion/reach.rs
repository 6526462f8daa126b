//! What the arm can do at a hitting point, for the planners that choose a
//! stroke before the generator sees it: which face tilts the KR 6 R900 can
//! present there (joints within the software limits with margin, clear of
//! the singular wrist and the stretched elbow) and the fastest bat along
//! the face's normal its axes deliver ([`ReachMap`]). The generator refuses
//! the first kind of stroke and slows the second to what the axes give
//! ([`super::generator`]); a return aimed without knowing either is hit
//! with another face or a slower bat than it was aimed with.
//!
//! The joint checks the generator applies to a stroke's target live here
//! too (one implementation for both): [`inside_margin`],
//! [`clear_of_singularities`], [`stop_point`], [`clear_to_rest`] and the
//! TCP-to-joint velocity [`joint_velocity`].
//!
//! The map is built once, at start-up (it allocates there, a few thousand
//! inverse kinematics); looking a point up reads the four grid points
//! around it and takes the most cautious of them, without allocating.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use super::MotionLimits;
use super::margins::{
    ELBOW_MARGIN_RAD, JERK_RAMP_S, JOINT_LIMIT_FRACTION, LIMIT_MARGIN_RAD, ORIENTATION_MARGIN_RAD, PATH_WALL_MARGIN_M,
    VELOCITY_STEP_S,
};
use crate::geometry::EulerZyx;
use crate::geometry::Pose6;
use crate::kinematics::{AXES, Axis, Joints, LimitKind, LimitViolation, Pose};
use crate::physics::Vec3;

/// `q` at least [`LIMIT_MARGIN_RAD`] inside every software limit.
pub(crate) fn inside_margin(lim: &MotionLimits, q: &Joints) -> Result<(), LimitViolation> {
    inside_by(lim, q, LIMIT_MARGIN_RAD)
}

/// `q` at least `margin` rad inside every software limit.
pub(crate) fn inside_by(lim: &MotionLimits, q: &Joints, margin: f64) -> Result<(), LimitViolation> {
    let l = &lim.arm.limits;
    for axis in Axis::ALL {
        let i = axis.index();
        let (lo, hi) = (l.min[i] + margin, l.max[i] - margin);
        if !(lo..=hi).contains(&q.0[i]) {
            let limit = if q.0[i] < lo { l.min[i] } else { l.max[i] };
            return Err(LimitViolation { axis, kind: LimitKind::Position, value: q.0[i], limit });
        }
    }
    Ok(())
}

/// `q` on the same side of the wrist and elbow singularities as `now`, at
/// least `wrist` rad from A5 = 0 and [`ELBOW_MARGIN_RAD`] from the
/// stretched elbow (where a small TCP motion asks the axes for unbounded
/// speed, and the reach ends).
pub(crate) fn clear_of_singularities(
    lim: &MotionLimits,
    now: &Joints,
    q: &Joints,
    wrist: f64,
) -> Result<(), LimitViolation> {
    let arm = &lim.arm;
    let a5 = q.0[4];
    if a5 * now.0[4] <= 0.0 || a5.abs() < wrist {
        return Err(LimitViolation { axis: Axis::A5, kind: LimitKind::SingularWrist, value: a5, limit: wrist });
    }
    let stretched = arm.geometry.stretched_a3();
    let bend = |a3: f64| {
        let d = a3 - stretched;
        d - (d / std::f64::consts::TAU).round() * std::f64::consts::TAU
    };
    let (before, then) = (bend(now.0[2]), bend(q.0[2]));
    if before * then <= 0.0 || then.abs() < ELBOW_MARGIN_RAD {
        return Err(LimitViolation { axis: Axis::A3, kind: LimitKind::Position, value: q.0[2], limit: stretched });
    }
    Ok(())
}

/// Where the axes come to rest braking from `qd` at `q` (the stroke's
/// limits: the jerk ramp, then full deceleration).
pub(crate) fn stop_point(lim: &MotionLimits, q: &Joints, qd: &[f64; AXES]) -> Joints {
    let l = &lim.arm.limits;
    Joints(core::array::from_fn(|i| {
        let a = l.acceleration[i] * JOINT_LIMIT_FRACTION;
        q.0[i] + qd[i] * (qd[i].abs() / (2.0 * a) + JERK_RAMP_S)
    }))
}

/// A rest pose after a hit: inside the limits with margin, clear of the
/// singularities (A5 `wrist` rad from 0), the TCP [`PATH_WALL_MARGIN_M`]
/// inside the workspace box.
pub(crate) fn clear_to_rest(lim: &MotionLimits, now: &Joints, q: &Joints, wrist: f64) -> Result<(), LimitViolation> {
    lim.arm.limits.check_position(q)?;
    inside_margin(lim, q)?;
    clear_of_singularities(lim, now, q, wrist)?;
    // As far inside as a stroke's path keeps: the safety filter brakes at
    // the walls, and the braking comes to rest past its target by a little
    // (0.5 mm) with the setpoints leading it (the lag's feed-forward).
    let tcp = lim.arm.tcp(q).to_pose6();
    for i in 0..3 {
        if tcp[i] < lim.lo[i] + PATH_WALL_MARGIN_M || tcp[i] > lim.hi[i] - PATH_WALL_MARGIN_M {
            let axis = Axis::ALL[i];
            return Err(LimitViolation { axis, kind: LimitKind::Position, value: q.0[i], limit: q.0[i] });
        }
    }
    Ok(())
}

/// The joint velocity at `q` (the joints of `pose`) of the TCP velocity
/// `v`: the joints of the pose `step` s along `v` (before it, for a
/// negative step), differenced; zero where that pose has none.
pub(crate) fn joint_velocity(lim: &MotionLimits, pose: &Pose6, q: &Joints, v: &Pose6, step: f64) -> [f64; AXES] {
    let moved: Pose6 = core::array::from_fn(|i| pose[i] + v[i] * step);
    match lim.arm.inverse_near(&Pose::from_pose6(&moved), q) {
        Ok(q2) => core::array::from_fn(|i| (q2.0[i] - q.0[i]) / step),
        Err(_) => [0.0; AXES],
    }
}

/// The share of the axes' speed that `qd` needs, against the stroke's
/// [`JOINT_LIMIT_FRACTION`] of it (> 1: the generator slows the bat).
pub(crate) fn speed_share(lim: &MotionLimits, qd: &[f64; AXES]) -> f64 {
    let l = &lim.arm.limits;
    (0..AXES).map(|i| qd[i].abs() / (l.speed[i] * JOINT_LIMIT_FRACTION)).fold(0.0, f64::max)
}

/// How many times the generator halves a bat speed whose rest point after
/// the hit is not clear before it refuses the stroke.
pub(crate) const REST_HALVINGS: usize = 3;

/// The least |A5| at a hitting pose the aim may choose, degrees: a few
/// times the generator's own floor (`WRIST_MARGIN` × the singular
/// threshold, 5°), since the follow-through, the lag's feed-forward and a
/// late refinement all move the wrist on from the hitting pose, and near
/// A5 = 0 a centimetre of TCP motion turns A4 and A6 by tens of degrees.
pub(crate) const REACH_WRIST_DEG: f64 = 15.0;

/// The grid's spacing in y and z, m.
pub(crate) const REACH_GRID_M: f64 = 0.05;
/// The face tilts the map holds, in steps of this many degrees.
pub(crate) const REACH_TILT_STEP_DEG: f64 = 5.0;
/// Most tilts one map holds (±40° in 5° steps: 17).
pub(crate) const REACH_TILTS: usize = 33;

/// The fastest bat, m/s, along the face's normal at each tilt of the map
/// at one point (0: the arm cannot present that face there).
pub(crate) type SpeedCaps = [f64; REACH_TILTS];

/// The blade's rolls about the face's normal tried at each point and tilt,
/// degrees from the stroke's own (`strike` C), nearest first. The roll
/// leaves the face where it is (the contact model sees only the normal)
/// but moves the wrist: at 20 cm over the table a face opened by 30° puts
/// A5 on its singularity unrolled, and 40° from it rolled by 30°.
pub(crate) const REACH_ROLLS_DEG: [f64; 7] = [0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0];
/// A roll nearer the stroke's own that lets the bat this near the fastest
/// allowed (a share of `max_bat_speed`) is taken before any further one.
const ROLL_GAIN: f64 = 0.9;

/// What the arm can do over the hitting window (see the module doc).
#[derive(Clone, Debug)]
pub struct ReachMap {
    /// The hitting plane, m (x in T).
    x: f64,
    /// The grid's first point (y, z in T), m, and its size.
    y0: f64,
    z0: f64,
    ny: usize,
    nz: usize,
    /// The tilts: the first, rad, and how many.
    tilt0: f64,
    tilts: usize,
    /// Speed caps, `[(iy * nz + iz) * tilts + k]`, and the blade's roll
    /// (Euler c in T, rad) that gives each.
    caps: Vec<f64>,
    rolls: Vec<f64>,
}

impl ReachMap {
    /// The map over the hitting plane `x` (T), y in `y`, z in `z` (m), for
    /// face tilts `tilt` (rad, most closed to most open), the face's
    /// heading at each point towards `target` (x, y in T) and its roll
    /// `roll(y)` — as the aim sets them — the stroke starting from home.
    pub fn new(
        lim: &MotionLimits,
        x: f64,
        y: [f64; 2],
        z: [f64; 2],
        tilt: [f64; 2],
        target: [f64; 2],
        roll: impl Fn(f64) -> f64,
    ) -> Self {
        // (Less a hair: 0.55 m / 0.05 m is 11.000000000000002.)
        let n = |r: [f64; 2]| ((r[1] - r[0]) / REACH_GRID_M - 1e-9).ceil().max(0.0) as usize + 1;
        let step = REACH_TILT_STEP_DEG.to_radians();
        let tilts = (((tilt[1] - tilt[0]) / step - 1e-9).ceil().max(0.0) as usize + 1).min(REACH_TILTS);
        let (ny, nz) = (n(y), n(z));
        let mut caps = Vec::with_capacity(ny * nz * tilts);
        let mut rolls = Vec::with_capacity(ny * nz * tilts);
        for iy in 0..ny {
            let py = y[0] + iy as f64 * REACH_GRID_M;
            for iz in 0..nz {
                let pz = z[0] + iz as f64 * REACH_GRID_M;
                let heading = (py - target[1]).atan2(x - target[0]);
                let c0 = roll(py);
                for k in 0..tilts {
                    let t = tilt[0] + k as f64 * step;
                    let at = |d: f64| {
                        let c = c0 + d.to_radians();
                        (speed_cap(lim, Vec3::new(x, py, pz), EulerZyx { a: heading, b: t, c }), c)
                    };
                    // The nearest roll that gives nearly the fastest bat
                    // allowed; else the one that gives the fastest.
                    let mut best = (0.0, c0);
                    for d in REACH_ROLLS_DEG {
                        let (cap, c) = at(d);
                        if cap > best.0 {
                            best = (cap, c);
                        }
                        if cap >= ROLL_GAIN * lim.max_bat_speed {
                            break;
                        }
                    }
                    let (cap, c) = best;
                    caps.push(cap);
                    rolls.push(c);
                }
            }
        }
        ReachMap { x, y0: y[0], z0: z[0], ny, nz, tilt0: tilt[0], tilts, caps, rolls }
    }

    /// The hitting plane the map is for (x in T), m.
    pub fn plane(&self) -> f64 {
        self.x
    }

    /// The tilt of entry `k`, rad.
    pub fn tilt(&self, k: usize) -> f64 {
        self.tilt0 + k as f64 * REACH_TILT_STEP_DEG.to_radians()
    }

    /// How many tilts the map holds.
    pub fn tilts(&self) -> usize {
        self.tilts
    }

    /// The caps at (y, z): per tilt, the least of the four grid points
    /// around it (outside the grid: the nearest edge's), and the roll of
    /// the nearest of them.
    pub fn caps_at(&self, y: f64, z: f64) -> (SpeedCaps, SpeedCaps) {
        let mut out = [0.0; REACH_TILTS];
        let mut roll = [0.0; REACH_TILTS];
        let cell = |v: f64, v0: f64, n: usize| {
            let u = ((v - v0) / REACH_GRID_M).clamp(0.0, (n - 1) as f64);
            // On a grid line (to rounding): that line alone.
            if (u - u.round()).abs() < 1e-9 {
                let k = u.round() as usize;
                return (k, k);
            }
            let lo = u.floor() as usize;
            (lo, (lo + 1).min(n - 1))
        };
        let (y_lo, y_hi) = cell(y, self.y0, self.ny);
        let (z_lo, z_hi) = cell(z, self.z0, self.nz);
        for k in 0..self.tilts {
            let at = |iy: usize, iz: usize| self.caps[(iy * self.nz + iz) * self.tilts + k];
            out[k] = at(y_lo, z_lo).min(at(y_lo, z_hi)).min(at(y_hi, z_lo)).min(at(y_hi, z_hi));
            let near = |v: f64, v0: f64, lo: usize, hi: usize| {
                if v - (v0 + lo as f64 * REACH_GRID_M) <= v0 + hi as f64 * REACH_GRID_M - v { lo } else { hi }
            };
            let (iy, iz) = (near(y, self.y0, y_lo, y_hi), near(z, self.z0, z_lo, z_hi));
            roll[k] = self.rolls[(iy * self.nz + iz) * self.tilts + k];
        }
        (out, roll)
    }
}

/// The fastest bat along the face's normal at `point` (T) with the face
/// `o` (T) that the axes deliver from home — what the generator would
/// slow a faster one to — or 0 where the arm cannot present that face
/// there clear of its limits (A5 at least [`REACH_WRIST_DEG`] from 0).
pub(crate) fn speed_cap(lim: &MotionLimits, point: Vec3, o: EulerZyx) -> f64 {
    let p = lim.point_t_to_b(point);
    let abc = lim.orientation_t_to_b(o);
    // The generator clamps the orientation to within a margin of the
    // workspace's range: a face outside it is not the face the bat would have.
    let m = ORIENTATION_MARGIN_RAD;
    if (0..3).any(|i| abc[i] < lim.lo[3 + i] + m || abc[i] > lim.hi[3 + i] - m) {
        return 0.0;
    }
    let pose: Pose6 = [p.x, p.y, p.z, abc[0], abc[1], abc[2]];
    let home = lim.home_joints;
    let Ok(q) = lim.arm.inverse_near(&Pose::from_pose6(&pose), &home) else { return 0.0 };
    let wrist = REACH_WRIST_DEG.to_radians();
    if lim.arm.limits.check_position(&q).is_err()
        || inside_margin(lim, &q).is_err()
        || clear_of_singularities(lim, &home, &q, wrist).is_err()
    {
        return 0.0;
    }
    let n = lim.rotate_t_to_b(o.face_normal());
    let unit: Pose6 = [n.x, n.y, n.z, 0.0, 0.0, 0.0];
    let qd = joint_velocity(lim, &pose, &q, &unit, VELOCITY_STEP_S);
    let share = speed_share(lim, &qd);
    if share <= 0.0 || !share.is_finite() {
        return 0.0;
    }
    let mut cap = (1.0 / share).min(lim.max_bat_speed);
    for _ in 0..=REST_HALVINGS {
        let stop = stop_point(lim, &q, &qd.map(|x| x * cap));
        if clear_to_rest(lim, &home, &stop, wrist).is_ok() {
            return cap;
        }
        cap *= 0.5;
    }
    0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;

    fn lim() -> MotionLimits {
        MotionLimits::from_robot(&Calibration::default_cell().robot)
    }

    #[test]
    fn a_rest_point_outside_the_box_is_not_clear() {
        // The safety filter brakes the TCP at the box's walls: a stroke's
        // follow-through that comes to rest past one is braked there (seen
        // at y_B = 0.65 with a lower-bouncing table: clamps, axis-rate
        // overs), and so is one that rests just inside: the braking passes
        // its rest point by 0.5 mm and the setpoints lead it (a wide hit at
        // 2 m/s resting 0.3 mm inside y_B = 0.75 was braked there for 33
        // cycles, two of them axis steps).
        let lim = lim();
        let home = lim.home_joints;
        let mut pose = lim.arm.tcp(&home).to_pose6();
        // Low, where the arm reaches past the box's side.
        pose[2] = lim.lo[2] + 0.05;
        for (y, clear) in [(lim.hi[1] - 0.02, true), (lim.hi[1] - 0.002, false), (lim.hi[1] + 0.02, false)] {
            pose[1] = y;
            let q = lim.arm.inverse_near(&Pose::from_pose6(&pose), &home).expect("reachable");
            assert_eq!(clear_to_rest(&lim, &home, &q, 0.0).is_ok(), clear, "y {y}");
        }
    }

    #[test]
    fn an_open_face_low_down_turns_the_wrist_onto_its_singularity() {
        let lim = lim();
        let at = |z: f64, tilt_deg: f64| {
            speed_cap(&lim, Vec3::new(1.6, 0.0, z), EulerZyx { a: 0.0, b: tilt_deg.to_radians(), c: 0.0 })
        };
        // Upright at mid height: the arm gives the bat its full speed.
        assert_eq!(at(0.40, 0.0), lim.max_bat_speed);
        // Open by 40° at 20 cm the wrist flips (A5 < 0 from home's 69°):
        // no such stroke; at 20° it is 12° from A5 = 0, inside the margin.
        assert_eq!(at(0.20, 40.0), 0.0);
        assert_eq!(at(0.20, 20.0), 0.0);
        // Closed by 20° at the same height, A5 is 62°: a stroke.
        assert!(at(0.20, -20.0) > 0.5, "{}", at(0.20, -20.0));
    }

    #[test]
    fn the_map_is_the_most_cautious_of_the_points_around() {
        let lim = lim();
        let m = ReachMap::new(
            &lim,
            1.6,
            [-0.6, 0.6],
            [0.15, 0.70],
            [-40f64.to_radians(), 40f64.to_radians()],
            [-0.7, 0.0],
            |_| 0.0,
        );
        assert_eq!(m.tilts(), 17);
        assert!((m.tilt(16) - 40f64.to_radians()).abs() < 1e-12);
        // A grid point: its own caps.
        let (c, roll) = m.caps_at(0.0, 0.20);
        let heading = 0f64.atan2(1.6 + 0.7);
        for k in 0..m.tilts() {
            let own = speed_cap(&lim, Vec3::new(1.6, 0.0, 0.20), EulerZyx { a: heading, b: m.tilt(k), c: roll[k] });
            assert!((c[k] - own).abs() < 1e-6, "tilt {}: {} vs {own}", m.tilt(k).to_degrees(), c[k]);
        }
        // Low down, an open face needs the blade rolled; upright it does not.
        assert_eq!(roll[8], 0.0);
        assert!(c[16] > 1.0 && roll[16].abs() > 0.2, "{c:?} {roll:?}");
        assert_eq!(speed_cap(&lim, Vec3::new(1.6, 0.0, 0.20), EulerZyx { a: heading, b: m.tilt(16), c: 0.0 }), 0.0);
        // Between points: at most each of the four around it.
        let mid = m.caps_at(0.025, 0.425).0;
        for k in 0..m.tilts() {
            for (y, z) in [(0.0, 0.40), (0.05, 0.40), (0.0, 0.45), (0.05, 0.45)] {
                assert!(mid[k] <= m.caps_at(y, z).0[k]);
            }
        }
        // Outside the grid: its edge.
        assert_eq!(m.caps_at(0.0, 0.0), m.caps_at(0.0, 0.15));
    }
}
