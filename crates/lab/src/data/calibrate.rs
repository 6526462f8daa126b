//! Calibration of the physics constants on real trajectories: a small,
//! deterministic Nelder–Mead search over chosen [`PhysicsParams`] fields
//! that minimises the evaluation's error on a training subset, reported
//! also on a held-out validation subset.
//!
//! The predictor is built from the parameters by a factory, so a spin
//! fitter whose fit depends on k_D and k_M is re-run for every candidate.
//! With the spin-free baseline only C_D, e and μ are identifiable (the lift
//! parameters multiply a zero spin); the lift parameters need the spin fit.

use topspin_core::physics::{LiftModel, PhysicsParams, Propagator};

use super::eval::{EvalConfig, Predictor, PreparedTrajectory, Report, TrajectoryResult, evaluate};
use super::mpi::median;

/// A physics constant the search may move.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum CalibParam {
    /// C_D.
    DragCoefficient,
    /// Table restitution e.
    Restitution,
    /// Table friction μ.
    Friction,
    /// C_M (constant lift) or c_m of the saturating model.
    LiftCm,
    /// s_half of [`LiftModel::Saturating`] (ignored for a constant lift).
    LiftSHalf,
}

impl CalibParam {
    /// The parameter's name in reports (its [`PhysicsParams`] field path, e.g.
    /// `lift.c_m`).
    pub fn name(self) -> &'static str {
        match self {
            CalibParam::DragCoefficient => "drag_coefficient",
            CalibParam::Restitution => "restitution",
            CalibParam::Friction => "friction",
            CalibParam::LiftCm => "lift.c_m",
            CalibParam::LiftSHalf => "lift.s_half",
        }
    }

    /// The admissible range; the search is penalised outside it.
    pub fn range(self) -> (f64, f64) {
        match self {
            CalibParam::DragCoefficient => (0.05, 1.5),
            CalibParam::Restitution => (0.3, 1.0),
            CalibParam::Friction => (0.0, 1.5),
            CalibParam::LiftCm => (0.0, 3.0),
            CalibParam::LiftSHalf => (0.01, 10.0),
        }
    }

    /// The initial simplex step.
    fn step(self) -> f64 {
        match self {
            CalibParam::DragCoefficient => 0.1,
            CalibParam::Restitution => 0.05,
            CalibParam::Friction => 0.1,
            CalibParam::LiftCm => 0.2,
            CalibParam::LiftSHalf => 0.2,
        }
    }

    /// The parameter's value in `p`; NaN for `s_half` when the lift model has
    /// none.
    pub fn get(self, p: &PhysicsParams) -> f64 {
        match (self, p.lift) {
            (CalibParam::DragCoefficient, _) => p.drag_coefficient,
            (CalibParam::Restitution, _) => p.restitution,
            (CalibParam::Friction, _) => p.friction,
            (CalibParam::LiftCm, l) => l.c_m0(),
            (CalibParam::LiftSHalf, LiftModel::Saturating { s_half, .. } | LiftModel::Crisis { s_half, .. }) => s_half,
            (CalibParam::LiftSHalf, LiftModel::Constant { .. } | LiftModel::Measured { .. }) => f64::NAN,
        }
    }

    /// Sets the parameter in `p` to `v`; does nothing where the lift model
    /// lacks it (`s_half` of a constant lift, any lift parameter of a measured
    /// curve).
    pub fn set(self, p: &mut PhysicsParams, v: f64) {
        match self {
            CalibParam::DragCoefficient => p.drag_coefficient = v,
            CalibParam::Restitution => p.restitution = v,
            CalibParam::Friction => p.friction = v,
            CalibParam::LiftCm => match &mut p.lift {
                LiftModel::Constant { c_m } | LiftModel::Saturating { c_m, .. } | LiftModel::Crisis { c_m, .. } => {
                    *c_m = v
                }
                // A measured curve is not searched: the calibration never sets one up.
                LiftModel::Measured { .. } => {}
            },
            CalibParam::LiftSHalf => {
                if let LiftModel::Saturating { s_half, .. } | LiftModel::Crisis { s_half, .. } = &mut p.lift {
                    *s_half = v;
                }
            }
        }
    }
}

