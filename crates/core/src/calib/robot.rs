//! The robot cell (`calib/robot.toml`): the KR 6 R900's joint chain, axis
//! limits and bat (built into a [`kinematics::Arm`] by [`RobotFile::arm`]),
//! where it stands relative to the table (T←B), its home pose, the
//! workspace box, the Cartesian TCP limits, the controller's POSCORR limits
//! and the RSI timing.
//!
//! Owns loading-time validation (every bad value is named by its key; the
//! home pose must have a joint solution within the axis limits) and the
//! conversions to radians. It does not generate motion (`motion`), solve
//! kinematics (`kinematics`) or speak RSI (`rsi`).

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use serde::{Deserialize, Serialize};

use crate::kinematics::{self, Arm, ArmGeometry, JointLimits, Joints, LimitKind, Pose, Unreachable};
use crate::physics::Vec3;

/// `calib/robot.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotFile {
    /// Format version of the file.
    pub version: u32,
    /// `[robot]`: the arm and its bat.
    pub robot: RobotModel,
    /// `[joints]`: the joint chain and the axis limits (files written before
    /// it existed, recordings among them, get the compiled-in KR 6 R900
    /// sixx).
    #[serde(default = "JointAxes::compiled_in")]
    pub joints: JointAxes,
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
    /// `[servo]`: how the axes follow a correction (files written before
    /// it existed get the compiled-in assumption).
    #[serde(default = "ServoModel::compiled_in")]
    pub servo: ServoModel,
    /// `[start]`: how a session starts wherever the arm stands and notices
    /// an arm that stopped following (files written before it existed get
    /// the compiled-in values).
    #[serde(default = "StartPolicy::compiled_in")]
    pub start: StartPolicy,
}

/// `[start]`: what the RSI session does with the arm it finds at RSI start
/// (and after a stop): play where it stands within the home tolerance,
/// else go home at the commissioning speed and rate; refuse a start whose
/// `RIst` is not the forward kinematics of its `AIPos` (another TOOL or
/// BASE); and notice an arm that stops following its commands.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartPolicy {
    /// The arm is home within this distance, mm …
    pub home_tolerance_mm: f64,
    /// … and this turn, degrees.
    pub home_tolerance_deg: f64,
    /// The commissioning speed of the TCP on the way home, mm/s (KUKA's T1
    /// allows 250).
    pub speed_mm_s: f64,
    /// The commissioning rate of the bat's turn on the way home, °/s.
    pub rate_deg_s: f64,
    /// `RIst` against the forward kinematics of `AIPos`: a start off by
    /// this much is refused (TOOL_DATA or BASE_DATA), mm …
    pub frames_tolerance_mm: f64,
    /// … or this much, degrees.
    pub frames_tolerance_deg: f64,
    /// The arm stopped following: `RIst` this far from what the servo model
    /// predicts, mm …
    pub follow_tolerance_mm: f64,
    /// … or turned this far from it, degrees …
    pub follow_tolerance_deg: f64,
    /// … for this many cycles in a row.
    pub follow_cycles: u32,
    /// A stopped arm is tried again once it has stood still this long, s.
    pub still_s: f64,
}

impl StartPolicy {
    /// An arm this far from home (mm, degrees) counts as home.
    pub fn is_home(&self, mm: f64, deg: f64) -> bool {
        mm <= self.home_tolerance_mm && deg <= self.home_tolerance_deg
    }

    /// The `[start]` of the compiled-in `calib/robot.toml`.
    pub fn compiled_in() -> Self {
        let file: RobotFile = toml::from_str(super::DEFAULT_ROBOT).expect("compiled-in calibration is valid (tested)");
        file.start
    }
}

/// How the robot's axes follow a correction, beyond RSI's own cycle: the
/// commanded pose reaches the drives `dead_time_ms` after the cycle that
/// would have it in place (whole cycles), then each axis follows it with a
/// first-order lag of time constant `lag_ms`. Identified on the robot
/// (`topspin identify`); simulated by the mock KR C4 and compensated by
/// the RSI session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ServoModel {
    /// Dead time, ms (a multiple of `rsi.cycle_ms`).
    pub dead_time_ms: f64,
    /// First-order lag time constant, ms.
    pub lag_ms: f64,
}

