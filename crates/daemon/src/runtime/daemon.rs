//! The daemon's threads (DESIGN §4): ingest → estimator → RSI loop, and
//! telemetry; optionally the logo thread (TTI1 crops → logo spin → the
//! estimator, through its own ring; it is not a hot thread). Each hot thread is a thin loop around a sans-IO core
//! (`Ingest`, `Estimator`, `RsiSession`); they talk through SPSC rings of
//! named capacity (rtrb) and a wait-free latest-value plan slot, and report
//! through their own telemetry ring. Threads are pinned and given SCHED_FIFO
//! where configured and permitted (refusals become warnings).
//!
//! Shutdown: `request_stop` stops ingest and estimator at once; the RSI
//! loop finishes the stroke under way, brings the bat home and keeps
//! answering until the controller stops sending (or never came), then
//! ends; telemetry drains last.

use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::rt::{self, RtWarning};
use super::telemetry::{
    self, DatagramRecord, LOGO_CROP_SIDE, LOGO_RING, LogoRecord, RECORDED_DATAGRAM, RECORDED_RSI, RSI_BYTES_RING,
    RsiRecord, TELEMETRY_RING, Telemetry, TelemetryInputs, TelemetrySink, TelemetrySummary, TelemetryTx,
};
use crate::clock;
use crate::rsi_server::{PlanReader, RsiServer, RsiSink, WaitStrategy, plan_slot};
use topspin_cnn::{Backend, LogoCnn};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::estimator::{Estimator, EstimatorConfig, LogoSpin};
use topspin_core::ingest::ClockMap;
use topspin_core::ingest::{Accepted, Ingest, IngestCounters};
use topspin_core::logo::LogoMethod;
use topspin_core::logo::{LogoCounters, LogoEngine, LogoStream};
use topspin_core::motion::Phase;
use topspin_core::rsi::{RsiSession, SessionConfig, SessionEvent, SessionStats};
use topspin_core::time::{Duration, Instant};
use topspin_core::wire::crop_origin;
use topspin_core::wire::{CROP_MAX_LEN, Crop};

/// Capacity of the logo → estimator ring, spins (one per ball).
pub(crate) const LOGO_SPIN_RING: usize = 8;
/// Receive timeout of the logo socket: ends quiet sequences, looks at the stop flag.
pub(crate) const LOGO_POLL: std::time::Duration = std::time::Duration::from_millis(5);
/// Capacity of the ingest → estimator ring, observations.
pub(crate) const OBSERVATION_RING: usize = 1024;
/// Largest tracker datagram read; longer ones are truncated (and malformed).
pub(crate) const MAX_TRACKER_DATAGRAM: usize = 512;
/// Receive timeout of the ingest socket: only for looking at the stop flag.
pub(crate) const INGEST_POLL: std::time::Duration = std::time::Duration::from_millis(20);
/// The estimator's idle wait when it blocks (it is unparked by ingest).
pub(crate) const ESTIMATOR_PARK: std::time::Duration = std::time::Duration::from_millis(5);
/// Longest drain after a stop request (the systemd unit's TimeoutStopSec
/// must exceed it).
pub(crate) const MAX_DRAIN: Duration = Duration::from_millis(5000);

/// Called first thing on every daemon thread with its role ("ingest",
/// "estimator", "rsi", "telemetry"): a seam for tests (the counting
/// allocator marks the hot threads) and profilers. Unset: nothing happens.
pub static THREAD_START_HOOK: std::sync::OnceLock<fn(&'static str)> = std::sync::OnceLock::new();

/// Per-thread core and real-time priority.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct ThreadSpec {
    /// The CPU to pin the thread to (`None`: not pinned).
    pub core: Option<usize>,
    /// The SCHED_FIFO priority (`None`: normal scheduling).
    pub priority: Option<i32>,
}

