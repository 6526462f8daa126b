//! The logo metrics of the paper's §III and §V on the filmed flights: per
//! logo method, the logo classification accuracy (found / visible ⇔ logo
//! centre on the visible hemisphere), the geodesic error of the pose
//! (networks only: the background method gives no orientation about the
//! logo's own axis), the vector-angle error of the logo position, and the
//! processing time per crop.

use serde::Serialize;

use super::flights::{Flight, SpinMethod};
use topspin_core::stats::Summary;

/// The paper's numbers per method: (classification accuracy, geodesic
/// deg, vector angle deg, ms per crop); NaN where the paper has none.
pub(crate) fn paper_numbers(m: SpinMethod) -> Option<[f64; 4]> {
    match m {
        SpinMethod::BgCentroid => Some([f64::NAN, f64::NAN, 5.77, 0.3]),
        SpinMethod::BgSegment => Some([f64::NAN, f64::NAN, 5.06, 0.3]),
        SpinMethod::Cnn => Some([0.96, 20.14, 4.23, 3.7]),
        _ => None,
    }
}

/// The logo methods of the table.
pub(crate) const LOGO_METHODS: [SpinMethod; 4] =
    [SpinMethod::BgCentroid, SpinMethod::BgSegment, SpinMethod::BgWeighted, SpinMethod::Cnn];

/// One row.
#[derive(Clone, Debug, Serialize)]
pub struct LogoRow {
    /// The method.
    pub method: SpinMethod,
    /// Its row name ([`SpinMethod::label`]).
    pub label: &'static str,
    /// False when the method is not available in this run (no model).
    pub available: bool,
    /// Crops evaluated.
    pub frames: usize,
    /// Fraction of frames classified right.
    pub classification: f64,
    /// Geodesic error of the logo pose, degrees (the tables print the
    /// mean, as the paper's); networks only, empty otherwise.
    pub geodesic: Summary,
    /// Angle between the found and the true logo centre, degrees, on frames
    /// with a logo found and some of it visible.
    pub vector_angle: Summary,
    /// Mean processing time per crop, ms (wall clock of the calling
    /// thread, on a shared machine).
    pub ms_per_crop: f64,
    /// The paper's numbers (classification accuracy, geodesic deg, vector angle
    /// deg, ms per crop; NaN where it has none), for a method the paper has.
    pub paper: Option<[f64; 4]>,
}

/// The table over `flights`.
pub fn table(flights: &[Flight]) -> Vec<LogoRow> {
    let frames: usize = flights.iter().map(|f| f.frames).sum();
    LOGO_METHODS
        .iter()
        .map(|&m| {
            let paper = paper_numbers(m);
            match m.bg_variant() {
                Some(_) => {
                    let i = m.index();
                    let angles: Vec<f64> = flights.iter().flat_map(|f| f.bg_angle_err[i].iter().copied()).collect();
                    let right: usize = flights.iter().map(|f| f.bg_classified_right).sum();
                    let secs: f64 = flights.iter().map(|f| f.bg_seconds).sum();
                    LogoRow {
                        method: m,
                        label: m.label(),
                        available: true,
                        frames,
                        classification: right as f64 / frames.max(1) as f64,
                        geodesic: Summary::of(&[]),
                        vector_angle: Summary::of(&angles),
                        ms_per_crop: secs * 1e3 / frames.max(1) as f64,
                        paper,
                    }
                }
                None => {
                    let with: Vec<&Flight> = flights.iter().filter(|f| f.cnn.is_some()).collect();
                    let cnn_frames: usize = with.iter().map(|f| f.frames).sum();
                    let cat =
                        |g: &dyn Fn(&Flight) -> Vec<f64>| -> Vec<f64> { with.iter().flat_map(|f| g(f)).collect() };
                    let angles = cat(&|f| f.cnn.as_ref().map(|c| c.angle_err.clone()).unwrap_or_default());
                    let geo = cat(&|f| f.cnn.as_ref().map(|c| c.geodesic_err.clone()).unwrap_or_default());
                    let right: usize = with.iter().filter_map(|f| f.cnn.as_ref()).map(|c| c.classified_right).sum();
                    let secs: f64 = with.iter().map(|f| f.cnn_seconds).sum();
                    LogoRow {
                        method: m,
                        label: m.label(),
                        available: !with.is_empty(),
                        frames: cnn_frames,
                        classification: right as f64 / cnn_frames.max(1) as f64,
                        geodesic: Summary::of(&geo),
                        vector_angle: Summary::of(&angles),
                        ms_per_crop: secs * 1e3 / cnn_frames.max(1) as f64,
                        paper,
                    }
                }
            }
        })
        .collect()
}
