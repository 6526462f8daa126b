//! Session recording (DESIGN §1, §4): every tracker datagram with its arrival
//! time, every strike plan, every RSI exchange and the periodic counters,
//! written by the telemetry thread to one MCAP file that Foxglove opens and
//! `topspin replay` re-runs bit for bit.
//!
//! # File layout
//!
//! An MCAP file (zstd chunks, single-threaded compression). First, before
//! any message, the attachments `config.toml` (the effective
//! `DaemonConfig` as TOML) and `calib/<file>.toml` (the calibration's
//! TOML texts) and a metadata record `topspin` (version, clock), so a
//! recording needs nothing else to be replayed. Then one channel per topic,
//! JSON messages (`message_encoding = "json"`) each with a JSON Schema
//! (`schema encoding = "jsonschema"`), log time = wall-clock ns since the
//! Unix epoch (so Foxglove's timeline shows the date): the daemon's
//! monotonic clock ([`crate::clock::now`]) plus the offset
//! `crate::clock::unix_offset_ns` taken once at start, kept in the
//! metadata as `META_LOG_TIME_OFFSET`. The `*_ns` fields inside the
//! messages stay on the monotonic clock (what replay uses). Beside these, the
//! session's channels ([`crate::channels`], Foxglove's protobuf schemas and
//! JSON plots) with the same log times, so a recording opened in Foxglove
//! looks like the live view:
//!
//! | topic | log time | message |
//! |---|---|---|
//! | [`TOPIC_DATAGRAM`] | arrival | `DatagramMsg`: `arrival_ns`, `from` ("IP:PORT"), `hex` (the datagram's bytes, lower-case hex), `observation` (the decoded TTB1 fields, or null when it does not parse) |
//! | [`TOPIC_PLAN`] | `made_at` | `PlanMsg`: every [`StrikePlan`] field (`*_ns` times; vectors as {x, y, z}; orientation {a, b, c}) and `f64_bits`, the 13 floats' IEEE bits as 16-digit hex strings in the order position xyz, velocity xyz, orientation abc, spin xyz, confidence — what replay compares |
//! | [`TOPIC_RSI`] | arrival | `RsiMsg`: `arrival_ns`, `sent_ns`, `request` and `answer` (the XML text; `request_hex`/`answer_hex` instead when the bytes are not UTF-8) |
//! | [`TOPIC_COUNTERS`] | `at` | the counters JSON object as the telemetry thread passes it |
//!
//! # Crash safety
//!
//! Messages are buffered in the open chunk. [`Recorder::flush`] closes the
//! chunk, writes it out and `fdatasync`s the file: a file cut off later (a
//! crash, a power cut) still reads back everything before that flush
//! ([`read_recording`] stops at the first incomplete record and says so). The
//! telemetry thread flushes about once a second; chunks also close by
//! themselves at `CHUNK_SIZE`.
//!
//! # What replay needs from the daemon
//!
//! Replay ([`replay::replay_recording`]) feeds every recorded datagram, in
//! file order, through a fresh [`topspin_core::ingest::Ingest`] and every accepted
//! one through [`topspin_core::estimator::Estimator::observe`], and compares the
//! plans. That is bit-exact when the daemon's estimator saw exactly the
//! accepted datagrams in arrival order (no ring overflow between ingest and
//! estimator — count and log them), and when its idle `poll(now)` calls do
//! not change plans: `poll` only ends silent tracks and clears stale
//! candidates, which `observe` also does at the next observation's capture
//! time, so the sequence of plans does not depend on when `poll` ran.
//!
//! Cold path: the recorder allocates and does file I/O; only the telemetry
//! thread calls it.

mod reader;
pub(crate) mod replay;
pub(crate) mod sink;
mod writer;

use serde::{Deserialize, Serialize};

use topspin_core::geometry::EulerZyx;
use topspin_core::physics::Vec3;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;
use topspin_core::wire::Observation;

pub use reader::{RecordedDatagram, RecordedExchange, Recording, read_recording};
pub use replay::{Difference, ReplayReport, replay_recording};
pub use sink::RecordingSink;
pub use writer::Recorder;

/// Topic of the tracker datagrams.
pub const TOPIC_DATAGRAM: &str = "/tracker/datagram";
/// Topic of the strike plans.
pub const TOPIC_PLAN: &str = "/estimator/plan";
/// Topic of the RSI exchanges.
pub const TOPIC_RSI: &str = "/rsi/exchange";
/// Topic of the periodic counters.
pub const TOPIC_COUNTERS: &str = "/telemetry/counters";
/// Attachment holding the effective configuration.
pub(crate) const ATTACHMENT_CONFIG: &str = "config.toml";
/// Prefix of the attachments holding the calibration files.
pub(crate) const ATTACHMENT_CALIB_PREFIX: &str = "calib/";
/// Uncompressed size at which a chunk closes by itself, bytes.
pub(crate) const CHUNK_SIZE: u64 = 256 * 1024;
/// The MCAP profile field (and the name of the metadata record).
pub(crate) const PROFILE: &str = "topspin";
/// Metadata key: log time − the daemon's monotonic clock, ns (log times are wall clock).
pub(crate) const META_LOG_TIME_OFFSET: &str = "log_time_offset_ns";

