//! The daemon's configuration (DESIGN §7): compiled defaults, then
//! `/etc/topspin/topspin.toml` if present, then `--config FILE`, then the
//! environment (`TOPSPIN_<SECTION>__<KEY>`, e.g.
//! `TOPSPIN_NETWORK__RSI_BIND=127.0.0.1:6000`), merged by the `config`
//! crate into one typed, validated [`DaemonConfig`].
//!
//! Typos are errors: a key no section knows is refused, naming the file (or
//! variable) and the key, and so is a value out of range, naming the key
//! (`network.rsi_bind: "x" is not an address`). `deploy/topspin.toml`
//! documents every key and equals the compiled defaults (tested).
//!
//! Cold path only: loaded once at start-up; owns no threads or sockets.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use topspin_core::estimator::EstimatorConfig;
use topspin_core::estimator::LearnConfig;

/// Where the system-wide configuration lives.
pub(crate) const SYSTEM_CONFIG_PATH: &str = "/etc/topspin/topspin.toml";
/// Prefix of the environment variables that override keys.
pub(crate) const ENV_PREFIX: &str = "TOPSPIN";
/// The largest CPU index a thread may be pinned to (glibc's `CPU_SETSIZE`).
pub(crate) const MAX_CORE: usize = 1023;

/// A configuration that cannot be used. Display is one line naming the file,
/// variable or key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// A configuration file could not be read.
    #[error("cannot read {path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why it could not be read.
        message: String,
    },
    /// A configuration file is not valid TOML.
    #[error("{path}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The TOML parser's message.
        message: String,
    },
    /// A layer (file or environment) names a key no section knows.
    #[error("{origin}: unknown key `{key}`")]
    UnknownKey {
        /// The file or environment variable that names the key.
        origin: String,
        /// The unknown key.
        key: String,
    },
    /// A key's value has the wrong type or is out of range.
    #[error("{key}: {message}")]
    Invalid {
        /// The key (`section.key`), or the section.
        key: String,
        /// What is wrong with it.
        message: String,
    },
    /// Anything else the merge reported.
    #[error("configuration: {0}")]
    Merge(String),
}

fn invalid(key: &str, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid { key: key.to_owned(), message: message.into() }
}

/// A CPU to pin a thread to, or none.
///
/// In TOML a core number, or the string `"none"` for a thread the scheduler
/// may move (omitting the key keeps the compiled default).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub struct Core(pub Option<usize>);

impl Serialize for Core {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Some(c) => s.serialize_u64(c as u64),
            None => s.serialize_str("none"),
        }
    }
}

