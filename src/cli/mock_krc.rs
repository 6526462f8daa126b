//! `topspin mock-krc`: the mock KR C4 on the command line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use anyhow::Context;
use clap::Args;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::time::Duration;
use topspin_sim::mock_krc::config::{ContextConfig, DEFAULT_CONTEXT_XML, DEFAULT_ETHERNET_XML, EthernetConfig};
use topspin_sim::mock_krc::{CorrMode, Faults, MockKrcConfig};

#[derive(Debug, Args)]
pub struct MockKrcArgs {
    /// The mock's own address.
    #[arg(long, default_value = "0.0.0.0:0")]
    pub bind: SocketAddr,
    /// The sensor's address (default: IP_NUMBER:PORT of the Ethernet XML).
    #[arg(long)]
    pub to: Option<SocketAddr>,
    /// Folder with topspin_ethernet.xml and topspin.rsi.xml (default: the
    /// compiled-in rsi/).
    #[arg(long)]
    pub rsi_dir: Option<PathBuf>,
    /// Calibration folder (robot.toml: home, limits).
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Sensor cycle in ms: 4 (#IPO_FAST) or 12 (#IPO).
    #[arg(long, default_value_t = 4)]
    pub cycle_ms: u32,
    #[arg(long, value_enum, default_value = "absolute")]
    pub mode: CorrMode,
    /// Late answers before RSI stops (default: Timeout of the context).
    #[arg(long)]
    pub late_limit: Option<u64>,
    /// Run this many cycles (default: until interrupted).
    #[arg(long)]
    pub cycles: Option<u64>,
    /// Drop this fraction of answers.
    #[arg(long, default_value_t = 0.0)]
    pub drop: f64,
    /// Delay this fraction of answers by --delay-ms.
    #[arg(long, default_value_t = 0.0)]
    pub delay: f64,
    #[arg(long, default_value_t = 6)]
    pub delay_ms: u64,
    /// Duplicate this fraction of answers.
    #[arg(long, default_value_t = 0.0)]
    pub duplicate: f64,
    /// Send this fraction of requests after the next one (reordered).
    #[arg(long, default_value_t = 0.0)]
    pub reorder: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The robot's dead time, ms, whole cycles (default: calib/robot.toml
    /// [servo] dead_time_ms).
    #[arg(long)]
    pub dead_time_ms: Option<f64>,
    /// The axes' first-order lag, ms (default: [servo] lag_ms).
    #[arg(long)]
    pub lag_ms: Option<f64>,
    /// Write the TCP path here (CSV).
    #[arg(long)]
    pub csv: Option<PathBuf>,
}

fn read(dir: &Option<PathBuf>, name: &str, default: &str) -> anyhow::Result<String> {
    match dir {
        Some(d) => std::fs::read_to_string(d.join(name))
            .map_err(|e| BadInput(format!("{}: {e}", d.join(name).display())).into()),
        None => Ok(default.to_owned()),
    }
}

pub fn run(a: MockKrcArgs) -> anyhow::Result<()> {
    let calib = Calibration::load(a.calib.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    let eth = EthernetConfig::parse(&read(&a.rsi_dir, "topspin_ethernet.xml", DEFAULT_ETHERNET_XML)?)
        .map_err(|e| BadInput(e.to_string()))?;
    let ctx = ContextConfig::parse(&read(&a.rsi_dir, "topspin.rsi.xml", DEFAULT_CONTEXT_XML)?)
        .map_err(|e| BadInput(e.to_string()))?;
    if a.cycle_ms != 4 && a.cycle_ms != 12 {
        return Err(BadInput("--cycle-ms must be 4 or 12".into()).into());
    }
    for (name, p) in [("--drop", a.drop), ("--delay", a.delay), ("--duplicate", a.duplicate), ("--reorder", a.reorder)]
    {
        if !(0.0..=1.0).contains(&p) {
            return Err(BadInput(format!("{name} must be within 0..1")).into());
        }
    }
    let mut robot = calib.robot.clone();
    robot.rsi.cycle_ms = a.cycle_ms;
    if let Some(d) = a.dead_time_ms {
        robot.servo.dead_time_ms = d;
    }
    if let Some(l) = a.lag_ms {
        robot.servo.lag_ms = l;
    }
    robot.validate().map_err(|e| BadInput(format!("--dead-time-ms/--lag-ms/--cycle-ms: {} = {}", e.key, e.value)))?;
    let mut cfg = MockKrcConfig::from_files(&eth, &ctx, &robot, a.mode, 1.02);
    cfg.bind = a.bind;
    if let Some(to) = a.to {
        cfg.sensor = to;
    }
    if let Some(l) = a.late_limit {
        cfg.controller.late_limit = l.max(1);
    }
    cfg.cycles = a.cycles;
    cfg.seed = a.seed;
    cfg.faults = Faults {
        drop: a.drop,
        delay: a.delay,
        delay_by: Duration::from_millis(a.delay_ms),
        duplicate: a.duplicate,
        reorder: a.reorder,
    };
    eprintln!(
        "mock-krc: sending <Rob> every {} ms to {} ({:?}, SENTYPE {})",
        a.cycle_ms, cfg.sensor, a.mode, eth.sentype
    );
    let stop = AtomicBool::new(false);
    let r = topspin_sim::mock_krc::run(&cfg, &stop).context("mock KR C4")?;
    println!(
        "cycles {} late {} stopped_by_limit {} stopped_by_monitor {} wrong_ipoc {} poscorr_clamped {} max_answer_delay_us {} \
         peak_axis_speed {:.0}% peak_axis_acceleration {:.0}% stopped: {}",
        r.cycles,
        r.late,
        r.stopped_by_limit,
        r.stopped_by_monitor,
        r.wrong_ipoc,
        r.poscorr_clamped,
        r.max_answer_delay.0 / 1000,
        r.peak_speed_share * 100.0,
        r.peak_acceleration_share * 100.0,
        r.stopped.map_or("no".to_owned(), |s| s.to_string()),
    );
    if let Some(p) = a.csv {
        r.write_csv(&p).with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}
