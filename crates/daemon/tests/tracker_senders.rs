//! The tracker-side TTB1 senders in `tools/tracker/` (a C header and plain
//! Python), each driven against the real daemon threads on loopback: every
//! datagram each sends is accepted by the daemon's ingest, and the bytes
//! parse to exactly the fields written. The C sender is compiled with `cc`
//! (the README's one system requirement); the Python one needs `python3`,
//! and says so on stderr and passes where it is absent.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::io::Write as _;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use topspin_core::calib::Calibration;
use topspin_core::wire::Observation;
use topspin_daemon::runtime::{Daemon, RuntimeConfig};

const COUNT: u64 = 120;

fn tools() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tools/tracker")
}

/// The C sender built from `send_example.c` and `ttb1.h`.
fn c_sender() -> PathBuf {
    let out = std::env::temp_dir().join(format!("ttb1-send-{}", std::process::id()));
    let status = Command::new("cc")
        .args(["-O2", "-Wall", "-Wextra", "-Werror", "-o"])
        .arg(&out)
        .arg(tools().join("send_example.c"))
        .arg("-lm")
        .status()
        .expect("a C compiler (`cc`)");
    assert!(status.success(), "send_example.c does not compile");
    out
}

fn python() -> Option<&'static str> {
    let ok = Command::new("python3").arg("--version").output().is_ok_and(|o| o.status.success());
    if !ok {
        let _ = writeln!(std::io::stderr(), "SKIPPED the Python TTB1 sender: no python3");
    }
    ok.then_some("python3")
}

/// Runs `sender` against a fresh daemon; the ingest's counters after it.
fn through_the_daemon(sender: impl FnOnce(&str, u16)) -> topspin_core::ingest::IngestCounters {
    let cal = Calibration::default_cell();
    let daemon = Daemon::start(&RuntimeConfig::loopback(), &cal, None).unwrap();
    let addr = daemon.tracker_addr;
    sender(&addr.ip().to_string(), addr.port());
    // The last datagrams reach the ingest thread within milliseconds.
    std::thread::sleep(Duration::from_millis(300));
    daemon.request_stop();
    daemon.join().unwrap().ingest
}

/// The datagrams `sender` sends to a plain socket, parsed.
fn parsed(sender: impl FnOnce(&str, u16)) -> Vec<Observation> {
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(500))).unwrap();
    let port = sock.local_addr().unwrap().port();
    sender("127.0.0.1", port);
    let mut out = Vec::new();
    let mut buf = [0u8; 64];
    let until = Instant::now() + Duration::from_secs(5);
    while let Ok(n) = sock.recv(&mut buf) {
        out.push(Observation::parse(&buf[..n]).unwrap_or_else(|e| panic!("datagram {}: {e}", out.len())));
        if out.len() as u64 == COUNT || Instant::now() > until {
            break;
        }
    }
    out
}

fn run_c(host: &str, port: u16) {
    let exe = c_sender();
    let status = Command::new(&exe).args([host, &port.to_string(), &COUNT.to_string()]).status().unwrap();
    let _ = std::fs::remove_file(&exe);
    assert!(status.success());
}

fn run_python(py: &str, host: &str, port: u16) {
    let status = Command::new(py)
        .arg(tools().join("ttb1.py"))
        .args(["--to", &format!("{host}:{port}"), "--count", &COUNT.to_string(), "--rate", "400"])
        .status()
        .unwrap();
    assert!(status.success());
}

/// What both senders write: numbered from 0, a valid ball seen by 3
/// cameras with a 1 mm residual, 5 ms (C) or 2.5 ms (Python) apart.
fn check_fields(obs: &[Observation], period_ns: u64) {
    assert_eq!(obs.len() as u64, COUNT);
    for (k, o) in obs.iter().enumerate() {
        assert_eq!(o.seq, k as u32);
        assert!(o.valid && o.cameras == 3 && (o.residual - 0.001).abs() < 1e-9, "{o:?}");
        assert_eq!(o.capture.as_nanos() - obs[0].capture.as_nanos(), k as u64 * period_ns);
        assert!((o.pos[1] - 0.05).abs() < 1e-7 && o.pos[2] >= 0.02, "{o:?}");
    }
}

#[test]
fn the_c_header_sends_what_the_daemon_accepts() {
    check_fields(&parsed(run_c), 5_000_000);
    let c = through_the_daemon(run_c);
    assert_eq!(c.accepted, COUNT, "{c:?}");
    assert_eq!((c.malformed, c.foreign, c.duplicate, c.out_of_order), (0, 0, 0, 0), "{c:?}");
}

#[test]
fn the_python_sender_sends_what_the_daemon_accepts() {
    let Some(py) = python() else { return };
    check_fields(&parsed(|h, p| run_python(py, h, p)), 2_500_000);
    let c = through_the_daemon(|h, p| run_python(py, h, p));
    assert_eq!(c.accepted, COUNT, "{c:?}");
    assert_eq!((c.malformed, c.foreign, c.duplicate, c.out_of_order), (0, 0, 0, 0), "{c:?}");
}
