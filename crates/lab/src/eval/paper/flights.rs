//! The filmed flights behind Table IV and the logo metrics: for each
//! launcher setting, the first `flights` balls that fly through the
//! ceiling camera's filmed strip (orange and white alternating), each with
//! its rendered crops, the three background-subtraction variants (paper's
//! centroid, + segment fit, our area-weighted mean), the two trajectory
//! fits (paper's cubic + Magnus solve, our refinement) on the observations
//! before the net, and the truth.
//!
//! Two extension points fill the remaining methods:
//!
//! - [`CropPredictor`]: anything that maps one 60 × 60 crop to a logo
//!   visibility and position (the CNN of the paper's §III). [`run_cnn`]
//!   feeds it every crop of every flight, fits the rotation with the same
//!   fit as the background method, and fills [`SpinMethod::Cnn`] and the
//!   network metrics.
//! - [`SpinFusion`]: anything that turns one flight's fits (trajectory and
//!   logo) into one spin; `run_fusion` fills [`SpinMethod::Fused`].
//!
//! Without them those rows say "no model".

use nalgebra::UnitQuaternion;
use rayon::prelude::*;
use serde::Serialize;

use super::{Clock, PaperConfig, Progress, ball_index};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::fit::{FitConfig, Method, Sample, TrajectoryFit, fit_trajectory};
use topspin_core::logo::BallView;
use topspin_core::logo::LogoMethod;
use topspin_core::logo::{BallReference, CropImage, DetectorConfig, LogoMeasurement, detect};
use topspin_core::logo::{LogoSample, RotationFit, RotationFitConfig, fit_rotation};
use topspin_core::logo::{geodesic_deg, swing_to};
use topspin_core::physics::Vec3;
use topspin_sim::render::{BallColour, MIN_FILMED_FRAMES, Scene, Sequence, SequenceOptions, render_sequence};
use topspin_sim::{Setting, SimBall, simulate_ball};

/// A way of estimating a flight's spin, as the rows of Table IV.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SpinMethod {
    /// Logo by background subtraction, the paper's plain centre.
    BgCentroid,
    /// The same with the circular-segment correction (paper).
    BgSegment,
    /// Area-weighted centre with the segment correction (ours).
    BgWeighted,
    /// A CNN's logo positions ([`CropPredictor`]).
    Cnn,
    /// The paper's cubic + linear Magnus solve.
    TrajectoryPaper,
    /// Our flight-model refinement (Levenberg–Marquardt).
    TrajectoryRefined,
    /// Logo and trajectory fused ([`SpinFusion`]).
    Fused,
}

impl SpinMethod {
    /// Every method, in table order ([`SpinMethod::index`] is the position
    /// here).
    pub const ALL: [SpinMethod; 7] = [
        SpinMethod::BgCentroid,
        SpinMethod::BgSegment,
        SpinMethod::BgWeighted,
        SpinMethod::Cnn,
        SpinMethod::TrajectoryPaper,
        SpinMethod::TrajectoryRefined,
        SpinMethod::Fused,
    ];

    /// The method's position in [`SpinMethod::ALL`] and in
    /// [`Flight::estimates`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// The row's name in the tables.
    pub fn label(self) -> &'static str {
        match self {
            SpinMethod::BgCentroid => "background subtraction",
            SpinMethod::BgSegment => "bg. sub. + segment fit",
            SpinMethod::BgWeighted => "bg. sub., weighted + segment (ours)",
            SpinMethod::Cnn => "CNN",
            SpinMethod::TrajectoryPaper => "trajectory fitting (paper)",
            SpinMethod::TrajectoryRefined => "trajectory, refined (ours)",
            SpinMethod::Fused => "fused logo + trajectory",
        }
    }

    /// The background-subtraction variant behind a logo method.
    pub(crate) fn bg_variant(self) -> Option<LogoMethod> {
        match self {
            SpinMethod::BgCentroid => Some(LogoMethod::Centroid),
            SpinMethod::BgSegment => Some(LogoMethod::Segment),
            SpinMethod::BgWeighted => Some(LogoMethod::Weighted),
            _ => None,
        }
    }
}

