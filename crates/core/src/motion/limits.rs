//! The cell's motion limits in generator units (m, rad, s) and the
//! conversion of a plan from the table frame T to the robot's BASE B.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use crate::calib::RobotFile;
use crate::geometry::{EulerZyx, Pose6, rot_zyx, unwrap_near, zyx_angles_asin};
use crate::kinematics::{Arm, Joints};
use crate::physics::Vec3;

/// Everything motion needs to know about the cell, in SI.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionLimits {
    /// Sensor cycle, s.
    pub dt: f64,
    /// Lower corner of the workspace (orientation: home − range).
    pub lo: Pose6,
    /// Upper corner of the workspace (orientation: home + range).
    pub hi: Pose6,
    /// Per-axis velocity limit, m/s and rad/s.
    pub vmax: Pose6,
    /// Per-axis acceleration limit, m/s² and rad/s².
    pub amax: Pose6,
    /// Per-axis jerk limit, m/s³ and rad/s³.
    pub jmax: Pose6,
    /// Home = RSI start pose.
    pub home: Pose6,
    /// The fastest bat speed a plan may ask for, m/s.
    pub max_bat_speed: f64,
    /// Base yaw in T, rad: the angle of B's x axis about T's z axis.
    pub base_yaw: f64,
    /// Base origin in T, m.
    pub base_xyz: [f64; 3],
    /// The arm (kinematics, axis limits) every stroke is checked against.
    pub arm: Arm,
    /// The joints at home.
    pub home_joints: Joints,
}

impl MotionLimits {
    /// From a validated `robot.toml`.
    pub fn from_robot(r: &RobotFile) -> Self {
        let rad = |d: [f64; 3]| d.map(f64::to_radians);
        let home_abc = rad(r.home.abc_deg);
        let range = rad(r.workspace.abc_range_deg);
        let cat = |a: [f64; 3], b: [f64; 3]| [a[0], a[1], a[2], b[0], b[1], b[2]];
        let l = &r.limits;
        MotionLimits {
            dt: r.cycle_s(),
            lo: cat(r.workspace.min_xyz_m, [0, 1, 2].map(|i| home_abc[i] - range[i])),
            hi: cat(r.workspace.max_xyz_m, [0, 1, 2].map(|i| home_abc[i] + range[i])),
            vmax: cat(l.velocity_m_s, rad(l.rot_velocity_deg_s)),
            amax: cat(l.acceleration_m_s2, rad(l.rot_acceleration_deg_s2)),
            jmax: cat(l.jerk_m_s3, rad(l.rot_jerk_deg_s3)),
            home: cat(r.home.xyz_m, home_abc),
            max_bat_speed: l.max_bat_speed_m_s,
            base_yaw: r.base_yaw(),
            base_xyz: r.cell.base_in_table_xyz_m,
            arm: r.arm(),
            home_joints: r.home_joints(&r.arm()).expect("a validated robot.toml has home joints"),
        }
    }

    /// A point from T to B.
    pub fn point_t_to_b(&self, p: Vec3) -> Vec3 {
        self.rotate_t_to_b(p - Vec3::from(self.base_xyz))
    }

    /// A direction from T to B.
    pub(crate) fn rotate_t_to_b(&self, v: Vec3) -> Vec3 {
        let (s, c) = self.base_yaw.sin_cos();
        Vec3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z)
    }

    /// A bat orientation (Euler ZYX in T) as KUKA A/B/C in B, each angle
    /// unwrapped to lie within π of home.
    pub fn orientation_t_to_b(&self, o: EulerZyx) -> [f64; 3] {
        let r = rot_zyx(-self.base_yaw, 0.0, 0.0) * o.matrix();
        let [a, b, c] = zyx_angles_asin(&r);
        [unwrap_near(a, self.home[3]), unwrap_near(b, self.home[4]), unwrap_near(c, self.home[5])]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;

    #[test]
    fn neutral_bat_in_t_is_home_orientation_in_b() {
        let lim = MotionLimits::from_robot(&Calibration::default_cell().robot);
        let abc = lim.orientation_t_to_b(EulerZyx::default());
        for i in 0..3 {
            assert!((abc[i] - lim.home[3 + i]).abs() < 1e-9, "{abc:?}");
        }
        let p = lim.point_t_to_b(Vec3::new(1.70, 0.0, 0.40));
        assert!((p - Vec3::new(0.35, 0.0, 0.45)).norm() < 1e-12);
    }
}
