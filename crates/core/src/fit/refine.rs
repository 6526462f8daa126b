//! Our refinement of the paper's fit: the flight model itself is fitted to
//! the observed positions by Levenberg–Marquardt over the initial position,
//! velocity and spin (nine parameters), started from the paper's estimate.
//! Unlike the cubic, the model has no approximation bias, and every sample
//! counts with its real weight.
//!
//! - Robust: Huber weights (k·σ), and samples beyond `reject_sigma` of the
//!   converged fit are named outliers and left out.
//! - Observability: only the spin perpendicular to the velocity shows in a
//!   trajectory. The data's information about ω (with position and velocity
//!   marginalised) is reported as a standard deviation per axis and the
//!   weakest direction; a weak prior keeps the spin along the flight
//!   direction at the first sample near zero where the data cannot say (a
//!   wheel or a racket imparts spin by tangential friction, perpendicular to
//!   the exit velocity), instead of inventing it.
//! - The Jacobian is by forward differences, with all ten trajectories
//!   integrated in lock step through the sample times (RK4, step ≤ the
//!   propagator's), so nothing is stored per sample.

use nalgebra::{SMatrix, SVector};

use super::Sample;
use crate::physics::{BallState, Propagator, Vec3};

type M9 = SMatrix<f64, 9, 9>;
type V9 = SVector<f64, 9>;

/// Settings of the refinement.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RefineConfig {
    /// Per-axis observation noise σ, m.
    pub noise: f64,
    /// Huber threshold in σ.
    pub huber_k: f64,
    /// Samples farther than this many σ (of the 3D residual) from the
    /// converged fit are outliers.
    pub reject_sigma: f64,
    /// Prior standard deviation of the spin along the flight direction at
    /// the first sample, rad/s (weak: the data wins wherever it can see).
    pub prior_along_velocity: f64,
    /// Prior standard deviation of each spin component, rad/s (very weak;
    /// keeps the problem well-posed).
    pub prior_spin: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Keep the spin at its initial value and fit position and velocity
    /// only (after a bounce, where the spin comes from the bounce model).
    pub fix_spin: bool,
}

impl Default for RefineConfig {
    fn default() -> Self {
        RefineConfig {
            noise: 0.002,
            huber_k: 2.5,
            reject_sigma: 6.0,
            prior_along_velocity: 15.0,
            prior_spin: 3000.0,
            max_iterations: 30,
            fix_spin: false,
        }
    }
}

/// The refined flight.
#[derive(Clone, Debug, PartialEq)]
pub struct Refined {
    /// Time of the first sample, where `state` holds.
    pub t0: f64,
    /// Position, velocity and spin at `t0`.
    pub state: BallState,
    /// 1σ of each spin component, rad/s (data and prior).
    pub spin_std: Vec3,
    /// The direction of ω the data determines worst (unit vector).
    pub weak_axis: Vec3,
    /// 1σ along `weak_axis` from the data alone, rad/s (infinite when the
    /// data says nothing about it).
    pub weak_axis_std: f64,
    /// RMS of the 3D residual over the inliers, m.
    pub rms: f64,
    /// Indices (into the given samples) rejected as outliers.
    pub outliers: Vec<usize>,
    /// Levenberg–Marquardt iterations run, over both passes.
    pub iterations: usize,
}

const STEPS: [f64; 9] = [1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-3, 1e-3, 1e-3];

fn to_state(theta: &V9) -> BallState {
    BallState::new(
        Vec3::new(theta[0], theta[1], theta[2]),
        Vec3::new(theta[3], theta[4], theta[5]),
        Vec3::new(theta[6], theta[7], theta[8]),
    )
}

/// Advances `s` from `from` to `to` by RK4 steps no longer than `prop.dt`.
fn fly_to(prop: &Propagator, s: &mut BallState, from: f64, to: f64) {
    let span = to - from;
    if span <= 0.0 {
        return;
    }
    let n = (span / prop.dt).ceil().max(1.0);
    let h = span / n;
    for _ in 0..n as usize {
        *s = prop.rk4(s, h);
    }
}

/// Calls `f(i, residual)` with each sample's residual p(tᵢ) − obsᵢ.
fn residuals(prop: &Propagator, samples: &[Sample], theta: &V9, mut f: impl FnMut(usize, Vec3)) {
    let mut s = to_state(theta);
    let mut t = samples[0].t;
    for (i, obs) in samples.iter().enumerate() {
        fly_to(prop, &mut s, t, obs.t);
        t = obs.t;
        f(i, s.pos - obs.pos);
    }
}

fn huber(r: f64, k: f64) -> f64 {
    if r <= k { 1.0 } else { k / r }
}

