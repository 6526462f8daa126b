//! Spin from a trajectory, and what follows from it (paper §IV, DESIGN §3).
//!
//! - `poly`: least-squares cubic per axis (time centred and scaled).
//! - `magnus`: the paper's linear solve of k_M ω × P′ = P″ + k_D‖P′‖P′ + g e_z.
//! - `outlier`: the paper's start-of-trajectory filter (sliding five-ball fits).
//! - [`refine`]: our refinement: the flight model itself fitted to the
//!   positions (Levenberg–Marquardt over initial position, velocity and
//!   spin, robust weights), with the spin's observability.
//! - [`predict`]: next table contact and the crossing of the hitting plane.
//! - `trajectory`: the pipeline over one recorded flight.
//!
//! Offline code paths may allocate; the pieces the streaming estimator
//! reuses (`poly`, `magnus`, `predict`) do not.

pub(crate) mod magnus;
pub(crate) mod outlier;
pub(crate) mod poly;
pub(crate) mod predict;
pub(crate) mod refine;
pub(crate) mod trajectory;
pub use magnus::{MagnusSolve, solve as solve_magnus};
pub use outlier::StartFilter;
pub use poly::Cubic;
pub use refine::{RefineConfig, Refined, refine};
pub use trajectory::{FitConfig, FitError, MIN_SAMPLES, Method, TrajectoryFit, fit_trajectory};

use crate::physics::Vec3;

/// One observed ball position at a time (seconds on the caller's clock).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Sample {
    /// Observation time, s.
    pub t: f64,
    /// Observed ball centre in the table frame T, m.
    pub pos: Vec3,
}

impl Sample {
    /// The sample of position `pos` (m, frame T) at time `t` (s).
    pub fn new(t: f64, pos: Vec3) -> Self {
        Sample { t, pos }
    }
}

pub use predict::{Contact, FlightEnd, HitPoint, Prediction, predict};
