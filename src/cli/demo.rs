//! `topspin demo`: the simulated tracker, the daemon and the mock KR C4 on
//! loopback; a table per ball and a summary, or one JSON object.

use clap::Args;

use super::BadInput;
use topspin_core::calib::Calibration;
use topspin_sim::TrackerModel;
use topspin_sim::demo::{DemoConfig, DemoReport, HIT_RADIUS, HIT_WINDOW, run as run_demo};

#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Number of launcher balls (cycling through the nine settings).
    #[arg(long, default_value_t = 9)]
    pub balls: usize,
    /// Command the robot as if it had no dead time and lag (the mock KR C4
    /// still has them: calib/robot.toml [servo]), to see what the
    /// compensation is worth.
    #[arg(long)]
    pub no_lag_comp: bool,
    /// The correction the daemon sends and the mock KR C4's RSI context
    /// takes: `cartesian` (RKorr, POSCORR) or `axis` (AKorr from topspin's
    /// inverse kinematics, AXISCORR).
    #[arg(long, default_value = "cartesian", value_parser = super::mock_krc::parse_correction)]
    pub correction: topspin_core::rsi::Correction,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Tracker noise per axis, mm.
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Share of tracker frames lost.
    #[arg(long, default_value_t = 0.0)]
    pub dropout: f64,
    /// Launch-to-launch gap, s.
    #[arg(long, default_value_t = 1.5)]
    pub gap: f64,
    /// One JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Stretch the mock KR C4's answer deadline (ms; default: one RSI
    /// cycle, as the controller). For tests on shared machines: answers
    /// later than a cycle are then counted in `answers_after_cycle`.
    #[arg(long, hide = true)]
    pub answer_deadline_ms: Option<u64>,
    /// Simulate the ceiling camera too and run the logo thread: `cnn` or
    /// `background`; its spins are fused into the estimator's.
    #[arg(long, value_name = "METHOD")]
    pub logo: Option<topspin_daemon::config::LogoMethodConfig>,
    /// --logo cnn: the network.
    #[command(flatten)]
    pub cnn: super::logo_cnn::CnnArgs,
    /// Serve the live Foxglove view (WebSocket) on ADDR (default 127.0.0.1:8765).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = topspin_daemon::viewer::DEFAULT_LIVE_ADDR)]
    pub live: Option<std::net::SocketAddr>,
    /// With --live: wait up to this long (s) for Foxglove to connect before the first ball.
    #[arg(long, default_value_t = 0.0)]
    pub live_wait: f64,
    /// Record the session to this MCAP file (the viewer's channels included).
    #[arg(long, value_name = "FILE")]
    pub record: Option<std::path::PathBuf>,
    /// Late answers before the mock KR C4 stops RSI (default: the context's
    /// Timeout, as the controller). For soaks that count every late answer.
    #[arg(long, hide = true)]
    pub late_limit: Option<u64>,
    /// Mistreat the tracker stream with every fault (20 % loss,
    /// 100 ms silences, duplicates, reordering, garbage at 10× the ball
    /// rate, a foreign ball, teleports, a clock jump): `sim::faults`.
    #[arg(long)]
    pub tracker_faults: bool,
    /// Where the mock KR C4's arm stands when RSI starts: joints A1..A6 in
    /// degrees, comma-separated (default: home). The daemon takes it home
    /// at the commissioning speed first, or holds where that is unsafe.
    #[arg(long, value_name = "A1,..,A6", value_parser = super::mock_krc::parse_six, allow_hyphen_values = true)]
    pub start_joints: Option<[f64; 6]>,
    /// Fly the balls in a world of `topspin eval worlds` (e.g. the lift
    /// measured on real balls: real-launcher, real-rally), from the cell's
    /// wheel launcher; the daemon knows only the calibration.
    #[arg(long, value_name = "NAME")]
    pub world: Option<String>,
    /// Where the balls come from: `launcher` (the nine settings),
    /// `aimed-launcher` (the same, every ball aimed through the hitting
    /// volume's window), or real human strokes measured right after the
    /// racket: `human-rally`, `human-serve`, `human` (both).
    #[arg(long, default_value_t = topspin_sim::Strokes::AimedLauncher, value_name = "SOURCE")]
    pub strokes: topspin_sim::Strokes,
}