impl<'de> Deserialize<'de> for Core {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Core;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a core number or \"none\"")
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Core, E> {
                usize::try_from(v).map(|c| Core(Some(c))).map_err(|_| E::custom("core number too large"))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Core, E> {
                u64::try_from(v)
                    .map_err(|_| E::custom(format!("{v} is not a core number")))
                    .and_then(|v| self.visit_u64(v))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Core, E> {
                if v.eq_ignore_ascii_case("none") {
                    Ok(Core(None))
                } else {
                    v.parse::<u64>()
                        .map_err(|_| E::custom(format!("{v:?} is not a core number or \"none\"")))
                        .and_then(|v| self.visit_u64(v))
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// How the RSI thread waits for the controller's next datagram (DESIGN §10).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RsiWait {
    /// Block in the kernel (poll with a timeout): cheap, ≈ 30 µs wake-up across cores.
    Blocking,
    /// Spin on a non-blocking socket: burns a core, p99.9 ≈ 25 µs.
    BusyPoll,
}

impl<'de> Deserialize<'de> for RsiWait {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        match s.as_str() {
            "blocking" => Ok(RsiWait::Blocking),
            "busy_poll" => Ok(RsiWait::BusyPoll),
            _ => Err(serde::de::Error::custom(format!("{s:?} is not \"blocking\" or \"busy_poll\""))),
        }
    }
}

/// `[network]`: the two UDP sockets and whom they accept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkConfig {
    /// Where the ingest thread receives tracker datagrams.
    #[serde(deserialize_with = "socket_addr")]
    pub tracker_bind: SocketAddr,
    /// Only datagrams from this IP are accepted as observations.
    #[serde(deserialize_with = "ip_addr")]
    pub tracker_source: IpAddr,
    /// Where the RSI thread receives the KR C4's datagrams (the IP/PORT of
    /// `rsi/topspin_ethernet.xml` on the robot side).
    #[serde(deserialize_with = "socket_addr")]
    pub rsi_bind: SocketAddr,
    /// Only RSI datagrams from this IP are answered.
    #[serde(deserialize_with = "ip_addr")]
    pub controller_source: IpAddr,
}

fn socket_addr<'de, D: Deserializer<'de>>(d: D) -> Result<SocketAddr, D::Error> {
    let s = String::deserialize(d)?;
    s.parse().map_err(|_| serde::de::Error::custom(format!("{s:?} is not an address (IP:PORT)")))
}

fn ip_addr<'de, D: Deserializer<'de>>(d: D) -> Result<IpAddr, D::Error> {
    let s = String::deserialize(d)?;
    s.parse().map_err(|_| serde::de::Error::custom(format!("{s:?} is not an IP address")))
}

/// `[threads]`: pinning and real-time scheduling.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThreadsConfig {
    /// SCHED_FIFO and mlockall where permitted (a warning where not).
    pub realtime: bool,
    /// The CPU the ingest thread is pinned to, or none.
    pub ingest_core: Core,
    /// The CPU the estimator thread is pinned to, or none.
    pub estimator_core: Core,
    /// The CPU the RSI thread is pinned to, or none.
    pub rsi_core: Core,
    /// The CPU the telemetry thread is pinned to, or none.
    pub telemetry_core: Core,
    /// The RSI thread's SCHED_FIFO priority, 1..=99.
    pub rsi_priority: u8,
    /// The ingest thread's SCHED_FIFO priority, 1..=99.
    pub ingest_priority: u8,
    /// The estimator thread's SCHED_FIFO priority, 1..=99.
    pub estimator_priority: u8,
    /// How the RSI thread waits for the controller's next datagram.
    pub rsi_wait: RsiWait,
}

/// `[tracker]`: the ball tracker's characteristics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerConfig {
    /// Per-axis position noise, mm (tunes the EKF and the start filter).
    pub noise_mm: f64,
    /// Capture → datagram sent, ms, added to the clock mapping.
    pub fixed_latency_ms: f64,
}

/// `[estimator]`: what the streaming estimator learns across a session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// Learn the air's drag, the table's e and μ and the filter's bounce
    /// noise from the balls of the session (false: every ball flies with
    /// the calibration, as before).
    pub learn_session: bool,
    /// Weight of a ball's own drag, read from its flight, against the
    /// session's for the rest of that flight, 0..=1.
    pub ball_drag_weight: f64,
    /// With `learn_session`: learn the spin the table meets per unit of
    /// the spin a flight shows, the next balls' spin prior (false: every
    /// ball bounces with the spin its flight showed). It starts anew with
    /// every start of the daemon.
    #[serde(default = "default_learn_spin")]
    pub learn_spin: bool,
    /// With `learn_spin`: read each ball's spin from its return as the
    /// tracker follows it back, against the stroke the arm was sent
    /// (false where the arm does not play the plans).
    #[serde(default = "default_learn_from_returns")]
    pub learn_from_returns: bool,
}

fn default_learn_from_returns() -> bool {
    true
}

fn default_learn_spin() -> bool {
    LearnConfig::default().spin
}

impl Default for EstimatorSection {
    fn default() -> Self {
        let l = LearnConfig::default();
        EstimatorSection {
            learn_session: l.enabled,
            ball_drag_weight: l.ball_drag_weight,
            learn_spin: l.spin,
            learn_from_returns: default_learn_from_returns(),
        }
    }
}

/// `[rsi]`: the RSI session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RsiConfig {
    /// `Type` of `<Sen>`: SENTYPE of the controller's Ethernet configuration.
    pub sentype: String,
    /// Compensate the robot's dead time and lag (`calib/robot.toml`
    /// `[servo]`): command ahead, feed the lag forward.
    #[serde(default = "yes")]
    pub servo_compensation: bool,
    /// `cartesian` (RKorr, POSCORR) or `axis` (AKorr, AXISCORR): as the
    /// controller's RSI context is built (`rsi/README.md`).
    #[serde(default = "cartesian")]
    pub correction: String,
}