/// What the search minimises (all in mm, pooled over the subset). A
/// trajectory whose target exists but whose prediction has none counts
/// `MISSING_PENALTY_MM`, so the search cannot win by losing balls.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Objective {
    /// Median bounce error.
    MedianBounce,
    /// Median error at the horizon.
    MedianAhead,
    /// Median bounce error + median error at the horizon.
    MedianSum,
    /// Mean bounce error + mean error at the horizon.
    MeanSum,
    /// Per set: median bounce error + median error at the horizon; then the
    /// mean over the sets. Every kind of shot weighs the same, however many
    /// trajectories it has (the pooled medians would follow the 48
    /// robot_no_spin shots and ignore the spin sets).
    SetMedianSum,
}

/// The error charged for a missing prediction, mm.
pub(crate) const MISSING_PENALTY_MM: f64 = 1000.0;

impl Objective {
    /// The objective's value for a report.
    pub fn value(self, rep: &Report, min_samples: usize) -> f64 {
        if self == Objective::SetMedianSum {
            let mut names: Vec<&str> = Vec::new();
            for r in &rep.results {
                if !names.contains(&r.set.as_str()) {
                    names.push(&r.set);
                }
            }
            let per_set: Vec<f64> = names
                .iter()
                .map(|name| {
                    let (bounce, ahead) = errors(rep.results.iter().filter(|r| r.set == *name), min_samples);
                    med(bounce) + med(ahead)
                })
                .collect();
            return mean(&per_set);
        }
        let (bounce, ahead) = errors(rep.results.iter(), min_samples);
        match self {
            Objective::MedianBounce => med(bounce),
            Objective::MedianAhead => med(ahead),
            Objective::MedianSum | Objective::SetMedianSum => med(bounce) + med(ahead),
            Objective::MeanSum => mean(&bounce) + mean(&ahead),
        }
    }
}

/// Bounce and horizon errors of the results, missing predictions charged
/// [`MISSING_PENALTY_MM`].
fn errors<'a>(results: impl Iterator<Item = &'a TrajectoryResult>, min_samples: usize) -> (Vec<f64>, Vec<f64>) {
    let mut bounce = Vec::new();
    let mut ahead = Vec::new();
    for r in results.filter(|r| r.samples_used >= min_samples) {
        if r.real_bounce.is_some() {
            bounce.push(r.bounce_error_mm.unwrap_or(MISSING_PENALTY_MM));
        }
        if r.real_ahead.is_some() || r.prediction.is_none() {
            ahead.push(r.ahead_error_mm.unwrap_or(MISSING_PENALTY_MM));
        }
    }
    (bounce, ahead)
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { 0.0 } else { v.iter().sum::<f64>() / v.len() as f64 }
}

fn med(mut v: Vec<f64>) -> f64 {
    if v.is_empty() { 0.0 } else { median(&mut v) }
}

/// What to calibrate and how long to search.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationSetup {
    /// The starting point; fields not in `params` stay as they are.
    pub base: PhysicsParams,
    /// The parameters searched, in the order of [`CalibrationResult::values`].
    pub params: Vec<CalibParam>,
    /// What the search minimises.
    pub objective: Objective,
    /// Upper bound on objective evaluations.
    pub max_evals: usize,
    /// Stop when the simplex's objective values differ by less, mm.
    pub tolerance: f64,
    /// Narrower admissible ranges than [`CalibParam::range`] for some
    /// parameters (e.g. the literature's range of C_D).
    pub ranges: Vec<(CalibParam, (f64, f64))>,
}

impl CalibrationSetup {
    /// The admissible range of `k` in this search.
    pub fn range(&self, k: CalibParam) -> (f64, f64) {
        self.ranges.iter().find(|(p, _)| *p == k).map_or_else(|| k.range(), |(_, r)| *r)
    }
}

impl CalibrationSetup {
    /// C_D, e and μ from `base`, median sum, 150 evaluations.
    pub fn drag_and_bounce(base: PhysicsParams) -> Self {
        CalibrationSetup {
            base,
            params: vec![CalibParam::DragCoefficient, CalibParam::Restitution, CalibParam::Friction],
            objective: Objective::MedianSum,
            max_evals: 150,
            tolerance: 0.05,
            ranges: Vec::new(),
        }
    }
}

