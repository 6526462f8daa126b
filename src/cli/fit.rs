//! `topspin fit FILE`: spin and prediction for one recorded flight;
//! `topspin fit stream FILE`: the streaming estimator over a recording of
//! many balls (DESIGN §8). The older spelling `fit --stream FILE` still
//! works.

use std::path::{Path, PathBuf};
use topspin_daemon::calib_files::CalibDir;

use clap::{Args, Subcommand, ValueEnum};
use serde_json::{Value, json};

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::fit::{FitConfig, Method, Sample, TrajectoryFit, fit_trajectory};
use topspin_core::physics::{Vec3, rad_to_rps};

/// Which physics coefficients to use.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum PhysicsChoice {
    /// The calibrated coefficients of `calib/physics.toml`.
    Calibrated,
    /// The paper's constants (C_D 0.4, C_M 0.6, ρ 1.29; e 0.90, μ 0.25).
    Paper,
}

/// Which spin fit.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodChoice {
    /// The paper's polynomial + linear Magnus fit.
    Paper,
    /// The paper's fit refined with the flight model (default).
    Refined,
}

#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct FitArgs {
    #[command(subcommand)]
    pub command: Option<FitCommand>,
    /// CSV with header `t,x,y,z` (s, m, table frame; extra columns ignored).
    #[arg(required = true)]
    pub file: Option<PathBuf>,
    #[command(flatten)]
    pub opts: FitOptions,
    /// The older spelling of `topspin fit stream FILE`.
    #[arg(long, hide = true)]
    pub stream: bool,
}

/// `topspin fit stream`.
#[derive(Debug, Subcommand)]
pub enum FitCommand {
    /// The streaming estimator over a recording of many balls (e.g.
    /// `topspin sim`'s stream.csv): one plan per ball.
    Stream {
        /// CSV with header `t,x,y,z` (s, m, table frame; extra columns
        /// ignored).
        file: PathBuf,
        #[command(flatten)]
        opts: FitOptions,
    },
}

/// What both modes take.
#[derive(Debug, Args)]
pub struct FitOptions {
    /// Print one JSON object instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// The hitting plane x = X in m (default: calib/strike.toml). With
    /// `stream`, that plane alone, whether or not the arm reaches it
    /// (default: the hitting volume, within the arm's reach).
    #[arg(long, value_name = "X")]
    pub hit_plane_x: Option<f64>,
    /// Physics coefficients.
    #[arg(long, value_enum, default_value_t = PhysicsChoice::Calibrated)]
    pub physics: PhysicsChoice,
    /// Spin fit.
    #[arg(long, value_enum, default_value_t = MethodChoice::Refined)]
    pub method: MethodChoice,
    /// Another calibration folder (same file names as calib/).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// The tracker's per-axis noise in mm (sets the outlier thresholds).
    #[arg(long, default_value_t = 2.0, value_name = "MM")]
    pub noise_mm: f64,
}

/// Reads a `t,x,y,z` CSV (extra columns ignored).
pub fn read_samples(path: &Path) -> Result<Vec<Sample>, BadInput> {
    let file = std::fs::File::open(path).map_err(|e| BadInput(format!("{}: {e}", path.display())))?;
    parse_samples(std::io::BufReader::new(file), &path.display().to_string())
}

/// Parses a `t,x,y,z` CSV from any reader (extra columns ignored); `name`
/// prefixes the error. Every value must be a finite number. Never panics
/// (fuzzed: `fuzz/fuzz_targets/fit_csv.rs`).
pub fn parse_samples(input: impl std::io::Read, name: &str) -> Result<Vec<Sample>, BadInput> {
    let mut reader = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(input);
    let headers = reader.headers().map_err(|e| BadInput(format!("{name}: {}", io_reason(&e))))?.clone();
    let column = |key: &str| {
        headers
            .iter()
            .position(|h| h == key)
            .ok_or_else(|| BadInput(format!("{name}: header has no column `{key}` (expected t,x,y,z)")))
    };
    let cols = [column("t")?, column("x")?, column("y")?, column("z")?];
    let mut samples = Vec::new();
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| BadInput(format!("{name}: data row {row}: {e}")))?;
        let mut v = [0.0; 4];
        for (k, &c) in cols.iter().enumerate() {
            let text = record.get(c).unwrap_or("");
            v[k] = text
                .parse::<f64>()
                .map_err(|_| BadInput(format!("{name}: data row {row}: `{text}` is not a number")))?;
            if !v[k].is_finite() {
                return Err(BadInput(format!("{name}: data row {row}: non-finite value `{text}`")));
            }
        }
        samples.push(Sample::new(v[0], Vec3::new(v[1], v[2], v[3])));
    }
    Ok(samples)
}

fn io_reason(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::Io(io) => io.to_string(),
        _ => e.to_string(),
    }
}

/// Loads the calibration named by `--calib` and `--physics`.
pub fn load_calibration(dir: Option<&Path>, physics: PhysicsChoice) -> Result<Calibration, BadInput> {
    let cal = Calibration::load(dir).map_err(|e| BadInput(e.to_string()))?;
    Ok(match physics {
        PhysicsChoice::Calibrated => cal,
        PhysicsChoice::Paper => cal.with_paper_physics(),
    })
}