impl RsiConfig {
    /// The correction (`correction`, validated by [`DaemonConfig::validate`]).
    pub fn correction(&self) -> topspin_core::rsi::Correction {
        self.correction.parse().unwrap_or_default()
    }
}

fn yes() -> bool {
    true
}

fn cartesian() -> String {
    "cartesian".to_owned()
}

/// `[telemetry]`: logs and counters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TelemetryConfig {
    /// Seconds between counter log lines.
    pub log_interval_s: f64,
    /// error, warn, info, debug or trace.
    pub log_level: String,
}

/// `[recording]`: the MCAP session recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordingConfig {
    /// Record the session to an MCAP file.
    pub enabled: bool,
    /// Folder the session files are written to.
    pub dir: PathBuf,
}

/// How the logo thread finds the logo.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum LogoMethodConfig {
    /// The network of `logo.model` (paper §III).
    Cnn,
    /// Background subtraction with the segment correction (paper §II).
    Background,
}

/// `[logo]`: the optional logo thread (spin from the ball's logo in the
/// ceiling camera's crops, fused into the estimator's spin).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogoConfig {
    /// Run the logo thread.
    pub enabled: bool,
    /// Where the logo thread receives TTI1 crop datagrams.
    #[serde(deserialize_with = "socket_addr")]
    pub crops_bind: SocketAddr,
    /// Only crops from this IP are accepted.
    #[serde(deserialize_with = "ip_addr")]
    pub crops_source: IpAddr,
    /// How the logo is found in a crop.
    pub method: LogoMethodConfig,
    /// The ONNX model; empty: `models/logo-compact.onnx` (see README).
    pub model: PathBuf,
    /// `auto` (ONNX Runtime when ORT_DYLIB_PATH names it, else tract),
    /// `tract` or `onnxruntime`.
    pub backend: topspin_cnn::Backend,
    /// The logo thread's core (give it one of its own).
    pub core: Core,
}

/// `[viewer]`: the live Foxglove view (see [`crate::viewer`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewerConfig {
    /// Serve the live view (`topspin run --live` turns it on too).
    pub live: bool,
    /// Where: loopback by default; the lab network's address to watch from elsewhere.
    pub live_bind: SocketAddr,
}

impl Default for ViewerConfig {
    fn default() -> Self {
        ViewerConfig { live: false, live_bind: SocketAddr::from(([127, 0, 0, 1], 8765)) }
    }
}

/// `[calib]`: which calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibConfig {
    /// A folder like `calib/`; empty: the compiled-in calibration.
    pub dir: PathBuf,
}

impl CalibConfig {
    /// The folder to pass to [`CalibDir::load`](crate::calib_files::CalibDir::load).
    pub fn dir(&self) -> Option<&Path> {
        (!self.dir.as_os_str().is_empty()).then_some(self.dir.as_path())
    }
}

/// The daemon's whole configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonConfig {
    /// `[network]`.
    pub network: NetworkConfig,
    /// `[threads]`.
    pub threads: ThreadsConfig,
    /// `[tracker]`.
    pub tracker: TrackerConfig,
    /// Absent in recordings made before it existed.
    #[serde(default)]
    pub estimator: EstimatorSection,
    /// `[rsi]`.
    pub rsi: RsiConfig,
    /// `[telemetry]`.
    pub telemetry: TelemetryConfig,
    /// `[recording]`.
    pub recording: RecordingConfig,
    /// Absent in recordings made before it existed.
    #[serde(default)]
    pub viewer: ViewerConfig,
    /// `[calib]`.
    pub calib: CalibConfig,
    /// `[logo]`.
    pub logo: LogoConfig,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        let lo = IpAddr::from([127, 0, 0, 1]);
        DaemonConfig {
            network: NetworkConfig {
                tracker_bind: SocketAddr::new(lo, 41000),
                tracker_source: lo,
                rsi_bind: SocketAddr::new(lo, 49152),
                controller_source: lo,
            },
            threads: ThreadsConfig {
                realtime: true,
                ingest_core: Core(Some(0)),
                estimator_core: Core(Some(1)),
                rsi_core: Core(Some(1)),
                telemetry_core: Core(Some(0)),
                rsi_priority: 80,
                ingest_priority: 70,
                estimator_priority: 60,
                rsi_wait: RsiWait::Blocking,
            },
            tracker: TrackerConfig { noise_mm: 2.0, fixed_latency_ms: 2.0 },
            estimator: EstimatorSection::default(),
            rsi: RsiConfig { sentype: "ImFree".to_owned(), servo_compensation: true, correction: cartesian() },
            telemetry: TelemetryConfig { log_interval_s: 10.0, log_level: "info".to_owned() },
            recording: RecordingConfig { enabled: false, dir: PathBuf::from("/var/lib/topspin") },
            viewer: ViewerConfig::default(),
            calib: CalibConfig { dir: PathBuf::new() },
            logo: LogoConfig {
                enabled: false,
                crops_bind: SocketAddr::new(lo, 41001),
                crops_source: lo,
                method: LogoMethodConfig::Background,
                model: PathBuf::new(),
                backend: topspin_cnn::Backend::Auto,
                core: Core(None),
            },
        }
    }
}

