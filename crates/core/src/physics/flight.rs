//! The flight model: dv/dt = −k_D‖v‖v + k_M(S)·(ω × v) − g e_z.
//!
//! k_D = C_D ρ A / (2m) (the paper prints it with a stray minus sign; drag
//! opposes motion). The Magnus coefficient k_M = C_M ρ A r / (2m) may fall
//! with the spin parameter S = r‖ω‖/‖v‖, as measured for real balls
//! ([`LiftModel::Saturating`], or a measured curve C_L(S) itself,
//! [`LiftModel::Measured`]); the paper's constant is
//! [`LiftModel::Constant`]. Spin is constant during flight.

use serde::{Deserialize, Serialize};

use nalgebra::Matrix3;

use super::{PhysicsParams, Vec3};

/// How the Magnus coefficient depends on the spin parameter S = r‖ω‖/‖v‖.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum LiftModel {
    /// The paper's model: C_M constant, so the lift force grows linearly
    /// with ‖ω‖.
    Constant {
        /// The Magnus coefficient C_M.
        c_m: f64,
    },
    /// C_M(S) = c_m / (1 + S / s_half): linear in ω at low spin, saturating
    /// at high spin (S ≫ s_half). Sawicki et al.'s C_L = S/(1 + 2S) is the
    /// member c_m = 1, s_half = 0.5.
    Saturating {
        /// C_M at vanishing spin parameter.
        c_m: f64,
        /// Spin parameter at which C_M has fallen to half of `c_m`.
        s_half: f64,
    },
    /// The saturating lift with a "lift crisis": a valley of C_L around
    /// `s_valley`, C_M(S) = c_m / (1 + S / s_half) · (1 − depth ·
    /// exp(−½((S − s_valley)/width)²)). The shape measured in flight for a
    /// Nittaku ball at Re ≈ 9·10⁴ (DESIGN §3): lift nearly vanishes near
    /// S ≈ 0.5. A world for the simulator; no estimator assumes it.
    Crisis {
        /// C_M at vanishing spin parameter.
        c_m: f64,
        /// Spin parameter at which the saturation halves C_M.
        s_half: f64,
        /// Spin parameter at the bottom of the valley.
        s_valley: f64,
        /// Share of the lift lost at the bottom (0–1).
        depth: f64,
        /// Width (standard deviation) of the valley in S.
        width: f64,
    },
    /// A lift coefficient measured on real balls: C_L(S) linear between
    /// the points (S_i, C_L_i), from C_L(0) = 0 to the first point and
    /// flat beyond the last; C_M = C_L / S. No law is assumed, so a curve
    /// that saturates the way real balls do (docs/physics.md) is flown as
    /// it was measured.
    Measured {
        /// Spin parameters S_i of the points, increasing.
        s: LiftPoints,
        /// Lift coefficients C_L at them.
        c_l: LiftPoints,
    },
}

/// Up to [`LiftPoints::CAP`] numbers of a measured lift curve, in a fixed
/// array so that a flight model stays `Copy` (written in TOML as a list).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LiftPoints {
    values: [f64; LiftPoints::CAP],
    len: u8,
}

impl LiftPoints {
    /// The most points a curve holds.
    pub const CAP: usize = 8;

    /// The points in `values`, or `None` where there are none or more
    /// than [`Self::CAP`].
    pub fn new(values: &[f64]) -> Option<Self> {
        if values.is_empty() || values.len() > Self::CAP {
            return None;
        }
        let mut v = [0.0; Self::CAP];
        v[..values.len()].copy_from_slice(values);
        Some(LiftPoints { values: v, len: values.len() as u8 })
    }

    /// The numbers held.
    pub fn as_slice(&self) -> &[f64] {
        &self.values[..usize::from(self.len)]
    }
}

impl Serialize for LiftPoints {
    fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
        self.as_slice().serialize(ser)
    }
}

impl<'de> Deserialize<'de> for LiftPoints {
    fn deserialize<D: serde::Deserializer<'de>>(de: D) -> Result<Self, D::Error> {
        let v = Vec::<f64>::deserialize(de)?;
        LiftPoints::new(&v).ok_or_else(|| {
            serde::de::Error::custom(format!("a lift curve has 1 to {} points, not {}", LiftPoints::CAP, v.len()))
        })
    }
}

/// C_L at `s` on the measured curve (`s` and `c_l` of equal length, `s`
/// increasing: [`super::PhysicsParams::validate`] checks it).
fn measured_c_l(s_pts: &[f64], c_l: &[f64], s: f64) -> f64 {
    let (mut s0, mut c0) = (0.0, 0.0);
    for (&s1, &c1) in s_pts.iter().zip(c_l) {
        if s <= s1 {
            return if s1 > s0 { c0 + (c1 - c0) * (s - s0) / (s1 - s0) } else { c1 };
        }
        (s0, c0) = (s1, c1);
    }
    c0
}

