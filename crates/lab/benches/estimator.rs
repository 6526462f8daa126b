//! Benchmark of `estimator`: the cost of one observation (EKF predict and
//! update, window refit, prediction through the bounce, stroke) on a
//! simulated stream of balls back to back. DESIGN §9 budget: p99 < 50 µs.
//! Criterion reports the mean per observation; a second pass times every
//! observation on its own and prints p50 / p99 / p99.9 / max (and, per
//! observation, the least of five runs: the work without the shared
//! machine's interruptions), with the
//! default stroke (`strike.aim = landing`: the return aimed through the
//! racket contact model) and with the paper's rule (`paper`) for the
//! aim's share, without the pre-bounce batch (`smooth`) for its, and on
//! the hitting plane alone for the hitting volume's.

use std::hint::black_box;
use topspin_daemon::clock;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use topspin_core::calib::Calibration;
use topspin_core::estimator::LearnConfig;
use topspin_core::estimator::{Estimator, EstimatorConfig, EstimatorEvent};
use topspin_core::physics::{Event, StopAt, Vec3};
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;
use topspin_lab::eval::stream::{StreamSetup, simulate_stream};
use topspin_sim::SimBall;
use topspin_sim::truth::Flight;

fn balls() -> (Vec<SimBall>, Vec<f64>) {
    simulate_stream(&Calibration::default_cell(), &StreamSetup { balls: 45, ..StreamSetup::default() })
}

fn observations((balls, launches): &(Vec<SimBall>, Vec<f64>)) -> Vec<(Instant, Vec3)> {
    balls
        .iter()
        .zip(launches)
        .flat_map(|(b, &t0)| b.observations.iter().map(move |o| (Instant::from_secs_f64(t0 + o.t), o.pos)))
        .collect()
}

/// The same stream with every ball returned as a first run's plans sent
/// it: its frames after the last plan's hit replaced by the return's (the
/// racket model at the plan's face and bat velocity, the ball's own
/// physics), 0.2 s of them at 150 Hz with 2 mm of noise. The estimator
/// reads each ball's spin from them (`learn.returns`).
fn with_returns(cal: &Calibration, (balls, launches): &(Vec<SimBall>, Vec<f64>)) -> Vec<(Instant, Vec3)> {
    let mut est = Estimator::new(cal, EstimatorConfig::default());
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let racket = cal.racket_model();
    let mut out = Vec::new();
    for (b, &t0) in balls.iter().zip(launches) {
        let mut plan = None;
        for o in &b.observations {
            plan = est.observe(Instant::from_secs_f64(t0 + o.t), o.pos).plan.or(plan);
        }
        let hit = plan.map_or(f64::INFINITY, |p: StrikePlan| p.hit_time.as_secs_f64() - t0);
        out.extend(b.observations.iter().filter(|o| o.t < hit).map(|o| (Instant::from_secs_f64(t0 + o.t), o.pos)));
        let Some(p) = plan else { continue };
        let ball = Flight::new(&b.truth.to_launch(), &b.physics).at(hit);
        let Some(impact) = racket.hit(&ball, &p.orientation.face_normal(), &p.velocity) else { continue };
        let (mut s, mut t) = (impact.after, hit);
        for k in 2..32 {
            let at = hit + k as f64 / 150.0;
            while let Event::Bounce { .. } = b.physics.advance(&mut s, &mut t, &StopAt::time(at)) {}
            let noise = Vec3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal)) * 0.002;
            out.push((Instant::from_secs_f64(t0 + t), s.pos + noise));
        }
    }
    out
}

/// The kind of step an observation was, for the split of the tail.
#[derive(Copy, Clone, PartialEq)]
enum Step {
    /// The observation that starts a track (start filter, cubic, EKF over
    /// the candidates, first prediction): once per ball.
    Start,
    /// A tracked observation that produced a plan (EKF, refit, prediction).
    Plan,
    /// The last frame of a return's watch: the spin read from it and kept
    /// (once per ball returned, `learn.returns`).
    Read,
    /// Anything else (candidate collected, withheld, after the hit).
    Other,
}

