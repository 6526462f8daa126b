//! The estimator's hot path allocates nothing after warm-up: 180 balls
//! back to back, one observation at a time (with noise, dropouts, outliers,
//! silences, and returns the bat sent back as planned, whose spin is
//! read) through `Estimator::observe`, counted by a global allocator.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use topspin_core::calib::Calibration;
use topspin_core::estimator::{Estimator, EstimatorConfig, LearnConfig};
use topspin_core::physics::{BallState, Event, StopAt, Vec3};
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;

#[path = "alloc_counter/mod.rs"]
mod alloc_counter;

#[global_allocator]
static GLOBAL: alloc_counter::Counting = alloc_counter::Counting;

/// Plays `balls` launcher-like balls into `est`, 0.4 s apart from `*t0`,
/// seen at 150 Hz (noise, dropouts, outliers); half of them the bat
/// returns as the latest plan says (the racket model at its hitting time),
/// seen flying back. The plans made.
fn play(est: &mut Estimator, cal: &Calibration, rng: &mut ChaCha8Rng, t0: &mut f64, balls: usize) -> usize {
    let (prop, racket) = (cal.propagator(), cal.racket_model());
    let noise = Normal::new(0.0, 0.002).unwrap();
    let mut plans = 0;
    for _ in 0..balls {
        let mut s = BallState::new(
            Vec3::new(-1.5, rng.random_range(-0.3..0.3), 0.3),
            Vec3::new(rng.random_range(5.0..9.0), rng.random_range(-0.4..0.4), rng.random_range(0.3..1.2)),
            Vec3::new(0.0, rng.random_range(-400.0..400.0), rng.random_range(-200.0..200.0)),
        );
        let mut t = *t0;
        let (returned, mut back) = (rng.random_bool(0.5), false);
        let mut plan: Option<StrikePlan> = None;
        loop {
            let mut target = t + 1.0 / 150.0;
            if let Some(p) = plan.filter(|_| returned && !back)
                && target >= p.hit_time.as_secs_f64()
            {
                while let Event::Bounce { .. } = prop.advance(&mut s, &mut t, &StopAt::time(p.hit_time.as_secs_f64())) {
                }
                if let Some(hit) = racket.hit(&s, &p.orientation.face_normal(), &p.velocity) {
                    s = hit.after;
                    back = true;
                }
                target = t + 1.0 / 150.0;
            }
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
            if done || s.pos.x > 2.0 || (back && s.pos.x < 0.8) {
                break;
            }
            if rng.random_bool(0.05) {
                continue; // dropout
            }
            let mut p = s.pos + Vec3::new(noise.sample(rng), noise.sample(rng), noise.sample(rng));
            if rng.random_bool(0.02) {
                p.y += 0.3; // outlier
            }
            let out = est.observe(Instant::from_secs_f64(t), p);
            plans += out.plan.is_some() as usize;
            plan = out.plan.or(plan);
        }
        *t0 = t + 0.4;
    }
    plans
}

#[test]
fn ten_thousand_observations_allocate_nothing() {
    let cal = Calibration::default_cell();
    let learn = LearnConfig { returns: true, ..LearnConfig::default() };
    let mut est = Estimator::new(&cal, EstimatorConfig { learn, ..EstimatorConfig::default() });
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut t0 = 1.0;
    play(&mut est, &cal, &mut rng, &mut t0, 20);
    let (plans, allocations) = alloc_counter::count_on_this_thread(|| play(&mut est, &cal, &mut rng, &mut t0, 180));
    assert_eq!(allocations, 0, "allocations on the hot path");
    assert!(plans > 1_000, "only {plans} plans");
    assert!(est.session().returns_read > 20, "{} returns read", est.session().returns_read);
}
