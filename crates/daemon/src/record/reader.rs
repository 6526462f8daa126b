//! Reading a recording back (also one cut off by a crash).

use crate::calib_files::calibration_from_texts;
use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::Path;

use mcap::records::Record;

use super::{
    ATTACHMENT_CALIB_PREFIX, ATTACHMENT_CONFIG, DatagramMsg, META_LOG_TIME_OFFSET, PROFILE, PlanMsg, RecordError,
    RsiMsg, TOPIC_COUNTERS, TOPIC_DATAGRAM, TOPIC_PLAN, TOPIC_RSI, from_hex, plain_file_name,
};
use crate::config::DaemonConfig;
use topspin_core::calib::Calibration;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;

/// A tracker datagram as recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedDatagram {
    /// When it arrived, on the daemon's monotonic clock.
    pub arrival: Instant,
    /// The sender.
    pub from: SocketAddr,
    /// The datagram's bytes.
    pub bytes: Vec<u8>,
}

/// An RSI exchange as recorded.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordedExchange {
    /// When the controller's datagram arrived, on the daemon's monotonic clock.
    pub arrival: Instant,
    /// The controller's datagram.
    pub request: Vec<u8>,
    /// Our answer.
    pub answer: Vec<u8>,
    /// When the answer was sent, on the daemon's monotonic clock.
    pub sent: Instant,
}

/// Everything a recording holds, in file order per topic.
#[derive(Clone, Debug)]
pub struct Recording {
    /// The configuration text as recorded.
    pub config_toml: String,
    /// ... and parsed.
    pub config: DaemonConfig,
    /// The calibration files `(name, TOML text)`.
    pub calib_files: Vec<(String, String)>,
    /// Every tracker datagram, parsed or not.
    pub observations: Vec<RecordedDatagram>,
    /// The strike plans the estimator published.
    pub plans: Vec<StrikePlan>,
    /// The RSI exchanges.
    pub exchanges: Vec<RecordedExchange>,
    /// The counters JSON objects, each at its log time on the monotonic clock.
    pub counters: Vec<(Instant, serde_json::Value)>,
    /// The file ended before its summary (a crash): it holds what was
    /// flushed, and this says why reading stopped.
    pub truncated: Option<String>,
    /// Log time − monotonic time, ns (the metadata's `log_time_offset_ns`; 0 in older files).
    pub log_time_offset: u64,
}

impl Recording {
    /// The recorded calibration, parsed from the recorded texts as
    /// [`CalibDir::load`](crate::calib_files::CalibDir::load) parses a
    /// folder's (a file the recording lacks is the compiled-in default).
    pub fn calibration(&self) -> Result<Calibration, RecordError> {
        if let Some((name, _)) = self.calib_files.iter().find(|(n, _)| !plain_file_name(n)) {
            return Err(RecordError::BadCalibName(name.clone()));
        }
        calibration_from_texts(&self.calib_files, "<recorded>")
            .map_err(|e| RecordError::Invalid { path: "recorded calibration".to_owned(), message: e.to_string() })
    }
}

/// Reads a recording. A file cut off after a [`super::Recorder::flush`]
/// reads back what was flushed (`truncated` says so); a file without the
/// recorded configuration, or not MCAP at all, is an error.
pub fn read_recording(path: &Path) -> Result<Recording, RecordError> {
    let shown = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| RecordError::Io { path: shown.clone(), source })?;
    let invalid = |message: String| RecordError::Invalid { path: shown.clone(), message };
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(invalid("not an MCAP file (no magic)".to_owned()));
    }
    let reader = mcap::read::ChunkFlattener::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|e| invalid(e.to_string()))?;

    let mut topics: HashMap<u16, String> = HashMap::new();
    let mut config_toml = None;
    let mut calib_files = Vec::new();
    let mut s = Recording {
        config_toml: String::new(),
        config: DaemonConfig::default(),
        calib_files: Vec::new(),
        observations: Vec::new(),
        plans: Vec::new(),
        exchanges: Vec::new(),
        counters: Vec::new(),
        truncated: None,
        log_time_offset: 0,
    };
    let mut ended = false;
    // Log times are wall clock (monotonic + this offset); 0 in older files.
    let mut offset = 0u64;
    for record in reader {
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                s.truncated = Some(e.to_string());
                break;
            }
        };
        match record {
            Record::Channel(c) => {
                topics.insert(c.id, c.topic);
            }
            Record::Metadata(m) if m.name == PROFILE => {
                offset = m.metadata.get(META_LOG_TIME_OFFSET).and_then(|v| v.parse().ok()).unwrap_or(0);
                s.log_time_offset = offset;
            }
            Record::Attachment { header, data, .. } => {
                let text = String::from_utf8(data.into_owned())
                    .map_err(|_| invalid(format!("attachment {} is not UTF-8", header.name)))?;
                if header.name == ATTACHMENT_CONFIG {
                    config_toml = Some(text);
                } else if let Some(name) = header.name.strip_prefix(ATTACHMENT_CALIB_PREFIX) {
                    calib_files.push((name.to_owned(), text));
                }
            }
            Record::Message { header, data } => {
                let topic = topics
                    .get(&header.channel_id)
                    .ok_or_else(|| invalid(format!("message on unknown channel {}", header.channel_id)))?;
                let bad =
                    |what: &str| invalid(format!("bad {topic} message (channel sequence {}): {what}", header.sequence));
                match topic.as_str() {
                    TOPIC_DATAGRAM => {
                        let m: DatagramMsg = serde_json::from_slice(&data).map_err(|e| bad(&e.to_string()))?;
                        s.observations.push(RecordedDatagram {
                            arrival: Instant::from_nanos(m.arrival_ns),
                            from: m.from.parse().map_err(|_| bad("from is not IP:PORT"))?,
                            bytes: from_hex(&m.hex).ok_or_else(|| bad("hex is not hex"))?,
                        });
                    }
                    TOPIC_PLAN => {
                        let m: PlanMsg = serde_json::from_slice(&data).map_err(|e| bad(&e.to_string()))?;
                        s.plans.push(m.to_plan().ok_or_else(|| bad("f64_bits must be 13 hex numbers"))?);
                    }
                    TOPIC_RSI => {
                        let m: RsiMsg = serde_json::from_slice(&data).map_err(|e| bad(&e.to_string()))?;
                        s.exchanges.push(RecordedExchange {
                            arrival: Instant::from_nanos(m.arrival_ns),
                            request: m.request_bytes().ok_or_else(|| bad("request"))?,
                            answer: m.answer_bytes().ok_or_else(|| bad("answer"))?,
                            sent: Instant::from_nanos(m.sent_ns),
                        });
                    }
                    TOPIC_COUNTERS => {
                        let v = serde_json::from_slice(&data).map_err(|e| bad(&e.to_string()))?;
                        s.counters.push((Instant::from_nanos(header.log_time.saturating_sub(offset)), v));
                    }
                    _ => {} // a topic a later version added
                }
            }
            Record::DataEnd(_) => {
                ended = true;
                break;
            }
            _ => {}
        }
    }
    if !ended && s.truncated.is_none() {
        s.truncated = Some("the file ends before its data end record".to_owned());
    }
    let config_toml = config_toml.ok_or_else(|| invalid(format!("no {ATTACHMENT_CONFIG} attachment")))?;
    s.config = DaemonConfig::from_toml(&config_toml).map_err(|e| invalid(format!("recorded configuration: {e}")))?;
    s.config_toml = config_toml;
    s.calib_files = calib_files;
    Ok(s)
}
