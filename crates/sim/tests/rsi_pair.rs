//! The RSI session against the mock KR C4 on a virtual clock
//! ([`topspin_sim::pair::Pair`]): what `crates/sim/tests/rsi_loopback.rs`
//! and `crates/sim/tests/rsi_faults.rs` check over UDP on the wall clock, here exact
//! and deterministic — no tolerance for a machine's scheduling noise, no
//! sleeps. 10 000 cycles of strikes with every answer on time and the bat
//! at each hitting pose at its hitting time; delayed, dropped, duplicated
//! answers and reordered requests counted exactly; an RSI restart (also
//! with the robot off home); 12 ms cycles, also under a 4 ms session. The
//! axis correction (AKorr into AXISCORR) against the axis context: the
//! strokes land as in Cartesian mode, within the joint limits; a controller
//! stopped mid-stroke by AXISCORRMON is survived; a session sending the
//! other correction is held, not obeyed.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use topspin_core::calib::Calibration;
use topspin_core::motion::MotionLimits;
use topspin_core::rsi::{Correction, RsiSession, SessionConfig, SessionEvent};
use topspin_core::time::{Duration, Instant};
use topspin_sim::mock_krc::ControllerConfig;
use topspin_sim::mock_krc::{Faults, MockKrcConfig, MockResult, StopReason};
use topspin_sim::pair::Pair;
use topspin_sim::strikes::{StrikeMiss, strike_stream};

const T0: Instant = Instant(1_000_000_000);

fn controller(cycle_ms: u32) -> ControllerConfig {
    let mut c = MockKrcConfig::default_cell().unwrap().controller;
    c.cycle_ms = cycle_ms;
    c
}

fn session(cycle_ms: u32) -> RsiSession {
    let mut cfg = SessionConfig::from_calibration(&Calibration::default_cell(), "ImFree");
    cfg.cycle_ms = cycle_ms;
    RsiSession::new(cfg).unwrap()
}

fn pair(session_ms: u32, controller_ms: u32, faults: Faults, late_limit: u64) -> Pair {
    let mut c = controller(controller_ms);
    c.late_limit = late_limit;
    Pair::new(session(session_ms), c, faults, 11, T0)
}

/// Nothing the sensor answered drove the robot past a limit.
fn within_limits(r: &MockResult) {
    assert_eq!(r.poscorr_clamped, 0, "{r:?}");
    assert!(r.stopped.is_none(), "the controller stopped: {:?}", r.stopped.map(|s| s.to_string()));
    assert_eq!(r.rates_over, 0, "an axis ran over its speed or acceleration");
    assert!(!r.stopped_by_monitor && !r.stopped_by_limit);
}

/// The commanded path within the cell's limits, cycle by cycle (path in
/// mm / deg, limits in m / rad).
fn path_within(r: &MockResult, lim: &MotionLimits, start: [f64; 6], dt: f64) {
    let scale = |i: usize| if i < 3 { 1e3 } else { 180.0 / std::f64::consts::PI };
    let mut v_prev = [0.0; 6];
    for (k, s) in r.path.iter().enumerate() {
        for i in 0..6 {
            let x = s.commanded[i] / scale(i);
            assert!(x >= lim.lo[i] - 1e-9 && x <= lim.hi[i] + 1e-9, "cycle {k} axis {i}: {x}");
            let prev = if k == 0 { start[i] } else { r.path[k - 1].commanded[i] };
            let v = (s.commanded[i] - prev) / dt / scale(i);
            assert!(v.abs() <= lim.vmax[i] * 1.001, "cycle {k} axis {i}: v {v}");
            let a = (v - v_prev[i]) / dt;
            assert!(a.abs() <= lim.amax[i] * 1.001 + 0.05, "cycle {k} axis {i}: a {a}");
            v_prev[i] = v;
        }
    }
}

