//! The spin sources side by side on the same simulated flights: for each
//! ball, the trajectory's spin (the refined Magnus
//! fit over the tracker's pre-bounce observations), the logo's spin from
//! the rendered ceiling-camera crops of the same flight by background
//! subtraction and by the CNN, and each logo spin fused with the
//! trajectory's (`super::fusion`). Errors are |ω̂ − ω| against the
//! simulator's truth.
//!
//! Rendering runs in parallel; the network runs on this thread (one
//! session).

use rayon::prelude::*;
use serde::Serialize;

use crate::eval::fit::{Window, windowed};
use topspin_cnn::{self as cnn, LogoCnn};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::fit::{FitConfig, Method as FitMethod, fit_trajectory};
use topspin_core::logo::DetectorConfig;
use topspin_core::logo::{CropInput, LogoMethod, process_sequence};
use topspin_core::logo::{Fused, SpinEstimate, fuse};
use topspin_core::logo::{RotationFit, RotationFitConfig};
use topspin_core::physics::{Vec3, rad_to_rps};
use topspin_core::stats::Summary;
use topspin_sim::render::{BallColour, MIN_FILMED_FRAMES, Scene, Sequence, SequenceOptions, render_sequence};
use topspin_sim::{Setting, SimBall, TrackerModel, simulate_ball};

/// The sources compared, in table order.
pub const SOURCES: [&str; 5] = ["trajectory", "background", "cnn", "fused background", "fused cnn"];

/// What to compare.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// Seed of the simulated balls and renderings.
    pub seed: u64,
    /// Filmed balls per setting.
    pub balls: usize,
    /// The launcher settings filmed.
    pub settings: Vec<Setting>,
    /// The balls' colour.
    pub colour: BallColour,
    /// Crops rendered per flight (at most).
    pub frames: usize,
    /// Tracker noise σ per axis, m.
    pub noise: f64,
}

/// One ball's estimates, rad/s, table frame (`None`: the source gave none).
#[derive(Clone, Debug, Serialize)]
pub struct CompareBall {
    /// The launcher setting.
    pub setting: Setting,
    /// The ball's index in the run.
    pub ball: usize,
    /// True spin, rad/s, table frame.
    pub spin_true: [f64; 3],
    /// Per source of [`SOURCES`].
    pub spin: [Option<[f64; 3]>; 5],
    /// The fusions that kept the trajectory alone (the logo failed the gate).
    pub gated: [bool; 2],
}

impl CompareBall {
    /// |ω̂ − ω| in rps per source.
    pub(crate) fn errors_rps(&self) -> [Option<f64>; 5] {
        let t = Vec3::from(self.spin_true);
        self.spin.map(|s| s.map(|s| rad_to_rps((Vec3::from(s) - t).norm())))
    }
}

/// A rendered ball with its tracker observations.
struct Filmed {
    ball: SimBall,
    seq: Sequence,
}

fn film(cal: &Calibration, scene: &Scene, opts: &CompareOptions, k: usize, setting: Setting) -> Option<Filmed> {
    let prop = cal.propagator();
    let tracker = TrackerModel { noise_sigma: opts.noise, ..TrackerModel::default() };
    let ball = simulate_ball(opts.seed, k, setting, &prop, cal.strike.hit_plane_x, &tracker).ok()?;
    let seq = render_sequence(scene, &ball.truth, &prop, opts.seed, k, &SequenceOptions { frames: opts.frames });
    (seq.frames.len() >= MIN_FILMED_FRAMES).then_some(Filmed { ball, seq })
}

fn trajectory_estimate(cal: &Calibration, b: &SimBall, noise: f64) -> Option<SpinEstimate> {
    let samples = windowed(b, Window::PreBounce);
    let cfg = FitConfig::new(FitMethod::Refined, cal.strike.hit_plane_x).with_noise(noise);
    SpinEstimate::from_fit(&fit_trajectory(&samples, &cal.propagator(), &cfg).ok()?)
}

fn logo_estimate(fit: Option<RotationFit>, seq: &Sequence) -> Option<SpinEstimate> {
    fit.map(|f| SpinEstimate::from_rotation(&f, seq.span()))
}

