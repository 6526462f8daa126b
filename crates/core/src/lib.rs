//! topspin's sans-IO core: everything the robot's threads compute, with no
//! clock and no socket. Time comes in as [`time::Instant`]; bytes come in
//! as slices and go out into the caller's buffers. The daemon
//! (`topspin-daemon`), the simulated world (`topspin-sim`) and the lab
//! (`topspin-lab`) all run this same code.
//!
//! - [`time`]: the `Instant` every algorithm takes as an argument.
//! - [`physics`]: flight model (drag, Magnus, gravity), table, bounce, and
//!   a fixed-step RK4 propagator with events.
//! - [`fit`]: spin from a trajectory — the paper's polynomial/Magnus fit
//!   with its outlier filter, and a flight-model refinement — and
//!   prediction of the bounce and the hitting point.
//! - [`estimator`]: the streaming estimator (EKF, trajectory life cycle,
//!   strike plan) the estimator thread owns.
//! - [`plan`]: the strike plan it publishes, and the contact criterion.
//! - [`ingest`]: tracker datagrams → validated observations on our clock.
//! - [`wire`]: the datagram codecs (checked view over bytes, validated value).
//! - [`rsi`]: KUKA RSI: XML scanner, codec, and the sans-IO session.
//! - [`motion`]: the stroke generator and the last safety filter.
//! - [`geometry`]: the pose, KUKA's Z-Y-X Euler angles, one rotation and
//!   the angle wraps every module shares.
//! - [`kinematics`]: the KR 6 R900 sixx — forward and closed-form inverse
//!   kinematics (all solutions, the continuous one), axis limits.
//! - [`calib`]: the calibration files in `calib/`.
//! - [`logo`]: spin from the ball's printed logo in ceiling-camera crops.
//! - [`stats`]: median / quantile summaries.
//!
//! Where to start: [`calib::Calibration`] (the cell, from text), then the
//! three sans-IO types the daemon's threads own, each with a runnable
//! example: [`ingest::Ingest`] (tracker datagrams in),
//! [`estimator::Estimator`] (observations → strike plans) and
//! [`rsi::RsiSession`] (`<Rob>` in, `<Sen>` out, every 4 ms). Offline:
//! [`fit::fit_trajectory`] and [`logo::LogoStream`].
//!
//! Each area exports its items flat (`topspin_core::rsi::RsiSession`); the
//! files inside an area are private. Two sub-areas keep a module of their
//! own: [`rsi::identify`] (the servo model's identification) and
//! [`calib::cell`] (the table's place from touch points).
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

#![warn(missing_docs)]
#![deny(unreachable_pub)]

pub mod calib;
pub mod estimator;
pub mod fit;
pub mod geometry;
pub mod ingest;
pub mod kinematics;
pub mod logo;
pub mod motion;
pub mod physics;
pub mod plan;
pub mod rsi;
pub mod stats;
pub mod time;
pub mod wire;
