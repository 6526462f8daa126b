//! The logo thread's work, sans-IO: TTI1 crops in (one at a time, capture
//! times on our clock), one spin per filmed ball out.
//!
//! Crops of one ball come at 380 Hz while it crosses the camera's strip; a
//! gap longer than [`SEQUENCE_GAP`] ends the sequence. A sequence is fitted
//! when it holds [`SEQUENCE_LEN`] crops (the rest of that pass is ignored)
//! or when it ends with at least [`MIN_CROPS`]. The crops are copied into
//! buffers sized at construction; the CNN runs in batches of up to
//! [`cnn::MAX_BATCH`] as they fill, the background method at the end (its
//! ball-without-logo reference needs the whole sequence).
//!
//! This is not a hot path: the inference backend and the background
//! method's reference allocate, once per batch or sequence. It runs on its
//! own thread and talks to the estimator through a ring only.

use crate::calib::camera::CameraCalib;
use crate::estimator::LogoSpin;
use crate::logo::ball::Circle;
use crate::logo::cnn::{self, CnnOutput, LogoNetwork};
use crate::logo::detect::{CropImage, DetectorConfig};
use crate::logo::fusion::SpinEstimate;
use crate::logo::pipeline::{CropInput, LogoMethod, process_sequence};
use crate::logo::rotation::{LogoSample, RotationFitConfig, fit_rotation};
use crate::logo::view::BallView;
use crate::time::{Duration, Instant};
use crate::wire::crop::Crop;
use crate::wire::crop::crop_origin;

/// Crops fitted per ball (≈ 53 ms at 380 Hz).
pub const SEQUENCE_LEN: usize = 20;
/// Fewest crops worth a fit.
pub(crate) const MIN_CROPS: usize = 10;
/// A gap that ends a sequence (≈ 4 frames at 380 Hz).
pub(crate) const SEQUENCE_GAP: Duration = Duration::from_millis(12);

/// How logo positions are found.
pub enum LogoEngine {
    /// The paper's background subtraction with the given position method.
    Background(LogoMethod),
    /// The CNN.
    Cnn(Box<dyn LogoNetwork>),
}

impl std::fmt::Debug for LogoEngine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LogoEngine::Background(m) => write!(f, "Background({})", m.name()),
            LogoEngine::Cnn(c) => write!(f, "Cnn({})", c.engine_name()),
        }
    }
}

/// The logo in the latest crop, as the CNN saw it.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SeenLogo {
    /// Its centre in the crop, px.
    pub crop_px: [f32; 2],
    /// Its direction on the ball, table frame.
    pub table: crate::physics::Vec3,
}

/// Counters of the logo thread.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LogoCounters {
    /// Crops received.
    pub crops: u64,
    /// Crops ignored: not 60 × 60, or not later than the previous one.
    pub dropped: u64,
    /// Sequences ended and handed to the fit (too short ones included).
    pub sequences: u64,
    /// Sequences that gave a spin.
    pub fitted: u64,
    /// CNN batches whose inference failed (their logos count as unseen).
    pub inference_failures: u64,
}

/// The logo thread's state.
#[derive(Debug)]
pub struct LogoStream {
    cam: CameraCalib,
    method: LogoEngine,
    det: DetectorConfig,
    fit: RotationFitConfig,
    /// Pixels of the current sequence, crop after crop.
    pixels: Vec<u8>,
    times: Vec<Instant>,
    circles: Vec<Circle>,
    /// CNN answers for the crops run so far.
    outputs: Vec<CnnOutput>,
    /// The current pass is already fitted: ignore it until a gap.
    done: bool,
    last: Option<Instant>,
    counters: LogoCounters,
}

const CROP_BYTES: usize = cnn::INPUT_SIZE * cnn::INPUT_SIZE * 3;

impl LogoStream {
    /// An empty stream for the ceiling camera `cam`, finding logos with
    /// `method`.
    pub fn new(cam: CameraCalib, method: LogoEngine) -> Self {
        let det = DetectorConfig::for_logo(cam.logo_angular_radius());
        LogoStream {
            cam,
            method,
            det,
            fit: RotationFitConfig::default(),
            pixels: Vec::with_capacity(SEQUENCE_LEN * CROP_BYTES),
            times: Vec::with_capacity(SEQUENCE_LEN),
            circles: Vec::with_capacity(SEQUENCE_LEN),
            outputs: Vec::with_capacity(SEQUENCE_LEN),
            done: false,
            last: None,
            counters: LogoCounters::default(),
        }
    }

    /// The counters so far.
    pub fn counters(&self) -> LogoCounters {
        self.counters
    }

