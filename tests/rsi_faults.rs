//! Fault tests against the mock KR C4 (short runs): delayed answers are
//! counted late and the mock stops RSI at the limit; dropped and
//! duplicated answers are survived; malformed requests never crash the
//! session.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use topspin::calib::Calibration;
use topspin::mock_krc::{self, Faults, MockKrcConfig, MockResult};
use topspin::rsi::server::{RsiServer, WaitStrategy, plan_slot};
use topspin::rsi::session::{MAX_ANSWER_LEN, RsiSession, SessionConfig};
use topspin::time::{Duration, Instant};

fn run_with(faults: Faults, late_limit: u64, cycles: u64) -> MockResult {
    let cal = Calibration::default_cell();
    let session = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
    let mut server = RsiServer::bind("127.0.0.1:0".parse().unwrap(), session, WaitStrategy::BusyPoll).unwrap();
    let addr = server.local_addr().unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let t = std::thread::spawn(move || server.run(&s2, &mut plan_slot().1, |_| {}).unwrap());
    let mut cfg = MockKrcConfig::default_cell().unwrap();
    cfg.sensor = addr;
    cfg.bind = "127.0.0.1:0".parse().unwrap();
    cfg.cycles = Some(cycles);
    cfg.controller.late_limit = late_limit;
    cfg.faults = faults;
    cfg.seed = 7;
    let r = mock_krc::spawn(cfg).unwrap().join().unwrap();
    stop.store(true, Ordering::Relaxed);
    t.join().unwrap();
    r
}

#[test]
fn delayed_answers_are_late_and_stop_rsi_at_the_limit() {
    let r = run_with(Faults { delay: 1.0, delay_by: Duration::from_millis(6), ..Faults::default() }, 20, 500);
    assert!(r.stopped_by_limit, "{r:?}");
    assert_eq!(r.late, 20);
    assert_eq!(r.cycles, 20);
    // The delayed answers arrive in a later cycle and are refused.
    assert!(r.wrong_ipoc > 0);
}

#[test]
fn dropped_and_duplicated_answers_are_counted_not_fatal() {
    let r = run_with(Faults { drop: 0.1, duplicate: 0.2, ..Faults::default() }, 1000, 150);
    assert_eq!(r.cycles, 150);
    assert!(!r.stopped_by_limit);
    assert!(r.dropped > 0 && r.duplicated > 0);
    // Every dropped answer is a late cycle (plus any the machine caused).
    assert!(r.late >= r.dropped);
}

#[test]
fn malformed_requests_never_crash_the_session() {
    let cal = Calibration::default_cell();
    let mut s = RsiSession::new(SessionConfig::from_calibration(&cal, "ImFree")).unwrap();
    let mut out = [0u8; MAX_ANSWER_LEN];
    let bad: [&[u8]; 8] = [
        b"",
        b"<Rob>",
        b"<Rob><IPOC>x</IPOC></Rob>",
        b"<Sen Type=\"ImFree\"><IPOC>1</IPOC></Sen>",
        b"\xff\xfe<Rob",
        b"<Rob><RIst X=\"1\"/><IPOC>1</IPOC></Rob>",
        b"<Rob><IPOC>99999999999999999999999</IPOC></Rob>",
        b"<<<<>>>>",
    ];
    for (k, b) in bad.iter().enumerate() {
        assert!(s.handle_datagram(Instant(k as u64), b, &mut out).is_err());
    }
    assert_eq!(s.stats().malformed, bad.len() as u64);
    // And it still answers a good one afterwards.
    let n = s.handle_datagram(Instant(10), b"<Rob Type=\"KUKA\"><IPOC>5</IPOC></Rob>", &mut out).unwrap();
    assert!(std::str::from_utf8(&out[..n]).unwrap().contains("<IPOC>5</IPOC>"));
}