/// The outcome of a search.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationResult {
    /// The best parameters found.
    pub params: PhysicsParams,
    /// (parameter, value) for each searched parameter.
    pub values: Vec<(CalibParam, f64)>,
    /// Objective evaluations the search used.
    pub evaluations: usize,
    /// Objective on the training subset at the starting point, mm.
    pub train_before: f64,
    /// Objective on the training subset at the best parameters, mm.
    pub train_after: f64,
    /// Objective on the validation subset at the starting point, mm.
    pub validation_before: f64,
    /// Objective on the validation subset at the best parameters, mm.
    pub validation_after: f64,
    /// The full report on the training subset with the calibrated parameters.
    pub train: Report,
    /// The full report on the validation subset with the calibrated parameters.
    pub validation: Report,
}

/// Splits prepared trajectories by file index: even → training, odd →
/// validation (each set is split, so both halves hold every kind of shot).
pub fn split_even_odd(trajs: &[PreparedTrajectory]) -> (Vec<PreparedTrajectory>, Vec<PreparedTrajectory>) {
    trajs.iter().cloned().partition(|t| t.index % 2 == 0)
}

/// The propagator `cfg` uses, rebuilt with `p`'s physics.
pub(crate) fn with_physics(cfg: &EvalConfig, p: &PhysicsParams) -> EvalConfig {
    let mut out = *cfg;
    let dt = cfg.propagator.dt;
    out.propagator = Propagator::new(p.flight_model(), p.bounce_model(), cfg.propagator.table);
    out.propagator.dt = dt;
    out
}

/// Evaluates the predictor built for `p` on `trajs`.
pub fn evaluate_with<F, P>(trajs: &[PreparedTrajectory], factory: &F, cfg: &EvalConfig, p: &PhysicsParams) -> Report
where
    F: Fn(&PhysicsParams) -> P,
    P: Predictor + Sync,
{
    evaluate(trajs, &factory(p), &with_physics(cfg, p))
}

/// Minimises `setup.objective` on `train` over `setup.params` by
/// Nelder–Mead (deterministic start simplex: the base point and one step
/// along each parameter), then reports both subsets.
pub fn calibrate<F, P>(
    train: &[PreparedTrajectory],
    validation: &[PreparedTrajectory],
    factory: F,
    cfg: &EvalConfig,
    setup: &CalibrationSetup,
) -> CalibrationResult
where
    F: Fn(&PhysicsParams) -> P,
    P: Predictor + Sync,
{
    let params = &setup.params;
    let make = |x: &[f64]| {
        let mut p = setup.base.clone();
        for (k, v) in params.iter().zip(x) {
            k.set(&mut p, *v);
        }
        p
    };
    let objective = |x: &[f64]| -> f64 {
        let mut penalty = 0.0;
        for (k, v) in params.iter().zip(x) {
            let (lo, hi) = setup.range(*k);
            if !(v.is_finite() && *v >= lo && *v <= hi) {
                penalty += 1e6 * (1.0 + (lo - v).max(v - hi).max(0.0));
            }
        }
        if penalty > 0.0 {
            return penalty;
        }
        let p = make(x);
        if p.validate().is_err() {
            return 1e6;
        }
        let rep = evaluate_with(train, &factory, cfg, &p);
        setup.objective.value(&rep, cfg.min_samples)
    };
    let x0: Vec<f64> = params.iter().map(|k| k.get(&setup.base)).collect();
    let steps: Vec<f64> = params.iter().map(|k| k.step()).collect();
    let (best, evaluations) = nelder_mead(&objective, &x0, &steps, setup.max_evals, setup.tolerance);
    let p_best = make(&best);
    let train_rep = evaluate_with(train, &factory, cfg, &p_best);
    let val_rep = evaluate_with(validation, &factory, cfg, &p_best);
    let val_before = evaluate_with(validation, &factory, cfg, &setup.base);
    let train_before = evaluate_with(train, &factory, cfg, &setup.base);
    CalibrationResult {
        values: params.iter().copied().zip(best.iter().copied()).collect(),
        params: p_best,
        evaluations,
        train_before: setup.objective.value(&train_before, cfg.min_samples),
        train_after: setup.objective.value(&train_rep, cfg.min_samples),
        validation_before: setup.objective.value(&val_before, cfg.min_samples),
        validation_after: setup.objective.value(&val_rep, cfg.min_samples),
        train: train_rep,
        validation: val_rep,
    }
}

