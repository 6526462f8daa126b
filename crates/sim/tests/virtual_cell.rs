//! The demo's whole cell on a virtual clock (`topspin_sim::virtual_cell`): the
//! simulated tracker → ingest → estimator → RSI session ↔ mock KR C4, the
//! strokes judged on the truth. What `tests/demo.rs` and
//! `tests/tracker_faults.rs` check through the real threads and sockets,
//! here exact: no late answer is the machine's, every datagram the
//! injector sent reaches the ingest, and the same seed gives the same run.

use topspin_cnn as cnn;
use topspin_core::calib::Calibration;
use topspin_core::kinematics::Joints;
use topspin_core::time::Duration;
use topspin_daemon::runtime::{LogoMethodChoice, LogoRuntime};
use topspin_sim::Strokes;
use topspin_sim::demo::{BallVerdict, DemoConfig, OutOfReach, meeting};
use topspin_sim::faults::TrackerFaults;
use topspin_sim::mock_krc::MockKrcConfig;
use topspin_sim::virtual_cell::{VirtualRun, run_virtual};

fn summary(r: &VirtualRun) -> String {
    let mut err: Vec<f64> = r.per_ball.iter().filter(|b| b.reachable).filter_map(|b| b.hit_err_mm).collect();
    err.sort_by(f64::total_cmp);
    let median = err.get(err.len() / 2).copied().unwrap_or(f64::NAN);
    let returned = r.returned();
    format!(
        "{} of {} reachable hit, {returned} returned, median miss {median:.1} mm; RSI {} cycles, {} late, {} axis-rate \
         overs, {} clamped{}; {} returns followed, {} spins read from them; ingest {:?}",
        r.hits(),
        r.reachable(),
        r.mock.cycles,
        r.mock.late,
        r.mock.rates_over,
        r.session.safety_clamped,
        r.mock.stopped.map_or(String::new(), |s| format!(", stopped: {s}")),
        r.returns_seen,
        r.returns_read,
        r.ingest
    ) + &r.logo.map_or(String::new(), |l| {
        format!("; logo {l:?}, {} spins fused, {} gated", r.logo_spins_fused, r.logo_spins_gated)
    })
}

/// The ceiling camera's logo thread, finding the logo with `method`.
fn logo_runtime(method: LogoMethodChoice) -> LogoRuntime {
    LogoRuntime {
        bind: "127.0.0.1:0".parse().expect("literal"),
        source: None,
        method,
        camera: topspin_core::calib::CameraCalib::default_camera(),
        camera_latency: Duration(0),
        thread: Default::default(),
    }
}

/// The world `name` of `topspin eval worlds`, its balls spun as a
/// launcher spins them (axes across the flight).
fn launcher_world(cal: &Calibration, name: &str) -> topspin_sim::worlds::World {
    topspin_sim::worlds::world_named(cal, name).expect("a world of topspin eval worlds").with_launcher_axes()
}

/// The bat ended at home, within every limit.
fn home_within_limits(r: &VirtualRun) {
    assert_eq!(r.mock.poscorr_clamped, 0, "{}", summary(r));
    assert!(r.mock.stopped.is_none(), "{}: {:?}", summary(r), r.mock.stopped.map(|s| s.to_string()));
    assert!(!r.mock.stopped_by_monitor && !r.mock.stopped_by_limit, "{}", summary(r));
    let home = MockKrcConfig::default_cell().unwrap().controller.start;
    let end = r.mock.path.last().expect("cycles ran").actual;
    for i in 0..6 {
        assert!((end[i] - home[i]).abs() < 0.5, "the bat ended at {end:?}, home {home:?}");
    }
}

