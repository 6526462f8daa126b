//! Kinematics of the KUKA KR 6 R900 sixx (KR AGILUS), DESIGN §11: forward
//! kinematics, the closed-form inverse (all solutions), the choice of the
//! solution that keeps the configuration continuous, and the joint limits
//! the KR C4 enforces (software limit switches, axis speed and
//! acceleration, the singular wrist).
//!
//! # The chain
//!
//! The joint chain of ROS-Industrial's `kuka_kr6_support`
//! (`kr6r900sixx_macro.xacro`): each joint's origin is a translation in the
//! previous link's frame (all origins rpy = 0), then a rotation about the
//! joint's axis. The description's axes are A1 −z, A2 +y, A3 +y, A4 −x,
//! A5 +y, A6 −x, chosen so that a joint value *is* the KUKA angle the KR C4
//! shows: a positive KUKA angle turns about the listed (negative) axis, so
//! A1 > 0 turns the arm clockwise seen from above, A2 = −90° stands the
//! upper arm up. With the description's numbers ([`ArmGeometry::kr6_r900_sixx`]):
//!
//! ```text
//! base_link = $ROBROOT (B), at the foot on the A1 axis
//!   A1: Tz(0.400)  Rz(−A1)
//!   A2: Tx(0.025)  Ry(A2)
//!   A3: Tx(0.455)  Ry(A3)
//!   A4: Tz(0.035)  Rx(−A4)
//!   A5: Tx(0.420)  Ry(A5)        wrist centre (A4, A5, A6 meet here)
//!   A6: Tx(0.080)  Rx(−A6)
//!   $FLANGE = tool0 = link_6 · Ry(90°)   (z out of the flange)
//!   TCP = $FLANGE · $TOOL                ([`ArmGeometry::tool`])
//! ```
//!
//! All joints zero: the arm stretched along x_B, the flange at
//! (0.980, 0, 0.435) with A, B, C = 0°, 90°, 0°. KUKA's mechanical home
//! {A1 0, A2 −90, A3 90, A4 0, A5 90, A6 0}: the flange at (0.445, 0, 0.810)
//! pointing down.
//!
//! # The inverse
//!
//! Closed form, because A4, A5 and A6 meet in one point (the wrist centre)
//! and A2, A3, A5 are parallel: the wrist centre fixes A1 (front or back:
//! the wrist in front of the A1 axis or behind it, "overhead"), A2 and A3
//! (elbow up or down, a triangle); the rest of the orientation fixes A4, A5,
//! A6 (wrist flipped or not). Up to [`MAX_SOLUTIONS`] = 2 × 2 × 2 joint
//! vectors, each checked by forward kinematics before it is returned.
//! Angles come back in (−π, π]; [`Arm::nearest`] adds the turns (± 360° on
//! A4 and A6, whose limits allow them) that bring a solution closest to the
//! current joints.
//!
//! Singular wrist (A5 = 0: A4 and A6 on one line): only A4 + A6 is fixed.
//! The split is KUKA's `$SINGUL_POS[3]`: [`ArmGeometry::inverse`] keeps
//! A4 = 0 (`$SINGUL_POS[3] = 0`), [`Arm::inverse_near`] keeps the current
//! A4 (`= 1`); A6 takes the rest. The overhead singularity (wrist centre on
//! the A1 axis) is split the same way for A1.
//!
//! Internally SI (m, rad); the module owns no clock, no I/O and allocates
//! nothing. It does not decide what the robot does at a limit (the mock
//! KR C4 and the planner do) and it does not read `calib/` (the calibration
//! builds an [`Arm`]: `RobotFile::arm`).

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use std::f64::consts::{PI, TAU};
use std::fmt;

use heapless::Vec as HVec;
use nalgebra::{Matrix3, Rotation3};

use crate::geometry::{Pose6, rot_zyx, wrap_pi, zyx_angles};
use crate::physics::Vec3;

/// The number of axes.
pub const AXES: usize = 6;
/// The frames of [`ArmGeometry::frames`]: the base, one per axis, the TCP.
pub const FRAMES: usize = AXES + 2;

/// The most solutions one pose has: shoulder front/back × elbow up/down ×
/// wrist flipped or not.
pub const MAX_SOLUTIONS: usize = 8;

/// The solutions of one inverse-kinematics problem (no allocation).
pub type Solutions = HVec<Joints, MAX_SOLUTIONS>;

/// Below this, sin A5 counts as exactly singular in the inverse (A4 is
/// then chosen, not computed). Above it the computed split is used; both
/// reproduce the pose to rounding.
const SINGULAR_SIN: f64 = 1e-12;
/// Below this distance of the wrist centre from the A1 axis (m), A1 is
/// chosen, not computed (the overhead singularity).
const OVERHEAD_EPS: f64 = 1e-12;
/// Slack on the elbow triangle's cosine before a wrist centre counts as
/// out of reach (rounding at full stretch).
const REACH_SLACK: f64 = 1e-12;
/// Every solution [`ArmGeometry::inverse`] returns reproduces the pose to
/// this (m, and rad of rotation); a gross-error guard, far above rounding.
const FK_CHECK: f64 = 1e-6;

/// A joint vector A1..A6, rad, in KUKA's sign convention (as the KR C4's
/// `AIPos` shows it, in radians).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Joints(pub [f64; AXES]);

impl Joints {
    /// From degrees (as the KR C4 shows them).
    pub fn from_degrees(deg: [f64; AXES]) -> Self {
        Joints(deg.map(f64::to_radians))
    }

    /// In degrees.
    pub fn degrees(&self) -> [f64; AXES] {
        self.0.map(f64::to_degrees)
    }

    /// KUKA's mechanical home {A1 0, A2 −90, A3 90, A4 0, A5 90, A6 0}
    /// (DESIGN §11): upper arm up, forearm forward, flange down. Not the
    /// cell's home, which is a TCP pose (`calib/robot.toml [home]`).
    pub fn kuka_home() -> Self {
        Joints::from_degrees([0.0, -90.0, 90.0, 0.0, 90.0, 0.0])
    }

    /// The largest |self − other| over the axes, rad.
    pub fn max_abs_diff(&self, other: &Joints) -> f64 {
        (0..AXES).map(|i| (self.0[i] - other.0[i]).abs()).fold(0.0, f64::max)
    }
}

/// One axis, A1..A6.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Axis {
    /// Base rotation (about −z).
    A1,
    /// Shoulder (about y).
    A2,
    /// Elbow (about y).
    A3,
    /// Forearm roll (about −x).
    A4,
    /// Wrist bend (about y); singular at 0.
    A5,
    /// Flange roll (about −x).
    A6,
}

impl Axis {
    /// A1..A6 in order.
    pub const ALL: [Axis; AXES] = [Axis::A1, Axis::A2, Axis::A3, Axis::A4, Axis::A5, Axis::A6];

    /// The index into a [`Joints`] (A1 = 0).
    pub fn index(self) -> usize {
        self as usize
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "A{}", self.index() + 1)
    }
}

