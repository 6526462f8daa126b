//! `topspin logo FOLDER [--json]`: spin from a sequence of ball crops;
//! `topspin logo --eval`: the background method's accuracy on rendered
//! sequences; `--cnn-eval DIR` and `--compare`: the CNN's metrics and the
//! spin sources side by side (see [`super::logo_cnn`]).
//!
//! The folder holds the crops as PNG (RGB8 or RGBA8) and a `frames.csv`
//! with at least the columns `file,t,u,v,radius` (extra columns ignored):
//! the PNG's path relative to the folder, the capture time in seconds, and
//! the ball's circle as the camera side measured it, in full-sensor pixels.
//! A crop of w × h pixels lies at (⌊u⌋ − w/2, ⌊v⌋ − h/2) on the sensor (the
//! TTI1 convention). `topspin render` writes such folders, one per ball.

use std::fmt::Write as _;
use std::path::PathBuf;
use topspin_daemon::calib_files::CalibDir;

use serde_json::json;

use super::crops::read_folder;
use super::{BadInput, logo_cnn};
use topspin_core::calib::Calibration;
use topspin_core::calib::camera::CameraCalib;
use topspin_core::logo::pipeline::{CropInput, LogoMethod, process_sequence};
use topspin_core::logo::{CropImage, DetectorConfig, GapRule, RotationFitConfig};
use topspin_core::physics::rad_to_rps;
use topspin_lab::logo::eval::{self, BallEval, EvalOptions, Row};
use topspin_sim::Setting;
use topspin_sim::render::BallColour;

#[derive(Debug, clap::Args)]
pub struct LogoArgs {
    /// Folder with frames.csv (file,t,u,v,radius) and the PNG crops.
    #[arg(required_unless_present_any = ["eval", "compare", "cnn_eval"])]
    pub folder: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Evaluate on rendered sequences instead (no FOLDER).
    #[arg(long, conflicts_with_all = ["folder", "compare", "cnn_eval"])]
    pub eval: bool,
    /// Compare the trajectory's, the logo's (background, CNN) and the fused
    /// spins on the same simulated flights (no FOLDER).
    #[arg(long, conflicts_with_all = ["folder", "cnn_eval"])]
    pub compare: bool,
    /// The CNN's metrics and speed on a `topspin render --out` folder.
    #[arg(long, value_name = "DIR", conflicts_with = "folder")]
    pub cnn_eval: Option<PathBuf>,
    #[command(flatten)]
    pub cnn: logo_cnn::CnnArgs,
    /// --compare: leave the CNN out.
    #[arg(long)]
    pub no_cnn: bool,
    /// --eval: filmed balls per setting and colour.
    #[arg(long, default_value_t = 6)]
    pub balls: usize,
    /// --eval: seed of the simulated and rendered balls.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// --eval: `all` or comma-separated launcher settings.
    #[arg(long, default_value = "all")]
    pub setting: String,
    /// --eval: orange, white or both.
    #[arg(long, default_value = "both")]
    pub colour: String,
    /// --eval: frames per ball.
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
    /// Logo centre: centroid (paper, uncorrected), segment (paper with the
    /// circular-segment correction), weighted (area-weighted + segment) or
    /// cnn (the network of --model).
    #[arg(long, default_value = "segment")]
    pub method: String,
    /// Gaps of two or more unseen frames: paper (the large angle) or
    /// directed (angle in the rotation's direction plus predicted turns).
    #[arg(long, default_value = "directed")]
    pub gap_rule: String,
    /// Calibration folder (camera.toml; the others for --eval).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
}

fn bad(msg: impl Into<String>) -> anyhow::Error {
    BadInput(msg.into()).into()
}

fn parse_method(s: &str) -> Result<LogoMethod, BadInput> {
    LogoMethod::ALL
        .into_iter()
        .find(|m| m.name() == s)
        .ok_or_else(|| BadInput(format!("--method `{s}`: expected centroid, segment, weighted or cnn")))
}

