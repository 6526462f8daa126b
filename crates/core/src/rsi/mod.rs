//! KUKA RSI (DESIGN §5.3): the XML scanner, the datagram codec and the
//! sans-IO session that answers the controller every cycle.
//!
//! - `xml`: a tolerant, zero-allocation scanner.
//! - `codec`: `<Rob>` and `<Sen>` parse/emit in KUKA units.
//! - `session`: the daemon's sans-IO session (strokes → RKorr).
//! - `start`: what the session finds at RSI start: a usable pose, the
//!   calibration's tool and base (`RIst` against the kinematics of `AIPos`).
//! - `follow`: whether the arm follows the commands (the servo model's
//!   prediction against `RIst`).
//! - [`identify`]: `topspin identify`'s sans-IO side (excitation → RKorr,
//!   RIst → dead time and servo lag).

pub(crate) mod codec;
pub(crate) mod follow;
pub mod identify;
pub(crate) mod session;
pub(crate) mod start;
pub(crate) mod xml;
pub use codec::{Axes, CodecError, KukaPose, MAX_PRECISION, RobElement, RobFrame, SenFrame, SenView, check_text};
pub use follow::FollowMonitor;
pub use session::{
    ArmMode, ConfigError, Correction, MAX_ANSWER_LEN, RsiSession, ServoCompensation, SessionConfig, SessionError,
    SessionEvent, SessionState, SessionStats, UnknownCorrection,
};
pub use start::{FramesMismatch, LikelyFrame, Start, StartRefused, Verdict, assess, check_frames, read_start};
pub use xml::{Scanner, Token, XmlError, attr, trim};