/// A frame in B (or, for a tool, in the flange frame): position, m, and
/// rotation (the frame's axes as columns).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Origin, m.
    pub position: Vec3,
    /// Orientation.
    pub rotation: Rotation3<f64>,
}

impl Pose {
    /// The identity frame.
    pub fn identity() -> Self {
        Pose { position: Vec3::zeros(), rotation: Rotation3::identity() }
    }

    /// From a position (m) and KUKA A, B, C (rad): R = Rz(A)·Ry(B)·Rx(C),
    /// as [`rot_zyx`].
    pub fn from_xyz_abc(xyz: [f64; 3], abc: [f64; 3]) -> Self {
        Pose { position: Vec3::from(xyz), rotation: Rotation3::from_matrix_unchecked(rot_zyx(abc[0], abc[1], abc[2])) }
    }

    /// KUKA A, B, C (rad) of the rotation: A, C in (−π, π], B in
    /// [−π/2, π/2]. At B = ±90° (gimbal lock) A = 0 and C takes the rest.
    pub fn abc(&self) -> [f64; 3] {
        zyx_angles(self.rotation.matrix())
    }

    /// From a motion pose `[x, y, z, a, b, c]` (m, rad; KUKA A/B/C).
    pub fn from_pose6(p: &Pose6) -> Self {
        Pose::from_xyz_abc([p[0], p[1], p[2]], [p[3], p[4], p[5]])
    }

    /// As a motion pose `[x, y, z, a, b, c]` (angles as [`Pose::abc`];
    /// unwrap them near a reference where continuity matters).
    pub fn to_pose6(&self) -> Pose6 {
        let [a, b, c] = self.abc();
        [self.position.x, self.position.y, self.position.z, a, b, c]
    }

    /// `self · local`: the frame `local` (given in `self`) in `self`'s
    /// parent frame.
    pub fn compose(&self, local: &Pose) -> Pose {
        Pose { position: self.position + self.rotation * local.position, rotation: self.rotation * local.rotation }
    }

    /// The inverse frame: `self.compose(&self.inverse())` is the identity.
    pub fn inverse(&self) -> Pose {
        let r = self.rotation.transpose();
        Pose { position: -(r * self.position), rotation: r }
    }

    /// Distance to `other`: position (m) and the angle of the relative
    /// rotation (rad), accurate down to rounding (no `acos` of a trace).
    pub fn distance(&self, other: &Pose) -> (f64, f64) {
        let chord = (self.rotation.matrix() - other.rotation.matrix()).norm(); // = 2√2·sin(θ/2)
        ((self.position - other.position).norm(), 2.0 * (chord / (2.0 * std::f64::consts::SQRT_2)).min(1.0).asin())
    }
}

/// The arm's link lengths (the origin table of DESIGN §11) and its tool.
///
/// The closed form needs the description's structure: A1 on the z axis of
/// B, every link in the arm's plane (no y offsets), the wrist axes meeting
/// in one point. Within it the lengths are calibration values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmGeometry {
    /// A2 axis above the foot (A1 origin, z), m.
    pub shoulder_height: f64,
    /// A2 axis ahead of the A1 axis (A2 origin, x), m.
    pub shoulder_offset: f64,
    /// A2 → A3 (A3 origin, x), m.
    pub upper_arm: f64,
    /// A3 → A4 axis, across the upper arm (A4 origin, z), m.
    pub elbow_offset: f64,
    /// A4 origin → wrist centre along A4 (A5 origin, x), m.
    pub forearm: f64,
    /// Wrist centre → flange along A6 (A6 origin, x), m.
    pub flange: f64,
    /// `$TOOL`: the TCP in the flange frame.
    pub tool: Pose,
}

/// A joint chain the closed form cannot solve: the first origin entry that
/// breaks the structure ([`ArmGeometry`]).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("origin of {axis}, coordinate {coordinate}: {value} does not fit the KR 6 R900's chain")]
pub struct UnsupportedChain {
    /// The joint whose origin is off.
    pub axis: Axis,
    /// 0, 1, 2 = x, y, z.
    pub coordinate: usize,
    /// The value found.
    pub value: f64,
}

/// The joint origins of `kr6r900sixx_macro.xacro`, m, A1..A6 (DESIGN §11).
#[rustfmt::skip]
pub const KR6_R900_SIXX_ORIGINS: [[f64; 3]; AXES] = [
    [0.0, 0.0, 0.400],
    [0.025, 0.0, 0.0],
    [0.455, 0.0, 0.0],
    [0.0, 0.0, 0.035],
    [0.420, 0.0, 0.0],
    [0.080, 0.0, 0.0],
];

/// Which entries of the origin table the closed form allows to be non-zero
/// (x, y, z per joint), and which of those must be positive.
const FREE: [[bool; 3]; AXES] = [
    [false, false, true],
    [true, false, false],
    [true, false, false],
    [false, false, true],
    [true, false, false],
    [true, false, false],
];

/// Ry(90°), exactly: $FLANGE in link_6.
fn ry90() -> Rotation3<f64> {
    Rotation3::from_matrix_unchecked(Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0))
}

fn rx(t: f64) -> Rotation3<f64> {
    let (s, c) = t.sin_cos();
    Rotation3::from_matrix_unchecked(Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c))
}

fn ry(t: f64) -> Rotation3<f64> {
    let (s, c) = t.sin_cos();
    Rotation3::from_matrix_unchecked(Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c))
}

fn rz(t: f64) -> Rotation3<f64> {
    let (s, c) = t.sin_cos();
    Rotation3::from_matrix_unchecked(Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0))
}

/// Forward kinematics: every frame the KR C4 reports, in B.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmPose {
    /// The wrist centre (where A4, A5, A6 meet), m.
    pub wrist: Vec3,
    /// `$FLANGE` (tool0).
    pub flange: Pose,
    /// The TCP (the bat centre): `flange · tool`.
    pub tcp: Pose,
}

/// Where a joint vector sits among the inverse's branches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Configuration {
    /// The wrist centre is behind the A1 axis (negative x in the frame
    /// that turns with A1): KUKA's overhead area.
    pub overhead: bool,
    /// A3 beyond the stretched elbow (A3 > atan2(elbow_offset, forearm),
    /// within half a turn): in the basic area, the elbow above the
    /// shoulder–wrist line.
    pub elbow_up: bool,
    /// A5 < 0.
    pub wrist_flipped: bool,
}

impl ArmGeometry {
    /// The description's chain ([`KR6_R900_SIXX_ORIGINS`]) with `tool`.
    pub fn kr6_r900_sixx(tool: Pose) -> Self {
        Self::from_origins(&KR6_R900_SIXX_ORIGINS, tool).expect("the description's chain fits (tested)")
    }