fn parse_gap_rule(s: &str) -> Result<GapRule, BadInput> {
    match s {
        "paper" => Ok(GapRule::Paper),
        "directed" => Ok(GapRule::Directed),
        _ => Err(BadInput(format!("--gap-rule `{s}`: expected paper or directed"))),
    }
}

pub fn run(a: LogoArgs) -> anyhow::Result<()> {
    let cam = CameraCalib::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let fit_cfg = RotationFitConfig { gap_rule: parse_gap_rule(&a.gap_rule)?, ..RotationFitConfig::default() };
    if let Some(dir) = &a.cnn_eval {
        let mut net = a.cnn.load()?;
        return logo_cnn::run_cnn_eval(dir, &mut net, a.json);
    }
    if a.compare {
        if a.balls == 0 || a.frames < eval::MIN_FRAMES {
            return Err(bad(format!("--balls must be ≥ 1 and --frames ≥ {}", eval::MIN_FRAMES)));
        }
        let colour = match parse_colours(&a.colour)?.as_slice() {
            [c] => *c,
            _ => BallColour::Orange,
        };
        let opts = logo_cnn::compare_options(a.seed, a.balls, parse_settings(&a.setting)?, colour, a.frames);
        let mut net = if a.no_cnn { None } else { Some(a.cnn.load()?) };
        return logo_cnn::run_compare(a.calib.as_deref(), &cam, &opts, net.as_mut(), a.json);
    }
    if a.method == "cnn" {
        let Some(folder) = a.folder.as_deref() else {
            return Err(bad("FOLDER is required with --method cnn"));
        };
        let mut net = a.cnn.load()?;
        return logo_cnn::run_folder(folder, &read_folder(folder)?, &cam, &fit_cfg, &mut net, a.json);
    }
    let method = parse_method(&a.method)?;
    if a.eval {
        return run_eval(&a, &cam, fit_cfg);
    }
    let Some(folder) = a.folder.as_deref() else {
        return Err(bad("FOLDER is required without --eval"));
    };
    let frames = read_folder(folder)?;
    let inputs: Vec<CropInput<'_>> = frames
        .iter()
        .map(|f| CropInput {
            t: f.t,
            crop: CropImage::new(f.x0, f.y0, f.width, f.height, &f.rgb).expect("decoded crops are whole"),
            circle: f.circle,
        })
        .collect();
    let det = DetectorConfig::for_logo(cam.logo_angular_radius());
    let r = process_sequence(&cam, &inputs, &det, &fit_cfg, method)
        .map_err(|e| bad(format!("{}: {e}", folder.display())))?;
    let seen = r.measurements.iter().filter(|m| m.is_some()).count();
    let fit = r.fit.map_err(|e| bad(format!("{}: {e}", folder.display())))?;
    let w = fit.spin;
    if a.json {
        let v = json!({
            "spin": [w.x, w.y, w.z],
            "spin_rps": [rad_to_rps(w.x), rad_to_rps(w.y), rad_to_rps(w.z)],
            "rate": fit.rate,
            "rate_rps": rad_to_rps(fit.rate),
            "axis": [fit.axis.x, fit.axis.y, fit.axis.z],
            "frames": frames.len(),
            "logo_seen": seen,
            "method": method.name(),
            "rms_angle": fit.rms_angle,
            "rms_circle": fit.rms_circle,
            "frame": "table",
        });
        println!("{v}");
    } else {
        println!(
            "spin [{:.1} {:.1} {:.1}] rad/s = [{:.2} {:.2} {:.2}] rps, |ω| {:.1} rad/s ({:.2} rps), table frame; \
             logo seen in {seen} of {} frames",
            w.x,
            w.y,
            w.z,
            rad_to_rps(w.x),
            rad_to_rps(w.y),
            rad_to_rps(w.z),
            fit.rate,
            rad_to_rps(fit.rate),
            frames.len()
        );
    }
    Ok(())
}