impl LiftModel {
    /// C_M at spin parameter `s`.
    pub fn c_m(&self, s: f64) -> f64 {
        match *self {
            LiftModel::Constant { c_m } => c_m,
            LiftModel::Saturating { c_m, s_half } => c_m / (1.0 + s / s_half),
            LiftModel::Crisis { c_m, s_half, s_valley, depth, width } => {
                let z = (s - s_valley) / width;
                c_m / (1.0 + s / s_half) * (1.0 - depth * (-0.5 * z * z).exp())
            }
            LiftModel::Measured { s: s_pts, c_l } => {
                let (s_pts, c_l) = (s_pts.as_slice(), c_l.as_slice());
                if s > 1e-9 { measured_c_l(s_pts, c_l, s) / s } else { c_l[0] / s_pts[0].max(1e-9) }
            }
        }
    }

    /// C_M at vanishing spin.
    pub fn c_m0(&self) -> f64 {
        match *self {
            LiftModel::Constant { c_m } | LiftModel::Saturating { c_m, .. } | LiftModel::Crisis { c_m, .. } => c_m,
            LiftModel::Measured { .. } => self.c_m(0.0),
        }
    }

    /// The lift coefficient C_L = C_M·S at `s`.
    pub fn c_l(&self, s: f64) -> f64 {
        self.c_m(s) * s
    }
}

/// Per-flight multipliers of the drag and the lift: a ball, the air and
/// the day are not exactly the calibration (DESIGN §3). The refined fit
/// estimates them from a flight; 1 is the calibration itself.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FlightScales {
    /// Multiplier of k_D.
    pub drag: f64,
    /// Multiplier of the Magnus coefficient (the whole C_L(S) curve).
    pub lift: f64,
}

impl FlightScales {
    /// The calibration itself.
    pub const ONE: FlightScales = FlightScales { drag: 1.0, lift: 1.0 };
}

/// The ball's equation of motion with its coefficients precomputed.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FlightModel {
    k_d: f64,
    /// ρ A r / (2m): multiply by C_M to get k_M.
    lift_scale: f64,
    lift: LiftModel,
    radius: f64,
    gravity: f64,
}

impl FlightModel {
    /// The flight model of the ball, air and lift constants in `p`.
    pub fn new(p: &PhysicsParams) -> Self {
        let area = std::f64::consts::PI * p.radius * p.radius;
        FlightModel {
            k_d: p.drag_coefficient * p.air_density * area / (2.0 * p.mass),
            lift_scale: p.air_density * area * p.radius / (2.0 * p.mass),
            lift: p.lift,
            radius: p.radius,
            gravity: p.gravity,
        }
    }

    /// This model with its drag and lift multiplied by `scales`.
    pub fn scaled(&self, scales: FlightScales) -> FlightModel {
        FlightModel { k_d: self.k_d * scales.drag, lift_scale: self.lift_scale * scales.lift, ..*self }
    }

    /// Drag coefficient k_D in 1/m.
    pub fn k_d(&self) -> f64 {
        self.k_d
    }

    /// Magnus coefficient at vanishing spin, k_M(0).
    pub(crate) fn k_m0(&self) -> f64 {
        self.lift_scale * self.lift.c_m0()
    }

    /// Magnus coefficient k_M at the given velocity and spin.
    pub fn k_m(&self, vel: &Vec3, spin: &Vec3) -> f64 {
        self.k_m_at(vel.norm(), spin.norm())
    }

    /// k_M at speed `speed` and spin rate `w` (‖v‖ and ‖ω‖, already known
    /// to the caller).
    #[inline]
    fn k_m_at(&self, speed: f64, w: f64) -> f64 {
        match self.lift {
            LiftModel::Constant { c_m } => self.lift_scale * c_m,
            // C_M / (1 + S/S½) with S = r‖ω‖/‖v‖, in one division (the
            // flight's inner loop).
            LiftModel::Saturating { c_m, s_half } => {
                let d = speed * s_half + self.radius * w;
                if speed > 1e-9 { self.lift_scale * c_m * (speed * s_half / d) } else { self.lift_scale * c_m }
            }
            LiftModel::Crisis { .. } | LiftModel::Measured { .. } => {
                let s = if speed > 1e-9 { self.radius * w / speed } else { 0.0 };
                self.lift_scale * self.lift.c_m(s)
            }
        }
    }

