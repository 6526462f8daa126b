//! `topspin logo FOLDER [--json]`: spin from a sequence of ball crops;
//! `topspin logo eval`: the background methods' accuracy on rendered
//! sequences; `logo cnn-eval DIR` and `logo compare`: the CNN's metrics and
//! the spin sources side by side (see [`super::logo_cnn`]). The older
//! spellings `--eval`, `--compare` and `--cnn-eval DIR` still work.
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

use super::args::{Colours, GapRuleChoice, LogoMethodChoice, Settings};
use super::crops::read_folder;
use super::{bad, logo_cnn};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::{CropImage, DetectorConfig, RotationFitConfig};
use topspin_core::logo::{CropInput, process_sequence};
use topspin_core::physics::rad_to_rps;
use topspin_lab::logo::eval::{self, BallEval, EvalOptions, Row};
use topspin_sim::render::MIN_FILMED_FRAMES;

#[derive(Debug, clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct LogoArgs {
    #[command(subcommand)]
    pub command: Option<LogoCommand>,
    /// Folder with frames.csv (file,t,u,v,radius) and the PNG crops.
    #[arg(required_unless_present_any = ["eval", "compare", "cnn_eval"])]
    pub folder: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub fit: FitOptions,
    #[command(flatten)]
    pub cnn: logo_cnn::CnnArgs,
    /// Calibration folder (camera.toml).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// The older spelling of `topspin logo eval`.
    #[arg(long, hide = true, conflicts_with_all = ["folder", "compare", "cnn_eval"])]
    pub eval: bool,
    /// The older spelling of `topspin logo compare`.
    #[arg(long, hide = true, conflicts_with_all = ["folder", "cnn_eval"])]
    pub compare: bool,
    /// The older spelling of `topspin logo cnn-eval DIR`.
    #[arg(long, hide = true, value_name = "DIR", conflicts_with = "folder")]
    pub cnn_eval: Option<PathBuf>,
    /// With the older spellings: leave the CNN out of the comparison.
    #[arg(long, hide = true)]
    pub no_cnn: bool,
    /// With the older spellings: the rendered flights.
    #[command(flatten, next_help_heading = None)]
    pub rendered: Rendered,
}

/// `topspin logo eval | compare | cnn-eval`.
#[derive(Debug, clap::Subcommand)]
pub enum LogoCommand {
    /// The background methods' accuracy on rendered sequences.
    Eval(EvalArgs),
    /// The trajectory's, the logo's (background, CNN) and the fused spins
    /// on the same simulated flights.
    Compare(CompareArgs),
    /// The CNN's metrics and speed on a `topspin render --out` folder.
    CnnEval(CnnEvalArgs),
}

/// How the logo's positions become a spin.
#[derive(Debug, clap::Args)]
pub struct FitOptions {
    /// Where the logo's centre is taken from.
    #[arg(long, value_enum, default_value_t = LogoMethodChoice::Segment)]
    pub method: LogoMethodChoice,
    /// How gaps of two or more unseen frames are bridged.
    #[arg(long, value_enum, default_value_t = GapRuleChoice::Directed)]
    pub gap_rule: GapRuleChoice,
}

/// The rendered flights an evaluation runs on.
#[derive(Debug, clap::Args)]
pub struct Rendered {
    /// Filmed balls per setting and colour.
    #[arg(long, default_value_t = 6)]
    pub balls: usize,
    /// Seed of the simulated and rendered balls.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// `all` or comma-separated launcher settings.
    #[arg(long, default_value = "all")]
    pub setting: Settings,
    /// Ball colours (`compare`: the first of them).
    #[arg(long, value_enum, default_value_t = Colours::Both)]
    pub colour: Colours,
    /// Frames per ball.
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
}

impl Rendered {
    fn check(&self) -> anyhow::Result<()> {
        if self.balls == 0 || self.frames < MIN_FILMED_FRAMES {
            return Err(bad(format!("--balls must be ≥ 1 and --frames ≥ {MIN_FILMED_FRAMES}")));
        }
        Ok(())
    }
}