fn percentiles(obs: &[(Instant, Vec3)], cal: &Calibration, cfg: EstimatorConfig, label: &str) {
    let mut timed: Vec<(f64, Step)> = Vec::with_capacity(obs.len() * 5);
    // Per observation, the least of the five runs: the work it does,
    // without the machine's interruptions (runs are deterministic).
    let mut least = vec![f64::INFINITY; obs.len()];
    for _ in 0..5 {
        let mut est = Estimator::new(cal, cfg);
        for (k, &(t, p)) in obs.iter().enumerate() {
            let start = clock::now();
            let out = black_box(est.observe(t, p));
            let ns = (clock::now() - start).0 as f64;
            least[k] = least[k].min(ns);
            let step = if out.events.iter().any(|e| matches!(e, EstimatorEvent::Started { .. })) {
                Step::Start
            } else if out.plan.is_some() {
                Step::Plan
            } else if out.events.iter().any(|e| matches!(e, EstimatorEvent::Learned { .. }))
                && !out.events.iter().any(|e| matches!(e, EstimatorEvent::Ended { .. }))
            {
                Step::Read
            } else {
                Step::Other
            };
            timed.push((ns, step));
        }
    }
    let report = |name: &str, keep: &dyn Fn(Step) -> bool| {
        let mut ns: Vec<f64> = timed.iter().filter(|(_, s)| keep(*s)).map(|(n, _)| *n).collect();
        if ns.is_empty() {
            return;
        }
        ns.sort_by(f64::total_cmp);
        let q = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] / 1e3;
        println!(
            "estimator/observe {label} {name} ({} samples): p50 {:.1} µs  p99 {:.1} µs  p99.9 {:.1} µs  max {:.1} µs",
            ns.len(),
            q(0.5),
            q(0.99),
            q(0.999),
            ns[ns.len() - 1] / 1e3
        );
    };
    report("per observation", &|_| true);
    least.sort_by(f64::total_cmp);
    let q = |p: f64| least[((least.len() - 1) as f64 * p) as usize] / 1e3;
    println!(
        "estimator/observe {label}   least of 5 runs per observation: p50 {:.1} µs  p99 {:.1} µs  mean {:.2} µs",
        q(0.5),
        q(0.99),
        least.iter().sum::<f64>() / least.len() as f64 / 1e3
    );
    report("  starting a track", &|s| s == Step::Start);
    report("  tracked, with a plan", &|s| s == Step::Plan);
    report("  reading a return", &|s| s == Step::Read);
    report("  other", &|s| s == Step::Other);
}

fn benches(c: &mut Criterion) {
    let stream = balls();
    let obs = observations(&stream);
    let cal = Calibration::default_cell();
    let cfg = EstimatorConfig::default();
    percentiles(&obs, &cal, cfg, "[aim landing]");
    // The daemon's: each ball's spin read from its return, as the tracker
    // follows it back (the reading once per ball, when the watch ends).
    let learn = LearnConfig { returns: true, ..LearnConfig::default() };
    percentiles(&with_returns(&cal, &stream), &cal, EstimatorConfig { learn, ..cfg }, "[aim landing, returns read]");
    let mut paper = cal.clone();
    paper.strike.aim = topspin_core::calib::AimMode::Paper;
    percentiles(&obs, &paper, cfg, "[aim paper]");
    percentiles(&obs, &cal, EstimatorConfig { smooth: false, ..cfg }, "[aim landing, no batch]");
    // The spin prior's cost (its bounce search once per ball, its scale
    // every sample before the bounce), side by side in the same run.
    let mut no_spin = cfg;
    no_spin.learn.spin = false;
    percentiles(&obs, &cal, no_spin, "[aim landing, no spin learning]");
    // The hitting volume's cost: the same stream on the plane alone.
    let mut plane = cal.clone();
    plane.strike.hit_depth_x = None;
    percentiles(&obs, &plane, cfg, "[aim landing, plane alone]");
    // Start-up: one reach map per plane of the volume.
    for (label, cal) in [("volume", &cal), ("plane alone", &plane)] {
        let start = clock::now();
        black_box(Estimator::new(cal, cfg));
        println!("estimator/new {label}: {:.1} ms", (clock::now() - start).0 as f64 / 1e6);
    }
    c.bench_function("estimator/observe_stream_of_45_balls", |b| {
        b.iter(|| {
            let mut est = Estimator::new(&cal, EstimatorConfig::default());
            for &(t, p) in &obs {
                black_box(est.observe(t, p));
            }
        })
    });
    // The same stream without a ball's own drag (read every 8 samples
    // before its bounce): what that reading costs.
    let mut no_ball_drag = EstimatorConfig::default();
    no_ball_drag.learn.ball_drag_weight = 0.0;
    c.bench_function("estimator/observe_stream_of_45_balls_without_ball_drag", |b| {
        b.iter(|| {
            let mut est = Estimator::new(&cal, no_ball_drag);
            for &(t, p) in &obs {
                black_box(est.observe(t, p));
            }
        })
    });
    println!("({} observations per iteration)", obs.len());
}

criterion_group!(estimator, benches);
criterion_main!(estimator);
