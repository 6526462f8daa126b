//! Benchmarks of `fit` (DESIGN §9 budgets): the paper's Magnus fit over 60
//! observations (< 5 µs), our flight-model refinement over the same, and
//! prediction through the bounce to the hitting plane (< 20 µs).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use topspin_core::calib::Calibration;
use topspin_core::fit::Cubic;
use topspin_core::fit::{RefineConfig, refine};
use topspin_core::fit::{Sample, predict, solve_magnus};
use topspin_core::physics::{BallState, FlightScales, Vec3};

/// 60 observations at 150 Hz of a topspin ball from the opponent's end,
/// with a deterministic 2 mm-scale wobble standing in for noise.
fn flight() -> (Vec<Sample>, Calibration) {
    let cal = Calibration::default_cell();
    let prop = cal.propagator();
    let mut s = BallState::new(Vec3::new(-1.6, 0.1, 0.35), Vec3::new(6.5, -0.2, 0.6), Vec3::new(0.0, 300.0, -40.0));
    let samples = (0..60)
        .map(|i| {
            let wobble = Vec3::new((i as f64 * 1.7).sin(), (i as f64 * 2.3).cos(), (i as f64 * 3.1).sin()) * 0.002;
            let out = Sample::new(i as f64 / 150.0, s.pos + wobble);
            s = prop.fly(&s, 1.0 / 150.0);
            out
        })
        .collect();
    (samples, cal)
}

fn benches(c: &mut Criterion) {
    let (samples, cal) = flight();
    let prop = cal.propagator();
    c.bench_function("fit/paper_magnus_60", |b| {
        b.iter(|| {
            let cubic = Cubic::fit(black_box(&samples).iter()).unwrap();
            solve_magnus(&cubic, samples.iter().map(|s| s.t), &prop.flight).unwrap()
        })
    });
    let cubic = Cubic::fit(samples.iter()).unwrap();
    let lin = solve_magnus(&cubic, samples.iter().map(|s| s.t), &prop.flight).unwrap();
    let init = BallState::new(cubic.pos(0.0), cubic.vel(0.0), lin.spin_linear);
    c.bench_function("fit/refine_60", |b| {
        b.iter(|| refine(black_box(&samples), &init, FlightScales::ONE, &prop, &RefineConfig::default()))
    });
    let last = samples[samples.len() - 1];
    let state = BallState::new(cubic.pos(last.t), cubic.vel(last.t), lin.spin_linear);
    c.bench_function("fit/predict_bounce_to_hit_plane", |b| {
        b.iter(|| predict(&prop, black_box(&state), last.t, cal.strike.hit_plane_x, false))
    });
}

criterion_group!(fit, benches);
criterion_main!(fit);