    /// From the origin table (m, A1..A6, in the previous link's frame, as
    /// in DESIGN §11) and the tool. Entries that are zero in the
    /// description must stay zero; the upper arm and forearm must be
    /// positive, the rest finite and not negative.
    pub fn from_origins(origins: &[[f64; 3]; AXES], tool: Pose) -> Result<Self, UnsupportedChain> {
        for (j, row) in origins.iter().enumerate() {
            for (k, &value) in row.iter().enumerate() {
                let ok = if FREE[j][k] {
                    let positive = j == 2 || j == 4;
                    value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 }
                } else {
                    value == 0.0
                };
                if !ok {
                    return Err(UnsupportedChain { axis: Axis::ALL[j], coordinate: k, value });
                }
            }
        }
        Ok(ArmGeometry {
            shoulder_height: origins[0][2],
            shoulder_offset: origins[1][0],
            upper_arm: origins[2][0],
            elbow_offset: origins[3][2],
            forearm: origins[4][0],
            flange: origins[5][0],
            tool,
        })
    }

    /// A3 at the stretched elbow (the forearm's wrist centre on the upper
    /// arm's line), rad.
    pub fn stretched_a3(&self) -> f64 {
        self.elbow_offset.atan2(self.forearm)
    }

    /// The farthest the wrist centre gets from the A1 axis, m (the
    /// datasheet's reach, 0.901 m).
    pub fn reach(&self) -> f64 {
        self.shoulder_offset + self.upper_arm + self.forearm.hypot(self.elbow_offset)
    }

    /// Forward kinematics of `q`: the wrist, flange and TCP of
    /// [`frames`](Self::frames).
    pub fn forward(&self, q: &Joints) -> ArmPose {
        let f = self.frames(q);
        ArmPose {
            wrist: f[5].position,
            flange: Pose { position: f[6].position, rotation: f[6].rotation * ry90() },
            tcp: f[7],
        }
    }

    /// Every link frame of `q` in B, foot to bat ([`FRAMES`] of them):
    /// `[0]` B itself (the foot, on the A1 axis); `[i]`, i = 1..=6, joint
    /// Ai's frame (link i): at the joint's origin, turned by the joint
    /// (`[5]` is the wrist centre, `[6]` link_6 at the flange, whose
    /// `$FLANGE` is `[6]`·Ry(90°)); `[7]` the TCP, the same as
    /// [`forward`](Self::forward)'s. Consecutive origins are the ends of
    /// the arm's links (the foot's column, the shoulder offset, the upper
    /// arm, the elbow offset, the forearm, the wrist, the tool). A fixed
    /// array: nothing allocated.
    pub fn frames(&self, q: &Joints) -> [Pose; FRAMES] {
        let q = &q.0;
        let p1 = Vec3::new(0.0, 0.0, self.shoulder_height);
        let r1 = rz(-q[0]);
        let p2 = p1 + r1 * Vec3::new(self.shoulder_offset, 0.0, 0.0);
        let r2 = r1 * ry(q[1]);
        let p3 = p2 + r2 * Vec3::new(self.upper_arm, 0.0, 0.0);
        let r3 = r2 * ry(q[2]);
        let p4 = p3 + r3 * Vec3::new(0.0, 0.0, self.elbow_offset);
        let r4 = r3 * rx(-q[3]);
        let wrist = p4 + r4 * Vec3::new(self.forearm, 0.0, 0.0);
        let r5 = r4 * ry(q[4]);
        let p6 = wrist + r5 * Vec3::new(self.flange, 0.0, 0.0);
        let r6 = r5 * rx(-q[5]);
        let flange = Pose { position: p6, rotation: r6 * ry90() };
        let at = |position, rotation| Pose { position, rotation };
        [
            Pose::identity(),
            at(p1, r1),
            at(p2, r2),
            at(p3, r3),
            at(p4, r4),
            at(wrist, r5),
            at(p6, r6),
            flange.compose(&self.tool),
        ]
    }

    /// The TCP pose of `q` (forward kinematics).
    pub fn tcp(&self, q: &Joints) -> Pose {
        self.forward(q).tcp
    }

    /// The branch `q` lies on.
    pub fn configuration(&self, q: &Joints) -> Configuration {
        let w = self.forward(q).wrist;
        let (s1, c1) = q.0[0].sin_cos();
        Configuration {
            overhead: w.x * c1 - w.y * s1 < 0.0,
            elbow_up: wrap_pi(q.0[2] - self.stretched_a3()) > 0.0,
            wrist_flipped: q.0[4] < 0.0,
        }
    }

    /// Every joint vector (up to [`MAX_SOLUTIONS`], angles in (−π, π])
    /// that puts the TCP at `tcp`, limits not applied; empty when the pose
    /// is out of reach. At the singular wrist A4 = 0, at the overhead
    /// singularity A1 = 0 (KUKA's `$SINGUL_POS` = 0). Order: shoulder
    /// front, back; elbow up, down; wrist not flipped, flipped.
    pub fn inverse(&self, tcp: &Pose) -> Solutions {
        self.inverse_flange(&tcp.compose(&self.tool.inverse()), 0.0, 0.0)
    }

    /// As [`inverse`](Self::inverse) for a flange pose, with the A1 and A4
    /// that the overhead and wrist singularities keep.
    pub fn inverse_flange(&self, flange: &Pose, singular_a1: f64, singular_a4: f64) -> Solutions {
        let mut out = Solutions::new();
        let r6 = flange.rotation * ry90().transpose(); // link_6: x along A6
        let w = flange.position - r6 * Vec3::new(self.flange, 0.0, 0.0);
        let rho = w.x.hypot(w.y);
        let a1_front = if rho < OVERHEAD_EPS { singular_a1 } else { (-w.y).atan2(w.x) };
        let l3 = self.forearm.hypot(self.elbow_offset);
        let delta = self.stretched_a3();
        for (q1, r) in [(wrap_pi(a1_front), rho), (wrap_pi(a1_front + PI), -rho)] {
            let u = r - self.shoulder_offset;
            let v = w.z - self.shoulder_height;
            let c = (u * u + v * v - self.upper_arm.powi(2) - l3 * l3) / (2.0 * self.upper_arm * l3);
            if c.is_nan() || c.abs() > 1.0 + REACH_SLACK {
                continue;
            }
            let e0 = c.clamp(-1.0, 1.0).acos();
            // Elbow up first: e < 0 (A3 > stretched).
            for e in [-e0, e0] {
                let theta2 = v.atan2(u) - (l3 * e.sin()).atan2(self.upper_arm + l3 * e.cos());
                let (q2, q3) = (wrap_pi(-theta2), wrap_pi(delta - e));
                let r3 = rz(-q1) * ry(q2 + q3);
                let wm = r3.transpose() * r6; // = Rx(−A4)·Ry(A5)·Rx(−A6)
                let m = wm.matrix();
                let s = m[(1, 0)].hypot(m[(2, 0)]);
                for sign in [1.0, -1.0] {
                    let q5 = (sign * s).atan2(m[(0, 0)]);
                    // α = −A4 from the A5 column; at the singular wrist, chosen.
                    let alpha = if s < SINGULAR_SIN {
                        -singular_a4 + if sign < 0.0 { PI } else { 0.0 }
                    } else {
                        (sign * m[(1, 0)]).atan2(-sign * m[(2, 0)])
                    };
                    // γ = −A6 from what remains: exact for any α the A5 column allows.
                    let rest = (rx(alpha) * ry(q5)).transpose() * wm;
                    let gamma = rest[(2, 1)].atan2(rest[(1, 1)]);
                    let q = Joints([q1, q2, q3, wrap_pi(-alpha), wrap_pi(q5), wrap_pi(-gamma)]);
                    let (dp, dr) = self.forward(&q).flange.distance(flange);
                    let duplicate = out.iter().any(|o: &Joints| o.max_abs_diff(&q) < 1e-12);
                    if dp <= FK_CHECK && dr <= FK_CHECK && !duplicate {
                        // Capacity is 2 × 2 × 2 = MAX_SOLUTIONS: never full here.
                        let _ = out.push(q);
                    }
                }
                if e0 == 0.0 {
                    break; // both elbows are the same
                }
            }
        }
        out
    }
}

