//! The robot cell (`calib/robot.toml`): where the KR 6 R900 stands relative
//! to the table (T←B), its home pose, the workspace box, the Cartesian TCP
//! limits, the controller's POSCORR limits and the RSI timing.
//!
//! Owns loading-time validation (every bad value is named by its key) and
//! the conversions to radians. It does not generate motion (`motion`) or
//! speak RSI (`rsi`).

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use serde::{Deserialize, Serialize};

use crate::physics::Vec3;

/// `calib/robot.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFile {
    /// Format version of the file.
    pub version: u32,
    /// `[robot]`: the arm and its bat.
    pub robot: RobotModel,
    /// `[cell]`: where the base stands in the table frame.
    pub cell: CellPlacement,
    /// `[home]`: the home (RSI start) pose.
    pub home: HomePose,
    /// `[workspace]`: the box the TCP never leaves.
    pub workspace: Workspace,
    /// `[limits]`: Cartesian TCP limits.
    pub limits: TcpLimits,
    /// `[poscorr]`: the controller's POSCORR limits.
    pub poscorr: PosCorrLimits,
    /// `[rsi]`: RSI timing.
    pub rsi: RsiTiming,
}

/// The arm itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotModel {
    /// Robot model name (informational, shown in the viewer).
    pub model: String,
    /// Datasheet reach (wrist centre), m.
    pub reach_m: f64,
    /// Flange to bat centre (the TCP), m.
    pub tool_length_m: f64,
    /// The A2 axis (shoulder) in B, m.
    pub shoulder_xyz_m: [f64; 3],
    /// Datasheet axis speeds A1..A6, °/s (informational).
    pub axis_speed_deg_s: [f64; 6],
}

/// T←B: where the base stands in the table frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellPlacement {
    /// Origin of the robot base B in the table frame T, m.
    pub base_in_table_xyz_m: [f64; 3],
    /// Rotation of B about z_T, degrees.
    pub base_yaw_in_table_deg: f64,
}

/// The home (= RSI start) pose in B.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HomePose {
    /// TCP (bat centre) position in B, m.
    pub xyz_m: [f64; 3],
    /// Orientation as KUKA A, B, C (rotations about Z, Y, X) in B, degrees.
    pub abc_deg: [f64; 3],
}

/// The box the TCP never leaves, in B, and the orientation range.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Workspace {
    /// Lower corner of the box in B, m.
    pub min_xyz_m: [f64; 3],
    /// Upper corner of the box in B, m.
    pub max_xyz_m: [f64; 3],
    /// Allowed deviation from the home orientation, ± per KUKA angle A, B,
    /// C, degrees.
    pub abc_range_deg: [f64; 3],
}

/// Cartesian TCP limits per axis in B.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TcpLimits {
    /// Velocity limit per axis x, y, z, m/s.
    pub velocity_m_s: [f64; 3],
    /// Acceleration limit per axis x, y, z, m/s².
    pub acceleration_m_s2: [f64; 3],
    /// Jerk limit per axis x, y, z, m/s³.
    pub jerk_m_s3: [f64; 3],
    /// Angular rate limit per KUKA angle A, B, C, °/s.
    pub rot_velocity_deg_s: [f64; 3],
    /// Angular acceleration limit per KUKA angle A, B, C, °/s².
    pub rot_acceleration_deg_s2: [f64; 3],
    /// Angular jerk limit per KUKA angle A, B, C, °/s³.
    pub rot_jerk_deg_s3: [f64; 3],
    /// The fastest bat speed a plan may ask for at the hit (faster is
    /// clamped), m/s.
    pub max_bat_speed_m_s: f64,
}

/// The controller's POSCORR / POSCORRMON limits (relative to the start pose).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PosCorrLimits {
    /// Lower POSCORR translation limit per axis x, y, z, mm.
    pub lower_xyz_mm: [f64; 3],
    /// Upper POSCORR translation limit per axis x, y, z, mm.
    pub upper_xyz_mm: [f64; 3],
    /// POSCORR rotation limit, degrees.
    pub max_rot_angle_deg: f64,
    /// POSCORRMON: total (Euclidean) translation that stops the robot, mm.
    pub mon_max_trans_mm: f64,
    /// POSCORRMON: total rotation that stops the robot, degrees.
    pub mon_max_rot_deg: f64,
}

