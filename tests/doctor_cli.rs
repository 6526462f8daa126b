//! `topspin doctor` as a user runs it on this machine: the JSON report
//! holds every check once with a valid status and a summary and exit code
//! that agree with them; the text report has one line per check; a
//! configuration that cannot work exits 1 naming the failed checks; an
//! unusable configuration or argument exits 2 with one line. Whatever
//! this machine's verdicts are, they must be consistent: no status or
//! timing is asserted.

use std::process::{Command, Output};

use topspin_daemon::doctor::CHECKS;

fn topspin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_topspin"));
    // The report must come from the file given, not from a developer's environment.
    for (k, _) in std::env::vars().filter(|(k, _)| k.starts_with("TOPSPIN_")) {
        c.env_remove(k);
    }
    c
}

fn config(dir: &tempfile::TempDir, text: &str) -> String {
    let p = dir.path().join("topspin.toml");
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_owned()
}

fn json(out: &Output) -> serde_json::Value {
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

/// Every check once, in order, with a status, a detail and a fix exactly
/// where it did not pass; the summary counts them; the exit code follows.
fn assert_consistent(out: &Output) -> serde_json::Value {
    let r = json(out);
    let checks = r["checks"].as_array().expect("checks");
    let names: Vec<&str> = checks.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(names, CHECKS, "{r:#}");
    let mut counts = [0u64; 3];
    for c in checks {
        let status = c["status"].as_str().unwrap();
        let i = ["pass", "warn", "fail"].iter().position(|s| *s == status).unwrap_or_else(|| panic!("status {status}"));
        counts[i] += 1;
        assert!(!c["detail"].as_str().unwrap().is_empty(), "{c}");
        assert_eq!(c["fix"].is_string(), status != "pass", "a fix exactly where it did not pass: {c}");
    }
    assert_eq!(
        [&r["summary"]["pass"], &r["summary"]["warn"], &r["summary"]["fail"]].map(|v| v.as_u64().unwrap()),
        counts,
        "{r:#}"
    );
    assert_eq!(out.status.code(), Some(if counts[2] > 0 { 1 } else { 0 }), "{r:#}");
    r
}

#[test]
fn json_report_on_this_machine_is_complete_and_consistent() {
    let out = topspin().args(["doctor", "--json", "--probe-seconds", "0.3"]).output().unwrap();
    let r = assert_consistent(&out);
    // The probe ran (75 deadlines of 4 ms), or said why not.
    let probe = r["checks"].as_array().unwrap().last().unwrap()["detail"].as_str().unwrap().to_owned();
    assert!(probe.contains("wake-ups every 4 ms") || probe.starts_with("not run: a topspin daemon runs"), "{probe}");
}

#[test]
fn text_report_has_one_line_per_check_then_the_counts() {
    let out = topspin().args(["doctor", "--no-probe"]).output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), CHECKS.len() + 1, "{text}");
    for (line, name) in lines.iter().zip(CHECKS) {
        let mut words = line.split_whitespace();
        let status = words.next().unwrap();
        assert!(["PASS", "WARN", "FAIL"].contains(&status), "{line}");
        assert_eq!(words.next(), Some(name), "{line}");
        assert_eq!(line.contains("  fix: "), status != "PASS", "{line}");
    }
    assert!(lines.last().unwrap().ends_with(" fail"), "{text}");
    assert!(text.contains("WARN  jitter_probe   not run (--no-probe)"), "{text}");
}

#[test]
fn a_configuration_that_cannot_work_fails_naming_the_checks() {
    // A core no PC has and an address from TEST-NET-1 that no NIC holds.
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(&dir, "[threads]\nrsi_core = 1023\n[network]\nrsi_bind = \"192.0.2.1:49152\"\n");
    let out = topspin().args(["doctor", "--json", "--no-probe", "--config", &cfg]).output().unwrap();
    let r = assert_consistent(&out);
    assert_eq!(out.status.code(), Some(1));
    let status = |name: &str| r["checks"].as_array().unwrap().iter().find(|c| c["name"] == name).unwrap().clone();
    assert_eq!(status("cores")["status"], "fail", "{r:#}");
    assert!(status("cores")["detail"].as_str().unwrap().starts_with("threads.rsi_core = 1023: no such core online"));
    assert_eq!(status("addresses")["status"], "fail", "{r:#}");
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.starts_with("topspin: not ready for the 4 ms loop: cores, ") && err.contains("addresses"), "{err}");
}

#[test]
fn unusable_input_exits_2_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let bad_key = config(&dir, "[threads]\nrsi_cor = 1\n");
    for (args, names) in [
        (vec!["doctor", "--config", "/nonexistent/topspin.toml"], "/nonexistent/topspin.toml"),
        (vec!["doctor", "--config", &bad_key], "threads.rsi_cor"),
        (vec!["doctor", "--probe-seconds", "0"], "--probe-seconds"),
        (vec!["doctor", "--probe-seconds", "nan"], "--probe-seconds"),
    ] {
        let out = topspin().args(&args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(names), "{args:?}: {err}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
}

#[test]
fn help_names_the_thresholds_and_an_example() {
    let out = topspin().args(["doctor", "--help"]).output().unwrap();
    assert!(out.status.success());
    let help = String::from_utf8(out.stdout).unwrap();
    for needle in
        ["--probe-seconds", "--no-probe", "--json", "p99.9 <= 100 us", "max <= 1 ms", "4 ms or more late", "Examples:"]
    {
        assert!(help.contains(needle), "{needle}: {help}");
    }
}