/// Refines `init` (the state at `samples[0].t`) against `samples`
/// (time-ordered, at least 4).
pub fn refine(samples: &[Sample], init: &BallState, prop: &Propagator, cfg: &RefineConfig) -> Refined {
    let n = samples.len();
    let sigma = cfg.noise.max(1e-5);
    let mut theta = V9::from_iterator(init.pos.iter().chain(init.vel.iter()).chain(init.spin.iter()).copied());
    let mut keep = vec![true; n];

    // The flight direction at the first sample, where the spin was imparted.
    let along = if init.vel.norm() > 1e-6 { init.vel.normalize() } else { Vec3::x() };
    let mut prior = M9::zeros();
    let p_along = along * along.transpose() / (cfg.prior_along_velocity * cfg.prior_along_velocity);
    let p_abs = nalgebra::Matrix3::identity() / (cfg.prior_spin * cfg.prior_spin);
    prior.fixed_view_mut::<3, 3>(6, 6).copy_from(&(p_along + p_abs));

    let weights = |theta: &V9, keep: &[bool], out: &mut Vec<f64>| {
        out.clear();
        out.resize(n, 0.0);
        residuals(prop, samples, theta, |i, r| {
            out[i] = if keep[i] { huber(r.norm() / sigma, cfg.huber_k) } else { 0.0 };
        });
    };
    let cost = |theta: &V9, w: &[f64]| {
        let mut c = 0.0;
        residuals(prop, samples, theta, |i, r| c += w[i] * r.norm_squared() / (sigma * sigma));
        c + (theta.fixed_rows::<3>(6).transpose() * prior.fixed_view::<3, 3>(6, 6) * theta.fixed_rows::<3>(6))[0]
    };

    let mut w = Vec::with_capacity(n);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut info = M9::zeros();
    for pass in 0..2 {
        weights(&theta, &keep, &mut w);
        let mut current = cost(&theta, &w);
        for _ in 0..cfg.max_iterations {
            iterations += 1;
            // Jacobian by forward differences, ten trajectories in lock step.
            let mut states: [BallState; 10] = core::array::from_fn(|j| {
                let mut th = theta;
                if j > 0 {
                    th[j - 1] += STEPS[j - 1];
                }
                to_state(&th)
            });
            let mut jtj = M9::zeros();
            let mut jtr = V9::zeros();
            let mut t = samples[0].t;
            for (i, obs) in samples.iter().enumerate() {
                for s in states.iter_mut() {
                    fly_to(prop, s, t, obs.t);
                }
                t = obs.t;
                if w[i] == 0.0 {
                    continue;
                }
                let r = states[0].pos - obs.pos;
                let mut jac = SMatrix::<f64, 3, 9>::zeros();
                for j in 0..9 {
                    jac.set_column(j, &((states[j + 1].pos - states[0].pos) / STEPS[j]));
                }
                let wi = w[i] / (sigma * sigma);
                jtj += jac.transpose() * jac * wi;
                jtr += jac.transpose() * r * wi;
            }
            info = jtj;
            let mut normal = jtj + prior;
            let mut grad = jtr + prior * theta;
            if cfg.fix_spin {
                for k in 6..9 {
                    normal.row_mut(k).fill(0.0);
                    normal.column_mut(k).fill(0.0);
                    normal[(k, k)] = 1.0;
                    grad[k] = 0.0;
                }
            }
            let mut improved = false;
            for _ in 0..10 {
                let mut damped = normal;
                for k in 0..9 {
                    damped[(k, k)] *= 1.0 + lambda;
                }
                let Some(chol) = damped.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let delta = -chol.solve(&grad);
                let trial = theta + delta;
                let c = cost(&trial, &w);
                if c.is_finite() && c < current {
                    let rel = (current - c) / current.max(1e-300);
                    theta = trial;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = rel > 1e-12;
                    break;
                }
                lambda *= 4.0;
            }
            // Re-weight (Huber) around the new estimate.
            weights(&theta, &keep, &mut w);
            current = cost(&theta, &w);
            if !improved {
                break;
            }
        }
        if pass == 0 {
            // Name the outliers of the converged fit and fit once more without them.
            let mut any = false;
            residuals(prop, samples, &theta, |i, r| {
                if r.norm() > cfg.reject_sigma * sigma {
                    keep[i] = false;
                    any = true;
                }
            });
            if !any || keep.iter().filter(|k| **k).count() < 6 {
                keep.iter_mut().for_each(|k| *k = true);
                break;
            }
        }
    }

    // Residual RMS over the inliers.
    let (mut sum, mut count) = (0.0, 0usize);
    residuals(prop, samples, &theta, |i, r| {
        if keep[i] {
            sum += r.norm_squared();
            count += 1;
        }
    });
    let rms = (sum / count.max(1) as f64).sqrt();
    // Scale the information by the noise actually seen (per-axis σ̂ ≈ rms/√3).
    let sigma_hat = (rms / 3f64.sqrt()).max(1e-6);
    let scale = (sigma * sigma) / (sigma_hat * sigma_hat);
    let cov = (info * scale + prior).try_inverse().unwrap_or_else(|| M9::from_diagonal_element(f64::INFINITY));
    let spin_std = Vec3::new(cov[(6, 6)].sqrt(), cov[(7, 7)].sqrt(), cov[(8, 8)].sqrt());
    // Data-only information about ω with position and velocity marginalised.
    let i_xx = info.fixed_view::<6, 6>(0, 0).into_owned();
    let i_xw = info.fixed_view::<6, 3>(0, 6).into_owned();
    let i_ww = info.fixed_view::<3, 3>(6, 6).into_owned();
    let (weak_axis, weak_axis_std) = match i_xx.try_inverse() {
        Some(inv) => {
            let schur = (i_ww - i_xw.transpose() * inv * i_xw) * scale;
            let eig = nalgebra::SymmetricEigen::new(schur);
            let k = eig.eigenvalues.imin();
            let lam = eig.eigenvalues[k];
            (eig.eigenvectors.column(k).into_owned(), if lam > 0.0 { lam.sqrt().recip() } else { f64::INFINITY })
        }
        None => (along, f64::INFINITY),
    };
    let outliers = keep.iter().enumerate().filter(|(_, k)| !**k).map(|(i, _)| i).collect();
    Refined { t0: samples[0].t, state: to_state(&theta), spin_std, weak_axis, weak_axis_std, rms, outliers, iterations }
}
