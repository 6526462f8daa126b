//! `topspin eval paper --out DIR`: the paper's tables (III, IV, logo
//! metrics, real data) and figures in one run: `DIR/tables.md`,
//! `DIR/results.json` and `DIR/*.svg`, with a progress bar on stderr.
//!
//! The CNN (`--model`, `--backend`; `--no-cnn` leaves it out) and the
//! fused estimate (`--fuse-logo`) plug in through
//! [`topspin_lab::eval::paper::Extensions`] as [`topspin_lab::eval::paper::plug`]'s
//! predictor and fusion.

use std::path::{Path, PathBuf};
use topspin_daemon::calib_files::CalibDir;

use clap::Args;

use super::BadInput;
use super::fit::{PhysicsChoice, load_calibration};
use topspin_core::calib::Calibration;
use topspin_core::calib::CameraCalib;
use topspin_lab::data::MPI_LAB_TO_TABLE;
use topspin_lab::data::prepare;
use topspin_lab::data::{load, locate};
use topspin_lab::eval::paper::plug::{CnnPredictor, FusedLogo, TrajectoryLogoFusion};
use topspin_lab::eval::paper::report::{Histogram, LatencyRun, PaperReport, markdown};
use topspin_lab::eval::paper::{Extensions, PaperConfig, Progress, figures, run_tables};
use topspin_lab::progress::{StageBar, worker_threads};
use topspin_sim::demo::{DemoConfig, run_loopback};

#[derive(Debug, Args)]
pub struct EvalPaperArgs {
    /// Folder for tables.md, results.json and the figures (created).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Table III: balls per launcher setting.
    #[arg(long, default_value_t = 10)]
    pub bounce_balls: usize,
    /// Table IV: filmed flights per launcher setting.
    #[arg(long, default_value_t = 50)]
    pub flights: usize,
    /// Crops per filmed flight (380 Hz).
    #[arg(long, default_value_t = 20)]
    pub frames: usize,
    /// Tracker noise per axis, mm.
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Seconds of `topspin bench latency` for the latency histograms (0: none).
    #[arg(long, default_value_t = 5.0)]
    pub latency_s: f64,
    /// The MPI launcher folder (default: $TOPSPIN_MPI_DATA or ../shared/data/mpi-launcher).
    #[arg(long, value_name = "DIR")]
    pub data: Option<PathBuf>,
    /// Physics of the simulation and the fits.
    #[arg(long, value_enum, default_value_t = PhysicsChoice::Calibrated)]
    pub physics: PhysicsChoice,
    /// Another calibration folder.
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub cnn: super::logo_cnn::CnnArgs,
    /// Leave the CNN out (its rows say "no model").
    #[arg(long)]
    pub no_cnn: bool,
    /// The logo estimate fused with the refined trajectory fit.
    #[arg(long, value_enum, default_value = "segment")]
    pub fuse_logo: FusedLogo,
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_owned))
        .unwrap_or_else(|| "?".into())
}

/// A short `bench latency` run: the daemon threads, the mock KR C4 and
/// the simulated tracker on loopback.
pub fn latency_run(seconds: f64, cal: &Calibration) -> anyhow::Result<LatencyRun> {
    let gap = 1.2;
    let cfg = DemoConfig { balls: (seconds / gap).ceil().max(1.0) as usize, gap, ..DemoConfig::default() };
    let r = run_loopback(&cfg, cal)?;
    let t = &r.daemon.telemetry;
    let hist = |name: &str, h: &hdrhistogram::Histogram<u64>| Histogram {
        name: name.to_owned(),
        buckets: h.iter_recorded().map(|v| (v.value_iterated_to(), v.count_at_value())).collect(),
        p50: h.value_at_quantile(0.5),
        p99: h.value_at_quantile(0.99),
        p999: h.value_at_quantile(0.999),
        max: h.max(),
        n: h.len(),
    };
    Ok(LatencyRun {
        seconds,
        rsi_cycles: r.mock.cycles,
        late_answers: r.mock.late,
        histograms: vec![hist("RSI answer", &t.rsi_answer_us), hist("observation → plan", &t.obs_to_plan_us)],
    })
}

fn data_dir(explicit: Option<&Path>) -> Option<PathBuf> {
    if let Some(d) = explicit {
        return Some(d.to_owned());
    }
    let roots = [std::env::current_dir().ok(), Some(PathBuf::from(env!("CARGO_MANIFEST_DIR")))];
    roots.iter().flatten().find_map(|r| locate(r))
}