#[test]
fn ten_thousand_cycles_of_strikes() {
    let cal = Calibration::default_cell();
    let lim = MotionLimits::from_robot(&cal.robot);
    let mut p = pair(4, 4, Faults::default(), 100);
    let n = 10_000u64;
    let finals = p.run_strikes(4, n);
    let r = p.result();
    let st = *p.session.stats();

    assert_eq!(r.cycles, n);
    assert_eq!(r.late, 0, "every answer on time");
    assert_eq!((r.wrong_ipoc, r.malformed, r.wrong_type), (0, 0, 0), "IPOC and type echoed");
    assert_eq!((st.requests, st.answers), (n, n), "every request answered");
    assert_eq!((st.ipoc_gaps, st.ipoc_repeats, st.plans_rejected, st.slow_answers), (0, 0, 0, 0));
    assert_eq!(st.max_latency, p.timing.processing);
    within_limits(&r);
    path_within(&r, &lim, controller(4).start, 0.004);

    // The bat at each hitting pose at its hitting time.
    assert_eq!(finals.len(), 39, "strikes");
    for plan in &finals {
        let StrikeMiss { best_mm: best, rot_deg: rot, .. } = StrikeMiss::of(&r.path, plan, &lim);
        assert!(best < 2.0, "strike {}: {best:.3} mm from the hitting point within ±2 ms", plan.trajectory);
        assert!(rot < 0.5, "strike {}: orientation off by {rot:.3}°", plan.trajectory);
    }
}

#[test]
fn the_same_inputs_make_the_same_path() {
    let run = || {
        let mut p = pair(4, 4, Faults { drop: 0.05, duplicate: 0.05, reorder: 0.02, ..Faults::default() }, 1000);
        p.run(500);
        p.result()
    };
    assert_eq!(run(), run());
}

#[test]
fn delayed_answers_are_late_and_stop_rsi_at_the_limit() {
    let mut p = pair(4, 4, Faults { delay: 1.0, delay_by: Duration::from_millis(6), ..Faults::default() }, 20);
    assert_eq!(p.run(500), 20);
    let r = p.result();
    assert!(r.stopped_by_limit);
    assert_eq!((r.cycles, r.late, r.delayed), (20, 20, 20));
    // Each delayed answer arrives in the next cycle and is refused there.
    assert_eq!(r.wrong_ipoc, 19);
    assert!(p.step().is_none(), "a stopped RSI sends nothing");
}

#[test]
fn dropped_and_duplicated_answers_are_counted_not_fatal() {
    let mut p = pair(4, 4, Faults { drop: 0.1, duplicate: 0.2, ..Faults::default() }, 1000);
    assert_eq!(p.run(150), 150);
    let r = p.result();
    assert!(!r.stopped_by_limit);
    assert!(r.dropped > 0 && r.duplicated > 0, "{r:?}");
    // Every dropped answer is a late cycle, and nothing else is.
    assert_eq!(r.late, r.dropped);
    // A duplicate is the cycle's second answer: offered after the
    // accepted one, it waits and is refused next cycle as stale.
    assert_eq!(r.wrong_ipoc, r.duplicated);
    assert_eq!(p.session.stats().answers, 150);
}

#[test]
fn reordered_requests_are_answered_and_survived() {
    let mut p = pair(4, 4, Faults { reorder: 0.05, ..Faults::default() }, 1000);
    assert_eq!(p.run(400), 400);
    let r = p.result();
    let st = *p.session.stats();
    assert!(r.reordered > 0);
    // A held request is answered a cycle late: exactly one late cycle each.
    assert_eq!(r.late, r.reordered);
    assert_eq!(st.answers + st.malformed, st.requests, "every request that arrived answered");
    assert_eq!(st.requests, 400, "the last request may still be held");
    assert_eq!(r.poscorr_clamped, 0);
    assert!(!r.stopped_by_monitor);
    let events = p.take_events();
    assert_eq!(
        events.iter().filter(|e| matches!(e, SessionEvent::IpocBackwards { .. })).count() as u64,
        r.reordered,
        "the session saw each held request arrive behind the next"
    );
}

#[test]
fn rsi_stopped_and_restarted_resumes() {
    let mut p = pair(4, 4, Faults::default(), 100);
    assert_eq!(p.run(150), 150);
    let first = p.result();
    // The controller restarts RSI a second later: a fresh run, IPOC far ahead.
    let mut c = controller(4);
    c.first_ipoc = 10_000_000;
    p.restart(Duration::from_millis(1000), c);
    assert!(p.take_events().iter().any(|e| matches!(e, SessionEvent::RobotSilent)), "silence noticed");
    assert_eq!(p.run(150), 150);
    let second = p.result();
    within_limits(&first);
    within_limits(&second);
    assert_eq!((first.late, second.late), (0, 0));
    let st = p.session.stats();
    assert_eq!((st.requests, st.answers), (300, 300));
}

