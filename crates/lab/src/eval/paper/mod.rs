//! `topspin eval paper`: the paper's tables and figures, reproduced on the
//! simulator (tracker and camera models) and on the real MPI recordings,
//! beside the paper's own numbers, and beaten where we can.
//!
//! - [`bounce`]: Table III, bounce-point error with the fitted spin and
//!   without spin (a Kalman filter on position and velocity), per setting.
//! - [`flights`]: the filmed flights shared by Table IV and the logo
//!   metrics: rendered crops, the background-subtraction variants, the
//!   trajectory fits, and the two extension points ([`flights::CropPredictor`]
//!   for a CNN, [`flights::SpinFusion`] for a fused estimate).
//! - [`classify`]: Table IV, spin-type classification by nearest median.
//! - [`logo_metrics`]: §III/§V, vector-angle, classification and geodesic
//!   errors and the processing time per crop of each logo method.
//! - [`real`]: bounce and 0.3 s-ahead error on the real recordings.
//! - [`plug`]: the product's CNN and logo + trajectory fusion as those
//!   extensions.
//! - [`figures`](mod@figures): the paper's figures (and ours) as SVG, with plotters.
//! - [`report`]: the whole run as Markdown (`tables.md`) and JSON.
//!
//! What this module must not do: read a clock (the caller passes one for the
//! per-crop timing), print, or touch files (the command line writes them).
//! Everything is seeded; the numbers do not depend on the thread count.

pub mod bounce;
pub mod classify;
pub mod figures;
pub mod flights;
pub mod logo_metrics;
pub mod plug;
pub mod real;
pub mod report;

use serde::Serialize;

use topspin_sim::Setting;

/// How a paper run is made.
#[derive(Copy, Clone, Debug, PartialEq, Serialize)]
pub struct PaperConfig {
    /// Seed of every simulated ball and rendering.
    pub seed: u64,
    /// Table III: trajectories per launcher setting (the paper: 10).
    pub bounce_balls: usize,
    /// Table IV and the logo metrics: filmed flights per setting (the paper: 50).
    pub flights: usize,
    /// Ceiling-camera crops per flight (the paper: 10 to 30).
    pub frames: usize,
    /// Tracker noise per axis, mm.
    pub noise_mm: f64,
    /// Tracker rate, Hz.
    pub tracker_hz: f64,
    /// Balls tried per setting to find `flights` that fly through the
    /// camera's filmed strip, as a multiple of `flights`.
    pub tries_factor: usize,
}

impl Default for PaperConfig {
    fn default() -> Self {
        PaperConfig {
            seed: 1,
            bounce_balls: 10,
            flights: 50,
            frames: 20,
            noise_mm: 2.0,
            tracker_hz: 150.0,
            tries_factor: 4,
        }
    }
}

impl PaperConfig {
    /// The tracker model of the simulated flights.
    pub fn tracker(&self) -> topspin_sim::TrackerModel {
        topspin_sim::TrackerModel {
            rate_hz: self.tracker_hz,
            noise_sigma: self.noise_mm * 1e-3,
            ..topspin_sim::TrackerModel::default()
        }
    }
}

/// Where a long run reports its progress (a progress bar, or nothing).
pub trait Progress: Sync {
    /// A new stage of `total` steps begins.
    fn stage(&self, name: &str, total: u64);
    /// `n` steps of the current stage are done.
    fn inc(&self, n: u64);
}

/// No progress reporting.
#[derive(Copy, Clone, Debug, Default)]
pub struct Silent;

impl Progress for Silent {
    fn stage(&self, _name: &str, _total: u64) {}
    fn inc(&self, _n: u64) {}
}

/// Seconds on some monotonic clock, for the per-crop timing only (the
/// library reads no clock itself).
pub type Clock<'a> = &'a (dyn Fn() -> f64 + Sync);

/// Ball index `j` of setting `i` in a run: unique across settings, so
/// that every setting draws its own balls from one seed.
pub(crate) fn ball_index(setting: usize, j: usize) -> usize {
    setting + Setting::ALL.len() * j
}

