//! Telemetry: the fixed-size events the hot threads push through their SPSC
//! rings, and the cold thread that drains them — counters, latency
//! histograms (hdrhistogram), periodic logs (tracing), and an optional
//! sink (the session recording). Hot threads never format, log or wait:
//! a full ring drops the event and counts it.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use hdrhistogram::Histogram;
use rtrb::{Consumer, Producer};
use serde::Serialize;

use topspin_core::estimator::EstimatorEvent;
use topspin_core::ingest::{Dropped, IngestCounters};
use topspin_core::physics::{BallState, Vec3};
use topspin_core::plan::StrikePlan;
use topspin_core::rsi::SessionEvent;
use topspin_core::time::Instant;

/// Capacity of each thread's telemetry ring, events.
pub(crate) const TELEMETRY_RING: usize = 8192;
/// Seconds between flushes of the sink (the session file: what is flushed
/// survives a crash of the process).
pub(crate) const FLUSH_INTERVAL_S: f64 = 1.0;
/// Bytes of each received datagram kept for the recording.
pub(crate) const RECORDED_DATAGRAM: usize = 64;
/// Bytes of each RSI request and answer kept for the recording.
pub(crate) const RECORDED_RSI: usize = 1024;

/// One received tracker datagram.
#[derive(Copy, Clone, Debug)]
pub struct DatagramRecord {
    /// When it arrived, on the daemon's clock.
    pub arrival: Instant,
    /// The sender.
    pub from: SocketAddr,
    /// Length on the wire (may exceed what is kept).
    pub len: u16,
    /// Its first `RECORDED_DATAGRAM` bytes (see [`kept`](Self::kept)).
    pub bytes: [u8; RECORDED_DATAGRAM],
    /// The sequence number if accepted, otherwise why it was dropped.
    pub outcome: Result<u32, Dropped>,
}

impl DatagramRecord {
    /// The kept bytes.
    pub fn kept(&self) -> &[u8] {
        &self.bytes[..(self.len as usize).min(RECORDED_DATAGRAM)]
    }
}

/// One RSI exchange with its bytes (pushed only when recording).
#[derive(Copy, Clone, Debug)]
pub struct RsiRecord {
    /// When the controller's request arrived, on the daemon's clock.
    pub arrival: Instant,
    /// When the answer was sent, on the daemon's clock.
    pub sent: Instant,
    /// Bytes of `request` used (at most `RECORDED_RSI`).
    pub request_len: u16,
    /// The request's first bytes.
    pub request: [u8; RECORDED_RSI],
    /// Bytes of `answer` used (at most `RECORDED_RSI`).
    pub answer_len: u16,
    /// The answer's first bytes.
    pub answer: [u8; RECORDED_RSI],
}

/// An event from a hot thread.
#[derive(Copy, Clone, Debug)]
pub enum Telemetry {
    /// A tracker datagram the ingest thread received.
    Datagram(DatagramRecord),
    /// An event of the estimator.
    Estimator(EstimatorEvent),
    /// A plan published; `arrival` of the observation that made it.
    Plan {
        /// The plan.
        plan: StrikePlan,
        /// When the observation that made it arrived.
        arrival: Instant,
        /// When the plan was published to the RSI thread.
        published: Instant,
    },
    /// An event of the RSI session.
    Rsi(SessionEvent),
    /// One observation the estimator took (capture time on our clock,
    /// position in T) and, when it tracks a ball after it, the trajectory
    /// and its EKF state at that time (for the viewer).
    Observed {
        /// The capture time, on our clock.
        capture: Instant,
        /// The ball's position in the table frame, m.
        pos: Vec3,
        /// The tracked trajectory's number and its EKF state, if a ball is tracked.
        track: Option<(u32, BallState)>,
    },
    /// One RSI answer: request arrival and answer sent.
    Answer {
        /// When the request arrived.
        arrival: Instant,
        /// When the answer was sent.
        sent: Instant,
    },
}

