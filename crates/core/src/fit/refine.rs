//! Our refinement of the paper's fit: the flight model itself is fitted to
//! the observed positions by Levenberg–Marquardt over the initial position,
//! velocity and spin and this flight's drag and lift multipliers (eleven
//! parameters), started from the paper's estimate. Unlike the cubic, the
//! model has no approximation bias, and every sample counts with its real
//! weight.
//!
//! - Ball and air: the multipliers of k_D and of the lift
//!   ([`FlightScales`]) are fitted in logarithm with Gaussian priors from
//!   the calibration ([`FlightVariation`]): a flight that decelerates
//!   faster than the calibration says is read as more drag, not bent into
//!   a wrong spin. Where the data cannot tell a multiplier (the lift scale
//!   and the spin's size trade off exactly under a linear lift), its prior
//!   holds.
//!
//! - Robust: Huber weights (k·σ), and samples beyond `reject_sigma` of the
//!   converged fit are named outliers and left out.
//! - Observability: only the spin perpendicular to the velocity shows in a
//!   trajectory. The data's information about ω (with position and velocity
//!   marginalised) is reported as a standard deviation per axis and the
//!   weakest direction; a weak prior keeps the spin along the flight
//!   direction at the first sample near zero where the data cannot say (a
//!   wheel or a racket imparts spin by tangential friction, perpendicular to
//!   the exit velocity), instead of inventing it. The prior is a Cauchy
//!   (heavy-tailed) one, applied by re-weighting: it yields where the data
//!   sees a large along-velocity component (sidespin about the vertical on
//!   a rising ball), which a Gaussian prior of the same width would erase.
//! - The Jacobian comes with one trajectory: the sensitivities of position
//!   and velocity to the eleven parameters are integrated with it through
//!   the sample times (RK4, step ≤ the propagator's; the flight's Jacobian
//!   to second order per step), so nothing is stored per sample. (Forward
//!   differences, twelve trajectories in lock step, cost 2.3× as much:
//!   `cargo bench --bench fit -- refine_60`, 2.81 against 1.21 ms.)

use nalgebra::{SMatrix, SVector};

use super::Sample;
use crate::physics::{BallState, FlightScales, FlightVariation, Propagator, Sensitivities, Vec3};

/// Parameters: position (3), velocity (3), spin (3), ln drag and ln lift multipliers.
const NP: usize = 11;
type MP = SMatrix<f64, NP, NP>;
type VP = SVector<f64, NP>;
/// Index of ln(drag multiplier) and ln(lift multiplier) in θ.
const DRAG: usize = 9;
const LIFT: usize = 10;

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
    /// Scale of the (Cauchy) prior on the spin along the flight direction
    /// at the first sample, rad/s: weak, and yielding where the data sees.
    pub prior_along_velocity: f64,
    /// Prior standard deviation of each spin component, rad/s: real balls
    /// reach 100–175 rps (DESIGN §3), so 800 rad/s (127 rps) is weak; it
    /// matters only where the lift saturates and the trajectory no longer
    /// tells the spin's size.
    pub prior_spin: f64,
    /// Prior spread of this flight's drag and lift multipliers (0: keep
    /// the given multiplier).
    pub variation: FlightVariation,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Keep the spin and the multipliers at their initial values and fit
    /// position and velocity only (after a bounce, where the spin comes
    /// from the bounce model).
    pub fix_spin: bool,
}

/// The weak isotropic prior on the spin, rad/s (σ about zero): real balls
/// reach 100–175 rps (DESIGN §3), so 800 rad/s (127 rps) is weak; it
/// matters only where the lift saturates and a flight no longer tells the
/// spin's size. Shared with the estimator's pre-bounce batches.
pub(crate) const SPIN_PRIOR_STD: f64 = 800.0;

