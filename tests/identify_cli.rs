//! `topspin identify` as a user runs it: the binary on a loopback port,
//! the mock KR C4 (in this process, on its own thread and the wall clock)
//! sending `<Rob>` every 4 ms with the controller's real deadline. The
//! JSON's dead time and lag are checked against the mock's configuration;
//! late answers (a loaded machine) are allowed and must not matter — the
//! mock's late limit is lifted so that they cannot stop the run. Exit 2
//! and one line for unusable input, exit 1 with the reason when nothing
//! comes.

#![allow(clippy::disallowed_methods)] // a process test: it waits on the wall clock

use std::net::UdpSocket;
use std::process::{Command, Output, Stdio};

use topspin_sim::mock_krc::{self, MockKrcConfig};

fn topspin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_topspin"))
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// Runs `topspin identify … --json` against a mock set up by `servo`.
fn identify_against_mock(extra: &[&str], servo: impl FnOnce(&mut MockKrcConfig)) -> (Output, mock_krc::MockResult) {
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let mut args = vec!["identify", "--bind", &addr, "--json", "--wait-s", "20", "--hold-s", "0.5"];
    args.extend_from_slice(extra);
    let child = topspin().args(&args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut cfg = MockKrcConfig::default_cell().unwrap();
    cfg.sensor = addr.parse().unwrap();
    cfg.bind = "127.0.0.1:0".parse().unwrap();
    cfg.controller.late_limit = u64::MAX;
    servo(&mut cfg);
    // Give the child time to bind; requests before that are lost, which
    // the identifier takes as the start a little later.
    std::thread::sleep(std::time::Duration::from_millis(300));
    let mock = mock_krc::spawn(cfg).unwrap();
    let out = child.wait_with_output().unwrap();
    let result = mock.stop().unwrap();
    (out, result)
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "exit {:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn the_ideal_mock_has_no_dead_time_and_no_lag() {
    let (out, mock) = identify_against_mock(&["--axis", "z", "--seconds", "3"], |c| {
        c.controller.dead_time_cycles = 0;
        c.controller.lag_s = 0.0;
    });
    let r = json(&out);
    eprintln!(
        "ideal mock: dead time {} ms, lag {} ± {} ms, fit {} %, late {} (mock late {}), {} cycles",
        r["dead_time_ms"], r["lag_ms"], r["lag_std_ms"], r["fit_percent"], r["late"], mock.late, r["cycles"]
    );
    assert_eq!(r["dead_time_cycles"], 0, "{r}");
    assert_eq!(r["dead_time_ms"], 0.0, "{r}");
    assert!(r["lag_ms"].as_f64().unwrap() < 0.5, "{r}");
    assert_eq!(r["cycle_ms"], 4);
    assert_eq!(r["ended"], "hold_elapsed");
    assert!(r["gain"][2].as_f64().is_some_and(|g| (g - 1.0).abs() < 0.01) && r["gain"][0].is_null(), "{r}");
    assert_eq!(r["calib_toml"], "[servo]\ndead_time_ms = 0.0\nlag_ms = 0.0\n");
    assert!(r["cycles"].as_u64().unwrap() >= 750, "{r}");
}

/// The mock with `d` cycles of dead time and a lag of `lag_s`: the JSON's
/// dead time within one cycle, its lag within 20 %.
fn recovers(d: u32, lag_s: f64, extra: &[&str]) {
    let (out, mock) = identify_against_mock(extra, |c| {
        c.controller.dead_time_cycles = d;
        c.controller.lag_s = lag_s;
    });
    let r = json(&out);
    eprintln!(
        "mock d {d} cycles, lag {:.1} ms → d {} ({} ms ± {:.2}, runner-up {} ×{:.2}), lag {:.2} ± {:.3} ms, fit {:.2} %, rms {:.4} mm, late {} gaps {} of {} cycles (mock late {}, axis rates over {})",
        lag_s * 1e3,
        r["dead_time_cycles"],
        r["dead_time_ms"],
        r["dead_time_std_ms"].as_f64().unwrap(),
        r["dead_time_runner_up_cycles"],
        r["dead_time_runner_up_ratio"].as_f64().unwrap_or(f64::INFINITY),
        r["lag_ms"].as_f64().unwrap(),
        r["lag_std_ms"].as_f64().unwrap(),
        r["fit_percent"].as_f64().unwrap(),
        r["rms_mm"].as_f64().unwrap(),
        r["late"],
        r["gaps"],
        r["cycles"],
        mock.late,
        mock.rates_over
    );
    let got_d = r["dead_time_cycles"].as_i64().unwrap();
    assert!((got_d - d as i64).abs() <= 1, "dead time {got_d} cycles, configured {d}: {r}");
    assert_eq!(r["dead_time_ms"].as_f64().unwrap(), got_d as f64 * 4.0);
    let lag_ms = r["lag_ms"].as_f64().unwrap();
    assert!((lag_ms - lag_s * 1e3).abs() <= 0.2 * lag_s * 1e3, "lag {lag_ms} ms, configured {} ms: {r}", lag_s * 1e3);
    let toml = r["calib_toml"].as_str().unwrap();
    assert!(toml.starts_with("[servo]\ndead_time_ms = ") && toml.contains("\nlag_ms = "), "{toml}");
}

#[test]
fn the_mock_s_3_cycles_and_15_ms_are_recovered() {
    recovers(3, 0.015, &["--axis", "x", "--seconds", "4"]);
}

#[test]
fn the_mock_s_1_cycle_and_30_ms_are_recovered_on_every_axis() {
    recovers(1, 0.030, &["--axis", "all", "--seconds", "9"]);
}

#[test]
fn no_controller_is_a_failure_with_its_reason() {
    let port = free_port();
    let out = topspin()
        .args(["identify", "--bind", &format!("127.0.0.1:{port}"), "--wait-s", "0.3", "--axis", "x", "--seconds", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.trim().lines().last().unwrap();
    assert!(last.starts_with("topspin: no request from the controller on 127.0.0.1:"), "{err}");
    // For scripts: the reason and the counters as JSON too.
    let out = topspin()
        .args(["identify", "--bind", &format!("127.0.0.1:{port}"), "--wait-s", "0.3", "--json", "--axis", "y"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(r["error"].as_str().unwrap().starts_with("no request from the controller"), "{r}");
    assert_eq!(
        (r["ended"].as_str(), r["requests"].as_u64(), r["lag_ms"].is_null()),
        (Some("no_request"), Some(0), true)
    );
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    for (args, says) in [
        (vec!["--bind", "nonsense"], "--bind nonsense"),
        (vec!["--axis", "w"], "'w' for '--axis"),
        (vec!["--amplitude-mm", "50"], "amplitude 50 mm"),
        (vec!["--amplitude-mm", "abc"], "--amplitude-mm"),
        (vec!["--seconds", "1"], "1 s: must be within"),
        (vec!["--wait-s", "0"], "--wait-s 0"),
        (vec!["--config", "/nonexistent/topspin.toml"], "/nonexistent/topspin.toml"),
        (vec!["--bind", "192.0.2.1:49152"], "RSI port 192.0.2.1:49152"),
    ] {
        let out = topspin().arg("identify").args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

#[test]
fn help_has_an_example() {
    let out = topspin().args(["identify", "--help"]).output().unwrap();
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    assert!(help.contains("Example") && help.contains("topspin identify --axis all"), "{help}");
}

#[test]
fn another_tool_is_refused_at_the_first_request_with_exit_2() {
    // The KRL program runs a TOOL_DATA 30 mm longer than calib/robot.toml's
    // bat: RIst is not the kinematics of AIPos, and nothing is moved.
    let (out, mock) = identify_against_mock(&["--axis", "x", "--seconds", "3"], |c| {
        c.controller.arm.geometry.tool.position.z += 0.03;
        let q = c.controller.start_joints;
        c.controller.stand_at(q);
    });
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.trim().lines().last().unwrap();
    assert!(last.contains("refused at the first request") && last.contains("most likely TOOL_DATA"), "{err}");
    assert!(last.contains("30.0 mm"), "{last}");
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(r["error"].as_str().unwrap().contains("TOOL_DATA"), "{r}");
    let start = mock.path.first().unwrap().commanded;
    assert!(mock.path.iter().all(|s| s.commanded == start), "the robot was not moved");
}
