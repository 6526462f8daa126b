//! `topspin sim` end to end: files on disk, the live UDP stream on
//! loopback, and the exit code for unusable input.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use topspin_core::wire::Observation;

const BIN: &str = env!("CARGO_BIN_EXE_topspin");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("topspin-sim-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn run_to(dir: &PathBuf, extra: &[&str]) -> std::process::Output {
    Command::new(BIN).args(["sim", "--out"]).arg(dir).args(extra).output().unwrap()
}

#[test]
fn writes_csv_truth_and_stream() {
    let dir = temp_dir("files");
    let out = run_to(&dir, &["--balls", "3", "--seed", "4", "--false-starts", "2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 3, "{stdout}");
    assert!(stdout.contains("backspin-medium"), "{stdout}");

    let mut stream_rows = 0;
    for k in 0..3 {
        let csv = std::fs::read_to_string(dir.join(format!("ball-{k:03}.csv"))).unwrap();
        let mut lines = csv.lines();
        assert_eq!(lines.next(), Some("t,x,y,z"));
        let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
        assert!(rows.len() > 50, "{} rows", rows.len());
        assert!(rows.windows(2).all(|w| w[1][0] > w[0][0]));
        stream_rows += rows.len();

        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(format!("ball-{k:03}.json"))).unwrap()).unwrap();
        let expect = ["backspin-low", "backspin-medium", "backspin-high"][k];
        assert_eq!(json["setting"], expect);
        assert_eq!(json["outliers"], serde_json::json!([0, 1]));
        assert_eq!(json["samples"].as_u64().unwrap() as usize, rows.len());
        let bounce_x = json["bounce"]["pos"][0].as_f64().unwrap();
        assert!(bounce_x > 0.0 && bounce_x < 1.37);
        let hit_t = json["hit"]["t"].as_f64().unwrap();
        assert!(rows.last().unwrap()[0] <= hit_t);
        assert!(json["spin"][1].as_f64().unwrap() < 0.0);
        assert!(json["net_crossing_t"].as_f64().unwrap() < json["bounce"]["t"].as_f64().unwrap());
    }
    let stream = std::fs::read_to_string(dir.join("stream.csv")).unwrap();
    let mut lines = stream.lines();
    assert_eq!(lines.next(), Some("t,x,y,z,ball"));
    let t: Vec<f64> = lines.map(|l| l.split(',').next().unwrap().parse().unwrap()).collect();
    assert_eq!(t.len(), stream_rows);
    assert!(t.windows(2).all(|w| w[1] > w[0]));

    // Same seed, same bytes; ball k does not depend on the number of balls.
    let again = temp_dir("files-again");
    assert!(run_to(&again, &["--balls", "2", "--seed", "4", "--false-starts", "2"]).status.success());
    for name in ["ball-000.csv", "ball-001.json"] {
        assert_eq!(std::fs::read(dir.join(name)).unwrap(), std::fs::read(again.join(name)).unwrap(), "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&again);
}

#[test]
fn streams_one_ball_over_udp() {
    let rx = UdpSocket::bind("127.0.0.1:0").unwrap();
    rx.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    let addr = rx.local_addr().unwrap().to_string();
    let mut child = Command::new(BIN)
        .args(["sim", "--to", &addr, "--bind", "127.0.0.1:0", "--balls", "1"])
        .args(["--setting", "topspin-high", "--seed", "2"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut got = Vec::new();
    let mut buf = [0u8; 64];
    while Instant::now() < deadline {
        match rx.recv(&mut buf) {
            Ok(n) => got.push(Observation::parse(&buf[..n]).expect("valid TTB1 datagram")),
            Err(_) => {
                if child.try_wait().unwrap().is_some() {
                    break;
                }
            }
        }
    }
    let status = child.wait().unwrap();
    assert!(status.success());
    assert!(got.len() > 20, "{} datagrams", got.len());
    for (i, o) in got.iter().enumerate() {
        assert_eq!(o.seq as usize, i);
        assert!(o.valid && o.cameras == 2);
    }
    assert!(got.windows(2).all(|w| w[1].capture > w[0].capture));
    // The ball flies towards the robot.
    assert!(got.last().unwrap().pos[0] > got[0].pos[0] + 2.0);
}

#[test]
fn human_serves_are_written_with_their_truth() {
    // Real serves: launched behind the opponent's end, a bounce on their
    // own half, then the one on the robot's half that the truth records.
    let dir = temp_dir("serves");
    let out = run_to(&dir, &["--balls", "3", "--seed", "2", "--strokes", "human-serve"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for k in 0..3 {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(format!("ball-{k:03}.json"))).unwrap()).unwrap();
        let launch_x = json["launch"]["pos"][0].as_f64().unwrap();
        let bounce = &json["bounce"];
        assert!(launch_x < -1.0, "{launch_x}");
        assert!(bounce["pos"][0].as_f64().unwrap() > 0.0);
        assert!(json["net_crossing_t"].as_f64().unwrap() < bounce["t"].as_f64().unwrap());
        // Human serves spin slowly next to the launcher's 20–100 rps.
        assert!(json["spin_rps"].as_f64().unwrap() < 20.0, "{}", json["spin_rps"]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    let dir = temp_dir("bad");
    for args in [
        vec!["--setting", "curveball-low"],
        vec!["--noise-mm", "-1"],
        vec!["--rate", "0"],
        vec!["--physics", "vacuum"],
        vec!["--strokes", "elite"],
        vec!["--strokes", "human", "--setting", "topspin-low"],
    ] {
        let out = run_to(&dir, &args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // A file where the output folder should be.
    let file = temp_dir("bad-file");
    std::fs::write(&file, "x").unwrap();
    let out = run_to(&file.join("sub"), &["--balls", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let _ = std::fs::remove_file(&file);
}

#[test]
fn a_closed_pipe_ends_the_listing_quietly() {
    // `topspin sim … | head -1`: the reader goes away after the first line.
    use std::io::{BufRead, BufReader};
    use std::os::unix::process::ExitStatusExt;
    let dir = temp_dir("pipe");
    let mut child = Command::new(BIN)
        .args(["sim", "--balls", "1000", "--out"])
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut first).unwrap();
    assert!(first.starts_with("ball 000"), "{first}");
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}: {stderr}", out.status);
    let _ = std::fs::remove_dir_all(&dir);
}