/// What a joint vector, speed or acceleration broke.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LimitKind {
    /// Past a software limit switch.
    Position,
    /// |A5| under the singular-wrist threshold.
    SingularWrist,
    /// Faster than the axis may turn.
    Speed,
    /// Accelerating harder than the axis may.
    Acceleration,
}

/// The first limit a joint state breaks: the axis, what, its value and the
/// limit (rad, rad/s, rad/s²; shown in degrees).
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub struct LimitViolation {
    /// The axis.
    pub axis: Axis,
    /// Which limit.
    pub kind: LimitKind,
    /// The axis's value (position, speed or acceleration; signed).
    pub value: f64,
    /// The limit it broke: the crossed bound for a position, the
    /// magnitude limit otherwise.
    pub limit: f64,
}

impl fmt::Display for LimitViolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (v, l) = (self.value.to_degrees(), self.limit.to_degrees());
        match self.kind {
            LimitKind::Position => write!(f, "software limit switch {}: {v:.2}° beyond {l:.2}°", self.axis),
            LimitKind::SingularWrist => write!(f, "singular wrist: |{}| = {:.3}° < {l:.3}°", self.axis, v.abs()),
            LimitKind::Speed => write!(f, "{} speed {:.1}°/s over {l:.1}°/s", self.axis, v.abs()),
            LimitKind::Acceleration => write!(f, "{} acceleration {:.0}°/s² over {l:.0}°/s²", self.axis, v.abs()),
        }
    }
}

/// The axes' limits, rad, rad/s, rad/s².
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimits {
    /// Lower software limit switch per axis, rad.
    pub min: [f64; AXES],
    /// Upper software limit switch per axis, rad.
    pub max: [f64; AXES],
    /// Speed limit per axis, rad/s.
    pub speed: [f64; AXES],
    /// Acceleration limit per axis, rad/s².
    pub acceleration: [f64; AXES],
    /// |A5| below this is the singular wrist, rad.
    pub singular_a5: f64,
}

impl JointLimits {
    /// True when every axis is within its software limits.
    pub fn within(&self, q: &Joints) -> bool {
        (0..AXES).all(|i| (self.min[i]..=self.max[i]).contains(&q.0[i]))
    }

    /// Position (A1..A6), then the singular wrist: the first broken limit.
    /// A non-finite angle breaks its position limit.
    pub fn check_position(&self, q: &Joints) -> Result<(), LimitViolation> {
        for axis in Axis::ALL {
            let (i, v) = (axis.index(), q.0[axis.index()]);
            if v.is_nan() || v < self.min[i] {
                return Err(LimitViolation { axis, kind: LimitKind::Position, value: v, limit: self.min[i] });
            }
            if v > self.max[i] {
                return Err(LimitViolation { axis, kind: LimitKind::Position, value: v, limit: self.max[i] });
            }
        }
        let a5 = q.0[Axis::A5.index()];
        if a5.abs() < self.singular_a5 {
            return Err(LimitViolation {
                axis: Axis::A5,
                kind: LimitKind::SingularWrist,
                value: a5,
                limit: self.singular_a5,
            });
        }
        Ok(())
    }

    /// Everything, in the order position (A1..A6), singular wrist, speed
    /// (A1..A6), acceleration (A1..A6): the first broken limit. Non-finite
    /// values break their limit.
    pub fn check(&self, q: &Joints, speed: &[f64; AXES], acceleration: &[f64; AXES]) -> Result<(), LimitViolation> {
        self.check_position(q)?;
        for (kind, values, limits) in
            [(LimitKind::Speed, speed, &self.speed), (LimitKind::Acceleration, acceleration, &self.acceleration)]
        {
            for axis in Axis::ALL {
                let i = axis.index();
                if values[i].is_nan() || values[i].abs() > limits[i] {
                    return Err(LimitViolation { axis, kind, value: values[i], limit: limits[i] });
                }
            }
        }
        Ok(())
    }
}

/// The arm: its geometry and its limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arm {
    /// Links and tool.
    pub geometry: ArmGeometry,
    /// Axis limits.
    pub limits: JointLimits,
}

/// Why [`Arm::inverse_near`] found no joint vector.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum Unreachable {
    /// The wrist centre is beyond the arm's reach (or too close to the
    /// shoulder): no solution at all.
    #[error("out of the arm's reach")]
    OutOfReach,
    /// Solutions exist, none within the software limits; the one nearest
    /// the current joints breaks this limit first.
    #[error("{0}")]
    Limit(LimitViolation),
}

impl Arm {
    /// Forward kinematics of `q`.
    pub fn forward(&self, q: &Joints) -> ArmPose {
        self.geometry.forward(q)
    }

    /// The TCP of `q`.
    pub fn tcp(&self, q: &Joints) -> Pose {
        self.geometry.tcp(q)
    }

    /// Every link frame of `q` ([`ArmGeometry::frames`]).
    pub fn frames(&self, q: &Joints) -> [Pose; FRAMES] {
        self.geometry.frames(q)
    }

    /// Every solution for `tcp` ([`ArmGeometry::inverse`]).
    pub fn inverse(&self, tcp: &Pose) -> Solutions {
        self.geometry.inverse(tcp)
    }

    /// `solution` turned by whole turns, per axis, to lie within the
    /// software limits closest to `current`; else the first axis that no
    /// turn brings within them.
    fn unwrap_near(&self, solution: &Joints, current: &Joints) -> Result<Joints, LimitViolation> {
        let (min, max) = (&self.limits.min, &self.limits.max);
        let mut q = *solution;
        for axis in Axis::ALL {
            let i = axis.index();
            let mut best: Option<f64> = None;
            for k in -2..=2 {
                let v = solution.0[i] + k as f64 * TAU;
                let fits = (min[i]..=max[i]).contains(&v);
                if fits && best.is_none_or(|b| (v - current.0[i]).abs() < (b - current.0[i]).abs()) {
                    best = Some(v);
                }
            }
            let value = solution.0[i];
            let limit = if value > max[i] { max[i] } else { min[i] };
            q.0[i] = best.ok_or(LimitViolation { axis, kind: LimitKind::Position, value, limit })?;
        }
        Ok(q)
    }

    /// Σ ((q − current) / max speed)²: the distance that picks a solution.
    fn cost(&self, q: &Joints, current: &Joints) -> f64 {
        (0..AXES).map(|i| ((q.0[i] - current.0[i]) / self.limits.speed[i]).powi(2)).sum()
    }

