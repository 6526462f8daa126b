//! The CNN's parts of `topspin logo`:
//!
//! - `cnn-eval DIR`: the network's metrics (paper §III) on a folder of
//!   `topspin render --out` (its `labels.csv`), inferred here through `ort`
//!   on the chosen backend: visibility classification accuracy, geodesic
//!   error of the orientation and vector angle of the logo (on crops whose
//!   logo faces the camera), and the time per crop and per batch of 5.
//! - `compare`: trajectory, background, CNN and fused spins on the same
//!   simulated flights ([`topspin_lab::logo::compare`]).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use topspin_daemon::calib_files::CalibDir;

use serde_json::json;

use super::bad;
use super::crops::{FolderFrame, read_png};
use topspin_cnn::{self as cnn, CnnOutput, LogoCnn};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::RotationFitConfig;
use topspin_core::logo::{geodesic_deg, swing_to};
use topspin_core::physics::{Vec3, rad_to_rps};
use topspin_core::stats::Summary;
use topspin_lab::logo::compare::{self, CompareBall, CompareOptions, CompareRow, SOURCES};
use topspin_sim::Setting;
use topspin_sim::render::BallColour;

/// The CNN's model and backend on the command line (`logo`, `demo`,
/// `eval paper`).
#[derive(Clone, Debug, clap::Args)]
pub struct CnnArgs {
    /// The CNN's ONNX model (default: $TOPSPIN_LOGO_MODEL, else
    /// models/logo-compact.onnx).
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// CNN backend: auto (ONNX Runtime when ORT_DYLIB_PATH names its
    /// library, else tract), tract or onnxruntime.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: cnn::Backend,
}

impl CnnArgs {
    pub fn model_path(&self) -> PathBuf {
        self.model.clone().unwrap_or_else(cnn::default_model)
    }

    /// Loads the network or says, in one line, why not.
    pub fn load(&self) -> anyhow::Result<LogoCnn> {
        LogoCnn::load(&self.model_path(), &self.backend).map_err(|e| bad(e.to_string()))
    }
}

struct Labelled {
    rgb: Vec<u8>,
    logo_view: Vec3,
}

fn read_labels(dir: &Path) -> anyhow::Result<Vec<Labelled>> {
    let path = dir.join("labels.csv");
    let name = path.display().to_string();
    let mut reader = csv::Reader::from_path(&path).map_err(|e| bad(format!("{name}: {e}")))?;
    let headers = reader.headers().map_err(|e| bad(format!("{name}: {e}")))?.clone();
    let col = |k: &str| {
        headers
            .iter()
            .position(|h| h == k)
            .ok_or_else(|| bad(format!("{name}: no column `{k}` (topspin render writes it)")))
    };
    let (file, vx, vy, vz) = (col("file")?, col("view_x")?, col("view_y")?, col("view_z")?);
    let mut out = Vec::new();
    for (row, rec) in reader.records().enumerate() {
        let rec = rec.map_err(|e| bad(format!("{name}: row {row}: {e}")))?;
        let num = |c: usize| rec.get(c).and_then(|s| s.parse::<f64>().ok()).filter(|x| x.is_finite());
        let (Some(x), Some(y), Some(z)) = (num(vx), num(vy), num(vz)) else { continue };
        let png = dir.join(rec.get(file).unwrap_or(""));
        let (w, h, rgb) = read_png(&png).map_err(|e| bad(format!("{}: {e}", png.display())))?;
        if w != cnn::INPUT_SIZE || h != cnn::INPUT_SIZE {
            continue;
        }
        out.push(Labelled { rgb, logo_view: Vec3::new(x, y, z).normalize() });
    }
    if out.is_empty() {
        return Err(bad(format!("{name}: no usable crops")));
    }
    Ok(out)
}

fn median_ms(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs.get(xs.len() / 2).copied().unwrap_or(f64::NAN) * 1e3
}

/// `topspin logo cnn-eval DIR`.
pub fn run_cnn_eval(dir: &Path, net: &mut LogoCnn, as_json: bool) -> anyhow::Result<()> {
    let data = read_labels(dir)?;
    let crops: Vec<&[u8]> = data.iter().map(|d| d.rgb.as_slice()).collect();
    let mut out = vec![CnnOutput::default(); crops.len()];
    net.infer(&crops, &mut out).map_err(|e| bad(e.to_string()))?;
    let mut right = 0usize;
    let (mut geo, mut vec) = (Vec::new(), Vec::new());
    for (d, o) in data.iter().zip(&out) {
        let visible = d.logo_view.z > 0.0;
        right += ((o.visibility >= cnn::VISIBLE_THRESHOLD) == visible) as usize;
        if visible {
            geo.push(geodesic_deg(&o.orientation, &swing_to(&d.logo_view)));
            vec.push(o.logo_view().angle(&d.logo_view).to_degrees());
        }
    }
    // Timing: one crop and batches of five, repeated.
    let mut one = [out[0]];
    let mut five = [out[0]; cnn::MAX_BATCH];
    let (mut t1, mut t5) = (Vec::new(), Vec::new());
    for i in 0..60 {
        let k = (i * 7) % crops.len().saturating_sub(cnn::MAX_BATCH).max(1);
        let t = topspin_daemon::clock::now();
        net.infer(&crops[k..k + 1], &mut one).map_err(|e| bad(e.to_string()))?;
        t1.push(topspin_daemon::clock::secs_since(t));
        if crops.len() >= cnn::MAX_BATCH {
            let t = topspin_daemon::clock::now();
            net.infer(&crops[k..k + cnn::MAX_BATCH], &mut five).map_err(|e| bad(e.to_string()))?;
            t5.push(topspin_daemon::clock::secs_since(t));
        }
    }
    let (g, v) = (Summary::of(&geo), Summary::of(&vec));
    let r = json!({
        "folder": dir.display().to_string(),
        "backend": net.backend().name(),
        "crops": data.len(),
        "logo_visible": geo.len(),
        "classification_accuracy": right as f64 / data.len() as f64,
        "geodesic_deg": g,
        "vector_angle_deg": v,
        "ms_per_crop": median_ms(t1),
        "ms_per_batch5": median_ms(t5),
    });
    if as_json {
        println!("{r}");
    } else {
        println!(
            "{}: {} crops ({} with the logo facing the camera), backend {}\n\
             classification accuracy {:.3}; geodesic error mean {:.2}° (median {:.2}°); \
             vector angle mean {:.2}° (median {:.2}°, p90 {:.2}°)\n\
             {:.3} ms per crop, {:.3} ms per batch of {} (medians, one thread)",
            dir.display(),
            data.len(),
            geo.len(),
            net.backend().name(),
            r["classification_accuracy"].as_f64().unwrap_or(f64::NAN),
            g.mean,
            g.median,
            v.mean,
            v.median,
            v.p90,
            r["ms_per_crop"].as_f64().unwrap_or(f64::NAN),
            r["ms_per_batch5"].as_f64().unwrap_or(f64::NAN),
            cnn::MAX_BATCH
        );
    }
    Ok(())
}

