//! `topspin sim`: simulated balls (the launcher's, or real human strokes)
//! as the tracker sees them, written
//! as files (`--out DIR`: one CSV and one truth JSON per ball, and a
//! back-to-back stream.csv) and/or streamed live as TTB1 datagrams over UDP
//! (`--to ADDR`). The content is deterministic in `--seed`; only the
//! pacing of the live stream follows the wall clock.

use std::fmt::Write as _;
use std::io::Write as _;
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use topspin_daemon::calib_files::CalibDir;

use anyhow::Context as _;
use serde::Serialize;

use super::args::Settings;
use super::bad;
use super::fit::PhysicsChoice;
use topspin_core::calib::Calibration;
use topspin_sim::{self as sim, Setting, SimBall, TrackerModel, Truth};

/// Where the live stream's capture clock starts before the first launch, s
/// (the tracker's monotonic clock counts from the start of the stream).
pub const STREAM_LEAD: f64 = 0.2;

#[derive(Debug, clap::Args)]
#[command(group = clap::ArgGroup::new("sink").required(true).multiple(true).args(["out", "to"]))]
pub struct SimArgs {
    /// Write ball-NNN.csv, ball-NNN.json and stream.csv into DIR.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Stream the observations as TTB1 datagrams to ADDR (host:port) in
    /// real time.
    #[arg(long, value_name = "ADDR")]
    pub to: Option<String>,
    /// Local address for the stream's socket.
    #[arg(long, value_name = "ADDR", default_value = "0.0.0.0:0")]
    pub bind: String,
    /// What to simulate (boxed: the options are large next to other
    /// subcommands' arguments).
    #[command(flatten)]
    pub opts: Box<SimOptions>,
}

/// The simulation options shared by the file and the stream output (and
/// reusable by other commands that run the simulated tracker).
#[derive(Debug, clap::Args)]
pub struct SimOptions {
    /// Number of balls.
    #[arg(long, default_value_t = 20)]
    pub balls: usize,
    /// Seed of the run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// `all`, or one or more comma-separated settings (backspin-low, …,
    /// topspin-high); ball k takes setting k mod their number.
    #[arg(long, default_value = "all")]
    pub setting: Settings,
    /// Where the balls come from: `launcher` (the settings above),
    /// `aimed-launcher` (the same, every ball aimed through the hitting
    /// volume's window), or real human strokes measured right after the
    /// racket: `human-rally`, `human-serve`, `human` (both).
    #[arg(long, default_value_t = sim::Strokes::Launcher, value_name = "SOURCE")]
    pub strokes: sim::Strokes,
    /// Tracker noise, standard deviation per axis, mm.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub noise_mm: f64,
    /// Tracker frame rate, Hz.
    #[arg(long, default_value_t = 150.0, allow_negative_numbers = true)]
    pub rate: f64,
    /// Probability that the tracker loses the ball in a frame.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub dropout: f64,
    /// False detections (a hand near the launcher) at each flight's start.
    #[arg(long, default_value_t = 0)]
    pub false_starts: usize,
    /// Tracker latency (capture to arrival) for the live stream, ms.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
    pub latency_ms: f64,
    /// Physics coefficients.
    #[arg(long, value_enum, default_value_t = PhysicsChoice::Calibrated)]
    pub physics: PhysicsChoice,
    /// Calibration folder instead of the compiled-in one.
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// Seconds between launches (longer where a flight needs it).
    #[arg(long, default_value_t = 1.5, allow_negative_numbers = true)]
    pub gap: f64,
}

/// The validated options.
struct Plan {
    settings: Vec<Setting>,
    cal: Calibration,
    tracker: TrackerModel,
}