/// RSI timing.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RsiTiming {
    /// Sensor cycle, ms: 4 (#IPO_FAST) or 12 (#IPO).
    pub cycle_ms: u32,
    /// Delay from the request carrying a commanded pose until the robot
    /// reaches it, ms.
    pub lead_ms: u32,
    /// Late answers after which the controller stops RSI (its ETHERNET
    /// timeout).
    pub late_limit: u32,
    /// How long the stroke keeps the hit velocity after the hit before
    /// returning home, s.
    pub follow_through_s: f64,
}

/// A value in `robot.toml` that cannot be used: its key and value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BadKey {
    /// The key, as `section.field`.
    pub key: &'static str,
    /// The bad value (for an array, the first bad element; for the reach
    /// check, the corner's distance from the shoulder, m).
    pub value: f64,
}

fn positive(key: &'static str, v: &[f64]) -> Result<(), BadKey> {
    for &value in v {
        if !(value.is_finite() && value > 0.0) {
            return Err(BadKey { key, value });
        }
    }
    Ok(())
}

fn finite(key: &'static str, v: &[f64]) -> Result<(), BadKey> {
    for &value in v {
        if !value.is_finite() {
            return Err(BadKey { key, value });
        }
    }
    Ok(())
}

impl RobotFile {
    /// Checks every value; the first bad one is named.
    pub fn validate(&self) -> Result<(), BadKey> {
        let r = &self.robot;
        positive("robot.reach_m", &[r.reach_m])?;
        finite("robot.tool_length_m", &[r.tool_length_m])?;
        finite("robot.shoulder_xyz_m", &r.shoulder_xyz_m)?;
        positive("robot.axis_speed_deg_s", &r.axis_speed_deg_s)?;
        finite("cell.base_in_table_xyz_m", &self.cell.base_in_table_xyz_m)?;
        finite("cell.base_yaw_in_table_deg", &[self.cell.base_yaw_in_table_deg])?;
        finite("home.xyz_m", &self.home.xyz_m)?;
        finite("home.abc_deg", &self.home.abc_deg)?;
        let w = &self.workspace;
        finite("workspace.min_xyz_m", &w.min_xyz_m)?;
        finite("workspace.max_xyz_m", &w.max_xyz_m)?;
        positive("workspace.abc_range_deg", &w.abc_range_deg)?;
        for i in 0..3 {
            if w.max_xyz_m[i] - w.min_xyz_m[i] < 0.05 {
                return Err(BadKey { key: "workspace.max_xyz_m", value: w.max_xyz_m[i] });
            }
            if !(w.min_xyz_m[i]..=w.max_xyz_m[i]).contains(&self.home.xyz_m[i]) {
                return Err(BadKey { key: "home.xyz_m", value: self.home.xyz_m[i] });
            }
        }
        // Every corner of the box within reach of the shoulder.
        let radius = r.reach_m + r.tool_length_m.max(0.0);
        for corner in 0..8 {
            let mut d2 = 0.0;
            for i in 0..3 {
                let c = if corner >> i & 1 == 1 { w.max_xyz_m[i] } else { w.min_xyz_m[i] };
                d2 += (c - r.shoulder_xyz_m[i]).powi(2);
            }
            if d2.sqrt() > radius {
                return Err(BadKey { key: "workspace.max_xyz_m", value: d2.sqrt() });
            }
        }
        let l = &self.limits;
        positive("limits.velocity_m_s", &l.velocity_m_s)?;
        positive("limits.acceleration_m_s2", &l.acceleration_m_s2)?;
        positive("limits.jerk_m_s3", &l.jerk_m_s3)?;
        positive("limits.rot_velocity_deg_s", &l.rot_velocity_deg_s)?;
        positive("limits.rot_acceleration_deg_s2", &l.rot_acceleration_deg_s2)?;
        positive("limits.rot_jerk_deg_s3", &l.rot_jerk_deg_s3)?;
        positive("limits.max_bat_speed_m_s", &[l.max_bat_speed_m_s])?;
        if l.max_bat_speed_m_s > l.velocity_m_s.iter().copied().fold(f64::INFINITY, f64::min) {
            return Err(BadKey { key: "limits.max_bat_speed_m_s", value: l.max_bat_speed_m_s });
        }
        // POSCORR must contain workspace − home (so the PC clamps first).
        let p = &self.poscorr;
        finite("poscorr.lower_xyz_mm", &p.lower_xyz_mm)?;
        finite("poscorr.upper_xyz_mm", &p.upper_xyz_mm)?;
        for i in 0..3 {
            let lo = (w.min_xyz_m[i] - self.home.xyz_m[i]) * 1e3;
            let hi = (w.max_xyz_m[i] - self.home.xyz_m[i]) * 1e3;
            if p.lower_xyz_mm[i] > lo {
                return Err(BadKey { key: "poscorr.lower_xyz_mm", value: p.lower_xyz_mm[i] });
            }
            if p.upper_xyz_mm[i] < hi {
                return Err(BadKey { key: "poscorr.upper_xyz_mm", value: p.upper_xyz_mm[i] });
            }
        }
        let rot_total = w.abc_range_deg.iter().map(|a| a * a).sum::<f64>().sqrt();
        positive("poscorr.max_rot_angle_deg", &[p.max_rot_angle_deg])?;
        if p.max_rot_angle_deg < rot_total {
            return Err(BadKey { key: "poscorr.max_rot_angle_deg", value: p.max_rot_angle_deg });
        }
        positive("poscorr.mon_max_trans_mm", &[p.mon_max_trans_mm])?;
        positive("poscorr.mon_max_rot_deg", &[p.mon_max_rot_deg])?;
        let rs = &self.rsi;
        if rs.cycle_ms != 4 && rs.cycle_ms != 12 {
            return Err(BadKey { key: "rsi.cycle_ms", value: rs.cycle_ms as f64 });
        }
        if rs.lead_ms > 100 {
            return Err(BadKey { key: "rsi.lead_ms", value: rs.lead_ms as f64 });
        }
        if rs.late_limit == 0 {
            return Err(BadKey { key: "rsi.late_limit", value: 0.0 });
        }
        if !(rs.follow_through_s.is_finite() && (0.0..=1.0).contains(&rs.follow_through_s)) {
            return Err(BadKey { key: "rsi.follow_through_s", value: rs.follow_through_s });
        }
        Ok(())
    }