/// Everything the threads need, already validated.
#[derive(Clone, Debug, PartialEq)]
pub struct RuntimeConfig {
    /// Where the ingest thread receives tracker datagrams.
    pub tracker_bind: SocketAddr,
    /// Only datagrams from this address are accepted (`None`: any).
    pub tracker_source: Option<IpAddr>,
    /// Where the RSI thread receives the controller's datagrams.
    pub rsi_bind: SocketAddr,
    /// Only requests from this address are answered (`None`: any).
    pub controller_source: Option<IpAddr>,
    /// Lock the memory and give the hot threads their SCHED_FIFO priorities
    /// (false: every thread runs with normal scheduling).
    pub realtime: bool,
    /// The ingest thread's core and priority.
    pub ingest: ThreadSpec,
    /// The estimator thread's core and priority.
    pub estimator: ThreadSpec,
    /// The RSI thread's core and priority.
    pub rsi: ThreadSpec,
    /// The telemetry thread's core (its priority is not used).
    pub telemetry: ThreadSpec,
    /// How the RSI thread waits for the controller's next datagram.
    pub rsi_wait: WaitStrategy,
    /// The estimator spins on its ring instead of parking.
    pub estimator_busy_poll: bool,
    /// Tracker noise σ per axis, m.
    pub tracker_noise: f64,
    /// What the estimator learns across the session (`[estimator]`).
    pub learn: topspin_core::estimator::LearnConfig,
    /// The tracker's capture → datagram latency, added to the clock mapping.
    pub tracker_fixed_latency: Duration,
    /// `Type` of `<Sen>` in the answers.
    pub sentype: String,
    /// Seconds between counter log lines.
    pub log_interval_s: f64,
    /// Push the RSI bytes to telemetry (for the recording).
    pub record_rsi: bool,
    /// The logo thread, if on.
    pub logo: Option<LogoRuntime>,
    /// Compensate the robot's dead time and lag (`[servo]`).
    pub servo_compensation: bool,
    /// Cartesian (RKorr) or axis (AKorr) correction (`[rsi] correction`).
    pub correction: topspin_core::rsi::Correction,
}

/// The logo thread's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct LogoRuntime {
    /// Where the logo thread receives crop datagrams.
    pub bind: SocketAddr,
    /// Only crops from this address are accepted (`None`: any).
    pub source: Option<IpAddr>,
    /// How the logo is found in a crop.
    pub method: LogoMethodChoice,
    /// The ceiling camera's calibration.
    pub camera: CameraCalib,
    /// Capture → datagram latency of the camera side.
    pub camera_latency: Duration,
    /// The logo thread's core (its priority is not used).
    pub thread: ThreadSpec,
}

/// How the logo thread finds the logo.
#[derive(Clone, Debug, PartialEq)]
pub enum LogoMethodChoice {
    /// The logo CNN.
    Cnn {
        /// The ONNX model file.
        model: std::path::PathBuf,
        /// The engine that runs it.
        backend: Backend,
    },
    /// Background subtraction with the segment correction.
    Background,
}

impl LogoMethodChoice {
    /// The logo stream's method: the CNN loaded from its model (the
    /// reason when it does not load), or background subtraction.
    pub fn load(&self) -> Result<LogoEngine, String> {
        Ok(match self {
            LogoMethodChoice::Cnn { model, backend } => {
                LogoEngine::Cnn(Box::new(LogoCnn::load(model, backend).map_err(|e| e.to_string())?))
            }
            LogoMethodChoice::Background => LogoEngine::Background(LogoMethod::Segment),
        })
    }
}

impl RuntimeConfig {
    /// Everything on loopback with ephemeral ports, no pinning, SCHED_FIFO
    /// for the hot threads where permitted (else warnings and normal
    /// scheduling): for the demo, benches and tests.
    pub fn loopback() -> Self {
        let lo: SocketAddr = "127.0.0.1:0".parse().expect("literal");
        RuntimeConfig {
            tracker_bind: lo,
            tracker_source: Some(lo.ip()),
            rsi_bind: lo,
            controller_source: Some(lo.ip()),
            realtime: false,
            ingest: ThreadSpec { core: None, priority: Some(70) },
            estimator: ThreadSpec { core: None, priority: Some(60) },
            rsi: ThreadSpec { core: None, priority: Some(80) },
            telemetry: ThreadSpec::default(),
            rsi_wait: WaitStrategy::Blocking,
            estimator_busy_poll: false,
            tracker_noise: 0.002,
            learn: topspin_core::estimator::LearnConfig { returns: true, ..Default::default() },
            tracker_fixed_latency: Duration::from_millis(2),
            sentype: "ImFree".to_owned(),
            log_interval_s: 10.0,
            record_rsi: false,
            logo: None,
            servo_compensation: true,
            correction: topspin_core::rsi::Correction::Cartesian,
        }
    }
}

