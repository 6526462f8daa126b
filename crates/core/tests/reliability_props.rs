//! Property tests of the reliability invariants (the rest are listed in
//! RELIABILITY.md): the safety filter alone under any request sequence, and
//! the RSI session under a hostile controller (jittered arrivals, IPOC
//! gaps, repeats and steps back) with hostile plans.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use proptest::prelude::*;
use topspin_core::calib::Calibration;
use topspin_core::geometry::EulerZyx;
use topspin_core::geometry::Pose6;
use topspin_core::motion::MotionLimits;
use topspin_core::motion::SafetyFilter;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::rsi::{MAX_ANSWER_LEN, RsiSession, SessionConfig};
use topspin_core::time::Instant;

fn hostile() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -3.0f64..3.0,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => -1e300f64..1e300,
    ]
}

fn limits() -> MotionLimits {
    MotionLimits::from_robot(&Calibration::default_cell().robot)
}

/// Checks one step of `p` after `prev` (velocity `v_prev`) against the box,
/// the velocity and the acceleration limits; returns the new velocity.
fn check_step(lim: &MotionLimits, prev: &Pose6, v_prev: &Pose6, p: &Pose6) -> Result<Pose6, TestCaseError> {
    let mut v = [0.0; 6];
    for i in 0..6 {
        prop_assert!(p[i].is_finite(), "axis {} not finite", i);
        prop_assert!(p[i] >= lim.lo[i] - 1e-9 && p[i] <= lim.hi[i] + 1e-9, "axis {} at {} outside the box", i, p[i]);
        v[i] = (p[i] - prev[i]) / lim.dt;
        prop_assert!(v[i].abs() <= lim.vmax[i] * (1.0 + 1e-9) + 1e-9, "axis {} velocity {}", i, v[i]);
        let a = (v[i] - v_prev[i]) / lim.dt;
        prop_assert!(a.abs() <= lim.amax[i] * (1.0 + 1e-6) + 1e-6, "axis {} acceleration {}", i, a);
    }
    Ok(v)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// Whatever it is asked (far outside the box, NaN, ±∞, jumps), the
    /// filter's output stays in the box with bounded velocity and
    /// acceleration, from any start inside the box.
    #[test]
    fn safety_filter_never_exceeds_a_limit(
        start in prop::array::uniform6(0.0f64..1.0),
        requests in prop::collection::vec(prop::array::uniform6(hostile()), 1..300),
    ) {
        let lim = limits();
        let start: Pose6 = std::array::from_fn(|i| lim.lo[i] + start[i] * (lim.hi[i] - lim.lo[i]));
        let mut f = SafetyFilter::new(&lim, start);
        let (mut prev, mut v) = (start, [0.0; 6]);
        for r in &requests {
            // Scale the finite part of a request to the box's size around its centre.
            let desired: Pose6 = std::array::from_fn(|i| 0.5 * (lim.lo[i] + lim.hi[i]) + r[i] * (lim.hi[i] - lim.lo[i]));
            let (p, _) = f.filter(&desired);
            v = check_step(&lim, &prev, &v, &p)?;
            prev = p;
        }
    }

    /// A controller that jitters (0–20 ms between requests), skips,
    /// repeats and steps its IPOC back, with hostile plans: every request
    /// is answered with its IPOC and every command stays within the box,
    /// velocity and acceleration limits.
    #[test]
    fn session_commands_stay_in_limits_under_a_hostile_controller(
        steps in prop::collection::vec((0u64..20_000_000, prop_oneof![6 => Just(4i64), 1 => Just(0i64), 1 => Just(8i64), 1 => Just(-4i64), 1 => Just(400i64)]), 50..400),
        plans in prop::collection::vec((hostile(), hostile(), hostile(), hostile(), -1.0f64..1.0, -0.2f64..1.0), 1..8),
    ) {
        let cal = Calibration::default_cell();
        let lim = MotionLimits::from_robot(&cal.robot);
        let mut cfg = SessionConfig::from_calibration(&cal, "ImFree");
        // The controller's arm stands at home whatever is planned: the
        // follow check runs but does not stop the strokes under test.
        (cfg.start.follow_tolerance_mm, cfg.start.follow_tolerance_deg) = (1e9, 1e9);
        let mut s = RsiSession::new(cfg).unwrap();
        let mut out = [0u8; MAX_ANSWER_LEN];
        let mut rob_buf = [0u8; 1024];
        let start = [350.0, 0.0, 450.0, 180.0, 0.0, 0.0];
        let (mut now, mut ipoc) = (Instant(1_000_000_000), 100_000i64);
        let mut prev: Option<Pose6> = None;
        let mut v = [0.0; 6];
        let mut plans = plans.into_iter();
        for (k, (gap_ns, dipoc)) in steps.into_iter().enumerate() {
            now = Instant(now.0 + gap_ns);
            ipoc = (ipoc + dipoc).max(1);
            if k % 40 == 5 && let Some((x, y, z, vx, b, dt_hit)) = plans.next() {
                let hit = now.as_secs_f64() + dt_hit;
                s.set_plan(StrikePlan {
                    seq: k as u32, trajectory: k as u32, made_at: now,
                    hit_time: Instant::from_secs_f64(hit.max(0.0)),
                    position: Vec3::new(1.6 + x * 0.2, y * 0.3, 0.3 + z * 0.1),
                    velocity: Vec3::new(vx, 0.0, 0.0),
                    orientation: EulerZyx { a: 0.0, b, c: 0.0 },
                    spin: Vec3::zeros(), confidence: 1.0,
                });
            }
            let frame = RobFrame {
                ipoc: ipoc as u64,
                rist: Some(KukaPose::from_array(start)),
                aipos: Some(lim.home_joints.degrees()),
                ..Default::default()
            };
            let n = frame.emit(&[RobElement::RIst, RobElement::AIPos], 4, &mut rob_buf).unwrap();
            let len = s.handle_datagram(now, &rob_buf[..n], &mut out).unwrap();
            prop_assert_eq!(SenFrame::parse(&out[..len]).unwrap().ipoc, ipoc as u64);
            if dipoc == 0 && k > 0 {
                // A repeated IPOC: answered, but the robot did not advance,
                // so neither does the filter.
                continue;
            }
            // The filter starts at rest at the pose the first request reports.
            let p = *prev.get_or_insert_with(|| s.start_pose());
            let c = s.last_command();
            v = check_step(&lim, &p, &v, &c)?;
            prev = Some(c);
        }
    }
}
