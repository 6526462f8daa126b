//! `topspin check tracker` as a user runs it: listening on a port while a
//! tracker sends (here this test, from its own socket), the JSON report's
//! counts; exit 2 and one line for unusable input.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::Duration;

use topspin_core::time::Instant;
use topspin_core::wire::{OBSERVATION_LEN, Observation};

fn topspin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_topspin"))
}

#[test]
fn it_reports_what_a_tracker_sends() {
    let port = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let child = topspin()
        .args(["check", "tracker", "--bind", &format!("127.0.0.1:{port}"), "--seconds", "2", "--json"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(400));
    let tx = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut buf = [0u8; OBSERVATION_LEN];
    for seq in (0..60u32).filter(|s| *s != 7) {
        let capture = Instant(1_000_000_000 + u64::from(seq) * 5_000_000);
        Observation { seq, capture, pos: [0.3, -0.1, 0.02], residual: 0.001, cameras: 3, valid: true }.emit(&mut buf);
        tx.send_to(&buf, ("127.0.0.1", port)).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    tx.send_to(b"not a ball", ("127.0.0.1", port)).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["accepted"], 59, "{r}");
    assert_eq!((r["seq_gaps"].as_u64(), r["seq_missing"].as_u64()), (Some(1), Some(1)), "{r}");
    assert_eq!(r["bad"]["wrong_length"], 1, "{r}");
    assert_eq!(r["at_rest_share"], 1.0, "{r}");
    let rate = r["rate_hz"].as_f64().unwrap();
    assert!(rate > 50.0 && rate < 250.0, "rate {rate}");
    assert!(r["clock_offset_ns"].as_i64().is_some() && r["jitter_us"][2].as_f64().is_some(), "{r}");
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    for args in [
        vec!["check", "tracker", "--seconds=0"],
        vec!["check", "tracker", "--config", "/nonexistent/topspin.toml", "--seconds", "1"],
    ] {
        let out = topspin().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
    }
}
