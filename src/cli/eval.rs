//! `topspin eval ...`: the accuracy tables on simulated flights (and, with
//! `real`, on the recorded launcher data). Markdown on stdout, or one JSON
//! object with `--json`. Seeded: the same command prints the same numbers.

use std::fmt::Write;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use super::BadInput;
use super::fit::{PhysicsChoice, load_calibration};
use topspin_core::stats::Summary;
use topspin_lab::eval::fit::{MethodRow, Window, accuracy, outlier_experiment};
use topspin_lab::eval::stream::{LeadRow, StreamSetup, TypeTiming, evaluate, evaluate_worlds};
use topspin_lab::eval::worlds;
use topspin_sim::TrackerModel;
use topspin_sim::simulate_set;

#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Batch spin fit on simulated launcher balls: paper vs refined.
    Fit(EvalFitArgs),
    /// Streaming estimator on balls back to back: plan error vs lead time.
    Stream(EvalStreamArgs),
    /// Batch fit in worlds whose physics is not the estimator's: default vs paper.
    Worlds(EvalWorldsArgs),
    /// Real launcher trajectories: bounce and look-ahead error with and without the fitted spin.
    Real(super::eval_real::EvalRealArgs),
    /// The paper's tables and figures (Tables III, IV, logo metrics, real data) into a folder.
    Paper(super::eval_paper::EvalPaperArgs),
}

