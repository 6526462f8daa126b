//! The crate's one geometry vocabulary: the pose the motion layer moves
//! ([`Pose6`]), KUKA's Z-Y-X Euler convention ([`EulerZyx`], [`rot_zyx`],
//! [`zyx_angles`], [`zyx_angles_asin`]) and angle wrapping ([`wrap_pi`], [`unwrap_near`],
//! [`wrap_deg_near`]). Every other module (kinematics, motion, the plan,
//! the RSI session, calibration) builds on these, so that one angle means
//! the same thing everywhere (DESIGN §1).
//!
//! KUKA's A, B, C: rotate by A about z, then by B about the new y, then by
//! C about the new x, i.e. R = Rz(A)·Ry(B)·Rx(C).

use std::f64::consts::{PI, TAU};

use nalgebra::Matrix3;

/// A TCP pose: x, y, z (m), a, b, c (rad, KUKA Euler Z-Y-X). In the motion
/// layer it is in the robot's BASE frame B with the angles unwrapped
/// (continuous, near home).
pub type Pose6 = [f64; 6];

/// An orientation as KUKA Euler angles Z-Y-X in radians: rotate by `a`
/// about z, then `b` about the new y, then `c` about the new x.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct EulerZyx {
    /// First rotation, about z, rad.
    pub a: f64,
    /// Second rotation, about the new y, rad.
    pub b: f64,
    /// Third rotation, about the new x, rad.
    pub c: f64,
}

impl EulerZyx {
    /// The rotation Rz(a)·Ry(b)·Rx(c): the rotated frame's axes in the
    /// frame the angles are given in (its columns).
    pub fn matrix(&self) -> Matrix3<f64> {
        rot_zyx(self.a, self.b, self.c)
    }
}

/// Rz(a)·Ry(b)·Rx(c), angles in radians.
pub fn rot_zyx(a: f64, b: f64, c: f64) -> Matrix3<f64> {
    let (sa, ca) = a.sin_cos();
    let (sb, cb) = b.sin_cos();
    let (sc, cc) = c.sin_cos();
    Matrix3::new(
        ca * cb,
        ca * sb * sc - sa * cc,
        ca * sb * cc + sa * sc,
        sa * cb,
        sa * sb * sc + ca * cc,
        sa * sb * cc - ca * sc,
        -sb,
        cb * sc,
        cb * cc,
    )
}

/// The Z-Y-X angles `[a, b, c]` of a rotation matrix, the inverse of
/// [`rot_zyx`]: a, c in (−π, π], b in [−π/2, π/2]. At b = ±90° (gimbal
/// lock) a = 0 and c takes the rest.
pub fn zyx_angles(r: &Matrix3<f64>) -> [f64; 3] {
    let cb = r[(0, 0)].hypot(r[(1, 0)]);
    let b = (-r[(2, 0)]).atan2(cb);
    if cb < 1e-12 {
        // R = Ry(±90°)·Rx(c ∓ a): only c ∓ a is defined.
        let c = if r[(2, 0)] < 0.0 { r[(0, 1)].atan2(r[(1, 1)]) } else { (-r[(0, 1)]).atan2(r[(1, 1)]) };
        return [0.0, b, c];
    }
    [r[(1, 0)].atan2(r[(0, 0)]), b, r[(2, 1)].atan2(r[(2, 2)])]
}

/// The Z-Y-X angles `(a, b, c)` of a rotation matrix away from gimbal
/// lock, with b from asin (a bat's orientation, whose tilt stays far from
/// ±90°). It agrees with [`zyx_angles`] to the last bit or two of b; the
/// T→B conversion of a plan's orientation uses it, and the recorded
/// sessions replay bit for bit with it.
pub fn zyx_angles_asin(r: &Matrix3<f64>) -> [f64; 3] {
    let b = (-r[(2, 0)]).clamp(-1.0, 1.0).asin();
    [r[(1, 0)].atan2(r[(0, 0)]), b, r[(2, 1)].atan2(r[(2, 2)])]
}

/// `x` wrapped into (−π, π].
pub fn wrap_pi(x: f64) -> f64 {
    let y = x - (x / TAU).round() * TAU;
    if y <= -PI { y + TAU } else { y }
}

/// `x` plus a multiple of 2π, within π of `reference`.
pub fn unwrap_near(x: f64, reference: f64) -> f64 {
    x - ((x - reference) / TAU).round() * TAU
}

/// `a` wrapped into (`near` − 180°, `near` + 180°], degrees.
pub fn wrap_deg_near(a: f64, near: f64) -> f64 {
    let d = (a - near).rem_euclid(360.0);
    near + if d > 180.0 { d - 360.0 } else { d }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_angles_of_a_rotation_give_it_back() {
        for abc in [[0.3, -0.2, 0.1], [-2.9, 1.2, 3.0], [0.0, 0.0, 0.0], [PI, 0.4, -PI / 2.0]] {
            let r = rot_zyx(abc[0], abc[1], abc[2]);
            let back = zyx_angles(&r);
            let again = rot_zyx(back[0], back[1], back[2]);
            assert!((r - again).norm() < 1e-12, "{abc:?} -> {back:?}");
            assert!(back.iter().all(|x| (-PI..=PI).contains(x)));
        }
        // Gimbal lock: only c − a is defined, and it survives.
        let r = rot_zyx(0.3, PI / 2.0, 0.5);
        let [a, b, c] = zyx_angles(&r);
        assert_eq!(a, 0.0);
        assert!((b - PI / 2.0).abs() < 1e-9 && (rot_zyx(a, b, c) - r).norm() < 1e-9);
        // Away from the lock the asin form is the same angles.
        let r = rot_zyx(0.3, -0.2, 0.1);
        let (x, y) = (zyx_angles(&r), zyx_angles_asin(&r));
        assert!((0..3).all(|i| (x[i] - y[i]).abs() < 1e-15), "{x:?} {y:?}");
    }

    #[test]
    fn the_matrix_is_rz_ry_rx_and_nalgebras_euler_convention() {
        let (a, b, c) = (0.4, -0.2, 0.9);
        let r = rot_zyx(a, b, c);
        let rz = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), a);
        let ry = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), b);
        let rx = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::x_axis(), c);
        assert!((r - (rz * ry * rx).into_inner()).norm() < 1e-12);
        // nalgebra's (roll, pitch, yaw) is the same rotation, bit for bit.
        assert_eq!(r, nalgebra::Rotation3::from_euler_angles(c, b, a).into_inner());
        assert_eq!(EulerZyx { a, b, c }.matrix(), r);
    }

    #[test]
    fn wraps_land_where_they_say() {
        assert_eq!(wrap_pi(PI), PI);
        assert_eq!(wrap_pi(-PI), PI);
        assert!((wrap_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((unwrap_near(0.1, 2.0 * TAU) - (0.1 + 2.0 * TAU)).abs() < 1e-12);
        assert!((unwrap_near(-3.0, 3.0) - (TAU - 3.0)).abs() < 1e-12);
        assert_eq!(wrap_deg_near(-176.5, 180.0), 183.5);
        assert_eq!(wrap_deg_near(-2.0, 180.0), 358.0);
        assert_eq!(wrap_deg_near(10.0, 0.0), 10.0);
    }
}