/// One method's spin for one flight.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Estimate {
    /// Table frame, rad/s.
    Spin([f64; 3]),
    /// The method ran and gave no spin (the reason).
    Failed(String),
    /// The method is not available in this run (no model).
    NoModel,
}

impl Estimate {
    /// The spin, rad/s, table frame, where the method gave one.
    pub fn spin(&self) -> Option<Vec3> {
        match self {
            Estimate::Spin(s) => Some(Vec3::from(*s)),
            _ => None,
        }
    }
}

/// What a crop predictor (a CNN) says about one crop.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CropPrediction {
    /// Logo visibility in [−1, 1] (the paper's output; > 0: visible).
    pub visibility: f64,
    /// The logo's centre on the unit sphere, camera frame.
    pub logo_camera: Option<Vec3>,
    /// The swing from the view frame's +z onto the logo, where the
    /// predictor gives one (for the geodesic error): the ball's pose up to
    /// the twist about the logo's axis, which a circular logo cannot show.
    pub logo_swing: Option<UnitQuaternion<f64>>,
}

/// A per-crop logo predictor: the CNN plugs in here. It sees the crop as
/// the camera side cut it and the ball's view (circle and view frame); it
/// may keep state (buffers, a session) and is called from one thread.
pub trait CropPredictor {
    /// A short name for the tables (e.g. the model file).
    fn name(&self) -> String;
    /// The logo's visibility and position in one crop.
    fn predict(&mut self, crop: &CropImage<'_>, view: &BallView) -> CropPrediction;
}

/// Per-frame metrics of a CNN on one flight.
#[derive(Clone, Debug, Default, Serialize)]
pub struct CnnFrames {
    /// Frames where (visibility > 0) ⇔ logo centre on the visible side.
    pub classified_right: usize,
    /// Vector angle, degrees, on frames truly visible and predicted visible.
    #[serde(skip)]
    pub angle_err: Vec<f64>,
    /// Geodesic distance, degrees, on the same frames (where a pose came).
    #[serde(skip)]
    pub geodesic_err: Vec<f64>,
}

/// One filmed flight.
#[derive(Clone, Debug, Serialize)]
pub struct Flight {
    /// The launcher setting.
    pub setting: Setting,
    /// The ball's index in the run.
    pub ball: usize,
    /// The ball's colour (`orange` or `white`).
    pub colour: &'static str,
    /// Crops rendered of the flight.
    pub frames: usize,
    /// Frames whose logo centre is on the visible hemisphere.
    pub truth_visible: usize,
    /// Frames where the background method's "found" ⇔ truly visible.
    pub bg_classified_right: usize,
    /// Vector-angle errors, degrees, per background variant (centroid,
    /// segment, weighted), on frames with a logo found and some of it on
    /// the visible hemisphere.
    #[serde(skip)]
    pub bg_angle_err: [Vec<f64>; 3],
    /// Seconds in the background detector over this flight's crops
    /// (the reference included).
    pub bg_seconds: f64,
    /// Seconds in the crop predictor (the CNN) over this flight's crops;
    /// 0 without one.
    pub cnn_seconds: f64,
    /// The CNN's per-frame metrics, once it ran.
    pub cnn: Option<CnnFrames>,
    /// True spin, rad/s, table frame.
    pub spin_true: [f64; 3],
    /// Per [`SpinMethod::ALL`].
    pub estimates: Vec<Estimate>,
}

impl Flight {
    /// The estimate of method `m`.
    pub fn estimate(&self, m: SpinMethod) -> &Estimate {
        &self.estimates[m.index()]
    }
}

/// The fits behind a flight's estimates (for fusion and figures).
#[derive(Clone, Debug, Default)]
pub struct FlightFits {
    /// The paper's trajectory fit, where it succeeded.
    pub paper: Option<TrajectoryFit>,
    /// The refined trajectory fit, where it succeeded.
    pub refined: Option<TrajectoryFit>,
    /// Per background variant, table frame.
    pub bg: [Option<RotationFit>; 3],
    /// The CNN's, table frame.
    pub cnn: Option<RotationFit>,
    /// Seconds from the first crop to the last (the logo fits' span).
    pub logo_span: f64,
}

/// Everything a fusion sees of one flight.
#[derive(Copy, Clone, Debug)]
pub struct FusionInput<'a> {
    /// The flight and its estimates.
    pub flight: &'a Flight,
    /// The fits behind them.
    pub fits: &'a FlightFits,
}

