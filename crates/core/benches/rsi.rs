//! RSI per-cycle cost: parse + plan + emit (DESIGN §9: answer p99.9 < 100 µs),
//! with the Cartesian correction (RKorr) and the axis correction (AKorr: our
//! inverse kinematics each cycle) side by side.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use topspin_core::calib::Calibration;
use topspin_core::geometry::EulerZyx;
use topspin_core::motion::MotionLimits;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{Correction, MAX_ANSWER_LEN, RsiSession, SessionConfig};
use topspin_core::rsi::{KukaPose, RobElement, RobFrame, SenFrame};
use topspin_core::time::Instant;

/// A request at home; `q`: the home joints (AIPos, ASPos), degrees.
fn request(ipoc: u64, q: [f64; 6], buf: &mut [u8]) -> usize {
    let home = KukaPose::from_array([350.0, 0.0, 450.0, 180.0, 0.0, 0.0]);
    let all = [RobElement::RIst, RobElement::RSol, RobElement::AIPos, RobElement::ASPos, RobElement::Delay];
    RobFrame { ipoc, rist: Some(home), rsol: Some(home), aipos: Some(q), aspos: Some(q), delay: Some(0) }
        .emit(&all, 4, buf)
        .unwrap()
}

fn bench(c: &mut Criterion) {
    let mut req = [0u8; 1024];
    let q = MotionLimits::from_robot(&Calibration::default_cell().robot).home_joints.degrees();
    let n = request(4208831, q, &mut req);
    let mut out = [0u8; MAX_ANSWER_LEN];
    c.bench_function("rsi/parse_rob", |b| b.iter(|| RobFrame::parse(black_box(&req[..n])).unwrap()));
    c.bench_function("rsi/emit_sen", |b| {
        b.iter(|| {
            SenFrame {
                sentype: "ImFree",
                estr: None,
                rkorr: Some(KukaPose::from_array([12.3, -3.2, 40.0, 0.0, 28.0, 0.0])),
                akorr: None,
                ipoc: 4208831,
            }
            .emit(4, black_box(&mut out))
            .unwrap()
        })
    });
    let cal = Calibration::default_cell();
    for correction in Correction::ALL {
        cycles(c, &cal, correction, q, &mut req, &mut out);
    }
}

/// `rsi/cycle_*` (Cartesian) or `rsi/axis_cycle_*` (axis).
fn cycles(c: &mut Criterion, cal: &Calibration, correction: Correction, q: [f64; 6], req: &mut [u8], out: &mut [u8]) {
    let prefix = match correction {
        Correction::Cartesian => "rsi/cycle",
        Correction::Axis => "rsi/axis_cycle",
    };
    let mk = || {
        let mut cfg = SessionConfig::from_calibration(cal, "ImFree");
        cfg.correction = correction;
        // The bench's controller stands still while strokes are planned:
        // the follow check runs every cycle (its cost is in the figures)
        // but never stops the strokes.
        cfg.start.follow_tolerance_mm = 1e9;
        cfg.start.follow_tolerance_deg = 1e9;
        RsiSession::new(cfg).unwrap()
    };
    // `turn`: the face's tilt alternates by 29° from plan to plan, so that
    // near the hit every refinement is late and taken in part (the
    // generator's costliest path: a search over shares of the turn).
    let plan = |seq: u32, now: Instant, hit: Instant, turn: bool| StrikePlan {
        seq,
        trajectory: 1,
        made_at: now,
        hit_time: hit,
        position: Vec3::new(1.6, 0.2 + (seq % 7) as f64 * 1e-3, 0.3),
        velocity: Vec3::new(-1.0, 0.0, 0.1),
        orientation: EulerZyx { a: 0.1, b: 0.3 + if turn { (seq % 2) as f64 * 0.5 } else { 0.0 }, c: 0.0 },
        spin: Vec3::zeros(),
        confidence: 1.0,
    };
    // Cycle without a new plan (sampling the stroke).
    let mut s = mk();
    let mut k = 0u64;
    c.bench_function(&format!("{prefix}_sample"), |b| {
        b.iter(|| {
            k += 1;
            let now = Instant(1_000_000_000 + k * 4_000_000);
            let n = request(100 + 4 * k, q, req);
            s.handle_datagram(now, &req[..n], out).unwrap()
        })
    });
    // Cycle with a new plan every cycle (Ruckig re-plan each time); a new
    // stroke every 100 cycles so the hit stays ahead.
    for (name, turn) in [("replan", false), ("replan_turn", true)] {
        let mut s = mk();
        let mut k = 0u64;
        c.bench_function(&format!("{prefix}_{name}"), |b| {
            b.iter(|| {
                k += 1;
                let now = Instant(1_000_000_000 + k * 4_000_000);
                let hit = Instant(1_000_000_000 + ((k / 100) * 100 + 150) * 4_000_000);
                s.set_plan(plan(k as u32, now, hit, turn));
                let n = request(100 + 4 * k, q, req);
                s.handle_datagram(now, &req[..n], out).unwrap()
            })
        });
        assert_eq!(s.stats().axis_held, 0, "{correction}: every cycle sent");
        assert_eq!(s.stats().arm_stops, 0, "{correction}: the strokes were planned");
        assert_eq!(s.generator().taken_in_part > 0, turn, "{correction} {name}: late turns taken in part");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
