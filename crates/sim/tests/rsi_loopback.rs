//! The mock KR C4 against the RSI server's UDP shell on loopback and the
//! wall clock, 2 500 cycles (10 s) with a stream of strike plans: every
//! answer on time, IPOC echoed, the TCP path within every limit, the bat at
//! the hitting pose at the hitting time within 2 mm and 2 ms. The same
//! stream runs for 10 000 cycles on the virtual clock, exactly, in
//! `crates/sim/tests/rsi_pair.rs`; this test is for the threads and sockets.
//!
//! "On time" is judged by the mock, as the controller would. Its deadline
//! is one cycle on the robot; here it is stretched to 20 ms by default
//! (`TOPSPIN_TEST_DEADLINE_MS`), because on a loaded shared 2-core machine
//! a preempted thread misses 4 ms now and then — measured: a few per 1 500
//! cycles at load average 4. Even 20 ms is missed once in a few thousand
//! cycles on a busy CI machine (the thread was simply not scheduled; its
//! work per request is microseconds, see the benches). So late answers are
//! allowed up to 0.2% of the cycles, and the few cycles around a late one
//! — where the controller, like the real one, held the last command and
//! its own limiter smoothed the jump — are left out of the limit and
//! accuracy checks; the robot's limiter may act only after a late answer,
//! until the robot has caught up with the commanded path. The answers later than one cycle are printed; the 4 ms
//! budget itself is measured by the benches.
//! The same run in axis mode (`AKorr` from our inverse kinematics against
//! the mock's axis context, AXISCORR), one run after the other.
//! `TOPSPIN_LOOPBACK_CYCLES` shortens the run while debugging;
//! `TOPSPIN_LOOPBACK_CSV=FILE` writes the mock's TCP path.

#![allow(clippy::needless_range_loop)] // parallel per-axis arrays

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use topspin_core::calib::Calibration;
use topspin_core::motion::MotionLimits;
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::{Correction, RsiSession, SessionConfig};
use topspin_core::time::Duration;
use topspin_daemon::clock;
use topspin_daemon::rsi_server::{RsiServer, WaitStrategy, plan_slot};
use topspin_sim::mock_krc::{self, MockKrcConfig};
use topspin_sim::strikes::{StrikeMiss, strike_stream};

fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name).ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}

/// The two runs take turns: each wants the machine to itself.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn ten_thousand_cycles_of_strikes() {
    strikes_over_udp(Correction::Cartesian);
}

#[test]
fn strikes_with_axis_correction() {
    strikes_over_udp(Correction::Axis);
}

