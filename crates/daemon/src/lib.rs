//! topspin's daemon: the process that runs on the robot PC. It owns the
//! one clock reader, the threads and their real-time set-up, the RSI
//! server loop, the configuration, systemd, recording/replay and the live
//! Foxglove view, around the sans-IO core (`topspin-core`). Nothing here
//! simulates, renders, evaluates or plots: those live above, in
//! `topspin-sim` and `topspin-lab`.
//!
//! - [`clock`]: the only place that reads the clock.
//! - [`runtime`]: the daemon's threads, real-time set-up and telemetry.
//! - [`rsi_server`]: the sensor-side UDP loop around the RSI session.
//! - [`rsi_identify`]: the UDP loop of `topspin identify` around the
//!   sans-IO identifier.
//! - [`config`]: the layered, validated configuration.
//! - [`calib_files`]: the calibration read from a `calib/` folder.
//! - [`systemd`]: readiness and watchdog notifications.
//! - [`record`]: session recording (MCAP) and bit-exact replay.
//! - [`channels`]: the topics and schemas the recording and the view share.
//! - [`viewer`]: the Foxglove view, live and from a recording.
//! - [`tracker_check`]: what the tracker sends (`topspin check tracker`).
//! - [`doctor`]: is this PC ready for the 4 ms loop (`topspin doctor`).
//! - [`touch`]: the RSI listener that reads touch points (`topspin calibrate cell --rsi`).
//!
//! Where to start: [`config::DaemonConfig`] (the layered configuration),
//! then [`runtime::Daemon`], which starts the threads from it and returns
//! a [`runtime::DaemonSummary`] when it stops. [`record::read_recording`]
//! and [`record::replay_recording`] read and re-run a recorded session.
//! Each area exports its items flat; the files inside an area are private
//! (only `runtime::rt` and the `doctor` checks keep a module of their own).
//!
//! `DESIGN §n` in these docs cites section n of `docs/design.md`.

#![warn(missing_docs)]
#![deny(unreachable_pub)]

pub mod calib_files;
pub mod channels;
pub mod clock;
pub mod config;
pub mod doctor;
pub mod record;
pub mod rsi_floor;
pub mod rsi_identify;
pub mod rsi_server;
pub mod runtime;
pub mod systemd;
pub mod touch;
pub mod tracker_check;
pub mod viewer;
