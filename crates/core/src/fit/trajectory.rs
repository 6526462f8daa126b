//! The fit of one recorded flight, end to end: validate the samples, drop
//! the start outliers (paper filter), split at an observed bounce, fit the
//! spin on the pre-bounce window (the paper's method, optionally refined
//! with the flight model), carry the state to the last observation (through
//! the bounce if the recording goes on past it), and predict the next
//! contact and the hitting point.

use super::Sample;
use super::magnus;
use super::outlier::StartFilter;
use super::poly::Cubic;
use super::predict::{Prediction, predict};
use super::refine::{RefineConfig, refine};
use crate::physics::{BallState, FlightScales, Propagator, Vec3};

/// The fewest samples a flight needs for a fit.
pub const MIN_SAMPLES: usize = 8;
/// The fewest samples after an observed bounce that are fitted on their own.
pub(crate) const MIN_POST_BOUNCE: usize = 6;

/// Which spin fit.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Method {
    /// The paper's: cubic per axis, linear least squares for ω; state from
    /// the cubic at the last sample.
    Paper,
    /// The paper's, then the flight model fitted to the positions.
    Refined,
}

/// Settings of a trajectory fit.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FitConfig {
    /// Which spin fit to run.
    pub method: Method,
    /// The paper's start-of-trajectory outlier filter.
    pub start_filter: StartFilter,
    /// Settings of the flight-model refinement (used by [`Method::Refined`]).
    pub refine: RefineConfig,
    /// The hitting plane x = const, m.
    pub hit_plane_x: f64,
}

impl FitConfig {
    /// Settings for `method` and the hitting plane x = `hit_plane_x` (m),
    /// with the default outlier filter and refinement.
    pub fn new(method: Method, hit_plane_x: f64) -> Self {
        FitConfig { method, start_filter: StartFilter::default(), refine: RefineConfig::default(), hit_plane_x }
    }

    /// The same settings with the calibration's prior on how far one
    /// flight's drag and lift may stray (`calib/physics.toml`).
    pub fn with_variation(mut self, variation: crate::physics::FlightVariation) -> Self {
        self.refine.variation = variation;
        self
    }

    /// The same settings for a tracker with per-axis noise `sigma` (m).
    pub fn with_noise(mut self, sigma: f64) -> Self {
        self.start_filter.noise = sigma;
        self.refine.noise = sigma;
        self
    }
}

/// Why a flight cannot be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer samples than a fit needs.
    #[error("{n} samples, at least {min} needed")]
    TooFewSamples {
        /// Samples available (all of them, or the inliers before an observed bounce).
        n: usize,
        /// Samples needed.
        min: usize,
    },
    /// A sample's time is not after the previous one.
    #[error("sample {row}: time does not increase")]
    NotMonotonic {
        /// 0-based index of the offending sample.
        row: usize,
    },
    /// A sample holds NaN or infinity.
    #[error("sample {row}: non-finite value")]
    NonFinite {
        /// 0-based index of the offending sample.
        row: usize,
    },
    /// The samples do not determine a trajectory.
    #[error("the samples do not determine a trajectory")]
    Degenerate,
}

/// The result of fitting one flight.
#[derive(Clone, Debug, PartialEq)]
pub struct TrajectoryFit {
    /// The spin fit that produced this result.
    pub method: Method,
    /// Spin before the (first observed or predicted) bounce, rad/s.
    pub spin: Vec3,
    /// 1σ per spin component, rad/s (refined fit only).
    pub spin_std: Option<Vec3>,
    /// The spin direction the trajectory determines worst and its 1σ,
    /// rad/s (refined fit only).
    pub weak_axis: Option<(Vec3, f64)>,
    /// This flight's drag and lift multipliers of the calibration, and
    /// their 1σ (refined fit only; the prediction flies with them).
    pub scales: Option<(FlightScales, FlightScales)>,
    /// Time of the last observation used, s.
    pub t_last: f64,
    /// Ball state at `t_last` (past an observed bounce: after it).
    pub state_last: BallState,
    /// Samples that entered the fit (all minus outliers).
    pub samples_used: usize,
    /// 0-based indices of the rejected samples.
    pub outliers: Vec<usize>,
    /// Index of the sample nearest an observed table contact, if any.
    pub observed_bounce: Option<usize>,
    /// RMS of the fit's residual, m.
    pub rms: f64,
    /// From the state at the last observation.
    pub prediction: Prediction,
}