pub fn run(a: DemoArgs) -> anyhow::Result<()> {
    if a.balls == 0 {
        return Err(BadInput("--balls must be at least 1".into()).into());
    }
    if !(a.noise_mm.is_finite() && a.noise_mm >= 0.0) {
        return Err(BadInput(format!("--noise-mm {} must be ≥ 0", a.noise_mm)).into());
    }
    if !(0.0..1.0).contains(&a.dropout) {
        return Err(BadInput(format!("--dropout {} must be in [0, 1)", a.dropout)).into());
    }
    if !(a.gap.is_finite() && a.gap > 0.0) {
        return Err(BadInput(format!("--gap {} must be positive", a.gap)).into());
    }
    let cal = Calibration::default_cell();
    let world = match &a.world {
        Some(name) => Some(
            topspin_sim::worlds::world_named(&cal, name)
                .ok_or_else(|| BadInput(format!("--world {name}: no such world (see topspin eval worlds)")))?
                .with_launcher_axes(),
        ),
        None => None,
    };
    let mut runtime = topspin_daemon::runtime::RuntimeConfig::loopback();
    runtime.servo_compensation = !a.no_lag_comp;
    runtime.correction = a.correction;
    if let Some(method) = a.logo {
        runtime.logo = Some(topspin_daemon::runtime::LogoRuntime {
            bind: "127.0.0.1:0".parse().expect("literal"),
            source: Some([127, 0, 0, 1].into()),
            method: match method {
                topspin_daemon::config::LogoMethodConfig::Cnn => topspin_daemon::runtime::LogoMethodChoice::Cnn {
                    model: a.cnn.model_path(),
                    backend: a.cnn.backend.clone(),
                },
                topspin_daemon::config::LogoMethodConfig::Background => {
                    topspin_daemon::runtime::LogoMethodChoice::Background
                }
            },
            camera: topspin_core::calib::CameraCalib::default_camera(),
            camera_latency: topspin_core::time::Duration(0),
            thread: Default::default(),
        });
    }
    let cfg = DemoConfig {
        runtime,
        balls: a.balls,
        seed: a.seed,
        tracker: TrackerModel { noise_sigma: a.noise_mm * 1e-3, dropout: a.dropout, ..TrackerModel::default() },
        gap: a.gap,
        answer_deadline: a.answer_deadline_ms.map(topspin_core::time::Duration::from_millis),
        live: a.live,
        live_wait: topspin_core::time::Duration::from_nanos((a.live_wait.max(0.0) * 1e9) as u64),
        record: a.record.clone(),
        late_limit: a.late_limit,
        tracker_faults: a.tracker_faults.then(topspin_sim::faults::TrackerFaults::all),
        start_joints: a.start_joints,
        world,
        strokes: a.strokes,
        ..DemoConfig::default()
    };
    if !a.json {
        eprintln!(
            "topspin demo: {} {} balls, {} mm tracker noise, daemon and mock KR C4 (4 ms RSI) on loopback, about {:.0} s",
            a.balls,
            a.strokes,
            a.noise_mm,
            a.balls as f64 * a.gap + 1.5
        );
    }
    if let Some(addr) = a.live {
        eprintln!("topspin demo: live view on ws://{addr} (Foxglove: Open connection → Foxglove WebSocket)");
    }
    let report = run_demo(&cfg, &cal)?;
    if a.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", table(&report));
    }
    Ok(())
}

/// " (2 low, 1 wide)", or nothing when every ball was reachable.
fn out_of_reach(o: &topspin_sim::demo::OutOfReach) -> String {
    let parts: Vec<String> =
        [(o.no_crossing, "no crossing after the bounce"), (o.wide, "wide"), (o.low, "low"), (o.high, "high")]
            .iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
    if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) }
}