/// A recording that cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created, written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: String,
        /// The OS's error.
        source: std::io::Error,
    },
    /// The MCAP layer failed.
    #[error("{path}: MCAP: {message}")]
    Mcap {
        /// The recording's path.
        path: String,
        /// What the MCAP layer reported.
        message: String,
    },
    /// The file is not a topspin recording (a missing or bad part named).
    #[error("{path}: not a usable topspin recording: {message}")]
    Invalid {
        /// The recording's path (`recorded calibration` for its calibration).
        path: String,
        /// What is missing or bad.
        message: String,
    },
    /// A calibration file name that cannot be recorded.
    #[error("calibration file name {0:?} is not a plain file name")]
    BadCalibName(String),
}

/// Whether a calibration file's name is a plain file name, as a recording
/// may carry it: not empty, no path separator, not hidden nor `.`/`..`.
pub(crate) fn plain_file_name(name: &str) -> bool {
    !name.is_empty() && !name.contains(['/', '\\']) && !name.starts_with('.')
}

/// Lower-case hex of `bytes`.
pub(crate) fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(DIGITS[(b >> 4) as usize] as char);
        s.push(DIGITS[(b & 15) as usize] as char);
    }
    s
}

/// The bytes of a hex string (either case); `None` if it is not hex.
pub(crate) fn from_hex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    let nibble = |c: u8| (c as char).to_digit(16).map(|d| d as u8);
    s.as_bytes().chunks(2).map(|p| Some(nibble(p[0])? << 4 | nibble(p[1])?)).collect()
}

/// JSON has no NaN or infinities (serde_json writes null): read null back as NaN.
/// The exact values are in [`PlanMsg::f64_bits`].
fn nan_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// A vector as Foxglove plots it.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct XyzMsg {
    #[serde(deserialize_with = "nan_if_null")]
    pub x: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub y: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub z: f64,
}

impl From<Vec3> for XyzMsg {
    fn from(v: Vec3) -> Self {
        XyzMsg { x: v.x, y: v.y, z: v.z }
    }
}

/// The decoded fields of a TTB1 datagram (for plots; replay uses the bytes).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct ObservationMsg {
    pub seq: u32,
    pub capture_ns: u64,
    pub x: f32,
    pub y: f32,
    pub z: f32,
    /// Null when unknown (NaN).
    pub residual: Option<f32>,
    pub cameras: u16,
    pub valid: bool,
}

/// A message on [`TOPIC_DATAGRAM`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct DatagramMsg {
    pub arrival_ns: u64,
    /// The sender, "IP:PORT".
    pub from: String,
    /// The datagram, lower-case hex.
    pub hex: String,
    /// The decoded observation, or null when the datagram does not parse.
    pub observation: Option<ObservationMsg>,
}

impl DatagramMsg {
    pub(crate) fn new(arrival: Instant, from: std::net::SocketAddr, bytes: &[u8]) -> Self {
        let observation = Observation::parse(bytes).ok().map(|o| ObservationMsg {
            seq: o.seq,
            capture_ns: o.capture.as_nanos(),
            x: o.pos[0],
            y: o.pos[1],
            z: o.pos[2],
            residual: (!o.residual.is_nan()).then_some(o.residual),
            cameras: o.cameras,
            valid: o.valid,
        });
        DatagramMsg { arrival_ns: arrival.as_nanos(), from: from.to_string(), hex: to_hex(bytes), observation }
    }
}

/// A message on [`TOPIC_PLAN`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct PlanMsg {
    pub seq: u32,
    pub trajectory: u32,
    pub made_at_ns: u64,
    pub hit_time_ns: u64,
    /// hit_time − made_at, s (for plots).
    #[serde(deserialize_with = "nan_if_null")]
    pub lead_s: f64,
    pub position: XyzMsg,
    pub velocity: XyzMsg,
    pub orientation: EulerMsg,
    /// rad/s.
    pub spin: XyzMsg,
    #[serde(deserialize_with = "nan_if_null")]
    pub confidence: f64,
    /// The IEEE bits of the 13 floats (see the module doc), 16 hex digits each.
    pub f64_bits: Vec<String>,
}

/// Bat orientation, KUKA ZYX Euler angles in radians.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct EulerMsg {
    #[serde(deserialize_with = "nan_if_null")]
    pub a: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub b: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub c: f64,
}

