//! The whole paper run as one value: Markdown (`tables.md`) and JSON
//! (`results.json`). Each table says how it was made.

use std::fmt::Write;

use serde::Serialize;

use super::PaperConfig;
use super::bounce::{BounceTable, PREDICTORS as BOUNCE_PREDICTORS};
use super::classify::{MethodClasses, paper_column};
use super::flights::{Flight, SpinMethod};
use super::logo_metrics::LogoRow;
use super::real::{HORIZONS, RealTable};
use topspin_core::stats::Summary;
use topspin_sim::Setting;

/// A latency histogram: (upper bucket edge µs, count) pairs, and its
/// percentiles.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Histogram {
    /// The path measured (e.g. `RSI answer`).
    pub name: String,
    /// (upper bucket edge in µs, count) per recorded bucket.
    pub buckets: Vec<(u64, u64)>,
    /// Median, µs.
    pub p50: u64,
    /// 99th percentile, µs.
    pub p99: u64,
    /// 99.9th percentile, µs.
    pub p999: u64,
    /// Largest value, µs.
    pub max: u64,
    /// Values recorded.
    pub n: u64,
}

/// A short `topspin bench latency` run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct LatencyRun {
    /// Length of the run asked for, s.
    pub seconds: f64,
    /// RSI cycles the mock KR C4 ran.
    pub rsi_cycles: u64,
    /// Cycles without a valid answer by the deadline.
    pub late_answers: u64,
    /// One histogram per path (RSI answer, observation → plan).
    pub histograms: Vec<Histogram>,
}

/// Everything one `topspin eval paper` run produced.
#[derive(Clone, Debug, Serialize)]
pub struct PaperReport {
    /// The command line that reproduces the run.
    pub command: String,
    /// The run's settings.
    pub config: PaperConfig,
    /// Physics constants of the simulation and the fits.
    pub physics: String,
    /// Table III.
    pub bounce: BounceTable,
    /// Table IV, one entry per method.
    pub classes: Vec<MethodClasses>,
    /// The logo metrics.
    pub logo: Vec<LogoRow>,
    /// Balls tried per setting to find the filmed flights.
    pub tried: [usize; 9],
    /// The filmed flights.
    pub flights: Vec<Flight>,
    /// The CNN's name, where one ran.
    pub cnn: Option<String>,
    /// The fusion's name, where one ran.
    pub fusion: Option<String>,
    /// The real-data table, where the recordings were found.
    pub real: Option<RealTable>,
    /// Why there is no real-data table, where there is none.
    pub real_note: Option<String>,
    /// The latency bench, where one ran.
    pub latency: Option<LatencyRun>,
    /// File names of the figures written.
    pub figures: Vec<String>,
    /// Wall time of each stage, s.
    pub stage_seconds: Vec<(String, f64)>,
    /// Wall time of the whole run, s.
    pub wall_seconds: f64,
    /// The machine: cores, worker threads, load average at the start and at the
    /// end.
    pub machine: String,
}

fn pct(x: f64) -> String {
    if x.is_finite() { format!("{:.1} %", x * 100.0) } else { "–".into() }
}

fn num(x: f64, digits: usize) -> String {
    if x.is_finite() { format!("{x:.digits$}") } else { "–".into() }
}

fn mean_std(s: &Summary) -> String {
    if s.n == 0 { "–".into() } else { format!("{:.1} ± {:.1}", s.mean, s.std) }
}

/// Table III as Markdown.
pub(crate) fn bounce_markdown(t: &BounceTable, cfg: &PaperConfig) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "### Bounce prediction (paper Table III)\n\n{} simulated balls per launcher setting (seed {}), tracker {} Hz \
         with {} mm noise per axis; each predicted from its observations **before the net** and compared with the \
         true first bounce (xy distance), mm, mean ± std (median). *Kalman, no spin*: the paper's comparison, an EKF on \
         position and velocity with the spin pinned at 0; *refined, spin 0*: our flight-model fit without spin. \
         The paper: 10 real balls per setting, its prediction window not stated.\n",
        cfg.bounce_balls, cfg.seed, cfg.tracker_hz, cfg.noise_mm
    );
    let _ = writeln!(
        o,
        "| setting | n | paper: with spin | paper: without | {} | {} | **{}** | {} |",
        BOUNCE_PREDICTORS[2], BOUNCE_PREDICTORS[0], BOUNCE_PREDICTORS[1], BOUNCE_PREDICTORS[3]
    );
    let _ = writeln!(o, "|---|---|---|---|---|---|---|---|");
    let cell = |s: &Summary| format!("{} ({})", mean_std(s), num(s.median, 1));
    for r in &t.rows {
        let _ = writeln!(
            o,
            "| {} | {} | {:.1} ± {:.1} | {:.1} ± {:.1} | {} | {} | **{}** | {} |",
            r.setting,
            r.ours[1].n,
            r.paper[0],
            r.paper[1],
            r.paper[2],
            r.paper[3],
            cell(&r.ours[2]),
            cell(&r.ours[0]),
            cell(&r.ours[1]),
            cell(&r.ours[3])
        );
    }
    let pm = |c: usize| t.rows.iter().map(|r| r.paper[c]).sum::<f64>() / t.rows.len().max(1) as f64;
    let _ = writeln!(
        o,
        "| all | {} | {:.1} | {:.1} | {} | {} | **{}** | {} |",
        t.all[1].n,
        pm(0),
        pm(2),
        cell(&t.all[2]),
        cell(&t.all[0]),
        cell(&t.all[1]),
        cell(&t.all[3])
    );
    o
}

