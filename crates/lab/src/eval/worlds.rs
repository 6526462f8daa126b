//! The batch fit in worlds whose physics is not the estimator's
//! (`topspin_sim::worlds`, issue 15): per world, tracker noise and window,
//! the default (refined) fit against the paper's method on the same balls.

use serde::Serialize;

use topspin_core::calib::Calibration;
use topspin_sim::TrackerModel;
use topspin_sim::worlds::{simulate_world, worlds};

use super::fit::{MethodRow, accuracy};

/// One world's rows.
#[derive(Clone, Debug, Serialize)]
pub struct WorldReport {
    pub world: &'static str,
    pub about: &'static str,
    /// Balls simulated (some settings may not be aimable in a world).
    pub balls: usize,
    /// Per noise, window and method (`paper`, `refined`).
    pub rows: Vec<MethodRow>,
}

/// Every world at every noise level: `n` balls each, seeded with `seed`,
/// fitted with the calibration `cal`.
pub fn evaluate(cal: &Calibration, seed: u64, n: usize, noise_levels: &[f64]) -> Vec<WorldReport> {
    worlds(cal)
        .into_iter()
        .map(|world| {
            let mut rows = Vec::new();
            let mut balls = 0;
            for &noise in noise_levels {
                let tracker = TrackerModel { noise_sigma: noise, ..TrackerModel::default() };
                let set = simulate_world(&world, cal, seed, n, &tracker);
                balls = set.len();
                rows.extend(accuracy(cal, &set, noise));
            }
            WorldReport { world: world.name, about: world.about, balls, rows }
        })
        .collect()
}
