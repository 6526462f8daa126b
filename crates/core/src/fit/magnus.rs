//! The paper's spin fit (§IV-A): with P′, P″ from the cubic, each sample
//! gives k_M ω × P′(t) = P″(t) + k_D‖P′‖P′ + g e_z; all of them stacked are
//! solved for a constant ω by linear least squares. Allocation-free: the
//! 3×3 normal equations are accumulated directly.

use nalgebra::Matrix3;

use super::poly::Cubic;
use crate::physics::{FlightModel, Vec3};

/// The least-squares spin and the normal matrix MᵀM of the solve (its
/// eigenvalues say how well each direction of ω is determined).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct MagnusSolve {
    /// ω under the constant coefficient k_M(0), rad/s.
    pub spin_linear: Vec3,
    /// MᵀM of the stacked system, (rad/s)⁻² · (m/s²)².
    pub normal: Matrix3<f64>,
    /// Mean speed over the samples, m/s.
    pub mean_speed: f64,
}

/// Solves for ω over the sample times `times` (at least two, with the
/// velocity turning, for a unique answer). `None` if singular.
pub fn solve(cubic: &Cubic, times: impl Iterator<Item = f64>, model: &FlightModel) -> Option<MagnusSolve> {
    let k_m = model.k_m0();
    let k_d = model.k_d();
    let g = Vec3::new(0.0, 0.0, model.gravity());
    let mut mtm = Matrix3::<f64>::zeros();
    let mut mta = Vec3::zeros();
    let (mut speed_sum, mut n) = (0.0, 0usize);
    for t in times {
        let v = cubic.vel(t);
        let speed = v.norm();
        let a = cubic.acc(t) + v * (k_d * speed) + g;
        // Row block M = −k_M [v]×  (ω × v = −[v]× ω), so
        // MᵀM = k_M² (‖v‖² I − v vᵀ) and Mᵀa = k_M (v × a).
        let vv = speed * speed;
        mtm += (Matrix3::from_diagonal_element(vv) - v * v.transpose()) * (k_m * k_m);
        mta += v.cross(&a) * k_m;
        speed_sum += speed;
        n += 1;
    }
    if n == 0 {
        return None;
    }
    // A tiny ridge keeps the solve defined when the velocity never turns
    // (the component of ω along v is then unobservable and comes out 0).
    let ridge = mtm.trace() * 1e-9 + 1e-12;
    let spin_linear = (mtm + Matrix3::identity() * ridge).cholesky()?.solve(&mta);
    spin_linear.iter().all(|c| c.is_finite()).then_some(MagnusSolve {
        spin_linear,
        normal: mtm,
        mean_speed: speed_sum / n as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Sample;
    use crate::physics::{BallState, PhysicsParams, Propagator, Table};

    #[test]
    fn recovers_spin_from_a_noise_free_flight() {
        let p = PhysicsParams::paper();
        let prop = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        let spin = Vec3::new(0.0, -250.0, 60.0);
        let mut s = BallState::new(Vec3::new(-1.4, 0.0, 0.3), Vec3::new(6.0, 0.2, 1.0), spin);
        let mut samples = Vec::new();
        for i in 0..45 {
            samples.push(Sample::new(i as f64 / 150.0, s.pos));
            s = prop.fly(&s, 1.0 / 150.0);
        }
        let c = Cubic::fit(samples.iter()).unwrap();
        let m = solve(&c, samples.iter().map(|s| s.t), &prop.flight).unwrap();
        // The paper's method is biased by the cubic's approximation; within 10 %.
        let err = (m.spin_linear - spin).norm() / spin.norm();
        assert!(err < 0.1, "spin {:?} vs {spin:?}: {err}", m.spin_linear);
    }
}