/// A fused estimate (logo + Magnus): plugs in here.
pub trait SpinFusion {
    /// A short name for the tables.
    fn name(&self) -> String;
    /// One flight's fused spin, rad/s, table frame; `None`: no spin.
    fn fuse(&mut self, input: &FusionInput<'_>) -> Option<Vec3>;
}

/// All filmed flights of a run, in setting order.
#[derive(Debug, Default)]
pub struct FlightSet {
    /// The flights, in setting order.
    pub flights: Vec<Flight>,
    /// The fits behind each flight, in the same order.
    pub fits: Vec<FlightFits>,
    /// The rendered sequences, kept only when asked (a CNN needs them).
    pub sequences: Vec<Option<Sequence>>,
    /// Balls tried per setting, and how many of them were filmed.
    pub tried: [usize; 9],
    /// The crop predictor's name, once run.
    pub cnn_name: Option<String>,
    /// The fusion's name, once run.
    pub fusion_name: Option<String>,
}

/// The observations before the true net crossing.
pub(crate) fn pre_net_samples(ball: &SimBall) -> Vec<Sample> {
    let end = ball.truth.net_crossing_t.unwrap_or(f64::INFINITY);
    ball.observations.iter().filter(|o| o.t < end).map(|o| Sample::new(o.t, o.pos)).collect()
}

/// The background method over a sequence: per frame the measurement (or
/// none), with the seconds spent (reference + detection) on `clock`.
pub(crate) fn bg_measurements(
    cam: &CameraCalib,
    seq: &Sequence,
    clock: Clock<'_>,
) -> Option<(Vec<Option<LogoMeasurement>>, f64)> {
    let det = DetectorConfig::for_logo(cam.logo_angular_radius());
    let t0 = clock();
    let pairs: Vec<(CropImage<'_>, BallView)> = seq
        .frames
        .iter()
        .map(|f| {
            let m = f.label.measured;
            BallView::new(cam, m.u, m.v, m.radius).map(|v| (f.crop_image(), v))
        })
        .collect::<Option<_>>()?;
    let reference = BallReference::from_crops(&pairs, det.colour_fraction)?;
    let ms = pairs.iter().map(|(c, v)| detect(&det, &reference, c, v)).collect();
    Some((ms, clock() - t0))
}

/// Logo samples of a variant (camera frame).
pub(crate) fn logo_samples(seq: &Sequence, ms: &[Option<LogoMeasurement>], variant: LogoMethod) -> Vec<LogoSample> {
    seq.frames
        .iter()
        .zip(ms)
        .map(|(f, m)| LogoSample::new(f.label.t, m.as_ref().map(|m| variant.position(m))))
        .collect()
}

fn estimate_of<E: ToString>(r: Result<Vec3, E>) -> Estimate {
    match r {
        Ok(s) => Estimate::Spin(s.into()),
        Err(e) => Estimate::Failed(e.to_string()),
    }
}

/// One filmed flight; `None` when ball k is not filmed for `MIN_FILMED_FRAMES`.
#[allow(clippy::too_many_arguments)]
fn process(
    cal: &Calibration,
    scene: &Scene,
    cfg: &PaperConfig,
    setting: Setting,
    k: usize,
    keep_crops: bool,
    clock: Clock<'_>,
) -> Option<(Flight, FlightFits, Option<Sequence>)> {
    let prop = cal.propagator();
    let cam = &scene.cam;
    let ball = simulate_ball(cfg.seed, k, setting, &prop, cal.strike.hit_plane_x, &cfg.tracker()).ok()?;
    let seq = render_sequence(scene, &ball.truth, &prop, cfg.seed, k, &SequenceOptions { frames: cfg.frames });
    if seq.frames.len() < MIN_FILMED_FRAMES {
        return None;
    }
    let (ms, bg_seconds) = bg_measurements(cam, &seq, clock)?;
    let rot_cfg = RotationFitConfig::default();
    let mut fits = FlightFits { logo_span: seq.span(), ..FlightFits::default() };
    let mut estimates = vec![Estimate::NoModel; SpinMethod::ALL.len()];
    for (i, variant) in LogoMethod::ALL.into_iter().enumerate() {
        let r = fit_rotation(&logo_samples(&seq, &ms, variant), &rot_cfg).map(|f| f.rotated(&cam.table_from_camera));
        fits.bg[i] = r.ok();
        let m = [SpinMethod::BgCentroid, SpinMethod::BgSegment, SpinMethod::BgWeighted][i];
        estimates[m.index()] = estimate_of(r.map(|f| f.spin));
    }
    let samples = pre_net_samples(&ball);
    let noise = cfg.noise_mm * 1e-3;
    for (method, m) in [(Method::Paper, SpinMethod::TrajectoryPaper), (Method::Refined, SpinMethod::TrajectoryRefined)]
    {
        let r = fit_trajectory(&samples, &prop, &FitConfig::new(method, cal.strike.hit_plane_x).with_noise(noise));
        estimates[m.index()] = estimate_of(r.as_ref().map(|f| f.spin).map_err(|e| e.to_string()));
        match method {
            Method::Paper => fits.paper = r.ok(),
            Method::Refined => fits.refined = r.ok(),
        }
    }
    let limb = -cam.logo_angular_radius().sin();
    let mut flight = Flight {
        setting,
        ball: k,
        colour: scene.colour.name(),
        frames: seq.frames.len(),
        truth_visible: 0,
        bg_classified_right: 0,
        bg_angle_err: Default::default(),
        bg_seconds,
        cnn_seconds: 0.0,
        cnn: None,
        spin_true: ball.truth.spin,
        estimates,
    };
    for (f, m) in seq.frames.iter().zip(&ms) {
        let l = &f.label;
        flight.truth_visible += l.logo_visible as usize;
        flight.bg_classified_right += (m.is_some() == l.logo_visible) as usize;
        if let Some(m) = m
            && l.logo_facing > limb
        {
            for (i, variant) in LogoMethod::ALL.into_iter().enumerate() {
                flight.bg_angle_err[i].push(variant.position(m).angle(&l.logo_camera).to_degrees());
            }
        }
    }
    Some((flight, fits, keep_crops.then_some(seq)))
}

/// Renders and processes the filmed flights of `cfg` (parallel over
/// settings and colours; the result does not depend on the thread count).
/// `keep_crops` keeps the sequences for a [`CropPredictor`].
pub fn collect(
    cal: &Calibration,
    cam: &CameraCalib,
    cfg: &PaperConfig,
    keep_crops: bool,
    progress: &dyn Progress,
    clock: Clock<'_>,
) -> FlightSet {
    let colours = BallColour::ALL;
    let jobs: Vec<(usize, usize)> =
        (0..Setting::ALL.len()).flat_map(|i| (0..colours.len()).map(move |c| (i, c))).collect();
    progress.stage("Table IV: filmed flights", (Setting::ALL.len() * cfg.flights) as u64);
    type Got = (usize, usize, Vec<(usize, Flight, FlightFits, Option<Sequence>)>);
    let mut per_job: Vec<Got> = jobs
        .par_iter()
        .map(|&(i, c)| {
            let scene = Scene::new(cam.clone(), colours[c]);
            // Colour c films balls j ≡ c (mod 2): half the flights each.
            let want = (cfg.flights + colours.len() - 1 - c) / colours.len();
            let mut got = Vec::new();
            let mut tried = 0;
            let mut j = c;
            while got.len() < want && tried < cfg.tries_factor.max(1) * want.max(1) {
                let k = ball_index(i, j);
                tried += 1;
                if let Some((f, fits, seq)) = process(cal, &scene, cfg, Setting::ALL[i], k, keep_crops, clock) {
                    got.push((j, f, fits, seq));
                    progress.inc(1);
                }
                j += colours.len();
            }
            (i, tried, got)
        })
        .collect();
    per_job.sort_by_key(|(i, _, _)| *i);
    let mut set = FlightSet::default();
    let mut rows: Vec<(usize, usize, Flight, FlightFits, Option<Sequence>)> = Vec::new();
    for (i, tried, got) in per_job {
        set.tried[i] += tried;
        rows.extend(got.into_iter().map(|(j, f, fits, seq)| (i, j, f, fits, seq)));
    }
    rows.sort_by_key(|r| (r.0, r.1));
    for (_, _, f, fits, seq) in rows {
        set.flights.push(f);
        set.fits.push(fits);
        set.sequences.push(seq);
    }
    set
}

/// Runs `predictor` over every crop of every flight (sequences must have
/// been kept), fits the rotation from its logo positions and fills the
/// CNN's estimate and frame metrics.
pub fn run_cnn(
    set: &mut FlightSet,
    cam: &CameraCalib,
    predictor: &mut dyn CropPredictor,
    progress: &dyn Progress,
    clock: Clock<'_>,
) {
    progress.stage("CNN over the crops", set.flights.len() as u64);
    set.cnn_name = Some(predictor.name());
    let limb = -cam.logo_angular_radius().sin();
    for ((flight, fits), seq) in set.flights.iter_mut().zip(&mut set.fits).zip(&set.sequences) {
        progress.inc(1);
        let Some(seq) = seq else {
            flight.estimates[SpinMethod::Cnn.index()] = Estimate::Failed("crops not kept".into());
            continue;
        };
        let mut frames = CnnFrames::default();
        let mut samples = Vec::with_capacity(seq.frames.len());
        for f in &seq.frames {
            let l = &f.label;
            let Some(view) = BallView::new(cam, l.measured.u, l.measured.v, l.measured.radius) else {
                samples.push(LogoSample::new(l.t, None));
                continue;
            };
            let t0 = clock();
            let p = predictor.predict(&f.crop_image(), &view);
            flight.cnn_seconds += clock() - t0;
            let visible = p.visibility > 0.0;
            frames.classified_right += (visible == l.logo_visible) as usize;
            let pos = if visible { p.logo_camera.filter(|v| v.iter().all(|c| c.is_finite())) } else { None };
            if let Some(pos) = pos
                && l.logo_facing > limb
            {
                frames.angle_err.push(pos.angle(&l.logo_camera).to_degrees());
                if let Some(q) = p.logo_swing {
                    frames.geodesic_err.push(geodesic_deg(&q, &swing_to(&view.to_view(&l.logo_camera))));
                }
            }
            samples.push(LogoSample::new(l.t, pos.map(|v| v.normalize())));
        }
        let r = fit_rotation(&samples, &RotationFitConfig::default()).map(|f| f.rotated(&cam.table_from_camera));
        fits.cnn = r.ok();
        flight.estimates[SpinMethod::Cnn.index()] = estimate_of(r.map(|f| f.spin));
        flight.cnn = Some(frames);
    }
}

/// Runs `fusion` over every flight and fills the fused estimate.
pub(crate) fn run_fusion(set: &mut FlightSet, fusion: &mut dyn SpinFusion) {
    set.fusion_name = Some(fusion.name());
    for (flight, fits) in set.flights.iter_mut().zip(&set.fits) {
        let spin = fusion.fuse(&FusionInput { flight, fits });
        flight.estimates[SpinMethod::Fused.index()] = match spin {
            Some(s) => Estimate::Spin(s.into()),
            None => Estimate::Failed("fusion gave no spin".into()),
        };
    }
}
