//! The robot boundary on the virtual clock, the RSI session against the
//! mock KR C4: a start wherever the arm stands (home at the
//! commissioning speed, then play; or hold where the way home is unsafe),
//! after every restart too; brakes applied mid-stroke (the stroke
//! abandoned, no jump when the axes move again, the session goes on); a
//! KRL program with another TOOL_DATA or BASE_DATA refused at the first
//! request.

use topspin_core::calib::Calibration;
use topspin_core::kinematics::{Joints, Pose};
use topspin_core::motion::{MotionLimits, PlanRejected};
use topspin_core::rsi::KukaPose;
use topspin_core::rsi::{ArmMode, RsiSession, SessionConfig, SessionEvent};
use topspin_core::rsi::{LikelyFrame, StartRefused};
use topspin_core::time::{Duration, Instant};
use topspin_sim::mock_krc::ControllerConfig;
use topspin_sim::mock_krc::{Faults, MockKrcConfig, PathSample};
use topspin_sim::pair::Pair;
use topspin_sim::strikes::{StrikeMiss, strike_stream};

const T0: Instant = Instant(1_000_000_000);

fn limits() -> MotionLimits {
    MotionLimits::from_robot(&Calibration::default_cell().robot)
}

fn session() -> RsiSession {
    RsiSession::new(SessionConfig::from_calibration(&Calibration::default_cell(), "ImFree")).unwrap()
}

fn controller() -> ControllerConfig {
    MockKrcConfig::default_cell().unwrap().controller
}

/// The controller standing at home joints + `deg` (degrees per axis).
fn standing_off_home(deg: [f64; 6]) -> ControllerConfig {
    let mut c = controller();
    let h = limits().home_joints.degrees();
    c.stand_at(Joints::from_degrees(core::array::from_fn(|i| h[i] + deg[i])));
    c
}

fn pose(s: &[f64; 6]) -> Pose {
    KukaPose::from_array(*s).to_pose()
}

/// The largest step of the commanded TCP (mm) and turn (degrees) per cycle.
fn largest_steps(path: &[PathSample], start: [f64; 6]) -> (f64, f64) {
    let mut last = pose(&start);
    let (mut dp, mut da) = (0.0f64, 0.0f64);
    for s in path {
        let p = pose(&s.commanded);
        let (d, a) = p.distance(&last);
        dp = dp.max(d * 1e3);
        da = da.max(a.to_degrees());
        last = p;
    }
    (dp, da)
}

#[test]
fn an_arm_off_home_goes_home_at_the_commissioning_speed_then_plays() {
    let c = standing_off_home([30.0, -5.0, 5.0, 10.0, 20.0, -30.0]);
    let start = c.start;
    let (from, turn) = pose(&start).distance(&Pose::from_pose6(&limits().home));
    assert!(from > 0.15 && turn.to_degrees() > 25.0, "{from} m, {}°", turn.to_degrees());
    let mut p = Pair::new(session(), c, Faults::default(), 11, T0);
    // A ball's plans arrive from the first cycle on: refused until home.
    let finals = p.run_strikes(5, 4000);
    let r = p.result();
    assert!(r.stopped.is_none(), "{:?}", r.stopped.map(|s| s.to_string()));
    assert_eq!((r.poscorr_clamped, r.rates_over), (0, 0));
    let events = p.take_events();
    let going = events.iter().position(|e| matches!(e, SessionEvent::GoingHome { .. })).expect("went home");
    let home = events.iter().position(|e| matches!(e, SessionEvent::Home)).expect("arrived");
    assert!(going < home);
    let SessionEvent::GoingHome { duration, .. } = events[going] else { unreachable!() };
    let homing_cycles = (duration.as_secs_f64() / 0.004).ceil() as usize;
    // On the way: no step over the commissioning speed (200 mm/s = 0.8 mm
    // a cycle; the goal is 1 mm) or turn over its rate (30°/s).
    let (dp, da) = largest_steps(&r.path[..homing_cycles], start);
    assert!(dp <= 0.8 * 1.001, "largest step {dp:.3} mm");
    assert!(da <= 0.12 * 1.001, "largest turn {da:.4}° a cycle");
    assert!(dp > 0.4 || da > 0.06, "at the commissioning speed or rate, not crawling ({dp:.3} mm, {da:.4}°)");
    // Plans before home were refused as such, and the strokes after it hit.
    let not_home =
        events.iter().filter(|e| matches!(e, SessionEvent::PlanRejected { reason: PlanRejected::NotHome, .. })).count();
    assert!(not_home > 50, "{not_home}");
    let lim = limits();
    let hit = finals
        .iter()
        .filter(|plan| plan.hit_time.as_secs_f64() > T0.as_secs_f64() + duration.as_secs_f64() + 0.7)
        .map(|plan| StrikeMiss::of(&r.path, plan, &lim).best_mm)
        .collect::<Vec<_>>();
    assert!(hit.len() >= 10 && hit.iter().all(|&m| m < 2.0), "{hit:?}");
    assert_eq!(p.session.arm_mode(), ArmMode::Playing);
    assert_eq!(p.session.stats().ways_home, 1);
}

