//! The mock KR C4: behaves as the controller does over RSI, for
//! hardware-in-the-loop runs, integration tests and `topspin mock-krc`.
//!
//! - `config`: reads the controller-side files in `rsi/` (Ethernet XML:
//!   port, SENTYPE, SEND list; RSI context: Timeout, Precision, POSCORR and
//!   POSCORRMON limits), so those files are exercised by every run.
//! - `controller`: the sans-IO controller model — `<Rob>` out, `<Sen>` in,
//!   IPOC check, late counting into `<Delay>`, stop at the Timeout limit,
//!   RKorr applied in #ABSOLUTE or #RELATIVE mode through POSCORR-style
//!   limits and the robot's own velocity/acceleration limits, path log.
//! - `faults`: drop, delay and duplicate answers — a wrapper around the
//!   link, seeded, not `if`s in the core. [`crate::pair`] runs the
//!   controller and the RSI session on one virtual clock with them.
//! - `runner`: the UDP loop on an absolute 4 ms (or 12 ms) schedule, in
//!   process on a thread (stop flag, result) or from the command line.

pub(crate) mod config;
pub(crate) mod controller;
pub(crate) mod faults;
pub(crate) mod runner;

pub use config::{ContextConfig, EthernetConfig, RsiFileError, rsi_files};
pub use controller::{Brakes, ControllerConfig, CorrMode, MockController, PathSample, StopReason, Verdict};
pub use faults::Faults;
pub use runner::{MockHandle, MockKrcConfig, MockResult, run, spawn};