/// The plan's floats in the order of [`PlanMsg::f64_bits`].
pub(crate) fn plan_floats(p: &StrikePlan) -> [f64; 13] {
    let o = &p.orientation;
    [
        p.position.x,
        p.position.y,
        p.position.z,
        p.velocity.x,
        p.velocity.y,
        p.velocity.z,
        o.a,
        o.b,
        o.c,
        p.spin.x,
        p.spin.y,
        p.spin.z,
        p.confidence,
    ]
}

impl From<&StrikePlan> for PlanMsg {
    fn from(p: &StrikePlan) -> Self {
        PlanMsg {
            seq: p.seq,
            trajectory: p.trajectory,
            made_at_ns: p.made_at.as_nanos(),
            hit_time_ns: p.hit_time.as_nanos(),
            lead_s: p.hit_time.secs_since(p.made_at),
            position: p.position.into(),
            velocity: p.velocity.into(),
            orientation: EulerMsg { a: p.orientation.a, b: p.orientation.b, c: p.orientation.c },
            spin: p.spin.into(),
            confidence: p.confidence,
            f64_bits: plan_floats(p).iter().map(|v| format!("{:016x}", v.to_bits())).collect(),
        }
    }
}

impl PlanMsg {
    /// The exact plan: times from the `*_ns` fields, floats from `f64_bits`.
    pub(crate) fn to_plan(&self) -> Option<StrikePlan> {
        if self.f64_bits.len() != 13 {
            return None;
        }
        let mut f = [0.0; 13];
        for (v, s) in f.iter_mut().zip(&self.f64_bits) {
            *v = f64::from_bits(u64::from_str_radix(s, 16).ok()?);
        }
        Some(StrikePlan {
            seq: self.seq,
            trajectory: self.trajectory,
            made_at: Instant::from_nanos(self.made_at_ns),
            hit_time: Instant::from_nanos(self.hit_time_ns),
            position: Vec3::new(f[0], f[1], f[2]),
            velocity: Vec3::new(f[3], f[4], f[5]),
            orientation: EulerZyx { a: f[6], b: f[7], c: f[8] },
            spin: Vec3::new(f[9], f[10], f[11]),
            confidence: f[12],
        })
    }
}

/// A message on [`TOPIC_RSI`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct RsiMsg {
    pub arrival_ns: u64,
    pub sent_ns: u64,
    /// The controller's datagram as text (absent when not UTF-8: see `request_hex`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub request_hex: Option<String>,
    /// Our answer as text (absent when not UTF-8: see `answer_hex`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answer: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answer_hex: Option<String>,
}

fn text_or_hex(bytes: &[u8]) -> (Option<String>, Option<String>) {
    match std::str::from_utf8(bytes) {
        Ok(s) => (Some(s.to_owned()), None),
        Err(_) => (None, Some(to_hex(bytes))),
    }
}

impl RsiMsg {
    pub(crate) fn new(arrival: Instant, request: &[u8], answer: &[u8], sent: Instant) -> Self {
        let (request, request_hex) = text_or_hex(request);
        let (answer, answer_hex) = text_or_hex(answer);
        RsiMsg { arrival_ns: arrival.as_nanos(), sent_ns: sent.as_nanos(), request, request_hex, answer, answer_hex }
    }

    fn bytes(text: &Option<String>, hex: &Option<String>) -> Option<Vec<u8>> {
        match (text, hex) {
            (Some(t), None) => Some(t.as_bytes().to_vec()),
            (None, Some(h)) => from_hex(h),
            (None, None) => Some(Vec::new()),
            (Some(_), Some(_)) => None,
        }
    }

    /// The request's bytes.
    pub(crate) fn request_bytes(&self) -> Option<Vec<u8>> {
        Self::bytes(&self.request, &self.request_hex)
    }

    /// The answer's bytes.
    pub(crate) fn answer_bytes(&self) -> Option<Vec<u8>> {
        Self::bytes(&self.answer, &self.answer_hex)
    }
}