pub fn run(args: FitArgs) -> anyhow::Result<()> {
    let (file, args, stream) = match args.command {
        Some(FitCommand::Stream { file, opts }) => (file, opts, true),
        None => (args.file.expect("clap requires FILE without a subcommand"), args.opts, args.stream),
    };
    let cal = load_calibration(args.calib.as_deref(), args.physics)?;
    let hit_plane_x = args.hit_plane_x.unwrap_or(cal.strike.hit_plane_x);
    if !hit_plane_x.is_finite() {
        return Err(BadInput("--hit-plane-x must be finite".into()).into());
    }
    if !(args.noise_mm.is_finite() && args.noise_mm > 0.0) {
        return Err(BadInput("--noise-mm must be positive".into()).into());
    }
    let samples = read_samples(&file)?;
    if stream {
        return super::replay_stream::run(&samples, &cal, args.hit_plane_x, args.noise_mm * 1e-3, args.json);
    }
    let method = match args.method {
        MethodChoice::Paper => Method::Paper,
        MethodChoice::Refined => Method::Refined,
    };
    let cfg =
        FitConfig::new(method, hit_plane_x).with_noise(args.noise_mm * 1e-3).with_variation(cal.physics.variation);
    let fit =
        fit_trajectory(&samples, &cal.propagator(), &cfg).map_err(|e| BadInput(format!("{}: {e}", file.display())))?;
    if args.json {
        println!("{}", to_json(&fit, hit_plane_x));
    } else {
        print!("{}", summary(&fit, hit_plane_x));
    }
    Ok(())
}

fn v3(v: &Vec3) -> Value {
    json!([v.x, v.y, v.z])
}

/// The JSON object of DESIGN §8.
pub fn to_json(fit: &TrajectoryFit, hit_plane_x: f64) -> Value {
    let p = &fit.prediction;
    json!({
        "method": match fit.method { Method::Paper => "paper", Method::Refined => "refined" },
        "spin": v3(&fit.spin),
        "spin_rps": v3(&fit.spin.map(rad_to_rps)),
        "spin_std": fit.spin_std.as_ref().map(v3),
        "weak_axis": fit.weak_axis.map(|(axis, std)| json!({"axis": v3(&axis), "std": if std.is_finite() { json!(std) } else { Value::Null }})),
        "lift_scale": fit.scales.map(|(s, _)| s.lift),
        "lift_scale_std": fit.scales.map(|(_, e)| e.lift),
        "drag_scale": fit.scales.map(|(s, _)| s.drag),
        "drag_scale_std": fit.scales.map(|(_, e)| e.drag),
        "t": fit.t_last,
        "position": v3(&fit.state_last.pos),
        "velocity": v3(&fit.state_last.vel),
        "bounce": p.bounce.map(|c| json!({"t": c.t, "x": c.pos.x, "y": c.pos.y, "spin_after": v3(&c.after.spin)})),
        "hit": p.hit.map(|h| json!({"t": h.t, "position": v3(&h.state.pos), "velocity": v3(&h.state.vel), "spin": v3(&h.state.spin)})),
        "hit_plane_x": hit_plane_x,
        "samples_used": fit.samples_used,
        "outliers": fit.outliers,
        "observed_bounce_row": fit.observed_bounce,
        "rms_mm": fit.rms * 1e3,
    })
}

fn summary(fit: &TrajectoryFit, hit_plane_x: f64) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let rps = fit.spin.map(rad_to_rps);
    let _ = writeln!(
        out,
        "spin        {:8.1} {:8.1} {:8.1} rad/s  ({:.1} {:.1} {:.1} rps, |ω| = {:.1} rps)",
        fit.spin.x,
        fit.spin.y,
        fit.spin.z,
        rps.x,
        rps.y,
        rps.z,
        rps.norm()
    );
    if let Some((axis, std)) = fit.weak_axis {
        let _ = writeln!(
            out,
            "weakest     along ({:.2}, {:.2}, {:.2}): ±{:.0} rad/s from the trajectory",
            axis.x, axis.y, axis.z, std
        );
    }
    if let Some((s, e)) = fit.scales {
        let _ = writeln!(
            out,
            "ball, air   drag × {:.2} ± {:.2}, lift × {:.2} ± {:.2} of the calibration",
            s.drag, e.drag, s.lift, e.lift
        );
    }
    let s = &fit.state_last;
    let _ = writeln!(
        out,
        "at t={:.4}  position ({:.3}, {:.3}, {:.3}) m, velocity ({:.2}, {:.2}, {:.2}) m/s",
        fit.t_last, s.pos.x, s.pos.y, s.pos.z, s.vel.x, s.vel.y, s.vel.z
    );
    match fit.prediction.bounce {
        Some(c) => {
            let _ = writeln!(out, "bounce      t={:.4}  x={:.3} y={:.3} m", c.t, c.pos.x, c.pos.y);
        }
        None => out.push_str("bounce      none predicted\n"),
    }
    match fit.prediction.hit {
        Some(h) => {
            let _ = writeln!(
                out,
                "hit x={hit_plane_x:.2} t={:.4}  y={:.3} z={:.3} m, velocity ({:.2}, {:.2}, {:.2}) m/s",
                h.t, h.state.pos.y, h.state.pos.z, h.state.vel.x, h.state.vel.y, h.state.vel.z
            );
        }
        None => {
            let _ = writeln!(out, "hit         none (flight ends: {:?})", fit.prediction.end);
        }
    }
    let _ = writeln!(
        out,
        "samples     {} used, outliers {:?}, rms {:.2} mm",
        fit.samples_used,
        fit.outliers,
        fit.rms * 1e3
    );
    out
}