fn strikes_over_udp(correction: Correction) {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let cal = Calibration::default_cell();
    let lim = MotionLimits::from_robot(&cal.robot);
    let mut scfg = SessionConfig::from_calibration(&cal, "ImFree");
    scfg.correction = correction;
    let session = RsiSession::new(scfg).unwrap();
    let mut server = RsiServer::bind("127.0.0.1:0".parse().unwrap(), session, WaitStrategy::Blocking).unwrap();
    let addr = server.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let (mut plans, mut reader) = plan_slot();
    let s2 = stop.clone();
    let server_thread = std::thread::spawn(move || {
        server
            .run(&s2, &mut reader, |e| {
                if let topspin_core::rsi::SessionEvent::PlanAccepted { seq, late_by, .. } = e
                    && late_by.0 > 0
                    && std::env::var("DBG").is_ok()
                {
                    eprintln!("plan {seq} late by {late_by:?}");
                }
            })
            .unwrap();
        server.into_session()
    });

    let n = env_u64("TOPSPIN_LOOPBACK_CYCLES", 2_500);
    let mut mcfg = MockKrcConfig::default_cell_for(correction).unwrap();
    mcfg.sensor = addr;
    mcfg.bind = "127.0.0.1:0".parse().unwrap();
    mcfg.cycles = Some(n);
    mcfg.answer_deadline = Duration::from_millis(env_u64("TOPSPIN_TEST_DEADLINE_MS", 20));
    let start = clock::now();
    let mock = mock_krc::spawn(mcfg.clone()).unwrap();

    // The strike stream (`topspin_sim::strikes`), published on the wall clock.
    let end = start + Duration::from_millis(n * 4);
    let mut finals: Vec<StrikePlan> = Vec::new();
    for r in strike_stream(4, start, end) {
        clock::sleep_until(r.plan.made_at, Duration::from_micros(100));
        plans.publish(r.plan);
        if r.committed {
            finals.push(r.plan);
        }
    }
    let r = mock.join().unwrap();
    if let Ok(p) = std::env::var("TOPSPIN_LOOPBACK_CSV") {
        r.write_csv(std::path::Path::new(&p)).unwrap(); // the TCP path, for a look at a failure
    }
    stop.store(true, Ordering::Relaxed);
    let session = server_thread.join().unwrap();
    let st = *session.stats();
    eprintln!(
        "mock: cycles {} late {} after one cycle {} wrong_ipoc {} poscorr_clamped {} rates_over {} max_answer_delay {:?}",
        r.cycles, r.late, r.answers_after_cycle, r.wrong_ipoc, r.poscorr_clamped, r.rates_over, r.max_answer_delay
    );
    eprintln!("session: {st:?}");

    assert_eq!(r.cycles, n);
    assert!(r.late <= n / 500, "{} late answers in {n} cycles", r.late);
    assert_eq!(st.answers, st.requests, "every request answered");
    // A late answer echoes its own request's IPOC, which is no longer the current one.
    assert!(r.wrong_ipoc <= r.late, "IPOC not echoed: {}", r.wrong_ipoc);
    assert_eq!(r.malformed + r.wrong_type, 0);
    assert!(!r.stopped_by_limit && !r.stopped_by_monitor);
    assert_eq!(st.plans_rejected, 0);
    assert_eq!((r.poscorr_clamped, r.axiscorr_clamped, r.wrong_kind), (0, 0, 0));
    assert_eq!(st.axis_held, 0);
    if correction == Correction::Axis {
        // The joints stayed within the software limit switches.
        for s in &r.path {
            let q = topspin_core::kinematics::Joints::from_degrees(s.joints);
            lim.arm.limits.check_position(&q).unwrap_or_else(|v| panic!("{v}"));
        }
    }

    // The robot never stopped; its axes stayed within their speeds and
    // accelerations except where a late answer held the correction (a
    // velocity step the axes take through their lag).
    assert!(r.stopped.is_none(), "the controller stopped: {:?}", r.stopped.map(|s| s.to_string()));
    if r.late == 0 {
        assert_eq!(r.rates_over, 0, "an axis over its limits with every answer on time");
    }

    // The bat at each hitting pose at its hitting time.
    assert!(finals.len() + 3 >= (n as usize * 4 / 1000), "{} strikes", finals.len());
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    let mut skipped = 0;
    for p in &finals {
        let th = p.hit_time;
        let late_before_hit =
            r.path.iter().any(|s| !s.on_time && s.t.0 + 200_000_000 > th.0 && s.t.0 < th.0 + 8_000_000);
        if late_before_hit {
            skipped += 1;
            continue;
        }
        let m = StrikeMiss::of(&r.path, p, &lim);
        let (best, rot) = (m.best_mm, m.rot_deg);
        if std::env::var("DBG").is_ok() {
            eprintln!("strike {} {m:?}", p.trajectory);
            continue;
        }
        worst = (worst.0.max(best), worst.1.max(rot), worst.2.max(m.at_hit_mm));
        assert!(best < 2.0, "strike {}: {best:.3} mm from the hitting point within ±2 ms", p.trajectory);
        assert!(rot < 0.5, "strike {}: orientation off by {rot:.3}°", p.trajectory);
    }
    assert!(skipped as u64 <= r.late, "{skipped} strikes left out for {} late answers", r.late);
    eprintln!(
        "{correction}: {} strikes ({skipped} left out: a late answer in their last 200 ms); worst: {:.3} mm within ±2 ms, {:.3} mm at the hit time, {:.3}°",
        finals.len(),
        worst.0,
        worst.2,
        worst.1
    );
}