/// How the RSI link stands, shared for the shutdown decision.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum LinkState {
    /// No RSI session has started.
    NoRobot = 0,
    /// The arm is moving: a stroke, or on its way home.
    Moving = 1,
    /// The bat is home.
    Home = 2,
    /// The controller went silent with the bat away from home.
    Silent = 3,
    /// The controller went silent with the bat at home (RSI ended there).
    SilentHome = 4,
    /// The start was refused: held where the arm stands.
    Held = 5,
}

/// The link's state after session event `e`, from `current` (`None`: no
/// change).
fn next_link(current: LinkState, e: &SessionEvent) -> Option<LinkState> {
    match e {
        SessionEvent::Started { .. } | SessionEvent::Home => Some(LinkState::Home),
        SessionEvent::GoingHome { .. } | SessionEvent::ArmStopped { .. } => Some(LinkState::Moving),
        SessionEvent::StartRefused { .. } => Some(LinkState::Held),
        SessionEvent::RobotSilent if current == LinkState::Home => Some(LinkState::SilentHome),
        SessionEvent::RobotSilent => Some(LinkState::Silent),
        SessionEvent::PhaseChanged(Phase::Hold) => Some(LinkState::Home),
        SessionEvent::PhaseChanged(_) => Some(LinkState::Moving),
        _ => None,
    }
}

impl LinkState {
    fn from_u8(x: u8) -> Self {
        match x {
            1 => LinkState::Moving,
            2 => LinkState::Home,
            3 => LinkState::Silent,
            4 => LinkState::SilentHome,
            5 => LinkState::Held,
            _ => LinkState::NoRobot,
        }
    }
}

/// What the daemon's run ended with.
#[derive(Debug)]
pub struct DaemonSummary {
    /// What the telemetry thread saw.
    pub telemetry: TelemetrySummary,
    /// The ingest thread's counters.
    pub ingest: IngestCounters,
    /// The RSI session's statistics.
    pub session: SessionStats,
    /// The real-time requests the OS refused.
    pub warnings: Vec<RtWarning>,
    /// The RSI loop ended with the bat home (or no robot was there).
    pub ended_home: bool,
    /// The logo thread's counters, if it ran.
    pub logo: Option<LogoCounters>,
}

/// The running daemon.
#[derive(Debug)]
pub struct Daemon {
    /// The logo thread's end of the crop ring to the viewer (present when
    /// the daemon has a sink; take it with `Option::take`).
    pub logo_tx: Option<TelemetryTx<LogoRecord>>,
    /// The address the ingest thread's socket is bound to.
    pub tracker_addr: SocketAddr,
    /// The address the RSI thread's socket is bound to.
    pub rsi_addr: SocketAddr,
    /// Where the logo thread receives crops, if it runs.
    pub crops_addr: Option<SocketAddr>,
    stop: Arc<AtomicBool>,
    rsi_stop: Arc<AtomicBool>,
    telemetry_stop: Arc<AtomicBool>,
    link: Arc<AtomicU8>,
    ingest: JoinHandle<IngestCounters>,
    estimator: JoinHandle<()>,
    rsi: JoinHandle<io::Result<SessionStats>>,
    telemetry: JoinHandle<TelemetrySummary>,
    logo: Option<JoinHandle<LogoCounters>>,
    warnings: Arc<Mutex<Vec<RtWarning>>>,
}

struct ObsItem {
    accepted: Accepted,
    arrival: Instant,
}

fn spawn<T: Send + 'static>(
    name: &'static str,
    spec: ThreadSpec,
    realtime: bool,
    warnings: &Arc<Mutex<Vec<RtWarning>>>,
    f: impl FnOnce() -> T + Send + 'static,
) -> io::Result<JoinHandle<T>> {
    let warnings = warnings.clone();
    std::thread::Builder::new().name(format!("topspin-{name}")).spawn(move || {
        if let Some(hook) = THREAD_START_HOOK.get() {
            hook(name);
        }
        let refused = rt::setup_current(name, spec.core, if realtime { spec.priority } else { None });
        if !refused.is_empty() {
            warnings.lock().unwrap_or_else(|e| e.into_inner()).extend(refused);
        }
        f()
    })
}

