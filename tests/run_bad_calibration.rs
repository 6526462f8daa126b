//! `topspin run` with a calibration it must not start on (bad
//! input): limits that are not numbers, or an arm that cannot reach the
//! hitting window, stop the start with exit 2 and one line naming the key,
//! before a socket is bound.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

/// A `calib/` copy whose robot.toml has `from` replaced by `to`.
fn calib_with(dir: &Path, from: &str, to: &str) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("calib");
    for f in ["physics.toml", "table.toml", "strike.toml", "robot.toml", "camera.toml"] {
        let text = std::fs::read_to_string(src.join(f)).unwrap();
        let text = if f == "robot.toml" {
            assert!(text.contains(from), "{from}");
            text.replacen(from, to, 1)
        } else {
            text
        };
        std::fs::write(dir.join(f), text).unwrap();
    }
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Runs the daemon on that calibration: (exit code, stderr). A daemon that
/// wrongly starts is killed after 20 s (and fails the test).
fn run(dir: &Path) -> (Option<i32>, String) {
    let mut child = Command::new(BIN)
        .arg("run")
        .env("TOPSPIN_CALIB__DIR", dir)
        .env("TOPSPIN_NETWORK__TRACKER_BIND", format!("127.0.0.1:{}", free_port()))
        .env("TOPSPIN_NETWORK__RSI_BIND", format!("127.0.0.1:{}", free_port()))
        .env("TOPSPIN_THREADS__REALTIME", "false")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t0.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = child.wait_with_output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).trim().to_owned())
}

#[test]
fn limits_that_are_not_numbers_name_the_key() {
    let dir = tempfile::tempdir().unwrap();
    calib_with(dir.path(), "speed_deg_s = [360.0,", "speed_deg_s = [\"fast\",");
    let (code, err) = run(dir.path());
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("robot.toml") && err.contains("`joints.speed_deg_s`"), "{err}");
}

#[test]
fn an_arm_that_cannot_reach_the_hitting_window_stops_the_start() {
    // A1 fenced to ±20°: home and the workspace box still pass, but the bat
    // reaches only the middle of the window.
    let dir = tempfile::tempdir().unwrap();
    calib_with(dir.path(), "min_deg = [-170.0,", "min_deg = [-20.0,");
    let robot = std::fs::read_to_string(dir.path().join("robot.toml")).unwrap();
    std::fs::write(dir.path().join("robot.toml"), robot.replacen("max_deg = [170.0,", "max_deg = [20.0,", 1)).unwrap();
    let (code, err) = run(dir.path());
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("strike.window_y") && err.contains("joints.min_deg"), "{err}");
}