fn validate(samples: &[Sample]) -> Result<(), FitError> {
    for (row, s) in samples.iter().enumerate() {
        if !(s.t.is_finite() && s.pos.iter().all(|c| c.is_finite())) {
            return Err(FitError::NonFinite { row });
        }
        if row > 0 && s.t <= samples[row - 1].t {
            return Err(FitError::NotMonotonic { row });
        }
    }
    if samples.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples { n: samples.len(), min: MIN_SAMPLES });
    }
    Ok(())
}

/// The index of the lowest sample of the first observed table contact: a
/// local minimum of z near the surface with the ball clearly falling into
/// it and rising out of it.
pub(crate) fn find_bounce(samples: &[Sample], radius: f64) -> Option<usize> {
    let z = |i: usize| samples[i].pos.z;
    (2..samples.len().saturating_sub(2)).find(|&i| {
        z(i) < radius + 0.04
            && (i - 2..=i + 2).all(|k| z(k) >= z(i))
            && z(i - 2) - z(i) > 0.004
            && z(i + 2) - z(i) > 0.004
    })
}

/// Fits one flight; `samples` in time order on any clock.
pub fn fit_trajectory(samples: &[Sample], prop: &Propagator, cfg: &FitConfig) -> Result<TrajectoryFit, FitError> {
    validate(samples)?;
    let mut rejected: Vec<usize> = cfg.start_filter.outliers(samples).iter().copied().collect();
    let inliers: Vec<usize> = (0..samples.len()).filter(|i| !rejected.contains(i)).collect();
    let clean: Vec<Sample> = inliers.iter().map(|&i| samples[i]).collect();
    let bounce_at = find_bounce(&clean, prop.flight.radius());
    let (pre, post) = match bounce_at {
        Some(b) => (&clean[..b], &clean[b + 1..]),
        None => (&clean[..], &clean[..0]),
    };
    if pre.len() < MIN_SAMPLES {
        return Err(FitError::TooFewSamples { n: pre.len(), min: MIN_SAMPLES });
    }

    // The paper's fit on the pre-bounce window.
    let cubic = Cubic::fit(pre.iter()).ok_or(FitError::Degenerate)?;
    let solve = magnus::solve(&cubic, pre.iter().map(|s| s.t), &prop.flight).ok_or(FitError::Degenerate)?;
    let spin_paper = prop.flight.spin_from_linear(&solve.spin_linear, solve.mean_speed).unwrap_or(solve.spin_linear);

    let mut fit_rejects: Vec<usize> = Vec::new();
    let (t_pre_end, state_pre_end, spin_std, weak_axis, scales, mut rms) = match cfg.method {
        Method::Paper => {
            let t = pre[pre.len() - 1].t;
            let s = BallState::new(cubic.pos(t), cubic.vel(t), spin_paper);
            (t, s, None, None, None, cubic_rms(&cubic, pre, &[]))
        }
        Method::Refined => {
            let init = BallState::new(cubic.pos(pre[0].t), cubic.vel(pre[0].t), spin_paper);
            let r = refine(pre, &init, FlightScales::ONE, prop, &cfg.refine);
            fit_rejects.extend(r.outliers.iter().copied());
            let t = pre[pre.len() - 1].t;
            let mut s = r.state;
            let mut t_now = r.t0;
            advance_flight(&prop.with_scales(r.scales), &mut s, &mut t_now, t);
            // Never worse than the data: where the model fits the window
            // clearly worse than the cubic does, the world is not the model,
            // and the state the prediction starts from leans on the cubic.
            let w = data_weight(r.rms, cubic_rms(&cubic, pre, &r.outliers));
            s.pos = s.pos * (1.0 - w) + cubic.pos(t) * w;
            s.vel = s.vel * (1.0 - w) + cubic.vel(t) * w;
            (t, s, Some(r.spin_std), Some((r.weak_axis, r.weak_axis_std)), Some((r.scales, r.scales_std)), r.rms)
        }
    };
    // The rest flies with this flight's drag and lift.
    let prop = &prop.with_scales(scales.map_or(FlightScales::ONE, |(s, _)| s));
    let spin = state_pre_end.spin;

    // Past an observed bounce: the spin after it from the bounce model, the
    // state from the post-bounce samples.
    let (t_last, state_last) = if post.len() >= MIN_POST_BOUNCE {
        let p = predict(prop, &state_pre_end, t_pre_end, f64::INFINITY);
        let spin_after = p.bounce.map(|c| c.after.spin).unwrap_or(spin);
        let post_cubic = Cubic::fit(post.iter()).ok_or(FitError::Degenerate)?;
        let t = post[post.len() - 1].t;
        match cfg.method {
            Method::Paper => (t, BallState::new(post_cubic.pos(t), post_cubic.vel(t), spin_after)),
            Method::Refined => {
                let init = BallState::new(post_cubic.pos(post[0].t), post_cubic.vel(post[0].t), spin_after);
                let r = refine(post, &init, FlightScales::ONE, prop, &RefineConfig { fix_spin: true, ..cfg.refine });
                let offset = pre.len() + 1;
                fit_rejects.extend(r.outliers.iter().map(|i| i + offset));
                rms = rms.max(r.rms);
                let mut s = r.state;
                let mut t_now = r.t0;
                advance_flight(prop, &mut s, &mut t_now, t);
                (t, s)
            }
        }
    } else {
        (t_pre_end, state_pre_end)
    };

    // Map rejects in `clean` back to rows of `samples`.
    rejected.extend(fit_rejects.iter().map(|&i| inliers[i]));
    rejected.sort_unstable();
    let used_post = if post.len() >= MIN_POST_BOUNCE { post.len() + 1 } else { 0 };
    let samples_used = pre.len() + used_post - fit_rejects.len();
    let prediction = predict(prop, &state_last, t_last, cfg.hit_plane_x);
    Ok(TrajectoryFit {
        method: cfg.method,
        spin,
        spin_std,
        weak_axis,
        scales,
        t_last,
        state_last,
        samples_used,
        outliers: rejected,
        observed_bounce: bounce_at.map(|b| inliers[b]),
        rms,
        prediction,
    })
}

