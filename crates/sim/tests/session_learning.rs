//! The streaming estimator learns the world across a session, on the
//! virtual clock: simulated balls of a world unlike the
//! calibration, back to back and observed through the bounce, fed to the
//! estimator one observation at a time. Exact where the claim is exact
//! (learning off changes nothing, a reset starts from the calibration, a
//! bad ball's bound), within stated tolerances where it is statistical.

use topspin_core::calib::Calibration;
use topspin_core::estimator::LearnConfig;
use topspin_core::estimator::{EndReason, Estimator, EstimatorConfig, EstimatorEvent, LogoSpin};
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;
use topspin_sim::worlds::{World, simulate_world_ball, world_named};
use topspin_sim::{SimBall, SpinAxis, TrackerModel, schedule};

const NOISE: f64 = 0.002;

fn tracker() -> TrackerModel {
    TrackerModel { noise_sigma: NOISE, ..TrackerModel::default() }
}

/// `n` balls of `world` (seed 1) and their launch times, one second apart.
fn session(world: &World, cal: &Calibration, n: usize) -> (Vec<SimBall>, Vec<f64>) {
    let balls: Vec<SimBall> = (0..n).filter_map(|k| simulate_world_ball(world, cal, 1, k, &tracker())).collect();
    let ends: Vec<f64> = balls.iter().map(|b| b.observations.last().map_or(0.0, |o| o.t)).collect();
    let launches = schedule(&ends, 1.0).into_iter().map(|t| t + 1.0).collect();
    (balls, launches)
}

fn config(learn: LearnConfig) -> EstimatorConfig {
    EstimatorConfig { learn, ..EstimatorConfig::default().with_noise(NOISE) }
}

/// Feeds `balls` (launched at `launches`) to `est`; each ball's plans.
fn feed(est: &mut Estimator, balls: &[SimBall], launches: &[f64]) -> Vec<Vec<StrikePlan>> {
    balls
        .iter()
        .zip(launches)
        .map(|(b, &t0)| {
            b.observations.iter().filter_map(|o| est.observe(Instant::from_secs_f64(t0 + o.t), o.pos).plan).collect()
        })
        .collect()
}

/// What a plan says about the ball (not its sequence number or track id).
fn what(p: &StrikePlan) -> (Instant, Instant, [f64; 3], [f64; 3]) {
    (p.made_at, p.hit_time, p.position.into(), p.spin.into())
}

#[test]
fn the_table_and_the_air_converge_to_the_worlds() {
    let cal = Calibration::default_cell();
    for (name, tol_e, tol_mu, tol_drag) in [("other-table", 0.015, 0.03, 0.025), ("heavy-air", 0.015, 0.03, 0.03)] {
        let world = world_named(&cal, name).unwrap();
        let (balls, launches) = session(&world, &cal, 60);
        let mut est = Estimator::new(&cal, config(LearnConfig::default()));
        feed(&mut est, &balls, &launches);
        let s = est.session();
        // The world's drag: its C_D over the calibration's, times its balls' mean.
        let drag = world.physics.drag_coefficient / cal.physics.drag_coefficient
            * 0.5
            * (world.ball_drag.0 + world.ball_drag.1);
        assert!(s.restitution.count >= 40, "{name}: {} bounces of {}", s.restitution.count, balls.len());
        assert!((s.restitution.value - world.physics.restitution).abs() < tol_e, "{name}: {s:?}");
        assert!((s.friction.value - world.physics.friction).abs() < tol_mu, "{name}: {s:?}");
        // Read from the batches (the whole model): within 2–3 %; the cubic
        // read 3–5 % low.
        assert!((s.drag.value - drag).abs() < tol_drag, "{name}: {s:?} (drag {drag})");
        // And it started from the calibration's table, which is further off.
        assert!(
            (cal.physics.restitution - world.physics.restitution).abs() > tol_e
                || (cal.physics.friction - world.physics.friction).abs() > tol_mu,
            "{name}"
        );
    }
}

