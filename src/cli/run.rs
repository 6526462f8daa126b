//! `topspin run`: the daemon (DESIGN §4). Configuration from the layers of
//! `config`, calibration from `calib.dir`, the threads of
//! `runtime::daemon`, the session recording if enabled, systemd readiness
//! and watchdog, and a clean stop on SIGTERM/SIGINT: the bat is brought
//! home and answered until the controller stops, then everything ends.
//! Exit code 0 after a signal, 1 if the daemon failed, 2 for unusable
//! configuration or calibration.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use topspin_daemon::calib_files::{CalibDir, calibration_texts};

use clap::Args;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_core::time::Duration;
use topspin_daemon::config::{DaemonConfig, LogoMethodConfig, RsiWait};
use topspin_daemon::record::Recorder;
use topspin_daemon::record::RecordingSink;
use topspin_daemon::rsi_server::WaitStrategy;
use topspin_daemon::runtime::TelemetrySink;
use topspin_daemon::runtime::{Daemon, LogoMethodChoice, LogoRuntime, RuntimeConfig, ThreadSpec};
use topspin_daemon::systemd::Notifier;
use topspin_daemon::viewer::{LiveServer, ViewerSink};

#[derive(Debug, Args)]
pub struct RunArgs {
    /// Configuration file (over /etc/topspin/topspin.toml, under TOPSPIN_* variables).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the effective configuration and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Serve the live Foxglove view (WebSocket) on ADDR (default: `[viewer] live_bind`).
    #[arg(long, value_name = "ADDR", num_args = 0..=1)]
    pub live: Option<Option<std::net::SocketAddr>>,
}

/// The threads' settings from the daemon configuration (and, for the logo
/// thread, the camera's calibration).
pub fn runtime_config(c: &DaemonConfig) -> Result<RuntimeConfig, BadInput> {
    let t = &c.threads;
    let spec =
        |core: topspin_daemon::config::Core, priority: u8| ThreadSpec { core: core.0, priority: Some(priority as i32) };
    Ok(RuntimeConfig {
        tracker_bind: c.network.tracker_bind,
        tracker_source: Some(c.network.tracker_source),
        rsi_bind: c.network.rsi_bind,
        controller_source: Some(c.network.controller_source),
        realtime: t.realtime,
        ingest: spec(t.ingest_core, t.ingest_priority),
        estimator: spec(t.estimator_core, t.estimator_priority),
        rsi: spec(t.rsi_core, t.rsi_priority),
        telemetry: ThreadSpec { core: t.telemetry_core.0, priority: None },
        rsi_wait: match t.rsi_wait {
            RsiWait::Blocking => WaitStrategy::Blocking,
            RsiWait::BusyPoll => WaitStrategy::BusyPoll,
        },
        estimator_busy_poll: false,
        tracker_noise: c.tracker_noise_m(),
        learn: c.estimator_config().learn,
        tracker_fixed_latency: Duration::from_nanos(c.fixed_latency_ns()),
        sentype: c.rsi.sentype.clone(),
        log_interval_s: c.telemetry.log_interval_s,
        record_rsi: c.recording.enabled,
        logo: logo_runtime(c)?,
        servo_compensation: c.rsi.servo_compensation,
        correction: c.rsi.correction(),
    })
}

fn logo_runtime(c: &DaemonConfig) -> Result<Option<LogoRuntime>, BadInput> {
    let l = &c.logo;
    if !l.enabled {
        return Ok(None);
    }
    Ok(Some(LogoRuntime {
        bind: l.crops_bind,
        source: Some(l.crops_source),
        method: match l.method {
            LogoMethodConfig::Cnn => LogoMethodChoice::Cnn { model: c.logo_model(), backend: l.backend.clone() },
            LogoMethodConfig::Background => LogoMethodChoice::Background,
        },
        camera: CameraCalib::load(c.calib.dir()).map_err(|e| BadInput(e.to_string()))?,
        camera_latency: Duration::from_nanos(c.fixed_latency_ns()),
        thread: ThreadSpec { core: l.core.0, priority: None },
    }))
}

