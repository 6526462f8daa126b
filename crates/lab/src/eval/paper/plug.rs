//! The product's CNN and fusion as the paper run's extensions: the
//! network of [`topspin_cnn`] as a [`CropPredictor`], and the
//! daemon's logo + trajectory fusion ([`topspin_core::logo::fuse`], the EKF's
//! spin update in batch form) as a [`SpinFusion`].

use super::flights::{CropPrediction, CropPredictor, FusionInput, SpinFusion, SpinMethod};
use topspin_cnn::{CnnOutput, INPUT_SIZE, LogoCnn, VISIBLE_THRESHOLD};
use topspin_core::logo::BallView;
use topspin_core::logo::CropImage;
use topspin_core::logo::{Fused, SpinEstimate, fuse};
use topspin_core::physics::Vec3;

/// The logo CNN, one crop per call (the per-crop time is what the table
/// reports; the daemon batches on ONNX Runtime).
#[derive(Debug)]
pub struct CnnPredictor {
    net: LogoCnn,
    name: String,
}

impl CnnPredictor {
    /// `name`: how the tables call it (the model file and the backend).
    pub fn new(net: LogoCnn, name: String) -> Self {
        CnnPredictor { net, name }
    }
}

impl CropPredictor for CnnPredictor {
    fn name(&self) -> String {
        self.name.clone()
    }

    /// A crop that is not the network's 60 × 60, or a failed inference,
    /// counts as "no logo seen".
    fn predict(&mut self, crop: &CropImage<'_>, view: &BallView) -> CropPrediction {
        let mut out = [CnnOutput::default()];
        let ran =
            crop.width == INPUT_SIZE && crop.height == INPUT_SIZE && self.net.infer(&[crop.rgb], &mut out).is_ok();
        let o = out[0];
        CropPrediction {
            // The network's probability, as the paper's visibility in [−1, 1].
            visibility: if ran { 2.0 * f64::from(o.visibility) - 2.0 * f64::from(VISIBLE_THRESHOLD) } else { -1.0 },
            logo_camera: ran.then(|| view.to_camera(&o.logo_view())),
            logo_swing: ran.then_some(o.orientation),
        }
    }
}

/// Which logo estimate the fusion takes.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FusedLogo {
    /// Background subtraction with the segment correction (the daemon's
    /// default `logo.method`).
    Segment,
    /// The CNN's.
    Cnn,
}

/// Refined trajectory fit (ω, Σ with its weak axis) and one logo rotation
/// fit (ω, Σ from its residuals), combined by inverse covariance behind
/// the χ² gate; the trajectory alone where the logo has no fit or fails
/// the gate, nothing where the trajectory has no fit.
#[derive(Copy, Clone, Debug)]
pub struct TrajectoryLogoFusion {
    /// The logo estimate fused.
    pub logo: FusedLogo,
    /// Flights where the logo was fused.
    pub fused: usize,
    /// Flights where the χ² gate kept the trajectory alone.
    pub gated: usize,
}

impl TrajectoryLogoFusion {
    /// A fusion with `logo`, its counts at zero.
    pub fn new(logo: FusedLogo) -> Self {
        TrajectoryLogoFusion { logo, fused: 0, gated: 0 }
    }
}

impl SpinFusion for TrajectoryLogoFusion {
    fn name(&self) -> String {
        let logo = match self.logo {
            FusedLogo::Segment => "background + segment fit",
            FusedLogo::Cnn => "CNN",
        };
        format!("refined trajectory fit + {logo} logo (inverse covariance, χ² gate)")
    }

    fn fuse(&mut self, input: &FusionInput<'_>) -> Option<Vec3> {
        let fits = input.fits;
        let trajectory = SpinEstimate::from_fit(fits.refined.as_ref()?)?;
        let logo = match self.logo {
            FusedLogo::Segment => fits.bg[SpinMethod::BgSegment.index()].as_ref(),
            FusedLogo::Cnn => fits.cnn.as_ref(),
        };
        let Some(logo) = logo else { return Some(trajectory.spin) };
        let fused = fuse(&trajectory, &SpinEstimate::from_rotation(logo, fits.logo_span));
        match fused {
            Fused::Both(_) => self.fused += 1,
            Fused::TrajectoryOnly(..) => self.gated += 1,
        }
        Some(fused.estimate().spin)
    }
}