#[test]
fn a_bad_ball_moves_what_was_learned_at_most_one_clipped_step() {
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "other-table").unwrap();
    let (mut balls, mut launches) = session(&world, &cal, 30);
    let cfg = LearnConfig::default();
    let mut est = Estimator::new(&cal, config(cfg));
    feed(&mut est, &balls, &launches);
    let before = *est.session();
    assert!(before.restitution.count >= cfg.memory, "{before:?}");
    // One ball from a dead table in thick air (e 0.6, μ 0.6, drag ×1.8).
    let bad_world = World {
        physics: topspin_core::physics::PhysicsParams {
            restitution: 0.6,
            friction: 0.6,
            drag_coefficient: 1.8 * cal.physics.drag_coefficient,
            ..world.physics.clone()
        },
        ball_drag: (1.0, 1.0),
        ..world.clone()
    };
    let bad = (0..9).find_map(|k| simulate_world_ball(&bad_world, &cal, 7, k, &tracker())).unwrap();
    let t0 = launches.last().unwrap() + 3.0;
    balls.clear();
    launches.clear();
    balls.push(bad);
    launches.push(t0);
    feed(&mut est, &balls, &launches);
    // Silence ends its track (and takes its bounce).
    let mut out = Default::default();
    est.poll(Instant::from_secs_f64(t0 + 5.0), &mut out);
    let after = *est.session();
    assert!(after.restitution.count > before.restitution.count, "the bad ball's bounce was taken: {after:?}");
    // A running mean over `memory` balls with clipped steps: e by ≤ 0.08,
    // μ by ≤ 0.1, drag by ≤ 0.3, each weighted 1/(memory + 1).
    let w = 1.0 / f64::from(cfg.memory + 1);
    assert!((after.restitution.value - before.restitution.value).abs() <= 0.08 * w + 1e-12, "{before:?} {after:?}");
    assert!((after.friction.value - before.friction.value).abs() <= 0.1 * w + 1e-12, "{before:?} {after:?}");
    assert!((after.drag.value - before.drag.value).abs() <= 0.3 * w + 1e-12, "{before:?} {after:?}");
    for k in 0..3 {
        let (a, b) = (after.bounce_vel[k].value, before.bounce_vel[k].value);
        assert!((a - b).abs() <= 0.1 * w + 1e-12, "axis {k}: {b} → {a}");
    }
    // It did pull the way the bad ball went.
    assert!(after.restitution.value < before.restitution.value, "{before:?} {after:?}");
}

/// What the table model leaves unexplained after a bounce is learned per
/// axis: sideways where the spin along the flight (skewed axes) kicks the
/// ball sideways at the bounce, which no trajectory before it shows; little
/// where a launcher's axes leave the model nothing to miss.
#[test]
fn the_bounce_noise_is_learned_where_the_model_misses() {
    let cal = Calibration::default_cell();
    let learned = |axis: SpinAxis| {
        let world = World { axis, ball_lift: (1.0, 1.0), ..world_named(&cal, "other-table").unwrap() };
        let (balls, launches) = session(&world, &cal, 60);
        let mut est = Estimator::new(&cal, config(LearnConfig::default()));
        feed(&mut est, &balls, &launches);
        est.session().bounce_noise()
    };
    let start = EstimatorConfig::default().noise.bounce_vel;
    let (skewed, launcher) = (learned(SpinAxis::Skewed { max_deg: 20.0 }), learned(SpinAxis::Perpendicular));
    // Sideways: (0.2 m/s)² and more where the axes are skewed, a quarter
    // of that or less from a launcher; both moved off the start.
    assert!(skewed.y > 0.03 && launcher.y < 0.25 * skewed.y, "skewed {skewed:?}, launcher {launcher:?}");
    assert!(launcher.y < start.y && launcher.z < start.z, "launcher {launcher:?} from {start:?}");
}