/// Log levels `telemetry.log_level` accepts.
pub(crate) const LOG_LEVELS: [&str; 5] = ["error", "warn", "info", "debug", "trace"];

impl DaemonConfig {
    /// The effective configuration: defaults < `SYSTEM_CONFIG_PATH` (if
    /// present) < `file` < the process environment.
    pub fn load(file: Option<&Path>) -> Result<DaemonConfig, ConfigError> {
        Self::load_layers(Some(Path::new(SYSTEM_CONFIG_PATH)), file, std::env::vars())
    }

    /// As [`load`](Self::load) with the system file and the environment
    /// given: `system` is skipped when `None` or absent, `file` must exist,
    /// `env` holds `(name, value)` pairs of which only `TOPSPIN_…__…` count.
    pub fn load_layers(
        system: Option<&Path>,
        file: Option<&Path>,
        env: impl IntoIterator<Item = (String, String)>,
    ) -> Result<DaemonConfig, ConfigError> {
        let merge = |e: config::ConfigError| ConfigError::Merge(e.to_string());
        let defaults = config::Config::try_from(&DaemonConfig::default()).map_err(merge)?;
        let mut builder = config::Config::builder().add_source(defaults);
        if let Some(sys) = system
            && sys.exists()
        {
            builder = builder.add_source(checked_file(sys)?);
        }
        if let Some(f) = file {
            builder = builder.add_source(checked_file(f)?);
        }
        let env = checked_env(env)?;
        if !env.is_empty() {
            builder = builder.add_source(
                config::Environment::with_prefix(ENV_PREFIX)
                    .prefix_separator("_")
                    .separator("__")
                    .try_parsing(true)
                    .source(Some(env)),
            );
        }
        let merged = builder.build().map_err(from_config_error)?;
        let cfg: DaemonConfig = merged.try_deserialize().map_err(from_config_error)?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Parses one TOML text holding a whole or partial configuration over the
    /// defaults (no system file, no environment).
    pub fn from_toml(text: &str) -> Result<DaemonConfig, ConfigError> {
        let origin = "<text>";
        let table: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| ConfigError::Syntax { path: origin.into(), message: one_line(&e) })?;
        check_keys(&table, origin)?;
        let merged = config::Config::builder()
            .add_source(config::Config::try_from(&DaemonConfig::default()).map_err(from_config_error)?)
            .add_source(config::File::from_str(text, config::FileFormat::Toml))
            .build()
            .map_err(from_config_error)?;
        let cfg: DaemonConfig = merged.try_deserialize().map_err(from_config_error)?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The configuration as TOML (for `--print-config` and recordings);
    /// [`from_toml`](Self::from_toml) reads it back to the same value.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a DaemonConfig always serialises (no maps with odd keys, no NaN-only types)")
    }

