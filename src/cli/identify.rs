//! `topspin identify`: the sensor side of a short, safe excitation over RSI
//! that measures the robot's dead time and servo lag from `RIst` and
//! prints them with the lines for `calib/robot.toml` (`[servo]`). The
//! protocol and the fit are `topspin_core::rsi::identify`; the socket loop
//! is `topspin_daemon::rsi_identify`.

use std::fmt::Write as _;
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use topspin_daemon::calib_files::CalibDir;

use clap::Args;
use serde::Serialize;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::rsi::identify::{
    AxisChoice, Excitation, ExcitationConfig, Identification, Identifier, IdentifierConfig, excitation,
};
use topspin_core::time::Duration;
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::rsi_identify::{self, IdentifyLoop, LoopEnd, LoopOutcome, Progress};

/// No request for this long ends the run, s.
pub(crate) const SILENCE_S: f64 = 0.5;

/// `topspin identify`.
#[derive(Debug, Args)]
#[command(after_help = "Example (T1, reduced override, `topspin_rsi.src` selected; start this first):\n  \
    topspin identify --axis all --amplitude-mm 3 --seconds 12\n  \
    topspin identify --bind 192.168.1.2:49152 --axis z --json > servo.json")]
pub struct IdentifyArgs {
    /// Bind here instead of the configured `network.rsi_bind` (IP:PORT of
    /// rsi/topspin_ethernet.xml).
    #[arg(long)]
    pub bind: Option<String>,
    /// Largest correction on the moving axis, mm (0.5 to 10).
    #[arg(long, default_value_t = excitation::DEFAULT_AMPLITUDE_MM)]
    pub amplitude_mm: f64,
    /// Axis to excite in BASE (`all`: one after the other).
    #[arg(long, value_enum, default_value_t = AxisArg::All)]
    pub axis: AxisArg,
    /// Length of the excitation, s (split between the axes).
    #[arg(long, default_value_t = 12.0)]
    pub seconds: f64,
    /// How long to wait for the controller's first request, s.
    #[arg(long, default_value_t = 60.0)]
    pub wait_s: f64,
    /// Zero held after the excitation before topspin stops answering, s.
    #[arg(long, default_value_t = 1.0)]
    pub hold_s: f64,
    /// Configuration file (network.rsi_bind, controller_source, rsi.sentype,
    /// calib.dir); layered as `topspin run`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// One JSON object instead of the text report.
    #[arg(long)]
    pub json: bool,
}

/// `--json`: the result (or, on failure, `error` and the counters).
#[derive(Debug, Default, Serialize)]
struct Report {
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    dead_time_ms: Option<f64>,
    dead_time_cycles: Option<usize>,
    dead_time_std_ms: Option<f64>,
    dead_time_runner_up_cycles: Option<usize>,
    dead_time_runner_up_ratio: Option<f64>,
    lag_ms: Option<f64>,
    lag_std_ms: Option<f64>,
    lag_ms_per_axis: Option<[Option<f64>; 3]>,
    gain: Option<[Option<f64>; 3]>,
    rms_mm: Option<f64>,
    fit_percent: Option<f64>,
    residual_correlation: Option<f64>,
    rss_by_dead_time_mm2: Option<Vec<f64>>,
    rist_noise_mm: Option<f64>,
    /// Request → the answered pose in RIst, with no dead time and no lag.
    pipeline_ms: u32,
    cycle_ms: u32,
    cycles: usize,
    gaps: usize,
    late: usize,
    requests: u64,
    ipoc_repeats: u64,
    stale: u64,
    restarts: u64,
    malformed: u64,
    foreign: u64,
    max_answer_latency_us: u64,
    start_pose: Option<[f64; 6]>,
    off_home: Option<bool>,
    axes: String,
    amplitude_mm: f64,
    seconds: f64,
    ended: &'static str,
    calib_toml: Option<String>,
    /// `[servo]` of the calibration in use, for comparison.
    calib_now: Option<ServoNow>,
}

#[derive(Debug, Serialize)]
struct ServoNow {
    dead_time_ms: f64,
    lag_ms: f64,
}

/// `--axis x|y|z|all`.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AxisArg {
    /// BASE x.
    X,
    /// BASE y.
    Y,
    /// BASE z.
    Z,
    /// x, y and z, one after the other.
    All,
}

impl AxisArg {
    fn choice(self) -> AxisChoice {
        match self {
            AxisArg::X => AxisChoice::X,
            AxisArg::Y => AxisChoice::Y,
            AxisArg::Z => AxisChoice::Z,
            AxisArg::All => AxisChoice::All,
        }
    }

    fn name(self) -> &'static str {
        match self {
            AxisArg::X => "x",
            AxisArg::Y => "y",
            AxisArg::Z => "z",
            AxisArg::All => "all",
        }
    }
}

fn positive(name: &str, v: f64) -> Result<(), BadInput> {
    if v.is_finite() && v > 0.0 { Ok(()) } else { Err(BadInput(format!("{name} {v}: must be a positive number"))) }
}