    /// k_M at `vel`, `spin` with its gradients with respect to the
    /// velocity and the spin (zero for a constant lift): what a Jacobian
    /// of the Magnus acceleration k_M(S)·(ω × v) needs beyond k_M itself.
    pub fn k_m_with_gradients(&self, vel: &Vec3, spin: &Vec3) -> (f64, Vec3, Vec3) {
        let k_m = self.k_m(vel, spin);
        let (speed, w) = (vel.norm(), spin.norm());
        if matches!(self.lift, LiftModel::Constant { .. }) || speed < 1e-9 || w < 1e-9 {
            return (k_m, Vec3::zeros(), Vec3::zeros());
        }
        let s = self.radius * w / speed;
        // dC_M/dS by a central difference (exact enough for a Jacobian).
        let h = 1e-6 * (1.0 + s);
        let lo = (s - h).max(0.0);
        let dk_ds = self.lift_scale * (self.lift.c_m(s + h) - self.lift.c_m(lo)) / (s + h - lo);
        // S = r‖ω‖/‖v‖: ∂S/∂ω = r ω̂/‖v‖, ∂S/∂v = −S v̂/‖v‖.
        let d_dw = spin * (dk_ds * self.radius / (w * speed));
        let d_dv = vel * (-dk_ds * s / (speed * speed));
        (k_m, d_dv, d_dw)
    }

    /// The acceleration's derivatives at `vel`, `spin`: ∂a/∂v and ∂a/∂ω
    /// (the flight's Jacobian for a filter's or a fit's sensitivities).
    pub fn accel_jacobians(&self, vel: &Vec3, spin: &Vec3) -> (Matrix3<f64>, Matrix3<f64>) {
        let speed = vel.norm().max(1e-9);
        let (k_m, dk_dv, dk_dw) = self.k_m_with_gradients(vel, spin);
        // ∂a/∂v = −k_D(‖v‖ I + v vᵀ/‖v‖) + k_M [ω]× + (ω×v) ∂k_M/∂vᵀ;
        // ∂a/∂ω = −k_M [v]× + (ω×v) ∂k_M/∂ωᵀ (k_M falls with S where the lift saturates).
        let magnus = spin.cross(vel);
        let dadv = -(Matrix3::identity() * speed + vel * vel.transpose() / speed) * self.k_d
            + spin.cross_matrix() * k_m
            + magnus * dk_dv.transpose();
        let dadw = -vel.cross_matrix() * k_m + magnus * dk_dw.transpose();
        (dadv, dadw)
    }

    /// The lift model C_M(S).
    pub fn lift(&self) -> LiftModel {
        self.lift
    }

    /// Ball radius in m.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Gravitational acceleration in m/s² (acting along −z).
    pub fn gravity(&self) -> f64 {
        self.gravity
    }

    /// The ball's acceleration at velocity `vel` with spin `spin`.
    #[inline]
    pub fn accel(&self, vel: &Vec3, spin: &Vec3) -> Vec3 {
        self.accel_spinning(vel, spin, spin.norm())
    }

    /// [`Self::accel`] with ‖ω‖ = `w` known (constant over a flight step).
    #[inline]
    pub(crate) fn accel_spinning(&self, vel: &Vec3, spin: &Vec3, w: f64) -> Vec3 {
        let speed = vel.norm();
        let mut a = vel * (-self.k_d * speed) + spin.cross(vel) * self.k_m_at(speed, w);
        a.z -= self.gravity;
        a
    }

    /// The spin whose Magnus acceleration under this model equals that of
    /// `spin_linear` under the constant coefficient k_M(0) at speed `speed`
    /// (same direction, magnitude corrected for lift saturation). This maps
    /// a spin solved linearly with k_M(0), as in the paper's fit, onto this
    /// model. Returns `None` where no finite spin produces that much lift.
    pub(crate) fn spin_from_linear(&self, spin_linear: &Vec3, speed: f64) -> Option<Vec3> {
        match self.lift {
            LiftModel::Constant { .. } => Some(*spin_linear),
            LiftModel::Saturating { s_half, .. } => {
                // |ω| / (1 + r|ω|/(v s_half)) = m  ⇒  |ω| = m / (1 − r m / (v s_half))
                let m = spin_linear.norm();
                let denom = 1.0 - self.radius * m / (speed.max(1e-9) * s_half);
                (denom > 1e-3).then(|| spin_linear / denom)
            }
            // Not monotonic in ω: no unique inverse.
            LiftModel::Crisis { .. } => None,
            LiftModel::Measured { .. } => self.spin_by_bisection(spin_linear, speed),
        }
    }

