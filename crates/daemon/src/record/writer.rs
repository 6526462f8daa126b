//! The MCAP writer the telemetry thread owns (see the module doc).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;

use super::{
    ATTACHMENT_CALIB_PREFIX, ATTACHMENT_CONFIG, CHUNK_SIZE, DatagramMsg, META_LOG_TIME_OFFSET, PROFILE, PlanMsg,
    RecordError, RsiMsg, TOPIC_COUNTERS, TOPIC_DATAGRAM, TOPIC_PLAN, TOPIC_RSI, plain_file_name, schema,
};
use crate::channels::{TOPICS, Topic};
use crate::config::DaemonConfig;
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;

/// A buffered file whose `flush` also reaches the disk (`fdatasync`).
struct SyncFile {
    inner: BufWriter<File>,
}

impl Write for SyncFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.inner.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()?;
        self.inner.get_ref().sync_data()
    }
}

impl Seek for SyncFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.inner.seek(pos)
    }
}

#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// Writes one session to an MCAP file. Dropping it without
/// [`finish`](Recorder::finish) still writes the summary (errors ignored).
pub struct Recorder {
    path: PathBuf,
    writer: mcap::Writer<SyncFile>,
    datagram: Channel,
    plan: Channel,
    rsi: Channel,
    counters: Channel,
    /// The viewer's channels, in [`TOPICS`] order.
    view: Vec<Channel>,
    /// Added to the monotonic times to make the log times (wall clock).
    offset: u64,
    messages: u64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("path", &self.path).field("messages", &self.messages).finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates `path` (replacing a file there) and writes the configuration,
    /// the calibration texts (`(file name, TOML text)`, e.g. from
    /// [`calibration_texts`](crate::calib_files::calibration_texts)) and the channels, flushed to disk before the
    /// first message.
    pub fn create(
        path: &Path,
        config: &DaemonConfig,
        calib_files: &[(String, String)],
    ) -> Result<Recorder, RecordError> {
        for (name, _) in calib_files {
            if !plain_file_name(name) {
                return Err(RecordError::BadCalibName(name.clone()));
            }
        }
        let shown = path.display().to_string();
        let file = File::create(path).map_err(|source| RecordError::Io { path: shown.clone(), source })?;
        let mcap_err = |e: mcap::McapError| RecordError::Mcap { path: shown.clone(), message: e.to_string() };
        let options = mcap::WriteOptions::new()
            .profile(PROFILE)
            .compression(Some(mcap::Compression::Zstd))
            .compression_threads(0)
            .chunk_size(Some(CHUNK_SIZE));
        let mut writer = options.create(SyncFile { inner: BufWriter::new(file) }).map_err(mcap_err)?;

        let now_unix_ns = crate::clock::unix_now_ns();
        let mut meta = BTreeMap::new();
        meta.insert("version".to_owned(), env!("CARGO_PKG_VERSION").to_owned());
        let offset = crate::clock::unix_offset_ns();
        meta.insert(
            "clock".to_owned(),
            "log times: Unix ns (the daemon's monotonic clock + log_time_offset_ns); *_ns fields: monotonic".to_owned(),
        );
        meta.insert(META_LOG_TIME_OFFSET.to_owned(), offset.to_string());
        meta.insert("created_unix_ns".to_owned(), now_unix_ns.to_string());
        writer
            .write_metadata(&mcap::records::Metadata { name: PROFILE.to_owned(), metadata: meta })
            .map_err(mcap_err)?;
        let attach = |w: &mut mcap::Writer<SyncFile>, name: String, text: &str| {
            w.attach(&mcap::Attachment {
                log_time: 0,
                create_time: now_unix_ns,
                name,
                media_type: "application/toml".to_owned(),
                data: std::borrow::Cow::Borrowed(text.as_bytes()),
            })
        };
        attach(&mut writer, ATTACHMENT_CONFIG.to_owned(), &config.to_toml()).map_err(mcap_err)?;
        for (name, text) in calib_files {
            attach(&mut writer, format!("{ATTACHMENT_CALIB_PREFIX}{name}"), text).map_err(mcap_err)?;
        }

        let mut channel = |topic: &str, name: &str, schema: &str| -> Result<Channel, mcap::McapError> {
            let schema_id = writer.add_schema(name, "jsonschema", schema.as_bytes())?;
            let id = writer.add_channel(schema_id, topic, "json", &BTreeMap::new())?;
            Ok(Channel { id, sequence: 0 })
        };
        let datagram = channel(TOPIC_DATAGRAM, "topspin.TrackerDatagram", schema::DATAGRAM).map_err(mcap_err)?;
        let plan = channel(TOPIC_PLAN, "topspin.StrikePlan", schema::PLAN).map_err(mcap_err)?;
        let rsi = channel(TOPIC_RSI, "topspin.RsiExchange", schema::RSI).map_err(mcap_err)?;
        let counters = channel(TOPIC_COUNTERS, "topspin.Counters", schema::COUNTERS).map_err(mcap_err)?;
        let mut view = Vec::with_capacity(TOPICS.len());
        for t in TOPICS {
            let s = t.schema();
            let schema_id = writer.add_schema(&s.name, &s.encoding, &s.data).map_err(mcap_err)?;
            let id = writer.add_channel(schema_id, t.name(), t.encoding(), &BTreeMap::new()).map_err(mcap_err)?;
            view.push(Channel { id, sequence: 0 });
        }
        writer.flush().map_err(mcap_err)?;
        Ok(Recorder { path: path.to_owned(), writer, datagram, plan, rsi, counters, view, offset, messages: 0 })
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Messages written so far.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    fn mcap_err(&self, e: mcap::McapError) -> RecordError {
        RecordError::Mcap { path: self.path.display().to_string(), message: e.to_string() }
    }

    fn write(&mut self, which: fn(&mut Recorder) -> &mut Channel, at: Instant, json: &[u8]) -> Result<(), RecordError> {
        let log_time = at.as_nanos() + self.offset;
        let id = which(self).id;
        self.write_at(id, log_time, json)
    }

    fn write_at(&mut self, channel: u16, log_time: u64, data: &[u8]) -> Result<(), RecordError> {
        let Some(ch) = self.channel_mut(channel) else { return Ok(()) };
        let header = MessageHeader { channel_id: ch.id, sequence: ch.sequence, log_time, publish_time: log_time };
        ch.sequence = ch.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, data).map_err(|e| self.mcap_err(e))?;
        self.messages += 1;
        Ok(())
    }