#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    #[command(flatten)]
    pub rendered: Rendered,
    /// How gaps of two or more unseen frames are bridged.
    #[arg(long, value_enum, default_value_t = GapRuleChoice::Directed)]
    pub gap_rule: GapRuleChoice,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Calibration folder.
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    #[command(flatten)]
    pub rendered: Rendered,
    #[command(flatten)]
    pub cnn: logo_cnn::CnnArgs,
    /// Leave the CNN out.
    #[arg(long)]
    pub no_cnn: bool,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Calibration folder.
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
}

#[derive(Debug, clap::Args)]
pub struct CnnEvalArgs {
    /// A `topspin render --out` folder.
    pub dir: PathBuf,
    #[command(flatten)]
    pub cnn: logo_cnn::CnnArgs,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// What `topspin logo` was asked for.
enum Mode {
    Folder { folder: PathBuf, json: bool, fit: FitOptions, cnn: logo_cnn::CnnArgs, calib: Option<PathBuf> },
    Command(LogoCommand),
}

impl LogoArgs {
    /// The mode, with the older flag spellings read as their subcommands.
    fn mode(self) -> Mode {
        let LogoArgs { command, folder, json, fit, cnn, calib, eval, compare, cnn_eval, no_cnn, rendered } = self;
        let command = match (command, cnn_eval) {
            (Some(c), _) => c,
            (None, Some(dir)) => LogoCommand::CnnEval(CnnEvalArgs { dir, cnn, json }),
            (None, None) if compare => LogoCommand::Compare(CompareArgs { rendered, cnn, no_cnn, json, calib }),
            (None, None) if eval => LogoCommand::Eval(EvalArgs { rendered, gap_rule: fit.gap_rule, json, calib }),
            (None, None) => {
                let folder = folder.expect("clap requires FOLDER without a subcommand");
                return Mode::Folder { folder, json, fit, cnn, calib };
            }
        };
        Mode::Command(command)
    }
}

pub fn run(a: LogoArgs) -> anyhow::Result<()> {
    let (folder, json, fit, cnn, calib) = match a.mode() {
        Mode::Command(LogoCommand::CnnEval(c)) => return logo_cnn::run_cnn_eval(&c.dir, &mut c.cnn.load()?, c.json),
        Mode::Command(LogoCommand::Compare(c)) => return run_compare(c),
        Mode::Command(LogoCommand::Eval(e)) => return run_eval(e),
        Mode::Folder { folder, json, fit, cnn, calib } => (folder, json, fit, cnn, calib),
    };
    let folder = folder.as_path();
    let cam = CameraCalib::load(calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let fit_cfg = RotationFitConfig { gap_rule: fit.gap_rule.into(), ..RotationFitConfig::default() };
    let Some(method) = fit.method.background() else {
        let mut net = cnn.load()?;
        return logo_cnn::run_folder(folder, &read_folder(folder)?, &cam, &fit_cfg, &mut net, json);
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
    if json {
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

fn run_compare(c: CompareArgs) -> anyhow::Result<()> {
    c.rendered.check()?;
    let cam = CameraCalib::load(c.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let r = &c.rendered;
    let colour = c.rendered.colour.list()[0];
    let opts = logo_cnn::compare_options(r.seed, r.balls, r.setting.0.clone(), colour, r.frames);
    let mut net = if c.no_cnn { None } else { Some(c.cnn.load()?) };
    logo_cnn::run_compare(c.calib.as_deref(), &cam, &opts, net.as_mut(), c.json)
}

fn run_eval(a: EvalArgs) -> anyhow::Result<()> {
    a.rendered.check()?;
    let cam = CameraCalib::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let cal = Calibration::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let r = &a.rendered;
    let opts = EvalOptions {
        seed: r.seed,
        balls: r.balls,
        frames: r.frames,
        settings: r.setting.0.clone(),
        colours: r.colour.list(),
        max_tries: 8 * r.balls + 8,
        fit: RotationFitConfig { gap_rule: a.gap_rule.into(), ..RotationFitConfig::default() },
    };
    let cam = &cam;
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
