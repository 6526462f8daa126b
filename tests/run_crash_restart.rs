//! The daemon as a process under the signals systemd sends:
//! SIGTERM in the middle of a stroke brings the bat home within limits and
//! exits 0; SIGKILL mid-stroke leaves a recording that still opens and
//! holds what was flushed; a restarted daemon (as `Restart=on-failure`
//! does) answers a restarted RSI and records a complete file.
//!
//! "Mid-stroke" is read from the daemon's own log: the signal goes out on
//! the first `PhaseChanged(Approach)` (the bat leaving home for a ball).
//!
//! Limits: no POSCORR clamp and no monitor stop. The mock's `rates_over`
//! is not asserted here: on this shared machine some answers are late (the
//! mock CLI keeps the controller's deadline), and a held-then-resumed
//! correction is a velocity step the axes take through their lag — that is
//! lateness, tested in crates/sim/tests/rsi_faults.rs, not a command out of bounds.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use topspin_core::calib::Calibration;

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// `topspin run` on the given ports (no real-time: a test machine); its
/// stderr lines go to the returned channel.
fn daemon(tracker: u16, rsi: u16, recording: Option<&Path>) -> (Child, mpsc::Receiver<String>) {
    let mut cmd = Command::new(BIN);
    cmd.arg("run")
        .env("TOPSPIN_NETWORK__TRACKER_BIND", format!("127.0.0.1:{tracker}"))
        .env("TOPSPIN_NETWORK__RSI_BIND", format!("127.0.0.1:{rsi}"))
        .env("TOPSPIN_THREADS__REALTIME", "false")
        .env("TOPSPIN_TELEMETRY__LOG_LEVEL", "info")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    if let Some(dir) = recording {
        cmd.env("TOPSPIN_RECORDING__ENABLED", "true").env("TOPSPIN_RECORDING__DIR", dir);
    }
    let mut child = cmd.spawn().unwrap();
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// The mock KR C4 for `cycles` cycles. Its late limit is raised far above
/// the controller's: this shared machine's scheduling noise must not stop
/// RSI (what the test is about is counted separately).
fn mock(rsi: u16, cycles: u32, csv: &Path) -> Child {
    Command::new(BIN)
        .args([
            "mock-krc",
            "--bind",
            "127.0.0.1:0",
            "--late-limit",
            "1000000",
            "--cycles",
            &cycles.to_string(),
            "--csv",
        ])
        .arg(csv)
        .arg("--to")
        .arg(format!("127.0.0.1:{rsi}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

fn sim(tracker: u16, balls: u32, seed: u32) -> Child {
    Command::new(BIN)
        .args(["sim", "--balls", &balls.to_string(), "--seed", &seed.to_string(), "--gap", "1.2", "--to"])
        .arg(format!("127.0.0.1:{tracker}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// Waits for a log line containing `needle`; returns the log so far.
fn wait_for(rx: &mpsc::Receiver<String>, needle: &str, within: Duration) -> String {
    let start = Instant::now();
    let mut log = String::new();
    while start.elapsed() < within {
        if let Ok(line) = rx.recv_timeout(Duration::from_millis(100)) {
            log.push_str(&line);
            log.push('\n');
            if line.contains(needle) {
                return log;
            }
        }
    }
    panic!("no `{needle}` in the daemon's log within {within:?}:\n{log}");
}

fn signal(child: &Child, sig: &str) {
    assert!(Command::new("kill").args([sig, &child.id().to_string()]).status().unwrap().success());
}

fn wait_exit(child: &mut Child, within: Duration) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(start.elapsed() < within, "process did not end within {within:?}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The mock's one-line summary as (key, value) pairs.
fn mock_summary(child: Child) -> Vec<(String, String)> {
    let out = child.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let words: Vec<String> = text.split_whitespace().map(str::to_owned).collect();
    words.chunks(2).filter(|c| c.len() == 2).map(|c| (c[0].clone(), c[1].clone())).collect()
}

fn get<'a>(s: &'a [(String, String)], key: &str) -> &'a str {
    s.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str()).unwrap_or_else(|| panic!("no {key} in {s:?}"))
}

/// The last actual TCP position in the mock's CSV (mm).
fn last_position(csv: &Path) -> [f64; 3] {
    let mut r = csv::Reader::from_path(csv).unwrap();
    let h = r.headers().unwrap().clone();
    let col = |k: &str| h.iter().position(|x| x == k).unwrap();
    let (x, y, z) = (col("act_x_mm"), col("act_y_mm"), col("act_z_mm"));
    let last = r.records().map(Result::unwrap).last().expect("a path");
    [x, y, z].map(|c| last[c].parse().unwrap())
}

fn home_mm() -> [f64; 3] {
    Calibration::default_cell().robot.home.xyz_m.map(|v| v * 1e3)
}

fn recordings(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    v.sort();
    v
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topspin-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn sigterm_mid_stroke_brings_the_bat_home_within_limits() {
    let dir = tmp("sigterm");
    let (tracker, rsi) = (free_port(), free_port());
    let (mut d, log) = daemon(tracker, rsi, None);
    wait_for(&log, "running: tracker datagrams", Duration::from_secs(20));
    let csv = dir.join("path.csv");
    let m = mock(rsi, 2500, &csv);
    let mut s = sim(tracker, 3, 1);
    let seen = wait_for(&log, "PhaseChanged(Approach)", Duration::from_secs(20));
    signal(&d, "-TERM");
    let status = wait_exit(&mut d, Duration::from_secs(30));
    let _ = s.kill();
    let _ = s.wait();
    let summary = mock_summary(m);
    assert!(status.success(), "daemon exit {status:?}\n{seen}");
    assert_eq!(get(&summary, "stopped_by_monitor"), "false", "{summary:?}");
    assert_eq!(get(&summary, "poscorr_clamped"), "0", "{summary:?}");
    let (end, home) = (last_position(&csv), home_mm());
    for i in 0..3 {
        assert!((end[i] - home[i]).abs() < 1.0, "bat at {end:?}, home {home:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigkill_mid_stroke_keeps_the_recording_and_a_restart_resumes() {
    let dir = tmp("sigkill");
    let (tracker, rsi) = (free_port(), free_port());
    let (mut a, log) = daemon(tracker, rsi, Some(&dir));
    wait_for(&log, "running: tracker datagrams", Duration::from_secs(20));
    let csv1 = dir.join("path1.csv");
    let m1 = mock(rsi, 2500, &csv1);
    let mut s1 = sim(tracker, 3, 2);
    wait_for(&log, "PhaseChanged(Approach)", Duration::from_secs(20));
    // Past at least one of the recorder's flushes (about once a second).
    std::thread::sleep(Duration::from_millis(2500));
    signal(&a, "-KILL");
    let _ = wait_exit(&mut a, Duration::from_secs(10));
    let _ = s1.kill();
    let _ = s1.wait();
    // The controller counts every cycle after the kill late (the real one
    // stops RSI at its limit; this mock runs its cycles out first).
    let summary1 = mock_summary(m1);
    assert!(get(&summary1, "late").parse::<u64>().unwrap() > 100, "{summary1:?}");
    assert_eq!(get(&summary1, "poscorr_clamped"), "0", "{summary1:?}");

    // The killed file opens and holds what was flushed.
    let files = recordings(&dir);
    assert_eq!(files.len(), 1, "{files:?}");
    let killed = topspin_daemon::record::read_recording(&files[0]).expect("a killed recording still opens");
    assert!(killed.truncated.is_some(), "a killed file cannot have its summary");
    assert!(!killed.observations.is_empty() && !killed.exchanges.is_empty(), "nothing flushed was kept");
    let replay = Command::new(BIN).arg("replay").arg(&files[0]).output().unwrap();
    assert_eq!(replay.status.code(), Some(0), "{}", String::from_utf8_lossy(&replay.stdout));

    // systemd restarts the daemon; the controller restarts RSI.
    let (mut b, log) = daemon(tracker, rsi, Some(&dir));
    wait_for(&log, "running: tracker datagrams", Duration::from_secs(20));
    let csv2 = dir.join("path2.csv");
    let m2 = mock(rsi, 1500, &csv2);
    let s2 = sim(tracker, 1, 3).wait_with_output().unwrap();
    assert!(s2.status.success());
    signal(&b, "-TERM");
    let status = wait_exit(&mut b, Duration::from_secs(30));
    assert!(status.success(), "restarted daemon exit {status:?}");
    let summary2 = mock_summary(m2);
    assert_eq!(get(&summary2, "stopped_by_limit"), "false", "{summary2:?}");
    assert_eq!(get(&summary2, "stopped_by_monitor"), "false", "{summary2:?}");
    assert_eq!(get(&summary2, "poscorr_clamped"), "0", "{summary2:?}");
    let files = recordings(&dir);
    assert_eq!(files.len(), 2, "the restart must not overwrite the killed recording: {files:?}");
    let complete =
        files.iter().map(|f| topspin_daemon::record::read_recording(f).unwrap()).find(|s| s.truncated.is_none());
    assert!(complete.is_some(), "the restarted daemon's recording is complete");
    let _ = std::fs::remove_dir_all(&dir);
}