use crate::data::eval::{Predictor, PreparedTrajectory, predicted_position};
use crate::data::spin::FitPredictor;
use flights::{CropPredictor, FlightSet, SpinFusion};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::logo::LogoMethod;
use topspin_core::logo::{RotationFitConfig, fit_rotation};
use topspin_core::physics::Vec3;
use topspin_sim::render::{BallColour, Scene, SequenceOptions, render_sequence};
use topspin_sim::truth::true_position_at;
use topspin_sim::{SimBall, simulate_ball};

/// The methods a run cannot provide itself: a crop predictor (the CNN)
/// and a fusion of logo and trajectory. `None`: their rows say "no model".
#[derive(Default)]
pub struct Extensions<'a> {
    /// The crop predictor (the CNN).
    pub cnn: Option<&'a mut dyn CropPredictor>,
    /// The fusion of logo and trajectory.
    pub fusion: Option<&'a mut dyn SpinFusion>,
}

impl std::fmt::Debug for Extensions<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Extensions")
            .field("cnn", &self.cnn.as_ref().map(|c| c.name()))
            .field("fusion", &self.fusion.as_ref().map(|c| c.name()))
            .finish()
    }
}

/// The tables of one run (the figures and the latency come separately).
#[derive(Debug)]
pub struct Tables {
    /// Table III.
    pub bounce: bounce::BounceTable,
    /// The filmed flights behind Table IV and the logo metrics.
    pub set: FlightSet,
    /// Table IV: one classification per method of [`flights::SpinMethod::ALL`].
    pub classes: Vec<classify::MethodClasses>,
    /// The logo metrics, one row per logo method.
    pub logo: Vec<logo_metrics::LogoRow>,
    /// The real-data table, given the recordings.
    pub real: Option<real::RealTable>,
    /// Seconds per stage on `clock`.
    pub stage_seconds: Vec<(String, f64)>,
}

/// Runs every table: Table III, the filmed flights (with the extensions),
/// Table IV, the logo metrics and, given the recordings, the real-data
/// table (under `cal`'s physics).
pub fn run_tables(
    cal: &Calibration,
    cam: &CameraCalib,
    cfg: &PaperConfig,
    real_data: Option<&[PreparedTrajectory]>,
    ext: Extensions<'_>,
    progress: &dyn Progress,
    clock: Clock<'_>,
) -> Tables {
    let mut stages = Vec::new();
    let mut t = clock();
    let mut lap = |name: &str, stages: &mut Vec<(String, f64)>| {
        let now = clock();
        stages.push((name.to_owned(), now - t));
        t = now;
    };
    let bounce = bounce::table(cal, cfg, progress);
    lap("Table III (bounce prediction)", &mut stages);
    let mut set = flights::collect(cal, cam, cfg, ext.cnn.is_some(), progress, clock);
    lap("filmed flights (render, logo, trajectory fits)", &mut stages);
    if let Some(cnn) = ext.cnn {
        flights::run_cnn(&mut set, cam, cnn, progress, clock);
        set.sequences.iter_mut().for_each(|s| *s = None);
        lap("CNN", &mut stages);
    }
    if let Some(fusion) = ext.fusion {
        flights::run_fusion(&mut set, fusion);
    }
    let classes = classify::table(&set.flights);
    let logo = logo_metrics::table(&set.flights);
    let real = real_data.map(|d| {
        progress.stage("real recordings", 1);
        let r = real::table(d, &cal.physics, "calibrated (calib/physics.toml)");
        progress.inc(1);
        r
    });
    lap("Table IV, logo metrics, real data", &mut stages);
    Tables { bounce, set, classes, logo, real, stage_seconds: stages }
}

/// A simulated ball of `setting` index `i` (its first ball of the run).
fn first_ball(cal: &Calibration, cfg: &PaperConfig, i: usize) -> anyhow::Result<SimBall> {
    let prop = cal.propagator();
    Ok(simulate_ball(cfg.seed, ball_index(i, 0), Setting::ALL[i], &prop, cal.strike.hit_plane_x, &cfg.tracker())?)
}

fn path_of(prop: &topspin_core::physics::Propagator, pred: &crate::data::eval::Prediction, t_end: f64) -> Vec<Vec3> {
    let n = ((t_end - pred.t) / 0.004).ceil().max(1.0) as usize;
    (0..=n).filter_map(|k| predicted_position(prop, pred, pred.t + (t_end - pred.t) * k as f64 / n as f64)).collect()
}