#[test]
fn thirty_balls_are_hit_on_virtual_time() {
    let cal = Calibration::default_cell();
    let cfg = DemoConfig { balls: 30, seed: 7, ..DemoConfig::default() };
    let r = run_virtual(&cfg, &cal);
    eprintln!("virtual demo: {}", summary(&r));
    assert_eq!(r.balls.len(), 30);
    // The hitting volume reaches balls the plane alone does not.
    let on_the_plane = r.balls.iter().filter(|b| topspin_sim::demo::reachable(&cal, b)).count();
    assert!(r.reachable() > on_the_plane && on_the_plane >= 20, "{on_the_plane}: {}", summary(&r));
    assert!(r.hits() as f64 >= 0.95 * r.reachable() as f64, "{}", summary(&r));
    // Returns: over the net onto the opponent's half, judged on
    // the bat's actual pose and velocity; robots in the literature return
    // 80–97 % of launcher balls. Those met off the plane, at the window's
    // edge, are the harder ones: over seeds 1–25 the cell returns 89.2 % of
    // the reachable balls (`returns_over_seeds`), this seed 83 %.
    let returned = r.returned();
    assert!(returned as f64 >= 0.8 * r.reachable() as f64, "{}", summary(&r));
    assert_eq!(r.mock.late, 0);
    assert_eq!((r.session.requests, r.session.answers), (r.mock.cycles, r.mock.cycles));
    // Plans the axes cannot make are refused (and the ball skipped where
    // none can be made); what is taken keeps every axis within its limits,
    // and no stroke meets the safety filter: a face at the edge of the
    // workspace's orientation range once had the filter brake the wrist,
    // a step the axes took through their lag (A2 at 2.5× its acceleration
    // limit; seed 2 on the wall clock, A4 at 5.9×). Strokes now keep 10°
    // inside that range (`ORIENTATION_MARGIN_RAD`).
    assert_eq!(r.session.safety_clamped, 0, "{}", summary(&r));
    assert_eq!(r.mock.rates_over, 0, "{}", summary(&r));
    // Every frame is taken in: the flights', and those of the returns the
    // tracker followed back over the table. Each return met reads its
    // ball's spin (some slide on the rubber, and tell nothing).
    let flights = r.balls.iter().map(|b| b.observations.len()).sum::<usize>();
    assert_eq!(r.ingest.accepted as usize, flights + r.return_frames);
    assert!(r.returns_seen >= r.hits() && r.returns_read as f64 >= 0.7 * r.returns_seen as f64, "{}", summary(&r));
    home_within_limits(&r);
    // One plan per trajectory, each within the 4 ms the judge allows.
    for b in r.per_ball.iter().filter(|b| b.reachable) {
        let dt = b.plan_dt_ms.expect("a plan for every reachable ball");
        assert!(dt.abs() <= 4.0, "ball {}: plan {dt:.2} ms off the true hit", b.ball);
    }
}

#[test]
fn the_same_seed_makes_the_same_session() {
    let cal = Calibration::default_cell();
    let cfg = DemoConfig { balls: 6, seed: 21, ..DemoConfig::default() };
    let (a, b) = (run_virtual(&cfg, &cal), run_virtual(&cfg, &cal));
    assert_eq!(a.mock, b.mock);
    assert_eq!(a.last_plans, b.last_plans);
    let misses = |r: &VirtualRun| r.per_ball.iter().map(|v| v.hit_err_mm).collect::<Vec<_>>();
    assert_eq!(misses(&a), misses(&b));
}

/// A run with no tail still plays its last stroke out and ends with the
/// bat rested home: the same verdicts as a run with a long tail.
#[test]
fn the_last_stroke_is_never_cut_short() {
    let cal = Calibration::default_cell();
    let cfg = DemoConfig { balls: 4, seed: 5, tail_s: 0.0, ..DemoConfig::default() };
    let short = run_virtual(&cfg, &cal);
    let long = run_virtual(&DemoConfig { tail_s: 1.5, ..cfg }, &cal);
    home_within_limits(&short);
    assert!(short.hits() >= 1 && short.per_ball.last().is_some_and(|v| v.hit), "{}", summary(&short));
    let verdicts = |r: &VirtualRun| r.per_ball.iter().map(|v| (v.hit, v.returned, v.hit_err_mm)).collect::<Vec<_>>();
    assert_eq!(verdicts(&short), verdicts(&long));
    assert!(short.mock.path.len() < long.mock.path.len());
}

#[test]
fn every_tracker_fault_at_once_is_survived_and_counted_exactly() {
    let cal = Calibration::default_cell();
    let cfg = DemoConfig { balls: 9, seed: 3, tracker_faults: Some(TrackerFaults::all()), ..DemoConfig::default() };
    let r = run_virtual(&cfg, &cal);
    let f = r.injected.expect("faults were injected");
    let i = r.ingest;
    eprintln!("tracker faults: {}; injected {f:?}", summary(&r));
    // RSI answered on time throughout, and the robot stayed in its limits.
    assert_eq!(r.mock.late, 0);
    home_within_limits(&r);
    // Every fault reached the ingest and was dropped and counted there.
    assert_eq!(i.foreign, f.foreign, "{i:?} {f:?}");
    assert_eq!(i.malformed, f.garbage, "{i:?} {f:?}");
    assert!(i.duplicate > 0 && i.out_of_order > 0 && i.clock_jumps > 0, "{i:?}");
    // The data still allows hits.
    assert!(r.reachable() > 0 && r.hits() > 0, "{}", summary(&r));
}