    /// [`Self::spin_from_linear`] for any lift whose force grows with the
    /// spin: bisection on ‖ω‖ up to 3000 rad/s (far beyond real balls).
    fn spin_by_bisection(&self, spin_linear: &Vec3, speed: f64) -> Option<Vec3> {
        let m = spin_linear.norm();
        if m < 1e-9 {
            return Some(*spin_linear);
        }
        let force = |w: f64| self.k_m_at(speed, w) * w;
        let target = self.k_m0() * m;
        let (mut lo, mut hi) = (0.0, 3000.0);
        if force(hi) < target {
            return None;
        }
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if force(mid) < target { lo = mid } else { hi = mid }
        }
        Some(spin_linear * (0.5 * (lo + hi) / m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drag_opposes_motion_and_gravity_pulls_down() {
        let m = PhysicsParams::paper().flight_model();
        let a = m.accel(&Vec3::new(5.0, 0.0, 0.0), &Vec3::zeros());
        assert!(a.x < 0.0);
        assert!((a.x + m.k_d() * 25.0).abs() < 1e-12);
        assert_eq!(a.z, -9.81);
    }

    #[test]
    fn topspin_pushes_down_backspin_lifts() {
        let m = PhysicsParams::paper().flight_model();
        let v = Vec3::new(6.0, 0.0, 0.0);
        let top = m.accel(&v, &Vec3::new(0.0, 300.0, 0.0));
        let back = m.accel(&v, &Vec3::new(0.0, -300.0, 0.0));
        assert!(top.z < -9.81 && back.z > -9.81);
    }

    #[test]
    fn k_m_gradients_match_finite_differences() {
        let mut p = PhysicsParams::paper();
        p.lift = LiftModel::Saturating { c_m: 1.0, s_half: 0.5 };
        let m = p.flight_model();
        let v = Vec3::new(6.0, 0.5, 1.0);
        let w = Vec3::new(20.0, -300.0, 80.0);
        let (k, dv, dw) = m.k_m_with_gradients(&v, &w);
        assert_eq!(k, m.k_m(&v, &w));
        for a in 0..3 {
            let e = Vec3::ith(a, 1e-5);
            let num_v = (m.k_m(&(v + e), &w) - m.k_m(&(v - e), &w)) / 2e-5;
            let num_w = (m.k_m(&v, &(w + e)) - m.k_m(&v, &(w - e))) / 2e-5;
            assert!((num_v - dv[a]).abs() < 1e-9 && (num_w - dw[a]).abs() < 1e-11, "{a}: {num_v} {dv} {num_w} {dw}");
        }
        let (_, dv0, dw0) = PhysicsParams::paper().flight_model().k_m_with_gradients(&v, &w);
        assert_eq!((dv0, dw0), (Vec3::zeros(), Vec3::zeros()));
    }

    #[test]
    fn saturating_lift_inverts_the_linear_spin() {
        let mut p = PhysicsParams::paper();
        p.lift = LiftModel::Saturating { c_m: 0.6, s_half: 0.4 };
        let m = p.flight_model();
        let v = Vec3::new(7.0, 0.0, 1.0);
        let w = Vec3::new(10.0, -400.0, 30.0);
        // Magnus acceleration of w under the saturating model, expressed as
        // an equivalent spin under the constant k_M(0):
        let w_lin = w * (m.k_m(&v, &w) / m.k_m0());
        let back = m.spin_from_linear(&w_lin, v.norm()).unwrap();
        assert!((back - w).norm() < 1e-9);
    }

    #[test]
    fn a_measured_curve_is_flown_as_measured() {
        let pts = |v: &[f64]| LiftPoints::new(v).unwrap();
        let lift = LiftModel::Measured { s: pts(&[0.2, 0.4, 0.75]), c_l: pts(&[0.19, 0.24, 0.25]) };
        assert!((lift.c_l(0.1) - 0.095).abs() < 1e-12);
        assert!((lift.c_l(0.3) - 0.215).abs() < 1e-12);
        assert_eq!(lift.c_l(2.0), 0.25);
        assert!((lift.c_m0() - 0.95).abs() < 1e-12);
        let mut p = PhysicsParams::paper();
        p.lift = lift;
        let m = p.flight_model();
        let v = Vec3::new(7.0, 0.0, 1.0);
        let w = Vec3::new(10.0, -100.0, 30.0);
        let w_lin = w * (m.k_m(&v, &w) / m.k_m0());
        let back = m.spin_from_linear(&w_lin, v.norm()).unwrap();
        assert!((back - w).norm() < 1e-6, "{back:?}");
        // More bend than the flat top of the curve can give: no spin does it.
        assert_eq!(m.spin_from_linear(&(w_lin * 50.0), v.norm()), None);
        assert!(LiftPoints::new(&[0.0; 9]).is_none() && LiftPoints::new(&[]).is_none());
    }
}