#[test]
fn an_rsi_restart_takes_the_arm_where_it_stands_again() {
    let mut p = Pair::new(session(), controller(), Faults::default(), 11, T0);
    assert_eq!(p.run(100), 100);
    assert!(p.take_events().contains(&SessionEvent::Home), "home at once");
    // The controller restarts RSI where a KRL program left the arm.
    let mut c = standing_off_home([-15.0, 8.0, 10.0, 0.0, 10.0, -20.0]);
    c.first_ipoc = 50_000_000;
    let start = c.start;
    p.restart(Duration::from_millis(500), c);
    assert_eq!(p.run(1500), 1500);
    let events = p.take_events();
    assert!(events.iter().any(|e| matches!(e, SessionEvent::Started { off_home: true, .. })));
    assert!(events.iter().any(|e| matches!(e, SessionEvent::GoingHome { .. })));
    assert!(events.contains(&SessionEvent::Home));
    let r = p.result();
    assert!(r.stopped.is_none());
    let (dp, _) = largest_steps(&r.path[100..], start);
    assert!(dp <= 0.8 * 1.001, "{dp}");
    let end = r.path.last().unwrap().actual;
    let home = controller().start;
    assert!((0..3).all(|i| (end[i] - home[i]).abs() < 0.05), "{end:?}");
}