/// The measurement behind docs/results.md's virtual-cell numbers (not a check):
/// `SEEDS=1,2,3,4,5,7 BALLS=27 [CORRECTION=axis] [WORLD=real-launcher]
/// [STROKES=human-rally] [LOGO=background|cnn] [AIM_TARGET=x,y]
/// [AIM_PATTERN=x,y;x,y] [AIM_AWAY=1] [AIM_BAT_SPEED=slow,fast] [PLANE_ALONE=1]
/// cargo test --release --test virtual_cell --
/// --ignored --nocapture` (`WORLD`: a world of `topspin eval worlds`,
/// default the calibration's own physics; `STROKES`: the balls' source,
/// default the cell's launcher; `LOGO`: the ceiling camera's spin fused,
/// found by background subtraction or the CNN; `AIM_…`: where the returns
/// are aimed, `strike.aim_target`, a pattern, or away from the opponent,
/// and `strike.aim_bat_speed`; `PLANE_ALONE`: the hitting plane without the volume;
/// `NO_RETURNS`: the tracker does not follow the returns)
/// prints every ball not returned (or
/// missed) with the judge's reason and the totals over the seeds: over
/// the reachable balls, and over all balls (every ball of a run bounces
/// on the robot's half).
#[test]
#[ignore = "a measurement: run it by name"]
fn returns_over_seeds() {
    let mut cal = Calibration::default_cell();
    let pair = |s: &str| -> [f64; 2] {
        let v: Vec<f64> = s.split(',').map(|v| v.trim().parse().expect("a target: x,y")).collect();
        [v[0], v[1]]
    };
    if let Ok(t) = std::env::var("AIM_TARGET") {
        cal.strike.aim_target = pair(&t);
    }
    if let Ok(p) = std::env::var("AIM_PATTERN") {
        cal.strike.aim_pattern = p.split(';').map(pair).collect();
        cal.strike.aim_strategy = topspin_core::calib::AimStrategy::Pattern;
    }
    if let Ok(v) = std::env::var("AIM_BAT_SPEED") {
        cal.strike.aim_bat_speed = pair(&v);
    }
    if std::env::var("PLANE_ALONE").is_ok() {
        cal.strike.hit_depth_x = None;
    }
    if std::env::var("AIM_AWAY").is_ok() {
        cal.strike.aim_strategy = topspin_core::calib::AimStrategy::Away;
    }
    let seeds: Vec<u64> = std::env::var("SEEDS")
        .unwrap_or_else(|_| "1,2,3,4,5,7".into())
        .split(',')
        .map(|s| s.trim().parse().expect("SEEDS: comma-separated integers"))
        .collect();
    let balls = std::env::var("BALLS").map_or(27, |s| s.parse().expect("BALLS: an integer"));
    let world = std::env::var("WORLD").ok().map(|name| launcher_world(&cal, &name));
    let strokes = std::env::var("STROKES")
        .map_or(Strokes::Launcher, |s| s.parse().expect("STROKES: a stroke source of topspin demo --strokes"));
    let logo = std::env::var("LOGO").ok().map(|m| {
        logo_runtime(match m.as_str() {
            "background" => LogoMethodChoice::Background,
            "cnn" => LogoMethodChoice::Cnn { model: cnn::default_model(), backend: cnn::Backend::Auto },
            _ => panic!("LOGO: background or cnn"),
        })
    });
    let (mut all, mut all_returned, mut reach, mut hit, mut returned) = (0, 0, 0, 0, 0);
    let (mut rates_over, mut clamped) = (0, 0);
    let mut miss = Vec::new();
    let mut out = [0usize; 4];
    let mut per_setting = std::collections::BTreeMap::<String, [usize; 3]>::new();
    let (mut plan_err, mut tracking) = (Vec::new(), Vec::new());
    // Timing tolerance of the returns per setting (earlier, later, ms),
    // and failed balls a shifted arrival would have returned.
    let mut tolerance = std::collections::BTreeMap::<String, (Vec<f64>, Vec<f64>)>::new();
    let mut mistimed = 0;
    // Spin tolerance of the returns per setting: how much less and more
    // spin (× the true spin at the contact) the same strokes return.
    let mut spin_tolerance = std::collections::BTreeMap::<String, (Vec<f64>, Vec<f64>)>::new();
    for &seed in &seeds {
        let mut cfg = DemoConfig { balls, seed, world: world.clone(), strokes, ..DemoConfig::default() };
        if let Ok(c) = std::env::var("CORRECTION") {
            cfg.runtime.correction = c.parse().expect("CORRECTION: cartesian or axis");
        }
        cfg.runtime.logo = logo.clone();
        cfg.tracker.follows_returns = std::env::var("NO_RETURNS").is_err();
        let r = run_virtual(&cfg, &cal);
        rates_over += r.mock.rates_over;
        clamped += r.session.safety_clamped;
        all += r.balls.len();
        all_returned += r.per_ball.iter().filter(|b| b.returned).count();
        for (name, t) in topspin_sim::demo::by_setting(&r.balls, &r.per_ball) {
            let sum = per_setting.entry(name).or_default();
            for (s, n) in sum.iter_mut().zip([t.balls, t.reachable, t.returned]) {
                *s += n;
            }
        }
        let o = OutOfReach::of(&cal, &r.balls);
        for (sum, n) in out.iter_mut().zip([o.no_crossing, o.wide, o.low, o.high]) {
            *sum += n;
        }
        for b in r.per_ball.iter().filter(|b| b.reachable) {
            reach += 1;
            hit += b.hit as usize;
            returned += b.returned as usize;
            miss.extend(b.hit_err_mm);
            plan_err.extend(b.plan_err_mm);
            tracking.extend(b.tracking_err_mm);
            if let (true, Some([lo, hi])) = (b.returned, b.timing_window_ms) {
                let t = tolerance.entry(b.setting.clone()).or_default();
                t.0.push(-lo);
                t.1.push(hi);
            }
            if let (true, Some([lo, hi])) = (b.returned, b.contact.and_then(|c| c.spin_window)) {
                let t = spin_tolerance.entry(b.setting.clone()).or_default();
                t.0.push(lo);
                t.1.push(hi);
            }
            if !(b.hit && b.returned) {
                mistimed += b.timing_window_ms.is_some() as usize;
                eprintln!(
                    "seed {seed} ball {:2} {:15} spin {:?} rps, read {:?}; miss {:.1} mm, plan {:+.1} ms, returned \
                     by arrival shifts {:?} ms, by spins ×{:?}; {} {}",
                    b.ball,
                    b.setting,
                    b.true_spin_rps.map(|v| v.round()),
                    b.estimated_spin_rps.map(|w| w.map(|v| v.round())),
                    b.hit_err_mm.unwrap_or(f64::NAN),
                    b.plan_dt_ms.unwrap_or(f64::NAN),
                    b.timing_window_ms,
                    b.contact.and_then(|c| c.spin_window).map(|w| w.map(|k| (k * 100.0).round() / 100.0)),
                    b.return_fail.map_or("returned", |f| f.name()),
                    b.return_why.as_deref().unwrap_or("")
                );
            }
        }
        eprintln!("{}", summary(&r));
    }
    for (name, [n, reach, ret]) in &per_setting {
        eprintln!(
            "{name:16} {n:4} balls, {reach:4} reachable, {ret:4} returned ({:.1} % of all)",
            100.0 * *ret as f64 / *n as f64
        );
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let (mut early_all, mut late_all) = (Vec::new(), Vec::new());
    for (name, (early, late)) in &mut tolerance {
        early_all.extend_from_slice(early);
        late_all.extend_from_slice(late);
        eprintln!(
            "{name:16} timing tolerance of {:4} returns: {:.0} ms earlier, {:.0} ms later (medians)",
            early.len(),
            median(early),
            median(late)
        );
    }
    for (name, (less, more)) in &mut spin_tolerance {
        eprintln!(
            "{name:16} spin tolerance of {:4} returns: ×{:.2} to ×{:.2} of the true spin (medians)",
            less.len(),
            median(less),
            median(more)
        );
    }
    eprintln!(
        "timing tolerance of all returns: {:.0} ms earlier, {:.0} ms later (medians; each side at most {} ms); \
         {mistimed} balls not returned would have been with the ball earlier or later",
        median(&mut early_all),
        median(&mut late_all),
        topspin_sim::returns::TIMING_SPAN_MS
    );
    eprintln!(
        "seeds {seeds:?} × {balls} balls: {hit} of {reach} reachable hit ({:.1} %), {returned} returned ({:.1} %), \
         median miss {:.1} mm (last plan vs truth {:.1} mm, bat vs last plan {:.1} mm); \
         {rates_over} axis-rate overs, {clamped} safety-clamped cycles; {all_returned} of all {all} balls returned \
         ({:.1} %); out of reach: {} no crossing after the bounce, {} wide, {} low, {} high",
        100.0 * hit as f64 / reach as f64,
        100.0 * returned as f64 / reach as f64,
        median(&mut miss),
        median(&mut plan_err),
        median(&mut tracking),
        100.0 * all_returned as f64 / all as f64,
        out[0],
        out[1],
        out[2],
        out[3]
    );
}

#[test]
fn the_ceiling_cameras_spin_reaches_the_estimator_and_corrects_what_the_flight_misread() {
    // Air whose lift saturates: the flight reads fast spins low, and the
    // strokes answer the spin the camera saw instead.
    let cal = Calibration::default_cell();
    let world = launcher_world(&cal, "real-launcher");
    let mut cfg = DemoConfig { balls: 27, seed: 1, world: Some(world), ..DemoConfig::default() };
    let without = run_virtual(&cfg, &cal);
    cfg.runtime.logo = Some(logo_runtime(LogoMethodChoice::Background));
    let with = run_virtual(&cfg, &cal);
    eprintln!("without the camera: {}\nwith it: {}", summary(&without), summary(&with));
    let logo = with.logo.expect("the logo stream ran");
    assert!(without.logo.is_none());
    // Every rendered crop reached the stream; each spin it fitted went to
    // the estimator, which fused or gated it.
    assert_eq!(logo.dropped, 0);
    assert!(logo.fitted > 0 && logo.fitted <= logo.sequences, "{logo:?}");
    assert!(with.logo_spins_fused > 0 && with.logo_spins_fused + with.logo_spins_gated <= logo.fitted, "{logo:?}");
    assert_eq!((with.mock.late, with.mock.rates_over, with.session.safety_clamped), (0, 0, 0), "{}", summary(&with));
    home_within_limits(&with);
    // The strokes answer a spin nearer the truth, and return at least as
    // many balls (over 25 seeds the returns of the reachable balls go
    // from 78 % to 88 %, `returns_over_seeds`; the hits stay at 98 %
    // either way, one ball up or down from seed to seed).
    let spin_err = |r: &VirtualRun| {
        let mut e: Vec<f64> = r.per_ball.iter().filter(|b| b.reachable).filter_map(|b| b.spin_err_pct).collect();
        e.sort_by(f64::total_cmp);
        e[e.len() / 2]
    };
    let (e_with, e_without) = (spin_err(&with), spin_err(&without));
    eprintln!("median spin error {e_without:.1} % without the camera, {e_with:.1} % with it");
    assert!(e_with < 0.5 * e_without, "{e_with:.1} % vs {e_without:.1} %");
    assert!(with.returned() >= without.returned(), "{} vs {}", summary(&with), summary(&without));
}

#[test]
fn an_arm_that_starts_off_home_is_taken_home_first_and_then_plays() {
    // RSI starts with the arm where a KRL program left it (A1 +30°, the
    // wrist turned): the session takes it home at the commissioning speed,
    // refuses the plans meanwhile, and hits the balls that come after.
    let cal = Calibration::default_cell();
    let home = cal.robot.home_joints(&cal.robot.arm()).unwrap().degrees();
    let off = [30.0, -5.0, 5.0, 10.0, 20.0, -30.0];
    let cfg = DemoConfig {
        balls: 8,
        seed: 4,
        start_joints: Some(core::array::from_fn(|i| home[i] + off[i])),
        ..DemoConfig::default()
    };
    let r = run_virtual(&cfg, &cal);
    assert!(r.mock.stopped.is_none(), "{}", summary(&r));
    assert_eq!((r.mock.poscorr_clamped, r.mock.rates_over), (0, 0), "{}", summary(&r));
    assert_eq!(r.session.ways_home, 1);
    assert_eq!(r.session.arm_stops, 0);
    // The way home takes about 2.6 s: the first two balls come before it
    // ends. POSCORR's limits count from the RSI start pose, here 0.15 m
    // to the side of home (and turned 60°): a ball met beyond them
    // (y_B = −y_T past +0.65 m) is not the arm's from this start.
    let start = cal.robot.arm().tcp(&Joints::from_degrees(cfg.start_joints.unwrap())).to_pose6();
    let (lo, hi) = (cal.robot.poscorr.lower_xyz_mm[1] * 1e-3, cal.robot.poscorr.upper_xyz_mm[1] * 1e-3);
    let within = |b: &&BallVerdict| {
        meeting(&cal, &r.balls[b.ball]).is_some_and(|h| (start[1] + lo..=start[1] + hi).contains(&-h.pos[1]))
    };
    let later: Vec<_> = r.per_ball.iter().filter(|b| b.reachable).skip(2).filter(within).collect();
    assert!(!later.is_empty() && later.iter().filter(|b| b.hit).count() + 1 >= later.len(), "{}", summary(&r));
}

#[test]
fn the_cell_plays_balls_that_fly_the_lift_real_balls_showed() {
    // The balls fly the launcher flights' measured lift, each its own drag
    // and lift, on a table unlike the calibration's; the daemon knows only
    // the calibration, and the judges fly every ball as it flew.
    let cal = Calibration::default_cell();
    let world = launcher_world(&cal, "real-launcher");
    let cfg = DemoConfig { balls: 18, seed: 5, world: Some(world), ..DemoConfig::default() };
    let r = run_virtual(&cfg, &cal);
    eprintln!("real-launcher: {}", summary(&r));
    let own = cal.propagator();
    assert!(r.balls.iter().all(|b| b.physics != own));
    assert_ne!(r.balls[0].physics, r.balls[1].physics);
    assert!(r.reachable() >= 10, "{}", summary(&r));
    assert!(r.hits() as f64 >= 0.8 * r.reachable() as f64, "{}", summary(&r));
    assert_eq!((r.session.safety_clamped, r.mock.rates_over), (0, 0), "{}", summary(&r));
    home_within_limits(&r);
}

#[test]
fn the_cell_plays_human_rally_strokes_and_serves() {
    // Real human strokes (rally strokes and serves through their bounce on
    // the server's half), as measured right after the racket, fly at the
    // robot; the daemon tracks each through every table contact.
    let cal = Calibration::default_cell();
    let cfg = DemoConfig { balls: 27, seed: 3, strokes: Strokes::Human, ..DemoConfig::default() };
    let r = run_virtual(&cfg, &cal);
    eprintln!("human: {}", summary(&r));
    assert_eq!(r.balls.len(), 27);
    assert!(r.balls.iter().any(|b| b.truth.launch.pos[0] > -1.3), "rally strokes from over the table");
    let serves: Vec<_> = r.balls.iter().filter(|b| b.truth.launch.pos[0] < -1.3).collect();
    assert!(!serves.is_empty(), "serves from behind the table");
    // Judged like a match: per stroke type and speed band, over all balls.
    let split = topspin_sim::demo::by_setting(&r.balls, &r.per_ball);
    assert_eq!(split.values().map(|t| t.balls).sum::<usize>(), 27);
    assert_eq!(split.values().map(|t| t.reachable).sum::<usize>(), r.reachable());
    assert!(split.values().all(|t| t.returned <= t.balls));
    // Every ball is played off its bounce on the robot's half.
    assert!(r.balls.iter().all(|b| b.truth.bounce.is_some_and(|bn| bn.pos[0] > 0.0)));
    assert!(r.reachable() >= 10, "{}", summary(&r));
    assert!(r.hits() + 1 >= r.reachable(), "{}", summary(&r));
    let returned = r.returned();
    assert!(returned as f64 >= 0.85 * r.reachable() as f64, "{}", summary(&r));
    assert_eq!((r.session.safety_clamped, r.mock.rates_over), (0, 0), "{}", summary(&r));
    home_within_limits(&r);
}

/// A wide ball met at y_B 0.70 with the bat at 2 m/s: its follow-through
/// came to rest 0.3 mm inside the box's side, passed it by 0.5 mm, and the
/// safety filter braked it there for 33 cycles, two of them axis steps
/// the controller counted (saturating world, seed 24). Rest points keep
/// the path's 5 mm inside now.
#[test]
fn a_wide_hit_comes_to_rest_inside_the_box() {
    let cal = Calibration::default_cell();
    let world = launcher_world(&cal, "saturating");
    let cfg = DemoConfig { balls: 27, seed: 24, world: Some(world), ..DemoConfig::default() };
    let r = run_virtual(&cfg, &cal);
    assert!(r.hits() > 0, "{}", summary(&r));
    assert_eq!((r.session.safety_clamped, r.mock.rates_over), (0, 0), "{}", summary(&r));
    home_within_limits(&r);
}