/// RMS of the cubic's 3D residual over the samples not in `outliers`.
fn cubic_rms(cubic: &Cubic, samples: &[Sample], outliers: &[usize]) -> f64 {
    let squares: Vec<f64> = (0..samples.len())
        .filter(|i| !outliers.contains(i))
        .map(|i| (cubic.pos(samples[i].t) - samples[i].pos).norm_squared())
        .collect();
    (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt()
}

/// Where a model that fits the window is trusted less than the cubic: the
/// cubic's weight, from the ratio of the two residuals' mean squares. A
/// right model fits about as well as the cubic (one parameter fewer:
/// ratio ≈ 1, and above 1.5 only by chance at 3σ for a 50-sample window);
/// the weight then grows with the misfit and reaches 1 at ratio 2.5.
fn data_weight(model_rms: f64, cubic_rms: f64) -> f64 {
    const TRUSTED: f64 = 1.5;
    const SPAN: f64 = 1.0;
    if !(cubic_rms > 0.0 && model_rms.is_finite()) {
        return 0.0;
    }
    let ratio = (model_rms / cubic_rms).powi(2);
    ((ratio - TRUSTED) / SPAN).clamp(0.0, 1.0)
}

/// Pure flight from `*t` to `to` (no events: within an observed segment).
fn advance_flight(prop: &Propagator, s: &mut BallState, t: &mut f64, to: f64) {
    *s = prop.fly(s, to - *t);
    *t = to;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::Calibration;
    use crate::physics::Event;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A launcher-like flight observed at 150 Hz with noise, up to 5 mm
    /// before the hitting plane; returns the samples and the true pre-bounce spin.
    fn observed_flight(seed: u64, noise: f64, spin: Vec3) -> (Vec<Sample>, Propagator, f64) {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = Normal::new(0.0, noise).unwrap();
        let mut s = BallState::new(Vec3::new(-1.5, 0.1, 0.3), Vec3::new(7.0, -0.2, 0.9), spin);
        let mut t = 0.0;
        let mut out = Vec::new();
        let dt = 1.0 / 150.0;
        let stop = crate::physics::StopAt::time(0.0);
        loop {
            out.push(Sample::new(t, s.pos + Vec3::new(n.sample(&mut rng), n.sample(&mut rng), n.sample(&mut rng))));
            let target = t + dt;
            loop {
                match prop.advance(&mut s, &mut t, &crate::physics::StopAt { t_max: target, ..stop }) {
                    Event::TimeLimit { .. } => break,
                    Event::Bounce { .. } => continue,
                    _ => return (out, prop, cal.strike.hit_plane_x),
                }
            }
            // Stop 5 mm short of the plane, so that no noisy sample lies past it.
            if s.pos.x > cal.strike.hit_plane_x - 0.005 {
                return (out, prop, cal.strike.hit_plane_x);
            }
        }
    }

    #[test]
    fn refined_fit_recovers_spin_and_names_outliers() {
        // Spin imparted perpendicular to the exit velocity (7, -0.2, 0.9), as by a launcher.
        let spin = Vec3::new(137.0 / 7.0, 280.0, -90.0);
        let (mut samples, prop, x_hit) = observed_flight(7, 0.001, spin);
        let clean = fit_trajectory(&samples, &prop, &FitConfig::new(Method::Refined, x_hit).with_noise(0.001)).unwrap();
        assert!(clean.observed_bounce.is_some());
        let err = (clean.spin - spin).norm() / spin.norm();
        assert!(err < 0.03, "spin {:?}: {err}", clean.spin);
        let paper = fit_trajectory(&samples, &prop, &FitConfig::new(Method::Paper, x_hit).with_noise(0.001)).unwrap();
        let err_paper = (paper.spin - spin).norm() / spin.norm();
        assert!(err_paper > err, "paper {err_paper} refined {err}");

        samples[0].pos += Vec3::new(0.08, 0.05, -0.04);
        samples[1].pos += Vec3::new(0.06, -0.09, 0.02);
        let dirty = fit_trajectory(&samples, &prop, &FitConfig::new(Method::Refined, x_hit).with_noise(0.001)).unwrap();
        assert_eq!(dirty.outliers, vec![0, 1]);
        let err_dirty = (dirty.spin - spin).norm() / spin.norm();
        // Two samples fewer at the start, and the spin's size shares the data
        // with this flight's lift scale (fitted since issue 15).
        assert!(err_dirty < 0.05, "dirty {err_dirty} clean {err} spin {:?} vs {:?}", dirty.spin, clean.spin);
        let (scales, std) = clean.scales.unwrap();
        assert!((scales.drag - 1.0).abs() < 3.0 * std.drag && std.drag < 0.05, "drag {scales:?} ± {std:?}");
        assert!((scales.lift - 1.0).abs() < 3.0 * std.lift, "lift {scales:?} ± {std:?}");
        assert!(dirty.prediction.hit.is_some());
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let prop = Calibration::default_cell().propagator();
        let cfg = FitConfig::new(Method::Refined, 1.6);
        let s: Vec<Sample> =
            (0..10).map(|i| Sample::new(i as f64 * 0.01, Vec3::new(i as f64 * 0.05, 0.0, 0.3))).collect();
        assert_eq!(
            fit_trajectory(&s[..5], &prop, &cfg).unwrap_err(),
            FitError::TooFewSamples { n: 5, min: MIN_SAMPLES }
        );
        let mut bad = s.clone();
        bad[4].t = bad[3].t;
        assert_eq!(fit_trajectory(&bad, &prop, &cfg).unwrap_err(), FitError::NotMonotonic { row: 4 });
        bad = s.clone();
        bad[2].pos.y = f64::NAN;
        assert_eq!(fit_trajectory(&bad, &prop, &cfg).unwrap_err(), FitError::NonFinite { row: 2 });
    }
}
