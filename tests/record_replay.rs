//! Record a session with the library (simulated tracker → Ingest →
//! Estimator, as the daemon does), then `topspin replay` it: identical plans
//! exit 0, a tampered plan exits 1, a file cut off after a flush still
//! replays what it holds, a file that is no recording exits 2.

use std::net::SocketAddr;
use std::path::Path;
use std::process::{Command, Output};

use topspin_core::calib::Calibration;
use topspin_core::estimator::Estimator;
use topspin_core::ingest::Ingest;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;
use topspin_core::wire::{OBSERVATION_LEN, Observation};
use topspin_daemon::calib_files::calibration_texts;
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::record::{Recorder, read_recording};
use topspin_lab::eval::stream::{StreamSetup, simulate_stream};

const TRACKER: &str = "127.0.0.7:5555";

struct Recorded {
    datagrams: usize,
    plans: Vec<StrikePlan>,
}

/// Records `balls` simulated balls (plus a foreign and a malformed datagram
/// now and then, RSI exchanges and counters), flushing every 50 datagrams.
fn record(path: &Path, balls: usize) -> Recorded {
    let cal = Calibration::default_cell();
    let mut cfg = DaemonConfig::default();
    cfg.network.tracker_source = "127.0.0.7".parse().unwrap();
    cfg.tracker.noise_mm = 1.5;
    let (sim, launches) = simulate_stream(&cal, &StreamSetup { balls, seed: 7, noise_mm: 1.5, ..Default::default() });
    let mut rec = Recorder::create(path, &cfg, &calibration_texts(None).unwrap()).unwrap();
    let mut ingest = Ingest::new(Some(cfg.network.tracker_source), cfg.fixed_latency_ns());
    let mut est = Estimator::new(&cal, cfg.estimator_config());
    let from: SocketAddr = TRACKER.parse().unwrap();
    let stranger: SocketAddr = "10.1.2.3:5555".parse().unwrap();
    let (mut seq, mut datagrams, mut plans) = (0u32, 0usize, Vec::new());
    for (ball, &t0) in sim.iter().zip(&launches) {
        for o in &ball.observations {
            let capture = Instant::from_secs_f64(t0 + o.t);
            // The tracker's clock runs 5 s behind ours; 1–3 ms network delay.
            let arrival =
                Instant::from_nanos(capture.as_nanos() + 5_000_000_000 + 1_000_000 + (seq as u64 * 7919) % 2_000_000);
            let tracker_capture = Instant::from_nanos(capture.as_nanos());
            let mut buf = [0u8; OBSERVATION_LEN];
            let pos = [o.pos.x as f32, o.pos.y as f32, o.pos.z as f32];
            Observation { seq, capture: tracker_capture, pos, residual: 0.001, cameras: 3, valid: true }.emit(&mut buf);
            seq += 1;
            let mut feed = |bytes: &[u8], who: SocketAddr| {
                rec.observation(arrival, who, bytes).unwrap();
                datagrams += 1;
                if let Ok(a) = ingest.accept(bytes, who, arrival)
                    && let Some(p) = est.observe(a.capture, a.pos).plan
                {
                    rec.plan(&p).unwrap();
                    plans.push(p);
                }
            };
            if seq % 97 == 0 {
                feed(&buf, stranger);
                feed(&buf[..20], from);
            }
            feed(&buf, from);
            if seq % 4 == 0 {
                let req = format!("<Rob Type=\"KUKA\"><IPOC>{seq}</IPOC></Rob>");
                rec.rsi(
                    arrival,
                    req.as_bytes(),
                    b"<Sen Type=\"ImFree\"></Sen>",
                    Instant::from_nanos(arrival.as_nanos() + 40_000),
                )
                .unwrap();
            }
            if seq % 50 == 0 {
                rec.counters(&serde_json::json!({ "ingest": ingest.counters(), "seq": seq }), arrival).unwrap();
                rec.flush().unwrap();
            }
        }
    }
    rec.rsi(Instant::from_nanos(1), &[0xff, 0xfe, b'<'], b"", Instant::from_nanos(2)).unwrap();
    rec.finish().unwrap();
    Recorded { datagrams, plans }
}

