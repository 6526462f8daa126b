//! topspin's simulated world: what stands in for the lab's hardware in
//! hardware-in-the-loop runs, the demo and the tests. Seeded, physically
//! simulated flights with ground truth, the observations a tracker would
//! report (and its faults), the mock KR C4, the ceiling camera's renderer,
//! and the loopback demo that judges every stroke on the truth.
//!
//! - [`launcher`]: the paper's nine launcher settings and aiming.
//! - [`strokes`]: the balls' source: the launcher, or real human strokes.
//! - [`truth`]: ground truth of a flight (bounce, net, hitting plane).
//! - [`tracker`]: sampling, noise, dropouts and false detections.
//! - [`udp_tracker`]: the simulated tracker on the network (TTB1, paced).
//! - [`faults`]: the tracker-side fault injector around the stream.
//! - [`strikes`]: a synthetic strike-plan stream for the RSI tests.
//! - [`mock_krc`]: the mock KR C4 (RSI client, controller model, faults).
//! - [`pair`]: the RSI session and the mock KR C4 on one virtual clock.
//! - [`render`]: labelled synthetic ceiling-camera crops.
//! - [`demo`]: tracker + daemon + mock KR C4 on loopback, judged.
//! - [`returns`]: the judge of returns: the bat's actual path meets the
//!   true ball, the rubber sends it back, the flight says where it lands.
//! - [`probe`]: a minimal Foxglove WebSocket client that counts.
//! - [`worlds`]: physics unlike the estimator's, for judging the fit.
//! - [`virtual_cell`]: the demo's whole cell (tracker, ingest, estimator, RSI
//!   session, mock KR C4) on a virtual clock, judged the same way.
//!
//! Everything is driven by `ChaCha8Rng` seeded from one `u64`; ball k draws
//! from its own streams (`ball_rngs`), so ball k is the same whatever the
//! number of balls or the tracker options. No clock, no I/O: the command
//! line writes files and paces the live stream.
//!
//! Where to start: [`simulate_ball`] (one seeded flight with its truth
//! and observations), [`virtual_cell::run_virtual`] (the whole cell on a
//! virtual clock, from a [`demo::DemoConfig`]), [`pair::Pair`] (an RSI
//! session against the mock KR C4, cycle by cycle) and
//! [`mock_krc::MockKrcConfig`] (the mock on a socket).
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

#![warn(missing_docs)]
#![deny(unreachable_pub)]

pub mod demo;
pub mod faults;
pub mod launcher;
pub mod mock_krc;
pub mod pair;
pub mod probe;
pub mod render;
mod return_feed;
pub mod returns;
pub mod strikes;
pub mod strokes;
pub mod tracker;
pub mod truth;
pub mod udp_tracker;
pub mod virtual_cell;
pub mod worlds;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use launcher::{Launch, NoValidShot, Power, Setting, SpinAxis, SpinType, launch, launch_with};
pub use strokes::{Redraws, Strokes};
pub use tracker::{SimObservation, TrackerModel, observe};
pub use truth::{Truth, true_state_at};

use topspin_core::calib::Calibration;
use topspin_core::physics::Propagator;

/// `n` simulated balls cycling through the nine settings; balls whose shot
/// cannot be aimed (never with the shipped calibration) are skipped.
pub fn simulate_set(cal: &Calibration, seed: u64, n: usize, tracker: &TrackerModel) -> Vec<SimBall> {
    simulate_in(None, Strokes::Launcher, cal, seed, n, tracker).0
}

/// `n` balls of `strokes` in `world` ([`worlds::World`]; `None`: the
/// calibration's own physics, every ball alike) on the cell of `cal`, and
/// the human states passed over because they never reached the robot's
/// half. Balls that cannot be had (a launcher shot that cannot be aimed,
/// 64 human draws out of play) are skipped.
pub fn simulate_in(
    world: Option<&worlds::World>,
    strokes: Strokes,
    cal: &Calibration,
    seed: u64,
    n: usize,
    tracker: &TrackerModel,
) -> (Vec<SimBall>, Redraws) {
    let mut redraws = Redraws::default();
    if strokes == Strokes::Launcher {
        let balls = match world {
            Some(world) => worlds::simulate_world(world, cal, seed, n, tracker),
            None => {
                let prop = cal.propagator();
                (0..n)
                    .filter_map(|k| {
                        simulate_ball(seed, k, Setting::ALL[k % 9], &prop, cal.strike.hit_plane_x, tracker).ok()
                    })
                    .collect()
            }
        };
        return (balls, redraws);
    }
    let balls = (0..n).filter_map(|k| simulate_stroke(world, strokes, cal, seed, k, tracker, &mut redraws)).collect();
    (balls, redraws)
}

