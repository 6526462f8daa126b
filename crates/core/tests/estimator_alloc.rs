//! The estimator's hot path allocates nothing after warm-up: 10 000
//! observations of balls back to back (with noise, dropouts, outliers and
//! silences) through `Estimator::observe`, counted by a global allocator.

use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use topspin_core::calib::Calibration;
use topspin_core::estimator::{Estimator, EstimatorConfig};
use topspin_core::physics::{BallState, Event, StopAt, Vec3};
use topspin_core::time::Instant;

#[path = "alloc_counter/mod.rs"]
mod alloc_counter;

#[global_allocator]
static GLOBAL: alloc_counter::Counting = alloc_counter::Counting;

/// Observations of `balls` launcher-like balls at 150 Hz, 0.4 s apart.
fn stream(balls: usize, seed: u64) -> Vec<(f64, Vec3)> {
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.002).unwrap();
    let mut out = Vec::new();
    let mut t0 = 1.0;
    for _ in 0..balls {
        let mut s = BallState::new(
            Vec3::new(-1.5, rng.random_range(-0.3..0.3), 0.3),
            Vec3::new(rng.random_range(5.0..9.0), rng.random_range(-0.4..0.4), rng.random_range(0.3..1.2)),
            Vec3::new(0.0, rng.random_range(-400.0..400.0), rng.random_range(-200.0..200.0)),
        );
        let mut t = t0;
        loop {
            let target = t + 1.0 / 150.0;
            let mut done = false;
            loop {
                match prop.advance(&mut s, &mut t, &StopAt::time(target)) {
                    Event::TimeLimit { .. } => break,
                    Event::Bounce { .. } => continue,
                    _ => {
                        done = true;
                        break;
                    }
                }
            }
            if done || s.pos.x > 2.0 {
                break;
            }
            if rng.random_bool(0.05) {
                continue; // dropout
            }
            let mut p = s.pos + Vec3::new(noise.sample(&mut rng), noise.sample(&mut rng), noise.sample(&mut rng));
            if rng.random_bool(0.02) {
                p.y += 0.3; // outlier
            }
            out.push((t, p));
        }
        t0 = t + 0.4;
    }
    out
}

#[test]
fn ten_thousand_observations_allocate_nothing() {
    let obs = stream(200, 3);
    assert!(obs.len() > 11_000, "{} observations", obs.len());
    let mut est = Estimator::new(&Calibration::default_cell(), EstimatorConfig::default());
    let (warm, hot) = obs.split_at(obs.len() - 10_000);
    let mut plans = 0usize;
    for &(t, p) in warm {
        plans += est.observe(Instant::from_secs_f64(t), p).plan.is_some() as usize;
    }
    let ((), allocations) = alloc_counter::count_on_this_thread(|| {
        for &(t, p) in hot {
            plans += est.observe(Instant::from_secs_f64(t), p).plan.is_some() as usize;
        }
    });
    assert_eq!(allocations, 0, "allocations on the hot path");
    assert!(plans > 1_000, "only {plans} plans");
}