fn plan(a: &SimOptions) -> anyhow::Result<Plan> {
    let settings = a.setting.0.clone();
    if !(a.noise_mm.is_finite() && a.noise_mm >= 0.0) {
        return Err(bad(format!("--noise-mm {} must be ≥ 0", a.noise_mm)));
    }
    if !(a.rate.is_finite() && a.rate > 0.0 && a.rate <= 100_000.0) {
        return Err(bad(format!("--rate {} must be > 0 Hz", a.rate)));
    }
    if !(a.dropout.is_finite() && (0.0..1.0).contains(&a.dropout)) {
        return Err(bad(format!("--dropout {} must be in [0, 1)", a.dropout)));
    }
    if !(a.latency_ms.is_finite() && a.latency_ms >= 0.0) {
        return Err(bad(format!("--latency-ms {} must be ≥ 0", a.latency_ms)));
    }
    if !(a.gap.is_finite() && a.gap > 0.0) {
        return Err(bad(format!("--gap {} must be > 0 s", a.gap)));
    }
    let cal = Calibration::load(a.calib.as_deref()).map_err(|e| bad(e.to_string()))?;
    let cal = match a.physics {
        PhysicsChoice::Calibrated => cal,
        PhysicsChoice::Paper => cal.with_paper_physics(),
    };
    Ok(Plan {
        settings,
        cal,
        tracker: TrackerModel {
            rate_hz: a.rate,
            noise_sigma: a.noise_mm * 1e-3,
            dropout: a.dropout,
            false_starts: a.false_starts,
            latency: a.latency_ms * 1e-3,
            ..TrackerModel::default()
        },
    })
}

/// `ball-NNN.json`: the truth, plus the tracker's side.
#[derive(Serialize)]
struct BallFile<'a> {
    ball: usize,
    seed: u64,
    #[serde(flatten)]
    truth: &'a Truth,
    /// 0-based data rows of ball-NNN.csv that are false detections.
    outliers: Vec<usize>,
    samples: usize,
    tracker: TrackerFile,
}

#[derive(Serialize)]
struct TrackerFile {
    rate_hz: f64,
    noise_sigma: f64,
    dropout: f64,
    false_starts: usize,
}

pub fn run(args: SimArgs) -> anyhow::Result<()> {
    let a = &*args.opts;
    let p = plan(a)?;
    let prop = p.cal.propagator();
    let x_hit = p.cal.strike.hit_plane_x;
    let mut balls = Vec::with_capacity(a.balls);
    if a.strokes == sim::Strokes::Launcher {
        for k in 0..a.balls {
            let setting = p.settings[k % p.settings.len()];
            let ball =
                sim::simulate_ball(a.seed, k, setting, &prop, x_hit, &p.tracker).map_err(|e| bad(e.to_string()))?;
            balls.push(ball);
        }
    } else {
        if a.setting.0 != Setting::ALL {
            return Err(bad(format!(
                "--setting chooses the launcher's balls; it does not apply with --strokes {}",
                a.strokes
            )));
        }
        let (drawn, o) = sim::simulate_in(None, a.strokes, &p.cal, a.seed, a.balls, &p.tracker);
        if drawn.len() < a.balls {
            let why =
                if a.strokes.is_launcher() { "the launcher could not aim" } else { "never reached the robot's half" };
            return Err(bad(format!("--strokes {}: {} of {} balls {why}", a.strokes, a.balls - drawn.len(), a.balls)));
        }
        if !a.strokes.is_launcher() {
            eprintln!(
                "topspin sim: {} states of {} passed over, never on the robot's half (net {}, long {}, wide {}, serve \
             faults {})",
                o.total(),
                a.strokes,
                o.net,
                o.long,
                o.wide,
                o.serve
            );
        }
        balls = drawn;
    }
    let ends: Vec<f64> = balls.iter().map(|b| b.truth.end_t).collect();
    let starts = sim::schedule(&ends, a.gap);

    if let Some(dir) = &args.out {
        write_files(dir, a, &p, &balls, &starts)?;
    }
    for b in &balls {
        println!("{}", summary(b));
    }
    if let Some(to) = &args.to {
        stream(to, &args.bind, &p.tracker, &balls, &starts)?;
    }
    Ok(())
}

