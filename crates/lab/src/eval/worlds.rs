//! The batch fit in worlds whose physics is not the estimator's
//! (`topspin_sim::worlds`): per world, tracker noise and window,
//! the default (refined) fit against the paper's method on the same balls.

use serde::Serialize;

use topspin_core::calib::Calibration;
use topspin_sim::TrackerModel;
use topspin_sim::worlds::{simulate_world, worlds};

use super::fit::{MethodRow, accuracy};

/// One world's rows.
#[derive(Clone, Debug, Serialize)]
pub struct WorldReport {
    /// The world's short name.
    pub world: &'static str,
    /// What is unlike the estimator's model, in a few words.
    pub about: &'static str,
    /// Balls simulated (some settings may not be aimable in a world).
    pub balls: usize,
    /// Per noise, window and method (`paper`, `refined`).
    pub rows: Vec<MethodRow>,
}

/// Every world at every noise level: `n` balls each, seeded with `seed`,
/// fitted with the calibration `cal` (`known_table`: with each world's own
/// restitution and friction in place of the calibration's, as a session
/// that has learned the table would fit).
pub fn evaluate(cal: &Calibration, seed: u64, n: usize, noise_levels: &[f64], known_table: bool) -> Vec<WorldReport> {
    worlds(cal)
        .into_iter()
        .map(|world| {
            let mut fit_cal = cal.clone();
            if known_table {
                fit_cal.physics.restitution = world.physics.restitution;
                fit_cal.physics.friction = world.physics.friction;
            }
            let mut rows = Vec::new();
            let mut balls = 0;
            for &noise in noise_levels {
                let tracker = TrackerModel { noise_sigma: noise, ..TrackerModel::default() };
                let set = simulate_world(&world, cal, seed, n, &tracker);
                balls = set.len();
                rows.extend(accuracy(&fit_cal, &set, noise));
            }
            WorldReport { world: world.name, about: world.about, balls, rows }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::fit::Window;

    /// Across the bounce the hit time rests on the table: in a world with
    /// other e and μ, the fit that knows the table times the hit far
    /// better than the one with the calibration's.
    #[test]
    fn the_hit_time_across_the_bounce_rests_on_the_table() {
        let cal = Calibration::default_cell();
        let hit_dt = |known: bool| -> f64 {
            let reports = evaluate(&cal, 3, 18, &[0.001], known);
            let w = reports.iter().find(|w| w.world == "other-table").expect("other-table");
            let row = w.rows.iter().find(|r| r.method == "refined" && r.window == Window::PreBounce).expect("row");
            row.hit_dt_ms.median
        };
        let (calibrated, known) = (hit_dt(false), hit_dt(true));
        assert!(known < 0.3 * calibrated, "known table {known:.2} ms, the calibration's {calibrated:.2} ms");
    }
}
