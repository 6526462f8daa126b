//! Real recorded trajectories: the MPI launcher set (`shared/data/
//! mpi-launcher/`, read in place, never copied into the repository), its
//! lab → table transform, bounce detection, and the real-data evaluation
//! harness with a calibration routine for the physics constants.
//!
//! - [`mpi`]: loading (typed errors, no panics on bad rows) and sampling
//!   statistics.
//! - [`frame`]: [`frame::LabToTable`] with the constant in use, the
//!   evidence for it ([`frame::estimate_frame`]), and bounce detection.
//! - [`eval`]: the [`eval::Predictor`] trait, the spin-free cubic baseline,
//!   and per-set error statistics (bounce point, position 0.3 s ahead).
//! - [`calibrate`]: a derivative-free search over physics constants with a
//!   train/validation split.
//!
//! Offline code: it allocates and reads files; nothing here runs on a hot
//! path.

pub mod calibrate;
pub mod eval;
pub mod frame;
pub mod mpi;
pub mod polyfit;
pub mod spin;
pub mod study;