    /// Takes one crop; returns the spin of a sequence it completed.
    pub fn crop(&mut self, c: &Crop<'_>) -> Option<LogoSpin> {
        self.counters.crops += 1;
        if c.width as usize != cnn::INPUT_SIZE
            || c.height as usize != cnn::INPUT_SIZE
            || self.last.is_some_and(|l| c.capture <= l)
        {
            self.counters.dropped += 1;
            return None;
        }
        let mut out = None;
        if self.last.is_some_and(|l| c.capture - l > SEQUENCE_GAP) {
            out = self.finish();
        }
        self.last = Some(c.capture);
        if self.done {
            return out;
        }
        self.pixels.extend_from_slice(c.pixels);
        self.times.push(c.capture);
        self.circles.push(Circle { u: c.u as f64, v: c.v as f64, radius: c.radius as f64 });
        if let LogoEngine::Cnn(_) = self.method
            && (self.times.len() - self.outputs.len() == cnn::MAX_BATCH || self.times.len() == SEQUENCE_LEN)
        {
            self.run_cnn();
        }
        if self.times.len() == SEQUENCE_LEN {
            let r = self.fit_sequence();
            self.done = true;
            return r.or(out);
        }
        out
    }

    /// The logo in the latest crop, once the network has run on it (the
    /// CNN runs in batches; the background method reports per sequence).
    pub fn last_logo(&self) -> Option<SeenLogo> {
        let i = self.times.len().checked_sub(1)?;
        let o = self.outputs.get(i)?.seen(cnn::VISIBLE_THRESHOLD)?;
        let c = self.circles[i];
        let view = BallView::new(&self.cam, c.u, c.v, c.radius)?;
        let (du, dv) = view.disc_to_pixel_offset(o.x, o.y);
        let (x0, y0) = crop_origin(c.u, c.v, cnn::INPUT_SIZE as u32, cnn::INPUT_SIZE as u32);
        Some(SeenLogo {
            crop_px: [(c.u + du - x0 as f64) as f32, (c.v + dv - y0 as f64) as f32],
            table: self.cam.table_from_camera * view.to_camera(&o),
        })
    }

    /// Ends a sequence that has gone quiet; call now and then.
    pub fn poll(&mut self, now: Instant) -> Option<LogoSpin> {
        if self.last.is_some_and(|l| now > l && now - l > SEQUENCE_GAP) {
            let r = self.finish();
            self.last = None;
            return r;
        }
        None
    }

    fn finish(&mut self) -> Option<LogoSpin> {
        let r = if self.done || self.times.is_empty() { None } else { self.fit_sequence() };
        self.pixels.clear();
        self.times.clear();
        self.circles.clear();
        self.outputs.clear();
        self.done = false;
        r
    }

    fn run_cnn(&mut self) {
        let LogoEngine::Cnn(net) = &mut self.method else { return };
        let from = self.outputs.len();
        let to = self.times.len();
        let mut crops: [&[u8]; cnn::MAX_BATCH] = [&[]; cnn::MAX_BATCH];
        for (k, i) in (from..to).enumerate() {
            crops[k] = &self.pixels[i * CROP_BYTES..(i + 1) * CROP_BYTES];
        }
        let mut answers = [CnnOutput::default(); cnn::MAX_BATCH];
        if net.infer_crops(&crops[..to - from], &mut answers).is_err() {
            self.counters.inference_failures += 1;
        }
        // A failed batch counts as unseen logos.
        self.outputs.extend_from_slice(&answers[..to - from]);
    }

    fn fit_sequence(&mut self) -> Option<LogoSpin> {
        let n = self.times.len();
        self.counters.sequences += 1;
        if n < MIN_CROPS {
            return None;
        }
        if let LogoEngine::Cnn(_) = self.method
            && self.outputs.len() < n
        {
            self.run_cnn();
        }
        let t0 = self.times[0];
        let secs = |t: Instant| (t - t0).as_secs_f64();
        let fit = match &self.method {
            LogoEngine::Cnn(_) => {
                let samples: Vec<LogoSample> =
                    (0..n).map(|i| self.outputs[i].sample(&self.cam, self.circles[i], secs(self.times[i]))).collect();
                fit_rotation(&samples, &self.fit).ok().map(|f| f.rotated(&self.cam.table_from_camera))
            }
            LogoEngine::Background(m) => {
                let inputs: Option<Vec<CropInput<'_>>> = (0..n)
                    .map(|i| {
                        let c = self.circles[i];
                        let (x0, y0) = crop_origin(c.u, c.v, cnn::INPUT_SIZE as u32, cnn::INPUT_SIZE as u32);
                        let rgb = &self.pixels[i * CROP_BYTES..(i + 1) * CROP_BYTES];
                        let crop = CropImage::new(x0, y0, cnn::INPUT_SIZE, cnn::INPUT_SIZE, rgb)?;
                        Some(CropInput { t: secs(self.times[i]), crop, circle: c })
                    })
                    .collect();
                inputs
                    .and_then(|inputs| process_sequence(&self.cam, &inputs, &self.det, &self.fit, *m).ok())
                    .and_then(|r| r.fit.ok())
            }
        };
        let fit = fit?;
        self.counters.fitted += 1;
        let est = SpinEstimate::from_rotation(&fit, secs(self.times[n - 1]));
        Some(LogoSpin { last_crop: self.times[n - 1], spin: est.spin, cov: est.cov })
    }
}