impl ServoModel {
    /// The `[servo]` of the compiled-in `calib/robot.toml`.
    pub fn compiled_in() -> Self {
        let file: RobotFile = toml::from_str(super::DEFAULT_ROBOT).expect("compiled-in calibration is valid (tested)");
        file.servo
    }

    /// The dead time in whole cycles of `cycle_ms`.
    pub fn dead_time_cycles(&self, cycle_ms: u32) -> u32 {
        (self.dead_time_ms / cycle_ms as f64).round().max(0.0) as u32
    }

    /// The lag's time constant, s.
    pub fn lag_s(&self) -> f64 {
        self.lag_ms * 1e-3
    }
}

/// The share of its gap a first-order lag of time constant `lag_s` closes
/// in a cycle of `dt` s, α = 1 − e^(−dt/τ) (1 without a lag).
pub fn lag_step(dt: f64, lag_s: f64) -> f64 {
    if lag_s > 0.0 { 1.0 - (-dt / lag_s).exp() } else { 1.0 }
}

/// The arm and its bat.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotModel {
    /// Robot model name (informational, shown in the viewer).
    pub model: String,
    /// Flange to bat centre (the TCP) along the flange's z, m.
    pub tool_length_m: f64,
    /// The TCP frame's orientation in the flange frame, KUKA A, B, C,
    /// degrees (`$TOOL` = {0, 0, tool_length, A, B, C}; the bat below a
    /// downward flange, {0, 0, 180}, where a file does not say).
    #[serde(default = "bat_below_flange")]
    pub tool_abc_deg: [f64; 3],
    /// Keys of files written before `[joints]` (recordings keep them):
    /// read and ignored; the reach now follows from the joint chain, the
    /// shoulder and the axis speeds live in `[joints]`.
    #[serde(default, skip_serializing)]
    pub reach_m: Option<f64>,
    /// Ignored (see `reach_m`).
    #[serde(default, skip_serializing)]
    pub shoulder_xyz_m: Option<[f64; 3]>,
    /// Ignored (see `reach_m`).
    #[serde(default, skip_serializing)]
    pub axis_speed_deg_s: Option<[f64; 6]>,
}

fn bat_below_flange() -> [f64; 3] {
    [0.0, 0.0, 180.0]
}

impl JointAxes {
    /// The `[joints]` of the compiled-in `calib/robot.toml`.
    pub fn compiled_in() -> Self {
        let file: RobotFile = toml::from_str(super::DEFAULT_ROBOT).expect("compiled-in calibration is valid (tested)");
        file.joints
    }
}

/// The joint chain (DESIGN §11) and the axis limits, A1..A6.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointAxes {
    /// Each joint's origin in the previous link's frame, m (the
    /// description's table; the zeros must stay zeros).
    pub origin_xyz_m: [[f64; 3]; 6],
    /// Lower software limit switches, degrees.
    pub min_deg: [f64; 6],
    /// Upper software limit switches, degrees.
    pub max_deg: [f64; 6],
    /// Axis speed limits, °/s.
    pub speed_deg_s: [f64; 6],
    /// Axis acceleration limits, °/s² (assumptions to identify).
    pub acceleration_deg_s2: [f64; 6],
    /// |A5| below this is the singular wrist, degrees.
    pub singular_a5_deg: f64,
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
    /// check, the corner's distance from the A1 axis at shoulder height, m;
    /// for the home pose, the joint angle that breaks its limit, degrees).
    pub value: f64,
}

/// KUKA's T1 limit on the TCP's speed, mm/s: `[start] speed_mm_s` stays within it.
pub(crate) const T1_SPEED_MM_S: f64 = 250.0;
/// The fastest commissioning turn `[start] rate_deg_s` may name, °/s.
pub(crate) const MAX_COMMISSIONING_RATE_DEG_S: f64 = 90.0;

