//! `topspin doctor`: is this PC ready for a 4 ms RSI loop? One line per
//! check (`PASS|WARN|FAIL  name  detail  fix: …`) or one JSON object, from
//! [`topspin_daemon::doctor`]. Exit 0 when nothing failed, 1 when a check
//! failed, 2 for an unusable configuration or argument.

use std::path::PathBuf;
use topspin_daemon::calib_files::CalibDir;

use clap::Args;

use super::BadInput;
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::doctor::{self, Host, probe};

/// `topspin doctor`.
#[derive(Debug, Args)]
#[command(after_long_help = AFTER_HELP, after_help = AFTER_HELP)]
pub struct DoctorArgs {
    /// Configuration file (its cores, priorities, wait strategy and
    /// addresses); layered as `topspin run`.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// One JSON object: {"checks": [{"name", "status", "detail", "fix"}], "summary": {"pass", "warn", "fail"}}.
    #[arg(long)]
    pub json: bool,
    /// How long the wake-up jitter probe runs on the RSI core, s.
    #[arg(long, value_name = "S", default_value_t = probe::DEFAULT_SECONDS)]
    pub probe_seconds: f64,
    /// Skip the jitter probe (reported as a warning).
    #[arg(long)]
    pub no_probe: bool,
    /// Also listen this long (s) on network.rsi_bind for the controller's
    /// RSI requests (answered with zero corrections: nothing moves) and
    /// judge the arm's start: home, off home (the daemon goes home at the
    /// commissioning speed), or refused (another TOOL_DATA/BASE_DATA, an
    /// unsafe way home).
    #[arg(long, value_name = "S")]
    pub robot_wait: Option<f64>,
    /// Calibration folder for --robot-wait (default: the configuration's calib.dir).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
}

const AFTER_HELP: &str = "\
Checks (pass / warn / fail; nothing needs root, nothing is changed):
  kernel         PREEMPT_RT (pass) or another preemption model (warn)
  cores          configured cores online (fail if not), the RSI thread pinned, what shares its core
                 (fail: rsi_wait = busy_poll on a core another thread is pinned to)
  isolation      the RSI core in isolcpus= / a cpuset partition, nohz_full=
  smt            the RSI core's SMT siblings isolated and free of topspin's other threads
  governor       the hot cores' cpufreq governor is `performance`
  rtprio         SCHED_FIFO at the configured priorities allowed (RLIMIT_RTPRIO or CAP_SYS_NICE)
  memlock        mlockall allowed (RLIMIT_MEMLOCK unlimited or CAP_IPC_LOCK)
  rt_throttling  SCHED_FIFO gets CPU time (fail: sched_rt_runtime_us = 0)
  addresses      every bind address on an interface (fail if not), senders on local networks
  rsi_nic        the NIC holding network.rsi_bind: link up (fail if down), its IRQs on the RSI core
                 (blocking wait) or off it (busy_poll)
  swap           no swap, or memory locking allowed
  time_sync      the kernel clock is synchronised (chrony, ntpd, systemd-timesyncd, ptp4l)
  robot_start    (--robot-wait S only) the controller's first RSI request: the arm home (pass), off home
                 with a clear way home at commissioning speed (warn), RIst not the kinematics of AIPos
                 under calib/robot.toml's tool and base, or an unsafe way home (fail)
  jitter_probe   a thread on the RSI core at the RSI priority sleeps to absolute 4 ms deadlines
                 (clock_nanosleep) for --probe-seconds; wake-up lateness median / p99 / p99.9 / max:
                 pass  p99.9 <= 100 us (DESIGN §9's RSI answer budget) and max <= 1 ms (a quarter cycle)
                 warn  worse, every wake-up within the 4 ms cycle
                 fail  a wake-up 4 ms or more late (that cycle's answer would be late)
                 Skipped while a `topspin run` process is alive (it would compete with its RSI thread).

The limits and capabilities are this process's: run doctor as the service runs to see the service's
(docs/guide/doctor.md).

Exit code: 0 nothing failed, 1 a check failed, 2 an unusable configuration or argument.

Examples:
  topspin doctor --config /etc/topspin/topspin.toml
  topspin doctor --json --probe-seconds 30 | jq '.checks[] | select(.status != \"pass\")'";

/// Runs `topspin doctor`.
pub fn run(a: DoctorArgs) -> anyhow::Result<()> {
    if !(a.probe_seconds.is_finite() && (0.01..=3600.0).contains(&a.probe_seconds)) {
        return Err(BadInput(format!("--probe-seconds {}: must be between 0.01 and 3600", a.probe_seconds)).into());
    }
    let cfg = DaemonConfig::load(a.config.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    let mut report = doctor::diagnose(&Host::live(), &cfg, (!a.no_probe).then_some(a.probe_seconds));
    if let Some(w) = a.robot_wait {
        if !(w.is_finite() && (0.01..=600.0).contains(&w)) {
            return Err(BadInput(format!("--robot-wait {w}: must be between 0.01 and 600")).into());
        }
        let dir = a.calib.as_deref().or(cfg.calib.dir());
        let cal = topspin_core::calib::Calibration::load(dir).map_err(|e| BadInput(e.to_string()))?;
        let mut checks = report.checks;
        checks.push(doctor::robot::check(&cfg, &cal, w));
        report = doctor::Report::new(checks);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.text());
    }
    if report.exit_code() != 0 {
        let failed: Vec<&str> =
            report.checks.iter().filter(|c| c.status == doctor::Status::Fail).map(|c| c.name).collect();
        anyhow::bail!("not ready for the 4 ms loop: {} failed", failed.join(", "));
    }
    Ok(())
}
