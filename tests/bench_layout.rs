//! `topspin bench latency --layout` as a user runs it:
//! `dedicated` refused with exit 2 and one line where the process may use
//! too few cores (here under `taskset` to one CPU, so on any machine);
//! `shared` runs and its JSON names the layout and what each thread got;
//! the mock KR C4 and tracker threads of the loopback run are pinned where
//! asked, and a refusal is reported by thread, not fatal. No timing is
//! asserted (the figures are the bench's, docs/results.md, "The running system").

use std::process::Command;

use topspin_core::calib::Calibration;
use topspin_core::time::Duration;
use topspin_daemon::runtime::ThreadSpec;
use topspin_daemon::runtime::rt::{self, RtRefused, RtWarning};
use topspin_sim::demo::{DemoConfig, run_loopback};

fn topspin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_topspin"))
}

#[test]
fn dedicated_is_refused_in_one_line_where_cores_are_too_few() {
    let cpu = rt::allowed_cpus()[0];
    let has_taskset = Command::new("taskset").arg("--version").output().is_ok_and(|o| o.status.success());
    for json in [false, true] {
        let mut c = if has_taskset {
            let mut c = Command::new("taskset");
            c.args(["-c", &cpu.to_string(), env!("CARGO_BIN_EXE_topspin")]);
            c
        } else if rt::allowed_cpus().len() < 6 {
            topspin()
        } else {
            eprintln!("SKIPPED dedicated_is_refused_in_one_line_where_cores_are_too_few: no taskset and 6+ CPUs");
            return;
        };
        c.args(["bench", "latency", "--layout", "dedicated", "--duration", "2"]);
        if json {
            c.arg("--json");
        }
        let out = c.output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(out.stdout.is_empty(), "{}", String::from_utf8_lossy(&out.stdout));
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.starts_with("topspin: --layout dedicated needs 6 physical cores"), "{stderr}");
        if has_taskset {
            assert!(
                stderr.contains(&format!("this process may use 1 CPU(s) ({cpu}) on 1 physical core(s)")),
                "{stderr}"
            );
        }
    }
}

#[test]
fn shared_runs_and_says_what_each_thread_got() {
    let out = topspin().args(["bench", "latency", "--duration", "2", "--json"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["layout"], "shared");
    assert!(r["cores"].is_null(), "{r}");
    assert_eq!(r["rsi_wait"], "Blocking");
    assert_eq!(r["estimator_busy_poll"], false);
    let allowed: Vec<u64> = rt::allowed_cpus().into_iter().map(|c| c as u64).collect();
    assert_eq!(r["cpus_allowed"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).collect::<Vec<_>>(), allowed);
    for t in ["rsi", "estimator", "ingest", "telemetry", "mock-krc", "tracker"] {
        assert_eq!(r["threads"][t]["sched"], "SCHED_OTHER", "{t}: {r}");
        assert!(r["threads"][t]["core"].is_null(), "{t}: {r}");
    }
    assert!(r["rsi_cycles"].as_u64().unwrap() > 0, "{r}");
}

#[test]
fn the_mock_and_tracker_threads_are_pinned_where_asked() {
    let cpus = rt::allowed_cpus();
    let cfg = DemoConfig {
        balls: 2,
        gap: 1.2,
        answer_deadline: Some(Duration::from_millis(50)),
        mock_thread: ThreadSpec { core: Some(*cpus.last().unwrap()), priority: None },
        // No such CPU: refused, reported, and the run goes on.
        tracker_thread: ThreadSpec { core: Some(100_000), priority: None },
        ..DemoConfig::default()
    };
    let r = run_loopback(&cfg, &Calibration::default_cell()).unwrap();
    assert_eq!(r.mock.rt_warnings, []);
    assert_eq!(r.tracker_warnings, [RtWarning { thread: "tracker", what: RtRefused::Pin { core: 100_000 } }]);
    assert!(r.daemon.ingest.accepted > 0, "the tracker streamed from its own thread");
    assert!(r.mock.cycles > 0);
}
