//! The racket contact: the ball meets the bat's rubber and leaves it with a
//! new velocity and spin (the stroke's physics; DESIGN §3 has the table's).
//!
//! The model is Nakashima, Ogawa, Kobayashi and Hayakawa's rigid ball on
//! an elastic rubber ("Modeling of rebound phenomenon of a rigid ball with
//! friction and elastic effects", Proc. American Control Conference 2010,
//! pp. 1410–1415), as Gossard fits it to 8 194 measured racket bounces
//! ("Learning racket-ball bounce dynamics across diverse rubbers for robotic
//! table tennis", arXiv:2604.11349, 2026; data and fits in
//! github.com/gossardt/tt_rackets), with a Coulomb limit on the tangential
//! impulse. In the bat's frame, with n the face's outward normal and the
//! ball's contact point c = p − r n:
//!
//! - relative velocity u = v − v_s, with v_s the bat surface's velocity at c
//!   (the bat's linear velocity plus ω_bat × (c − bat centre)); the ball
//!   approaches when u_n = u·n < 0;
//! - normal: u_n⁺ = −e u_n with e = e₀ − e₁|u_n| clamped to [0, 1] (a
//!   rubber's restitution falls with the impact speed);
//! - tangential: the slip of the ball's surface at c, s = u − u_n n − r ω×n,
//!   meets the rubber's tangential elasticity: impulse P = −k_p s with
//!   k_p = k₀ − k₁‖s‖ (Nakashima's k_p, in kg; the rubber springs back, so
//!   the slip reverses: s⁺ = (1 − 5k_p/2m) s for a thin shell), but never
//!   more than Coulomb friction allows, ‖P‖ ≤ μ(1 + e) m |u_n| (then the
//!   ball slides on the rubber throughout the contact);
//! - v⁺ = v + (J_n n + P)/m with J_n = (1 + e) m |u_n|, and
//!   ω⁺ = ω + (−r n) × P / I with I = (2/3) m r² (thin shell).
//!
//! Pure functions of their inputs: no clock, no I/O, no allocation.

use serde::{Deserialize, Serialize};

use super::{BallState, Vec3};
use crate::physics::params::InvalidParam;

/// The rubber's constants: `[racket]` in `calib/physics.toml`. Missing keys
/// (and a missing section, in files written before it existed) take the
/// defaults below.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RacketParams {
    /// Normal restitution e₀ of ball on rubber at vanishing impact speed.
    pub restitution: f64,
    /// Fall of the restitution per m/s of normal impact speed, s/m
    /// (e = restitution − restitution_slope·|u_n|, clamped to [0, 1]).
    pub restitution_slope: f64,
    /// Tangential elasticity k₀ (Nakashima's k_p) at vanishing slip, kg: the
    /// tangential impulse per m/s of slip of the ball's surface on the rubber.
    pub k_p: f64,
    /// Fall of k_p per m/s of slip, kg·s/m (k_p = k_p − k_p_slope·‖s‖, ≥ 0).
    pub k_p_slope: f64,
    /// Coulomb friction coefficient ball–rubber: the tangential impulse never
    /// exceeds friction × the normal impulse.
    pub friction: f64,
    /// Radius of the bat's face, taken as a disc about the TCP, m.
    pub bat_radius: f64,
}

impl Default for RacketParams {
    /// An offensive inverted rubber: Gossard's racket 01 (andro Hexer Duro,
    /// 2.1 mm sponge, on an offensive carbon blade), the fits of
    /// `configs/rackets.py` ("stateful" restitution and k_p, linear in the
    /// normal and the slip speed). The friction limit is ours: in that data
    /// set the tangential impulse of the fastest-spinning bounces
    /// (720–770 rad/s) levels off at 0.60–0.63 of (1 + e) m |u_n| where the
    /// linear k_p still follows it; 0.65 lets the limit act only beyond the
    /// measured range (grazing contacts). A 150 × 160 mm blade as a disc of
    /// radius 75 mm.
    fn default() -> Self {
        RacketParams {
            restitution: 0.917,
            restitution_slope: 0.0217,
            k_p: 1.93e-3,
            k_p_slope: 1.98e-5,
            friction: 0.65,
            bat_radius: 0.075,
        }
    }
}

