//! A sequence of crops → logo positions → spin in the table frame. Builds
//! the ball-without-logo reference from the sequence itself (cold), then
//! runs the per-crop detector (hot, allocation-free) and the rotation fit.

use crate::calib::camera::CameraCalib;
use crate::logo::ball::Circle;
use crate::logo::detect::{BallReference, CropImage, DetectorConfig, LogoMeasurement, detect};
use crate::logo::rotation::{LogoSample, RotationFit, RotationFitConfig, RotationFitError, fit_rotation};
use crate::logo::view::BallView;

/// Fewest crops that make a reference (a median needs a few).
pub(crate) const MIN_REFERENCE_CROPS: usize = 3;

/// One crop of a sequence: capture time (s), the pixels, and the ball's
/// circle as the camera side measured it (full-sensor pixels).
#[derive(Copy, Clone, Debug)]
pub struct CropInput<'a> {
    /// Capture time, s (any fixed origin).
    pub t: f64,
    /// The crop's pixels and its place on the sensor.
    pub crop: CropImage<'a>,
    /// The ball's circle, full-sensor px.
    pub circle: Circle,
}

/// Which logo centre feeds the rotation fit.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum LogoMethod {
    /// The paper's normalised mean, no correction.
    Centroid,
    /// The paper's normalised mean with the circular-segment correction.
    Segment,
    /// Area-weighted mean with the circular-segment correction (ours).
    Weighted,
}

impl LogoMethod {
    /// Every method, in declaration order.
    pub const ALL: [LogoMethod; 3] = [LogoMethod::Centroid, LogoMethod::Segment, LogoMethod::Weighted];

    /// Short lowercase name (for reports).
    pub fn name(self) -> &'static str {
        match self {
            LogoMethod::Centroid => "centroid",
            LogoMethod::Segment => "segment",
            LogoMethod::Weighted => "weighted",
        }
    }

    /// The position this method takes from a measurement.
    pub fn position(self, m: &LogoMeasurement) -> crate::physics::Vec3 {
        match self {
            LogoMethod::Centroid => m.centroid,
            LogoMethod::Segment => m.corrected,
            LogoMethod::Weighted => m.weighted,
        }
    }
}

/// Why a sequence could not be processed at all.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum SequenceError {
    /// Too few crops for the ball-without-logo reference.
    #[error("{crops} crops (need at least {MIN_REFERENCE_CROPS})")]
    TooFewCrops {
        /// Crops in the sequence.
        crops: usize,
    },
    /// A crop's circle is unusable (non-finite or non-positive radius).
    #[error("crop {index}: unusable ball circle")]
    BadCircle {
        /// Index of the crop in the sequence.
        index: usize,
    },
}

/// Everything a sequence gave.
#[derive(Clone, Debug)]
pub struct SequenceResult {
    /// Per crop, the logo found (or not).
    pub measurements: Vec<Option<LogoMeasurement>>,
    /// Whether the ball is coloured (the colour threshold was used).
    pub coloured: bool,
    /// The rotation fit, table frame.
    pub fit: Result<RotationFit, RotationFitError>,
}

/// The ball's views, one per crop.
pub fn views(cam: &CameraCalib, inputs: &[CropInput<'_>]) -> Result<Vec<BallView>, SequenceError> {
    inputs
        .iter()
        .enumerate()
        .map(|(index, c)| {
            BallView::new(cam, c.circle.u, c.circle.v, c.circle.radius).ok_or(SequenceError::BadCircle { index })
        })
        .collect()
}

/// Runs the background-subtraction method over one ball's crops (in time
/// order) and fits the rotation with the positions `method` gives.
pub fn process_sequence(
    cam: &CameraCalib,
    inputs: &[CropInput<'_>],
    det: &DetectorConfig,
    fit: &RotationFitConfig,
    method: LogoMethod,
) -> Result<SequenceResult, SequenceError> {
    if inputs.len() < MIN_REFERENCE_CROPS {
        return Err(SequenceError::TooFewCrops { crops: inputs.len() });
    }
    let views = views(cam, inputs)?;
    let pairs: Vec<_> = inputs.iter().zip(&views).map(|(c, v)| (c.crop, *v)).collect();
    let reference = BallReference::from_crops(&pairs, det.colour_fraction)
        .ok_or(SequenceError::TooFewCrops { crops: inputs.len() })?;
    let measurements: Vec<_> = pairs.iter().map(|(c, v)| detect(det, &reference, c, v)).collect();
    let samples: Vec<_> = inputs
        .iter()
        .zip(&measurements)
        .map(|(c, m)| LogoSample::new(c.t, m.as_ref().map(|m| method.position(m))))
        .collect();
    let fit = fit_rotation(&samples, fit).map(|f| f.rotated(&cam.table_from_camera));
    Ok(SequenceResult { measurements, coloured: reference.coloured, fit })
}