    /// The solution that keeps the motion continuous from `current`: each
    /// turned (± 360° where the limits allow) to lie within the software
    /// limits closest to `current`, then the one nearest in time (axis
    /// distances weighted by 1 / max speed, summed in squares); the first
    /// on a tie. `None` when none fits the limits.
    pub fn nearest(&self, solutions: &[Joints], current: &Joints) -> Option<Joints> {
        let mut best: Option<(f64, Joints)> = None;
        for s in solutions {
            if let Ok(q) = self.unwrap_near(s, current) {
                let cost = self.cost(&q, current);
                if best.is_none_or(|(b, _)| cost < b) {
                    best = Some((cost, q));
                }
            }
        }
        best.map(|(_, q)| q)
    }

    /// The joint vector for `tcp` nearest `current` ([`nearest`](Self::nearest));
    /// at the singular wrist it keeps the current A4, at the overhead
    /// singularity the current A1 (KUKA's `$SINGUL_POS` = 1). The
    /// singular-wrist threshold is not applied (check the result).
    pub fn inverse_near(&self, tcp: &Pose, current: &Joints) -> Result<Joints, Unreachable> {
        let flange = tcp.compose(&self.geometry.tool.inverse());
        let solutions = self.geometry.inverse_flange(&flange, current.0[0], current.0[3]);
        if solutions.is_empty() {
            return Err(Unreachable::OutOfReach);
        }
        if let Some(q) = self.nearest(&solutions, current) {
            return Ok(q);
        }
        // Name the limit that the solution closest to `current` (each axis
        // within half a turn of it) breaks.
        let wrapped = |q: &Joints| Joints(core::array::from_fn(|i| current.0[i] + wrap_pi(q.0[i] - current.0[i])));
        let mut closest = solutions[0];
        for s in solutions.iter() {
            if self.cost(&wrapped(s), current) < self.cost(&wrapped(&closest), current) {
                closest = *s;
            }
        }
        match self.unwrap_near(&closest, current) {
            Err(v) => Err(Unreachable::Limit(v)),
            Ok(q) => Ok(q), // unreachable: `nearest` found none that fits
        }
    }

    /// [`JointLimits::check`].
    pub fn check(&self, q: &Joints, speed: &[f64; AXES], acceleration: &[f64; AXES]) -> Result<(), LimitViolation> {
        self.limits.check(q, speed, acceleration)
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::FRAC_PI_2;

    use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

    use super::*;

    const DEG: f64 = PI / 180.0;

    /// The bat: 0.20 m along the flange's z, turned 180° about its x
    /// (`calib/robot.toml`).
    fn bat() -> Pose {
        Pose::from_xyz_abc([0.0, 0.0, 0.20], [0.0, 0.0, PI])
    }

    /// The description's numbers (DESIGN §11) with assumed accelerations.
    fn arm() -> Arm {
        Arm {
            geometry: ArmGeometry::kr6_r900_sixx(bat()),
            limits: JointLimits {
                min: [-170.0, -190.0, -120.0, -185.0, -120.0, -350.0].map(|d: f64| d.to_radians()),
                max: [170.0, 45.0, 156.0, 185.0, 120.0, 350.0].map(|d: f64| d.to_radians()),
                speed: [360.0, 300.0, 360.0, 381.0, 388.0, 615.0].map(|d: f64| d.to_radians()),
                acceleration: [3000.0, 3000.0, 3500.0, 5000.0, 5000.0, 8000.0].map(|d: f64| d.to_radians()),
                singular_a5: 1.0_f64.to_radians(),
            },
        }
    }

    fn close(a: Vec3, b: [f64; 3]) -> bool {
        (a - Vec3::from(b)).norm() < 1e-12
    }

    fn rot_close(a: &Rotation3<f64>, b: &Rotation3<f64>) -> bool {
        (a.matrix() - b.matrix()).norm() < 1e-12
    }

    /// A deterministic generator (SplitMix64) of uniform numbers in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
        fn joints_within(&mut self, l: &JointLimits) -> Joints {
            Joints(core::array::from_fn(|i| l.min[i] + (l.max[i] - l.min[i]) * self.next()))
        }
    }

    #[test]
    fn forward_of_known_joint_vectors_matches_the_description() {
        let g = ArmGeometry::kr6_r900_sixx(bat());
        // All zero: stretched along x, 0.025 + 0.455 + 0.420 + 0.080 ahead,
        // 0.400 + 0.035 up; $FLANGE = Ry(90°) (A, B, C = 0, 90°, 0).
        let f = g.forward(&Joints::default());
        assert!(close(f.wrist, [0.900, 0.0, 0.435]));
        assert!(close(f.flange.position, [0.980, 0.0, 0.435]));
        assert!(rot_close(&f.flange.rotation, &ry(FRAC_PI_2)));
        let abc = f.flange.abc();
        assert!((abc[0]).abs() < 1e-12 && (abc[1] - FRAC_PI_2).abs() < 1e-12 && abc[2].abs() < 1e-12, "{abc:?}");
        // The bat 0.20 m further along the flange's z (= x_B), its frame
        // the flange's turned 180° about x.
        assert!(close(f.tcp.position, [1.180, 0.0, 0.435]));
        assert!(rot_close(&f.tcp.rotation, &(ry(FRAC_PI_2) * rx(PI))));

        // KUKA home: upper arm up (A2 at 0.855), forearm forward
        // (0.025 + 0.420 ahead, 0.855 + 0.035 up), flange down 0.080.
        let f = g.forward(&Joints::kuka_home());
        assert!(close(f.wrist, [0.445, 0.0, 0.890]));
        assert!(close(f.flange.position, [0.445, 0.0, 0.810]));
        assert!(rot_close(&f.flange.rotation, &ry(PI)));
        // The bat hangs 0.20 m below the flange; its frame is A = 180°.
        assert!(close(f.tcp.position, [0.445, 0.0, 0.610]));
        assert!(rot_close(&f.tcp.rotation, &rz(PI)));

        // A1 = +30°: clockwise seen from above (about −z).
        let (s, c) = (30.0 * DEG).sin_cos();
        let f = g.forward(&Joints::from_degrees([30.0, 0.0, 0.0, 0.0, 0.0, 0.0]));
        assert!(close(f.flange.position, [0.980 * c, -0.980 * s, 0.435]));
        // A2 = −90°: the arm stands up; the 0.035 offset now points to −x.
        let f = g.forward(&Joints::from_degrees([0.0, -90.0, 0.0, 0.0, 0.0, 0.0]));
        assert!(close(f.flange.position, [0.025 - 0.035, 0.0, 0.400 + 0.455 + 0.500]));
        // A3 = +90°: the forearm points down from the elbow (0.480, 0.400).
        let f = g.forward(&Joints::from_degrees([0.0, 0.0, 90.0, 0.0, 0.0, 0.0]));
        assert!(close(f.flange.position, [0.480 + 0.035, 0.0, 0.400 - 0.500]));
        // A5 = +90°: the flange bends down 0.080 from the wrist centre.
        let f = g.forward(&Joints::from_degrees([0.0, 0.0, 0.0, 0.0, 90.0, 0.0]));
        assert!(close(f.flange.position, [0.900, 0.0, 0.355]));
        assert!(rot_close(&f.flange.rotation, &ry(PI)));
        // A4 and A6 roll about −x_B: the flange stays, its frame turns.
        for (q, turn) in
            [([0.0, 0.0, 0.0, 90.0, 0.0, 0.0], rx(-FRAC_PI_2)), ([0.0, 0.0, 0.0, 0.0, 0.0, 45.0], rx(-PI / 4.0))]
        {
            let f = g.forward(&Joints::from_degrees(q));
            assert!(close(f.flange.position, [0.980, 0.0, 0.435]));
            assert!(rot_close(&f.flange.rotation, &(turn * ry(FRAC_PI_2))));
        }
        // A4 = 90°, A5 = 90°: A5 bends towards −z of link 4, which A4 has
        // turned to −y_B (Rx(−90°)·z = +y_B).
        let f = g.forward(&Joints::from_degrees([0.0, 0.0, 0.0, 90.0, 90.0, 0.0]));
        assert!(close(f.flange.position, [0.900, -0.080, 0.435]), "{}", f.flange.position);
        assert_eq!(g.reach(), 0.025 + 0.455 + 0.420f64.hypot(0.035));
        assert!((g.reach() - 0.901).abs() < 1e-3);
    }

