//! The real daemon (`topspin run`) with recording on, against the mock
//! KR C4 and the simulated tracker (three processes on loopback); SIGTERM
//! ends it cleanly (exit 0) and `topspin replay` reproduces every plan of
//! the recording bit for bit.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::net::UdpSocket;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

#[test]
fn daemon_records_and_replay_reproduces_every_plan() {
    let dir = std::env::temp_dir().join(format!("topspin-run-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (tracker, rsi) = (free_port(), free_port());
    let mut daemon = Command::new(BIN)
        .arg("run")
        .env("TOPSPIN_NETWORK__TRACKER_BIND", format!("127.0.0.1:{tracker}"))
        .env("TOPSPIN_NETWORK__RSI_BIND", format!("127.0.0.1:{rsi}"))
        .env("TOPSPIN_THREADS__REALTIME", "false")
        .env("TOPSPIN_RECORDING__ENABLED", "true")
        .env("TOPSPIN_RECORDING__DIR", &dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let mut mock = Command::new(BIN)
        .args(["mock-krc", "--bind", "127.0.0.1:0", "--cycles", "1500", "--to"])
        .arg(format!("127.0.0.1:{rsi}"))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let sim = Command::new(BIN)
        .args(["sim", "--balls", "3", "--gap", "1.2", "--to"])
        .arg(format!("127.0.0.1:{tracker}"))
        .output()
        .unwrap();
    assert!(sim.status.success());
    std::thread::sleep(Duration::from_millis(500));
    let kill = Command::new("kill").args(["-TERM", &daemon.id().to_string()]).status().unwrap();
    assert!(kill.success());
    // The daemon answers until the controller stops (the mock's 1500 cycles), then ends.
    let start = Instant::now();
    let status = loop {
        if let Some(s) = daemon.try_wait().unwrap() {
            break s;
        }
        assert!(start.elapsed() < Duration::from_secs(15), "daemon did not stop");
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = mock.wait();
    let mut log = String::new();
    std::io::Read::read_to_string(daemon.stderr.as_mut().unwrap(), &mut log).unwrap();
    assert!(status.success(), "daemon exit {status:?}\n{log}");
    assert!(log.contains("stopping: bringing the bat home"), "{log}");

    let file = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"));
    let file = file.expect("a recording");
    let replay = Command::new(BIN).arg("replay").arg(&file).output().unwrap();
    let text = String::from_utf8_lossy(&replay.stdout);
    assert_eq!(replay.status.code(), Some(0), "{text}");
    let plans = text.lines().find(|l| l.starts_with("plans")).unwrap_or_default().to_owned();
    assert!(!plans.contains(" 0 recorded"), "{text}");
    assert!(text.lines().any(|l| l.starts_with("different") && l.trim_end().ends_with(" 0")), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}
