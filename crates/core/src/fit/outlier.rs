//! The paper's start-of-trajectory outlier filter (§IV-B): of the first 20
//! observations, fit a cubic to the last five accepted ones and test the
//! one before them; accept it (it joins the window, which slides back) if
//! it lies close to the fit's extrapolation, otherwise reject it and test
//! the next earlier one against the same window. False detections at the
//! start (a hand near the launcher) are removed this way.
//!
//! Two choices the paper leaves open, made here:
//! - The local fit is a quadratic, not the paper's cubic: over five samples
//!   (≈ 30 ms) the flight is a parabola to well under a millimetre, and a
//!   cubic through five noisy points extrapolated two samples back (after
//!   a rejection) amplifies the noise about tenfold, which hides a hand
//!   10 cm off.
//! - "A specific threshold" is a prediction interval: `n_sigma` × noise ×
//!   √(1 + φᵀ(ΦᵀΦ)⁻¹φ) (the extrapolation's own uncertainty from the
//!   window's geometry) plus a fixed model allowance, so it adapts to noise
//!   and irregular sampling.

use heapless::Vec as HVec;
use nalgebra::{Matrix3, Vector3};

use super::Sample;
use crate::physics::Vec3;

/// How many observations at the start of a trajectory are checked.
pub(crate) const START_WINDOW: usize = 20;
/// How many accepted observations each local fit uses.
pub(crate) const LOCAL_FIT_LEN: usize = 5;

/// Settings of the start filter.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StartFilter {
    /// Per-axis observation noise σ, m.
    pub noise: f64,
    /// Width of the prediction interval in σ.
    pub n_sigma: f64,
    /// Added tolerance for the cubic's own model error, m.
    pub model_allowance: f64,
}

impl Default for StartFilter {
    fn default() -> Self {
        StartFilter { noise: 0.002, n_sigma: 5.0, model_allowance: 0.005 }
    }
}

impl StartFilter {
    /// The 0-based indices among `samples` rejected as start outliers,
    /// ascending.
    pub fn outliers(&self, samples: &[Sample]) -> HVec<usize, START_WINDOW> {
        let mut rejected: HVec<usize, START_WINDOW> = HVec::new();
        let m = samples.len().min(START_WINDOW);
        if m <= LOCAL_FIT_LEN {
            return rejected;
        }
        // The window: the LOCAL_FIT_LEN accepted samples nearest after the candidate.
        let mut window: [usize; LOCAL_FIT_LEN] = core::array::from_fn(|k| m - LOCAL_FIT_LEN + k);
        for candidate in (0..m - LOCAL_FIT_LEN).rev() {
            let s = &samples[candidate];
            let Some((predicted, variance_factor)) = extrapolate(samples, &window, s.t) else {
                continue;
            };
            let miss = (predicted - s.pos).norm();
            let limit = self.n_sigma * self.noise * (1.0 + variance_factor).sqrt() + self.model_allowance;
            if miss <= limit {
                window.rotate_right(1);
                window[0] = candidate;
            } else {
                // Capacity is START_WINDOW ≥ m: cannot overflow.
                let _ = rejected.push(candidate);
            }
        }
        rejected.reverse();
        rejected
    }
}

/// Least-squares parabola per axis through the window's samples, evaluated
/// at `t`, with φᵀ(ΦᵀΦ)⁻¹φ there.
fn extrapolate(samples: &[Sample], window: &[usize], t: f64) -> Option<(Vec3, f64)> {
    let t0 = samples[window[0]].t;
    let span = (samples[window[window.len() - 1]].t - t0).max(1e-9);
    let phi = |ti: f64| {
        let x = (ti - t0) / span;
        Vector3::new(1.0, x, x * x)
    };
    let mut a = Matrix3::<f64>::zeros();
    let mut b = Matrix3::<f64>::zeros();
    for &i in window {
        let p = phi(samples[i].t);
        a += p * p.transpose();
        b += p * samples[i].pos.transpose();
    }
    let inv = a.try_inverse()?;
    let coef = inv * b;
    let p = phi(t);
    let predicted = (p.transpose() * coef).transpose();
    Some((predicted, (p.transpose() * inv * p)[0]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{BallState, PhysicsParams, Propagator, Table, Vec3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn flight(noise: f64, seed: u64) -> Vec<Sample> {
        let p = PhysicsParams::paper();
        let prop = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0, noise).unwrap();
        let mut s = BallState::new(Vec3::new(-1.5, 0.0, 0.3), Vec3::new(7.0, 0.3, 1.0), Vec3::new(0.0, 300.0, 0.0));
        (0..40)
            .map(|i| {
                let out = Sample::new(
                    i as f64 / 150.0,
                    s.pos + Vec3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng)),
                );
                s = prop.fly(&s, 1.0 / 150.0);
                out
            })
            .collect()
    }

    #[test]
    fn clean_flights_lose_nothing() {
        let f = StartFilter::default();
        for seed in 0..50 {
            let s = flight(0.002, seed);
            assert!(f.outliers(&s).is_empty(), "seed {seed}: {:?}", f.outliers(&s));
        }
    }

    #[test]
    fn false_detections_at_the_start_are_removed() {
        let f = StartFilter::default();
        for seed in 0..50 {
            let mut s = flight(0.002, seed);
            s[0].pos += Vec3::new(-0.05, 0.08, -0.03);
            s[1].pos += Vec3::new(0.10, -0.02, 0.05);
            let out = f.outliers(&s);
            assert_eq!(out.as_slice(), &[0, 1], "seed {seed}");
        }
    }
}
