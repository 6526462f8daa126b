//! `topspin calibrate cell`: where the robot's BASE stands in the table
//! frame, from touch points ([`topspin_core::calib::cell`]). The touches
//! come from a file (`--points`, TOML or CSV, the TCP in B in mm as the
//! pendant shows it) or are read over RSI (`--rsi`: the robot's `RIst`,
//! averaged over a few cycles, while [`topspin_daemon::touch`] answers
//! every request with a zero correction). Prints per-point residuals, the
//! full and the level fit and the `[cell]` lines; `--write DIR` replaces
//! those two lines of `DIR/robot.toml` (comments kept), after the result
//! loads and validates with the rest of `DIR`, atomically.
//!
//! Exit 2 with one line for unusable input (a file, a name, a degenerate
//! point set); exit 1 for a fit refused by its bounds, with the reason.

use std::fmt::Write as _;
use std::io::BufRead;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use topspin_daemon::calib_files::CalibDir;

use clap::{Args, Subcommand};

use super::bad;
use topspin_core::calib::Calibration;
use topspin_core::calib::cell::{
    self, Bounds, CellFit, DEFAULT_MAX_RMS_M, DEFAULT_MAX_SPREAD_MM, DEFAULT_MAX_TILT_DEG, DEFAULT_MAX_WORST_M, Touch,
    TouchFile,
};
use topspin_core::physics::Table;
use topspin_daemon::config::DaemonConfig;
use topspin_daemon::touch::TouchListener;

/// What to calibrate.
#[derive(Debug, Subcommand)]
pub enum CalibrateCommand {
    /// Find the table frame in the robot's BASE from touch points and
    /// write `calib/robot.toml`'s `[cell]`.
    ///
    /// Touch at least four table points (not all on one line) with the
    /// bat's centre (the TCP). Named points (`--list-points`): the surface
    /// corners, the centre line's ends, the net posts' tops; a point of
    /// your own is given by its table coordinates. Examples:
    ///
    /// `topspin calibrate cell --points touches.csv --write calib` (CSV
    /// header `name,x_mm,y_mm,z_mm`, optional `table_x_m,table_y_m,table_z_m`);
    ///
    /// `topspin calibrate cell --rsi --touch corner_robot_pos_y,corner_robot_neg_y,centre_robot_end,mark=1.07,0,0`
    /// (press Enter with the bat on each point; RSI answered with zero
    /// corrections on the configured `network.rsi_bind`).
    Cell(CellArgs),
}

/// `topspin calibrate cell`.
#[derive(Debug, Args)]
pub struct CellArgs {
    /// Touches from a file: TOML (`contact_offset_mm`, `[[point]]` with
    /// `name`, `tcp_mm`, optional `table_xyz_m`) or CSV (`.csv`).
    #[arg(long, value_name = "FILE", conflicts_with = "rsi")]
    pub points: Option<PathBuf>,
    /// Read each touch from the robot over RSI (`RIst`).
    #[arg(long)]
    pub rsi: bool,
    /// With `--rsi`: the points to touch, in order, comma-separated; a
    /// point of your own as NAME=X,Y,Z (table frame, m) in its own `--touch`.
    #[arg(long, value_name = "NAMES")]
    pub touch: Vec<String>,
    /// With `--rsi`: listen here (default: the configuration's `network.rsi_bind`).
    #[arg(long, value_name = "ADDR")]
    pub bind: Option<SocketAddr>,
    /// Daemon configuration (`network.rsi_bind`, `rsi.sentype`).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// With `--rsi`: cycles averaged per touch.
    #[arg(long, default_value_t = 25)]
    pub samples: usize,
    /// With `--rsi`: refuse a touch whose RIst strays further than this
    /// from its mean (the robot moved), mm.
    #[arg(long, default_value_t = DEFAULT_MAX_SPREAD_MM)]
    pub max_spread_mm: f64,
    /// The TCP's height above each point when it touches it, along the
    /// table's normal, mm (overrides the file's `contact_offset_mm`; 0
    /// when neither says).
    #[arg(long, value_name = "MM")]
    pub contact_offset_mm: Option<f64>,
    /// Table geometry and current `[cell]` from this folder (default:
    /// `--write`'s folder, else the compiled-in calibration).
    #[arg(long, value_name = "DIR")]
    pub calib: Option<PathBuf>,
    /// Replace the `[cell]` lines of DIR/robot.toml with the fit.
    #[arg(long, value_name = "DIR")]
    pub write: Option<PathBuf>,
    /// Refuse a fit whose RMS residual is over this, mm.
    #[arg(long, default_value_t = DEFAULT_MAX_RMS_M * 1e3)]
    pub max_rms_mm: f64,
    /// Refuse a fit whose worst residual is over this, mm.
    #[arg(long, default_value_t = DEFAULT_MAX_WORST_M * 1e3)]
    pub max_worst_mm: f64,
    /// Refuse a base tilted (roll and pitch) more than this from level, degrees.
    #[arg(long, default_value_t = DEFAULT_MAX_TILT_DEG)]
    pub max_tilt_deg: f64,
    /// One JSON object on stdout instead of the text report.
    #[arg(long)]
    pub json: bool,
    /// List the named table points and exit.
    #[arg(long)]
    pub list_points: bool,
}