    /// Maps a point from B to T.
    pub fn b_to_t(&self, p_b: Vec3) -> Vec3 {
        let (s, c) = self.cell.base_yaw_in_table_deg.to_radians().sin_cos();
        let t = self.cell.base_in_table_xyz_m;
        Vec3::new(c * p_b.x - s * p_b.y + t[0], s * p_b.x + c * p_b.y + t[1], p_b.z + t[2])
    }

    /// Maps a point from T to B.
    pub(crate) fn t_to_b(&self, p_t: Vec3) -> Vec3 {
        self.rotate_t_to_b(p_t - Vec3::from(self.cell.base_in_table_xyz_m))
    }

    /// Rotates a direction (velocity) from T to B.
    pub(crate) fn rotate_t_to_b(&self, v_t: Vec3) -> Vec3 {
        let (s, c) = self.cell.base_yaw_in_table_deg.to_radians().sin_cos();
        Vec3::new(c * v_t.x + s * v_t.y, -s * v_t.x + c * v_t.y, v_t.z)
    }

    /// The base's yaw in T, rad.
    pub fn base_yaw(&self) -> f64 {
        self.cell.base_yaw_in_table_deg.to_radians()
    }

    /// The sensor cycle, s.
    pub(crate) fn cycle_s(&self) -> f64 {
        self.rsi.cycle_ms as f64 * 1e-3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn default_file() -> RobotFile {
        toml::from_str(include_str!("../../../../calib/robot.toml")).unwrap()
    }

    #[test]
    fn default_cell_is_valid_and_consistent() {
        let r = default_file();
        r.validate().unwrap();
        // The hitting plane x_T = 1.60 is inside the box.
        let p = r.t_to_b(Vec3::new(1.60, 0.0, 0.3));
        assert!((p.x - 0.45).abs() < 1e-12);
        assert!(p.x > r.workspace.min_xyz_m[0] && p.x < r.workspace.max_xyz_m[0]);
        let back = r.b_to_t(p);
        assert!((back - Vec3::new(1.60, 0.0, 0.3)).norm() < 1e-12);
    }

    #[test]
    fn bad_values_are_named() {
        let mut r = default_file();
        r.limits.jerk_m_s3[1] = -1.0;
        assert_eq!(r.validate().unwrap_err().key, "limits.jerk_m_s3");
        let mut r = default_file();
        r.workspace.max_xyz_m = [2.0, 2.0, 2.0];
        assert_eq!(r.validate().unwrap_err().key, "workspace.max_xyz_m");
        let mut r = default_file();
        r.rsi.cycle_ms = 5;
        assert_eq!(r.validate().unwrap_err().key, "rsi.cycle_ms");
        let mut r = default_file();
        r.poscorr.upper_xyz_mm[2] = 10.0;
        assert_eq!(r.validate().unwrap_err().key, "poscorr.upper_xyz_mm");
    }
}