/// Options shared by the simulated evaluations.
#[derive(Debug, Args)]
pub struct SimSetArgs {
    /// Number of simulated balls (cycling through the nine settings).
    #[arg(long, default_value_t = 225)]
    pub balls: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Physics of the simulation and the fit.
    #[arg(long, value_enum, default_value_t = PhysicsChoice::Calibrated)]
    pub physics: PhysicsChoice,
    /// Another calibration folder.
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// One JSON object instead of Markdown.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
pub struct EvalFitArgs {
    #[command(flatten)]
    pub set: SimSetArgs,
    /// Tracker noise levels, mm (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [1.0, 3.0])]
    pub noise_mm: Vec<f64>,
}

#[derive(Debug, Args)]
pub struct EvalWorldsArgs {
    /// Balls per world and noise level (cycling through the nine settings).
    #[arg(long, default_value_t = 90)]
    pub balls: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The estimator's calibration folder (the worlds are built on its cell).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// Tracker noise levels, mm (comma-separated).
    #[arg(long, value_delimiter = ',', default_values_t = [1.0, 3.0])]
    pub noise_mm: Vec<f64>,
    /// Fit with each world's own table (restitution, friction) instead of
    /// the calibration's: what the fits make of a flight once the table is
    /// known (the daemon learns it over a session; one flight before its
    /// bounce cannot show it)
    #[arg(long)]
    pub known_table: bool,
    /// One JSON object instead of Markdown.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  topspin eval stream --balls 180 --world other-table\n  \
    topspin eval stream --balls 180 --all-worlds --json   (every world as one session, learning on and off)\n  \
    topspin eval stream --balls 180 --all-worlds --launcher   (the same balls' axes perpendicular to the flight)")]
pub struct EvalStreamArgs {
    #[command(flatten)]
    pub set: SimSetArgs,
    #[arg(long, default_value_t = 2.0)]
    pub noise_mm: f64,
    /// Share of frames lost.
    #[arg(long, default_value_t = 0.05)]
    pub dropout: f64,
    /// The tracker's frame rate, Hz (the paper's tracker: 150).
    #[arg(long, default_value_t = 150.0)]
    pub rate_hz: f64,
    /// Fly the balls in a world of `topspin eval worlds` (linear-weak,
    /// linear-strong, saturating, crisis, heavy-air, other-table, and the
    /// lift measured on real balls: real-launcher, real-rally) instead of
    /// the calibration's own.
    #[arg(long, value_name = "NAME")]
    pub world: Option<String>,
    /// The estimator learns nothing across the session (drag, table, spin).
    #[arg(long)]
    pub no_learning: bool,
    /// The estimator learns the drag and the table, not the spin the
    /// table meets per unit of the spin a flight shows.
    #[arg(long)]
    pub no_spin_learning: bool,
    /// Every world (and the calibration's own) as one session of --balls
    /// balls, the EKF with the session learning on and off side by side:
    /// at the net, 0.25 s and 0.15 s before the hit.
    #[arg(long, conflicts_with_all = ["world", "no_learning"])]
    pub all_worlds: bool,
    /// A world's balls from a wheel launcher: spin axes perpendicular to
    /// the exit velocity (a world's own axes are skewed: sidespin about the
    /// vertical, the others tipped up to 20° towards the flight).
    #[arg(long)]
    pub launcher: bool,
    /// A world's balls all fly with its lift (by default each ball's own
    /// lift is the world's ×0.85–1.15).
    #[arg(long)]
    pub same_lift: bool,
    /// Where the balls come from: `launcher` (the nine settings), or real
    /// human strokes measured right after the racket: `human-rally`,
    /// `human-serve`, `human` (both).
    #[arg(long, default_value_t = topspin_sim::Strokes::Launcher, value_name = "SOURCE")]
    pub strokes: topspin_sim::Strokes,
    /// Judge the plans on the plane x = X (m) alone, after the ball's
    /// bounce, whether or not the arm reaches it (default: the hitting
    /// plane of calib/strike.toml, within the arm's reach).
    #[arg(long, value_name = "X")]
    pub hit_plane_x: Option<f64>,
}

pub fn run(cmd: EvalCommand) -> anyhow::Result<()> {
    match cmd {
        EvalCommand::Fit(a) => run_fit(a),
        EvalCommand::Stream(a) => run_stream(a),
        EvalCommand::Worlds(a) => run_worlds(a),
        EvalCommand::Real(a) => super::eval_real::run_real(a),
        EvalCommand::Paper(a) => super::eval_paper::run_paper(a),
    }
}

fn check_noise(mm: f64) -> Result<(), BadInput> {
    if mm.is_finite() && mm > 0.0 { Ok(()) } else { Err(BadInput(format!("noise {mm} mm must be positive"))) }
}

fn cell(s: &Summary) -> String {
    format!("{:.2}", s.median)
}

fn fit_table(rows: &[MethodRow]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "| noise | window | method | spin err % (median) | bounce err mm | hit err mm | hit Δt ms | failed |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|");
    for r in rows {
        let window = window_name(r.window);
        let _ = writeln!(
            out,
            "| {:.0} mm | {window} | {} | {} | {} | {} | {} | {} |",
            r.noise_mm,
            r.method,
            cell(&r.spin_err_pct),
            cell(&r.bounce_err_mm),
            cell(&r.hit_err_mm),
            cell(&r.hit_dt_ms),
            r.failures
        );
    }
    out
}

fn run_worlds(a: EvalWorldsArgs) -> anyhow::Result<()> {
    let cal = load_calibration(a.calib.as_deref(), PhysicsChoice::Calibrated)?;
    for &mm in &a.noise_mm {
        check_noise(mm)?;
    }
    let noise: Vec<f64> = a.noise_mm.iter().map(|mm| mm * 1e-3).collect();
    let reports = worlds::evaluate(&cal, a.seed, a.balls, &noise, a.known_table);
    if a.json {
        println!(
            "{}",
            serde_json::json!({"balls": a.balls, "seed": a.seed, "known_table": a.known_table, "worlds": reports})
        );
        return Ok(());
    }
    let table = if a.known_table { "each world's own table (e, μ)" } else { "the calibration's table" };
    println!(
        "Batch fit in worlds unlike the estimator's model, {} balls per world and noise (nine settings, each \
         ball its own drag and lift, skewed spin axes), seed {}, fitted with {table}. Medians, default \
         (refined) / paper:\n",
        a.balls, a.seed
    );
    println!("| world | noise | window | spin err % | bounce err mm | hit err mm | hit Δt ms | failed |");
    println!("|---|---|---|---|---|---|---|---|");
    for w in &reports {
        for pair in w.rows.chunks(2) {
            let [paper, ours] = pair else { continue };
            let both = |f: fn(&MethodRow) -> &Summary| format!("{} / {}", cell(f(ours)), cell(f(paper)));
            println!(
                "| {} | {:.0} mm | {} | {} | {} | {} | {} | {} / {} |",
                w.world,
                ours.noise_mm,
                window_name(ours.window),
                both(|r| &r.spin_err_pct),
                both(|r| &r.bounce_err_mm),
                both(|r| &r.hit_err_mm),
                both(|r| &r.hit_dt_ms),
                ours.failures,
                paper.failures
            );
        }
    }
    println!();
    for w in &reports {
        println!("- {}: {}", w.world, w.about);
    }
    Ok(())
}

fn window_name(w: Window) -> &'static str {
    match w {
        Window::PreBounce => "to bounce",
        Window::PreNet => "to net",
    }
}

fn run_fit(a: EvalFitArgs) -> anyhow::Result<()> {
    let cal = load_calibration(a.set.calib.as_deref(), a.set.physics)?;
    for &mm in &a.noise_mm {
        check_noise(mm)?;
    }
    let mut rows = Vec::new();
    for &mm in &a.noise_mm {
        let tracker = TrackerModel { noise_sigma: mm * 1e-3, ..TrackerModel::default() };
        let balls = simulate_set(&cal, a.set.seed, a.set.balls, &tracker);
        rows.extend(accuracy(&cal, &balls, mm * 1e-3));
    }
    let outliers = outlier_experiment(&cal, a.set.seed, a.set.balls, 0.002, 2);
    if a.set.json {
        println!(
            "{}",
            serde_json::json!({"balls": a.set.balls, "seed": a.set.seed, "rows": rows, "start_outliers": outliers})
        );
        return Ok(());
    }
    println!(
        "Batch spin fit, {} simulated launcher balls (nine settings), seed {}, medians:\n",
        a.set.balls, a.set.seed
    );
    print!("{}", fit_table(&rows));
    println!(
        "\nTwo false detections at the start (2 mm noise, refined fit, pre-bounce): named exactly in {:.1}% \
         of balls, all found in {:.1}%; spin error {:.2}% clean vs {:.2}% with them (ratio {:.2}).",
        outliers.named_exactly * 100.0,
        outliers.all_found * 100.0,
        outliers.spin_err_clean_pct,
        outliers.spin_err_dirty_pct,
        outliers.ratio
    );
    Ok(())
}

fn run_stream(a: EvalStreamArgs) -> anyhow::Result<()> {
    let cal = load_calibration(a.set.calib.as_deref(), a.set.physics)?;
    check_noise(a.noise_mm)?;
    if !(0.0..1.0).contains(&a.dropout) {
        return Err(BadInput(format!("--dropout {} must be in [0, 1)", a.dropout)).into());
    }
    if a.set.balls == 0 {
        return Err(BadInput("--balls 0: a stream needs at least one ball".to_owned()).into());
    }
    if !(30.0..=2000.0).contains(&a.rate_hz) {
        return Err(BadInput(format!("--rate-hz {} must be in [30, 2000]", a.rate_hz)).into());
    }
    if a.strokes == topspin_sim::Strokes::AimedLauncher {
        return Err(BadInput("--strokes aimed-launcher: the stream judges the launcher as it is set".into()).into());
    }
    if let Some(x) = a.hit_plane_x
        && !(x.is_finite() && x > 0.0)
    {
        return Err(BadInput(format!("--hit-plane-x {x} must be on the robot's side (x > 0)")).into());
    }
    let world = match &a.world {
        Some(name) => Some(
            topspin_sim::worlds::world_named(&cal, name)
                .ok_or_else(|| BadInput(format!("--world {name}: no such world (see topspin eval worlds)")))?
                .name,
        ),
        None => None,
    };
    let setup = StreamSetup {
        balls: a.set.balls,
        seed: a.set.seed,
        noise_mm: a.noise_mm,
        dropout: a.dropout,
        rate_hz: a.rate_hz,
        world,
        learn: !a.no_learning,
        learn_spin: !a.no_spin_learning,
        launcher: a.launcher,
        same_lift: a.same_lift,
        strokes: a.strokes,
        hit_plane_x: a.hit_plane_x,
        ..Default::default()
    };
    if a.all_worlds {
        return run_stream_worlds(&cal, &setup, a.set.json);
    }
    let report = evaluate(&cal, &setup);
    if a.set.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    let plane = match setup.hit_plane_x {
        Some(x) => format!(" on the plane x = {x:.2} m alone"),
        None => String::new(),
    };
    println!(
        "Streaming estimator, {} {} balls back to back ({} with the true hit inside the hitting window{plane}, \
         {} of them tracked), {} Hz, {} mm noise, {:.0}% dropouts, two false starts on every {}th ball; medians \
         (p90 in brackets):\n",
        report.balls,
        setup.strokes,
        report.reachable,
        report.tracked,
        setup.rate_hz,
        setup.noise_mm,
        setup.dropout * 100.0,
        setup.outliers_every
    );
    println!("| when | source | hit point err mm | hit time err ms | no plan |");
    println!("|---|---|---|---|---|");
    for r in report.at_net.iter().chain(&report.by_lead) {
        let when =
            if r.lead_s.is_nan() { "ball at the net".to_owned() } else { format!("{:.2} s before hit", r.lead_s) };
        println!(
            "| {when} | {} | {:.1} ({:.1}) | {:.2} ({:.2}) | {} |",
            r.source, r.hit_err_mm.median, r.hit_err_mm.p90, r.hit_dt_ms.median, r.hit_dt_ms.p90, r.missing
        );
    }
    println!(
        "\nThe EKF's signed hit-time error per ball type (plan − truth, ms: positive is late), median and \
         90th percentile, split by the plan made before or after the true bounce (median, number of balls), \
         the median time of the plan after the bounce, and for the plans made before it, the forward kick \
         the plan predicted the table to give (the ball's gain in v_x) less the true kick, median (p90 of \
         its size), m/s:\n"
    );
    println!("| lead | ball | all: median (p90) | before the bounce | after it | plan − bounce ms | kick err m/s |");
    println!("|---|---|---|---|---|---|---|");
    let signed = |s: &Summary| {
        if s.n == 0 { "–".to_owned() } else { format!("{:+.1} ({})", s.median, s.n) }
    };
    let kick = |r: &TypeTiming| {
        let (s, size) = (&r.kick_err_m_s, &r.kick_miss_m_s);
        if s.n == 0 { "–".to_owned() } else { format!("{:+.2} ({:.2})", s.median, size.p90) }
    };
    for r in &report.timing {
        println!(
            "| {:.2} s | {} | {:+.1} ({:+.1}) | {} | {} | {:+.0} | {} |",
            r.lead_s,
            r.setting,
            r.signed_dt_ms.median,
            r.signed_dt_ms.p90,
            signed(&r.before_bounce_ms),
            signed(&r.after_bounce_ms),
            r.plan_after_bounce_ms.median,
            kick(r)
        );
    }
    let l = &report.learned;
    println!(
        "\nWorld: {}{}. The EKF's session {}: drag × {:.3} of the calibration, table e {:.3}, μ {:.3} \
         (from {} bounces, {} unexplained, {} flown again), velocity σ left after a bounce {:.2}, {:.2}, {:.2} m/s (x, y, z), \
         spin the table meets per unit of the flight's × {:.2}, {:.2}, {:.2}, {:.2} at S {:?} (σ of its log \
         {:.2}, {:.2}, {:.2}, {:.2}).",
        setup.world.unwrap_or("the calibration's own"),
        if setup.world.is_some() && (setup.launcher || setup.same_lift) {
            format!(", {}", world_balls(&setup))
        } else {
            String::new()
        },
        if setup.learn { "learned" } else { "learned nothing (--no-learning)" },
        l.drag_scale,
        l.restitution,
        l.friction,
        l.bounces,
        l.unexplained,
        l.surprised,
        l.bounce_vel[0].sqrt(),
        l.bounce_vel[1].sqrt(),
        l.bounce_vel[2].sqrt(),
        l.spin_scale[0],
        l.spin_scale[1],
        l.spin_scale[2],
        l.spin_scale[3],
        topspin_core::estimator::SPIN_BIN_CENTRES,
        l.spin_share[0],
        l.spin_share[1],
        l.spin_share[2],
        l.spin_share[3]
    );
    Ok(())
}

/// How a world's balls are made (`--launcher`, `--same-lift`), for the
/// tables' headings.
fn world_balls(setup: &StreamSetup) -> String {
    let axes = if setup.launcher {
        "from a launcher: spin axes perpendicular to the flight"
    } else {
        "the worlds' skewed spin axes"
    };
    if setup.same_lift { format!("{axes}, every ball with its world's lift") } else { axes.to_owned() }
}

fn run_stream_worlds(cal: &topspin_core::calib::Calibration, setup: &StreamSetup, json: bool) -> anyhow::Result<()> {
    let report = evaluate_worlds(cal, setup);
    if json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "Streaming estimator, every world as one session of {} balls back to back ({}), observed through \
         the bounce, {} mm noise, {:.0}% dropouts; the EKF's latest plan, medians (p90 in brackets) over the \
         balls whose true hit lies inside the hitting window:\n",
        setup.balls,
        world_balls(setup),
        setup.noise_mm,
        setup.dropout * 100.0
    );
    println!(
        "| world | learning | at the net: hit mm / time ms | 0.25 s before | 0.15 s before | no plan (net) | \
         learned drag, e, μ (truth) |"
    );
    println!("|---|---|---|---|---|---|---|");
    let cell = |r: &LeadRow| {
        format!(
            "{:.1} ({:.1}) / {:.2} ({:.2})",
            r.hit_err_mm.median, r.hit_err_mm.p90, r.hit_dt_ms.median, r.hit_dt_ms.p90
        )
    };
    for w in &report {
        for (learning, rows) in [("on", &w.on), ("off", &w.off)] {
            let learned = if learning == "on" {
                let (l, t) = (&w.learned, &w.truth);
                format!(
                    "{:.3}, {:.3}, {:.3} ({:.3}, {:.3}, {:.3})",
                    l.drag_scale, l.restitution, l.friction, t.drag_scale, t.restitution, t.friction
                )
            } else {
                "–".to_owned()
            };
            println!(
                "| {} | {learning} | {} | {} | {} | {} | {learned} |",
                w.world,
                cell(&rows[0]),
                cell(&rows[1]),
                cell(&rows[2]),
                rows[0].missing
            );
        }
    }
    Ok(())
}