    /// Checks every value, naming the first bad key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let n = &self.network;
        for (key, addr) in [("network.tracker_bind", n.tracker_bind), ("network.rsi_bind", n.rsi_bind)] {
            if addr.port() == 0 {
                return Err(invalid(key, format!("\"{addr}\" needs a port (1..=65535)")));
            }
        }
        for (key, ip) in
            [("network.tracker_source", n.tracker_source), ("network.controller_source", n.controller_source)]
        {
            if ip.is_unspecified() || ip.is_multicast() {
                return Err(invalid(key, format!("\"{ip}\" is not a host address (name the sender's IP)")));
            }
        }
        let t = &self.threads;
        for (key, core) in [
            ("threads.ingest_core", t.ingest_core),
            ("threads.estimator_core", t.estimator_core),
            ("threads.rsi_core", t.rsi_core),
            ("threads.telemetry_core", t.telemetry_core),
            ("logo.core", self.logo.core),
        ] {
            if let Some(c) = core.0
                && c > MAX_CORE
            {
                return Err(invalid(key, format!("{c} is above {MAX_CORE}")));
            }
        }
        for (key, p) in [
            ("threads.rsi_priority", t.rsi_priority),
            ("threads.ingest_priority", t.ingest_priority),
            ("threads.estimator_priority", t.estimator_priority),
        ] {
            if !(1..=99).contains(&p) {
                return Err(invalid(key, format!("{p} is not a SCHED_FIFO priority (1..=99)")));
            }
        }
        let tr = &self.tracker;
        if !(tr.noise_mm.is_finite() && tr.noise_mm > 0.0 && tr.noise_mm <= 100.0) {
            return Err(invalid("tracker.noise_mm", format!("{} is not in (0, 100] mm", tr.noise_mm)));
        }
        if !(tr.fixed_latency_ms.is_finite() && (0.0..=1000.0).contains(&tr.fixed_latency_ms)) {
            return Err(invalid("tracker.fixed_latency_ms", format!("{} is not in [0, 1000] ms", tr.fixed_latency_ms)));
        }
        let w = self.estimator.ball_drag_weight;
        if !(w.is_finite() && (0.0..=1.0).contains(&w)) {
            return Err(invalid("estimator.ball_drag_weight", format!("{w} is not in [0, 1]")));
        }
        let s = &self.rsi.sentype;
        if s.is_empty() || s.len() > 64 || !s.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-') {
            return Err(invalid("rsi.sentype", format!("{s:?} is not a SENTYPE (1 to 64 of A-Z a-z 0-9 _ -)")));
        }
        if self.rsi.correction.parse::<topspin_core::rsi::Correction>().is_err() {
            return Err(invalid(
                "rsi.correction",
                format!("{:?} is not \"cartesian\" or \"axis\"", self.rsi.correction),
            ));
        }
        let te = &self.telemetry;
        if !(te.log_interval_s.is_finite() && te.log_interval_s > 0.0) {
            return Err(invalid("telemetry.log_interval_s", format!("{} is not a positive time", te.log_interval_s)));
        }
        if !LOG_LEVELS.contains(&te.log_level.as_str()) {
            return Err(invalid(
                "telemetry.log_level",
                format!("{:?} is not one of {}", te.log_level, LOG_LEVELS.join(", ")),
            ));
        }
        if self.recording.dir.as_os_str().is_empty() {
            return Err(invalid("recording.dir", "is empty"));
        }
        let l = &self.logo;
        if l.crops_bind.port() == 0 {
            return Err(invalid("logo.crops_bind", format!("\"{}\" needs a port (1..=65535)", l.crops_bind)));
        }
        if l.crops_source.is_unspecified() || l.crops_source.is_multicast() {
            return Err(invalid("logo.crops_source", format!("\"{}\" is not a host address", l.crops_source)));
        }
        if l.enabled && l.method == LogoMethodConfig::Cnn && !self.logo_model().is_file() {
            return Err(invalid("logo.model", format!("{} is not a file", self.logo_model().display())));
        }
        Ok(())
    }

    /// `logo.model`, or the default model when empty.
    pub fn logo_model(&self) -> PathBuf {
        if self.logo.model.as_os_str().is_empty() { topspin_cnn::default_model() } else { self.logo.model.clone() }
    }

    /// `tracker.noise_mm` in metres (for `EstimatorConfig::with_noise`).
    pub fn tracker_noise_m(&self) -> f64 {
        self.tracker.noise_mm * 1e-3
    }

    /// The estimator's settings: tuned to `tracker.noise_mm`, learning
    /// across the session as `[estimator]` says.
    pub fn estimator_config(&self) -> EstimatorConfig {
        let mut cfg = EstimatorConfig::default().with_noise(self.tracker_noise_m());
        cfg.learn = if self.estimator.learn_session {
            LearnConfig {
                ball_drag_weight: self.estimator.ball_drag_weight,
                spin: self.estimator.learn_spin,
                returns: self.estimator.learn_from_returns,
                ..LearnConfig::default()
            }
        } else {
            LearnConfig::OFF
        };
        cfg
    }

    /// `tracker.fixed_latency_ms` in nanoseconds (for `Ingest::new`).
    pub fn fixed_latency_ns(&self) -> u64 {
        (self.tracker.fixed_latency_ms * 1e6).round() as u64
    }
}