    #[test]
    fn forward_equals_the_description_chain() {
        // The URDF read literally: origin translation, then a rotation by
        // the joint value about the listed axis; tool0 = rpy (0, π/2, 0).
        let axes =
            [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]];
        let g = ArmGeometry::kr6_r900_sixx(bat());
        let limits = arm().limits;
        let mut rng = Rng(7);
        for _ in 0..1000 {
            let q = rng.joints_within(&limits);
            let mut t = Isometry3::identity();
            for i in 0..AXES {
                let [x, y, z] = KR6_R900_SIXX_ORIGINS[i];
                let axis = Unit::new_normalize(Vector3::from(axes[i]));
                t *= Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_axis_angle(&axis, q.0[i]));
            }
            t *=
                Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_euler_angles(0.0, FRAC_PI_2, 0.0));
            let f = g.forward(&q).flange;
            let urdf = Pose { position: t.translation.vector, rotation: t.rotation.to_rotation_matrix() };
            let (dp, dr) = f.distance(&urdf);
            assert!(dp < 1e-12 && dr < 1e-12, "{q:?}: {dp:e} {dr:e}");
        }
    }

    #[test]
    fn frames_are_the_description_chain_link_by_link() {
        // KUKA home: the column, the shoulder offset, the upper arm up, the
        // elbow offset, the forearm forward, the flange down, the bat below.
        let g = ArmGeometry::kr6_r900_sixx(bat());
        let f = g.frames(&Joints::kuka_home());
        let origins = [
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 0.400],
            [0.025, 0.0, 0.400],
            [0.025, 0.0, 0.855],
            [0.025, 0.0, 0.890],
            [0.445, 0.0, 0.890],
            [0.445, 0.0, 0.810],
            [0.445, 0.0, 0.610],
        ];
        for (k, o) in origins.iter().enumerate() {
            assert!(close(f[k].position, *o), "frame {k}: {:?}", f[k].position);
        }
        assert_eq!(f[0], Pose::identity());

        // Across the joint space: frame i is the URDF's chain through joint
        // i; the last three are forward's wrist, flange and TCP, bit for bit.
        let axes =
            [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]];
        let mut rng = Rng(11);
        for _ in 0..1000 {
            let q = rng.joints_within(&arm().limits);
            let f = g.frames(&q);
            let mut t = Isometry3::identity();
            for i in 0..AXES {
                let [x, y, z] = KR6_R900_SIXX_ORIGINS[i];
                let axis = Unit::new_normalize(Vector3::from(axes[i]));
                t *= Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_axis_angle(&axis, q.0[i]));
                let urdf = Pose { position: t.translation.vector, rotation: t.rotation.to_rotation_matrix() };
                let (dp, dr) = f[i + 1].distance(&urdf);
                assert!(dp < 1e-12 && dr < 1e-12, "{q:?}, frame {}: {dp:e} {dr:e}", i + 1);
            }
            let fk = g.forward(&q);
            assert_eq!(f[FRAMES - 1], fk.tcp);
            assert_eq!(f[5].position, fk.wrist);
            assert_eq!(f[6].position, fk.flange.position);
            assert_eq!(f[6].rotation * ry90(), fk.flange.rotation);
            assert_eq!(arm().frames(&q), f);
        }
    }

    #[test]
    fn kuka_abc_is_the_geometry_convention() {
        for abc in [[0.3, -0.2, 0.1], [PI, 0.0, 0.0], [-2.0, 1.2, 3.0], [0.5, FRAC_PI_2, 0.2], [0.5, -FRAC_PI_2, 0.2]] {
            let p = Pose::from_xyz_abc([0.1, 0.2, 0.3], abc);
            assert_eq!(p.rotation.into_inner(), rot_zyx(abc[0], abc[1], abc[2]));
            let back = Pose::from_xyz_abc([0.1, 0.2, 0.3], p.abc());
            assert!(p.distance(&back).1 < 1e-12, "{abc:?} -> {:?}", p.abc());
            let p6 = p.to_pose6();
            assert!(Pose::from_pose6(&p6).distance(&p).1 < 1e-12);
        }
        let p = Pose::from_xyz_abc([0.1, -0.2, 0.3], [0.4, 0.5, -0.6]);
        let (dp, dr) = p.compose(&p.inverse()).distance(&Pose::identity());
        assert!(dp < 1e-15 && dr < 1e-15);
        // The rotation distance resolves tiny angles.
        let q = Pose { rotation: p.rotation * rz(1e-11), ..p };
        assert!((p.distance(&q).1 - 1e-11).abs() < 1e-15);
    }

    #[test]
    fn inverse_of_forward_round_trips_across_the_joint_space() {
        let arm = arm();
        let g = &arm.geometry;
        let mut rng = Rng(16);
        let (mut checked, mut matched, mut total) = (0, 0, 0);
        for _ in 0..20_000 {
            let q = rng.joints_within(&arm.limits);
            let pose = g.tcp(&q);
            let sols = g.inverse(&pose);
            assert!(!sols.is_empty() && sols.len().is_multiple_of(2), "{q:?}: {} solutions", sols.len());
            total += sols.len();
            for s in &sols {
                let (dp, dr) = g.tcp(s).distance(&pose);
                assert!(dp < 1e-9 && dr < 1e-9, "{q:?} -> {s:?}: {dp:e} m, {dr:e} rad");
                assert!(s.0.iter().all(|a| a.abs() <= PI));
            }
            // Well away from the singularities the original is among them
            // (angles modulo 2π).
            let w = g.forward(&q).wrist;
            let stretch = (q.0[2] - g.stretched_a3()).sin().abs();
            if q.0[4].sin().abs() > 1e-2 && stretch > 1e-2 && w.x.hypot(w.y) > 1e-2 {
                checked += 1;
                let hit = sols.iter().any(|s| (0..AXES).all(|i| wrap_pi(s.0[i] - q.0[i]).abs() < 1e-9));
                assert!(hit, "{q:?} not among {sols:?}");
                // ... and every branch is a different configuration.
                for (i, a) in sols.iter().enumerate() {
                    for b in &sols[..i] {
                        assert_ne!(g.configuration(a), g.configuration(b));
                    }
                }
                matched += 1;
            }
        }
        assert_eq!(matched, checked);
        assert!(checked > 19_000, "{checked}");
        // Most poses of the joint space have all eight solutions.
        assert!(total as f64 / 20_000.0 > 6.0, "{total}");
    }

    #[test]
    fn inverse_gives_eight_distinct_configurations_for_kuka_home() {
        let g = arm().geometry;
        let sols = g.inverse(&g.tcp(&Joints::kuka_home()));
        assert_eq!(sols.len(), MAX_SOLUTIONS);
        // Front/up/not flipped first: KUKA home itself.
        assert!(sols[0].max_abs_diff(&Joints::kuka_home()) < 1e-12, "{:?}", sols[0].degrees());
        let c: Vec<Configuration> = sols.iter().map(|s| g.configuration(s)).collect();
        assert_eq!(c[0], Configuration { overhead: false, elbow_up: true, wrist_flipped: false });
        assert_eq!(c[1], Configuration { overhead: false, elbow_up: true, wrist_flipped: true });
        assert_eq!(c[2], Configuration { overhead: false, elbow_up: false, wrist_flipped: false });
        assert!(c[4].overhead && c[7].overhead && !c[3].overhead);
        // The flipped wrist: A4 + 180°, −A5, A6 + 180°.
        assert!((sols[1].0[3].abs() - PI).abs() < 1e-12 && (sols[1].0[4] + FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn out_of_reach_has_no_solution() {
        let arm = arm();
        let far = Pose::from_xyz_abc([1.5, 0.0, 0.435], [0.0, FRAC_PI_2, 0.0]);
        assert!(arm.inverse(&far).is_empty());
        assert_eq!(arm.inverse_near(&far, &Joints::kuka_home()), Err(Unreachable::OutOfReach));
        // Exactly stretched: one elbow, both wrists.
        let g = arm.geometry;
        let stretched = Joints([0.0, 0.0, g.stretched_a3(), 0.0, 0.3, 0.0]);
        let sols = g.inverse(&g.tcp(&stretched));
        assert!(sols.iter().any(|s| s.max_abs_diff(&stretched) < 1e-6), "{sols:?}");
        for s in &sols {
            let (dp, dr) = g.tcp(s).distance(&g.tcp(&stretched));
            assert!(dp < 1e-7 && dr < 1e-7, "{dp:e} {dr:e}");
        }
    }

    #[test]
    fn singular_wrist_is_solved_and_flagged() {
        let arm = arm();
        let g = &arm.geometry;
        // A5 = 0: only A4 + A6 = 50° is seen.
        let q = Joints::from_degrees([10.0, -80.0, 100.0, 30.0, 0.0, 20.0]);
        let pose = g.tcp(&q);
        let sols = g.inverse(&pose);
        assert_eq!(sols.len(), MAX_SOLUTIONS);
        for s in &sols {
            assert!(s.0.iter().all(|a| a.is_finite()));
            let (dp, dr) = g.tcp(s).distance(&pose);
            assert!(dp < 1e-12 && dr < 1e-12, "{dp:e} {dr:e}");
        }
        // `inverse` keeps A4 = 0 and gives A6 the sum (KUKA $SINGUL_POS[3] = 0);
        // the flipped wrist is A4 = 180°, A6 = 50° − 180°.
        let d = sols[0].degrees();
        assert!(d[3].abs() < 1e-9 && d[4].abs() < 1e-9 && (d[5] - 50.0).abs() < 1e-9, "{d:?}");
        assert!((d[0] - 10.0).abs() < 1e-9 && (d[1] + 80.0).abs() < 1e-9 && (d[2] - 100.0).abs() < 1e-9);
        let d = sols[1].degrees();
        assert!((d[3].abs() - 180.0).abs() < 1e-9 && d[4].abs() < 1e-9 && (d[5] + 130.0).abs() < 1e-9, "{d:?}");
        // `inverse_near` keeps the current A4 ($SINGUL_POS[3] = 1): from
        // A4 = 30° it returns the original exactly.
        let near = arm.inverse_near(&pose, &Joints::from_degrees([10.0, -80.0, 100.0, 30.0, 5.0, 20.0])).unwrap();
        assert!(near.max_abs_diff(&q) < 1e-12, "{:?}", near.degrees());
        // The check flags it (and a hair beyond the threshold does not).
        let e = arm.limits.check_position(&q).unwrap_err();
        assert_eq!((e.axis, e.kind), (Axis::A5, LimitKind::SingularWrist));
        assert_eq!(e.to_string(), "singular wrist: |A5| = 0.000° < 1.000°");
        let mut ok = q;
        ok.0[4] = -1.001 * DEG;
        assert!(arm.limits.check_position(&ok).is_ok());
        ok.0[4] = -0.999 * DEG;
        assert_eq!(arm.limits.check_position(&ok).unwrap_err().kind, LimitKind::SingularWrist);
        // Near (not at) the singularity the round trip still holds to 1e-9.
        for a5 in [1e-13, 1e-11, 1e-9, 1e-7, 1e-5] {
            let q = Joints([0.2, -1.4, 1.7, 0.5, a5, -0.3]);
            for s in &g.inverse(&g.tcp(&q)) {
                let (dp, dr) = g.tcp(s).distance(&g.tcp(&q));
                assert!(dp < 1e-9 && dr < 1e-9, "A5 = {a5:e}: {dp:e} {dr:e}");
            }
        }
    }

    #[test]
    fn overhead_singularity_is_solved() {
        let arm = arm();
        let g = &arm.geometry;
        // The wrist centre on the A1 axis: the upper arm up (A2 = −90°),
        // the forearm reaching back over the 0.025 m shoulder offset:
        // 0.025 + L3·cos ψ = 0 with ψ = A2 + A3 − stretched.
        let l3 = g.forearm.hypot(g.elbow_offset);
        let a3 = g.stretched_a3() + FRAC_PI_2 - (-g.shoulder_offset / l3).acos();
        let q = Joints([0.7, -FRAC_PI_2, a3, 0.2, 0.6, 0.1]);
        let w = g.forward(&q).wrist;
        assert!(w.x.hypot(w.y) < 1e-12, "{w}");
        let pose = g.tcp(&q);
        for s in &g.inverse(&pose) {
            let (dp, dr) = g.tcp(s).distance(&pose);
            assert!(dp < 1e-9 && dr < 1e-9, "{dp:e} {dr:e}");
        }
        let near = arm.inverse_near(&pose, &q).unwrap();
        assert!(near.max_abs_diff(&q) < 1e-9, "{:?} vs {:?}", near.degrees(), q.degrees());
    }

    #[test]
    fn nearest_keeps_a_cartesian_path_continuous() {
        let arm = arm();
        let g = &arm.geometry;
        // From KUKA home's TCP to a low forehand on the left, turning the
        // bat (A +40°, B −30°, C +20°), in 1 mm steps.
        let start = g.tcp(&Joints::kuka_home());
        let end = Pose {
            position: Vec3::new(0.45, 0.45, 0.25),
            rotation: start.rotation * Rotation3::from_euler_angles(20.0 * DEG, -30.0 * DEG, 40.0 * DEG),
        };
        let n = ((end.position - start.position).norm() / 1e-3).ceil() as usize;
        let mut q = Joints::kuka_home();
        let mut max_step = 0.0f64;
        for k in 1..=n {
            let t = k as f64 / n as f64;
            let pose = Pose {
                position: start.position.lerp(&end.position, t),
                rotation: start.rotation.slerp(&end.rotation, t),
            };
            let next = arm.inverse_near(&pose, &q).unwrap();
            let (dp, dr) = g.tcp(&next).distance(&pose);
            assert!(dp < 1e-9 && dr < 1e-9);
            assert_eq!(g.configuration(&next), g.configuration(&q));
            max_step = max_step.max(next.max_abs_diff(&q));
            q = next;
        }
        // About 1 mm and 0.1° of bat per step: no axis moves more than 0.5°.
        assert!(max_step < 0.5 * DEG, "{}", max_step / DEG);
    }

    #[test]
    fn nearest_follows_a_joint_path_through_the_singularity_and_past_180() {
        let arm = arm();
        let g = &arm.geometry;
        // A5 crosses 0 (at one sample exactly) with A4 = 30°; A6 runs from
        // 150° to 210° (past ±180°, allowed by ±350°). The IK returns A6 in
        // (−180°, 180°]; `nearest` must add the turn and keep the branch.
        let path =
            |k: i32| Joints::from_degrees([5.0, -70.0, 95.0, 30.0, (100 - k) as f64 * 0.1, 150.0 + 0.3 * k as f64]);
        let mut q = path(0);
        for k in 1..=200 {
            let want = path(k);
            let got = arm.inverse_near(&g.tcp(&want), &q).unwrap();
            assert!(got.max_abs_diff(&want) < 1e-9, "step {k}: {:?} vs {:?}", got.degrees(), want.degrees());
            q = got;
        }
        assert!((q.0[5] - 210.0 * DEG).abs() < 1e-9);
        // Plain `nearest` over the solutions: the same choice.
        let want = path(150);
        let sols = g.inverse(&g.tcp(&want));
        assert!(arm.nearest(&sols, &path(149)).unwrap().max_abs_diff(&want) < 1e-9);
        // A6 at 345° is reachable only one way round; from −10° the nearest
        // fitting turn of 345° is −15°.
        let s = [Joints::from_degrees([0.0, -90.0, 90.0, 0.0, 90.0, -15.0])];
        let from = Joints::from_degrees([0.0, -90.0, 90.0, 0.0, 90.0, 340.0]);
        assert!((arm.nearest(&s, &from).unwrap().0[5] - 345.0 * DEG).abs() < 1e-12);
        let from = Joints::from_degrees([0.0, -90.0, 90.0, 0.0, 90.0, -10.0]);
        assert!((arm.nearest(&s, &from).unwrap().0[5] + 15.0 * DEG).abs() < 1e-12);
        // A solution outside A1's ±170° fits no turn.
        let s = [Joints::from_degrees([175.0, -90.0, 90.0, 0.0, 90.0, 0.0])];
        assert_eq!(arm.nearest(&s, &from), None);
    }

    #[test]
    fn out_of_limits_names_the_axis() {
        let arm = arm();
        // Behind the robot: A1 would be 174.29° (beyond ±170°) in front;
        // the overhead branch needs A2 beyond +45°.
        let behind = Pose::from_xyz_abc([-0.5, -0.05, 0.5], [0.0, PI, 0.0]);
        assert!(!arm.inverse(&behind).is_empty());
        let e = arm.inverse_near(&behind, &Joints::kuka_home()).unwrap_err();
        let Unreachable::Limit(v) = e else { panic!("{e:?}") };
        assert_eq!((v.axis, v.kind), (Axis::A1, LimitKind::Position), "{v}");
        assert_eq!(v.to_string(), "software limit switch A1: 174.29° beyond 170.00°");
        // Each axis and kind is named.
        let ok = Joints::kuka_home();
        let zero = [0.0; AXES];
        assert_eq!(arm.check(&ok, &zero, &zero), Ok(()));
        for axis in Axis::ALL {
            let i = axis.index();
            let mut q = ok;
            q.0[i] = arm.limits.max[i] + 1e-9;
            assert_eq!(arm.check(&q, &zero, &zero).unwrap_err().axis, axis);
            q.0[i] = arm.limits.min[i] - 1e-9;
            let e = arm.check(&q, &zero, &zero).unwrap_err();
            assert_eq!((e.axis, e.kind, e.limit), (axis, LimitKind::Position, arm.limits.min[i]));
            let mut v = zero;
            v[i] = -1.01 * arm.limits.speed[i];
            let e = arm.check(&ok, &v, &zero).unwrap_err();
            assert_eq!((e.axis, e.kind), (axis, LimitKind::Speed));
            let mut a = zero;
            a[i] = 1.01 * arm.limits.acceleration[i];
            let e = arm.check(&ok, &zero, &a).unwrap_err();
            assert_eq!((e.axis, e.kind), (axis, LimitKind::Acceleration));
            a[i] = f64::NAN;
            assert_eq!(arm.check(&ok, &zero, &a).unwrap_err().kind, LimitKind::Acceleration);
        }
        let mut v = zero;
        v[1] = 301.0 * DEG;
        assert_eq!(arm.check(&ok, &v, &zero).unwrap_err().to_string(), "A2 speed 301.0°/s over 300.0°/s");
        // Position before speed.
        let mut q = ok;
        q.0[2] = 157.0 * DEG;
        assert_eq!(arm.check(&q, &v, &zero).unwrap_err().axis, Axis::A3);
        let mut q = ok;
        q.0[0] = f64::NAN;
        assert_eq!(arm.check(&q, &zero, &zero).unwrap_err().axis, Axis::A1);
    }

    #[test]
    fn off_structure_chains_are_named() {
        let mut o = KR6_R900_SIXX_ORIGINS;
        o[3][1] = 0.01;
        let e = ArmGeometry::from_origins(&o, bat()).unwrap_err();
        assert_eq!((e.axis, e.coordinate, e.value), (Axis::A4, 1, 0.01));
        let mut o = KR6_R900_SIXX_ORIGINS;
        o[2][0] = 0.0;
        assert_eq!(ArmGeometry::from_origins(&o, bat()).unwrap_err().axis, Axis::A3);
        let mut o = KR6_R900_SIXX_ORIGINS;
        o[5][0] = f64::NAN;
        assert_eq!(ArmGeometry::from_origins(&o, bat()).unwrap_err().axis, Axis::A6);
    }
}