/// Ball `k` of the run `seed` of `strokes` other than the launcher's
/// presets (the aimed launcher, human strokes) in `world` (else the
/// calibration's physics), seen by `tracker`; `None` where the aimed
/// launcher finds no launch. States that never reach the robot's half are
/// redrawn and counted in `redraws`.
pub fn simulate_stroke(
    world: Option<&worlds::World>,
    strokes: Strokes,
    cal: &Calibration,
    seed: u64,
    k: usize,
    tracker: &TrackerModel,
    redraws: &mut Redraws,
) -> Option<SimBall> {
    let physics = world.map_or_else(|| cal.propagator(), |w| worlds::ball_physics(w, cal, seed, k));
    let (mut rng_l, mut rng_t) = ball_rngs(seed, k);
    let l = if strokes == Strokes::AimedLauncher {
        let axis = world.map_or(SpinAxis::Perpendicular, |w| w.axis);
        strokes::launch_into_reach(Setting::ALL[k % 9], axis, &physics, &cal.strike, &mut rng_l).ok()?
    } else {
        strokes::draw_human(strokes, &physics, &mut rng_l, redraws)?
    };
    let truth = Truth::compute(&l, &physics, cal.strike.hit_plane_x);
    let observations = observe(&truth, &physics, tracker, 0.0, &mut rng_t);
    Some(SimBall { index: k, truth, observations, physics })
}

/// Shortest quiet time between one flight's end and the next launch, s.
pub(crate) const MIN_PAUSE: f64 = 0.1;

/// The launcher's and the tracker's random streams for ball `k` of a run
/// seeded with `seed` (ChaCha streams 2k and 2k + 1).
pub(crate) fn ball_rngs(seed: u64, k: usize) -> (ChaCha8Rng, ChaCha8Rng) {
    let mut launcher = ChaCha8Rng::seed_from_u64(seed);
    launcher.set_stream(2 * k as u64);
    let mut tracker = ChaCha8Rng::seed_from_u64(seed);
    tracker.set_stream(2 * k as u64 + 1);
    (launcher, tracker)
}

/// One simulated ball: its truth and what the tracker saw (times from its
/// own launch).
#[derive(Clone, Debug)]
pub struct SimBall {
    /// Index in the run.
    pub index: usize,
    /// The ball's ground truth: its flight, bounce and hitting-plane crossing.
    pub truth: Truth,
    /// What the tracker reported, in capture order (times in s from the ball's launch).
    pub observations: Vec<SimObservation>,
    /// The physics this ball flies: its world's, with its own drag and
    /// lift (what the judges fly it with).
    pub physics: Propagator,
}

impl SimBall {
    /// 0-based indices of the false detections among the observations.
    pub fn outlier_rows(&self) -> Vec<usize> {
        self.observations.iter().enumerate().filter_map(|(i, o)| o.outlier.then_some(i)).collect()
    }
}

/// Simulates ball `k` of the run `seed` with `setting`.
pub fn simulate_ball(
    seed: u64,
    k: usize,
    setting: Setting,
    prop: &Propagator,
    hit_plane_x: f64,
    tracker: &TrackerModel,
) -> Result<SimBall, NoValidShot> {
    let (mut rng_l, mut rng_t) = ball_rngs(seed, k);
    let l = launch(setting, prop, hit_plane_x, &mut rng_l)?;
    let truth = Truth::compute(&l, prop, hit_plane_x);
    let observations = observe(&truth, prop, tracker, 0.0, &mut rng_t);
    Ok(SimBall { index: k, truth, observations, physics: *prop })
}

/// Launch times of balls back to back: one every `gap` s, but never before
/// the previous flight's end plus `MIN_PAUSE`. `ends[k]` is ball k's
/// flight end, s after its own launch.
pub fn schedule(ends: &[f64], gap: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(ends.len());
    let mut next = 0.0f64;
    for end in ends {
        out.push(next);
        next = (next + gap).max(next + end + MIN_PAUSE);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::calib::Calibration;

    #[test]
    fn ball_k_does_not_depend_on_the_others() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let m = TrackerModel::default();
        let a = simulate_ball(7, 3, Setting::ALL[3], &prop, 1.6, &m).unwrap();
        let b = simulate_ball(7, 3, Setting::ALL[3], &prop, 1.6, &m).unwrap();
        assert_eq!(a.truth, b.truth);
        assert_eq!(a.observations, b.observations);
        let other = simulate_ball(7, 4, Setting::ALL[3], &prop, 1.6, &m).unwrap();
        assert_ne!(a.truth, other.truth);
        // Tracker options do not change the flight.
        let noisy = TrackerModel { false_starts: 2, dropout: 0.3, ..m };
        let c = simulate_ball(7, 3, Setting::ALL[3], &prop, 1.6, &noisy).unwrap();
        assert_eq!(a.truth, c.truth);
        assert_eq!(c.outlier_rows(), vec![0, 1]);
    }

    #[test]
    fn schedule_keeps_flights_apart() {
        assert_eq!(schedule(&[0.5, 0.5, 0.5], 1.5), vec![0.0, 1.5, 3.0]);
        let s = schedule(&[0.6, 0.6], 0.2);
        assert!((s[1] - 0.7).abs() < 1e-12);
    }
}
