//! Least-squares cubic P(t) per axis, as the paper fits to the observations
//! (§IV-A). Time is centred and scaled to [−1, 1] over the samples so the
//! normal equations stay well conditioned. Allocation-free.

use nalgebra::{Matrix4, Vector4};

use super::Sample;
use crate::physics::Vec3;

/// P(τ) = c₀ + c₁τ + c₂τ² + c₃τ³ per axis, with τ = (t − t_mid) / half_span.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Cubic {
    t_mid: f64,
    half_span: f64,
    coef: [Vec3; 4],
}

/// The basis (1, τ, τ², τ³) at τ.
fn basis(tau: f64) -> Vector4<f64> {
    Vector4::new(1.0, tau, tau * tau, tau * tau * tau)
}

impl Cubic {
    /// Fits the samples; `None` with fewer than four distinct times or a
    /// singular system.
    pub fn fit<'a>(samples: impl Iterator<Item = &'a Sample> + Clone) -> Option<Cubic> {
        let (mut lo, mut hi, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
        for s in samples.clone() {
            lo = lo.min(s.t);
            hi = hi.max(s.t);
            n += 1;
        }
        if n < 4 || hi <= lo {
            return None;
        }
        let t_mid = 0.5 * (lo + hi);
        let half_span = 0.5 * (hi - lo);
        let mut a = Matrix4::<f64>::zeros();
        let mut b = [Vector4::<f64>::zeros(); 3];
        for s in samples {
            let phi = basis((s.t - t_mid) / half_span);
            a += phi * phi.transpose();
            for (axis, b_axis) in b.iter_mut().enumerate() {
                *b_axis += phi * s.pos[axis];
            }
        }
        let chol = a.cholesky()?;
        let mut coef = [Vec3::zeros(); 4];
        for (axis, b_axis) in b.iter().enumerate() {
            let c = chol.solve(b_axis);
            for k in 0..4 {
                coef[k][axis] = c[k];
            }
        }
        let cubic = Cubic { t_mid, half_span, coef };
        cubic.coef.iter().all(|c| c.iter().all(|v| v.is_finite())).then_some(cubic)
    }

    /// How far P′(t) scatters with the samples' noise: its variance per
    /// unit variance of one sample's coordinate, for the fit of `samples`
    /// (the ones it was fitted to), b′ᵀ(AᵀA)⁻¹b′ with b′ the basis's
    /// derivative at `t`. `None` where the system is singular.
    pub fn vel_spread<'a>(&self, samples: impl Iterator<Item = &'a Sample>, t: f64) -> Option<f64> {
        let mut a = Matrix4::<f64>::zeros();
        for s in samples {
            let phi = basis(self.tau(s.t));
            a += phi * phi.transpose();
        }
        let x = self.tau(t);
        let db = Vector4::new(0.0, 1.0, 2.0 * x, 3.0 * x * x) / self.half_span;
        Some(db.dot(&a.cholesky()?.solve(&db)))
    }

    fn tau(&self, t: f64) -> f64 {
        (t - self.t_mid) / self.half_span
    }

    /// P(t).
    pub fn pos(&self, t: f64) -> Vec3 {
        let x = self.tau(t);
        let c = &self.coef;
        c[0] + (c[1] + (c[2] + c[3] * x) * x) * x
    }

    /// P′(t).
    pub fn vel(&self, t: f64) -> Vec3 {
        let x = self.tau(t);
        let c = &self.coef;
        (c[1] + (c[2] * 2.0 + c[3] * (3.0 * x)) * x) / self.half_span
    }

    /// P″(t).
    pub fn acc(&self, t: f64) -> Vec3 {
        let x = self.tau(t);
        let c = &self.coef;
        (c[2] * 2.0 + c[3] * (6.0 * x)) / (self.half_span * self.half_span)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_cubic() {
        let p = |t: f64| Vec3::new(1.0 + 2.0 * t - t * t + 0.5 * t * t * t, -t, 3.0 - 4.9 * t * t);
        let samples: Vec<Sample> = (0..30).map(|i| Sample::new(10.0 + i as f64 * 0.01, p(i as f64 * 0.01))).collect();
        let c = Cubic::fit(samples.iter()).unwrap();
        let t = 10.13;
        let x = 0.13;
        assert!((c.pos(t) - p(x)).norm() < 1e-9);
        assert!((c.vel(t) - Vec3::new(2.0 - 2.0 * x + 1.5 * x * x, -1.0, -9.8 * x)).norm() < 1e-7);
        assert!((c.acc(t) - Vec3::new(-2.0 + 3.0 * x, 0.0, -9.8)).norm() < 1e-5);
    }

    #[test]
    fn too_few_samples_is_none() {
        let s = [Sample::new(0.0, Vec3::zeros()); 3];
        assert!(Cubic::fit(s.iter()).is_none());
        let s = [Sample::new(0.0, Vec3::zeros()); 6];
        assert!(Cubic::fit(s.iter()).is_none());
    }
}
