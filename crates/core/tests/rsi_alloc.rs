//! The per-cycle path (parse, plan, generate, filter, emit) allocates
//! nothing after construction, in both correction modes (axis: also our
//! inverse kinematics per cycle), nor in any arm mode (the way home, a
//! stop, the way home again): a counting allocator proves it.

use topspin_core::calib::Calibration;
use topspin_core::geometry::EulerZyx;
use topspin_core::motion::MotionLimits;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{Correction, MAX_ANSWER_LEN, RsiSession, SessionConfig};
use topspin_core::rsi::{KukaPose, RobElement, RobFrame};
use topspin_core::time::Instant;

#[path = "alloc_counter/mod.rs"]
mod alloc_counter;

#[global_allocator]
static GLOBAL: alloc_counter::Counting = alloc_counter::Counting;

#[test]
fn the_cycle_path_does_not_allocate() {
    for c in Correction::ALL {
        cycles_do_not_allocate(c);
    }
}

fn cycles_do_not_allocate(correction: Correction) {
    let cal = Calibration::default_cell();
    let mut cfg = SessionConfig::from_calibration(&cal, "ImFree");
    cfg.correction = correction;
    // This controller's arm stands at home while strokes are planned: the
    // follow check runs every cycle but does not stop them.
    cfg.start.follow_tolerance_mm = 1e9;
    cfg.start.follow_tolerance_deg = 1e9;
    let mut s = RsiSession::new(cfg).unwrap();
    let home_joints = MotionLimits::from_robot(&cal.robot).home_joints.degrees();
    let mut req = [0u8; 1024];
    let mut out = [0u8; MAX_ANSWER_LEN];
    let all = [RobElement::RIst, RobElement::RSol, RobElement::AIPos, RobElement::ASPos, RobElement::Delay];
    let home = KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0]);
    let plan = |seq: u32, now: Instant| StrikePlan {
        seq,
        trajectory: 1,
        made_at: now,
        hit_time: Instant(1_500_000_000),
        position: Vec3::new(1.6, 0.2 + seq as f64 * 1e-4, 0.3),
        velocity: Vec3::new(-1.0, 0.0, 0.1),
        orientation: EulerZyx { a: 0.1, b: 0.3, c: 0.0 },
        spin: Vec3::zeros(),
        confidence: 1.0,
    };
    // Warm up: first request, one plan (Ruckig sizes its buffers once).
    let mut cycle = |k: u64, s: &mut RsiSession| {
        let now = Instant(1_000_000_000 + k * 4_000_000);
        let n = RobFrame {
            ipoc: 100 + 4 * k,
            rist: Some(home),
            rsol: Some(home),
            aipos: Some(home_joints),
            aspos: Some(home_joints),
            delay: Some(0),
        }
        .emit(&all, 4, &mut req)
        .unwrap();
        if k.is_multiple_of(2) {
            s.set_plan(plan(k as u32, now));
        }
        s.handle_datagram(now, &req[..n], &mut out).unwrap();
        while s.poll_event().is_some() {}
    };
    for k in 0..5 {
        cycle(k, &mut s);
    }
    let mut moved = 0.0f64;
    let ((), allocations) = alloc_counter::count_on_this_thread(|| {
        for k in 5..400 {
            cycle(k, &mut s);
            moved = s.last_axis_correction().iter().fold(moved, |m, a| m.max(a.abs()));
        }
    });
    assert_eq!(allocations, 0, "{correction}: allocations or reallocations in 395 cycles");
    assert_eq!((s.stats().answers, s.stats().arm_stops), (400, 0));
    if correction == Correction::Axis {
        assert_eq!(s.stats().axis_held, 0);
        assert!(moved > 1.0, "the stroke moved the axes ({moved}°)");
    }
}

#[test]
fn every_arm_mode_does_not_allocate() {
    // An arm that starts off home and follows as the servo model says (its
    // pose is the model's prediction), braked for 150 cycles mid-run: the
    // way home, the strokes, the stop and the way home again, with no
    // allocation after the first request.
    let cal = Calibration::default_cell();
    let lim = MotionLimits::from_robot(&cal.robot);
    let arm = lim.arm;
    let mut s = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
    let mut q = lim.home_joints;
    q.0[0] += 0.2;
    q.0[4] -= 0.2;
    let mut req = [0u8; 1024];
    let mut out = [0u8; MAX_ANSWER_LEN];
    let kuka = |q: &topspin_core::kinematics::Joints| KukaPose::from_pose(&arm.tcp(q));
    let mut braked = None;
    let mut cycle = |k: u64, s: &mut RsiSession| {
        let now = Instant(1_000_000_000 + k * 4_000_000);
        let stands = if (1200..1350).contains(&k) {
            *braked.get_or_insert(s.follow_monitor().predicted())
        } else {
            braked = None;
            if k == 0 { q } else { s.follow_monitor().predicted() }
        };
        let n = RobFrame {
            ipoc: 100 + 4 * k,
            rist: Some(kuka(&stands)),
            aipos: Some(stands.degrees()),
            ..RobFrame::default()
        }
        .emit(&[RobElement::RIst, RobElement::AIPos], 4, &mut req)
        .unwrap();
        if k.is_multiple_of(3) {
            let hit = Instant(1_000_000_000 + ((k / 150) * 150 + 140) * 4_000_000);
            s.set_plan(StrikePlan {
                seq: k as u32,
                trajectory: (k / 150) as u32,
                made_at: now,
                hit_time: hit,
                position: Vec3::new(1.6, 0.1, 0.3),
                velocity: Vec3::new(-1.0, 0.0, 0.1),
                orientation: EulerZyx { a: 0.1, b: 0.2, c: 0.0 },
                spin: Vec3::zeros(),
                confidence: 1.0,
            });
        }
        s.handle_datagram(now, &req[..n], &mut out).unwrap();
        while s.poll_event().is_some() {}
    };
    cycle(0, &mut s);
    let ((), allocations) = alloc_counter::count_on_this_thread(|| {
        for k in 1..2500 {
            cycle(k, &mut s);
        }
    });
    assert_eq!(allocations, 0, "allocations or reallocations in 2 499 cycles");
    let st = s.stats();
    assert_eq!(st.ways_home, 2, "{st:?}");
    assert_eq!(st.arm_stops, 1, "{st:?}");
    assert!(st.plans_accepted > 100, "{st:?}");
}