/// Each bounce the session learns from is announced with what it holds
/// after it (the daemon logs these); learning off announces nothing.
#[test]
fn what_the_session_learns_is_announced() {
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "other-table").unwrap();
    let (balls, launches) = session(&world, &cal, 12);
    let announced = |learn: LearnConfig| {
        let mut est = Estimator::new(&cal, config(learn));
        let mut learned = Vec::new();
        for (b, &t0) in balls.iter().zip(&launches) {
            for o in &b.observations {
                let out = est.observe(Instant::from_secs_f64(t0 + o.t), o.pos);
                learned.extend(out.events.iter().filter(|e| matches!(e, EstimatorEvent::Learned { .. })).copied());
            }
        }
        // Silence ends the last track (and takes its bounce).
        let mut out = Default::default();
        est.poll(Instant::from_secs_f64(launches.last().unwrap() + 5.0), &mut out);
        learned.extend(out.events.iter().filter(|e| matches!(e, EstimatorEvent::Learned { .. })).copied());
        (learned, *est.session())
    };
    let (learned, s) = announced(LearnConfig::default());
    assert_eq!(learned.len() as u32, s.bounce_vel[0].count, "one per bounce taken");
    assert!(learned.len() >= 8, "{} of {} balls", learned.len(), balls.len());
    let Some(EstimatorEvent::Learned { drag, restitution, friction, bounce_sigma, .. }) = learned.last().copied()
    else {
        unreachable!()
    };
    assert_eq!(
        (drag, restitution, friction, bounce_sigma),
        (
            s.drag.value as f32,
            s.restitution.value as f32,
            s.friction.value as f32,
            s.bounce_noise().map(|v| v.sqrt() as f32).into()
        )
    );
    assert!(announced(LearnConfig::OFF).0.is_empty());
}

#[test]
fn a_new_estimator_starts_from_the_calibration_and_learning_off_learns_nothing() {
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "heavy-air").unwrap();
    let (balls, launches) = session(&world, &cal, 12);
    let fresh = *Estimator::new(&cal, config(LearnConfig::default())).session();
    assert_eq!(fresh.restitution.value, cal.physics.restitution);
    assert_eq!(fresh.friction.value, cal.physics.friction);
    assert_eq!(fresh.drag.value, 1.0);
    assert_eq!(fresh.bounce_noise(), EstimatorConfig::default().noise.bounce_vel);
    assert_eq!(fresh.restitution.count, 0);
    let mut on = Estimator::new(&cal, config(LearnConfig::default()));
    feed(&mut on, &balls, &launches);
    assert_ne!(*on.session(), fresh);
    // A restart (a new configuration) forgets the session.
    assert_eq!(*Estimator::new(&cal, config(LearnConfig::default())).session(), fresh);
    let mut off = Estimator::new(&cal, config(LearnConfig::OFF));
    feed(&mut off, &balls, &launches);
    assert_eq!(*off.session(), fresh);
}

#[test]
fn learning_off_scores_each_ball_as_if_it_were_alone() {
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "other-table").unwrap();
    let (balls, launches) = session(&world, &cal, 12);
    let alone = |learn: LearnConfig| -> Vec<Vec<StrikePlan>> {
        balls
            .iter()
            .zip(&launches)
            .flat_map(|(b, &t0)| feed(&mut Estimator::new(&cal, config(learn)), std::slice::from_ref(b), &[t0]))
            .collect()
    };
    let same = |a: &[Vec<StrikePlan>], b: &[Vec<StrikePlan>]| {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.iter().map(what).eq(y.iter().map(what)))
    };
    // Off: bit-identical plans, ball by ball, in a session or alone.
    let off = feed(&mut Estimator::new(&cal, config(LearnConfig::OFF)), &balls, &launches);
    assert!(off.iter().filter(|p| !p.is_empty()).count() >= 8);
    assert!(same(&off, &alone(LearnConfig::OFF)));
    // On: the later balls fly with what the earlier ones taught.
    let on = feed(&mut Estimator::new(&cal, config(LearnConfig::default())), &balls, &launches);
    assert!(!same(&on, &alone(LearnConfig::default())));
    assert!(!same(&on, &off));
}

