//! Property tests: codec round trip and panic-freedom, the safety limits
//! under hostile plans, and a session that never crashes on bad bytes.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use proptest::prelude::*;
use topspin_core::calib::Calibration;
use topspin_core::geometry::EulerZyx;
use topspin_core::motion::MotionLimits;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::rsi::{MAX_ANSWER_LEN, RsiSession, SessionConfig};
use topspin_core::time::Instant;

fn pose() -> impl Strategy<Value = [f64; 6]> {
    prop::array::uniform6(-1e5f64..1e5)
}

fn hostile() -> impl Strategy<Value = f64> {
    prop_oneof![-5.0f64..5.0, Just(f64::NAN), Just(f64::INFINITY), Just(-1e300), -1e6f64..1e6,]
}

proptest! {
    #[test]
    fn sen_emit_then_parse(k in pose(), ipoc in any::<u64>(), prec in 0u8..=6) {
        let mut buf = [0u8; 1024];
        let n = SenFrame { sentype: "ImFree", estr: Some("x"), rkorr: Some(KukaPose::from_array(k)), akorr: None, ipoc }
            .emit(prec, &mut buf).unwrap();
        let v = SenFrame::parse(&buf[..n]).unwrap();
        prop_assert_eq!(v.ipoc, ipoc);
        prop_assert_eq!(v.sentype, b"ImFree");
        prop_assert_eq!(v.akorr, None);
        let back = v.rkorr.unwrap().to_array();
        for i in 0..6 {
            prop_assert!((back[i] - k[i]).abs() <= 0.5 * 10f64.powi(-(prec as i32)) + 1e-9 * k[i].abs());
        }
        // The same numbers as an axis correction (AKorr A1..A6, degrees).
        let n = SenFrame { sentype: "ImFree", estr: None, rkorr: None, akorr: Some(k), ipoc }
            .emit(prec, &mut buf).unwrap();
        let v = SenFrame::parse(&buf[..n]).unwrap();
        prop_assert_eq!((v.ipoc, v.rkorr), (ipoc, None));
        let back = v.akorr.unwrap();
        for i in 0..6 {
            prop_assert!((back[i] - k[i]).abs() <= 0.5 * 10f64.powi(-(prec as i32)) + 1e-9 * k[i].abs());
        }
    }

    #[test]
    fn rob_emit_then_parse(a in pose(), b in pose(), d in any::<u64>(), ipoc in any::<u64>()) {
        let f = RobFrame { ipoc, rist: Some(KukaPose::from_array(a)), rsol: Some(KukaPose::from_array(b)),
            aipos: Some(a), aspos: None, delay: Some(d) };
        let mut buf = [0u8; 2048];
        let all = [RobElement::Delay, RobElement::RIst, RobElement::RSol, RobElement::AIPos, RobElement::ASPos];
        let n = f.emit(&all, 4, &mut buf).unwrap();
        let g = RobFrame::parse(&buf[..n]).unwrap();
        prop_assert_eq!(g.ipoc, ipoc);
        prop_assert_eq!(g.delay, Some(d));
        prop_assert!(g.aspos.is_none());
        for i in 0..6 {
            prop_assert!((g.rist.unwrap().to_array()[i] - a[i]).abs() <= 5e-5 + 1e-12 * a[i].abs());
        }
    }

    #[test]
    fn parsers_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let _ = RobFrame::parse(&bytes);
        let _ = SenFrame::parse(&bytes);
    }

    #[test]
    fn parsers_never_panic_on_near_rsi(cut in 0usize..200, flip in 0usize..200, c in any::<u8>()) {
        let mut x = br#"<Rob Type="KUKA"><RIst X="1" Y="2" Z="3" A="4" B="5" C="6"/><Delay D="0"/><IPOC>9</IPOC></Rob>"#.to_vec();
        let k = flip % x.len();
        x[k] = c;
        x.truncate(cut.min(x.len()));
        let _ = RobFrame::parse(&x);
        let cal = Calibration::default_cell();
        let mut s = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
        let mut out = [0u8; MAX_ANSWER_LEN];
        let _ = s.handle_datagram(Instant(1), &x, &mut out);
    }
}

