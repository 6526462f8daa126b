//! Real recorded trajectories: the MPI launcher set (`shared/data/
//! mpi-launcher/`, read in place, never copied into the repository), its
//! lab → table transform, bounce detection, and the real-data evaluation
//! harness with a calibration routine for the physics constants.
//!
//! - `mpi`: loading (typed errors, no panics on bad rows) and sampling
//!   statistics.
//! - `frame`: [`frame::LabToTable`] with the constant in use, the
//!   evidence for it ([`frame::estimate_frame`]), and bounce detection.
//! - `eval`: the [`eval::Predictor`] trait, the spin-free cubic baseline,
//!   and per-set error statistics (bounce point, position 0.3 s ahead).
//! - [`calibrate`]: a derivative-free search over physics constants with a
//!   train/validation split.
//!
//! Offline code: it allocates and reads files; nothing here runs on a hot
//! path.

pub(crate) mod calibrate;
pub(crate) mod eval;
pub(crate) mod frame;
pub(crate) mod mpi;
pub(crate) mod polyfit;
pub(crate) mod spin;
pub(crate) mod study;
pub use calibrate::{
    CalibParam, CalibrationResult, CalibrationSetup, Objective, calibrate, evaluate_with, split_even_odd,
};
pub use eval::{
    CubicBaseline, EvalConfig, GroupReport, Prediction, Predictor, PreparedTrajectory, Report, Stats, TrajectoryResult,
    evaluate, prepare,
};
pub use frame::{
    BALL_RADIUS, BounceSearch, DetectedBounce, FrameEstimate, LabToTable, MPI_LAB_TO_TABLE, detect_bounces,
    estimate_frame,
};
pub use mpi::{DATA_ENV, MpiError, RealTrajectory, SETS, SamplingStats, load, locate, median, sampling_stats};
pub use spin::{FitPredictor, SpinFit};
pub use study::{
    LiftChoice, PREDICTORS, Row, SpinSummary, Variant, Which, calibrate_lift, calibration_markdown, compare,
    eval_config, markdown, objective, params_json, rows_json, spin_markdown, spin_summary,
};