fn one_line(e: &impl std::fmt::Display) -> String {
    e.to_string().split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Reads and checks one file layer (readable, TOML, known keys only).
fn checked_file(path: &Path) -> Result<config::File<config::FileSourceString, config::FileFormat>, ConfigError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| ConfigError::Read { path: path.to_owned(), message: e.to_string() })?;
    let table: toml::Table = text.parse().map_err(|e: toml::de::Error| ConfigError::Syntax {
        path: path.to_owned(),
        message: match e.span() {
            Some(span) => {
                let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}: {}", e.message())
            }
            None => e.message().to_owned(),
        },
    })?;
    check_keys(&table, &path.display().to_string())?;
    Ok(config::File::from_str(&text, config::FileFormat::Toml))
}

/// The sections and keys the compiled defaults have.
fn known_keys() -> toml::Table {
    toml::Table::try_from(DaemonConfig::default()).expect("defaults serialise")
}

fn check_keys(table: &toml::Table, origin: &str) -> Result<(), ConfigError> {
    let known = known_keys();
    for (section, value) in table {
        let Some(known_section) = known.get(section).and_then(|v| v.as_table()) else {
            return Err(ConfigError::UnknownKey { origin: origin.to_owned(), key: section.clone() });
        };
        let Some(keys) = value.as_table() else {
            return Err(invalid(section, "must be a [section] of keys"));
        };
        for key in keys.keys() {
            if !known_section.contains_key(key) {
                return Err(ConfigError::UnknownKey { origin: origin.to_owned(), key: format!("{section}.{key}") });
            }
        }
    }
    Ok(())
}

/// The `TOPSPIN_<SECTION>__<KEY>` variables, each naming a known key.
fn checked_env(env: impl IntoIterator<Item = (String, String)>) -> Result<HashMap<String, String>, ConfigError> {
    let known = known_keys();
    let prefix = format!("{ENV_PREFIX}_");
    let mut out = HashMap::new();
    for (name, value) in env {
        let Some(rest) = name.strip_prefix(&prefix) else { continue };
        // Only SECTION__KEY names are ours; other TOPSPIN_* variables are left alone.
        let Some((section, key)) = rest.split_once("__") else { continue };
        let (section, key) = (section.to_lowercase(), key.to_lowercase());
        let found = known.get(&section).and_then(|s| s.as_table()).is_some_and(|s| s.contains_key(&key));
        if !found {
            return Err(ConfigError::UnknownKey { origin: name, key: format!("{section}.{key}") });
        }
        out.insert(name, value);
    }
    Ok(out)
}

/// Turns the merge's error into one naming the key where it has one.
fn from_config_error(e: config::ConfigError) -> ConfigError {
    match &e {
        config::ConfigError::Type { key: Some(key), unexpected, expected, .. } => {
            invalid(key, format!("{unexpected} is not {}", with_article(expected)))
        }
        config::ConfigError::At { key: Some(key), error, .. } => invalid(key, one_line(error)),
        _ => ConfigError::Merge(one_line(&e)),
    }
}

fn with_article(expected: &str) -> String {
    if expected.starts_with("a ") || expected.starts_with("an ") {
        expected.to_owned()
    } else if expected.starts_with(['a', 'e', 'i', 'o', 'u']) {
        format!("an {expected}")
    } else {
        format!("a {expected}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip() {
        let d = DaemonConfig::default();
        d.validate().unwrap();
        assert_eq!(DaemonConfig::from_toml(&d.to_toml()).unwrap(), d);
    }

    #[test]
    fn unpinned_core_round_trips() {
        let mut d = DaemonConfig::default();
        d.threads.rsi_core = Core(None);
        let text = d.to_toml();
        assert!(text.contains("rsi_core = \"none\""), "{text}");
        assert_eq!(DaemonConfig::from_toml(&text).unwrap(), d);
    }
}