    fn channel_mut(&mut self, id: u16) -> Option<&mut Channel> {
        [&mut self.datagram, &mut self.plan, &mut self.rsi, &mut self.counters]
            .into_iter()
            .chain(self.view.iter_mut())
            .find(|c| c.id == id)
    }

    /// One message of the viewer's `topic` (encoded as [`Topic::encoding`]),
    /// log time `log_time_ns` (wall clock, as the viewer stamps it).
    pub fn view(&mut self, topic: Topic, data: &[u8], log_time_ns: u64) -> Result<(), RecordError> {
        let id = self.view[topic as usize].id;
        self.write_at(id, log_time_ns, data)
    }

    fn json(&self, value: &impl serde::Serialize) -> Result<Vec<u8>, RecordError> {
        serde_json::to_vec(value)
            .map_err(|e| RecordError::Mcap { path: self.path.display().to_string(), message: format!("JSON: {e}") })
    }

    /// One datagram as it arrived on the tracker socket (accepted or not).
    pub fn observation(&mut self, arrival: Instant, from: SocketAddr, bytes: &[u8]) -> Result<(), RecordError> {
        let json = self.json(&DatagramMsg::new(arrival, from, bytes))?;
        self.write(|r| &mut r.datagram, arrival, &json)
    }

    /// One published strike plan.
    pub fn plan(&mut self, plan: &StrikePlan) -> Result<(), RecordError> {
        let json = self.json(&PlanMsg::from(plan))?;
        self.write(|r| &mut r.plan, plan.made_at, &json)
    }

    /// One RSI exchange: the controller's datagram (arrived at `arrival`)
    /// and our answer (sent at `sent`).
    pub fn rsi(&mut self, arrival: Instant, request: &[u8], answer: &[u8], sent: Instant) -> Result<(), RecordError> {
        let json = self.json(&RsiMsg::new(arrival, request, answer, sent))?;
        self.write(|r| &mut r.rsi, arrival, &json)
    }

    /// The counters at `at` (any JSON; an object plots best).
    pub fn counters(&mut self, json: &serde_json::Value, at: Instant) -> Result<(), RecordError> {
        let bytes = self.json(json)?;
        self.write(|r| &mut r.counters, at, &bytes)
    }

    /// Closes the open chunk and writes it to disk (`fdatasync`): everything
    /// recorded so far survives a crash. Call about once a second.
    pub fn flush(&mut self) -> Result<(), RecordError> {
        self.writer.flush().map_err(|e| self.mcap_err(e))
    }

    /// Writes the summary (indexes, statistics) and closes the file.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let path = self.path.display().to_string();
        self.writer.into_inner().flush().map_err(|source| RecordError::Io { path, source })
    }
}