fn replay(path: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_topspin")).arg("replay").arg(path).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

#[test]
fn a_recording_reads_back_whole() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let rec = record(&path, 4);
    assert!(rec.plans.len() > 10, "{} plans", rec.plans.len());
    let s = read_recording(&path).unwrap();
    assert_eq!(s.truncated, None);
    assert_eq!(s.observations.len(), rec.datagrams);
    assert_eq!(s.plans, rec.plans);
    assert_eq!(s.config.tracker.noise_mm, 1.5);
    assert_eq!(s.calib_files, calibration_texts(None).unwrap());
    assert_eq!(s.calibration().unwrap(), Calibration::default_cell());
    assert!(s.counters.len() > 5);
    let last = s.exchanges.last().unwrap();
    assert_eq!((last.request.as_slice(), last.answer.as_slice()), (&[0xff, 0xfe, b'<'][..], &b""[..]));
    assert!(String::from_utf8_lossy(&s.exchanges[0].request).starts_with("<Rob"));
    assert_eq!(s.observations[0].from, TRACKER.parse().unwrap());
}

#[test]
fn replay_is_bit_exact_and_catches_a_tampered_plan() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let rec = record(&path, 4);
    let out = replay(&path);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let t = text(&out);
    assert!(t.contains(&format!("datagrams    {}", rec.datagrams)), "{t}");
    assert!(t.contains(&format!("identical    {n} of {n} compared", n = rec.plans.len())), "{t}");
    assert!(t.contains("foreign ") && !t.contains("foreign 0") && !t.contains("malformed 0"), "{t}");

    // The same session with one plan off by one ulp in one coordinate.
    let s = read_recording(&path).unwrap();
    let tampered = dir.path().join("tampered.mcap");
    let mut w = Recorder::create(&tampered, &s.config, &s.calib_files).unwrap();
    for d in &s.observations {
        w.observation(d.arrival, d.from, &d.bytes).unwrap();
    }
    let k = s.plans.len() / 2;
    for (i, p) in s.plans.iter().enumerate() {
        let mut p = *p;
        if i == k {
            p.position.y = f64::from_bits(p.position.y.to_bits() + 1);
        }
        w.plan(&p).unwrap();
    }
    w.finish().unwrap();
    let out = replay(&tampered);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let t = text(&out);
    assert!(t.contains(&format!("first difference at plan {k}: position.y")), "{t}");
    assert!(t.contains("different    1"), "{t}");

    // A plan missing at the end of a complete file is a difference too.
    let short = dir.path().join("short.mcap");
    let mut w = Recorder::create(&short, &s.config, &s.calib_files).unwrap();
    for d in &s.observations {
        w.observation(d.arrival, d.from, &d.bytes).unwrap();
    }
    for p in &s.plans[..s.plans.len() - 1] {
        w.plan(p).unwrap();
    }
    w.finish().unwrap();
    let out = replay(&short);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(text(&out).contains("extra"), "{}", text(&out));
}

#[test]
fn a_file_cut_off_after_a_flush_replays_what_it_holds() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session.mcap");
    let rec = record(&path, 6);
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let s = read_recording(&cut).unwrap();
    assert!(s.truncated.is_some());
    assert!(
        s.observations.len() > rec.datagrams / 3 && s.observations.len() < rec.datagrams,
        "{}",
        s.observations.len()
    );
    assert!(!s.plans.is_empty());
    assert_eq!(s.plans[..], rec.plans[..s.plans.len()]);
    let out = replay(&cut);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(text(&out).contains("truncated    yes"), "{}", text(&out));
}

#[test]
fn no_recording_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.mcap");
    std::fs::write(&garbage, b"hello, not an mcap").unwrap();
    let missing = dir.path().join("missing.mcap");
    // MCAP, but cut off before the configuration.
    let path = dir.path().join("session.mcap");
    record(&path, 1);
    let head = dir.path().join("head.mcap");
    std::fs::write(&head, &std::fs::read(&path).unwrap()[..12]).unwrap();
    for p in [&garbage, &missing, &head] {
        let out = replay(p);
        assert_eq!(out.status.code(), Some(2), "{}", text(&out));
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(p.file_name().unwrap().to_str().unwrap()), "{err}");
    }
}

#[test]
#[ignore = "writes target/example-session.mcap for a look in Foxglove"]
fn example_session_for_foxglove() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/example-session.mcap");
    record(&path, 9);
    println!("{}", text(&replay(&path)));
}
