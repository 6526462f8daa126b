//! `topspin mock-krc`: the mock KR C4 on the command line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use topspin_daemon::calib_files::CalibDir;

use anyhow::Context;
use clap::Args;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::rsi::Correction;
use topspin_core::time::Duration;
use topspin_sim::mock_krc::{ContextConfig, EthernetConfig, rsi_files};
use topspin_sim::mock_krc::{CorrMode, Faults, MockKrcConfig};

#[derive(Debug, Args)]
pub struct MockKrcArgs {
    /// The mock's own address.
    #[arg(long, default_value = "0.0.0.0:0")]
    pub bind: SocketAddr,
    /// The sensor's address (default: IP_NUMBER:PORT of the Ethernet XML).
    #[arg(long)]
    pub to: Option<SocketAddr>,
    /// Folder with topspin_ethernet.xml and topspin.rsi.xml (with
    /// --correction axis: topspin_axis_ethernet.xml and
    /// topspin_axis.rsi.xml); default: the compiled-in rsi/.
    #[arg(long)]
    pub rsi_dir: Option<PathBuf>,
    /// The RSI context the controller runs: `cartesian` (RKorr into
    /// POSCORR) or `axis` (AKorr into AXISCORR, AXISCORRMON). An answer
    /// with the other correction is held (HOLDON) and counted
    /// (`wrong_kind`).
    #[arg(long, default_value = "cartesian", value_parser = parse_correction)]
    pub correction: Correction,
    /// One JSON object with the run's counters instead of the line.
    #[arg(long)]
    pub json: bool,
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
    /// Where the arm stands when RSI starts: joints A1..A6, degrees,
    /// comma-separated (default: the calibration's home).
    #[arg(long, value_name = "A1,..,A6", value_parser = parse_six, allow_hyphen_values = true)]
    pub start_joints: Option<[f64; 6]>,
    /// Or the pose it stands at: X,Y,Z (mm), A,B,C (degrees) in BASE; the
    /// joints are its solution nearest --start-joints (default: home).
    #[arg(long, value_name = "X,Y,Z,A,B,C", value_parser = parse_six, allow_hyphen_values = true)]
    pub start_pose: Option<[f64; 6]>,
    /// The KRL program's TOOL_DATA (X,Y,Z mm, A,B,C degrees in the flange
    /// frame; default: calib/robot.toml's bat): RIst is its TCP.
    #[arg(long, value_name = "X,Y,Z,A,B,C", value_parser = parse_six, allow_hyphen_values = true)]
    pub tool_data: Option<[f64; 6]>,
    /// The KRL program's BASE_DATA relative to the robot's foot (default:
    /// the foot itself): RIst and the corrections are in it.
    #[arg(long, value_name = "X,Y,Z,A,B,C", value_parser = parse_six, allow_hyphen_values = true)]
    pub base_data: Option<[f64; 6]>,
    /// Brakes applied at cycle N for M cycles (an operator stop, the load
    /// check): the axes stand while RSI goes on.
    #[arg(long, value_name = "N:M", value_parser = parse_brakes)]
    pub brakes: Option<topspin_sim::mock_krc::Brakes>,
}

/// Six comma-separated numbers.
pub(crate) fn parse_six(s: &str) -> Result<[f64; 6], String> {
    let v: Vec<f64> =
        s.split(',').map(|x| x.trim().parse::<f64>().map_err(|e| format!("{x:?}: {e}"))).collect::<Result<_, _>>()?;
    let v: [f64; 6] = v.try_into().map_err(|v: Vec<f64>| format!("{} numbers, not 6", v.len()))?;
    if v.iter().all(|x| x.is_finite()) { Ok(v) } else { Err("not finite".into()) }
}

fn parse_brakes(s: &str) -> Result<topspin_sim::mock_krc::Brakes, String> {
    let (n, m) = s.split_once(':').ok_or("N:M (the first braked cycle, how many)")?;
    let at_cycle = n.trim().parse().map_err(|e| format!("{n:?}: {e}"))?;
    let cycles = m.trim().parse().map_err(|e| format!("{m:?}: {e}"))?;
    Ok(topspin_sim::mock_krc::Brakes { at_cycle, cycles })
}

