//! topspin: a table-tennis robot controller that reads and answers spin
//! (after Tebbe et al., "Spin Detection in Robotic Table Tennis", ICRA 2020).
//!
//! The layers, bottom up:
//!
//! - [`time`]: the `Instant` every algorithm takes as an argument; nothing
//!   below the runtime reads a clock.
//! - [`physics`]: flight model (drag, Magnus, gravity), table, bounce, and a
//!   fixed-step RK4 propagator with events.
//! - [`fit`]: spin from a trajectory — the paper's polynomial/Magnus fit with
//!   its outlier filter, and a flight-model refinement — and prediction of
//!   the bounce and the hitting point.
//! - [`estimator`]: the streaming estimator (EKF, trajectory life cycle,
//!   strike plan) the estimator thread owns.
//! - [`plan`]: the strike plan it publishes.
//! - [`eval`]: accuracy evaluations on simulated flights.
//! - [`sim`]: a seeded ball launcher and tracker model that produce
//!   realistic observations with ground truth.
//! - [`wire`]: the datagram codecs (checked view over bytes, validated value).
//! - [`calib`]: the calibration files in `calib/`.
//! - [`data`]: real recorded trajectories (MPI launcher set), their frame,
//!   and the real-data evaluation and calibration harness.
//! - [`logo`]: spin from the ball's printed logo in ceiling-camera crops
//!   (background subtraction, circular-segment correction, rotation fit).
//! - [`render`]: the ceiling-camera renderer, labelled synthetic crops.
//! - [`config`]: the daemon's layered, validated configuration.
//! - [`record`]: session recording (MCAP) and bit-exact replay.
//! - [`systemd`]: readiness and watchdog notifications for the service.
//! - [`cli`]: the `topspin` command line.

pub mod calib;
pub mod cli;
pub mod config;
pub mod data;
pub mod demo;
pub mod estimator;
pub mod eval;
pub mod fit;
pub mod ingest;
pub mod logo;
pub mod mock_krc;
pub mod motion;
pub mod physics;
pub mod plan;
pub mod record;
pub mod render;
pub mod rsi;
pub mod runtime;
pub mod sim;
pub mod systemd;
pub mod time;
pub mod viewer;
pub mod wire;
