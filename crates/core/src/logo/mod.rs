//! Spin from the ball's printed logo (paper §II; DESIGN §3 "Spin from the
//! logo"), the background-subtraction method, for the optional logo thread.
//!
//! The layers, in the order a crop passes them:
//!
//! - `ball`: the camera side's ball extraction — the circle (centre,
//!   radius) measured against the static background; what TTI1 carries.
//! - `view`: the ball's view frame and the map from pixels to points on
//!   the unit sphere (the paper's 3D projection, exact off the optical axis).
//! - [`detect`]: the ball without logo (a per-sequence reference), colour
//!   and difference thresholds and their union, the logo's normalised mean
//!   on the sphere, with the `segment` correction for logos cut by the rim.
//! - `rotation`: the rotation fit over a sequence of logo positions
//!   (plane, projected angles, half-revolution rule, regression line);
//!   shared with any other source of logo positions (a CNN).
//! - `pipeline`: a whole sequence of crops → spin in the table frame.
//! - `cnn`: the paper's second method's contract, a network from a crop
//!   to the logo's visibility and position (the engine is `topspin-cnn`).
//! - `fusion`: the logo's spin and the trajectory's, combined by their
//!   covariances behind a χ² gate.
//! - `stream`: the logo thread's work: TTI1 crops → sequences → spins.
//!
//! Their accuracy on rendered flights is measured in the lab
//! (`topspin_lab::logo`).
//!
//! What this module must not do: read clocks or sockets (times come with
//! the crops), or allocate per crop on the hot path ([`detect::detect`]).

pub(crate) mod ball;
pub(crate) mod cnn;
pub(crate) mod detect;
pub(crate) mod fusion;
pub(crate) mod pipeline;
pub(crate) mod rotation;
pub(crate) mod segment;
pub(crate) mod stream;
pub(crate) mod view;

pub use ball::{Circle, measure_ball};
pub use cnn::{CnnOutput, INPUT_LEN, INPUT_SIZE, LogoNetwork, MAX_BATCH, VISIBLE_THRESHOLD, geodesic_deg, swing_to};
pub use detect::{BallReference, CropImage, DetectorConfig, LogoMeasurement, detect};
pub use fusion::{Fused, SpinEstimate, fuse};
pub use pipeline::{CropInput, LogoMethod, SequenceError, SequenceResult, process_sequence, views};
pub use rotation::{GapRule, LogoSample, RotationFit, RotationFitConfig, RotationFitError, fit_rotation};
pub use stream::{LogoCounters, LogoEngine, LogoStream, SEQUENCE_LEN, SeenLogo};
pub use view::BallView;