fn summary(b: &SimBall) -> String {
    let t = &b.truth;
    let v: topspin_core::physics::Vec3 = t.launch.vel.into();
    let mut s = format!(
        "ball {:03} {:<15} speed {:5.2} m/s spin {:5.1} rps [{:7.1} {:7.1} {:7.1}] rad/s",
        b.index,
        t.setting,
        v.norm(),
        t.spin_rps,
        t.spin[0],
        t.spin[1],
        t.spin[2]
    );
    match &t.bounce {
        Some(bn) => {
            let _ = write!(s, " bounce x,y ({:.3}, {:.3}) at {:.3} s", bn.pos[0], bn.pos[1], bn.t);
        }
        None => s.push_str(" bounce -"),
    }
    match &t.hit {
        Some(h) => {
            let _ = write!(s, " hit y,z ({:.3}, {:.3}) at {:.3} s", h.pos[1], h.pos[2], h.t);
        }
        None => s.push_str(" hit -"),
    }
    let _ =
        write!(s, " samples {} outliers {}", b.observations.len(), b.observations.iter().filter(|o| o.outlier).count());
    s
}

fn write_files(dir: &Path, a: &SimOptions, p: &Plan, balls: &[SimBall], starts: &[f64]) -> anyhow::Result<()> {
    let io = |what: &Path, e: std::io::Error| bad(format!("cannot write {}: {e}", what.display()));
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let mut stream_csv = String::from("t,x,y,z,ball\n");
    for (b, start) in balls.iter().zip(starts) {
        let mut csv = String::from("t,x,y,z\n");
        for o in &b.observations {
            let _ = writeln!(csv, "{:.9},{:.6},{:.6},{:.6}", o.t, o.pos.x, o.pos.y, o.pos.z);
            let _ = writeln!(stream_csv, "{:.9},{:.6},{:.6},{:.6},{}", o.t + start, o.pos.x, o.pos.y, o.pos.z, b.index);
        }
        let path = dir.join(format!("ball-{:03}.csv", b.index));
        std::fs::write(&path, csv).map_err(|e| io(&path, e))?;
        let file = BallFile {
            ball: b.index,
            seed: a.seed,
            truth: &b.truth,
            outliers: b.outlier_rows(),
            samples: b.observations.len(),
            tracker: TrackerFile {
                rate_hz: p.tracker.rate_hz,
                noise_sigma: p.tracker.noise_sigma,
                dropout: p.tracker.dropout,
                false_starts: p.tracker.false_starts,
            },
        };
        let path = dir.join(format!("ball-{:03}.json", b.index));
        let mut json = serde_json::to_string_pretty(&file).context("serializing the truth")?;
        json.push('\n');
        std::fs::write(&path, json).map_err(|e| io(&path, e))?;
    }
    let path = dir.join("stream.csv");
    std::fs::write(&path, stream_csv).map_err(|e| io(&path, e))?;
    Ok(())
}

/// Streams in real time (see [`topspin_sim::udp_tracker`]); the capture clock is
/// the process clock, ball k launched at `STREAM_LEAD + starts[k]` s after
/// the start.
fn stream(to: &str, bind: &str, tracker: &TrackerModel, balls: &[SimBall], starts: &[f64]) -> anyhow::Result<()> {
    let socket = UdpSocket::bind(bind).map_err(|e| bad(format!("--bind {bind}: {e}")))?;
    socket.connect(to).map_err(|e| bad(format!("--to {to}: {e}")))?;
    let t0 = topspin_daemon::clock::now() + topspin_core::time::Duration::from_nanos((STREAM_LEAD * 1e9) as u64);
    let stop = std::sync::atomic::AtomicBool::new(false);
    let stats = topspin_sim::udp_tracker::stream(&socket, balls, starts, tracker.latency, t0, &stop)
        .with_context(|| format!("sending to {to}"))?;
    let total: usize = balls.iter().map(|b| b.observations.len()).sum();
    let mut err = std::io::stderr().lock();
    let _ = writeln!(err, "topspin sim: sent {} of {total} datagrams to {to}", stats.sent);
    Ok(())
}