fn rps(v: &[f64; 3]) -> String {
    format!("({:6.1} {:6.1} {:6.1})", v[0], v[1], v[2])
}

/// The per-ball table and the summary.
pub fn table(r: &DemoReport) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "ball  setting          true spin rps (x y z)   estimated spin rps      spin err  hit err   verdict       \
         (plan err, plan Δt, bat vs plan)  return"
    );
    for b in &r.per_ball {
        let est = b.estimated_spin_rps.as_ref().map_or("        no plan        ".to_owned(), rps);
        let spin_err = b.spin_err_pct.map_or("    -".to_owned(), |e| format!("{e:5.1}%"));
        let hit_err = b.hit_err_mm.map_or("     -".to_owned(), |e| format!("{e:5.1} mm"));
        let verdict = match (b.reachable, b.hit) {
            (false, _) => "out of reach",
            (true, true) => "HIT",
            (true, false) => "miss",
        };
        let diag = match (b.plan_err_mm, b.plan_dt_ms, b.tracking_err_mm) {
            (Some(p), Some(dt), Some(tr)) => format!("({p:.1} mm, {dt:+.1} ms, {tr:.1} mm)"),
            _ => String::new(),
        };
        let ret = match (b.reachable, b.return_fail) {
            (false, _) => String::new(),
            (true, None) => "RETURNED".to_owned(),
            (true, Some(f)) => f.name().to_owned(),
        };
        let landing = b.landing_xy.map_or(String::new(), |p| format!(" at ({:+.2}, {:+.2}) m", p[0], p[1]));
        let why = match (b.reachable, &b.return_why) {
            (true, Some(w)) => format!(" — {w}"),
            _ => String::new(),
        };
        let _ = writeln!(
            out,
            "{:4}  {:15}  {}  {}  {:>8}  {:>8}  {verdict:12}  {diag:30}  {ret}{landing}{why}",
            b.ball,
            b.setting,
            rps(&b.true_spin_rps),
            est,
            spin_err,
            hit_err
        );
    }
    let l = &r.latency_us;
    let _ = writeln!(
        out,
        "\n{} of {} reachable balls hit ({:.1}%; bat within {:.0} mm of the ball within ±{} ms of the true crossing), \
         {} out of reach{}",
        r.hits,
        r.reachable,
        r.hit_rate * 100.0,
        HIT_RADIUS * 1e3,
        HIT_WINDOW.0 / 1_000_000,
        r.balls - r.reachable,
        out_of_reach(&r.out_of_reach)
    );
    let o = &r.strokes_out_of_play;
    if o.total() > 0 {
        let _ = writeln!(
            out,
            "{} strokes: {} drawn states passed over, never on the robot's half (net {}, long {}, wide {}, serve \
             faults {})",
            r.strokes,
            o.total(),
            o.net,
            o.long,
            o.wide,
            o.serve
        );
    }
    let fails: Vec<String> = topspin_sim::returns::ReturnFail::ALL
        .iter()
        .filter(|f| r.return_fails.get(**f) > 0)
        .map(|f| format!("{} {}", r.return_fails.get(*f), f.name()))
        .collect();
    let _ = writeln!(
        out,
        "{} of {} reachable balls returned ({:.1}%{}; the bat's actual pose and velocity at contact, the rubber's \
         contact model, over the net onto the opponent's half){}",
        r.returns,
        r.reachable,
        r.return_rate * 100.0,
        if r.balls > r.reachable {
            format!(", {:.1}% of all {} balls", r.return_rate_all * 100.0, r.balls)
        } else {
            String::new()
        },
        if fails.is_empty() { String::new() } else { format!("; not returned: {}", fails.join(", ")) }
    );
    if r.returns > 0 {
        // Each side is measured up to the span: at it, "at least".
        let side = |ms: f64| {
            let at_least = ms >= topspin_sim::returns::TIMING_SPAN_MS as f64;
            format!("{}{ms:.0} ms", if at_least { "≥ " } else { "" })
        };
        let [early, late] = r.timing_tolerance_ms_median.map(side);
        let _ = writeln!(
            out,
            "timing tolerance of the returns (median): the same strokes return the ball {early} earlier to {late} \
             later"
        );
        // The window's grid spans one doubling either way: at its ends,
        // "at most" and "at least".
        let [less, more] = r.spin_tolerance_median;
        let less = format!("{}×{less:.2}", if less <= 0.5 + 1e-9 { "≤ " } else { "" });
        let more = format!("{}×{more:.2}", if more >= 2.0 - 1e-9 { "≥ " } else { "" });
        let _ = writeln!(
            out,
            "spin tolerance of the returns (median): the same strokes return the ball with {less} to {more} of its \
             spin"
        );
    }
    let _ = writeln!(
        out,
        "median spin error {:.1}%, median hit error {:.1} mm; RSI: {} cycles, {} late answers ({} later than a \
         cycle under a stretched deadline); bat home at the end: {}",
        r.spin_err_pct_median,
        r.hit_err_mm_median,
        r.rsi_cycles,
        r.late_rsi_answers,
        r.answers_after_cycle,
        r.ended_home
    );
    let _ = writeln!(
        out,
        "latency µs (p50 / p99 / p99.9 / max): RSI answer {} / {} / {} / {}, observation → plan {} / {} / {} / {}",
        l.rsi_answer.p50,
        l.rsi_answer.p99,
        l.rsi_answer.p999,
        l.rsi_answer.max,
        l.obs_to_plan.p50,
        l.obs_to_plan.p99,
        l.obs_to_plan.p999,
        l.obs_to_plan.max
    );
    let _ = writeln!(
        out,
        "plans taken late: {} (worst {:.1} ms), refused: {}",
        r.plans_late, r.late_by_max_ms, r.plans_rejected
    );
    if let Some(c) = &r.logo {
        let _ = writeln!(
            out,
            "logo thread: {} crops, {} sequences, {} fitted; spins fused into the track {}, refused by the gate {}",
            c.crops, c.sequences, c.fitted, r.logo_spins_fused, r.logo_spins_gated
        );
    }
    if let Some(f) = &r.tracker_faults {
        let i = &r.ingest;
        let _ = writeln!(
            out,
            "tracker faults: {} clean, {} lost, {} silenced, {} duplicated, {} reordered, {} garbage, {} foreign, \
             {} teleported, {} re-clocked; ingest: {} accepted, {} foreign, {} malformed, {} duplicate, \
             {} out of order, {} restarts, {} clock jumps",
            f.clean,
            f.lost,
            f.silenced,
            f.duplicated,
            f.reordered,
            f.garbage,
            f.foreign,
            f.teleported,
            f.clock_jumped,
            i.accepted,
            i.foreign,
            i.malformed,
            i.duplicate,
            i.out_of_order,
            i.tracker_restarts,
            i.clock_jumps
        );
    }
    let rb = &r.robot;
    let _ = writeln!(
        out,
        "robot: dead time {:.0} ms, lag {:.0} ms, compensation {}, {} correction; axes peaked at {:.0} % of their \
         speed, {:.0} % of their acceleration ({} cycles over a limit); {} POSCORR clamps, {} AXISCORR clamps; \
         stopped: {}",
        rb.dead_time_ms,
        rb.lag_ms,
        if rb.compensation { "on" } else { "off" },
        rb.correction,
        rb.peak_speed_share * 100.0,
        rb.peak_acceleration_share * 100.0,
        rb.rates_over,
        r.poscorr_clamped,
        rb.axiscorr_clamped,
        rb.stop_reason.as_deref().unwrap_or("no"),
    );
    if !rb.skipped.is_empty() {
        let list: Vec<String> = rb.skipped.iter().map(|(k, n)| format!("{k} {n}")).collect();
        let _ = writeln!(out, "balls skipped by the planner: {}", list.join(", "));
    }
    for w in &r.warnings {
        let _ = writeln!(out, "warning: {w}");
    }
    out
}