fn session_with_robot() -> (RsiSession, MotionLimits, Vec<u8>) {
    let cal = Calibration::default_cell();
    let lim = MotionLimits::from_robot(&cal.robot);
    let mut cfg = SessionConfig::from_calibration(&cal, "ImFree");
    // The controller's arm stands at home whatever is planned: the follow
    // check runs but does not stop the strokes under test.
    (cfg.start.follow_tolerance_mm, cfg.start.follow_tolerance_deg) = (1e9, 1e9);
    let s = RsiSession::new(cfg).unwrap();
    (s, lim, Vec::new())
}

/// A `<Rob>` of the arm standing at `home` (joint angles, degrees).
fn rob(ipoc: u64, home: [f64; 6]) -> Vec<u8> {
    let mut buf = [0u8; 1024];
    let f = RobFrame {
        ipoc,
        rist: Some(KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0])),
        aipos: Some(home),
        ..Default::default()
    };
    let n = f.emit(&[RobElement::RIst, RobElement::AIPos], 4, &mut buf).unwrap();
    buf[..n].to_vec()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Whatever the plans, every correction sent keeps the TCP in the box,
    /// within the per-cycle step (velocity) and step-change (acceleration)
    /// limits; every request is answered with its IPOC.
    #[test]
    fn corrections_never_break_the_limits(
        plans in prop::collection::vec((hostile(), hostile(), hostile(), hostile(), hostile(), hostile(), hostile(), -2.0f64..3.0, 0u32..3), 1..12)
    ) {
        let (mut s, lim, _) = session_with_robot();
        let mut out = [0u8; MAX_ANSWER_LEN];
        let start = [0.350, 0.0, 0.450, std::f64::consts::PI, 0.0, 0.0];
        let dt = lim.dt;
        let mut prev = start;
        let mut v_prev = [0.0; 6];
        let mut plans = plans.into_iter();
        let home = lim.home_joints.degrees();
        for k in 0..400u64 {
            let now = Instant(1_000_000_000 + k * 4_000_000);
            if k.is_multiple_of(25)
                && let Some((x, y, z, vx, vy, vz, b, dt_hit, _)) = plans.next()
            {
                let hit = (now.as_secs_f64() + dt_hit).max(0.0);
                s.set_plan(StrikePlan {
                    seq: k as u32, trajectory: 1, made_at: now,
                    hit_time: Instant::from_secs_f64(hit),
                    position: Vec3::new(1.6 + x * 0.2, y * 0.3, 0.3 + z * 0.1),
                    velocity: Vec3::new(vx, vy, vz),
                    orientation: EulerZyx { a: 0.0, b, c: 0.0 },
                    spin: Vec3::zeros(), confidence: 1.0,
                });
            }
            let ipoc = 1000 + 4 * k;
            let n = s.handle_datagram(now, &rob(ipoc, home), &mut out).unwrap();
            let v = SenFrame::parse(&out[..n]).unwrap();
            prop_assert_eq!(v.ipoc, ipoc);
            let c = s.last_command();
            for i in 0..6 {
                prop_assert!(c[i].is_finite());
                prop_assert!(c[i] >= lim.lo[i] - 1e-9 && c[i] <= lim.hi[i] + 1e-9, "axis {} {}", i, c[i]);
                let vel = (c[i] - prev[i]) / dt;
                prop_assert!(vel.abs() <= lim.vmax[i] * (1.0 + 1e-9) + 1e-9, "axis {} v {}", i, vel);
                prop_assert!(((vel - v_prev[i]) / dt).abs() <= lim.amax[i] * (1.0 + 1e-6) + 1e-6, "axis {} a", i);
                v_prev[i] = vel;
            }
            prev = c;
        }
    }
}