/// The longest dead time `[servo]` may name, ms.
pub(crate) const MAX_DEAD_TIME_MS: f64 = 100.0;
/// The longest lag `[servo]` may name, ms.
pub(crate) const MAX_LAG_MS: f64 = 200.0;

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
        finite("robot.tool_length_m", &[r.tool_length_m])?;
        finite("robot.tool_abc_deg", &r.tool_abc_deg)?;
        let j = &self.joints;
        finite("joints.origin_xyz_m", j.origin_xyz_m.as_flattened())?;
        let geometry = ArmGeometry::from_origins(&j.origin_xyz_m, Pose::identity())
            .map_err(|e| BadKey { key: "joints.origin_xyz_m", value: e.value })?;
        finite("joints.min_deg", &j.min_deg)?;
        finite("joints.max_deg", &j.max_deg)?;
        for i in 0..6 {
            if !(-360.0..=360.0).contains(&j.min_deg[i]) {
                return Err(BadKey { key: "joints.min_deg", value: j.min_deg[i] });
            }
            if !(-360.0..=360.0).contains(&j.max_deg[i]) || j.max_deg[i] <= j.min_deg[i] {
                return Err(BadKey { key: "joints.max_deg", value: j.max_deg[i] });
            }
        }
        positive("joints.speed_deg_s", &j.speed_deg_s)?;
        positive("joints.acceleration_deg_s2", &j.acceleration_deg_s2)?;
        if !(0.0..45.0).contains(&j.singular_a5_deg) {
            return Err(BadKey { key: "joints.singular_a5_deg", value: j.singular_a5_deg });
        }
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
        // Every corner of the box within reach: the wrist centre gets
        // `reach` from the A1 axis at shoulder height, the TCP at most
        // flange + tool_length beyond it.
        let radius = geometry.reach() + geometry.flange + r.tool_length_m.abs();
        let shoulder = [0.0, 0.0, geometry.shoulder_height];
        for corner in 0..8 {
            let mut d2 = 0.0;
            for i in 0..3 {
                let c = if corner >> i & 1 == 1 { w.max_xyz_m[i] } else { w.min_xyz_m[i] };
                d2 += (c - shoulder[i]).powi(2);
            }
            if d2.sqrt() > radius {
                return Err(BadKey { key: "workspace.max_xyz_m", value: d2.sqrt() });
            }
        }
        // The home pose: some joint solution within the limits, off the
        // singular wrist.
        let arm = self.arm();
        if self.home_joints(&arm).is_none() {
            let home = self.home_pose();
            return Err(match arm.inverse_near(&home, &Joints::kuka_home()) {
                Err(Unreachable::OutOfReach) => {
                    BadKey { key: "home.xyz_m (out of the arm's reach)", value: self.home.xyz_m[0] }
                }
                Err(Unreachable::Limit(v)) => BadKey {
                    key: "home.xyz_m (no joint solution within joints.min_deg / joints.max_deg)",
                    value: v.value.to_degrees(),
                },
                Ok(q) => match arm.limits.check_position(&q) {
                    Err(v) if v.kind == LimitKind::SingularWrist => BadKey {
                        key: "home.abc_deg (singular wrist: |A5| under joints.singular_a5_deg)",
                        value: v.value.to_degrees(),
                    },
                    _ => BadKey { key: "home.xyz_m (no joint solution within the joint limits)", value: f64::NAN },
                },
            });
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
        // And POSCORRMON every corner of the box: the monitor stops the
        // robot where the PC side still lets a stroke go.
        let corner_mm = (0..8)
            .map(|k: usize| {
                let d: [f64; 3] = core::array::from_fn(|i| {
                    (if k >> i & 1 == 0 { w.min_xyz_m[i] } else { w.max_xyz_m[i] }) - self.home.xyz_m[i]
                });
                1e3 * d.iter().map(|x| x * x).sum::<f64>().sqrt()
            })
            .fold(0.0, f64::max);
        if p.mon_max_trans_mm < corner_mm {
            return Err(BadKey { key: "poscorr.mon_max_trans_mm", value: p.mon_max_trans_mm });
        }
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
        let sv = &self.servo;
        let cycles = sv.dead_time_ms / rs.cycle_ms as f64;
        if !(sv.dead_time_ms.is_finite() && (0.0..=MAX_DEAD_TIME_MS).contains(&sv.dead_time_ms))
            || (cycles - cycles.round()).abs() > 1e-6
        {
            return Err(BadKey { key: "servo.dead_time_ms (whole cycles, 0-100 ms)", value: sv.dead_time_ms });
        }
        if !(sv.lag_ms.is_finite() && (0.0..=MAX_LAG_MS).contains(&sv.lag_ms)) {
            return Err(BadKey { key: "servo.lag_ms (0-200 ms)", value: sv.lag_ms });
        }
        let st = &self.start;
        positive("start.home_tolerance_mm", &[st.home_tolerance_mm])?;
        positive("start.home_tolerance_deg", &[st.home_tolerance_deg])?;
        positive("start.speed_mm_s", &[st.speed_mm_s])?;
        if st.speed_mm_s > T1_SPEED_MM_S {
            return Err(BadKey { key: "start.speed_mm_s (KUKA T1: at most 250)", value: st.speed_mm_s });
        }
        positive("start.rate_deg_s", &[st.rate_deg_s])?;
        if st.rate_deg_s > MAX_COMMISSIONING_RATE_DEG_S {
            return Err(BadKey { key: "start.rate_deg_s (at most 90)", value: st.rate_deg_s });
        }
        positive("start.frames_tolerance_mm", &[st.frames_tolerance_mm])?;
        positive("start.frames_tolerance_deg", &[st.frames_tolerance_deg])?;
        positive("start.follow_tolerance_mm", &[st.follow_tolerance_mm])?;
        positive("start.follow_tolerance_deg", &[st.follow_tolerance_deg])?;
        if !(1..=100).contains(&st.follow_cycles) {
            return Err(BadKey { key: "start.follow_cycles (1-100)", value: st.follow_cycles as f64 });
        }
        positive("start.still_s", &[st.still_s])?;
        Ok(())
    }

    /// The arm: its kinematics (chain and bat) and axis limits, in SI. For a
    /// file that passed [`validate`](Self::validate) (panics on a chain
    /// that validation rejects).
    pub fn arm(&self) -> Arm {
        let (r, j) = (&self.robot, &self.joints);
        let tool = Pose::from_xyz_abc([0.0, 0.0, r.tool_length_m], r.tool_abc_deg.map(f64::to_radians));
        Arm {
            geometry: ArmGeometry::from_origins(&j.origin_xyz_m, tool)
                .expect("joints.origin_xyz_m has the chain's shape (validated)"),
            limits: JointLimits {
                min: j.min_deg.map(f64::to_radians),
                max: j.max_deg.map(f64::to_radians),
                speed: j.speed_deg_s.map(f64::to_radians),
                acceleration: j.acceleration_deg_s2.map(f64::to_radians),
                singular_a5: j.singular_a5_deg.to_radians(),
            },
        }
    }

    /// The home (RSI start) pose of the TCP in B.
    pub fn home_pose(&self) -> Pose {
        Pose::from_xyz_abc(self.home.xyz_m, self.home.abc_deg.map(f64::to_radians))
    }

    /// The joints at the home pose: of the solutions within the limits and
    /// off the singular wrist, the one nearest KUKA's mechanical home
    /// ({0, −90, 90, 0, 90, 0}°). `None` when there is none (a validated
    /// file always has one).
    pub fn home_joints(&self, arm: &Arm) -> Option<Joints> {
        let kuka_home = Joints::kuka_home();
        let mut fitting: heapless::Vec<Joints, { kinematics::MAX_SOLUTIONS }> = heapless::Vec::new();
        for s in &arm.inverse(&self.home_pose()) {
            if let Some(q) = arm.nearest(core::slice::from_ref(s), &kuka_home)
                && arm.limits.check_position(&q).is_ok()
            {
                let _ = fitting.push(q); // at most as many as solutions
            }
        }
        arm.nearest(&fitting, &kuka_home)
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
    fn servo_is_whole_cycles_and_bounded_and_old_files_get_the_assumption() {
        let f = default_file();
        assert_eq!(f.servo.dead_time_cycles(f.rsi.cycle_ms), 3);
        assert!((f.servo.lag_s() - 0.015).abs() < 1e-12);
        for (dead, lag, key) in [
            (10.0, 15.0, "servo.dead_time_ms (whole cycles, 0-100 ms)"),
            (-4.0, 15.0, "servo.dead_time_ms (whole cycles, 0-100 ms)"),
            (f64::NAN, 15.0, "servo.dead_time_ms (whole cycles, 0-100 ms)"),
            (12.0, -1.0, "servo.lag_ms (0-200 ms)"),
            (12.0, f64::INFINITY, "servo.lag_ms (0-200 ms)"),
        ] {
            let mut g = f.clone();
            g.servo = ServoModel { dead_time_ms: dead, lag_ms: lag };
            assert_eq!(g.validate().unwrap_err().key, key, "{dead} {lag}");
        }
        let text = include_str!("../../../../calib/robot.toml");
        let old: RobotFile = toml::from_str(&text[..text.find("[servo]").unwrap()]).unwrap();
        assert_eq!(old.servo, f.servo);
    }

    #[test]
    fn files_from_before_the_joints_section_still_load() {
        // A version-1 file as recordings made before `[joints]` carry it.
        let text = include_str!("../../../../calib/robot.toml");
        let start = text.find("\n[joints]").unwrap();
        let end = text.find("\n[cell]").unwrap();
        let old = format!("{}{}", &text[..start], &text[end..]).replace(
            "tool_abc_deg = [0.0, 0.0, 180.0]",
            "reach_m = 0.901\nshoulder_xyz_m = [0.025, 0.0, 0.400]\naxis_speed_deg_s = [360.0, 300.0, 360.0, 381.0, 388.0, 615.0]",
        );
        assert!(!old.contains("\n[joints]") && !old.contains("\ntool_abc_deg =") && old.contains("reach_m"));
        let r: RobotFile = toml::from_str(&old).unwrap();
        r.validate().unwrap();
        assert_eq!(r.joints, default_file().joints);
        assert_eq!(r.arm(), default_file().arm());
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
    fn the_arm_is_the_description_with_the_bat() {
        let r = default_file();
        let arm = r.arm();
        let bat = Pose::from_xyz_abc([0.0, 0.0, 0.20], [0.0, 0.0, std::f64::consts::PI]);
        assert_eq!(arm.geometry, ArmGeometry::kr6_r900_sixx(bat));
        assert!((arm.geometry.reach() - 0.901).abs() < 1e-3);
        assert_eq!(arm.limits.max[1], 45f64.to_radians());
        assert_eq!(arm.limits.speed[5], 615f64.to_radians());
        // KUKA's mechanical home: the bat 0.20 m below the flange at
        // (0.445, 0, 0.810), its frame A = 180° (the neutral bat).
        let tcp = arm.tcp(&Joints::kuka_home());
        let want = Pose::from_xyz_abc([0.445, 0.0, 0.610], [std::f64::consts::PI, 0.0, 0.0]);
        let (dp, dr) = tcp.distance(&want);
        assert!(dp < 1e-12 && dr < 1e-12, "{tcp:?}");
    }

    #[test]
    fn home_has_a_joint_solution_within_the_limits() {
        let r = default_file();
        let arm = r.arm();
        let q = r.home_joints(&arm).unwrap();
        // The wrist centre 0.28 m above the TCP at (0.35, 0, 0.73): the
        // elbow triangle (0.455, hypot(0.420, 0.035), shoulder → wrist)
        // gives A2, A3; A5 bends the flange down: A2 + A3 + A5 = 90°.
        let (u, v) = (0.35 - 0.025, 0.73 - 0.400);
        let l3 = 0.420f64.hypot(0.035);
        let c = (u * u + v * v - 0.455f64.powi(2) - l3 * l3) / (2.0 * 0.455 * l3);
        let e = -c.acos();
        let a2 = -(v.atan2(u) - (l3 * e.sin()).atan2(0.455 + l3 * e.cos()));
        let a3 = 0.035f64.atan2(0.420) - e;
        let want = Joints([0.0, a2, a3, 0.0, std::f64::consts::FRAC_PI_2 - a2 - a3, 0.0]);
        assert!(q.max_abs_diff(&want) < 1e-12, "{:?}", q.degrees());
        let d = q.degrees();
        assert!(
            (d[1] + 100.076).abs() < 1e-3 && (d[2] - 121.096).abs() < 1e-3 && (d[4] - 68.980).abs() < 1e-3,
            "{d:?}"
        );
        assert_eq!(arm.limits.check_position(&q), Ok(()));
        let (dp, dr) = arm.tcp(&q).distance(&r.home_pose());
        assert!(dp < 1e-12 && dr < 1e-12);
        // The flipped wrist {0, a2, a3, 180, −A5, 180} fits too.
        let flipped = arm.inverse(&r.home_pose()).iter().filter(|s| arm.limits.check_position(s).is_ok()).count();
        assert_eq!(flipped, 2);
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
        // The monitor must let the arm reach the box's far corners.
        let mut r = default_file();
        r.poscorr.mon_max_trans_mm = 900.0;
        assert_eq!(r.validate().unwrap_err(), BadKey { key: "poscorr.mon_max_trans_mm", value: 900.0 });
        let mut r = default_file();
        r.joints.origin_xyz_m[3][1] = 0.01;
        assert_eq!(r.validate().unwrap_err(), BadKey { key: "joints.origin_xyz_m", value: 0.01 });
        let mut r = default_file();
        r.joints.max_deg[2] = -130.0;
        assert_eq!(r.validate().unwrap_err(), BadKey { key: "joints.max_deg", value: -130.0 });
        let mut r = default_file();
        r.joints.speed_deg_s[4] = 0.0;
        assert_eq!(r.validate().unwrap_err().key, "joints.speed_deg_s");
        let mut r = default_file();
        r.joints.acceleration_deg_s2[0] = f64::NAN;
        assert_eq!(r.validate().unwrap_err().key, "joints.acceleration_deg_s2");
        let mut r = default_file();
        r.joints.singular_a5_deg = -1.0;
        assert_eq!(r.validate().unwrap_err().key, "joints.singular_a5_deg");
        let mut r = default_file();
        r.robot.tool_abc_deg[1] = f64::INFINITY;
        assert_eq!(r.validate().unwrap_err().key, "robot.tool_abc_deg");
        // Home out of the limits: A5 within ±60° cannot bend the bat down.
        let mut r = default_file();
        (r.joints.min_deg[4], r.joints.max_deg[4]) = (-60.0, 60.0);
        let e = r.validate().unwrap_err();
        assert!(e.key.starts_with("home.xyz_m (no joint solution"), "{e:?}");
        assert!((e.value.abs() - 68.98).abs() < 0.01, "{e:?}");
        // ... in the singular band (the bat tilted 50°: |A5| = 19.3°) ...
        let mut r = default_file();
        r.joints.singular_a5_deg = 30.0;
        r.home.abc_deg = [180.0, 50.0, 0.0];
        let e = r.validate().unwrap_err();
        assert!(e.key.starts_with("home.abc_deg (singular wrist"), "{e:?}");
        assert!(e.value.abs() > 19.0 && e.value.abs() < 20.0, "{e:?}");
        // ... or out of reach (a longer bat reaches the box, a shorter arm not home).
        let mut r = default_file();
        r.joints.origin_xyz_m[2][0] = 0.2;
        r.joints.origin_xyz_m[4][0] = 0.2;
        r.robot.tool_length_m = 0.7;
        assert_eq!(r.validate().unwrap_err().key, "home.xyz_m (out of the arm's reach)");
    }
}