fn secs(s: f64) -> Duration {
    Duration((s * 1e9) as u64)
}

/// The `[servo]` lines for `calib/robot.toml`.
fn calib_toml(r: &Identification) -> String {
    format!("[servo]\ndead_time_ms = {:.1}\nlag_ms = {:.1}\n", r.dead_time_ms, r.lag_ms)
}

/// Runs `topspin identify`.
pub fn run(a: IdentifyArgs) -> anyhow::Result<()> {
    let axes = a.axis.choice();
    positive("--wait-s", a.wait_s)?;
    positive("--hold-s", a.hold_s)?;
    let cfg = DaemonConfig::load(a.config.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    let cal = Calibration::load(cfg.calib.dir()).map_err(|e| BadInput(e.to_string()))?;
    let bind: SocketAddr = match &a.bind {
        Some(b) => b.parse().map_err(|_| BadInput(format!("--bind {b}: not an address (IP:PORT)")))?,
        None => cfg.network.rsi_bind,
    };
    let cycle_ms = cal.robot.rsi.cycle_ms;
    let exc = Excitation::new(ExcitationConfig { amplitude_mm: a.amplitude_mm, axes, seconds: a.seconds, cycle_ms })
        .map_err(|e| BadInput(format!("identify: {e}")))?;
    // The controller's own clamp must let the excitation through.
    let pc = &cal.robot.poscorr;
    for (i, name) in ['x', 'y', 'z'].iter().enumerate().filter(|(i, _)| exc.excited()[*i]) {
        if pc.lower_xyz_mm[i] > -a.amplitude_mm || pc.upper_xyz_mm[i] < a.amplitude_mm {
            return Err(BadInput(format!(
                "--amplitude-mm {}: outside [poscorr] on {name} ({} .. {} mm) in robot.toml",
                a.amplitude_mm, pc.lower_xyz_mm[i], pc.upper_xyz_mm[i]
            ))
            .into());
        }
    }
    if pc.mon_max_trans_mm <= a.amplitude_mm {
        return Err(BadInput(format!(
            "--amplitude-mm {}: at or above POSCORRMON ({} mm) in robot.toml",
            a.amplitude_mm, pc.mon_max_trans_mm
        ))
        .into());
    }
    let mut id = Identifier::new(IdentifierConfig::from_calibration(&cal, &cfg.rsi.sentype), exc)
        .map_err(|e| BadInput(format!("identify: {e}")))?;
    let socket = UdpSocket::bind(bind).map_err(|e| BadInput(format!("RSI port {bind}: {e}")))?;
    let loop_cfg = IdentifyLoop {
        controller: Some(cfg.network.controller_source),
        wait_first: secs(a.wait_s),
        silence: secs(SILENCE_S),
        hold: secs(a.hold_s),
        realtime_priority: cfg.threads.realtime.then_some(cfg.threads.rsi_priority as i32),
    };
    let seconds = id.excitation().len() as f64 * cycle_ms as f64 * 1e-3;
    eprintln!(
        "identify: waiting up to {} s for the controller on {bind} ({} ±{} mm, {seconds:.1} s)",
        a.wait_s,
        a.axis.name(),
        a.amplitude_mm
    );
    let outcome = rsi_identify::run(&socket, &mut id, &loop_cfg, |p| match p {
        Progress::Started(from) => eprintln!("identify: controller {from}: exciting"),
        Progress::ExcitationDone => eprintln!("identify: excitation done, holding zero"),
    })?;
    if let Some(w) = &outcome.rt_warning {
        eprintln!("identify: warning: {w}");
    }
    let result = match outcome.end {
        LoopEnd::NoRequest => Err(no_request(bind, a.wait_s, &outcome)),
        _ => id.finish().map_err(|e| format!("identification failed: {e}")),
    };
    let mut report = base_report(&a, &id, &outcome, cycle_ms);
    let servo = &cal.robot.servo;
    report.calib_now = Some(ServoNow { dead_time_ms: servo.dead_time_ms, lag_ms: servo.lag_ms });
    match result {
        Ok(r) => {
            fill(&mut report, &r);
            if a.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                print!("{}", text(&a, &r));
                println!(
                    "(the calibration in use has dead_time_ms = {:.1}, lag_ms = {:.1})",
                    servo.dead_time_ms, servo.lag_ms
                );
            }
            Ok(())
        }
        Err(reason) => {
            if a.json {
                report.error = Some(reason.clone());
                println!("{}", serde_json::to_string_pretty(&report)?);
            }
            // Another TOOL or BASE than the calibration is the cell's
            // configuration, not a failed measurement: exit 2.
            if matches!(id.finish(), Err(topspin_core::rsi::identify::IdentifyError::Frames(_))) {
                return Err(BadInput(format!("identify refused at the first request: {reason}")).into());
            }
            Err(anyhow::anyhow!(reason))
        }
    }
}