/// Table IV as Markdown.
pub(crate) fn classes_markdown(
    classes: &[MethodClasses],
    flights: &[Flight],
    tried: &[usize; 9],
    cfg: &PaperConfig,
) -> String {
    let mut o = String::new();
    let filmed: [usize; 9] = std::array::from_fn(|i| flights.iter().filter(|f| f.setting == Setting::ALL[i]).count());
    let _ = writeln!(
        o,
        "### Spin-type classification (paper Table IV)\n\n{} filmed flights per setting (the first balls of seed {} \
         that fly through the ceiling camera's 1920 × 400 strip for ≥ 10 frames; {} of {} balls tried were filmed; orange \
         and white alternating), {} crops each at 380 Hz; trajectory methods on the same flights' tracker \
         observations before the net ({} Hz, {} mm). Per method: the median spin of each setting is its cluster \
         centre, each flight goes to the nearest centre; accuracy = share of a setting's flights assigned to it. A \
         flight without a spin (logo seen too rarely, fit failed) counts as wrong. Ours / paper.\n",
        cfg.flights,
        cfg.seed,
        filmed.iter().sum::<usize>(),
        tried.iter().sum::<usize>(),
        cfg.frames,
        cfg.tracker_hz,
        cfg.noise_mm
    );
    let _ = write!(o, "| setting |");
    for c in classes {
        let _ = write!(o, " {} |", c.label);
    }
    let _ = writeln!(o);
    let _ = writeln!(o, "|---|{}", "---|".repeat(classes.len()));
    let cell = |c: &MethodClasses, i: Option<usize>| -> String {
        if !c.available {
            return "— (no model)".into();
        }
        let ours = match i {
            Some(i) => c.accuracy[i],
            None => c.total,
        };
        let bold = matches!(c.method, SpinMethod::TrajectoryRefined);
        let ours = if bold { format!("**{}**", pct(ours)) } else { pct(ours) };
        match paper_column(c.method) {
            Some(p) => format!("{ours} / {:.1} %", p[i.unwrap_or(9)]),
            None => ours,
        }
    };
    for (i, s) in Setting::ALL.iter().enumerate() {
        let _ = write!(o, "| {s} |");
        for c in classes {
            let _ = write!(o, " {} |", cell(c, Some(i)));
        }
        let _ = writeln!(o);
    }
    let _ = write!(o, "| **in total** |");
    for c in classes {
        let _ = write!(o, " {} |", cell(c, None));
    }
    let _ = writeln!(o);
    let _ = write!(o, "| flights without a spin |");
    for c in classes {
        let _ = write!(o, " {} |", if c.available { c.no_spin.iter().sum::<usize>().to_string() } else { "–".into() });
    }
    let _ = writeln!(o);
    let _ = write!(o, "| median spin error % |");
    for c in classes {
        let _ = write!(o, " {} |", if c.available { num(c.spin_err_pct, 1) } else { "–".into() });
    }
    let _ = writeln!(o);
    o
}

/// The logo metrics as Markdown.
pub(crate) fn logo_markdown(rows: &[LogoRow], machine: &str) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "### Logo metrics (paper §III, §V)\n\nOn every crop of the filmed flights above (rendered, so the truth is \
         known). Classification: logo found/visible ⇔ its centre on the visible hemisphere. Vector angle: found vs \
         true logo centre, on frames where a logo was found and some of it is visible, degrees, mean (median). \
         Geodesic: pose error, networks only (the background method gives no rotation about the logo's axis). Time \
         per crop: mean wall time of the calling thread (background method: reference + detection; {machine}). \
         Ours / paper.\n"
    );
    let _ = writeln!(o, "| method | crops | classification acc. | geodesic ° | vector angle ° | ms per crop |");
    let _ = writeln!(o, "|---|---|---|---|---|---|");
    for r in rows {
        if !r.available {
            let p = r.paper.unwrap_or([f64::NAN; 4]);
            let _ = writeln!(
                o,
                "| {} | — (no model) | — / {} | — / {} | — / {} | — / {} |",
                r.label,
                num(p[0], 2),
                num(p[1], 2),
                num(p[2], 2),
                num(p[3], 1)
            );
            continue;
        }
        let with_paper = |ours: String, k: usize, d: usize| match r.paper {
            Some(p) if p[k].is_finite() => format!("{ours} / {}", num(p[k], d)),
            _ => ours,
        };
        let va = format!("{} ({})", num(r.vector_angle.mean, 2), num(r.vector_angle.median, 2));
        let geo = if r.geodesic.n == 0 { "n/a".into() } else { num(r.geodesic.mean, 2) };
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {} |",
            r.label,
            r.frames,
            with_paper(num(r.classification, 3), 0, 2),
            with_paper(geo, 1, 2),
            with_paper(va, 2, 2),
            with_paper(num(r.ms_per_crop, 3), 3, 1)
        );
    }
    o
}