/// Runs `topspin calibrate …`.
pub fn run(c: CalibrateCommand) -> anyhow::Result<()> {
    match c {
        CalibrateCommand::Cell(a) => cell_cmd(a),
    }
}

fn cell_cmd(a: CellArgs) -> anyhow::Result<()> {
    let calib_dir = a.calib.clone().or_else(|| a.write.clone());
    let calib = Calibration::load(calib_dir.as_deref()).map_err(|e| bad(e.to_string()))?;
    if a.list_points {
        return list_points(&calib.table, a.json);
    }
    for (name, v) in
        [("--max-rms-mm", a.max_rms_mm), ("--max-worst-mm", a.max_worst_mm), ("--max-tilt-deg", a.max_tilt_deg)]
    {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(format!("{name} {v}: must be a positive number")));
        }
    }
    let bounds =
        Bounds { max_rms_m: a.max_rms_mm * 1e-3, max_worst_m: a.max_worst_mm * 1e-3, max_tilt_deg: a.max_tilt_deg };
    let (touches, file_offset_mm) = match (&a.points, a.rsi) {
        (Some(path), _) => read_points(path, &calib.table)?,
        (None, true) => (touch_over_rsi(&a, &calib)?, None),
        (None, false) => return Err(bad("no touches: give --points FILE or --rsi (see --help)")),
    };
    let offset_mm = a.contact_offset_mm.or(file_offset_mm).unwrap_or(0.0);
    if !(offset_mm.is_finite() && offset_mm.abs() <= 100.0) {
        return Err(bad(format!("contact offset {offset_mm} mm: must be a number within ±100 mm")));
    }
    let prior = calib.robot.cell.base_yaw_in_table_deg;
    let fit = cell::fit_cell(&touches, offset_mm * 1e-3, prior).map_err(|e| bad(e.to_string()))?;
    let verdict = fit.check(&bounds);
    let mut written = None;
    let mut refusal = verdict.as_ref().err().map(ToString::to_string);
    if let (Some(dir), None) = (&a.write, &refusal) {
        match write_cell(dir, &fit) {
            Ok(path) => written = Some(path),
            Err(WriteError::Bad(e)) => return Err(e),
            Err(WriteError::Refused(why)) => refusal = Some(why),
        }
    }
    if a.json {
        let out = serde_json::json!({
            "ok": refusal.is_none(),
            "refusal": refusal,
            "cell": fit.cell,
            "cell_lines": fit.cell_lines(),
            "rms_mm": fit.rms_m * 1e3,
            "worst_mm": fit.worst_m * 1e3,
            "worst": fit.worst,
            "full": fit.full,
            "points": fit.residuals,
            "contact_offset_mm": offset_mm,
            "bounds": { "max_rms_mm": a.max_rms_mm, "max_worst_mm": a.max_worst_mm, "max_tilt_deg": a.max_tilt_deg },
            "previous_cell": calib.robot.cell,
            "written": written,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print!("{}", text(&fit, &calib, offset_mm, written.as_deref()));
    }
    match refusal {
        None => Ok(()),
        Some(why) => Err(anyhow::anyhow!("refused: {why}")),
    }
}

fn list_points(table: &Table, json: bool) -> anyhow::Result<()> {
    let pts = cell::named_points(table);
    if json {
        let m: serde_json::Map<_, _> = pts.iter().map(|(n, p)| (n.to_string(), serde_json::json!(p))).collect();
        println!("{}", serde_json::to_string_pretty(&m)?);
    } else {
        println!("named table points (table frame T, m; the TCP touches them from above, +z):");
        for (n, p) in pts {
            println!("  {n:<24} {:>8.4} {:>8.4} {:>8.4}", p[0], p[1], p[2]);
        }
    }
    Ok(())
}

fn text(fit: &CellFit, calib: &Calibration, offset_mm: f64, written: Option<&Path>) -> String {
    let mut s = String::new();
    let _ =
        writeln!(s, "cell calibration: {} points, contact offset {offset_mm:.1} mm along +z_T", fit.residuals.len());
    let _ = writeln!(
        s,
        "  {:<24} {:>28} {:>28} {:>10} {:>10}",
        "point", "table T (m)", "TCP in B (mm)", "level (mm)", "full (mm)"
    );
    for r in &fit.residuals {
        let t = format!("{:.4} {:.4} {:.4}", r.table_m[0], r.table_m[1], r.table_m[2]);
        let b = format!("{:.2} {:.2} {:.2}", r.tcp_b_m[0] * 1e3, r.tcp_b_m[1] * 1e3, r.tcp_b_m[2] * 1e3);
        let _ = writeln!(
            s,
            "  {:<24} {t:>28} {b:>28} {:>10.2} {:>10.2}",
            r.name,
            r.error_norm_m * 1e3,
            r.full_error_norm_m * 1e3
        );
    }
    let f = &fit.full;
    let p = f.base_in_table_xyz_m;
    let _ = writeln!(
        s,
        "full fit: base ({:.5}, {:.5}, {:.5}) m, yaw {:.4}°, pitch {:.4}°, roll {:.4}° (tilt {:.4}°), RMS {:.2} mm, worst {:.2} mm ({})",
        p[0],
        p[1],
        p[2],
        f.yaw_deg,
        f.pitch_deg,
        f.roll_deg,
        f.tilt_deg,
        f.rms_m * 1e3,
        f.worst_m * 1e3,
        f.worst
    );
    let (c, old) = (&fit.cell, &calib.robot.cell);
    let _ = writeln!(
        s,
        "level fit (the [cell] model): base ({:.5}, {:.5}, {:.5}) m, yaw {:.4}°, RMS {:.2} mm, worst {:.2} mm ({})",
        c.base_in_table_xyz_m[0],
        c.base_in_table_xyz_m[1],
        c.base_in_table_xyz_m[2],
        c.base_yaw_in_table_deg,
        fit.rms_m * 1e3,
        fit.worst_m * 1e3,
        fit.worst
    );
    let d: Vec<String> =
        (0..3).map(|i| format!("{:+.1}", (c.base_in_table_xyz_m[i] - old.base_in_table_xyz_m[i]) * 1e3)).collect();
    let _ = writeln!(
        s,
        "change from the current [cell]: ({}) mm, yaw {:+.4}°",
        d.join(", "),
        c.base_yaw_in_table_deg - old.base_yaw_in_table_deg
    );
    let _ = writeln!(s, "[cell]\n{}", fit.cell_lines().trim_end());
    if let Some(w) = written {
        let _ = writeln!(s, "written: {}", w.display());
    }
    s
}

/// Touches from a TOML or CSV file, and the file's contact offset (mm).
fn read_points(path: &Path, table: &Table) -> anyhow::Result<(Vec<Touch>, Option<f64>)> {
    let text = std::fs::read_to_string(path).map_err(|e| bad(format!("{}: {e}", path.display())))?;
    let at = |e: String| bad(format!("{}: {e}", path.display()));
    let is_csv = path.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv"));
    let entries: Vec<(String, [f64; 3], Option<[f64; 3]>)>;
    let mut offset = None;
    if is_csv {
        let mut r = csv::ReaderBuilder::new().trim(csv::Trim::All).comment(Some(b'#')).from_reader(text.as_bytes());
        let head = r.headers().map_err(|e| at(e.to_string()))?.clone();
        let col = |n: &str| head.iter().position(|h| h == n);
        let (Some(name), Some(x), Some(y), Some(z)) = (col("name"), col("x_mm"), col("y_mm"), col("z_mm")) else {
            return Err(at("the header must name the columns name,x_mm,y_mm,z_mm".to_owned()));
        };
        let own = [col("table_x_m"), col("table_y_m"), col("table_z_m")];
        let mut v = Vec::new();
        for (i, rec) in r.records().enumerate() {
            let rec = rec.map_err(|e| at(e.to_string()))?;
            let row = i + 2;
            let num = |c: usize, what: &str| -> anyhow::Result<f64> {
                let s = rec.get(c).unwrap_or("");
                s.parse::<f64>().map_err(|_| at(format!("line {row}: {what} {s:?} is not a number")))
            };
            let tcp = [num(x, "x_mm")?, num(y, "y_mm")?, num(z, "z_mm")?];
            let table_xyz = match own {
                [Some(a), Some(b), Some(c)] if !rec.get(a).unwrap_or("").is_empty() => {
                    Some([num(a, "table_x_m")?, num(b, "table_y_m")?, num(c, "table_z_m")?])
                }
                _ => None,
            };
            v.push((rec.get(name).unwrap_or("").to_owned(), tcp, table_xyz));
        }
        entries = v;
    } else {
        let f: TouchFile = toml::from_str(&text).map_err(|e| at(e.message().to_owned()))?;
        offset = f.contact_offset_mm;
        entries = f.point.into_iter().map(|p| (p.name, p.tcp_mm, p.table_xyz_m)).collect();
    }
    let mut touches = Vec::with_capacity(entries.len());
    for (name, tcp_mm, own) in entries {
        if name.is_empty() {
            return Err(at("a point without a name".to_owned()));
        }
        let table_m = cell::resolve_point(table, &name, own).map_err(at)?;
        touches.push(Touch { name, table_m, tcp_b_m: tcp_mm.map(|x| x * 1e-3) });
    }
    Ok((touches, offset))
}

/// `--touch` lists: names and own points (NAME=X,Y,Z).
fn touch_list(args: &[String], table: &Table) -> anyhow::Result<Vec<(String, [f64; 3])>> {
    let mut out = Vec::new();
    for a in args {
        if let Some((name, xyz)) = a.split_once('=') {
            let v: Vec<f64> = xyz
                .split(',')
                .map(|s| s.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| bad(format!("--touch {a}: NAME=X,Y,Z with three numbers (table frame, m)")))?;
            let [x, y, z] = v[..] else {
                return Err(bad(format!("--touch {a}: NAME=X,Y,Z with three numbers (table frame, m)")));
            };
            out.push((name.trim().to_owned(), [x, y, z]));
        } else {
            for n in a.split(',').map(str::trim).filter(|n| !n.is_empty()) {
                out.push((
                    n.to_owned(),
                    cell::resolve_point(table, n, None).map_err(|e| bad(format!("--touch: {e}")))?,
                ));
            }
        }
    }
    if out.len() < cell::MIN_POINTS {
        return Err(bad(format!(
            "--touch names {} points: at least {} are needed (--list-points shows the table's)",
            out.len(),
            cell::MIN_POINTS
        )));
    }
    Ok(out)
}

/// Reads each `--touch` point over RSI: Enter with the bat on the point.
fn touch_over_rsi(a: &CellArgs, calib: &Calibration) -> anyhow::Result<Vec<Touch>> {
    let points = touch_list(&a.touch, &calib.table)?;
    if a.samples == 0 || a.samples > 2500 {
        return Err(bad(format!("--samples {}: must be 1 to 2500", a.samples)));
    }
    if !(a.max_spread_mm.is_finite() && a.max_spread_mm > 0.0) {
        return Err(bad(format!("--max-spread-mm {}: must be a positive number", a.max_spread_mm)));
    }
    let cfg = DaemonConfig::load(a.config.as_deref()).map_err(|e| bad(e.to_string()))?;
    let bind = a.bind.unwrap_or(cfg.network.rsi_bind);
    let mut listener = TouchListener::bind(bind, &cfg.rsi.sentype).map_err(|e| bad(format!("RSI port {bind}: {e}")))?;
    eprintln!(
        "listening for RSI on {} (SENTYPE {}), answering zero corrections; T1, reduced speed.",
        listener.local_addr(),
        cfg.rsi.sentype
    );
    let timeout = std::time::Duration::from_secs(5);
    let stdin = std::io::stdin();
    let mut lines = stdin.lock().lines();
    let mut touches = Vec::new();
    for (name, p) in points {
        loop {
            eprintln!(
                "touch {name} (table {:.4}, {:.4}, {:.4} m) with the bat, then Enter (s Enter: skip):",
                p[0], p[1], p[2]
            );
            let Some(line) = lines.next() else {
                eprintln!("input ended: fitting the {} points read", touches.len());
                return Ok(touches);
            };
            let line = line.map_err(|e| bad(format!("stdin: {e}")))?;
            if line.trim() == "s" {
                break;
            }
            let requests = match listener.take_requests(a.samples, timeout) {
                Ok(s) => s,
                Err(e) => {
                    eprintln!("{name}: {e}; try again");
                    continue;
                }
            };
            // The touches are RIst: in the KRL program's TOOL and BASE,
            // which must be the calibration's (checked where AIPos comes).
            if let Some((p, Some(q))) = requests.first() {
                let r = &calib.robot;
                let arm = r.arm();
                if let Ok((pose, joints)) = topspin_core::rsi::read_start(&arm, Some(*p), Some(*q), None)
                    && let Some(m) = topspin_core::rsi::check_frames(
                        &arm,
                        &pose,
                        &joints,
                        r.start.frames_tolerance_mm,
                        r.start.frames_tolerance_deg,
                    )
                {
                    return Err(bad(format!("refused at the first request: {m}")));
                }
            }
            let samples: Vec<[f64; 3]> = requests.iter().map(|(p, _)| [p.x, p.y, p.z]).collect();
            match cell::average_still(&samples, a.max_spread_mm) {
                Ok(m) => {
                    eprintln!("{name}: TCP at ({:.2}, {:.2}, {:.2}) mm in B", m[0], m[1], m[2]);
                    touches.push(Touch { name: name.clone(), table_m: p, tcp_b_m: m.map(|x| x * 1e-3) });
                    break;
                }
                Err(e) => eprintln!("{name}: {e}; hold still and press Enter again"),
            }
        }
    }
    Ok(touches)
}

enum WriteError {
    Bad(anyhow::Error),
    Refused(String),
}

/// Replaces the `[cell]` lines of `dir/robot.toml`, after the new text
/// loads and validates with the rest of `dir`; atomically (a temporary
/// file in `dir`, synced, renamed over the old one).
fn write_cell(dir: &Path, fit: &CellFit) -> Result<PathBuf, WriteError> {
    let path = dir.join("robot.toml");
    let old = std::fs::read_to_string(&path).map_err(|e| WriteError::Bad(bad(format!("{}: {e}", path.display()))))?;
    let new = cell::replace_cell_lines(&old, &fit.cell)
        .map_err(|e| WriteError::Bad(bad(format!("{}: {e}", path.display()))))?;
    let loaded = topspin_daemon::calib_files::load_with_robot(Some(dir), &new)
        .map_err(|e| WriteError::Refused(format!("the new robot.toml does not validate, not written: {e}")))?;
    if cell::cell_lines(&loaded.robot.cell) != fit.cell_lines() {
        return Err(WriteError::Refused(format!("{}: the edited [cell] does not read back", path.display())));
    }
    let tmp = dir.join(format!(".robot.toml.calibrate-{}", std::process::id()));
    let write = || -> std::io::Result<()> {
        use std::io::Write;
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(new.as_bytes())?;
        f.sync_all()?;
        if let Ok(meta) = std::fs::metadata(&path) {
            std::fs::set_permissions(&tmp, meta.permissions())?;
        }
        std::fs::rename(&tmp, &path)
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        WriteError::Refused(format!("{}: {e}", path.display()))
    })?;
    Ok(path)
}