#[test]
fn rsi_restarted_with_the_robot_off_home_brings_it_home_within_limits() {
    // After a crash mid-stroke the controller restarts RSI where the robot
    // stopped: the session starts from that pose and brings the bat home.
    let home = controller(4).start;
    let mut start = home;
    start[0] += 60.0;
    start[2] -= 40.0;
    let mut c = controller(4);
    c.start = start;
    let mut p = Pair::new(session(4), c, Faults::default(), 11, T0);
    assert_eq!(p.run(300), 300);
    let r = p.result();
    within_limits(&r);
    assert_eq!(r.late, 0);
    let end = r.path.last().unwrap().actual;
    for i in 0..6 {
        assert!((end[i] - home[i]).abs() < 0.5, "from {start:?} the bat ended at {end:?}, home {home:?}");
    }
}

#[test]
fn twelve_ms_cycle() {
    let mut p = pair(12, 12, Faults::default(), 100);
    assert_eq!(p.run(80), 80);
    let r = p.result();
    within_limits(&r);
    assert_eq!(r.late, 0);
    let st = p.session.stats();
    assert_eq!((st.answers, st.ipoc_gaps), (80, 0));
}

#[test]
fn cycle_changed_to_12_ms_under_a_4_ms_session_is_survived() {
    // The controller runs #IPO (12 ms) while the sensor was configured for
    // #IPO_FAST: every IPOC step is a gap to the session, every request is
    // still answered, and the robot is never driven past its limits.
    let mut p = pair(4, 12, Faults::default(), 100);
    assert_eq!(p.run(80), 80);
    let r = p.result();
    within_limits(&r);
    let st = p.session.stats();
    assert_eq!(st.answers, 80);
    assert_eq!(st.ipoc_gaps, 79, "every step after the first");
}

fn axis_pair(session_correction: Correction) -> Pair {
    let mut cfg = SessionConfig::from_calibration(&Calibration::default_cell(), "ImFree");
    cfg.correction = session_correction;
    let c = MockKrcConfig::default_cell_for(Correction::Axis).unwrap().controller;
    Pair::new(RsiSession::new(cfg).unwrap(), c, Faults::default(), 11, T0)
}

#[test]
fn axis_correction_lands_the_strokes_as_the_cartesian_one() {
    let cal = Calibration::default_cell();
    let lim = MotionLimits::from_robot(&cal.robot);
    let n = 5_000u64;
    let mut cart = pair(4, 4, Faults::default(), 100);
    let cart_finals = cart.run_strikes(4, n);
    let mut axis = axis_pair(Correction::Axis);
    let finals = axis.run_strikes(4, n);
    assert_eq!(finals, cart_finals);
    assert_eq!(finals.len(), 19, "strikes");
    let (rc, r) = (cart.result(), axis.result());
    let st = *axis.session.stats();
    assert_eq!(r.cycles, n);
    assert_eq!((r.late, r.wrong_ipoc, r.wrong_type, r.wrong_kind, r.malformed), (0, 0, 0, 0, 0));
    assert_eq!((st.requests, st.answers, st.plans_rejected, st.axis_held), (n, n, 0, 0));
    assert_eq!(r.axiscorr_clamped, 0, "AXISCORR never had to clamp");
    within_limits(&r);
    path_within(&r, &lim, controller(4).start, 0.004);
    // The joints stayed within the software limit switches, off the wrist
    // singularity, every cycle.
    for (k, s) in r.path.iter().enumerate() {
        let q = topspin_core::kinematics::Joints::from_degrees(s.joints);
        lim.arm.limits.check_position(&q).unwrap_or_else(|v| panic!("cycle {k}: {v}"));
    }
    // Each stroke lands where the Cartesian one does, to a few µm (the
    // corrections differ only by their rounding to 4 decimals of mm or of
    // a degree).
    let mut worst = 0.0f64;
    for plan in &finals {
        let a = StrikeMiss::of(&r.path, plan, &lim);
        let c = StrikeMiss::of(&rc.path, plan, &lim);
        assert!(a.best_mm < 2.0, "strike {}: {:.3} mm from the hitting point within ±2 ms", plan.trajectory, a.best_mm);
        assert!(a.rot_deg < 0.5, "strike {}: orientation off by {:.3}°", plan.trajectory, a.rot_deg);
        worst = worst.max((a.at_hit_mm - c.at_hit_mm).abs());
    }
    assert!(worst < 0.01, "axis vs Cartesian at the hit time: {worst:.4} mm");
    // And the whole path, cycle by cycle.
    let dev =
        r.path.iter().zip(&rc.path).map(|(a, c)| (0..3).map(|i| (a.actual[i] - c.actual[i]).abs()).fold(0.0, f64::max));
    let dev = dev.fold(0.0f64, f64::max);
    eprintln!("axis vs Cartesian: {worst:.4} mm at the hit times, {dev:.4} mm along the path");
    assert!(dev < 0.01, "axis vs Cartesian path: {dev:.4} mm");
}