fn no_request(bind: SocketAddr, wait_s: f64, o: &LoopOutcome) -> String {
    let mut s = format!("no request from the controller on {bind} within {wait_s} s");
    if let Some(f) = o.foreign_from {
        let _ = write!(s, " ({} from {f}, not network.controller_source: ignored)", o.foreign);
    }
    s
}

fn base_report(a: &IdentifyArgs, id: &Identifier, o: &LoopOutcome, cycle_ms: u32) -> Report {
    let s = id.stats();
    let (trace, late) = id.trace();
    Report {
        pipeline_ms: cycle_ms,
        cycle_ms,
        cycles: trace.u.len(),
        gaps: trace.y.iter().filter(|y| y.is_none()).count(),
        late,
        requests: s.requests,
        ipoc_repeats: s.ipoc_repeats,
        stale: s.stale,
        restarts: s.restarts,
        malformed: s.malformed,
        foreign: o.foreign,
        max_answer_latency_us: s.max_latency.0 / 1000,
        axes: a.axis.name().to_owned(),
        amplitude_mm: a.amplitude_mm,
        seconds: id.excitation().len() as f64 * cycle_ms as f64 * 1e-3,
        ended: match o.end {
            LoopEnd::NoRequest => "no_request",
            LoopEnd::ControllerSilent => "controller_silent",
            LoopEnd::HoldElapsed => "hold_elapsed",
        },
        ..Report::default()
    }
}

fn fill(rep: &mut Report, r: &Identification) {
    let f = &r.fit;
    rep.dead_time_ms = Some(r.dead_time_ms);
    rep.dead_time_cycles = Some(f.dead_time_cycles);
    rep.dead_time_std_ms = Some(r.dead_time_std_ms);
    rep.dead_time_runner_up_cycles = Some(f.runner_up_cycles);
    rep.dead_time_runner_up_ratio = Some(f.runner_up_ratio).filter(|x| x.is_finite());
    rep.lag_ms = Some(r.lag_ms);
    rep.lag_std_ms = Some(r.lag_std_ms);
    rep.lag_ms_per_axis = Some(f.lag_s_per_axis.map(|t| t.map(|t| t * 1e3)));
    rep.gain = Some(f.gain);
    rep.rms_mm = Some(f.rms_mm);
    rep.fit_percent = Some(f.fit_percent);
    rep.residual_correlation = Some(f.residual_correlation);
    rep.rss_by_dead_time_mm2 = Some(f.rss_by_dead_time.clone());
    rep.rist_noise_mm = Some(r.rist_noise_mm);
    rep.start_pose = Some(r.start_pose.to_array());
    rep.off_home = Some(r.off_home);
    rep.cycles = r.cycles;
    rep.gaps = r.gaps;
    rep.late = r.late;
    rep.calib_toml = Some(calib_toml(r));
}

fn text(a: &IdentifyArgs, r: &Identification) -> String {
    let f = &r.fit;
    let mut s = String::new();
    let per_axis = |v: [Option<f64>; 3], scale: f64, prec: usize| {
        ['x', 'y', 'z']
            .iter()
            .zip(v)
            .filter_map(|(n, x)| x.map(|x| format!("{n} {:.*}", prec, x * scale)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = writeln!(
        s,
        "topspin identify: {} cycles of {} ms ({} ±{} mm), {} without RIst, {} answers not applied (late)",
        r.cycles,
        r.cycle_ms,
        a.axis.name(),
        a.amplitude_mm,
        r.gaps,
        r.late
    );
    let ratio = if f.runner_up_ratio.is_finite() { format!("{:.2}×", f.runner_up_ratio) } else { "∞×".to_owned() };
    let _ = writeln!(
        s,
        "  dead time  {:.1} ms ± {:.1} ms ({} cycles after the one-cycle pipeline; runner-up {} cycles at {ratio} the residual)",
        r.dead_time_ms, r.dead_time_std_ms, f.dead_time_cycles, f.runner_up_cycles
    );
    let _ = writeln!(
        s,
        "  lag        {:.1} ms ± {:.1} ms (per axis: {} ms)",
        r.lag_ms,
        r.lag_std_ms,
        per_axis(f.lag_s_per_axis, 1e3, 1)
    );
    let _ = writeln!(
        s,
        "  fit        {:.1} %, rms {:.3} mm, RIst noise {:.3} mm, gain {}",
        f.fit_percent,
        f.rms_mm,
        r.rist_noise_mm,
        per_axis(f.gain, 1.0, 3)
    );
    let _ =
        writeln!(s, "  request → RIst: {} ms pipeline + {:.1} ms dead time, then the lag", r.cycle_ms, r.dead_time_ms);
    if r.off_home {
        let p = r.start_pose;
        let _ = writeln!(s, "  ! the start pose ({:.1}, {:.1}, {:.1}) mm is off the calibrated home", p.x, p.y, p.z);
    }
    let _ = writeln!(s, "\nfor calib/robot.toml:\n{}", calib_toml(r));
    s
}