fn init_logging(level: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_env("TOPSPIN_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(format!("topspin={level}")));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
}

pub fn run(a: RunArgs) -> anyhow::Result<()> {
    let cfg = DaemonConfig::load(a.config.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    if a.print_config {
        print!("{}", cfg.to_toml());
        return Ok(());
    }
    let cal = Calibration::load(cfg.calib.dir()).map_err(|e| BadInput(e.to_string()))?;
    let rt = runtime_config(&cfg)?;
    init_logging(&cfg.telemetry.log_level);
    let recording = if cfg.recording.enabled {
        let dir = &cfg.recording.dir;
        std::fs::create_dir_all(dir).map_err(|e| BadInput(format!("recording.dir {}: {e}", dir.display())))?;
        let stamp = topspin_daemon::clock::unix_now_ns() / 1_000_000_000;
        // A restart within the same second (systemd after a crash) must not
        // overwrite the crashed run's recording.
        let path = (0..)
            .map(|k| {
                dir.join(if k == 0 { format!("topspin-{stamp}.mcap") } else { format!("topspin-{stamp}-{k}.mcap") })
            })
            .find(|p| !p.exists())
            .expect("an unused name");
        let files = calibration_texts(cfg.calib.dir()).map_err(|e| BadInput(e.to_string()))?;
        let rec = Recorder::create(&path, &cfg, &files).map_err(|e| BadInput(e.to_string()))?;
        tracing::info!(target: "topspin", "recording to {}", path.display());
        Some(RecordingSink::new(rec))
    } else {
        None
    };
    let live_addr = match a.live {
        Some(addr) => Some(addr.unwrap_or(cfg.viewer.live_bind)),
        None => cfg.viewer.live.then_some(cfg.viewer.live_bind),
    };
    let live = match live_addr {
        Some(addr) => {
            let server = LiveServer::start(addr, cfg.threads.telemetry_core.0).map_err(|e| BadInput(e.to_string()))?;
            tracing::info!(target: "topspin", "live view on ws://{}", server.addr());
            Some(server)
        }
        None => None,
    };
    let mut rcfg = rt;
    // The viewer shows the TCP from the RSI exchanges.
    rcfg.record_rsi |= live.is_some();
    let sink: Option<Box<dyn TelemetrySink>> = match (live, recording) {
        (None, None) => None,
        (live, recording) => Some(Box::new(ViewerSink::new(&cal, live, recording, None))),
    };
    let daemon = Daemon::start(&rcfg, &cal, sink).map_err(|e| anyhow::anyhow!("starting the daemon: {e}"))?;
    tracing::info!(
        target: "topspin",
        "running: tracker datagrams on {}, RSI on {}",
        daemon.tracker_addr,
        daemon.rsi_addr
    );
    let term = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGTERM, signal_hook::consts::SIGINT] {
        signal_hook::flag::register(sig, term.clone())?;
    }
    let notify = Notifier::from_env();
    let _ = notify.ready();
    let watchdog = notify.watchdog_interval().map(|d| d / 2);
    let mut last_ping = topspin_daemon::clock::now();
    let mut warned = 0;
    while !term.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(50));
        for w in daemon.warnings().iter().skip(warned) {
            tracing::warn!(target: "topspin", "{w}");
            warned += 1;
        }
        if let Some(every) = watchdog
            && topspin_daemon::clock::secs_since(last_ping) >= every.as_secs_f64()
        {
            let _ = notify.watchdog();
            last_ping = topspin_daemon::clock::now();
        }
    }
    tracing::info!(target: "topspin", "stopping: bringing the bat home");
    let _ = notify.stopping();
    let summary = daemon.join().map_err(|e| anyhow::anyhow!("stopping the daemon: {e}"))?;
    tracing::info!(
        target: "topspin",
        ended_home = summary.ended_home,
        "stopped: {}",
        summary.telemetry.to_json()
    );
    Ok(())
}