/// Every figure as (file name, SVG).
pub fn figures(
    cal: &Calibration,
    cam: &CameraCalib,
    cfg: &PaperConfig,
    set: &FlightSet,
    latency: Option<&report::LatencyRun>,
) -> anyhow::Result<Vec<(String, String)>> {
    let prop = cal.propagator();
    let noise = cfg.noise_mm * 1e-3;
    let mut out = Vec::new();
    // Fig. 6 and 7: a topspin-medium and a topspin-high ball.
    out.push((
        "fig6-two-point-velocity.svg".into(),
        figures::two_point_velocity(&first_ball(cal, cfg, 7)?, cfg.noise_mm)?,
    ));
    out.push(("fig7-accelerations.svg".into(), figures::accelerations(&first_ball(cal, cfg, 8)?, &prop, noise)?));
    // Fig. 5: the first filmed backspin-medium flight whose segment fit succeeded.
    if let Some(f) = set
        .flights
        .iter()
        .find(|f| f.setting == Setting::ALL[1] && f.estimate(flights::SpinMethod::BgSegment).spin().is_some())
    {
        let colour = if f.colour == BallColour::White.name() { BallColour::White } else { BallColour::Orange };
        let ball = simulate_ball(cfg.seed, f.ball, f.setting, &prop, cal.strike.hit_plane_x, &cfg.tracker())?;
        let seq = render_sequence(
            &Scene::new(cam.clone(), colour),
            &ball.truth,
            &prop,
            cfg.seed,
            f.ball,
            &SequenceOptions { frames: cfg.frames },
        );
        let zero = || 0.0;
        if let Some((ms, _)) = flights::bg_measurements(cam, &seq, &zero) {
            let samples = flights::logo_samples(&seq, &ms, LogoMethod::Segment);
            if let Ok(fit) = fit_rotation(&samples, &RotationFitConfig::default()) {
                let pos: Vec<Vec3> = samples.iter().filter_map(|s| s.pos).collect();
                let title = format!(
                    "{} ball {} ({}): logo centres, camera frame, {:.1} rps",
                    f.setting,
                    f.ball,
                    f.colour,
                    topspin_core::physics::rad_to_rps(fit.rate)
                );
                out.push(("fig5-logo-plane.svg".into(), figures::logo_plane(&title, &pos, &fit)?));
            }
        }
    }
    // Predicted vs true, one medium ball per spin type.
    let mut cases = Vec::new();
    for i in [1, 4, 7] {
        let ball = first_ball(cal, cfg, i)?;
        let samples = bounce::pre_net(&ball);
        let launch = ball.truth.to_launch();
        let t_end = ball.truth.end_t;
        let truth: Vec<Vec3> = (0..=200).map(|k| true_position_at(&launch, &prop, t_end * k as f64 / 200.0)).collect();
        let spin = FitPredictor::refined(&cal.physics).with_noise(noise).predict(&samples);
        let kf = bounce::KalmanNoSpin { propagator: prop, noise }.predict(&samples);
        cases.push(figures::PredictedCase {
            title: format!("{} ({:.0} rps)", ball.truth.setting, ball.truth.spin_rps),
            truth,
            observed: samples.iter().map(|s| s.1).collect(),
            with_spin: spin.map(|p| path_of(&prop, &p, t_end)).unwrap_or_default(),
            without_spin: kf.map(|p| path_of(&prop, &p, t_end)).unwrap_or_default(),
        });
    }
    out.push(("predicted-trajectories.svg".into(), figures::predicted(&cases)?));
    let methods: Vec<flights::SpinMethod> = flights::SpinMethod::ALL
        .into_iter()
        .filter(|m| set.flights.iter().any(|f| f.estimate(*m).spin().is_some()))
        .collect();
    out.push(("spin-clusters.svg".into(), figures::clusters(&set.flights, &methods)?));
    if let Some(l) = latency {
        out.push(("latency.svg".into(), figures::latency(l)?));
    }
    Ok(out)
}