#[test]
fn a_controller_stopped_mid_stroke_by_axiscorrmon_is_survived() {
    // AXISCORRMON at 3° on every axis: the first stroke trips it.
    let mut p = axis_pair(Correction::Axis);
    let mut c = MockKrcConfig::default_cell_for(Correction::Axis).unwrap().controller;
    c.axis_mon_max_deg = [3.0; 6];
    p.restart(Duration::from_millis(0), c);
    let end = T0 + Duration::from_millis(2_000);
    for r in strike_stream(4, T0, end) {
        while p.now() < r.plan.made_at {
            if p.step().is_none() {
                break;
            }
        }
        p.publish(r.plan);
    }
    let r = p.result();
    let Some(StopReason::AxisMonitor(axis)) = r.stopped else { panic!("not stopped by AXISCORRMON: {:?}", r.stopped) };
    assert_eq!(r.stopped.unwrap().key(), format!("axis_monitor_{}", axis.to_string().to_lowercase()));
    assert!(r.cycles > 100 && r.cycles < 500, "stopped mid-stroke at cycle {}", r.cycles);
    assert_eq!(r.late, 0);
    // The session notices the silence and carries on: a fresh RSI run is
    // answered from the pose the robot stopped in, and brings it home.
    let stopped_at = r.path.last().unwrap().actual;
    let mut c = MockKrcConfig::default_cell_for(Correction::Axis).unwrap().controller;
    c.first_ipoc = 10_000_000;
    c.start = stopped_at;
    c.start_joints = p.controller.joints();
    p.restart(Duration::from_millis(500), c);
    assert!(p.take_events().iter().any(|e| matches!(e, SessionEvent::RobotSilent)), "silence noticed");
    assert_eq!(p.run(400), 400);
    let second = p.result();
    assert_eq!((second.late, second.axiscorr_clamped, second.rates_over), (0, 0, 0));
    assert!(second.stopped.is_none(), "{:?}", second.stopped);
    let home = controller(4).start;
    let end = second.path.last().unwrap().actual;
    assert!((0..3).all(|i| (end[i] - home[i]).abs() < 0.5), "ended at {end:?}, home {home:?}");
    assert_eq!(p.session.stats().axis_held, 0);
}

#[test]
fn the_wrong_kind_of_correction_is_held_not_obeyed() {
    // A Cartesian session against the axis context: every answer on time,
    // none carries AKorr, so the robot holds its start pose (HOLDON) and
    // the controller counts each one.
    let mut p = axis_pair(Correction::Cartesian);
    let mut start = controller(4).start;
    start[0] += 30.0; // off home: the session's RKorr would move it
    let mut c = MockKrcConfig::default_cell_for(Correction::Axis).unwrap().controller;
    c.start = start;
    p.restart(Duration::from_millis(0), c);
    let mut asked = 0.0f64;
    for _ in 0..100 {
        p.step().expect("RSI running");
        asked = asked.max(p.session.last_correction().x.abs());
    }
    let r = p.result();
    assert_eq!((r.late, r.wrong_kind, r.axiscorr_clamped), (0, 100, 0));
    assert!(r.stopped.is_none());
    let moved = r.path.iter().map(|s| (0..3).map(|i| (s.actual[i] - start[i]).abs()).fold(0.0, f64::max));
    assert!(moved.fold(0.0f64, f64::max) < 1e-6, "the robot did not move");
    assert!(asked > 1.0, "the session did ask for a move home ({asked} mm)");
    // … and noticed that the arm does not follow.
    assert!(p.session.stats().arm_stops >= 1);
}