#[test]
fn an_unsafe_way_home_holds_with_zero_corrections_said_once() {
    // A1 turned 100° away: the way home swings the bat out of the box and
    // needs a correction past POSCORR.
    let c = standing_off_home([100.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let start = c.start;
    let mut p = Pair::new(session(), c, Faults::default(), 11, T0);
    p.run_strikes(3, 1500);
    let events = p.take_events();
    let refused: Vec<_> = events.iter().filter(|e| matches!(e, SessionEvent::StartRefused { .. })).collect();
    assert_eq!(refused.len(), 1, "said once: {refused:?}");
    let SessionEvent::StartRefused { reason: why, from_mm, .. } = refused[0] else { unreachable!() };
    assert!(*from_mm > 300.0, "names the offset: {from_mm} mm");
    assert!(matches!(why, StartRefused::WayHome(_)), "{why:?}");
    assert!(why.fix().contains("PTP to home in topspin_rsi.src"));
    let r = p.result();
    assert!(r.path.iter().all(|s| s.commanded == start), "nothing moved");
    assert!(r.stopped.is_none());
    assert_eq!(p.session.stats().plans_accepted, 0);
    assert_eq!(p.session.arm_mode(), ArmMode::Held);
}

#[test]
fn brakes_mid_stroke_abandon_the_stroke_and_nothing_jumps_when_they_open() {
    let mut p = Pair::new(session(), controller(), Faults::default(), 11, T0);
    let lim = limits();
    // Strokes until one is under way, then the brakes for 0.5 s.
    let end = T0 + Duration::from_millis(12_000);
    let stream = strike_stream(7, T0, end);
    let mut braked_at = None;
    let mut home_again = None;
    let mut finals = Vec::new();
    for r in stream {
        while p.now() < r.plan.made_at {
            p.step().expect("RSI running");
            if braked_at.is_some() && home_again.is_none() && p.session.arm_mode() == ArmMode::Homing {
                home_again = Some(usize::MAX);
            }
            if home_again == Some(usize::MAX) && p.session.arm_mode() == ArmMode::Playing {
                home_again = Some(p.result().path.len());
            }
            let approaching = p.session.generator().phase() == topspin_core::motion::Phase::Approach;
            if braked_at.is_none() && approaching && p.now() > T0 + Duration::from_millis(2000) {
                let left = p.session.generator().target().unwrap().hit_time - p.now().as_secs_f64();
                if left < 0.25 {
                    p.controller.apply_brakes(125);
                    braked_at = Some(p.result().path.len());
                }
            }
        }
        p.publish(r.plan);
        if r.committed {
            finals.push(r.plan);
        }
    }
    while p.now() < end {
        p.step().expect("RSI running");
    }
    let k0 = braked_at.expect("a stroke was braked");
    let r = p.result();
    assert!(r.stopped.is_none(), "the controller stopped: {:?}", r.stopped.map(|s| s.to_string()));
    let over: Vec<(usize, usize, f64, f64)> = {
        let l = lim.arm.limits;
        let mut v = vec![];
        for k in 2..r.path.len() {
            for i in 0..6 {
                let j = |n: usize| r.path[n].joints[i].to_radians();
                let qd = (j(k) - j(k - 1)) / 0.004;
                let qd0 = (j(k - 1) - j(k - 2)) / 0.004;
                let a = (qd - qd0) / 0.004;
                if qd.abs() > l.speed[i] || a.abs() > l.acceleration[i] {
                    v.push((k, i, qd / l.speed[i], a / l.acceleration[i]));
                }
            }
        }
        v
    };
    assert_eq!(
        r.rates_over,
        0,
        "no axis over its speed or acceleration: nothing jumped (brakes at {k0}: {over:?}, {:?})",
        p.take_events()
            .iter()
            .filter(|e| !matches!(e, SessionEvent::PlanAccepted { .. } | SessionEvent::PhaseChanged(_)))
            .collect::<Vec<_>>()
    );
    assert_eq!(p.controller.braked_cycles, 125);
    let st = *p.session.stats();
    assert_eq!((st.arm_stops, st.strokes_abandoned), (1, 1), "{st:?}");
    let events = p.take_events();
    let stopped = events.iter().position(|e| matches!(e, SessionEvent::ArmStopped { .. })).unwrap();
    assert!(matches!(events[stopped], SessionEvent::ArmStopped { stroke_abandoned: true, .. }));
    assert!(events[stopped..].iter().any(|e| matches!(e, SessionEvent::GoingHome { .. })));
    assert!(events[stopped..].contains(&SessionEvent::Home));
    // From the brakes until the arm is home again, the actual TCP never
    // moves faster than the commissioning speed after they open.
    let home = home_again.expect("home again");
    assert!(home > k0 + 125 && home < r.path.len(), "{home}");
    let after = &r.path[k0 + 125..home];
    let mut worst = 0.0f64;
    for w in after.windows(2) {
        worst = worst.max(pose(&w[1].actual).distance(&pose(&w[0].actual)).0 * 1e3);
    }
    assert!(worst <= 1.0, "a step of {worst:.2} mm after the brakes opened");
    // The session goes on: the balls whose plans began after it was home
    // again are met as in the same run without the brakes.
    let mut calm = Pair::new(session(), controller(), Faults::default(), 11, T0);
    calm.run_strikes(7, 3000);
    let calm = calm.result();
    let later: Vec<(f64, f64)> = finals
        .iter()
        .filter(|f| f.hit_time.as_secs_f64() - 0.6 > r.path[home].t.as_secs_f64())
        .map(|f| (StrikeMiss::of(&r.path, f, &lim).best_mm, StrikeMiss::of(&calm.path, f, &lim).best_mm))
        .collect();
    assert!(later.len() >= 4 && later.iter().all(|&(m, c)| m < c + 0.5), "{later:?}");
    assert!(later.iter().filter(|&&(m, _)| m < 2.0).count() >= 4, "{later:?}");
}

#[test]
fn the_arm_follows_the_servo_model_through_strokes() {
    // No fault: the follow check never fires, and its largest error is
    // small against its tolerance (15 mm).
    let mut p = Pair::new(session(), controller(), Faults::default(), 11, T0);
    p.run_strikes(2, 5000);
    assert_eq!(p.session.stats().arm_stops, 0);
    let e = p.session.follow_monitor().max_error_m * 1e3;
    assert!(e < 3.0, "largest error {e:.2} mm");
}

#[test]
fn another_tool_or_base_is_refused_at_the_first_request() {
    // TOOL_DATA 30 mm longer than calib/robot.toml's bat.
    let mut c = standing_off_home([0.0, 0.0, 0.0, 15.0, -10.0, 0.0]);
    c.arm.geometry.tool.position.z += 0.03;
    let q = c.start_joints;
    c.stand_at(q);
    let start = c.start;
    let mut p = Pair::new(session(), c, Faults::default(), 11, T0);
    assert_eq!(p.run(50), 50);
    let events = p.take_events();
    let Some(SessionEvent::StartRefused { reason: StartRefused::Frames(m), .. }) =
        events.iter().find(|e| matches!(e, SessionEvent::StartRefused { .. })).copied()
    else {
        panic!("not refused: {events:?}")
    };
    assert!((m.mm - 30.0).abs() < 0.1, "{m:?}");
    assert_eq!(m.likely, LikelyFrame::Tool);
    assert!(p.result().path.iter().all(|s| s.commanded == start));
    // BASE_DATA turned 2° about z.
    let mut c = controller();
    c.base = Pose::from_xyz_abc([0.0; 3], [2f64.to_radians(), 0.0, 0.0]);
    let q = c.start_joints;
    c.stand_at(q);
    let mut p = Pair::new(session(), c, Faults::default(), 11, T0);
    assert_eq!(p.run(10), 10);
    let Some(SessionEvent::StartRefused { reason: StartRefused::Frames(m), .. }) =
        p.take_events().iter().find(|e| matches!(e, SessionEvent::StartRefused { .. })).copied()
    else {
        panic!("not refused")
    };
    assert!((m.deg - 2.0).abs() < 0.01, "{m:?}");
    assert_eq!(m.likely, LikelyFrame::Base);
    assert!(m.to_string().contains("BASE_DATA"), "{m}");
}