fn background(cam: &CameraCalib, seq: &Sequence, cfg: &RotationFitConfig) -> Option<RotationFit> {
    let inputs: Vec<CropInput<'_>> = seq.frames.iter().map(|f| f.crop_input()).collect();
    let det = DetectorConfig::for_logo(cam.logo_angular_radius());
    let r = process_sequence(cam, &inputs, &det, cfg, LogoMethod::Segment).ok()?;
    r.fit.ok()
}

/// The CNN's rotation fit over a rendered sequence (camera frame → table).
pub(crate) fn cnn_fit(
    net: &mut LogoCnn,
    cam: &CameraCalib,
    seq: &Sequence,
    cfg: &RotationFitConfig,
) -> Result<Option<RotationFit>, cnn::CnnError> {
    let crops: Vec<_> = seq.frames.iter().map(|f| (f.label.t, f.label.measured, f.crop.rgb.as_slice())).collect();
    Ok(cnn::fit_crops(net, cam, &crops, cfg)?.1.ok())
}

/// Renders the balls of `opts` and compares the sources on each; the CNN
/// columns are empty without a network.
pub fn compare(
    cal: &Calibration,
    cam: &CameraCalib,
    opts: &CompareOptions,
    mut net: Option<&mut LogoCnn>,
) -> Result<Vec<CompareBall>, cnn::CnnError> {
    let scene = Scene::new(cam.clone(), opts.colour);
    let n = opts.settings.len().max(1);
    // Ball k = i + n·j of setting i: unique across settings, as in logo::eval.
    let filmed: Vec<Filmed> = opts
        .settings
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, &setting)| {
            let scene = &scene;
            (0..opts.balls * 20 + 20)
                .filter_map(move |j| film(cal, scene, opts, i + n * j, setting))
                .take(opts.balls)
                .collect::<Vec<_>>()
        })
        .collect();
    let fit_cfg = RotationFitConfig::default();
    let partial: Vec<(Option<SpinEstimate>, Option<SpinEstimate>)> = filmed
        .par_iter()
        .map(|f| {
            let traj = trajectory_estimate(cal, &f.ball, opts.noise);
            let bg = logo_estimate(background(cam, &f.seq, &fit_cfg), &f.seq);
            (traj, bg)
        })
        .collect();
    let mut out = Vec::with_capacity(filmed.len());
    for (f, (traj, bg)) in filmed.iter().zip(partial) {
        let cnn = match net.as_deref_mut() {
            Some(net) => logo_estimate(cnn_fit(net, cam, &f.seq, &fit_cfg)?, &f.seq),
            None => None,
        };
        let mut gated = [false; 2];
        let mut fused = [None, None];
        if let Some(t) = &traj {
            for (i, logo) in [bg, cnn].iter().enumerate() {
                if let Some(l) = logo {
                    let r = fuse(t, l);
                    gated[i] = matches!(r, Fused::TrajectoryOnly(..));
                    fused[i] = Some(r.estimate().spin.into());
                }
            }
        }
        let v = |e: &Option<SpinEstimate>| e.as_ref().map(|e| <[f64; 3]>::from(e.spin));
        out.push(CompareBall {
            setting: f.seq.setting,
            ball: f.ball.index,
            spin_true: f.seq.spin_table.into(),
            spin: [v(&traj), v(&bg), v(&cnn), fused[0], fused[1]],
            gated,
        });
    }
    Ok(out)
}

/// One row of the comparison: per source, how many balls it gave a spin
/// for and the error summary over those, rps.
#[derive(Clone, Debug, Serialize)]
pub struct CompareRow {
    /// The group's name (a setting, or `all`).
    pub group: String,
    /// Balls in the group.
    pub balls: usize,
    /// Balls each source gave a spin for, in [`SOURCES`] order.
    pub answered: [usize; 5],
    /// |ω̂ − ω| per source over the balls it gave a spin for, rps.
    pub error_rps: [Summary; 5],
}

/// One row named `group` over `balls`.
pub fn summarise(group: &str, balls: &[&CompareBall]) -> CompareRow {
    let mut answered = [0; 5];
    let mut errs: [Vec<f64>; 5] = Default::default();
    for b in balls {
        for (i, e) in b.errors_rps().into_iter().enumerate() {
            if let Some(e) = e {
                answered[i] += 1;
                errs[i].push(e);
            }
        }
    }
    CompareRow { group: group.to_owned(), balls: balls.len(), answered, error_rps: errs.map(|e| Summary::of(&e)) }
}