/// `topspin logo compare`.
pub fn run_compare(
    cal_dir: Option<&Path>,
    cam: &CameraCalib,
    opts: &CompareOptions,
    net: Option<&mut LogoCnn>,
    as_json: bool,
) -> anyhow::Result<()> {
    let cal = Calibration::load(cal_dir).map_err(|e| bad(e.to_string()))?;
    let balls = compare::compare(&cal, cam, opts, net).map_err(|e| bad(e.to_string()))?;
    let mut rows = Vec::new();
    for s in &opts.settings {
        let group: Vec<&CompareBall> = balls.iter().filter(|b| b.setting == *s).collect();
        rows.push(compare::summarise(&s.to_string(), &group));
    }
    let all: Vec<&CompareBall> = balls.iter().collect();
    rows.push(compare::summarise("all", &all));
    if as_json {
        println!("{}", serde_json::to_string(&json!({ "rows": rows, "balls": balls }))?);
    } else {
        print!("{}", compare_table(&rows));
    }
    Ok(())
}

/// The Markdown table of `compare`: median |ω̂ − ω| in rps per source,
/// with the share of balls each answered.
pub fn compare_table(rows: &[CompareRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Spin error |ω̂ − ω|, rps: median over the balls a source answered (answered / balls); \
         same simulated flights, 2 mm tracker noise, rendered 380 Hz crops\n"
    );
    let _ = write!(s, "| setting | balls ");
    for src in SOURCES {
        let _ = write!(s, "| {src} ");
    }
    let _ = writeln!(s, "|\n|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = write!(s, "| {} | {} ", r.group, r.balls);
        for i in 0..SOURCES.len() {
            let e = &r.error_rps[i];
            if e.n == 0 {
                let _ = write!(s, "| – ");
            } else {
                let _ = write!(s, "| {:.2} ({}/{}) ", e.median, r.answered[i], r.balls);
            }
        }
        let _ = writeln!(s, "|");
    }
    s
}

/// Options of `compare` from the flags.
pub fn compare_options(
    seed: u64,
    balls: usize,
    settings: Vec<Setting>,
    colour: BallColour,
    frames: usize,
) -> CompareOptions {
    CompareOptions { seed, balls, settings, colour, frames, noise: 0.002 }
}

/// `topspin logo FOLDER --method cnn`: the CNN's logo positions through
/// the rotation fit, table frame.
pub fn run_folder(
    folder: &Path,
    frames: &[FolderFrame],
    cam: &CameraCalib,
    fit_cfg: &RotationFitConfig,
    net: &mut LogoCnn,
    as_json: bool,
) -> anyhow::Result<()> {
    if let Some(i) = frames.iter().position(|f| f.rgb.len() != cnn::INPUT_SIZE * cnn::INPUT_SIZE * 3) {
        return Err(bad(format!("{}: frame {i} is not a 60 × 60 crop (the CNN's input)", folder.display())));
    }
    let crops: Vec<_> = frames.iter().map(|f| (f.t, f.circle, f.rgb.as_slice())).collect();
    let (seen, fit) = cnn::fit_crops(net, cam, &crops, fit_cfg).map_err(|e| bad(e.to_string()))?;
    let fit = fit.map_err(|e| bad(format!("{}: {e}", folder.display())))?;
    let w = fit.spin;
    if as_json {
        let v = json!({
            "spin": [w.x, w.y, w.z],
            "spin_rps": [rad_to_rps(w.x), rad_to_rps(w.y), rad_to_rps(w.z)],
            "rate": fit.rate,
            "axis": [fit.axis.x, fit.axis.y, fit.axis.z],
            "frames": frames.len(),
            "logo_seen": seen,
            "method": "cnn",
            "backend": net.backend().name(),
            "frame": "table",
        });
        println!("{v}");
    } else {
        println!(
            "spin [{:.1} {:.1} {:.1}] rad/s = [{:.2} {:.2} {:.2}] rps, table frame; logo seen (CNN, {}) in {seen} of {} frames",
            w.x,
            w.y,
            w.z,
            rad_to_rps(w.x),
            rad_to_rps(w.y),
            rad_to_rps(w.z),
            net.backend().name(),
            frames.len()
        );
    }
    Ok(())
}
