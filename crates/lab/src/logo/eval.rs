//! Accuracy of the background-subtraction method on rendered sequences
//! (the renderer is the ground truth): the vector angle between found and
//! true logo positions with and without the circular-segment correction
//! (paper: 5.77° → 5.06°), logo detection against the true visibility, and
//! the spin (axis angle, magnitude) against the simulator's, per launcher
//! setting. Also the rotation fit on the *true* positions of the frames the
//! detector saw, which separates the fit's own error from the detector's.

use rayon::prelude::*;
use serde::Serialize;

use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::DetectorConfig;
use topspin_core::logo::{CropInput, LogoMethod, process_sequence};
use topspin_core::logo::{LogoSample, RotationFitConfig, fit_rotation};
use topspin_core::physics::{Vec3, rad_to_rps};
use topspin_core::stats::Summary;
use topspin_sim::render::{BallColour, MIN_FILMED_FRAMES, Scene, SequenceOptions, render_sequence};
use topspin_sim::{Setting, TrackerModel, simulate_ball};

/// What to evaluate.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Seed of the simulated balls and renderings.
    pub seed: u64,
    /// Filmed balls wanted per setting and colour.
    pub balls: usize,
    /// Frames per ball.
    pub frames: usize,
    /// The launcher settings evaluated.
    pub settings: Vec<Setting>,
    /// The ball colours; every setting is filmed in each.
    pub colours: Vec<BallColour>,
    /// Balls tried per setting and colour before giving up on finding
    /// `balls` that fly through the filmed strip.
    pub max_tries: usize,
    /// The rotation fit's options (gap rule).
    pub fit: RotationFitConfig,
}

/// One evaluated ball.
#[derive(Clone, Debug, Serialize)]
pub struct BallEval {
    /// The launcher setting.
    pub setting: Setting,
    /// The ball's colour (`orange` or `white`).
    pub colour: &'static str,
    /// The ball's index in the run.
    pub ball: usize,
    /// Crops rendered of the flight.
    pub frames: usize,
    /// Frames whose logo's centre is on the visible hemisphere.
    pub truth_visible: usize,
    /// Frames in which a logo was found.
    pub detected: usize,
    /// Frames where found ⇔ truly visible.
    pub classified_right: usize,
    /// Vector-angle errors, degrees, on frames where a logo was found and
    /// some of it lies on the visible hemisphere: per method (centroid,
    /// segment, weighted).
    pub angle_err: [Vec<f64>; 3],
    /// The same restricted to logos touching the rim (cut).
    pub angle_err_cut: [Vec<f64>; 3],
    /// True spin, rad/s, table frame.
    pub spin_true: [f64; 3],
    /// Fitted spin per method, or the fit's error.
    pub spin_fit: [Result<[f64; 3], String>; 3],
    /// Fit on the true positions of the frames the detector saw.
    pub spin_fit_truth: Result<[f64; 3], String>,
}

fn angle_deg(a: &Vec3, b: &Vec3) -> f64 {
    a.angle(b).to_degrees()
}

/// Evaluates one rendered ball; `None` when it was not filmed long enough.
fn eval_ball(
    cal: &Calibration,
    scene: &Scene,
    seed: u64,
    k: usize,
    setting: Setting,
    frames: usize,
    fit_cfg: &RotationFitConfig,
) -> Option<BallEval> {
    let prop = cal.propagator();
    let cam = &scene.cam;
    let ball = simulate_ball(seed, k, setting, &prop, cal.strike.hit_plane_x, &TrackerModel::default()).ok()?;
    let seq = render_sequence(scene, &ball.truth, &prop, seed, k, &SequenceOptions { frames });
    if seq.frames.len() < MIN_FILMED_FRAMES {
        return None;
    }
    let inputs: Vec<CropInput<'_>> = seq.frames.iter().map(|f| f.crop_input()).collect();
    let det = DetectorConfig::for_logo(cam.logo_angular_radius());
    let mut spin_fit: [Result<[f64; 3], String>; 3] = std::array::from_fn(|_| Err(String::new()));
    let mut measurements = Vec::new();
    for (i, method) in LogoMethod::ALL.into_iter().enumerate() {
        let r = process_sequence(cam, &inputs, &det, fit_cfg, method).ok()?;
        spin_fit[i] = r.fit.map(|f| f.spin.into()).map_err(|e| e.to_string());
        measurements = r.measurements;
    }
    let mut e = BallEval {
        setting,
        colour: scene.colour.name(),
        ball: k,
        frames: seq.frames.len(),
        truth_visible: 0,
        detected: 0,
        classified_right: 0,
        angle_err: Default::default(),
        angle_err_cut: Default::default(),
        spin_true: seq.spin_table.into(),
        spin_fit,
        spin_fit_truth: Err(String::new()),
    };
    let mut truth_samples = Vec::with_capacity(seq.frames.len());
    for (f, m) in seq.frames.iter().zip(&measurements) {
        let l = &f.label;
        e.truth_visible += l.logo_visible as usize;
        e.detected += m.is_some() as usize;
        e.classified_right += (m.is_some() == l.logo_visible) as usize;
        truth_samples.push(LogoSample::new(l.t, m.map(|_| l.logo_camera)));
        if let Some(m) = m
            && l.logo_facing > -cam.logo_angular_radius().sin()
        {
            for (i, method) in LogoMethod::ALL.into_iter().enumerate() {
                let err = angle_deg(&method.position(m), &l.logo_camera);
                e.angle_err[i].push(err);
                if m.touches_limb {
                    e.angle_err_cut[i].push(err);
                }
            }
        }
    }
    e.spin_fit_truth = fit_rotation(&truth_samples, fit_cfg)
        .map(|f| f.rotated(&cam.table_from_camera).spin.into())
        .map_err(|e| e.to_string());
    Some(e)
}