impl Daemon {
    /// Binds the sockets and starts the threads. `sink` receives what the
    /// telemetry thread sees (the recording).
    pub fn start(cfg: &RuntimeConfig, cal: &Calibration, sink: Option<Box<dyn TelemetrySink>>) -> io::Result<Daemon> {
        let warnings = Arc::new(Mutex::new(Vec::new()));
        if cfg.realtime
            && let Err(w) = rt::lock_memory()
        {
            warnings.lock().unwrap_or_else(|e| e.into_inner()).push(w);
        }
        let tracker_socket = UdpSocket::bind(cfg.tracker_bind)?;
        tracker_socket.set_read_timeout(Some(INGEST_POLL))?;
        let tracker_addr = tracker_socket.local_addr()?;
        let mut session_cfg = SessionConfig::from_calibration(cal, &cfg.sentype);
        session_cfg.servo.enabled = cfg.servo_compensation;
        session_cfg.correction = cfg.correction;
        let session =
            RsiSession::new(session_cfg).map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))?;
        let server = RsiServer::bind(cfg.rsi_bind, session, cfg.rsi_wait)?;
        let rsi_addr = server.local_addr()?;

        let stop = Arc::new(AtomicBool::new(false));
        let rsi_stop = Arc::new(AtomicBool::new(false));
        let telemetry_stop = Arc::new(AtomicBool::new(false));
        let link = Arc::new(AtomicU8::new(LinkState::NoRobot as u8));
        let dropped = Arc::new(AtomicU64::new(0));
        let ingest_counters = Arc::new(Mutex::new(IngestCounters::default()));
        let (tx_ingest, rx_ingest) = telemetry::ring(&dropped, TELEMETRY_RING);
        let (tx_est, rx_est) = telemetry::ring(&dropped, TELEMETRY_RING);
        let (tx_rsi, rx_rsi) = telemetry::ring(&dropped, TELEMETRY_RING);
        let (bytes_tx, bytes_rx) = if cfg.record_rsi {
            let (tx, rx) = telemetry::ring(&dropped, RSI_BYTES_RING);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        // The logo thread's crops for the viewer: only when there is a sink.
        let (logo_tx, logo_rx) = if sink.is_some() {
            let (tx, rx) = telemetry::ring(&dropped, LOGO_RING);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        let (obs_tx, obs_rx) = rtrb::RingBuffer::<ObsItem>::new(OBSERVATION_RING);
        let (plan_tx, plan_rx) = plan_slot();
        let (spin_tx, spin_rx) = rtrb::RingBuffer::<LogoSpin>::new(LOGO_SPIN_RING);
        // The logo thread's socket and model first: a model that does not
        // load stops the start with its reason.
        let logo_parts = match &cfg.logo {
            Some(l) => {
                let socket = UdpSocket::bind(l.bind)?;
                socket.set_read_timeout(Some(LOGO_POLL))?;
                let method = l.method.load().map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
                Some((socket, LogoStream::new(l.camera.clone(), method), l.source, l.thread))
            }
            None => None,
        };
        let crops_addr = logo_parts.as_ref().map(|p| p.0.local_addr()).transpose()?;

        let estimator = {
            let est = Estimator::new(
                cal,
                EstimatorConfig { learn: cfg.learn, ..EstimatorConfig::default().with_noise(cfg.tracker_noise) },
            );
            let stop = stop.clone();
            let busy = cfg.estimator_busy_poll;
            spawn("estimator", cfg.estimator, cfg.realtime, &warnings, move || {
                estimator_loop(est, obs_rx, spin_rx, plan_tx, tx_est, &stop, busy)
            })?
        };
        // The viewer's crop ring goes to the logo thread when it runs.
        let mut logo_tx = logo_tx;
        let logo = match logo_parts {
            Some((socket, stream, source, spec)) => {
                let viewer = logo_tx.take();
                let stop = stop.clone();
                let latency = cfg.logo.as_ref().map_or(Duration(0), |l| l.camera_latency);
                let est_thread = estimator.thread().clone();
                Some(spawn("logo", spec, false, &warnings, move || {
                    logo_loop(stream, socket, source, spin_tx, viewer, latency, &stop, &est_thread)
                })?)
            }
            None => None,
        };
        let ingest = {
            let ing = Ingest::new(cfg.tracker_source, cfg.tracker_fixed_latency.0);
            let stop = stop.clone();
            let est_thread = estimator.thread().clone();
            let shared = ingest_counters.clone();
            spawn("ingest", cfg.ingest, cfg.realtime, &warnings, move || {
                ingest_loop(ing, tracker_socket, obs_tx, tx_ingest, &stop, &est_thread, &shared)
            })?
        };
        let rsi = {
            let sink =
                RsiTelemetry { tx: tx_rsi, link: link.clone(), bytes: bytes_tx, controller: cfg.controller_source };
            let rsi_stop = rsi_stop.clone();
            spawn("rsi", cfg.rsi, cfg.realtime, &warnings, move || rsi_loop(server, plan_rx, sink, &rsi_stop))?
        };
        let telemetry = {
            let stop = telemetry_stop.clone();
            let interval = cfg.log_interval_s;
            spawn("telemetry", cfg.telemetry, false, &warnings, move || {
                let ingest = move || *ingest_counters.lock().unwrap_or_else(|e| e.into_inner());
                let inputs = TelemetryInputs {
                    rings: vec![rx_ingest, rx_est, rx_rsi],
                    rsi_bytes: bytes_rx,
                    logo: logo_rx,
                    log_interval: interval,
                    sink,
                };
                telemetry::run(inputs, &stop, &dropped, &ingest, &clock::now)
            })?
        };
        Ok(Daemon {
            logo_tx,
            tracker_addr,
            rsi_addr,
            crops_addr,
            logo,
            stop,
            rsi_stop,
            telemetry_stop,
            link,
            ingest,
            estimator,
            rsi,
            telemetry,
            warnings,
        })
    }

    /// Real-time requests refused so far (the threads report at start).
    pub fn warnings(&self) -> Vec<RtWarning> {
        self.warnings.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// How the RSI link stands now.
    pub fn link_state(&self) -> LinkState {
        LinkState::from_u8(self.link.load(Ordering::Acquire))
    }

    /// Stops taking balls; the RSI loop goes on until the bat is home.
    pub fn request_stop(&self) {
        self.stop.store(true, Ordering::Release);
    }

    /// Waits for the drain — the bat home and the controller stopped
    /// (silent), or no robot at all, or at most `MAX_DRAIN` — and for
    /// every thread; returns what they saw.
    pub fn join(self) -> io::Result<DaemonSummary> {
        self.request_stop();
        let t0 = clock::now();
        let mut home = false;
        let ended_home = loop {
            match self.link_state() {
                // Already silent with the bat home (e.g. the controller
                // stopped before SIGTERM): it ended home.
                LinkState::NoRobot | LinkState::SilentHome => break true,
                LinkState::Silent => break home,
                // Held where it stood (a refused start): nothing will move.
                LinkState::Held => break false,
                LinkState::Home => home = true,
                LinkState::Moving => home = false,
            }
            if clock::now() - t0 >= MAX_DRAIN {
                break home;
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        };
        self.rsi_stop.store(true, Ordering::Release);
        let ingest = self.ingest.join().map_err(|_| io::Error::other("ingest thread panicked"))?;
        self.estimator.join().map_err(|_| io::Error::other("estimator thread panicked"))?;
        let logo = match self.logo {
            Some(h) => Some(h.join().map_err(|_| io::Error::other("logo thread panicked"))?),
            None => None,
        };
        let session = self.rsi.join().map_err(|_| io::Error::other("rsi thread panicked"))??;
        self.telemetry_stop.store(true, Ordering::Release);
        let telemetry = self.telemetry.join().map_err(|_| io::Error::other("telemetry thread panicked"))?;
        let warnings = self.warnings.lock().unwrap_or_else(|e| e.into_inner()).clone();
        Ok(DaemonSummary { telemetry, ingest, session, warnings, ended_home, logo })
    }
}

fn ingest_loop(
    mut ingest: Ingest,
    socket: UdpSocket,
    mut obs: rtrb::Producer<ObsItem>,
    mut tx: TelemetryTx,
    stop: &AtomicBool,
    estimator: &std::thread::Thread,
    shared: &Mutex<IngestCounters>,
) -> IngestCounters {
    let mut buf = [0u8; MAX_TRACKER_DATAGRAM];
    let mut since_publish = 0u32;
    while !stop.load(Ordering::Acquire) {
        let (n, from) = match socket.recv_from(&mut buf) {
            Ok(x) => x,
            Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => continue,
            Err(_) => continue, // e.g. ICMP errors surfacing on a UDP socket: nothing to do
        };
        let arrival = clock::now();
        let outcome = ingest.accept(&buf[..n], from, arrival);
        if let Ok(accepted) = outcome {
            // A full ring means the estimator fell behind: the newest wins next time.
            let _ = obs.push(ObsItem { accepted, arrival });
            estimator.unpark();
        }
        let mut bytes = [0u8; RECORDED_DATAGRAM];
        let kept = n.min(RECORDED_DATAGRAM);
        bytes[..kept].copy_from_slice(&buf[..kept]);
        tx.push(Telemetry::Datagram(DatagramRecord {
            arrival,
            from,
            len: n.min(u16::MAX as usize) as u16,
            bytes,
            outcome: outcome.map(|a| a.seq),
        }));
        // Share the counters with telemetry now and then (try_lock: never wait).
        since_publish += 1;
        if since_publish >= 64
            && let Ok(mut g) = shared.try_lock()
        {
            *g = ingest.counters();
            since_publish = 0;
        }
    }
    let c = ingest.counters();
    *shared.lock().unwrap_or_else(|e| e.into_inner()) = c;
    c
}

/// The logo thread: crops from the configured source → [`LogoStream`] →
/// spins to the estimator (a full ring drops the spin: it is one ball's);
/// each crop with what was seen in it to the viewer, if one is attached.
#[allow(clippy::too_many_arguments)] // the thread's whole world, once
fn logo_loop(
    mut stream: LogoStream,
    socket: UdpSocket,
    source: Option<IpAddr>,
    mut spins: rtrb::Producer<LogoSpin>,
    mut viewer: Option<TelemetryTx<LogoRecord>>,
    latency: Duration,
    stop: &AtomicBool,
    estimator: &std::thread::Thread,
) -> LogoCounters {
    let mut buf = vec![0u8; CROP_MAX_LEN + 1];
    let mut clock = ClockMap::new(latency.0);
    let mut foreign = 0u64;
    let mut malformed = 0u64;
    while !stop.load(Ordering::Acquire) {
        let spin = match socket.recv_from(&mut buf) {
            Ok((n, from)) => {
                if source.is_some_and(|ip| ip != from.ip()) {
                    foreign += 1;
                    continue;
                }
                match Crop::parse(&buf[..n]) {
                    Ok(mut c) => {
                        // The camera's clock mapped onto ours, as the tracker's is.
                        c.capture = clock.map(c.capture.0, clock::now());
                        let spin = stream.crop(&c);
                        if let Some(v) = viewer.as_mut() {
                            v.push(logo_record(&c, stream.last_logo()));
                        }
                        spin
                    }
                    Err(_) => {
                        malformed += 1;
                        continue;
                    }
                }
            }
            Err(_) => stream.poll(clock::now()),
        };
        if let Some(s) = spin {
            let _ = spins.push(s);
            estimator.unpark();
        }
    }
    let mut c = stream.counters();
    c.dropped += foreign + malformed;
    c
}

/// A crop for the viewer, with the ball and the logo in the crop's pixels
/// (TTI1 carries the ball's circle in the camera's).
pub(crate) fn logo_record(c: &Crop<'_>, logo: Option<topspin_core::logo::SeenLogo>) -> LogoRecord {
    let mut pixels = [0u8; 3 * LOGO_CROP_SIDE * LOGO_CROP_SIDE];
    let n = c.pixels.len().min(pixels.len());
    pixels[..n].copy_from_slice(&c.pixels[..n]);
    LogoRecord {
        capture: c.capture,
        trajectory: 0,
        width: c.width,
        height: c.height,
        pixels,
        ball_px: {
            let (x0, y0) = crop_origin(c.u.into(), c.v.into(), c.width.into(), c.height.into());
            [c.u - x0 as f32, c.v - y0 as f32, c.radius]
        },
        logo_px: logo.map(|l| l.crop_px),
        logo_dir: logo.map(|l| l.table.into()),
    }
}

fn estimator_loop(
    mut est: Estimator,
    mut obs: rtrb::Consumer<ObsItem>,
    mut logo: rtrb::Consumer<LogoSpin>,
    mut plans: crate::rsi_server::PlanWriter,
    mut tx: TelemetryTx,
    stop: &AtomicBool,
    busy_poll: bool,
) {
    // No idle `poll`: a silent track ends at the next observation (by
    // capture time), so a replay of the recorded datagrams makes the same
    // plans bit for bit.
    while !stop.load(Ordering::Acquire) {
        let mut any = false;
        while let Ok(spin) = logo.pop() {
            any = true;
            if let Some(e) = est.observe_logo_spin(&spin) {
                tx.push(Telemetry::Estimator(e));
            }
        }
        while let Ok(item) = obs.pop() {
            any = true;
            let out = est.observe(item.accepted.capture, item.accepted.pos);
            if let Some(plan) = out.plan {
                plans.publish(plan);
                tx.push(Telemetry::Plan { plan, arrival: item.arrival, published: clock::now() });
            }
            for e in out.events {
                tx.push(Telemetry::Estimator(e));
            }
            let track = est.tracking().map(|(id, ekf)| (id, ekf.state()));
            tx.push(Telemetry::Observed { capture: item.accepted.capture, pos: item.accepted.pos, track });
        }
        if !any {
            if busy_poll {
                std::hint::spin_loop();
            } else {
                std::thread::park_timeout(ESTIMATOR_PARK);
            }
        }
    }
}

struct RsiTelemetry {
    tx: TelemetryTx,
    link: Arc<AtomicU8>,
    /// The bytes of every exchange, when recording.
    bytes: Option<TelemetryTx<RsiRecord>>,
    controller: Option<IpAddr>,
}

impl RsiSink for RsiTelemetry {
    fn event(&mut self, e: SessionEvent) {
        if let Some(s) = next_link(LinkState::from_u8(self.link.load(Ordering::Acquire)), &e) {
            self.link.store(s as u8, Ordering::Release);
        }
        self.tx.push(Telemetry::Rsi(e));
    }

    fn exchange(&mut self, arrival: Instant, request: &[u8], answer: &[u8], sent: Instant) {
        self.tx.push(Telemetry::Answer { arrival, sent });
        if let Some(bytes) = self.bytes.as_mut() {
            let mut r = RsiRecord {
                arrival,
                sent,
                request_len: request.len().min(RECORDED_RSI) as u16,
                request: [0; RECORDED_RSI],
                answer_len: answer.len().min(RECORDED_RSI) as u16,
                answer: [0; RECORDED_RSI],
            };
            r.request[..r.request_len as usize].copy_from_slice(&request[..r.request_len as usize]);
            r.answer[..r.answer_len as usize].copy_from_slice(&answer[..r.answer_len as usize]);
            bytes.push(r);
        }
    }
}

fn rsi_loop(
    mut server: RsiServer,
    mut plans: PlanReader,
    sink: RsiTelemetry,
    stop: &AtomicBool,
) -> io::Result<SessionStats> {
    if let Some(ip) = sink.controller {
        server.allow_only(ip);
    }
    server.run(stop, &mut plans, sink)?;
    Ok(*server.session().stats())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_controller_silent_with_the_bat_home_ended_home() {
        let silent = SessionEvent::RobotSilent;
        assert_eq!(next_link(LinkState::Home, &silent), Some(LinkState::SilentHome));
        assert_eq!(next_link(LinkState::Moving, &silent), Some(LinkState::Silent));
        assert_eq!(
            next_link(LinkState::SilentHome, &SessionEvent::Started { ipoc: 1, off_home: false }),
            Some(LinkState::Home)
        );
        assert_eq!(next_link(LinkState::Home, &SessionEvent::PhaseChanged(Phase::Approach)), Some(LinkState::Moving));
        let going = SessionEvent::GoingHome { from_mm: 300.0, from_deg: 20.0, duration: Duration::from_millis(2000) };
        assert_eq!(next_link(LinkState::Home, &going), Some(LinkState::Moving));
        assert_eq!(next_link(LinkState::Moving, &SessionEvent::Home), Some(LinkState::Home));
        let refused = SessionEvent::StartRefused {
            reason: topspin_core::rsi::StartRefused::Missing("RIst"),
            from_mm: 0.0,
            from_deg: 0.0,
        };
        assert_eq!(next_link(LinkState::Home, &refused), Some(LinkState::Held));
        for s in [
            LinkState::NoRobot,
            LinkState::Moving,
            LinkState::Home,
            LinkState::Silent,
            LinkState::SilentHome,
            LinkState::Held,
        ] {
            assert_eq!(LinkState::from_u8(s as u8), s);
        }
    }
}
