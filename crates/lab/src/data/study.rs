//! The real-data study, end to end: predictions from the pre-net
//! samples with the fitted spin and without it, under the paper's physics
//! and under calibrated physics; and the calibration itself (C_D, lift,
//! e, μ) with the refined spin fit on all four sets. `topspin eval real`
//! and `crates/lab/tests/real_data.rs` are thin shells over this module.

use serde_json::{Value, json};

use topspin_core::physics::{LiftModel, PhysicsParams, Propagator, Table, rad_to_rps};

use super::calibrate::{
    CalibParam, CalibrationResult, CalibrationSetup, Objective, calibrate, split_even_odd, with_physics,
};
use super::eval::{
    CubicBaseline, EvalConfig, Prediction, PreparedTrajectory, Report, evaluate_predictions, predict_all,
};
use super::mpi::{SETS, median};
use super::spin::{FitPredictor, SpinFit};

/// The horizons reported, s: the 0.3 s, and 0.2 s, which every
/// trajectory reaches (14 of 15 topspin files end before t_last + 0.3 s).
pub(crate) const HORIZONS: [f64; 2] = [0.3, 0.2];

/// The horizon of the calibration objective, s: 0.2 s, so that all four
/// sets (topspin included) enter it.
pub(crate) const CALIB_HORIZON: f64 = 0.2;

/// The objective the calibration minimises: per set, median bounce error +
/// median error 0.2 s ahead, averaged over the four sets.
pub(crate) const CALIB_OBJECTIVE: Objective = Objective::SetMedianSum;

/// Evaluation settings for `p`'s physics at `horizon`.
pub fn eval_config(p: &PhysicsParams, horizon: f64) -> EvalConfig {
    let mut cfg = EvalConfig::new(Propagator::new(p.flight_model(), p.bounce_model(), Table::default()));
    cfg.horizon = horizon;
    cfg
}

/// Which predictor a row of the comparison uses.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Which {
    /// A spin fit of [`FitPredictor`].
    Fit(SpinFit),
    /// The cubic baseline of `eval` (spin 0).
    Cubic,
}

impl Which {
    /// A short label for tables.
    pub fn label(self) -> &'static str {
        match self {
            Which::Fit(k) => k.label(),
            Which::Cubic => "cubic, spin 0",
        }
    }

    /// True when the predictor estimates spin.
    pub(crate) fn with_spin(self) -> bool {
        matches!(self, Which::Fit(SpinFit::Paper | SpinFit::Refined))
    }

    /// The predictions of this predictor under `p` for every trajectory.
    pub fn predict(self, trajs: &[PreparedTrajectory], p: &PhysicsParams) -> Vec<Option<Prediction>> {
        let cfg = eval_config(p, CALIB_HORIZON);
        match self {
            Which::Fit(k) => predict_all(trajs, &FitPredictor::new(k, p), &cfg),
            Which::Cubic => predict_all(trajs, &CubicBaseline, &cfg),
        }
    }
}

/// The predictors compared, spin fits first.
pub const PREDICTORS: [Which; 4] =
    [Which::Fit(SpinFit::Refined), Which::Fit(SpinFit::Paper), Which::Fit(SpinFit::NoSpin), Which::Cubic];

/// One named set of physics constants.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    /// How the tables call it (e.g. `paper`).
    pub name: String,
    /// The constants.
    pub params: PhysicsParams,
}

/// One predictor under one physics: a report per horizon in `HORIZONS`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The physics variant's name ([`Variant::name`]).
    pub physics: String,
    /// The predictor.
    pub predictor: Which,
    /// One report per horizon, 0.3 s then 0.2 s.
    pub reports: Vec<Report>,
    /// The fitted states (spin included), one per trajectory.
    pub predictions: Vec<Option<Prediction>>,
}

/// Runs every predictor in `which` under every variant.
pub fn compare(trajs: &[PreparedTrajectory], variants: &[Variant], which: &[Which]) -> Vec<Row> {
    let mut rows = Vec::new();
    for v in variants {
        for &w in which {
            let predictions = w.predict(trajs, &v.params);
            let reports = HORIZONS
                .iter()
                .map(|&h| evaluate_predictions(trajs, &predictions, &eval_config(&v.params, h)))
                .collect();
            rows.push(Row { physics: v.name.clone(), predictor: w, reports, predictions });
        }
    }
    rows
}

fn cell(median: f64, count: usize) -> String {
    if count == 0 { "–".to_owned() } else { format!("{median:.1} ({count})") }
}

