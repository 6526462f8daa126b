//! The table bounce: a rigid thin-shell ball with Coulomb friction, sliding
//! or rolling at the contact (Nakashima et al. 2010; DESIGN §3).
//!
//! Slip at the contact v_T = (v_x − rω_y, v_y + rω_x);
//! α = μ(1+e)|v_z| / ‖v_T‖, capped at 2/5 (the ball leaves rolling);
//! v⁺ = A v⁻ + B ω⁻, ω⁺ = C v⁻ + D ω⁻ with the matrices below.

use super::{BallState, Vec3};

/// The contact model with its constants.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BounceModel {
    /// Coefficient of restitution e (normal).
    pub restitution: f64,
    /// Friction coefficient μ.
    pub friction: f64,
    /// Ball radius r in m.
    pub radius: f64,
}

/// The cap on α: at α = 2/5 the ball leaves the table rolling (no slip).
pub(crate) const ROLLING_ALPHA: f64 = 0.4;

impl BounceModel {
    /// A contact model from restitution e, friction μ and ball radius r (m).
    pub fn new(restitution: f64, friction: f64, radius: f64) -> Self {
        BounceModel { restitution, friction, radius }
    }

    /// The friction ratio α of this impact (2/5 when the ball rolls).
    pub(crate) fn alpha(&self, vel: &Vec3, spin: &Vec3) -> f64 {
        let r = self.radius;
        let slip_x = vel.x - r * spin.y;
        let slip_y = vel.y + r * spin.x;
        let slip = slip_x.hypot(slip_y);
        let normal = self.friction * (1.0 + self.restitution) * vel.z.abs();
        if slip <= normal / ROLLING_ALPHA { ROLLING_ALPHA } else { normal / slip }
    }

    /// Velocity and spin just after an impact with velocity `vel` (v_z < 0)
    /// and spin `spin` just before it. The position is unchanged.
    pub(crate) fn apply(&self, state: &BallState) -> BallState {
        let (v, w, r, e) = (state.vel, state.spin, self.radius, self.restitution);
        let a = self.alpha(&v, &w);
        let vel = Vec3::new((1.0 - a) * v.x + a * r * w.y, (1.0 - a) * v.y - a * r * w.x, -e * v.z);
        let k = 1.5 * a / r;
        let spin = Vec3::new(-k * v.y + (1.0 - 1.5 * a) * w.x, k * v.x + (1.0 - 1.5 * a) * w.y, w.z);
        BallState { pos: state.pos, vel, spin }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const R: f64 = 0.02;

    /// Kinetic energy per unit mass of a thin spherical shell (I = 2/3 m r²).
    fn energy(s: &BallState) -> f64 {
        0.5 * s.vel.norm_squared() + 0.5 * (2.0 / 3.0) * R * R * s.spin.norm_squared()
    }

    fn arb_impact() -> impl Strategy<Value = BallState> {
        (
            (-20.0..20.0f64, -20.0..20.0f64, -15.0..-0.01f64),
            (-1000.0..1000.0f64, -1000.0..1000.0f64, -1000.0..1000.0f64),
        )
            .prop_map(|((vx, vy, vz), (wx, wy, wz))| {
                BallState::new(Vec3::new(0.0, 0.0, R), Vec3::new(vx, vy, vz), Vec3::new(wx, wy, wz))
            })
    }

    proptest! {
        #[test]
        fn bounce_never_adds_energy(s in arb_impact(), e in 0.3..1.0f64, mu in 0.0..1.0f64) {
            let m = BounceModel::new(e, mu, R);
            let after = m.apply(&s);
            prop_assert!(energy(&after) <= energy(&s) * (1.0 + 1e-12) + 1e-12);
            prop_assert!(after.vel.z >= 0.0);
        }

        #[test]
        fn rolling_contact_leaves_no_slip(s in arb_impact(), e in 0.3..1.0f64) {
            // High friction forces the rolling branch.
            let m = BounceModel::new(e, 1e9, R);
            prop_assert_eq!(m.alpha(&s.vel, &s.spin), ROLLING_ALPHA);
            let after = m.apply(&s);
            let slip_x = after.vel.x - R * after.spin.y;
            let slip_y = after.vel.y + R * after.spin.x;
            prop_assert!(slip_x.abs() < 1e-9 && slip_y.abs() < 1e-9, "slip ({slip_x}, {slip_y})");
        }

        #[test]
        fn sliding_contact_keeps_slip_direction(s in arb_impact(), e in 0.3..1.0f64) {
            let m = BounceModel::new(e, 0.05, R);
            let a = m.alpha(&s.vel, &s.spin);
            prop_assume!(a < ROLLING_ALPHA);
            let after = m.apply(&s);
            let before = (s.vel.x - R * s.spin.y, s.vel.y + R * s.spin.x);
            let after_slip = (after.vel.x - R * after.spin.y, after.vel.y + R * after.spin.x);
            // Slip shrinks by (1 − 5α/2) and keeps its direction.
            let f = 1.0 - 2.5 * a;
            prop_assert!((after_slip.0 - f * before.0).abs() < 1e-9);
            prop_assert!((after_slip.1 - f * before.1).abs() < 1e-9);
        }
    }

    #[test]
    fn topspin_speeds_the_ball_up_backspin_slows_it() {
        let m = BounceModel::new(0.9, 0.25, R);
        let v = Vec3::new(5.0, 0.0, -3.0);
        let top = m.apply(&BallState::new(Vec3::zeros(), v, Vec3::new(0.0, 600.0, 0.0)));
        let back = m.apply(&BallState::new(Vec3::zeros(), v, Vec3::new(0.0, -600.0, 0.0)));
        assert!(top.vel.x > back.vel.x);
        assert!((top.vel.z - 2.7).abs() < 1e-12);
    }
}