#[test]
fn a_bounce_nothing_explains_is_counted_and_teaches_nothing() {
    // A ball that clips the table's edge (or a tracker that jumps at the
    // bounce): after the contact it flies slower along x and faster up
    // than any table and spin could make it. A small kick passes the
    // filter's gate and the bounce check names it; a large one loses the
    // track at the gate. Neither teaches the session anything.
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "other-table").unwrap();
    let (balls, launches) = session(&world, &cal, 12);
    for (kick, unexplained) in [((-0.6, 0.4), true), ((-1.5, 1.0), false)] {
        let mut est = Estimator::new(&cal, config(LearnConfig::default()));
        feed(&mut est, &balls, &launches);
        let t0 = launches.last().unwrap() + 3.0;
        let mut out = Default::default();
        est.poll(Instant::from_secs_f64(t0 - 1.0), &mut out);
        let before = *est.session();
        let mut odd = balls[7].clone();
        let tb = odd.truth.bounce.expect("it bounces").t;
        for o in odd.observations.iter_mut().filter(|o| o.t > tb) {
            let dt = o.t - tb;
            o.pos.x += kick.0 * dt;
            o.pos.z += kick.1 * dt;
        }
        let mut events = Vec::new();
        for o in &odd.observations {
            events.extend(est.observe(Instant::from_secs_f64(t0 + o.t), o.pos).events);
        }
        let mut out = Default::default();
        est.poll(Instant::from_secs_f64(t0 + 5.0), &mut out);
        events.extend(out.events);
        let named = events.iter().any(|e| matches!(e, EstimatorEvent::BounceUnexplained { .. }));
        let lost = events.iter().any(|e| matches!(e, EstimatorEvent::Ended { reason: EndReason::Lost, .. }));
        assert_eq!((named, lost), (unexplained, !unexplained), "{kick:?}: {events:?}");
        let after = *est.session();
        assert_eq!(after.unexplained, before.unexplained + u32::from(unexplained));
        // Neither the table, nor its noise, nor the spin prior moved.
        assert_eq!((after.restitution, after.friction), (before.restitution, before.friction), "{kick:?}");
        assert_eq!(after.bounce_vel, before.bounce_vel, "{kick:?}");
        assert_eq!(after.spin, before.spin, "{kick:?}");
    }
}

#[test]
fn the_cameras_spin_gives_the_ball_its_size_and_teaches_the_session() {
    // Fast topspin in air whose lift saturates: the flight reads the spin
    // low and the bounce cannot correct it (the contact slides). The
    // ceiling camera's spin, fused 0.1 s before the bounce, sets the size
    // of the spin the stroke answers, in every plan from then on (the
    // batches move the flight's spin, not the camera's); the session keeps
    // it for the next balls of that flight.
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "real-launcher").unwrap();
    let (balls, launches) = session(&world, &cal, 27);
    let k = balls.iter().position(|b| b.truth.setting.to_string() == "topspin-high").expect("a fast topspin ball");
    let (ball, t0) = (&balls[k], launches[k]);
    let truth = Vec3::from(ball.truth.spin);
    let tb = ball.truth.bounce.expect("it bounces").t;
    let off = |w: Vec3| (w.norm() / truth.norm() - 1.0).abs();
    let last_plan = |logo: bool| {
        let mut est = Estimator::new(&cal, config(LearnConfig::default()));
        let count = est.session().spin.count;
        let (mut plan, mut fused, mut worst) = (None, None, 0.0f64);
        for o in &ball.observations {
            if logo && fused.is_none() && o.t > tb - 0.1 {
                let m = LogoSpin {
                    last_crop: Instant::from_secs_f64(t0 + o.t),
                    spin: truth,
                    cov: nalgebra::Matrix3::identity() * 4.0,
                };
                fused = est.observe_logo_spin(&m);
            }
            let now = est.observe(Instant::from_secs_f64(t0 + o.t), o.pos).plan;
            if let Some(p) = now.filter(|_| fused.is_some() && o.t < tb) {
                worst = worst.max(off(p.spin));
            }
            plan = now.or(plan);
        }
        (plan.expect("a plan").spin, fused, est.session().spin.count - count, worst)
    };
    let (flown, _, _, _) = last_plan(false);
    let (seen, fused, taught, worst) = last_plan(true);
    assert!(worst < 0.10, "a plan after the camera's spin strays {worst} from its size");
    assert!(matches!(fused, Some(EstimatorEvent::LogoSpin { accepted: true, .. })), "{fused:?}");
    assert!(off(flown) > 0.25, "the flight alone: {flown} against {truth}");
    assert!(off(seen) < 0.10, "with the camera: {seen} against {truth}");
    assert!(taught >= 1, "the session kept the reading");
}