/// The comparison as Markdown: one table per set (and all pooled), medians
/// in mm with the count in brackets.
pub fn markdown(rows: &[Row]) -> String {
    let mut out = String::new();
    let names: Vec<String> = rows
        .first()
        .map(|r| r.reports[0].sets.iter().map(|g| g.name.clone()).chain(["all".to_owned()]).collect())
        .unwrap_or_default();
    for name in &names {
        out += &format!("\n**{name}** (median error, mm; count in brackets)\n\n");
        out += "| physics | predictor | spin | bounce xy | 0.3 s ahead 3D | 0.2 s ahead 3D |\n";
        out += "|---|---|---|---|---|---|\n";
        for r in rows {
            let group = |rep: &Report| rep.sets.iter().chain([&rep.all]).find(|g| &g.name == name).cloned();
            let Some(g0) = group(&r.reports[0]) else { continue };
            let g1 = group(&r.reports[1]).expect("same trajectories at every horizon");
            out += &format!(
                "| {} | {} | {} | {} | {} | {} |\n",
                r.physics,
                r.predictor.label(),
                if r.predictor.with_spin() { "fitted" } else { "0" },
                cell(g0.bounce.median, g0.bounce.count),
                cell(g0.ahead.median, g0.ahead.count),
                cell(g1.ahead.median, g1.ahead.count),
            );
        }
    }
    out
}

/// Typical fitted spin of one set, rps.
#[derive(Clone, Debug, PartialEq)]
pub struct SpinSummary {
    /// The set's name.
    pub set: String,
    /// Trajectories with a prediction (the spins summarised).
    pub count: usize,
    /// Median ‖ω‖.
    pub norm: f64,
    /// Median ω_x, ω_y, ω_z.
    pub components: [f64; 3],
    /// Range of ω_y (min, max).
    pub y_range: (f64, f64),
}

/// The fitted spins per set from a row's predictions.
pub fn spin_summary(trajs: &[PreparedTrajectory], predictions: &[Option<Prediction>]) -> Vec<SpinSummary> {
    let mut names: Vec<&str> = SETS.to_vec();
    for t in trajs {
        if !names.contains(&t.set.as_str()) {
            names.push(&t.set);
        }
    }
    names
        .iter()
        .filter_map(|name| {
            let spins: Vec<_> = trajs
                .iter()
                .zip(predictions)
                .filter(|(t, _)| t.set == *name)
                .filter_map(|(_, p)| p.map(|p| p.state.spin.map(rad_to_rps)))
                .collect();
            if spins.is_empty() {
                return None;
            }
            let comp = |k: usize| median(&mut spins.iter().map(|w| w[k]).collect::<Vec<_>>());
            let ys = spins.iter().map(|w| w.y);
            Some(SpinSummary {
                set: (*name).to_owned(),
                count: spins.len(),
                norm: median(&mut spins.iter().map(|w| w.norm()).collect::<Vec<_>>()),
                components: [comp(0), comp(1), comp(2)],
                y_range: (ys.clone().fold(f64::INFINITY, f64::min), ys.fold(f64::NEG_INFINITY, f64::max)),
            })
        })
        .collect()
}

/// The spin summary as Markdown.
pub fn spin_markdown(summary: &[SpinSummary]) -> String {
    let mut out = String::from("| set | n | median ‖ω‖ rps | median ω_x / ω_y / ω_z rps | ω_y range rps |\n");
    out += "|---|---|---|---|---|\n";
    for s in summary {
        out += &format!(
            "| {} | {} | {:.1} | {:+.1} / {:+.1} / {:+.1} | {:+.1} … {:+.1} |\n",
            s.set, s.count, s.norm, s.components[0], s.components[1], s.components[2], s.y_range.0, s.y_range.1
        );
    }
    out
}

/// The lift model a calibration searches.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum LiftChoice {
    /// C_M constant (the paper's model): C_D, c_m, e, μ.
    Constant,
    /// C_M(S) = c_m / (1 + S/s_half): C_D, c_m, s_half, e, μ.
    Saturating,
}

/// The ranges the calibration may explore: the literature's for C_D
/// (≈ 0.35–0.55 for a table-tennis ball), e (0.85–0.97) and μ (0.1–0.4);
/// wide ones for the lift parameters, which have no such consensus.
pub(crate) const PLAUSIBLE: [(CalibParam, (f64, f64)); 5] = [
    (CalibParam::DragCoefficient, (0.35, 0.55)),
    (CalibParam::Restitution, (0.85, 0.97)),
    (CalibParam::Friction, (0.1, 0.4)),
    (CalibParam::LiftCm, (0.05, 3.0)),
    (CalibParam::LiftSHalf, (0.02, 10.0)),
];

