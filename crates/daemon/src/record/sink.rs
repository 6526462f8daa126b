//! The recorder as the telemetry thread's sink: every datagram, plan and
//! RSI exchange the daemon saw goes into the session file; a failure to
//! write is logged once and recording stops, the robot does not.

use super::Recorder;
use crate::runtime::telemetry::{DatagramRecord, RsiRecord, TelemetrySink};
use topspin_core::plan::StrikePlan;
use topspin_core::time::Instant;

/// A [`Recorder`] fed by the telemetry thread.
#[derive(Debug)]
pub struct RecordingSink {
    recorder: Option<Recorder>,
}

impl RecordingSink {
    /// A sink that writes into `recorder`.
    pub fn new(recorder: Recorder) -> Self {
        RecordingSink { recorder: Some(recorder) }
    }

    fn write(&mut self, f: impl FnOnce(&mut Recorder) -> Result<(), super::RecordError>) {
        if let Some(r) = self.recorder.as_mut()
            && let Err(e) = f(r)
        {
            tracing::error!(target: "topspin::record", "recording stopped: {e}");
            self.recorder = None;
        }
    }

    /// One message of the viewer's channels (see [`crate::channels`]).
    pub fn view(&mut self, topic: crate::channels::Topic, data: &[u8], log_time_ns: u64) {
        self.write(|r| r.view(topic, data, log_time_ns));
    }

    /// Finishes the file (index and summary).
    pub fn finish(mut self) {
        if let Some(r) = self.recorder.take()
            && let Err(e) = r.finish()
        {
            tracing::error!(target: "topspin::record", "finishing the recording: {e}");
        }
    }
}

impl Drop for RecordingSink {
    fn drop(&mut self) {
        if let Some(r) = self.recorder.take() {
            let _ = r.finish();
        }
    }
}

impl TelemetrySink for RecordingSink {
    fn datagram(&mut self, d: &DatagramRecord) {
        self.write(|r| r.observation(d.arrival, d.from, d.kept()));
    }

    fn plan(&mut self, p: &StrikePlan) {
        self.write(|r| r.plan(p));
    }

    fn rsi(&mut self, x: &RsiRecord) {
        self.write(|r| {
            r.rsi(x.arrival, &x.request[..x.request_len as usize], &x.answer[..x.answer_len as usize], x.sent)
        });
    }

    fn counters(&mut self, json: &serde_json::Value, at: Instant) {
        self.write(|r| r.counters(json, at));
    }

    fn flush(&mut self) {
        self.write(|r| r.flush());
    }
}
