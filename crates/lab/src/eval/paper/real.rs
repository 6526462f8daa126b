//! The real-data table: on the MPI launcher recordings, the bounce point
//! and the position 0.3 s (and 0.2 s) ahead, predicted from the samples
//! before the net, with the fitted spin and without, per launcher set.
//! Thin over [`crate::data`]: the same preparation, predictors and scoring
//! as `topspin eval real`, plus the paper's Kalman filter without spin.

use serde::Serialize;

use super::bounce::KalmanNoSpin;
use crate::data::eval::{CubicBaseline, Predictor, PreparedTrajectory, evaluate_predictions, predict_all};
use crate::data::spin::{FitPredictor, REAL_NOISE};
use crate::data::study::eval_config;
use topspin_core::physics::PhysicsParams;

/// The predictors, in column order: (label, estimates spin).
pub const PREDICTORS: [(&str, bool); 5] = [
    ("refined fit", true),
    ("paper fit", true),
    ("Kalman, no spin", false),
    ("refined, spin 0", false),
    ("cubic, spin 0", false),
];

/// The horizons, s: the 0.3 s and 0.2 s (14 of 15 topspin
/// recordings end before 0.3 s).
pub(crate) const HORIZONS: [f64; 2] = [0.3, 0.2];

/// Errors of one predictor on one set, mm.
#[derive(Clone, Debug, Serialize)]
pub struct RealCell {
    /// The predictor's label (from [`PREDICTORS`]).
    pub predictor: &'static str,
    /// True when the predictor estimates spin.
    pub with_spin: bool,
    /// Bounce xy: count, median, mean, std.
    pub bounce: [f64; 4],
    /// 3D error at each of `HORIZONS`: count, median, mean, std.
    pub ahead: [[f64; 4]; 2],
}

/// One set's row group.
#[derive(Clone, Debug, Serialize)]
pub struct RealSet {
    /// The set's name, or `all`.
    pub set: String,
    /// Trajectories in the set.
    pub trajectories: usize,
    /// One cell per predictor, in [`PREDICTORS`] order.
    pub cells: Vec<RealCell>,
}

/// The table.
#[derive(Clone, Debug, Serialize)]
pub struct RealTable {
    /// Trajectories evaluated.
    pub trajectories: usize,
    /// The name of the physics constants used.
    pub physics: String,
    /// One group per set, then `all`.
    pub sets: Vec<RealSet>,
}

fn stats(s: &crate::data::eval::Stats) -> [f64; 4] {
    [s.count as f64, s.median, s.mean, s.std]
}

/// Runs the table on `trajs` under the physics `p` (named `physics`).
pub fn table(trajs: &[PreparedTrajectory], p: &PhysicsParams, physics: &str) -> RealTable {
    let cfgs = HORIZONS.map(|h| eval_config(p, h));
    let kalman = KalmanNoSpin { propagator: cfgs[0].propagator, noise: REAL_NOISE };
    let preds: [Box<dyn Predictor + Sync>; 5] = [
        Box::new(FitPredictor::refined(p)),
        Box::new(FitPredictor::paper(p)),
        Box::new(kalman),
        Box::new(FitPredictor::no_spin(p)),
        Box::new(CubicBaseline),
    ];
    let reports: Vec<_> = preds
        .iter()
        .map(|pr| {
            let predictions = predict_all(trajs, pr.as_ref(), &cfgs[0]);
            cfgs.each_ref().map(|c| evaluate_predictions(trajs, &predictions, c))
        })
        .collect();
    let names: Vec<String> =
        reports[0][0].sets.iter().map(|g| g.name.clone()).chain(std::iter::once("all".to_owned())).collect();
    let sets = names
        .iter()
        .map(|name| {
            let group = |r: &crate::data::eval::Report| {
                r.sets.iter().chain(std::iter::once(&r.all)).find(|g| &g.name == name).cloned().expect("same sets")
            };
            let cells = reports
                .iter()
                .zip(PREDICTORS)
                .map(|(r, (label, with_spin))| {
                    let (g0, g1) = (group(&r[0]), group(&r[1]));
                    RealCell {
                        predictor: label,
                        with_spin,
                        bounce: stats(&g0.bounce),
                        ahead: [stats(&g0.ahead), stats(&g1.ahead)],
                    }
                })
                .collect();
            RealSet { set: name.clone(), trajectories: group(&reports[0][0]).trajectories, cells }
        })
        .collect();
    RealTable { trajectories: trajs.len(), physics: physics.to_owned(), sets }
}