/// Renders and evaluates the balls of `opts` (in parallel over settings and
/// colours; the result does not depend on the thread count).
pub fn evaluate(cal: &Calibration, cam: &CameraCalib, opts: &EvalOptions) -> Vec<BallEval> {
    let jobs: Vec<(usize, Setting, BallColour)> =
        opts.settings.iter().enumerate().flat_map(|(i, s)| opts.colours.iter().map(move |c| (i, *s, *c))).collect();
    let n_settings = opts.settings.len().max(1);
    let mut out: Vec<BallEval> = jobs
        .par_iter()
        .flat_map_iter(|&(i, setting, colour)| {
            let scene = Scene::new(cam.clone(), colour);
            let mut got = Vec::new();
            for j in 0..opts.max_tries {
                if got.len() >= opts.balls {
                    break;
                }
                // Ball indices unique across settings: k = i + n·j.
                let k = i + n_settings * j;
                if let Some(e) = eval_ball(cal, &scene, opts.seed, k, setting, opts.frames, &opts.fit) {
                    got.push(e);
                }
            }
            got
        })
        .collect();
    out.sort_by_key(|e| (Setting::ALL.iter().position(|s| *s == e.setting), e.colour, e.ball));
    out
}

/// The errors of a fitted spin against the truth: axis angle (degrees, the
/// angle between the vectors) and magnitude error (rps, signed).
pub fn spin_errors(fit: &[f64; 3], truth: &[f64; 3]) -> (f64, f64) {
    let (f, t) = (Vec3::from(*fit), Vec3::from(*truth));
    (angle_deg(&f, &t), rad_to_rps(f.norm() - t.norm()))
}

/// One row of the summary table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    /// The group's name (a setting, `all <colour>` or `all`).
    pub group: String,
    /// Balls in the group.
    pub balls: usize,
    /// Crops over those balls.
    pub frames: usize,
    /// Detection accuracy (found ⇔ truly visible), fraction of frames.
    pub detection_accuracy: f64,
    /// Mean vector-angle error per method (centroid, segment, weighted), deg.
    pub angle_mean: [f64; 3],
    /// On cut logos only.
    pub angle_mean_cut: [f64; 3],
    /// Frames with a found logo touching the rim (those `angle_mean_cut`
    /// averages).
    pub cut_frames: usize,
    /// Spin: balls with a fitted spin, per method (centroid, segment,
    /// weighted).
    pub fitted: [usize; 3],
    /// Median axis error of the fitted spins, per method, deg.
    pub axis_median: [f64; 3],
    /// Median |magnitude error| of the fitted spins, per method, rps.
    pub magnitude_median: [f64; 3],
    /// The fit on the true logo positions of the frames the detector saw:
    /// balls fitted.
    pub truth_fitted: usize,
    /// Median axis error of the fits on true positions, deg.
    pub truth_axis_median: f64,
    /// Median |magnitude error| of the fits on true positions, rps.
    pub truth_magnitude_median: f64,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
}

/// Summarises `balls` into one row named `group`.
pub fn summarise(group: &str, balls: &[&BallEval]) -> Row {
    let frames: usize = balls.iter().map(|b| b.frames).sum();
    let right: usize = balls.iter().map(|b| b.classified_right).sum();
    let cat = |f: &dyn Fn(&BallEval) -> &Vec<f64>| -> Vec<f64> { balls.iter().flat_map(|b| f(b).clone()).collect() };
    let angle_mean = std::array::from_fn(|i| mean(&cat(&|b| &b.angle_err[i])));
    let angle_mean_cut = std::array::from_fn(|i| mean(&cat(&|b| &b.angle_err_cut[i])));
    let cut_frames = balls.iter().map(|b| b.angle_err_cut[0].len()).sum();
    let errs = |get: &dyn Fn(&BallEval) -> &Result<[f64; 3], String>| -> (usize, f64, f64) {
        let e: Vec<(f64, f64)> =
            balls.iter().filter_map(|b| get(b).as_ref().ok().map(|f| spin_errors(f, &b.spin_true))).collect();
        let axis: Vec<f64> = e.iter().map(|x| x.0).collect();
        let mag: Vec<f64> = e.iter().map(|x| x.1.abs()).collect();
        (e.len(), Summary::of(&axis).median, Summary::of(&mag).median)
    };
    let per: [(usize, f64, f64); 3] = std::array::from_fn(|i| errs(&|b| &b.spin_fit[i]));
    let truth = errs(&|b| &b.spin_fit_truth);
    Row {
        group: group.to_owned(),
        balls: balls.len(),
        frames,
        detection_accuracy: right as f64 / frames.max(1) as f64,
        angle_mean,
        angle_mean_cut,
        cut_frames,
        fitted: per.map(|p| p.0),
        axis_median: per.map(|p| p.1),
        magnitude_median: per.map(|p| p.2),
        truth_fitted: truth.0,
        truth_axis_median: truth.1,
        truth_magnitude_median: truth.2,
    }
}
