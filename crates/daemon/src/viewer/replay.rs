//! A recorded session through the viewer (`topspin replay FILE --live`):
//! the recorded datagrams through a fresh `Ingest` and `Estimator` (the
//! replay's path, so the same plans and EKF states as the daemon's) and the
//! recorded RSI exchanges, merged in arrival order and handed to a
//! [`TelemetrySink`] as the daemon's telemetry thread would, paced on the
//! recorded times.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::record::{RecordError, Recording};
use crate::runtime::telemetry::{QUEUE_INTERVAL_S, QueueDepths, RECORDED_RSI, RsiRecord, Telemetry, TelemetrySink};
use topspin_core::estimator::Estimator;
use topspin_core::ingest::Ingest;
use topspin_core::time::Duration;

/// Feeds `session` to `sink`; `speed`: recorded seconds per wall second
/// (`None`: as fast as it goes). Returns the events handed over.
pub fn view_recording(
    session: &Recording,
    sink: &mut dyn TelemetrySink,
    speed: Option<f64>,
    stop: &AtomicBool,
) -> Result<u64, RecordError> {
    let cal = session.calibration()?;
    let cfg = &session.config;
    let mut ingest = Ingest::new(Some(cfg.network.tracker_source), cfg.fixed_latency_ns());
    let mut est = Estimator::new(&cal, cfg.estimator_config());
    let (obs, rsi) = (&session.observations, &session.exchanges);
    let first = match (obs.first(), rsi.first()) {
        (Some(a), Some(b)) => a.arrival.min(b.arrival),
        (Some(a), None) => a.arrival,
        (None, Some(b)) => b.arrival,
        (None, None) => return Ok(0),
    };
    let wall0 = crate::clock::now();
    let (mut i, mut j, mut n) = (0, 0, 0u64);
    let mut next_queues = first;
    let queue_step = Duration::from_nanos((QUEUE_INTERVAL_S * 1e9) as u64);
    while (i < obs.len() || j < rsi.len()) && !stop.load(Ordering::Relaxed) {
        let take_obs = j >= rsi.len() || (i < obs.len() && obs[i].arrival <= rsi[j].arrival);
        let at = if take_obs { obs[i].arrival } else { rsi[j].arrival };
        if let Some(s) = speed.filter(|s| *s > 0.0) {
            let due = wall0 + Duration::from_nanos((at.secs_since(first) / s * 1e9) as u64);
            crate::clock::sleep_until(due, Duration::from_micros(0));
        }
        if at >= next_queues {
            next_queues = at + queue_step;
            sink.queues(&QueueDepths::default(), at);
        }
        if take_obs {
            let d = &obs[i];
            i += 1;
            let Ok(a) = ingest.accept(&d.bytes, d.from, d.arrival) else { continue };
            let out = est.observe(a.capture, a.pos);
            if let Some(plan) = out.plan {
                sink.plan(&plan);
                sink.event(&Telemetry::Plan { plan, arrival: d.arrival, published: d.arrival });
                n += 1;
            }
            for e in out.events {
                sink.event(&Telemetry::Estimator(e));
                n += 1;
            }
            let track = est.tracking().map(|(id, ekf)| (id, ekf.state()));
            sink.event(&Telemetry::Observed { capture: a.capture, pos: a.pos, track });
            n += 1;
        } else {
            let x = &rsi[j];
            j += 1;
            let mut r = RsiRecord {
                arrival: x.arrival,
                sent: x.sent,
                request_len: 0,
                request: [0; RECORDED_RSI],
                answer_len: 0,
                answer: [0; RECORDED_RSI],
            };
            let (q, a) = (x.request.len().min(RECORDED_RSI), x.answer.len().min(RECORDED_RSI));
            r.request[..q].copy_from_slice(&x.request[..q]);
            r.answer[..a].copy_from_slice(&x.answer[..a]);
            (r.request_len, r.answer_len) = (q as u16, a as u16);
            sink.rsi(&r);
            sink.event(&Telemetry::Answer { arrival: x.arrival, sent: x.sent });
            n += 1;
        }
    }
    sink.flush();
    Ok(n)
}