impl Default for RefineConfig {
    fn default() -> Self {
        RefineConfig {
            noise: 0.002,
            huber_k: 2.5,
            reject_sigma: 6.0,
            prior_along_velocity: 15.0,
            prior_spin: SPIN_PRIOR_STD,
            variation: FlightVariation::default(),
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
    /// This flight's drag and lift multipliers.
    pub scales: FlightScales,
    /// 1σ of the drag and the lift multiplier (data and prior; 0 where held).
    pub scales_std: FlightScales,
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

fn to_state(theta: &VP) -> BallState {
    BallState::new(
        Vec3::new(theta[0], theta[1], theta[2]),
        Vec3::new(theta[3], theta[4], theta[5]),
        Vec3::new(theta[6], theta[7], theta[8]),
    )
}

fn to_scales(theta: &VP) -> FlightScales {
    FlightScales { drag: theta[DRAG].exp(), lift: theta[LIFT].exp() }
}

/// The propagator of `prop` with θ's drag and lift multipliers.
fn scaled(prop: &Propagator, theta: &VP) -> Propagator {
    prop.with_scales(to_scales(theta))
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
fn residuals(prop: &Propagator, samples: &[Sample], theta: &VP, mut f: impl FnMut(usize, Vec3)) {
    let prop = scaled(prop, theta);
    let mut s = to_state(theta);
    let mut t = samples[0].t;
    for (i, obs) in samples.iter().enumerate() {
        fly_to(&prop, &mut s, t, obs.t);
        t = obs.t;
        f(i, s.pos - obs.pos);
    }
}

/// The Gauss–Newton normal equations JᵀWJ and JᵀWr of the residuals at
/// θ (weights `w`, σ), J from one trajectory and its sensitivities to θ
/// ([`Sensitivities`]) integrated with it.
fn normal_equations(prop: &Propagator, samples: &[Sample], theta: &VP, w: &[f64], sigma: f64) -> (MP, VP) {
    let prop = scaled(prop, theta);
    let mut s = to_state(theta);
    let mut phi = Sensitivities::<NP>::new(Some(DRAG), Some(LIFT));
    let mut jtj = MP::zeros();
    let mut jtr = VP::zeros();
    let mut t = samples[0].t;
    for (i, obs) in samples.iter().enumerate() {
        phi.fly(&prop, &mut s, obs.t - t, prop.dt);
        t = obs.t;
        if w[i] == 0.0 {
            continue;
        }
        let r = s.pos - obs.pos;
        let wi = w[i] / (sigma * sigma);
        jtj += phi.pos.transpose() * phi.pos * wi;
        jtr += phi.pos.transpose() * r * wi;
    }
    (jtj, jtr)
}

/// θ less the priors' means: the spin's and the multipliers' priors are
/// about 0 (ln 1), position and velocity have none.
fn prior_offset(theta: &VP) -> VP {
    let mut centred = *theta;
    centred.fixed_rows_mut::<6>(0).fill(0.0);
    centred
}

/// Pins the held parameters of a normal or information matrix (their rows
/// and columns cleared, 1 on the diagonal) so it stays invertible.
fn hold(m: &mut MP, free: &[bool; NP]) {
    for k in (0..NP).filter(|&k| !free[k]) {
        m.row_mut(k).fill(0.0);
        m.column_mut(k).fill(0.0);
        m[(k, k)] = 1.0;
    }
}

/// The IRLS weight of a Cauchy prior at `z` widths from its centre.
fn cauchy(z: f64) -> f64 {
    1.0 / (1.0 + z * z)
}

fn huber(r: f64, k: f64) -> f64 {
    if r <= k { 1.0 } else { k / r }
}

/// The prior's information matrix at θ: the spin's Cauchy prior along
/// `along` (re-weighted at θ), its weak isotropic prior, and the
/// multipliers' Gaussian priors (about the calibration, ln 1 = 0).
fn prior_at(theta: &VP, along: &Vec3, cfg: &RefineConfig, free: &[bool; NP]) -> MP {
    let mut prior = MP::zeros();
    let s = cfg.prior_along_velocity;
    let a = along.dot(&Vec3::new(theta[6], theta[7], theta[8]));
    let p_along = along * along.transpose() * (cauchy(a / s) / (s * s));
    let p_abs = nalgebra::Matrix3::identity() / (cfg.prior_spin * cfg.prior_spin);
    prior.fixed_view_mut::<3, 3>(6, 6).copy_from(&(p_along + p_abs));
    // Drag: Gaussian (the data pins it down). Lift: Cauchy, so a world
    // whose lift lies far outside the calibrated curve (beyond its
    // saturation) is followed instead of answered with an absurd spin.
    for (k, sigma, heavy_tailed) in [(DRAG, cfg.variation.drag, false), (LIFT, cfg.variation.lift, true)] {
        if free[k] {
            let w = if heavy_tailed { cauchy(theta[k] / sigma) } else { 1.0 };
            prior[(k, k)] = w / (sigma * sigma);
        }
    }
    prior
}

/// Refines `init` (the state at `samples[0].t`, flying with the calibrated
/// model times `init_scales`) against `samples` (time-ordered, at least 4).
pub fn refine(
    samples: &[Sample],
    init: &BallState,
    init_scales: FlightScales,
    prop: &Propagator,
    cfg: &RefineConfig,
) -> Refined {
    let n = samples.len();
    let sigma = cfg.noise.max(1e-5);
    let mut theta = VP::from_iterator(
        init.pos
            .iter()
            .chain(init.vel.iter())
            .chain(init.spin.iter())
            .copied()
            .chain([init_scales.drag.ln(), init_scales.lift.ln()]),
    );
    let mut free = [true; NP];
    if cfg.fix_spin {
        free[6..].iter_mut().for_each(|f| *f = false);
    }
    free[DRAG] &= cfg.variation.drag > 0.0;
    free[LIFT] &= cfg.variation.lift > 0.0;
    let mut keep = vec![true; n];

    // The flight direction at the first sample, where the spin was imparted.
    let along = if init.vel.norm() > 1e-6 { init.vel.normalize() } else { Vec3::x() };

    let weights = |theta: &VP, keep: &[bool], out: &mut Vec<f64>| {
        out.clear();
        out.resize(n, 0.0);
        residuals(prop, samples, theta, |i, r| {
            out[i] = if keep[i] { huber(r.norm() / sigma, cfg.huber_k) } else { 0.0 };
        });
    };
    let cost = |theta: &VP, w: &[f64], prior: &MP| {
        let mut c = 0.0;
        residuals(prop, samples, theta, |i, r| c += w[i] * r.norm_squared() / (sigma * sigma));
        let centred = prior_offset(theta);
        c + (centred.transpose() * prior * centred)[0]
    };

    let mut w = Vec::with_capacity(n);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut info = MP::zeros();
    let mut prior = prior_at(&theta, &along, cfg, &free);
    for pass in 0..2 {
        weights(&theta, &keep, &mut w);
        let mut current = cost(&theta, &w, &prior);
        for _ in 0..cfg.max_iterations {
            iterations += 1;
            let (mut jtj, mut jtr) = normal_equations(prop, samples, &theta, &w, sigma);
            // Held parameters carry no information (their columns are zero).
            for k in (0..NP).filter(|&k| !free[k]) {
                jtj.row_mut(k).fill(0.0);
                jtj.column_mut(k).fill(0.0);
                jtr[k] = 0.0;
            }
            info = jtj;
            let mut normal = jtj + prior;
            let mut grad = jtr + prior * prior_offset(&theta);
            hold(&mut normal, &free);
            for k in (0..NP).filter(|&k| !free[k]) {
                grad[k] = 0.0;
            }
            let mut improved = false;
            for _ in 0..10 {
                let mut damped = normal;
                for k in 0..NP {
                    damped[(k, k)] *= 1.0 + lambda;
                }
                let Some(chol) = damped.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let delta = -chol.solve(&grad);
                let trial = theta + delta;
                let c = cost(&trial, &w, &prior);
                if c.is_finite() && c < current {
                    let rel = (current - c) / current.max(1e-300);
                    theta = trial;
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = rel > 1e-12;
                    break;
                }
                lambda *= 4.0;
            }
            // Re-weight (Huber on the residuals, Cauchy on the along-velocity
            // spin) around the new estimate.
            weights(&theta, &keep, &mut w);
            prior = prior_at(&theta, &along, cfg, &free);
            current = cost(&theta, &w, &prior);
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
    let mut posterior = info * scale + prior;
    hold(&mut posterior, &free);
    let cov = posterior.try_inverse().unwrap_or_else(|| MP::from_diagonal_element(f64::INFINITY));
    let std = |k: usize| if free[k] { cov[(k, k)].sqrt() } else { 0.0 };
    let spin_std = if cfg.fix_spin { Vec3::zeros() } else { Vec3::new(std(6), std(7), std(8)) };
    let scales = to_scales(&theta);
    let scales_std = FlightScales { drag: scales.drag * std(DRAG), lift: scales.lift * std(LIFT) };
    let (weak_axis, weak_axis_std) = weakest_spin_direction(&(info * scale), &free).unwrap_or((along, f64::INFINITY));
    let outliers = keep.iter().enumerate().filter(|(_, k)| !**k).map(|(i, _)| i).collect();
    Refined {
        t0: samples[0].t,
        state: to_state(&theta),
        scales,
        scales_std,
        spin_std,
        weak_axis,
        weak_axis_std,
        rms,
        outliers,
        iterations,
    }
}

/// The data's information about ω with every other free parameter
/// marginalised (Schur complement): its weakest direction and 1σ there.
fn weakest_spin_direction(info: &MP, free: &[bool; NP]) -> Option<(Vec3, f64)> {
    // Reorder: the eight other parameters, then the spin. Held ones count as known.
    let others: [usize; 8] = [0, 1, 2, 3, 4, 5, DRAG, LIFT];
    let mut i_xx = SMatrix::<f64, 8, 8>::zeros();
    let mut i_xw = SMatrix::<f64, 8, 3>::zeros();
    for (a, &p) in others.iter().enumerate() {
        for (b, &q) in others.iter().enumerate() {
            i_xx[(a, b)] = info[(p, q)];
        }
        if !free[p] {
            i_xx[(a, a)] = 1.0;
        }
        for c in 0..3 {
            i_xw[(a, c)] = if free[p] { info[(p, 6 + c)] } else { 0.0 };
        }
    }
    let i_ww = info.fixed_view::<3, 3>(6, 6).into_owned();
    let schur = i_ww - i_xw.transpose() * i_xx.try_inverse()? * i_xw;
    let eig = nalgebra::SymmetricEigen::new(schur);
    let k = eig.eigenvalues.imin();
    let lam = eig.eigenvalues[k];
    Some((eig.eigenvectors.column(k).into_owned(), if lam > 0.0 { lam.sqrt().recip() } else { f64::INFINITY }))
}