/// Capacity of the ring of RSI bytes (recording only), exchanges.
pub(crate) const RSI_BYTES_RING: usize = 1024;
/// Capacity of the ring of logo crops (live view / recording), crops.
pub(crate) const LOGO_RING: usize = 64;
/// Largest logo crop side kept for the viewer, px (as `wire::crop::CROP_MAX_SIDE`).
pub(crate) const LOGO_CROP_SIDE: usize = 96;
/// Seconds between queue-depth samples handed to the sink.
pub(crate) const QUEUE_INTERVAL_S: f64 = 0.1;

/// One ball crop of the logo thread with what it found (for the viewer):
/// fixed-size and `Copy`, pushed through its own ring like the RSI bytes.
#[derive(Copy, Clone, Debug)]
pub struct LogoRecord {
    /// Capture time of the crop.
    pub capture: Instant,
    /// The ball's trajectory number (0 from the logo thread, which does not know it).
    pub trajectory: u32,
    /// Crop size, px (each at most `LOGO_CROP_SIDE`).
    pub width: u16,
    /// Crop height, px (at most `LOGO_CROP_SIDE`).
    pub height: u16,
    /// Row-major pixels, `rgb8` (3 bytes a pixel), `width * height * 3` used.
    pub pixels: [u8; 3 * LOGO_CROP_SIDE * LOGO_CROP_SIDE],
    /// The ball in the crop: centre u, v and radius, px.
    pub ball_px: [f32; 3],
    /// The detected logo's centre in the crop, px (`None`: not seen).
    pub logo_px: Option<[f32; 2]>,
    /// The fitted logo direction on the ball, unit vector in the table frame.
    pub logo_dir: Option<[f64; 3]>,
}

/// Ring occupancy seen by the telemetry thread, the most over a sample interval.
#[derive(Copy, Clone, Debug, Default, Serialize)]
pub struct QueueDepths {
    /// One per telemetry ring (ingest, estimator, RSI), events waiting.
    pub rings: [usize; 3],
    /// RSI bytes ring (recording or live view), exchanges waiting.
    pub rsi_bytes: usize,
    /// Events dropped because a ring was full, since the start.
    pub dropped: u64,
}

/// A hot thread's end of a telemetry ring.
#[derive(Debug)]
pub struct TelemetryTx<T = Telemetry> {
    producer: Producer<T>,
    dropped: Arc<AtomicU64>,
}

