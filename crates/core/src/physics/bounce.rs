//! The table bounce: a rigid thin-shell ball with Coulomb friction, sliding
//! or rolling at the contact (Nakashima et al. 2010; DESIGN §3).
//!
//! Slip at the contact v_T = (v_x − rω_y, v_y + rω_x);
//! α = μ(1+e)|v_z| / ‖v_T‖, capped at 2/5 (the ball leaves rolling);
//! v⁺ = A v⁻ + B ω⁻, ω⁺ = C v⁻ + D ω⁻ with the matrices below.
//!
//! A filter reads spin from a flight through its own lift curve; a real
//! ball's lift saturates, so the spin the table meets may be a multiple of
//! that reading ([`BounceModel::spin_scale`], learned per session by the
//! estimator): the contact acts on the scaled spin and hands the spin back
//! in the flight's units. The simulator's tables have a scale of 1.

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
    /// The spin at the contact per unit of the flight model's spin (1: the
    /// flight's spin is the ball's).
    pub spin_scale: f64,
}

/// The cap on α: at α = 2/5 the ball leaves the table rolling (no slip).
pub(crate) const ROLLING_ALPHA: f64 = 0.4;

impl BounceModel {
    /// A contact model from restitution e, friction μ and ball radius r (m).
    pub fn new(restitution: f64, friction: f64, radius: f64) -> Self {
        BounceModel { restitution, friction, radius, spin_scale: 1.0 }
    }

    /// This table meeting `scale` times the flight model's spin.
    pub fn with_spin_scale(self, scale: f64) -> Self {
        BounceModel { spin_scale: scale, ..self }
    }

    /// The friction ratio α of this impact (2/5 when the ball rolls).
    pub(crate) fn alpha(&self, vel: &Vec3, spin: &Vec3) -> f64 {
        let r = self.radius * self.spin_scale;
        let slip_x = vel.x - r * spin.y;
        let slip_y = vel.y + r * spin.x;
        let slip = slip_x.hypot(slip_y);
        let normal = self.friction * (1.0 + self.restitution) * vel.z.abs();
        if slip <= normal / ROLLING_ALPHA { ROLLING_ALPHA } else { normal / slip }
    }

    /// Velocity and spin just after an impact with velocity `vel` (v_z < 0)
    /// and spin `spin` just before it. The position is unchanged.
    pub(crate) fn apply(&self, state: &BallState) -> BallState {
        let (v, r, e) = (state.vel, self.radius, self.restitution);
        let a = self.alpha(&v, &state.spin);
        let w = state.spin * self.spin_scale;
        let vel = Vec3::new((1.0 - a) * v.x + a * r * w.y, (1.0 - a) * v.y - a * r * w.x, -e * v.z);
        let k = 1.5 * a / r;
        let spin = Vec3::new(-k * v.y + (1.0 - 1.5 * a) * w.x, k * v.x + (1.0 - 1.5 * a) * w.y, w.z);
        BallState { pos: state.pos, vel, spin: spin / self.spin_scale }
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

    /// A table meeting twice the flight's spin bounces a ball as the
    /// plain table bounces the ball with twice the spin, and hands the
    /// spin back in the flight's units.
    #[test]
    fn a_spin_scale_is_the_same_bounce_of_the_scaled_spin() {
        let plain = BounceModel::new(0.92, 0.2, R);
        let scaled = plain.with_spin_scale(2.0);
        for w in [Vec3::new(0.0, 150.0, 10.0), Vec3::new(40.0, -300.0, 0.0), Vec3::new(0.0, 400.0, 0.0)] {
            let s = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.4, -3.0), w);
            let (a, b) = (scaled.apply(&s), plain.apply(&BallState { spin: w * 2.0, ..s }));
            assert!((a.vel - b.vel).norm() < 1e-12 && (a.spin * 2.0 - b.spin).norm() < 1e-9, "{a:?} {b:?}");
        }
        let s = BallState::new(Vec3::zeros(), Vec3::new(5.0, 0.0, -3.0), Vec3::new(0.0, 200.0, 0.0));
        assert_eq!(plain.with_spin_scale(1.0).apply(&s), plain.apply(&s));
    }
}