fn parse_settings(s: &str) -> Result<Vec<Setting>, BadInput> {
    if s.trim().eq_ignore_ascii_case("all") {
        return Ok(Setting::ALL.to_vec());
    }
    s.split(',').map(|n| n.parse::<Setting>().map_err(|e| BadInput(e.to_string()))).collect()
}

/// `--colour orange|white|both`.
pub fn parse_colours(s: &str) -> Result<Vec<BallColour>, BadInput> {
    if s.trim().eq_ignore_ascii_case("both") {
        return Ok(BallColour::ALL.to_vec());
    }
    Ok(vec![s.parse::<BallColour>().map_err(BadInput)?])
}

fn run_eval(a: &LogoArgs, cam: &CameraCalib, fit: RotationFitConfig) -> anyhow::Result<()> {
    let cal = Calibration::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    if a.balls == 0 || a.frames < eval::MIN_FRAMES {
        return Err(bad(format!("--balls must be ≥ 1 and --frames ≥ {}", eval::MIN_FRAMES)));
    }
    let opts = EvalOptions {
        seed: a.seed,
        balls: a.balls,
        frames: a.frames,
        settings: parse_settings(&a.setting)?,
        colours: parse_colours(&a.colour)?,
        max_tries: 8 * a.balls + 8,
        fit,
    };
    let balls = eval::evaluate(&cal, cam, &opts);
    let mut rows = Vec::new();
    for s in &opts.settings {
        let group: Vec<&BallEval> = balls.iter().filter(|b| b.setting == *s).collect();
        rows.push(eval::summarise(&s.to_string(), &group));
    }
    for c in &opts.colours {
        let group: Vec<&BallEval> = balls.iter().filter(|b| b.colour == c.name()).collect();
        rows.push(eval::summarise(&format!("all {}", c.name()), &group));
    }
    let all: Vec<&BallEval> = balls.iter().collect();
    rows.push(eval::summarise("all", &all));
    if a.json {
        println!("{}", serde_json::to_string(&json!({ "rows": rows, "balls": balls }))?);
    } else {
        print!("{}", table(&rows));
    }
    Ok(())
}

fn f1(x: f64) -> String {
    if x.is_finite() { format!("{x:.2}") } else { "-".into() }
}

/// The two tables of docs/logo.md.
pub fn table(rows: &[Row]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Logo positions: mean vector-angle error, degrees (frames where a logo was found and some of it is on the visible hemisphere; detection accuracy: found ⇔ logo centre on the visible side)\n"
    );
    let _ = writeln!(
        s,
        "| setting | balls | frames | detection acc. | centroid (paper) | + segment fit | weighted + segment | cut frames | cut: centroid | cut: + segment | cut: weighted |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} % | {} | {} | {} | {} | {} | {} | {} |",
            r.group,
            r.balls,
            r.frames,
            100.0 * r.detection_accuracy,
            f1(r.angle_mean[0]),
            f1(r.angle_mean[1]),
            f1(r.angle_mean[2]),
            r.cut_frames,
            f1(r.angle_mean_cut[0]),
            f1(r.angle_mean_cut[1]),
            f1(r.angle_mean_cut[2]),
        );
    }
    let _ = writeln!(
        s,
        "\nSpin against the truth (table frame): balls fitted, median axis error (deg), median |magnitude error| (rps)\n"
    );
    let _ = writeln!(
        s,
        "| setting | balls | centroid: fitted | axis | mag | segment: fitted | axis | mag | weighted: fitted | axis | mag | true positions: fitted | axis | mag |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = write!(s, "| {} | {} ", r.group, r.balls);
        for i in 0..3 {
            let _ = write!(s, "| {} | {} | {} ", r.fitted[i], f1(r.axis_median[i]), f1(r.magnitude_median[i]));
        }
        let _ = writeln!(s, "| {} | {} | {} |", r.truth_fitted, f1(r.truth_axis_median), f1(r.truth_magnitude_median));
    }
    s
}