#[test]
fn a_bounce_that_surprised_the_filter_keeps_the_track_and_teaches_the_session() {
    // A session's first fast topspin balls in air measured on real balls:
    // the flight reads their spin at a third to a half, the table kicks
    // them forward far more than that spin would, and the first samples
    // after the bounce fall outside the gate. Lost there, the ball would
    // be picked up again as a new track with no bounce, and the session
    // would learn nothing from the balls it most needs. The bounce is
    // flown again with the spin's size free, once: one track, its bounce
    // learned, and its plans after the bounce on time.
    let cal = Calibration::default_cell();
    let world = world_named(&cal, "real-rally").unwrap();
    let (balls, launches) = session(&world, &cal, 27);
    let mut surprised = 0;
    for (k, ball) in balls.iter().enumerate().filter(|(_, b)| b.truth.setting.to_string().starts_with("topspin")) {
        let (t0, setting) = (launches[k], ball.truth.setting);
        let hit = ball.truth.hit.as_ref().expect("it crosses the hitting plane");
        // Each as a session's first ball.
        let mut est = Estimator::new(&cal, config(LearnConfig::default()));
        let (mut events, mut last) = (Vec::new(), None);
        for o in &ball.observations {
            let out = est.observe(Instant::from_secs_f64(t0 + o.t), o.pos);
            last = out.plan.or(last);
            events.extend(out.events);
        }
        let mut out = Default::default();
        est.poll(Instant::from_secs_f64(t0 + 5.0), &mut out);
        events.extend(out.events);
        if est.session().surprised == 0 {
            continue;
        }
        surprised += 1;
        let count = |f: &dyn Fn(&EstimatorEvent) -> bool| events.iter().filter(|e| f(e)).count();
        assert_eq!(count(&|e| matches!(e, EstimatorEvent::Started { .. })), 1, "{k} {setting}: {events:?}");
        assert_eq!(count(&|e| matches!(e, EstimatorEvent::Ended { reason: EndReason::Lost, .. })), 0, "{k} {setting}");
        assert_eq!(count(&|e| matches!(e, EstimatorEvent::Learned { .. })), 1, "{k} {setting}: its bounce taught");
        assert_eq!(est.session().spin.kept_by_speed(), 1, "{k} {setting}: its spin kept with its speed");
        let late = last.expect("plans").hit_time.as_secs_f64() - (t0 + hit.t);
        assert!(late.abs() < 0.003, "{k} {setting}: the last plan {:.1} ms off", late * 1e3);
    }
    // Medium and fast topspin, and one slow ball that its lift read low.
    assert!(surprised >= 5, "{surprised} of the first 9 topspin balls surprised the filter");
}