impl<T> TelemetryTx<T> {
    /// Pushes `e`; a full ring drops it (counted).
    #[inline]
    pub fn push(&mut self, e: T) {
        if self.producer.push(e).is_err() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Where the telemetry thread hands what it sees (the recording).
pub trait TelemetrySink: Send {
    /// Every tracker datagram received.
    fn datagram(&mut self, _d: &DatagramRecord) {}
    /// Every plan published.
    fn plan(&mut self, _p: &StrikePlan) {}
    /// Every RSI exchange with its bytes (only when the RSI bytes are pushed).
    fn rsi(&mut self, _r: &RsiRecord) {}
    /// Every event from the hot threads, after the calls above (the viewer).
    fn event(&mut self, _e: &Telemetry) {}
    /// One logo crop (the viewer).
    fn logo(&mut self, _l: &LogoRecord) {}
    /// The queue depths every `QUEUE_INTERVAL_S`.
    fn queues(&mut self, _q: &QueueDepths, _at: Instant) {}
    /// Called at each log interval and at the end.
    fn counters(&mut self, _json: &serde_json::Value, _at: Instant) {}
    /// Writes out what is buffered: about every `FLUSH_INTERVAL_S`, after
    /// each counters call, and at the end.
    fn flush(&mut self) {}
}

/// Percentiles of a latency histogram, µs.
#[derive(Copy, Clone, Debug, Serialize)]
pub struct Latency {
    /// The median.
    pub p50: u64,
    /// The 99th percentile.
    pub p99: u64,
    /// The 99.9th percentile.
    pub p999: u64,
    /// The largest value.
    pub max: u64,
    /// How many values were recorded.
    pub n: u64,
}

impl Latency {
    /// The percentiles of `h`.
    pub fn of(h: &hdrhistogram::Histogram<u64>) -> Self {
        Latency {
            p50: h.value_at_quantile(0.5),
            p99: h.value_at_quantile(0.99),
            p999: h.value_at_quantile(0.999),
            max: h.max(),
            n: h.len(),
        }
    }
}

/// Both latency histograms.
#[derive(Copy, Clone, Debug, Serialize)]
pub struct Latencies {
    /// RSI request arrival → answer sent.
    pub rsi_answer: Latency,
    /// Observation arrival → plan published.
    pub obs_to_plan: Latency,
}

impl Latencies {
    /// Both histograms of a telemetry summary.
    pub fn of(t: &TelemetrySummary) -> Self {
        Latencies { rsi_answer: Latency::of(&t.rsi_answer_us), obs_to_plan: Latency::of(&t.obs_to_plan_us) }
    }
}

/// What the telemetry thread has seen; returned at the end.
#[derive(Debug)]
pub struct TelemetrySummary {
    /// Observation arrival → plan published, µs.
    pub obs_to_plan_us: Histogram<u64>,
    /// RSI request arrival → answer sent, µs.
    pub rsi_answer_us: Histogram<u64>,
    /// The last plan of each trajectory, in order.
    pub last_plans: Vec<StrikePlan>,
    /// Plans published.
    pub plans: u64,
    /// Tracker datagrams received.
    pub datagrams: u64,
    /// Trajectories the estimator started.
    pub trajectories: u64,
    /// The controller's latest count of late answers (`<Delay>`).
    pub controller_late: u64,
    /// RSI session events.
    pub rsi_events: u64,
    /// Plans the RSI loop took although they arrive late, and the worst.
    pub plans_late: u64,
    /// The largest lateness of those plans, ms.
    pub late_by_max_ms: f64,
    /// Plans the RSI loop refused.
    pub plans_rejected: u64,
    /// Balls (trajectories) with a refused plan, by the first refusal's
    /// reason ([`PlanRejected::key`](topspin_core::motion::PlanRejected::key)).
    pub skipped: std::collections::BTreeMap<String, u64>,
    skipped_trajectories: std::collections::BTreeSet<u32>,
    /// Telemetry events dropped because a ring was full.
    pub telemetry_dropped: u64,
    /// The ingest thread's counters, as last read.
    pub ingest: IngestCounters,
    /// Logo spins fused into a track, and refused by its χ² gate.
    pub logo_spins_fused: u64,
    /// Logo spins refused by a track's χ² gate.
    pub logo_spins_gated: u64,
}

impl TelemetrySummary {
    fn new() -> Self {
        let h = || Histogram::new_with_bounds(1, 60_000_000, 3).expect("valid bounds");
        TelemetrySummary {
            obs_to_plan_us: h(),
            rsi_answer_us: h(),
            last_plans: Vec::new(),
            plans: 0,
            datagrams: 0,
            trajectories: 0,
            controller_late: 0,
            rsi_events: 0,
            plans_late: 0,
            late_by_max_ms: 0.0,
            plans_rejected: 0,
            skipped: Default::default(),
            skipped_trajectories: Default::default(),
            telemetry_dropped: 0,
            ingest: IngestCounters::default(),
            logo_spins_fused: 0,
            logo_spins_gated: 0,
        }
    }

    /// The counters as the JSON object the periodic log line and the sink get.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "datagrams": self.datagrams,
            "plans": self.plans,
            "trajectories": self.trajectories,
            "logo_spins_fused": self.logo_spins_fused,
            "logo_spins_gated": self.logo_spins_gated,
            "controller_late": self.controller_late,
            "plans_late": self.plans_late,
            "late_by_max_ms": self.late_by_max_ms,
            "plans_rejected": self.plans_rejected,
            "skipped": self.skipped,
            "telemetry_dropped": self.telemetry_dropped,
            "ingest": self.ingest,
            "latency_us": Latencies::of(self),
        })
    }
}

/// Creates one ring of `capacity`: the hot end and the cold end.
pub(crate) fn ring<T>(dropped: &Arc<AtomicU64>, capacity: usize) -> (TelemetryTx<T>, Consumer<T>) {
    let (producer, consumer) = rtrb::RingBuffer::new(capacity);
    (TelemetryTx { producer, dropped: dropped.clone() }, consumer)
}

fn us(from: Instant, to: Instant) -> u64 {
    ((to - from).0 / 1000).max(1)
}

