//! Offline evaluations on simulated flights with ground truth: the accuracy
//! of the batch spin fit ([`fit`]) and of the streaming estimator
//! ([`stream`]). Seeded and reproducible; the command line prints their
//! tables (`topspin eval ...`).

pub mod fit;
pub mod paper;
pub mod stats;
pub mod stream;

use crate::calib::Calibration;
use crate::sim::{Setting, SimBall, TrackerModel, simulate_ball};

/// `n` simulated balls cycling through the nine settings; balls whose shot
/// cannot be aimed (never with the shipped calibration) are skipped.
pub fn simulate_set(cal: &Calibration, seed: u64, n: usize, tracker: &TrackerModel) -> Vec<SimBall> {
    let prop = cal.propagator();
    (0..n)
        .filter_map(|k| simulate_ball(seed, k, Setting::ALL[k % 9], &prop, cal.strike.hit_plane_x, tracker).ok())
        .collect()
}