impl RacketParams {
    /// Checks every value; `mass` is the ball's (kg): k_p may not exceed
    /// 0.8 m, where the rubber's spring-back would return more slip than
    /// came in (energy from nowhere). Names the first offending key.
    pub fn validate(&self, mass: f64) -> Result<(), InvalidParam> {
        let checks = [
            ("racket.restitution", self.restitution, (0.0..=1.0).contains(&self.restitution)),
            ("racket.restitution_slope", self.restitution_slope, self.restitution_slope >= 0.0),
            ("racket.k_p", self.k_p, (0.0..=0.8 * mass).contains(&self.k_p)),
            ("racket.k_p_slope", self.k_p_slope, self.k_p_slope >= 0.0),
            ("racket.friction", self.friction, self.friction >= 0.0),
            ("racket.bat_radius", self.bat_radius, self.bat_radius > 0.0 && self.bat_radius < 0.5),
        ];
        match checks.into_iter().find(|(_, v, ok)| !(v.is_finite() && *ok)) {
            Some((key, value, _)) => Err(InvalidParam { key, value }),
            None => Ok(()),
        }
    }
}

/// The bat at one instant, in the table frame T.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Bat {
    /// Centre of the face (the TCP), m.
    pub centre: Vec3,
    /// Outward unit normal of the hitting face.
    pub normal: Vec3,
    /// Linear velocity of the centre, m/s.
    pub vel: Vec3,
    /// Angular velocity, rad/s.
    pub omega: Vec3,
}

impl Bat {
    /// Velocity of the face's material at the point `p`, m/s.
    pub fn surface_velocity(&self, p: &Vec3) -> Vec3 {
        self.vel + self.omega.cross(&(p - self.centre))
    }
}

/// How the rubber gripped the ball.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Regime {
    /// The rubber's tangential elasticity set the impulse (the slip
    /// reverses as the rubber springs back).
    Grip,
    /// Friction limited it: the ball slid on the rubber.
    Slide,
}

/// One ball–bat impact.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Impact {
    /// The ball just after the impact (position unchanged).
    pub after: BallState,
    /// The restitution this impact had.
    pub restitution: f64,
    /// Grip or slide.
    pub regime: Regime,
}

/// The contact model with the ball's mass and radius.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RacketModel {
    /// The rubber's constants.
    pub params: RacketParams,
    /// Ball mass, kg.
    pub mass: f64,
    /// Ball radius, m.
    pub radius: f64,
}

impl RacketModel {
    /// The model of a rubber `params` for a ball of `mass` (kg) and
    /// `radius` (m).
    pub fn new(params: RacketParams, mass: f64, radius: f64) -> Self {
        RacketModel { params, mass, radius }
    }

    /// The ball leaving a face with outward unit normal `normal` whose
    /// material at the contact point moves with `surface_vel`; `None` when
    /// the ball does not approach the face (u_n ≥ 0).
    pub fn hit(&self, ball: &BallState, normal: &Vec3, surface_vel: &Vec3) -> Option<Impact> {
        let (m, r, p) = (self.mass, self.radius, &self.params);
        let n = normal;
        let u = ball.vel - surface_vel;
        let u_n = u.dot(n);
        if u_n >= 0.0 || u_n.is_nan() {
            return None;
        }
        let e = (p.restitution - p.restitution_slope * -u_n).clamp(0.0, 1.0);
        let j_n = (1.0 + e) * m * -u_n;
        let slip = u - n * u_n - ball.spin.cross(n) * r;
        let s = slip.norm();
        let k = (p.k_p - p.k_p_slope * s).max(0.0);
        let (grip, limit) = (k * s, p.friction * j_n);
        let (impulse, regime) =
            if grip <= limit { (-slip * k, Regime::Grip) } else { (-slip * (limit / s), Regime::Slide) };
        let inertia = 2.0 / 3.0 * m * r * r;
        let vel = ball.vel + (n * j_n + impulse) / m;
        let spin = ball.spin + (-n * r).cross(&impulse) / inertia;
        Some(Impact { after: BallState { pos: ball.pos, vel, spin }, restitution: e, regime })
    }