/// What the telemetry thread drains and where it hands it.
#[allow(missing_debug_implementations)] // holds a `dyn TelemetrySink`
pub(crate) struct TelemetryInputs {
    /// The hot threads' telemetry rings.
    pub rings: Vec<Consumer<Telemetry>>,
    /// RSI bytes, when recording.
    pub rsi_bytes: Option<Consumer<RsiRecord>>,
    /// Logo crops, when the logo thread feeds the viewer.
    pub logo: Option<Consumer<LogoRecord>>,
    /// Seconds between periodic logs.
    pub log_interval: f64,
    /// Where what the thread sees is handed, if anywhere.
    pub sink: Option<Box<dyn TelemetrySink>>,
}

/// The telemetry thread's loop: drains the rings until `stop` (then once
/// more), logging every `log_interval` s of the clock `now`.
pub(crate) fn run(
    inputs: TelemetryInputs,
    stop: &AtomicBool,
    dropped: &AtomicU64,
    ingest: &dyn Fn() -> IngestCounters,
    now: &dyn Fn() -> Instant,
) -> TelemetrySummary {
    let TelemetryInputs { mut rings, mut rsi_bytes, mut logo, log_interval, mut sink } = inputs;
    let mut s = TelemetrySummary::new();
    let mut next_log = now().as_secs_f64() + log_interval;
    let mut next_flush = now().as_secs_f64() + FLUSH_INTERVAL_S;
    let mut next_queues = now().as_secs_f64() + QUEUE_INTERVAL_S;
    let mut depths = QueueDepths::default();
    loop {
        let stopping = stop.load(Ordering::Acquire);
        let mut any = false;
        for (i, ring) in rings.iter().enumerate().take(depths.rings.len()) {
            depths.rings[i] = depths.rings[i].max(ring.slots());
        }
        if let Some(r) = rsi_bytes.as_ref() {
            depths.rsi_bytes = depths.rsi_bytes.max(r.slots());
        }
        for ring in rings.iter_mut() {
            while let Ok(e) = ring.pop() {
                any = true;
                handle(&mut s, &e, &mut sink);
            }
        }
        if let Some(ring) = rsi_bytes.as_mut() {
            while let Ok(r) = ring.pop() {
                any = true;
                if let Some(k) = sink.as_mut() {
                    k.rsi(&r);
                }
            }
        }
        if let Some(ring) = logo.as_mut() {
            while let Ok(l) = ring.pop() {
                any = true;
                if let Some(k) = sink.as_mut() {
                    k.logo(&l);
                }
            }
        }
        let t = now();
        if t.as_secs_f64() >= next_queues {
            next_queues = t.as_secs_f64() + QUEUE_INTERVAL_S;
            depths.dropped = dropped.load(Ordering::Relaxed);
            if let Some(k) = sink.as_mut() {
                k.queues(&depths, t);
            }
            depths = QueueDepths::default();
        }
        if t.as_secs_f64() >= next_log || stopping {
            next_log = t.as_secs_f64() + log_interval;
            s.telemetry_dropped = dropped.load(Ordering::Relaxed);
            s.ingest = ingest();
            let json = s.to_json();
            tracing::info!(target: "topspin::telemetry", "{json}");
            if let Some(k) = sink.as_deref_mut() {
                k.counters(&json, t);
                k.flush();
            }
        }
        if t.as_secs_f64() >= next_flush {
            next_flush = t.as_secs_f64() + FLUSH_INTERVAL_S;
            if let Some(k) = sink.as_mut() {
                k.flush();
            }
        }
        if stopping {
            return s;
        }
        if !any {
            std::thread::sleep(std::time::Duration::from_millis(2));
        }
    }
}

fn handle(s: &mut TelemetrySummary, e: &Telemetry, sink: &mut Option<Box<dyn TelemetrySink>>) {
    tally(s, e, sink);
    if let Some(k) = sink {
        k.event(e);
    }
}

