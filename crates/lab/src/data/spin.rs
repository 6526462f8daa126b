//! [`Predictor`]s backed by the spin fit of [`topspin_core::fit`], each built from
//! a set of [`PhysicsParams`] so that the calibration can vary them:
//!
//! - [`FitPredictor::paper`]: the paper's method (cubic per axis, linear
//!   Magnus solve; state from the cubic at the last sample);
//! - [`FitPredictor::refined`]: the flight model fitted to the positions
//!   (Levenberg–Marquardt over position, velocity and spin);
//! - [`FitPredictor::no_spin`]: the same flight-model fit with the spin held
//!   at zero. A fairer "without spin" reference than the cubic baseline: the
//!   only difference to [`FitPredictor::refined`] is the spin.
//!
//! All three drop the paper's start outliers first and use the same noise
//! level ([`REAL_NOISE`]).

use topspin_core::fit::Cubic;
use topspin_core::fit::StartFilter;
use topspin_core::fit::{FitConfig, Method, Sample, fit_trajectory};
use topspin_core::fit::{RefineConfig, refine};
use topspin_core::physics::{BallState, FlightScales, FlightVariation, PhysicsParams, Propagator, Table, Vec3};

use super::eval::{Prediction, Predictor};

/// Per-axis tracker noise assumed for the MPI set, m: the measured RMS is
/// 0.5–2.7 mm per axis (docs/real-data.md), x the noisiest.
pub(crate) const REAL_NOISE: f64 = 0.002;

/// The hitting plane handed to the fit (it only affects the fit's own
/// prediction, which the evaluation does not use), m.
const HIT_PLANE_X: f64 = 1.6;

/// Which fit a [`FitPredictor`] runs.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum SpinFit {
    /// The paper's cubic + linear Magnus solve.
    Paper,
    /// The flight model fitted with spin.
    Refined,
    /// The flight model fitted with spin held at zero.
    NoSpin,
}

impl SpinFit {
    /// A short label for tables.
    pub fn label(self) -> &'static str {
        match self {
            SpinFit::Paper => "paper fit",
            SpinFit::Refined => "refined fit",
            SpinFit::NoSpin => "refined, spin 0",
        }
    }
}

/// A [`Predictor`] running [`topspin_core::fit`] with a given physics.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FitPredictor {
    /// Which fit it runs.
    pub kind: SpinFit,
    /// The physics the fit assumes (k_D, k_M, and the bounce model for a
    /// window that contains a bounce, which pre-net windows never do).
    pub propagator: Propagator,
    /// Per-axis noise σ, m (outlier thresholds and weights).
    pub noise: f64,
    /// The prior on one flight's drag and lift (`calib/physics.toml`).
    pub variation: FlightVariation,
}

impl FitPredictor {
    /// The fit `kind` under `p`'s flight and bounce models, the default table,
    /// `p`'s flight variation and 2 mm of noise per axis.
    pub fn new(kind: SpinFit, p: &PhysicsParams) -> Self {
        let propagator = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        FitPredictor { kind, propagator, noise: REAL_NOISE, variation: p.variation }
    }

    /// The paper's method.
    pub fn paper(p: &PhysicsParams) -> Self {
        Self::new(SpinFit::Paper, p)
    }

    /// The refined method.
    pub fn refined(p: &PhysicsParams) -> Self {
        Self::new(SpinFit::Refined, p)
    }

    /// The refined method with the spin held at zero.
    pub fn no_spin(p: &PhysicsParams) -> Self {
        Self::new(SpinFit::NoSpin, p)
    }

    /// The same predictor for another noise level σ (m).
    pub fn with_noise(mut self, sigma: f64) -> Self {
        self.noise = sigma;
        self
    }

    fn fit_zero_spin(&self, samples: &[Sample]) -> Option<Prediction> {
        let filter = StartFilter { noise: self.noise, ..StartFilter::default() };
        let rejected = filter.outliers(samples);
        let clean: Vec<Sample> =
            samples.iter().enumerate().filter(|(i, _)| !rejected.contains(i)).map(|(_, s)| *s).collect();
        if clean.len() < topspin_core::fit::MIN_SAMPLES {
            return None;
        }
        let cubic = Cubic::fit(clean.iter())?;
        let t0 = clean[0].t;
        let init = BallState::new(cubic.pos(t0), cubic.vel(t0), Vec3::zeros());
        let cfg = RefineConfig { noise: self.noise, fix_spin: true, ..RefineConfig::default() };
        let r = refine(&clean, &init, FlightScales::ONE, &self.propagator, &cfg);
        let t_last = clean[clean.len() - 1].t;
        let state = self.propagator.fly(&r.state, t_last - r.t0);
        Some(Prediction::calibrated(t_last, state))
    }
}

impl Predictor for FitPredictor {
    fn predict(&self, samples: &[(f64, Vec3)]) -> Option<Prediction> {
        let samples: Vec<Sample> = samples.iter().map(|&(t, p)| Sample::new(t, p)).collect();
        let method = match self.kind {
            SpinFit::Paper => Method::Paper,
            SpinFit::Refined => Method::Refined,
            SpinFit::NoSpin => return self.fit_zero_spin(&samples),
        };
        let cfg = FitConfig::new(method, HIT_PLANE_X).with_noise(self.noise).with_variation(self.variation);
        let fit = fit_trajectory(&samples, &self.propagator, &cfg).ok()?;
        let scales = fit.scales.map_or(FlightScales::ONE, |(s, _)| s);
        Some(Prediction { t: fit.t_last, state: fit.state_last, scales })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::eval::predicted_position;

    /// A spinning ball sampled at 180 Hz from `p`'s own physics, noise-free.
    fn flight(p: &PhysicsParams, spin: Vec3) -> Vec<(f64, Vec3)> {
        let prop = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        let s0 = BallState::new(Vec3::new(-1.35, 0.0, 0.35), Vec3::new(5.5, 0.0, 1.2), spin);
        let start = Prediction::calibrated(0.0, s0);
        (0..45)
            .map(|k| {
                let t = k as f64 / 180.0;
                (t, predicted_position(&prop, &start, t).unwrap())
            })
            .collect()
    }

    #[test]
    fn refined_recovers_spin_and_no_spin_does_not() {
        let p = PhysicsParams::paper();
        let spin = Vec3::new(0.0, -250.0, 0.0);
        let samples = flight(&p, spin);
        let r = FitPredictor::refined(&p).with_noise(0.0005).predict(&samples).unwrap();
        assert!((r.state.spin - spin).norm() < 0.1 * spin.norm(), "{:?}", r.state.spin);
        let n = FitPredictor::no_spin(&p).with_noise(0.0005).predict(&samples).unwrap();
        assert_eq!(n.state.spin, Vec3::zeros());
        assert_eq!(n.t, r.t);
        // The spin fit ends on the last sample; the spin-free one cannot
        // follow the Magnus curve and ends farther off.
        let last = samples[samples.len() - 1].1;
        assert!((r.state.pos - last).norm() < 1e-3);
        assert!((n.state.pos - last).norm() > (r.state.pos - last).norm());
        let paper = FitPredictor::paper(&p).with_noise(0.0005).predict(&samples).unwrap();
        assert!(paper.state.spin.y < -100.0, "{:?}", paper.state.spin);
    }
}