/// The search of one lift model on the even-indexed files of every set with
/// the refined spin fit, validated on the odd ones. Starts from `base`
/// (C_D, e, μ) with the lift model's own start values.
pub(crate) fn calibration_setup(base: &PhysicsParams, lift: LiftChoice, max_evals: usize) -> CalibrationSetup {
    let mut start = base.clone();
    let mut params =
        vec![CalibParam::DragCoefficient, CalibParam::LiftCm, CalibParam::Restitution, CalibParam::Friction];
    match lift {
        LiftChoice::Constant => start.lift = LiftModel::Constant { c_m: base.lift.c_m0() },
        LiftChoice::Saturating => {
            // Sawicki et al.'s C_L = S / (1 + 2S), i.e. c_m 1, s_half 0.5.
            start.lift = LiftModel::Saturating { c_m: 1.0, s_half: 0.5 };
            params.insert(2, CalibParam::LiftSHalf);
        }
    }
    CalibrationSetup {
        base: start,
        params,
        objective: CALIB_OBJECTIVE,
        max_evals,
        tolerance: 0.02,
        ranges: PLAUSIBLE.to_vec(),
    }
}

/// Runs `calibration_setup` with the refined fit, then restarts the
/// search once from its result (a fresh simplex: the objective is a sum of
/// medians, piecewise smooth, and a first simplex can collapse early). The
/// "before" values are those of the first start.
pub fn calibrate_lift(
    trajs: &[PreparedTrajectory],
    base: &PhysicsParams,
    lift: LiftChoice,
    max_evals: usize,
) -> CalibrationResult {
    let (train, validation) = split_even_odd(trajs);
    let setup = calibration_setup(base, lift, max_evals);
    let cfg = eval_config(&setup.base, CALIB_HORIZON);
    let first = calibrate(&train, &validation, FitPredictor::refined, &cfg, &setup);
    let restart = CalibrationSetup { base: first.params.clone(), ..setup };
    let mut second = calibrate(&train, &validation, FitPredictor::refined, &cfg, &restart);
    if second.train_after > first.train_after {
        return first;
    }
    second.evaluations += first.evaluations;
    second.train_before = first.train_before;
    second.validation_before = first.validation_before;
    second
}

/// The calibration objective of `p` with the refined fit on `trajs`.
pub fn objective(trajs: &[PreparedTrajectory], p: &PhysicsParams) -> f64 {
    let cfg = with_physics(&eval_config(p, CALIB_HORIZON), p);
    let rep = evaluate_predictions(trajs, &predict_all(trajs, &FitPredictor::refined(p), &cfg), &cfg);
    CALIB_OBJECTIVE.value(&rep, cfg.min_samples)
}

/// A calibration result as Markdown lines.
pub fn calibration_markdown(name: &str, r: &CalibrationResult) -> String {
    let values: Vec<String> = r.values.iter().map(|(k, v)| format!("{} = {v:.4}", k.name())).collect();
    format!(
        "- {name}: {} ({} evaluations); objective train {:.1} → {:.1} mm, validation {:.1} → {:.1} mm\n",
        values.join(", "),
        r.evaluations,
        r.train_before,
        r.train_after,
        r.validation_before,
        r.validation_after
    )
}

/// A physics variant as JSON.
pub fn params_json(p: &PhysicsParams) -> Value {
    serde_json::to_value(p).unwrap_or(Value::Null)
}

/// The comparison as JSON: per row, per horizon, per set (and all) the
/// bounce and horizon statistics.
pub fn rows_json(rows: &[Row]) -> Value {
    let stats = |s: &super::eval::Stats| json!({"count": s.count, "median": s.median, "mean": s.mean, "std": s.std});
    Value::Array(
        rows.iter()
            .map(|r| {
                json!({
                    "physics": r.physics,
                    "predictor": r.predictor.label(),
                    "spin": r.predictor.with_spin(),
                    "horizons": r.reports.iter().map(|rep| json!({
                        "horizon_s": rep.horizon,
                        "groups": rep.sets.iter().chain([&rep.all]).map(|g| json!({
                            "set": g.name,
                            "trajectories": g.trajectories,
                            "bounce_mm": stats(&g.bounce),
                            "ahead_mm": stats(&g.ahead),
                        })).collect::<Vec<_>>(),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect(),
    )
}