/// JSON Schemas of the channels (draft 2020-12), for Foxglove.
pub mod schema {
    pub(crate) const DATAGRAM: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"topspin.TrackerDatagram","description":"One UDP datagram from the tracker (TTB1, DESIGN 5.1) as it arrived","type":"object","properties":{"arrival_ns":{"type":"integer","description":"arrival, daemon monotonic clock, ns"},"from":{"type":"string","description":"sender IP:PORT"},"hex":{"type":"string","description":"the datagram's bytes, lower-case hex"},"observation":{"description":"decoded TTB1 fields, null if the datagram does not parse","anyOf":[{"type":"null"},{"type":"object","properties":{"seq":{"type":"integer"},"capture_ns":{"type":"integer","description":"tracker clock"},"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"residual":{"type":["number","null"]},"cameras":{"type":"integer"},"valid":{"type":"boolean"}}}]}},"required":["arrival_ns","from","hex","observation"]}"#;
    pub(crate) const PLAN: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"topspin.StrikePlan","description":"A strike plan the estimator published; table frame, SI units; a null number is NaN or infinite (exact values in f64_bits)","type":"object","properties":{"seq":{"type":"integer"},"trajectory":{"type":"integer"},"made_at_ns":{"type":"integer"},"hit_time_ns":{"type":"integer"},"lead_s":{"type":["number","null"]},"position":{"type":"object","properties":{"x":{"type":["number","null"]},"y":{"type":["number","null"]},"z":{"type":["number","null"]}},"required":["x","y","z"]},"velocity":{"type":"object","properties":{"x":{"type":["number","null"]},"y":{"type":["number","null"]},"z":{"type":["number","null"]}},"required":["x","y","z"]},"orientation":{"type":"object","properties":{"a":{"type":["number","null"]},"b":{"type":["number","null"]},"c":{"type":["number","null"]}},"required":["a","b","c"]},"spin":{"type":"object","properties":{"x":{"type":["number","null"]},"y":{"type":["number","null"]},"z":{"type":["number","null"]}},"required":["x","y","z"]},"confidence":{"type":["number","null"]},"f64_bits":{"type":"array","description":"IEEE bits of position xyz, velocity xyz, orientation abc, spin xyz, confidence (16 hex digits each)","items":{"type":"string"},"minItems":13,"maxItems":13}},"required":["seq","trajectory","made_at_ns","hit_time_ns","position","velocity","orientation","spin","confidence","f64_bits"]}"#;
    /// The schema of `TOPIC_RSI`'s messages (`RsiMsg`).
    pub const RSI: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"topspin.RsiExchange","description":"One RSI exchange: the KR C4's datagram and our answer","type":"object","properties":{"arrival_ns":{"type":"integer"},"sent_ns":{"type":"integer"},"request":{"type":"string","description":"the controller's XML"},"request_hex":{"type":"string","description":"instead of request when not UTF-8"},"answer":{"type":"string","description":"our XML"},"answer_hex":{"type":"string","description":"instead of answer when not UTF-8"}},"required":["arrival_ns","sent_ns"]}"#;
    pub(crate) const COUNTERS: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"topspin.Counters","description":"The daemon's counters (ingest, estimator, rsi, rings), as the telemetry thread sends them","type":"object"}"#;
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn only_plain_file_names_are_recorded_or_read() {
        for ok in ["physics.toml", "robot.toml", "a"] {
            assert!(plain_file_name(ok), "{ok}");
        }
        for bad in ["", ".", "..", ".hidden", "../robot.toml", "calib/robot.toml", "c:\\robot.toml", "/etc/passwd"] {
            assert!(!plain_file_name(bad), "{bad}");
        }
    }

    #[test]
    fn hex_round_trips_and_rejects_non_hex() {
        assert_eq!(to_hex(&[0, 0xab, 0x7f]), "00ab7f");
        assert_eq!(from_hex("00AB7f"), Some(vec![0, 0xab, 0x7f]));
        assert_eq!(from_hex("0"), None);
        assert_eq!(from_hex("zz"), None);
        assert_eq!(from_hex("é0"), None);
    }

    fn plan(v: f64) -> StrikePlan {
        StrikePlan {
            seq: 3,
            trajectory: 2,
            made_at: Instant(10),
            hit_time: Instant(u64::MAX),
            position: Vec3::new(v, -0.0, f64::MIN_POSITIVE / 2.0),
            velocity: Vec3::new(f64::NAN, f64::INFINITY, 1e300),
            orientation: EulerZyx { a: 0.1, b: 0.2, c: 0.3 },
            spin: Vec3::new(1.0 / 3.0, 2.0, 3.0),
            confidence: 0.5,
        }
    }

    proptest! {
        #[test]
        fn plans_round_trip_bit_for_bit_through_json(v in any::<f64>()) {
            let p = plan(v);
            let json = serde_json::to_vec(&PlanMsg::from(&p)).unwrap();
            let back = serde_json::from_slice::<PlanMsg>(&json).unwrap().to_plan().unwrap();
            prop_assert!(replay::differing_fields(&p, &back).is_empty());
        }

        #[test]
        fn rsi_bytes_round_trip(req in prop::collection::vec(any::<u8>(), 0..64), ans in ".{0,20}") {
            let m = RsiMsg::new(Instant(1), &req, ans.as_bytes(), Instant(2));
            let back: RsiMsg = serde_json::from_slice(&serde_json::to_vec(&m).unwrap()).unwrap();
            prop_assert_eq!(back.request_bytes().unwrap(), req);
            prop_assert_eq!(back.answer_bytes().unwrap(), ans.as_bytes());
        }
    }
}