/// A KUKA frame (mm, degrees) as a pose.
fn frame(v: [f64; 6]) -> topspin_core::kinematics::Pose {
    topspin_core::rsi::KukaPose::from_array(v).to_pose()
}

pub(crate) fn parse_correction(s: &str) -> Result<Correction, String> {
    s.parse().map_err(|e| format!("{s:?}: {e}"))
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
    let [(eth_name, eth_text), (ctx_name, ctx_text)] = rsi_files(a.correction);
    let eth = EthernetConfig::parse(&read(&a.rsi_dir, eth_name, eth_text)?)
        .map_err(|e| BadInput(format!("{eth_name}: {e}")))?;
    let ctx = ContextConfig::parse(&read(&a.rsi_dir, ctx_name, ctx_text)?)
        .map_err(|e| BadInput(format!("{ctx_name}: {e}")))?;
    ctx.check_feeds(&eth).map_err(|e| BadInput(format!("{ctx_name}: {e}")))?;
    if eth.correction() != a.correction {
        return Err(
            BadInput(format!("{eth_name}: receives {}, not --correction {}", eth.correction(), a.correction)).into()
        );
    }
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
    let c = &mut cfg.controller;
    if let Some(t) = a.tool_data {
        c.arm.geometry.tool = frame(t);
    }
    if let Some(b) = a.base_data {
        c.base = frame(b);
    }
    c.brakes = a.brakes;
    let near = a.start_joints.map(topspin_core::kinematics::Joints::from_degrees).unwrap_or(c.start_joints);
    match a.start_pose {
        Some(p) => {
            let pose = c.base.compose(&frame(p));
            let q = c.arm.inverse_near(&pose, &near).map_err(|e| BadInput(format!("--start-pose: {e}")))?;
            c.start = p;
            c.start_joints = q;
        }
        None if a.start_joints.is_some() || a.tool_data.is_some() || a.base_data.is_some() => c.stand_at(near),
        None => {}
    }
    cfg.faults = Faults {
        drop: a.drop,
        delay: a.delay,
        delay_by: Duration::from_millis(a.delay_ms),
        duplicate: a.duplicate,
        reorder: a.reorder,
    };
    eprintln!(
        "mock-krc: sending <Rob> every {} ms to {} ({:?}, {} correction, SENTYPE {})",
        a.cycle_ms, cfg.sensor, a.mode, a.correction, eth.sentype
    );
    let stop = AtomicBool::new(false);
    let r = topspin_sim::mock_krc::run(&cfg, &stop).context("mock KR C4")?;
    if let Some(p) = &a.csv {
        r.write_csv(p).with_context(|| format!("writing {}", p.display()))?;
    }
    if a.json {
        let v = serde_json::json!({
            "correction": a.correction.key(),
            "cycles": r.cycles,
            "late": r.late,
            "wrong_ipoc": r.wrong_ipoc,
            "wrong_type": r.wrong_type,
            "wrong_kind": r.wrong_kind,
            "malformed": r.malformed,
            "poscorr_clamped": r.poscorr_clamped,
            "axiscorr_clamped": r.axiscorr_clamped,
            "akorr_range_deg": r.akorr_range_deg,
            "max_answer_delay_us": r.max_answer_delay.0 / 1000,
            "peak_speed_share": r.peak_speed_share,
            "peak_acceleration_share": r.peak_acceleration_share,
            "rates_over": r.rates_over,
            "stopped": r.stopped.map(|s| s.key()),
            "stop_reason": r.stopped.map(|s| s.to_string()),
        });
        println!("{v}");
        return Ok(());
    }
    println!(
        "cycles {} late {} stopped_by_limit {} stopped_by_monitor {} wrong_ipoc {} wrong_kind {} poscorr_clamped {} \
         axiscorr_clamped {} max_answer_delay_us {} peak_axis_speed {:.0}% peak_axis_acceleration {:.0}% stopped: {}",
        r.cycles,
        r.late,
        r.stopped_by_limit,
        r.stopped_by_monitor,
        r.wrong_ipoc,
        r.wrong_kind,
        r.poscorr_clamped,
        r.axiscorr_clamped,
        r.max_answer_delay.0 / 1000,
        r.peak_speed_share * 100.0,
        r.peak_acceleration_share * 100.0,
        r.stopped.map_or("no".to_owned(), |s| s.to_string()),
    );
    Ok(())
}