    /// The ball leaving `bat`: the contact point is the ball's point nearest
    /// the face, p − r n.
    pub fn hit_bat(&self, ball: &BallState, bat: &Bat) -> Option<Impact> {
        let contact = ball.pos - bat.normal * self.radius;
        self.hit(ball, &bat.normal, &bat.surface_velocity(&contact))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const M: f64 = 0.0027;
    const R: f64 = 0.02;

    fn model() -> RacketModel {
        RacketModel::new(RacketParams::default(), M, R)
    }

    /// A rubber with constant e and k_p (no speed dependence).
    fn flat(e: f64, k_p: f64, friction: f64) -> RacketModel {
        let p =
            RacketParams { restitution: e, restitution_slope: 0.0, k_p, k_p_slope: 0.0, friction, bat_radius: 0.075 };
        RacketModel::new(p, M, R)
    }

    fn ball(v: Vec3, w: Vec3) -> BallState {
        BallState::new(Vec3::new(1.6, 0.0, 0.3), v, w)
    }

    /// Kinetic energy per unit mass of a thin shell.
    fn energy(s: &BallState, frame_vel: &Vec3) -> f64 {
        0.5 * (s.vel - frame_vel).norm_squared() + 0.5 * (2.0 / 3.0) * R * R * s.spin.norm_squared()
    }

    #[test]
    fn bat_at_rest_normal_incidence_returns_speed_times_e() {
        let m = model();
        let n = Vec3::new(-1.0, 0.0, 0.0);
        let i = m.hit(&ball(Vec3::new(6.0, 0.0, 0.0), Vec3::zeros()), &n, &Vec3::zeros()).unwrap();
        let e = 0.917 - 0.0217 * 6.0;
        assert!((i.restitution - e).abs() < 1e-12);
        assert!((i.after.vel - Vec3::new(-6.0 * e, 0.0, 0.0)).norm() < 1e-12, "{:?}", i.after.vel);
        assert_eq!(i.after.spin, Vec3::zeros());
        assert_eq!(i.regime, Regime::Grip);
    }

    #[test]
    fn a_moving_bat_adds_one_plus_e_times_its_normal_speed() {
        let m = flat(0.8, 1.9e-3, 0.65);
        let n = Vec3::new(-1.0, 0.0, 0.0);
        let b = ball(Vec3::new(5.0, 0.0, 0.0), Vec3::zeros());
        let rest = m.hit(&b, &n, &Vec3::zeros()).unwrap().after.vel;
        let moving = m.hit(&b, &n, &Vec3::new(-1.5, 0.0, 0.0)).unwrap().after.vel;
        // v⁺ = v_b − e (v − v_b) along n: 1.5 m/s more bat gives (1 + e)·1.5.
        assert!((moving.x - (rest.x - 1.8 * 1.5)).abs() < 1e-12, "{rest} {moving}");
        // A bat sliding along its own face adds no normal speed.
        let sliding = m.hit(&b, &n, &Vec3::new(0.0, 0.0, 1.0)).unwrap().after.vel;
        assert!((sliding.x - rest.x).abs() < 1e-12);
        assert!(sliding.z > 0.0, "the rubber drags the ball along: {sliding}");
    }

    #[test]
    fn grip_reverses_the_slip_slide_keeps_its_direction() {
        let n = Vec3::new(-1.0, 0.0, 0.0);
        // Slow oblique ball, no spin: slip along the face 2 m/s upwards.
        let b = ball(Vec3::new(6.0, 0.0, 2.0), Vec3::zeros());
        let slip_after = |i: &Impact| i.after.vel - n * i.after.vel.dot(&n) - i.after.spin.cross(&n) * R;
        let k = 1.9e-3;
        let grip = flat(0.8, k, 10.0).hit(&b, &n, &Vec3::zeros()).unwrap();
        assert_eq!(grip.regime, Regime::Grip);
        let f = 1.0 - 2.5 * k / M;
        assert!((slip_after(&grip) - Vec3::new(0.0, 0.0, 2.0 * f)).norm() < 1e-12, "{}", slip_after(&grip));
        assert!(f < 0.0, "the rubber springs back: slip reverses");
        // Low friction: the impulse is μ(1+e)m|u_n| and the slip shrinks but
        // keeps its sign.
        let mu = 0.05;
        let slide = flat(0.8, k, mu).hit(&b, &n, &Vec3::zeros()).unwrap();
        assert_eq!(slide.regime, Regime::Slide);
        let dv_t = slide.after.vel.z - 2.0;
        assert!((dv_t - -mu * 1.8 * 6.0).abs() < 1e-12, "{dv_t}");
        assert!(slip_after(&slide).z > 0.0 && slip_after(&slide).z < 2.0);
    }

    #[test]
    fn spin_turns_the_return_the_way_players_know() {
        // A ball flying to the robot (+x) meets a vertical face at rest.
        let m = model();
        let n = Vec3::new(-1.0, 0.0, 0.0);
        let v = Vec3::new(6.0, 0.0, 0.0);
        let top = m.hit(&ball(v, Vec3::new(0.0, 300.0, 0.0)), &n, &Vec3::zeros()).unwrap().after;
        let back = m.hit(&ball(v, Vec3::new(0.0, -300.0, 0.0)), &n, &Vec3::zeros()).unwrap().after;
        // Topspin (ω_y > 0 flying +x) kicks up off the bat, backspin drops:
        // why a topspin ball is met with a closed face, backspin with an open one.
        assert!(top.vel.z > 0.5 && back.vel.z < -0.5, "{} {}", top.vel, back.vel);
        // The rubber springs back: it takes nearly all the incoming spin off
        // (Gossard's data: 733 → 120 rad/s on a near-normal bounce).
        assert!(top.spin.y.abs() < 0.2 * 300.0, "{}", top.spin);
        // Sidespin (ω_z) throws the ball sideways.
        let side = m.hit(&ball(v, Vec3::new(0.0, 0.0, 300.0)), &n, &Vec3::zeros()).unwrap().after;
        // Contact at +x: surface velocity ω × (r x̂) = ω_z r ŷ, slip +y, impulse −y.
        assert!(side.vel.y < -0.5, "{}", side.vel);
    }

    #[test]
    fn a_ball_leaving_the_face_is_not_hit() {
        let n = Vec3::new(-1.0, 0.0, 0.0);
        assert!(model().hit(&ball(Vec3::new(-3.0, 0.0, 0.0), Vec3::zeros()), &n, &Vec3::zeros()).is_none());
        // A bat running away faster than the ball.
        assert!(model().hit(&ball(Vec3::new(2.0, 0.0, 0.0), Vec3::zeros()), &n, &Vec3::new(3.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn a_turning_bat_moves_its_face_where_the_ball_touches() {
        let bat = Bat {
            centre: Vec3::new(1.6, 0.0, 0.3),
            normal: Vec3::new(-1.0, 0.0, 0.0),
            vel: Vec3::zeros(),
            omega: Vec3::new(0.0, -10.0, 0.0),
        };
        // Contact 5 cm above the centre: ω × (0, 0, 0.05) = (−0.5, 0, 0).
        let p = Vec3::new(1.6 - R, 0.0, 0.35);
        assert!((bat.surface_velocity(&(p + Vec3::new(R, 0.0, 0.0))) - Vec3::new(-0.5, 0.0, 0.0)).norm() < 1e-12);
        let b = BallState::new(p, Vec3::new(5.0, 0.0, 0.0), Vec3::zeros());
        let turning = model().hit_bat(&b, &bat).unwrap().after.vel;
        let still = model().hit_bat(&b, &Bat { omega: Vec3::zeros(), ..bat }).unwrap().after.vel;
        assert!(turning.x < still.x - 0.5, "{turning} {still}");
    }

    #[test]
    fn validation_names_the_key() {
        let mut p = RacketParams::default();
        assert!(p.validate(M).is_ok());
        p.k_p = 0.9 * M;
        assert_eq!(p.validate(M).unwrap_err().key, "racket.k_p");
        p = RacketParams { restitution: 1.2, ..RacketParams::default() };
        assert_eq!(p.validate(M).unwrap_err().key, "racket.restitution");
        p = RacketParams { bat_radius: f64::NAN, ..RacketParams::default() };
        assert_eq!(p.validate(M).unwrap_err().key, "racket.bat_radius");
    }

    proptest! {
        #[test]
        fn a_resting_bat_never_adds_energy(
            (vx, vy, vz) in (0.5..15.0f64, -5.0..5.0f64, -5.0..5.0f64),
            (wx, wy, wz) in (-900.0..900.0f64, -900.0..900.0f64, -900.0..900.0f64),
            e in 0.0..1.0f64, k_frac in 0.0..0.8f64, mu in 0.0..2.0f64,
        ) {
            let m = flat(e, k_frac * M, mu);
            let b = ball(Vec3::new(vx, vy, vz), Vec3::new(wx, wy, wz));
            let n = Vec3::new(-1.0, 0.0, 0.0);
            let i = m.hit(&b, &n, &Vec3::zeros()).unwrap();
            prop_assert!(energy(&i.after, &Vec3::zeros()) <= energy(&b, &Vec3::zeros()) * (1.0 + 1e-12) + 1e-12);
            prop_assert!(i.after.vel.dot(&n) >= 0.0);
            // The rubber cannot change the spin about its own normal.
            prop_assert!((i.after.spin.dot(&n) - b.spin.dot(&n)).abs() < 1e-9);
        }
    }
}