/// The real-data table as Markdown.
pub(crate) fn real_markdown(t: &RealTable) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "### Real launcher balls (MPI recordings)\n\n{} recorded trajectories (`../shared/data/mpi-launcher`, \
         ~179 Hz), physics `{}`; each predicted from its samples before the net; bounce: xy distance to the detected \
         contact; ahead: 3D distance to the recording {} s / {} s after the last sample used (14 of 15 topspin files \
         end before 0.3 s). Median (mean ± std) mm, count in brackets.\n",
        t.trajectories, t.physics, HORIZONS[0], HORIZONS[1]
    );
    let _ = writeln!(o, "| set | predictor | spin | bounce | {} s ahead | {} s ahead |", HORIZONS[0], HORIZONS[1]);
    let _ = writeln!(o, "|---|---|---|---|---|---|");
    let cell = |s: &[f64; 4]| {
        if s[0] == 0.0 {
            "–".to_owned()
        } else {
            format!("{} ({} ± {}) [{}]", num(s[1], 1), num(s[2], 1), num(s[3], 1), s[0] as usize)
        }
    };
    for set in &t.sets {
        for c in &set.cells {
            let strong = c.predictor == "refined fit";
            let b = if strong { format!("**{}**", cell(&c.bounce)) } else { cell(&c.bounce) };
            let _ = writeln!(
                o,
                "| {} | {} | {} | {} | {} | {} |",
                set.set,
                c.predictor,
                if c.with_spin { "fitted" } else { "0" },
                b,
                cell(&c.ahead[0]),
                cell(&c.ahead[1])
            );
        }
    }
    o
}

/// The latency run as Markdown.
pub(crate) fn latency_markdown(l: &LatencyRun) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "### Latency (`topspin bench latency`, {:.0} s)\n\nDaemon threads, mock KR C4 (4 ms) and simulated tracker on \
         loopback, no real-time priority, while nothing else of this run computes; µs. Late RSI answers: {} of {}.\n",
        l.seconds, l.late_answers, l.rsi_cycles
    );
    let _ = writeln!(o, "| path | n | p50 | p99 | p99.9 | max |");
    let _ = writeln!(o, "|---|---|---|---|---|---|");
    for h in &l.histograms {
        let _ = writeln!(o, "| {} | {} | {} | {} | {} | {} |", h.name, h.n, h.p50, h.p99, h.p999, h.max);
    }
    o
}

/// All of it as one Markdown document.
pub fn markdown(r: &PaperReport) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "# The paper's tables, reproduced\n\n`{}` — seed {}, physics {}; wall time {:.0} s on {}.\n",
        r.command, r.config.seed, r.physics, r.wall_seconds, r.machine
    );
    o += &bounce_markdown(&r.bounce, &r.config);
    o += "\n";
    o += &classes_markdown(&r.classes, &r.flights, &r.tried, &r.config);
    if let Some(n) = &r.cnn {
        let _ = writeln!(o, "\nCNN: `{n}`.");
    }
    if let Some(n) = &r.fusion {
        let _ = writeln!(o, "\nFusion: `{n}`.");
    }
    o += "\n";
    o += &logo_markdown(&r.logo, &r.machine);
    o += "\n";
    match (&r.real, &r.real_note) {
        (Some(t), _) => o += &real_markdown(t),
        (None, Some(n)) => {
            let _ = writeln!(o, "### Real launcher balls\n\n{n}");
        }
        (None, None) => {}
    }
    if let Some(l) = &r.latency {
        o += "\n";
        o += &latency_markdown(l);
    }
    if !r.figures.is_empty() {
        let _ = writeln!(o, "\n### Figures\n");
        for f in &r.figures {
            let _ = writeln!(o, "- [{f}]({f})");
        }
    }
    let _ = writeln!(o, "\n### Stages\n");
    for (name, s) in &r.stage_seconds {
        let _ = writeln!(o, "- {name}: {s:.1} s");
    }
    o
}