/// Nelder–Mead (reflection 1, expansion 2, contraction ½, shrink ½) from
/// `x0` with the initial simplex x0 + steps_i e_i. Returns the best point
/// and the number of evaluations. Deterministic.
pub(crate) fn nelder_mead(
    f: &dyn Fn(&[f64]) -> f64,
    x0: &[f64],
    steps: &[f64],
    max_evals: usize,
    tolerance: f64,
) -> (Vec<f64>, usize) {
    let n = x0.len();
    if n == 0 {
        return (Vec::new(), 0);
    }
    let evals = std::cell::Cell::new(0usize);
    let eval = |x: &[f64]| {
        evals.set(evals.get() + 1);
        let v = f(x);
        if v.is_nan() { f64::INFINITY } else { v }
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    simplex.push((x0.to_vec(), eval(x0)));
    for i in 0..n {
        let mut x = x0.to_vec();
        x[i] += steps[i];
        let v = eval(&x);
        simplex.push((x, v));
    }
    let lerp = |a: &[f64], b: &[f64], t: f64| -> Vec<f64> { a.iter().zip(b).map(|(a, b)| a + t * (b - a)).collect() };
    while evals.get() < max_evals {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, worst) = (simplex[0].1, simplex[n].1);
        if (worst - best).abs() < tolerance {
            break;
        }
        let mut centroid = vec![0.0; n];
        for (x, _) in &simplex[..n] {
            for (c, xi) in centroid.iter_mut().zip(x) {
                *c += xi / n as f64;
            }
        }
        let xw = simplex[n].0.clone();
        // Reflection: centroid + (centroid − worst).
        let xr = lerp(&centroid, &xw, -1.0);
        let fr = eval(&xr);
        if fr < simplex[0].1 {
            let xe = lerp(&centroid, &xw, -2.0);
            let fe = eval(&xe);
            simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[n - 1].1 {
            simplex[n] = (xr, fr);
        } else {
            // Contraction, outside or inside.
            let (xc, fc) = if fr < worst {
                let xc = lerp(&centroid, &xw, -0.5);
                let fc = eval(&xc);
                (xc, fc)
            } else {
                let xc = lerp(&centroid, &xw, 0.5);
                let fc = eval(&xc);
                (xc, fc)
            };
            if fc < worst.min(fr) {
                simplex[n] = (xc, fc);
            } else {
                let x_best = simplex[0].0.clone();
                for item in simplex.iter_mut().skip(1) {
                    let x = lerp(&x_best, &item.0, 0.5);
                    let v = eval(&x);
                    *item = (x, v);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    (simplex.swap_remove(0).0, evals.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nelder_mead_finds_a_quadratic_minimum() {
        let f = |x: &[f64]| (x[0] - 1.0).powi(2) + 4.0 * (x[1] + 0.5).powi(2) + 3.0;
        let (x, n) = nelder_mead(&f, &[0.0, 0.0], &[0.5, 0.5], 500, 1e-12);
        assert!((x[0] - 1.0).abs() < 1e-4 && (x[1] + 0.5).abs() < 1e-4, "{x:?}");
        assert!(n <= 500);
    }

    #[test]
    fn params_round_trip_through_physics() {
        let mut p = PhysicsParams::paper();
        p.lift = LiftModel::Saturating { c_m: 0.6, s_half: 0.4 };
        for (k, v) in [
            (CalibParam::DragCoefficient, 0.5),
            (CalibParam::Restitution, 0.85),
            (CalibParam::Friction, 0.3),
            (CalibParam::LiftCm, 0.9),
            (CalibParam::LiftSHalf, 0.7),
        ] {
            k.set(&mut p, v);
            assert_eq!(k.get(&p), v, "{}", k.name());
        }
    }
}