fn tally(s: &mut TelemetrySummary, e: &Telemetry, sink: &mut Option<Box<dyn TelemetrySink>>) {
    match e {
        Telemetry::Datagram(d) => {
            s.datagrams += 1;
            if let Err(reason) = d.outcome {
                tracing::debug!(target: "topspin::ingest", from = %d.from, ?reason, "datagram dropped");
            }
            if let Some(k) = sink {
                k.datagram(d);
            }
        }
        Telemetry::Estimator(ev) => match ev {
            EstimatorEvent::Started { .. } => {
                s.trajectories += 1;
                tracing::info!(target: "topspin::estimator", ?ev);
            }
            EstimatorEvent::Withheld { .. } | EstimatorEvent::Rejected { .. } => {
                tracing::debug!(target: "topspin::estimator", ?ev)
            }
            EstimatorEvent::LogoSpin { accepted, .. } => {
                if *accepted {
                    s.logo_spins_fused += 1;
                } else {
                    s.logo_spins_gated += 1;
                }
                tracing::info!(target: "topspin::estimator", ?ev);
            }
            _ => tracing::info!(target: "topspin::estimator", ?ev),
        },
        Telemetry::Plan { plan, arrival, published } => {
            s.plans += 1;
            let _ = s.obs_to_plan_us.record(us(*arrival, *published));
            match s.last_plans.last_mut() {
                Some(last) if last.trajectory == plan.trajectory => *last = *plan,
                _ => s.last_plans.push(*plan),
            }
            if let Some(k) = sink {
                k.plan(plan);
            }
        }
        Telemetry::Rsi(ev) => {
            s.rsi_events += 1;
            match ev {
                SessionEvent::PlanAccepted { late_by, .. } if late_by.0 > 0 => {
                    s.plans_late += 1;
                    s.late_by_max_ms = s.late_by_max_ms.max(late_by.as_secs_f64() * 1e3);
                    tracing::debug!(target: "topspin::rsi", ?ev);
                }
                SessionEvent::PlanRejected { seq, reason } => {
                    s.plans_rejected += 1;
                    if let Some(p) = s.last_plans.iter().rev().find(|p| p.seq == *seq)
                        && s.skipped_trajectories.insert(p.trajectory)
                    {
                        *s.skipped.entry(reason.key().to_owned()).or_default() += 1;
                    }
                    tracing::debug!(target: "topspin::rsi", ?ev);
                }
                SessionEvent::PlanAccepted { .. } => {}
                SessionEvent::ControllerLate { delay } => {
                    s.controller_late = *delay;
                    tracing::warn!(target: "topspin::rsi", delay, "controller counted late answers");
                }
                SessionEvent::StartRefused { reason, from_mm, from_deg } => {
                    tracing::error!(
                        target: "topspin::rsi",
                        reason = reason.key(),
                        "RSI start refused, holding with zero corrections: the arm stands {from_mm:.0} mm and \
                         {from_deg:.0}° from home; {reason}; {}",
                        reason.fix()
                    );
                }
                SessionEvent::GoingHome { from_mm, from_deg, duration } => {
                    tracing::warn!(
                        target: "topspin::rsi",
                        "the arm stands {from_mm:.0} mm and {from_deg:.0}° from home: going home at the \
                         commissioning speed ({:.1} s); no strokes until it is there",
                        duration.as_secs_f64()
                    );
                }
                SessionEvent::Home => tracing::info!(target: "topspin::rsi", "the arm is home and following: playing"),
                SessionEvent::ArmStopped { error_mm, error_deg, stroke_abandoned } => {
                    tracing::error!(
                        target: "topspin::rsi",
                        stroke_abandoned,
                        "the arm stopped following its commands ({error_mm:.1} mm, {error_deg:.1}° from the servo \
                         model; brakes, an operator stop, a KSS error or the load check): holding, no strokes; \
                         home at the commissioning speed once it stands still"
                    );
                }
                SessionEvent::Malformed(_)
                | SessionEvent::BadValue(_)
                | SessionEvent::SlowAnswer { .. }
                | SessionEvent::IpocGap { .. }
                | SessionEvent::AxisHeld { .. } => {
                    tracing::warn!(target: "topspin::rsi", ?ev)
                }
                _ => tracing::info!(target: "topspin::rsi", ?ev),
            }
        }
        Telemetry::Answer { arrival, sent } => {
            let _ = s.rsi_answer_us.record(us(*arrival, *sent));
        }
        Telemetry::Observed { .. } => {}
    }
}