pub fn run_paper(a: EvalPaperArgs) -> anyhow::Result<()> {
    let started = topspin_daemon::clock::now();
    if !(a.noise_mm.is_finite() && a.noise_mm > 0.0) {
        return Err(BadInput(format!("--noise-mm {} must be positive", a.noise_mm)).into());
    }
    if a.flights < 2 || a.bounce_balls < 1 || a.frames < topspin_sim::render::MIN_FILMED_FRAMES {
        return Err(BadInput(format!(
            "need --flights ≥ 2, --bounce-balls ≥ 1 and --frames ≥ {}",
            topspin_sim::render::MIN_FILMED_FRAMES
        ))
        .into());
    }
    let cal = load_calibration(a.calib.as_deref(), a.physics)?;
    let cam = CameraCalib::load(a.calib.as_deref()).map_err(|e| BadInput(e.to_string()))?;
    std::fs::create_dir_all(&a.out).map_err(|e| BadInput(format!("{}: {e}", a.out.display())))?;
    let cfg = PaperConfig {
        seed: a.seed,
        bounce_balls: a.bounce_balls,
        flights: a.flights,
        frames: a.frames,
        noise_mm: a.noise_mm,
        ..PaperConfig::default()
    };
    let (real, real_note) = match data_dir(a.data.as_deref()) {
        Some(dir) => match load(&dir) {
            Ok(t) => (Some(prepare(&t, &MPI_LAB_TO_TABLE)), None),
            Err(e) => return Err(BadInput(format!("{}: {e}", dir.display())).into()),
        },
        None => (None, Some("MPI launcher data not found (`--data DIR` or `$TOPSPIN_MPI_DATA`): skipped.".to_owned())),
    };
    if a.no_cnn && a.fuse_logo == FusedLogo::Cnn {
        return Err(BadInput("--fuse-logo cnn needs the CNN (drop --no-cnn)".into()).into());
    }
    let mut cnn = if a.no_cnn {
        None
    } else {
        let model = a.cnn.model_path();
        let net = a.cnn.load()?;
        let name = format!(
            "{} on {}",
            model.file_name().map_or_else(|| model.display().to_string(), |f| f.to_string_lossy().into_owned()),
            net.backend().name()
        );
        Some(CnnPredictor::new(net, name))
    };
    let mut fusion = TrajectoryLogoFusion::new(a.fuse_logo);
    let load_before = load_average();
    let bar = StageBar::new(a.quiet);
    let epoch = topspin_daemon::clock::now();
    let clock = move || topspin_daemon::clock::secs_since(epoch);
    let ext = Extensions {
        cnn: cnn.as_mut().map(|c| c as &mut dyn topspin_lab::eval::paper::flights::CropPredictor),
        fusion: Some(&mut fusion),
    };
    let mut tables = run_tables(&cal, &cam, &cfg, real.as_deref(), ext, &bar, &clock);
    if let Some(name) = &mut tables.set.fusion_name {
        *name += &format!(": logo fused on {} flights, gated out on {}", fusion.fused, fusion.gated);
    }
    let latency = if a.latency_s > 0.0 {
        bar.stage(&format!("latency bench ({} s)", a.latency_s), 1);
        let t0 = topspin_daemon::clock::now();
        let l = latency_run(a.latency_s.max(2.0), &Calibration::default_cell())?;
        bar.inc(1);
        tables.stage_seconds.push(("latency bench".into(), topspin_daemon::clock::secs_since(t0)));
        Some(l)
    } else {
        None
    };
    bar.stage("figures", 1);
    let t0 = topspin_daemon::clock::now();
    let figs = figures(&cal, &cam, &cfg, &tables.set, latency.as_ref())?;
    for (name, svg) in &figs {
        std::fs::write(a.out.join(name), svg)?;
    }
    tables.stage_seconds.push(("figures".into(), topspin_daemon::clock::secs_since(t0)));
    bar.inc(1);
    bar.finish();
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let machine = format!(
        "{cores} cores, {} rayon threads, load average {load_before} at the start and {} at the end (a shared machine)",
        worker_threads(),
        load_average()
    );
    let mut command = format!(
        "topspin eval paper --out {} --seed {} --bounce-balls {} --flights {} --frames {} --noise-mm {}",
        a.out.display(),
        a.seed,
        a.bounce_balls,
        a.flights,
        a.frames,
        a.noise_mm
    );
    if a.latency_s != 5.0 {
        command += &format!(" --latency-s {}", a.latency_s);
    }
    if a.no_cnn {
        command += " --no-cnn";
    } else {
        if let Some(m) = &a.cnn.model {
            command += &format!(" --model {}", m.display());
        }
        if a.cnn.backend != topspin_cnn::Backend::Auto {
            command += &format!(" --backend {}", a.cnn.backend.name());
        }
    }
    if a.fuse_logo != FusedLogo::Segment {
        command += " --fuse-logo cnn";
    }
    let report = PaperReport {
        command,
        config: cfg,
        physics: match a.physics {
            PhysicsChoice::Calibrated => "calibrated (calib/physics.toml)".into(),
            PhysicsChoice::Paper => "the paper's".into(),
        },
        bounce: tables.bounce,
        classes: tables.classes,
        logo: tables.logo,
        tried: tables.set.tried,
        cnn: tables.set.cnn_name.clone(),
        fusion: tables.set.fusion_name.clone(),
        flights: tables.set.flights,
        real: tables.real,
        real_note,
        latency,
        figures: figs.into_iter().map(|f| f.0).collect(),
        stage_seconds: tables.stage_seconds,
        wall_seconds: topspin_daemon::clock::secs_since(started),
        machine,
    };
    let md = markdown(&report);
    std::fs::write(a.out.join("tables.md"), &md)?;
    std::fs::write(a.out.join("results.json"), serde_json::to_string_pretty(&report)?)?;
    print!("{md}");
    eprintln!("wrote {}/tables.md, results.json and {} figures", a.out.display(), report.figures.len());
    Ok(())
}
