//! Cell calibration (`topspin calibrate cell`): where the robot's BASE B
//! stands in the table frame T, from touch points. The bat (the TCP) is
//! placed on known table points and the robot's TCP position in B is read
//! (from `RIst` or the pendant); a least-squares rigid transform T←B maps
//! the touches onto the points.
//!
//! # Points and the contact offset
//!
//! [`named_points`] are the table's own marks, from `calib/table.toml`:
//! the four surface corners, the centre line's two ends and the net posts'
//! tops (a post's centre at y = ±`net_length`/2, its top at `net_height`).
//! Every point lies on a face whose normal is +z_T, and the TCP touching a
//! point sits at the point plus `contact_offset_m` along +z_T: zero where a
//! pointed tip is the TCP, half the bat's thickness where the bat's centre
//! is the TCP and its face lies on the point. A point of one's own (a mark
//! measured from the corner) is given by its T coordinates, on a face
//! facing +z_T too.
//!
//! # The fit
//!
//! [`fit_cell`] refuses degenerate sets ([`Degenerate`]: fewer than
//! [`MIN_POINTS`], a name twice, two points or two touches closer than
//! [`MIN_SEPARATION_M`], table points within [`MIN_OFF_LINE_M`] of one
//! line), then fits twice:
//! - the full rigid transform (Kabsch: SVD of the cross-covariance, the
//!   sign of the smallest singular direction chosen so the rotation is
//!   proper, det = +1), reported as roll, pitch, yaw (KUKA's Z-Y-X) and its
//!   tilt, the angle between the base's z and z_T;
//! - the model `calib/robot.toml` holds (`[cell]`: a position and a yaw
//!   about z_T, the base level), in closed form: the yaw that best turns
//!   the centred touches' x-y onto the points', then the translation
//!   between the centroids.
//!
//! [`CellFit::check`] holds the fit to [`Bounds`] and refuses
//! ([`Refusal`]) a base tilted beyond `max_tilt_deg` where the full fit
//! explains the touches (the yaw-only `[cell]` cannot hold a tilt: a point
//! 1 m from the base is off by 17 mm per degree; the fix is to level the
//! pedestal, not to hide it in a residual; refused rather than warned
//! about, since every plan would carry that error), and an RMS or worst
//! residual over the bound, naming the worst point of the level fit (a
//! point touched too high would be half hidden in a tilt by the full fit,
//! which then blames another).
//!
//! [`average_still`] turns a few cycles of `RIst` into one touch, refusing
//! a robot that moved meanwhile; [`replace_cell_lines`] edits the two
//! `[cell]` lines of a `robot.toml` text, keeping everything else.
//!
//! Sans-IO: no file, socket or clock here (the command line and
//! `topspin_daemon::touch` do those).

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::robot::CellPlacement;
use crate::geometry::wrap_deg_near;
use crate::physics::{Table, Vec3};

/// The fewest touches a fit accepts (three fix a rigid transform; the
/// fourth makes the residual say something).
pub const MIN_POINTS: usize = 4;
/// Two table points, or two touches, closer than this are one point, m.
pub const MIN_SEPARATION_M: f64 = 0.05;
/// The table points must not all lie within this distance of one line, m
/// (the rotation about that line would be unknown).
pub const MIN_OFF_LINE_M: f64 = 0.05;
/// Default bound on the RMS residual, m.
pub const DEFAULT_MAX_RMS_M: f64 = 0.003;
/// Default bound on the worst residual, m.
pub const DEFAULT_MAX_WORST_M: f64 = 0.006;
/// Default bound on the base's tilt (roll and pitch together), degrees.
pub const DEFAULT_MAX_TILT_DEG: f64 = 0.5;
/// Default bound on how far `RIst` may stray from its mean while a touch
/// is averaged, mm.
pub const DEFAULT_MAX_SPREAD_MM: f64 = 0.2;

/// The table's named points in T (m), from its geometry: corners, centre
/// line ends, net posts' tops. `pos_y`/`neg_y`: the side of y_T (y = z × x,
/// x_T towards the robot).
pub fn named_points(table: &Table) -> [(&'static str, [f64; 3]); 8] {
    let (x, y) = (table.robot_end_x(), table.width / 2.0);
    let (post, h) = (table.net_length / 2.0, table.net_height);
    [
        ("corner_robot_pos_y", [x, y, 0.0]),
        ("corner_robot_neg_y", [x, -y, 0.0]),
        ("corner_opponent_pos_y", [-x, y, 0.0]),
        ("corner_opponent_neg_y", [-x, -y, 0.0]),
        ("centre_robot_end", [x, 0.0, 0.0]),
        ("centre_opponent_end", [-x, 0.0, 0.0]),
        ("net_post_pos_y", [0.0, post, h]),
        ("net_post_neg_y", [0.0, -post, h]),
    ]
}

/// The named point `name` in T, m.
pub fn named_point(table: &Table, name: &str) -> Option<[f64; 3]> {
    named_points(table).into_iter().find(|(n, _)| *n == name).map(|(_, p)| p)
}

/// One touch: a table point and where the TCP was in B when it touched it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Touch {
    /// The point's name (a [`named_points`] name or one's own).
    pub name: String,
    /// The point in T, m (on a face facing +z_T).
    pub table_m: [f64; 3],
    /// The TCP in B, m.
    pub tcp_b_m: [f64; 3],
}

/// A touch set that no fit can use.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Degenerate {
    /// Fewer touches than [`MIN_POINTS`].
    #[error("{n} points: at least {MIN_POINTS} are needed, not all on one line")]
    TooFew {
        /// How many there are.
        n: usize,
    },
    /// A coordinate or the contact offset is not a finite number.
    #[error("point {name}: not a finite number")]
    NotFinite {
        /// The point (or `contact offset`).
        name: String,
    },
    /// One name twice.
    #[error("point {name} is given twice")]
    SameName {
        /// The name.
        name: String,
    },
    /// Two table points closer than [`MIN_SEPARATION_M`].
    #[error("points {a} and {b} are the same table point ({:.1} mm apart)", distance_m * 1e3)]
    SamePoint {
        /// The first point.
        a: String,
        /// The second point.
        b: String,
        /// Their distance in T, m.
        distance_m: f64,
    },
    /// Two touches at the same TCP position.
    #[error("points {a} and {b} were touched at the same robot position ({:.1} mm apart)", distance_m * 1e3)]
    SameTouch {
        /// The first point.
        a: String,
        /// The second point.
        b: String,
        /// Their distance in B, m.
        distance_m: f64,
    },
    /// All table points within [`MIN_OFF_LINE_M`] of one line.
    #[error(
        "points {names} lie on one line (the farthest is {:.1} mm off it, at least {:.0} mm needed): add a point off that line",
        off_line_m * 1e3, MIN_OFF_LINE_M * 1e3
    )]
    Collinear {
        /// The points, comma-separated.
        names: String,
        /// The largest distance of a point from the best line, m.
        off_line_m: f64,
    },
}

/// Limits a fit must hold to be written.
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// RMS residual, m.
    pub max_rms_m: f64,
    /// Worst single residual, m.
    pub max_worst_m: f64,
    /// The base's tilt from level, degrees.
    pub max_tilt_deg: f64,
}

impl Default for Bounds {
    fn default() -> Self {
        Bounds { max_rms_m: DEFAULT_MAX_RMS_M, max_worst_m: DEFAULT_MAX_WORST_M, max_tilt_deg: DEFAULT_MAX_TILT_DEG }
    }
}

/// A fit outside its [`Bounds`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// The touches fit the table only with the base tilted: the yaw-only
    /// `[cell]` cannot hold it.
    #[error(
        "the base is tilted {tilt_deg:.2}° (roll {roll_deg:.2}°, pitch {pitch_deg:.2}°) > {bound_deg:.2}°: level the robot's pedestal (calib/robot.toml [cell] holds a yaw only)"
    )]
    NotLevel {
        /// The angle between the base's z and z_T, degrees.
        tilt_deg: f64,
        /// Roll of the full fit, degrees.
        roll_deg: f64,
        /// Pitch of the full fit, degrees.
        pitch_deg: f64,
        /// The bound, degrees.
        bound_deg: f64,
    },
    /// RMS or worst residual over the bound: a point touched wrongly.
    #[error(
        "the touches do not fit the table: {which} residual {:.2} mm > {:.2} mm ({fit} fit), worst point {worst} ({:.2} mm): touch it again",
        value_m * 1e3, bound_m * 1e3, worst_m * 1e3
    )]
    Residual {
        /// `RMS` or `worst`.
        which: &'static str,
        /// `level` (the written model) or `full`.
        fit: &'static str,
        /// The residual over the bound, m.
        value_m: f64,
        /// The bound, m.
        bound_m: f64,
        /// The point with the largest residual.
        worst: String,
        /// Its residual, m.
        worst_m: f64,
    },
}

/// One point's residual under the level (written) fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// The point's name.
    pub name: String,
    /// The table point, T, m.
    pub table_m: [f64; 3],
    /// Where the TCP should be: the point plus the contact offset, T, m.
    pub target_m: [f64; 3],
    /// The TCP as touched, B, m.
    pub tcp_b_m: [f64; 3],
    /// The touch mapped by the level fit, T, m.
    pub fitted_m: [f64; 3],
    /// `fitted_m − target_m`, m.
    pub error_m: [f64; 3],
    /// Its length, m.
    pub error_norm_m: f64,
    /// The residual's length under the full (6-DOF) fit, m.
    pub full_error_norm_m: f64,
}

/// The unconstrained rigid transform T←B.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FullFit {
    /// The base origin in T, m.
    pub base_in_table_xyz_m: [f64; 3],
    /// Rotation about z_T (KUKA A), degrees.
    pub yaw_deg: f64,
    /// Rotation about the turned y (KUKA B), degrees.
    pub pitch_deg: f64,
    /// Rotation about the turned x (KUKA C), degrees.
    pub roll_deg: f64,
    /// Angle between the base's z axis and z_T, degrees.
    pub tilt_deg: f64,
    /// The rotation matrix, rows.
    pub rotation: [[f64; 3]; 3],
    /// RMS residual, m.
    pub rms_m: f64,
    /// Worst residual, m.
    pub worst_m: f64,
    /// The point with the worst residual.
    pub worst: String,
}

/// The fit: the level `[cell]` to write, its residuals, and the full fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellFit {
    /// The `[cell]` lines (base level, yaw only).
    pub cell: CellPlacement,
    /// RMS residual of the level fit, m.
    pub rms_m: f64,
    /// Worst residual of the level fit, m.
    pub worst_m: f64,
    /// The point with the worst residual.
    pub worst: String,
    /// Per point, in the order given.
    pub residuals: Vec<Residual>,
    /// The full rigid transform (roll and pitch say whether the base is level).
    pub full: FullFit,
    /// The contact offset along +z_T the targets include, m.
    pub contact_offset_m: f64,
}

fn v(a: [f64; 3]) -> Vec3 {
    Vector3::from(a)
}

fn arr(p: Vec3) -> [f64; 3] {
    [p.x, p.y, p.z]
}

fn centroid(ps: &[Vec3]) -> Vec3 {
    ps.iter().fold(Vec3::zeros(), |s, p| s + p) / ps.len() as f64
}

/// Checks the touch set (see [`Degenerate`]).
fn check_set(touches: &[Touch], targets: &[Vec3], tcps: &[Vec3]) -> Result<(), Degenerate> {
    if touches.len() < MIN_POINTS {
        return Err(Degenerate::TooFew { n: touches.len() });
    }
    for t in touches {
        if !t.table_m.iter().chain(&t.tcp_b_m).all(|x| x.is_finite()) {
            return Err(Degenerate::NotFinite { name: t.name.clone() });
        }
    }
    for i in 0..touches.len() {
        for j in i + 1..touches.len() {
            let (a, b) = (&touches[i].name, &touches[j].name);
            if a == b {
                return Err(Degenerate::SameName { name: a.clone() });
            }
            let d = (targets[i] - targets[j]).norm();
            if d < MIN_SEPARATION_M {
                return Err(Degenerate::SamePoint { a: a.clone(), b: b.clone(), distance_m: d });
            }
            let d = (tcps[i] - tcps[j]).norm();
            if d < MIN_SEPARATION_M {
                return Err(Degenerate::SameTouch { a: a.clone(), b: b.clone(), distance_m: d });
            }
        }
    }
    // The best line through the table points: the covariance's principal
    // direction; the largest distance from it.
    let c = centroid(targets);
    let cov = targets.iter().fold(Matrix3::zeros(), |m, q| m + (q - c) * (q - c).transpose());
    let eig = cov.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let dir: Vec3 = eig.eigenvectors.column(k).into_owned();
    let off_line_m = targets.iter().map(|q| ((q - c) - dir * (q - c).dot(&dir)).norm()).fold(0.0, f64::max);
    if off_line_m < MIN_OFF_LINE_M {
        let names = touches.iter().map(|t| t.name.as_str()).collect::<Vec<_>>().join(", ");
        return Err(Degenerate::Collinear { names, off_line_m });
    }
    Ok(())
}

fn stats(errors: &[f64], touches: &[Touch]) -> (f64, f64, String) {
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let (k, worst) = errors.iter().enumerate().fold((0, 0.0), |m, (i, &e)| if e > m.1 { (i, e) } else { m });
    (rms, worst, touches[k].name.clone())
}

/// Fits T←B to the touches: the TCP at `touches[i].tcp_b_m` touched
/// `touches[i].table_m` with the TCP `contact_offset_m` above it along
/// +z_T. The yaw is reported within ±180° of `yaw_near_deg` (the file's
/// current yaw, so that 180° stays 180° and not −180°).
pub fn fit_cell(touches: &[Touch], contact_offset_m: f64, yaw_near_deg: f64) -> Result<CellFit, Degenerate> {
    if !contact_offset_m.is_finite() {
        return Err(Degenerate::NotFinite { name: "contact offset".to_owned() });
    }
    let offset = Vec3::new(0.0, 0.0, contact_offset_m);
    let targets: Vec<Vec3> = touches.iter().map(|t| v(t.table_m) + offset).collect();
    let tcps: Vec<Vec3> = touches.iter().map(|t| v(t.tcp_b_m)).collect();
    check_set(touches, &targets, &tcps)?;
    let (pc, qc) = (centroid(&tcps), centroid(&targets));

    // Full fit (Kabsch): q ≈ R p + t.
    let h = tcps.iter().zip(&targets).fold(Matrix3::zeros(), |m, (p, q)| m + (p - pc) * (q - qc).transpose());
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u.expect("asked for U"), svd.v_t.expect("asked for V^T"));
    let v_m = v_t.transpose();
    let d = if (v_m * u.transpose()).determinant() < 0.0 { -1.0 } else { 1.0 };
    let r = v_m * Matrix3::from_diagonal(&Vec3::new(1.0, 1.0, d)) * u.transpose();
    let t = qc - r * pc;
    let full_errors: Vec<f64> = tcps.iter().zip(&targets).map(|(p, q)| (r * p + t - q).norm()).collect();
    let (full_rms, full_worst, full_worst_name) = stats(&full_errors, touches);
    let yaw = r[(1, 0)].atan2(r[(0, 0)]);
    let pitch = (-r[(2, 0)]).atan2(r[(2, 1)].hypot(r[(2, 2)]));
    let roll = r[(2, 1)].atan2(r[(2, 2)]);
    let full = FullFit {
        base_in_table_xyz_m: arr(t),
        yaw_deg: wrap_deg_near(yaw.to_degrees(), yaw_near_deg),
        pitch_deg: pitch.to_degrees(),
        roll_deg: roll.to_degrees(),
        tilt_deg: r[(2, 2)].clamp(-1.0, 1.0).acos().to_degrees(),
        rotation: [0, 1, 2].map(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)]]),
        rms_m: full_rms,
        worst_m: full_worst,
        worst: full_worst_name,
    };

    // Level fit: q ≈ Rz(θ) p + t. z is untouched by Rz, so θ maximises
    // Σ q'ᵀ Rz p' over the centred x-y parts alone.
    let (mut s, mut c) = (0.0, 0.0);
    for (p, q) in tcps.iter().zip(&targets) {
        let (p, q) = (p - pc, q - qc);
        s += p.x * q.y - p.y * q.x;
        c += p.x * q.x + p.y * q.y;
    }
    let theta = s.atan2(c);
    let (sn, cs) = theta.sin_cos();
    let rz = Matrix3::new(cs, -sn, 0.0, sn, cs, 0.0, 0.0, 0.0, 1.0);
    let tz = qc - rz * pc;
    let mut residuals = Vec::with_capacity(touches.len());
    let mut errors = Vec::with_capacity(touches.len());
    for (i, touch) in touches.iter().enumerate() {
        let fitted = rz * tcps[i] + tz;
        let e = fitted - targets[i];
        errors.push(e.norm());
        residuals.push(Residual {
            name: touch.name.clone(),
            table_m: touch.table_m,
            target_m: arr(targets[i]),
            tcp_b_m: touch.tcp_b_m,
            fitted_m: arr(fitted),
            error_m: arr(e),
            error_norm_m: e.norm(),
            full_error_norm_m: full_errors[i],
        });
    }
    let (rms_m, worst_m, worst) = stats(&errors, touches);
    Ok(CellFit {
        cell: CellPlacement {
            base_in_table_xyz_m: arr(tz),
            base_yaw_in_table_deg: wrap_deg_near(theta.to_degrees(), yaw_near_deg),
        },
        rms_m,
        worst_m,
        worst,
        residuals,
        full,
        contact_offset_m,
    })
}

impl CellFit {
    /// Holds the fit to `bounds`. A full fit within the residual bounds
    /// but tilted beyond `max_tilt_deg` is a base that is not level;
    /// otherwise the level fit's residuals decide and name the worst
    /// point (the level fit cannot absorb a point touched too high or low
    /// into a tilt, as the full fit partly does, so it names the right
    /// one); then the tilt and the full fit's worst residual.
    pub fn check(&self, bounds: &Bounds) -> Result<(), Refusal> {
        let f = &self.full;
        let not_level = || Refusal::NotLevel {
            tilt_deg: f.tilt_deg,
            roll_deg: f.roll_deg,
            pitch_deg: f.pitch_deg,
            bound_deg: bounds.max_tilt_deg,
        };
        let full_ok = f.rms_m <= bounds.max_rms_m && f.worst_m <= bounds.max_worst_m;
        if full_ok && f.tilt_deg > bounds.max_tilt_deg {
            return Err(not_level());
        }
        let level = [("RMS", self.rms_m, bounds.max_rms_m), ("worst", self.worst_m, bounds.max_worst_m)];
        for (which, value_m, bound_m) in level {
            if value_m > bound_m || value_m.is_nan() {
                let worst = self.worst.clone();
                return Err(Refusal::Residual { which, fit: "level", value_m, bound_m, worst, worst_m: self.worst_m });
            }
        }
        if f.tilt_deg > bounds.max_tilt_deg {
            return Err(not_level());
        }
        if !full_ok {
            let (which, value_m, bound_m) = if f.rms_m > bounds.max_rms_m {
                ("RMS", f.rms_m, bounds.max_rms_m)
            } else {
                ("worst", f.worst_m, bounds.max_worst_m)
            };
            let worst = f.worst.clone();
            return Err(Refusal::Residual { which, fit: "full", value_m, bound_m, worst, worst_m: f.worst_m });
        }
        Ok(())
    }

    /// The two `[cell]` lines for `calib/robot.toml`.
    pub fn cell_lines(&self) -> String {
        cell_lines(&self.cell)
    }
}

/// The two `[cell]` lines: position to 10 µm, yaw to 0.0001°.
pub fn cell_lines(cell: &CellPlacement) -> String {
    let p = cell.base_in_table_xyz_m;
    format!(
        "base_in_table_xyz_m = [{:.5}, {:.5}, {:.5}]\nbase_yaw_in_table_deg = {:.4}\n",
        p[0], p[1], p[2], cell.base_yaw_in_table_deg
    )
}

/// `RIst` moved while a touch was averaged.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum NotStill {
    /// No samples at all.
    #[error("no RIst samples")]
    Empty,
    /// A sample strayed more than the bound from the mean.
    #[error("the robot moved while the point was read: RIst strayed {spread_mm:.3} mm from its mean (> {bound_mm} mm)")]
    Moved {
        /// The largest distance of a sample from the mean, mm.
        spread_mm: f64,
        /// The bound, mm.
        bound_mm: f64,
    },
}

/// The mean of `samples_mm` (TCP positions, mm), provided no sample lies
/// more than `max_spread_mm` from it.
pub fn average_still(samples_mm: &[[f64; 3]], max_spread_mm: f64) -> Result<[f64; 3], NotStill> {
    if samples_mm.is_empty() {
        return Err(NotStill::Empty);
    }
    let ps: Vec<Vec3> = samples_mm.iter().map(|&p| v(p)).collect();
    let m = centroid(&ps);
    let spread_mm = ps.iter().map(|p| (p - m).norm()).fold(0.0, |a: f64, d| if d.is_nan() { d } else { a.max(d) });
    // NaN never passes.
    if !(m.iter().all(|x| x.is_finite()) && spread_mm <= max_spread_mm) {
        return Err(NotStill::Moved { spread_mm, bound_mm: max_spread_mm });
    }
    Ok(arr(m))
}

/// A `robot.toml` text whose `[cell]` lines cannot be edited.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EditError {
    /// No `[cell]` section, or it lacks the key.
    #[error("no `cell.{0}` line to replace")]
    Missing(&'static str),
    /// An array value that never closes.
    #[error("`cell.{0}`: its array never closes")]
    Unclosed(&'static str),
}

/// `text` (a `robot.toml`) with the values of `[cell]`'s
/// `base_in_table_xyz_m` and `base_yaw_in_table_deg` replaced by `cell`'s,
/// every other byte kept: comments, order, the rest of each line after the
/// value (a trailing comment). A value may span lines (an array); its
/// replacement takes one.
pub fn replace_cell_lines(text: &str, cell: &CellPlacement) -> Result<String, EditError> {
    const KEYS: [&str; 2] = ["base_in_table_xyz_m", "base_yaw_in_table_deg"];
    let lines = cell_lines(cell);
    let new_values: Vec<&str> = lines.lines().map(|l| l.split_once(" = ").map_or("", |(_, v)| v)).collect();
    let mut out = String::with_capacity(text.len() + 64);
    let mut found = [false; 2];
    let mut section = String::new();
    let mut rest = text;
    while !rest.is_empty() {
        let end = rest.find('\n').map_or(rest.len(), |i| i + 1);
        let (line, tail) = rest.split_at(end);
        rest = tail;
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') && !trimmed.starts_with("[[") {
            section = trimmed[1..].split(']').next().unwrap_or("").trim().to_owned();
        } else if trimmed.starts_with("[[") {
            section.clear();
        }
        let key = trimmed.split('=').next().unwrap_or("").trim();
        let k = KEYS.iter().position(|&name| name == key);
        match k {
            Some(k) if section == "cell" && trimmed.contains('=') => {
                found[k] = true;
                let indent = &line[..line.len() - trimmed.len()];
                let value_start = line.find('=').expect("contains '='") + 1;
                // The value's end: the closing ']' of an array (possibly
                // on a later line), else the start of a comment or the line.
                let mut value_line = line;
                if line[value_start..].trim_start().starts_with('[') {
                    while !value_line.split('#').next().unwrap_or("").contains(']') {
                        if rest.is_empty() {
                            return Err(EditError::Unclosed(KEYS[k]));
                        }
                        let end = rest.find('\n').map_or(rest.len(), |i| i + 1);
                        (value_line, rest) = rest.split_at(end);
                    }
                    let close = value_line.find(']').expect("checked") + 1;
                    out.push_str(&format!("{indent}{} = {}{}", KEYS[k], new_values[k], &value_line[close..]));
                } else {
                    let after = &line[value_start..];
                    let tail_at = after.find('#').unwrap_or_else(|| after.trim_end().len());
                    let tail = &after[tail_at..];
                    let sep = if tail.starts_with('#') { " " } else { "" };
                    let newline = if tail.ends_with('\n') || !line.ends_with('\n') { "" } else { "\n" };
                    out.push_str(&format!("{indent}{} = {}{sep}{tail}{newline}", KEYS[k], new_values[k]));
                }
            }
            _ => out.push_str(line),
        }
    }
    for (k, f) in found.iter().enumerate() {
        if !f {
            return Err(EditError::Missing(KEYS[k]));
        }
    }
    Ok(out)
}

/// What a touches file (TOML) holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TouchFile {
    /// The TCP's height above each point when it touches it, mm (default 0).
    #[serde(default)]
    pub contact_offset_mm: Option<f64>,
    /// The touches.
    #[serde(default)]
    pub point: Vec<TouchEntry>,
}

/// One `[[point]]` of a touches file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TouchEntry {
    /// A [`named_points`] name, or one's own with `table_xyz_m`.
    pub name: String,
    /// The TCP in B as the pendant shows it (X, Y, Z), mm.
    pub tcp_mm: [f64; 3],
    /// The point in T, m (only for a point not in [`named_points`]).
    #[serde(default)]
    pub table_xyz_m: Option<[f64; 3]>,
}

/// Resolves a point's T position: its own coordinates, else its name.
pub fn resolve_point(table: &Table, name: &str, own: Option<[f64; 3]>) -> Result<[f64; 3], String> {
    match (own, named_point(table, name)) {
        (Some(p), _) => Ok(p),
        (None, Some(p)) => Ok(p),
        (None, None) => Err(format!(
            "point {name:?} is not a table point ({}); give its table_xyz_m",
            named_points(table).map(|(n, _)| n).join(", ")
        )),
    }
}

#[cfg(test)]
#[allow(clippy::needless_range_loop)] // parallel x, y, z arrays
mod tests {
    use super::*;

    const ROBOT_TOML: &str = include_str!("../../../../calib/robot.toml");

    fn rot(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
        let (r, p, y) = (roll.to_radians(), pitch.to_radians(), yaw.to_radians());
        *(nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), y)
            * nalgebra::Rotation3::from_axis_angle(&Vec3::y_axis(), p)
            * nalgebra::Rotation3::from_axis_angle(&Vec3::x_axis(), r))
        .matrix()
    }

    /// Touches of `names` (plus own points) for a base at `base` turned by
    /// `r`, TCP `offset` above each point: p_B = Rᵀ (q + offset z − base).
    fn touches(points: &[(&str, [f64; 3])], r: Matrix3<f64>, base: [f64; 3], offset: f64) -> Vec<Touch> {
        points
            .iter()
            .map(|(name, q)| {
                let p = r.transpose() * (v(*q) + Vec3::new(0.0, 0.0, offset) - v(base));
                Touch { name: (*name).to_owned(), table_m: *q, tcp_b_m: arr(p) }
            })
            .collect()
    }

    fn reachable() -> Vec<(&'static str, [f64; 3])> {
        let t = Table::default();
        let mut p: Vec<_> = named_points(&t).into_iter().filter(|(n, _)| n.contains("robot")).collect();
        p.push(("mark_centre_30cm", [1.07, 0.0, 0.0]));
        p.push(("mark_pos_y_30cm", [1.07, 0.5, 0.0]));
        p
    }

    #[test]
    fn named_points_follow_the_table() {
        let t = Table { length: 2.0, width: 1.0, net_height: 0.2, net_length: 1.6 };
        assert_eq!(named_point(&t, "corner_robot_pos_y"), Some([1.0, 0.5, 0.0]));
        assert_eq!(named_point(&t, "corner_opponent_neg_y"), Some([-1.0, -0.5, 0.0]));
        assert_eq!(named_point(&t, "centre_opponent_end"), Some([-1.0, 0.0, 0.0]));
        assert_eq!(named_point(&t, "net_post_neg_y"), Some([0.0, -0.8, 0.2]));
        assert_eq!(named_point(&t, "net_centre"), None);
        assert!(resolve_point(&t, "mark", None).unwrap_err().contains("net_post_pos_y"));
        assert_eq!(resolve_point(&t, "mark", Some([0.5, 0.0, 0.0])), Ok([0.5, 0.0, 0.0]));
    }

    #[test]
    fn a_level_transform_is_recovered_exactly_from_noiseless_points() {
        let base = [2.093, -0.037, -0.081];
        let points: Vec<_> = named_points(&Table::default()).into();
        for (yaw, offset) in [(183.5, 0.0), (176.2, 0.006), (-2.0, 0.01), (180.0, 0.0)] {
            let t = touches(&points, rot(0.0, 0.0, yaw), base, offset);
            let f = fit_cell(&t, offset, 180.0).unwrap();
            for i in 0..3 {
                assert!((f.cell.base_in_table_xyz_m[i] - base[i]).abs() < 1e-9, "{yaw} {:?}", f.cell);
                assert!((f.full.base_in_table_xyz_m[i] - base[i]).abs() < 1e-9);
            }
            let want = wrap_deg_near(yaw, 180.0);
            assert!((f.cell.base_yaw_in_table_deg - want).abs() < 1e-9, "{yaw} {:?}", f.cell);
            assert!((f.full.yaw_deg - want).abs() < 1e-9);
            assert!(f.full.roll_deg.abs() < 1e-9 && f.full.pitch_deg.abs() < 1e-9 && f.full.tilt_deg < 1e-6);
            assert!(f.rms_m < 1e-12 && f.worst_m < 1e-12 && f.full.rms_m < 1e-12);
            assert_eq!(f.check(&Bounds::default()), Ok(()));
        }
    }

    #[test]
    fn a_tilted_transform_is_recovered_by_the_full_fit_and_refused() {
        let base = [2.05, 0.02, -0.05];
        let (roll, pitch, yaw) = (0.4, -0.7, 181.0);
        let t = touches(&reachable(), rot(roll, pitch, yaw), base, 0.0);
        let f = fit_cell(&t, 0.0, 180.0).unwrap();
        assert!((f.full.roll_deg - roll).abs() < 1e-9 && (f.full.pitch_deg - pitch).abs() < 1e-9, "{:?}", f.full);
        assert!((f.full.yaw_deg - yaw).abs() < 1e-9);
        for i in 0..3 {
            assert!((f.full.base_in_table_xyz_m[i] - base[i]).abs() < 1e-9);
        }
        let r = rot(roll, pitch, yaw);
        let tilt = r[(2, 2)].acos().to_degrees();
        assert!((f.full.tilt_deg - tilt).abs() < 1e-9 && f.full.rms_m < 1e-12);
        match f.check(&Bounds::default()) {
            Err(Refusal::NotLevel { tilt_deg, bound_deg, .. }) => {
                assert!((tilt_deg - tilt).abs() < 1e-9 && bound_deg == DEFAULT_MAX_TILT_DEG)
            }
            other => panic!("{other:?}"),
        }
        // Allowed a tilt, the level fit's residual (the tilt over ~0.4 m)
        // is what refuses it.
        let loose = Bounds { max_tilt_deg: 1.0, ..Bounds::default() };
        assert!(f.worst_m > DEFAULT_MAX_WORST_M, "{}", f.worst_m);
        match f.check(&loose) {
            Err(Refusal::Residual { which, fit, worst, .. }) => {
                assert_eq!((which, fit, worst.as_str()), ("RMS", "level", "corner_robot_pos_y"))
            }
            other => panic!("{other:?}"),
        }
        // A small tilt is within the bounds and the level fit holds.
        let t = touches(&reachable(), rot(0.05, 0.05, yaw), base, 0.0);
        assert_eq!(fit_cell(&t, 0.0, 180.0).unwrap().check(&Bounds::default()), Ok(()));
    }

    #[test]
    fn noise_gives_the_expected_residual_statistics() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let sigma = 0.0005; // 0.5 mm per axis
        let noise = Normal::new(0.0, sigma).unwrap();
        let base = [2.07, 0.01, -0.06];
        let (mut rms2, mut pos_err2, mut yaw_err2) = (0.0, 0.0, 0.0);
        let trials = 400;
        let points = reachable();
        for _ in 0..trials {
            let mut t = touches(&points, rot(0.0, 0.0, 182.0), base, 0.0);
            for touch in &mut t {
                for x in &mut touch.tcp_b_m {
                    *x += noise.sample(&mut rng);
                }
            }
            let f = fit_cell(&t, 0.0, 180.0).unwrap();
            rms2 += f.rms_m * f.rms_m;
            pos_err2 += (v(f.cell.base_in_table_xyz_m) - v(base)).norm_squared();
            yaw_err2 += (f.cell.base_yaw_in_table_deg - 182.0).powi(2);
        }
        // E[Σ|e|²] = σ² (3n − 4) for a 4-parameter fit of n 3-D points.
        let n = points.len() as f64;
        let want_rms = sigma * ((3.0 * n - 4.0) / n).sqrt();
        let rms = (rms2 / trials as f64).sqrt();
        assert!((rms / want_rms - 1.0).abs() < 0.05, "rms {rms} want {want_rms}");
        // The base within a millimetre and a tenth of a degree.
        assert!((pos_err2 / trials as f64).sqrt() < 0.001);
        assert!((yaw_err2 / trials as f64).sqrt() < 0.1);
    }

    #[test]
    fn a_point_touched_wrongly_is_named() {
        let mut t = touches(&reachable(), rot(0.0, 0.0, 180.0), [2.05, 0.0, -0.05], 0.0);
        t[1].tcp_b_m[1] += 0.02; // 2 cm off
        let f = fit_cell(&t, 0.0, 180.0).unwrap();
        assert_eq!(f.full.worst, "corner_robot_neg_y");
        assert_eq!(f.worst, "corner_robot_neg_y");
        match f.check(&Bounds::default()) {
            Err(Refusal::Residual { worst, which, fit, .. }) => {
                assert_eq!((worst.as_str(), which, fit), ("corner_robot_neg_y", "RMS", "level"))
            }
            other => panic!("{other:?}"),
        }
        // Loosen the RMS only: the worst bound names it.
        let b = Bounds { max_rms_m: 0.05, ..Bounds::default() };
        assert!(matches!(f.check(&b), Err(Refusal::Residual { which: "worst", .. })));
        // Touched 15 mm too high: the full fit tilts towards it and blames
        // another point; the level fit names it.
        let mut t = touches(&reachable(), rot(0.0, 0.0, 180.0), [2.05, 0.0, -0.05], 0.0);
        t[1].tcp_b_m[2] += 0.015;
        let f = fit_cell(&t, 0.0, 180.0).unwrap();
        assert_ne!(f.full.worst, "corner_robot_neg_y");
        match f.check(&Bounds::default()) {
            Err(Refusal::Residual { worst, fit, .. }) => {
                assert_eq!((worst.as_str(), fit), ("corner_robot_neg_y", "level"))
            }
            other => panic!("{other:?}"),
        }
        let b = Bounds { max_rms_m: 0.05, max_worst_m: 0.05, max_tilt_deg: 10.0 };
        assert_eq!(f.check(&b), Ok(()));
    }

    #[test]
    fn degenerate_sets_are_refused_by_name() {
        let r = rot(0.0, 0.0, 180.0);
        let base = [2.05, 0.0, -0.05];
        let all = touches(&reachable(), r, base, 0.0);
        assert_eq!(fit_cell(&all[..3], 0.0, 180.0).unwrap_err(), Degenerate::TooFew { n: 3 });
        // The robot's end line alone: collinear.
        let end: Vec<_> = named_points(&Table::default())
            .into_iter()
            .filter(|(n, _)| n.contains("robot"))
            .chain([("mark_on_end_line", [1.37, 0.4, 0.0])])
            .collect();
        match fit_cell(&touches(&end, r, base, 0.0), 0.0, 180.0).unwrap_err() {
            Degenerate::Collinear { names, off_line_m } => {
                assert_eq!(names, "corner_robot_pos_y, corner_robot_neg_y, centre_robot_end, mark_on_end_line");
                assert!(off_line_m < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        let mut t = all.clone();
        t[4].name = t[0].name.clone();
        assert_eq!(fit_cell(&t, 0.0, 180.0).unwrap_err(), Degenerate::SameName { name: "corner_robot_pos_y".into() });
        let mut t = all.clone();
        t[3].table_m = [1.37, 0.01, 0.0];
        t[3].name = "mark_near_centre".into();
        match fit_cell(&t, 0.0, 180.0).unwrap_err() {
            Degenerate::SamePoint { a, b, distance_m } => {
                assert_eq!((a.as_str(), b.as_str()), ("centre_robot_end", "mark_near_centre"));
                assert!((distance_m - 0.01).abs() < 1e-12);
            }
            other => panic!("{other:?}"),
        }
        let mut t = all.clone();
        t[4].tcp_b_m = t[2].tcp_b_m;
        let e = fit_cell(&t, 0.0, 180.0).unwrap_err();
        assert_eq!(e, Degenerate::SameTouch { a: "centre_robot_end".into(), b: t[4].name.clone(), distance_m: 0.0 });
        assert!(e.to_string().contains("same robot position"), "{e}");
        let mut t = all.clone();
        t[2].tcp_b_m[0] = f64::NAN;
        assert_eq!(fit_cell(&t, 0.0, 180.0).unwrap_err(), Degenerate::NotFinite { name: "centre_robot_end".into() });
        assert!(matches!(fit_cell(&all, f64::INFINITY, 180.0), Err(Degenerate::NotFinite { .. })));
    }

    #[test]
    fn still_average_refuses_motion() {
        let s = [[1.0, 2.0, 3.0], [1.1, 2.0, 3.0], [0.9, 2.0, 3.0]];
        assert_eq!(average_still(&s, 0.2), Ok([1.0, 2.0, 3.0]));
        match average_still(&s, 0.05) {
            Err(NotStill::Moved { spread_mm, bound_mm }) => {
                assert!((spread_mm - 0.1).abs() < 1e-12 && bound_mm == 0.05)
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(average_still(&[], 0.2), Err(NotStill::Empty));
        assert!(average_still(&[[f64::NAN, 0.0, 0.0]], 0.2).is_err());
    }

    #[test]
    fn cell_lines_are_replaced_and_nothing_else() {
        let cell = CellPlacement { base_in_table_xyz_m: [2.09312, -0.0371, -0.081], base_yaw_in_table_deg: 183.5 };
        let out = replace_cell_lines(ROBOT_TOML, &cell).unwrap();
        let r: super::super::RobotFile = toml::from_str(&out).unwrap();
        assert_eq!(r.cell, cell);
        // Every other line is the same.
        let (a, b): (Vec<_>, Vec<_>) = (ROBOT_TOML.lines().collect(), out.lines().collect());
        assert_eq!(a.len(), b.len());
        let changed: Vec<_> = a.iter().zip(&b).filter(|(x, y)| x != y).map(|(_, y)| *y).collect();
        assert_eq!(
            changed,
            ["base_in_table_xyz_m = [2.09312, -0.03710, -0.08100]", "base_yaw_in_table_deg = 183.5000"]
        );
        // Trailing comments, a multi-line array and no final newline.
        let text = "version = 1\n[home]\nbase_yaw_in_table_deg = 1.0\n[cell]\n  base_in_table_xyz_m = [\n 1.0,\n 2.0, 3.0] # where\nbase_yaw_in_table_deg = 90.0   # turned";
        let out = replace_cell_lines(text, &cell).unwrap();
        assert_eq!(
            out,
            "version = 1\n[home]\nbase_yaw_in_table_deg = 1.0\n[cell]\n  base_in_table_xyz_m = [2.09312, -0.03710, -0.08100] # where\nbase_yaw_in_table_deg = 183.5000 # turned"
        );
        assert_eq!(
            replace_cell_lines("[cell]\nbase_yaw_in_table_deg = 1\n", &cell),
            Err(EditError::Missing("base_in_table_xyz_m"))
        );
        assert_eq!(
            replace_cell_lines("[cell]\nbase_in_table_xyz_m = [1,\n", &cell),
            Err(EditError::Unclosed("base_in_table_xyz_m"))
        );
    }

    #[test]
    fn touch_files_parse() {
        let f: TouchFile = toml::from_str(
            "contact_offset_mm = 6.0\n[[point]]\nname = \"centre_robot_end\"\ntcp_mm = [680.0, 0.0, 56.0]\n[[point]]\nname = \"mark\"\ntcp_mm = [980.0, 0.0, 56.0]\ntable_xyz_m = [1.07, 0.0, 0.0]\n",
        )
        .unwrap();
        assert_eq!(f.contact_offset_mm, Some(6.0));
        assert_eq!(f.point.len(), 2);
        assert_eq!(f.point[1].table_xyz_m, Some([1.07, 0.0, 0.0]));
        assert!(toml::from_str::<TouchFile>("[[point]]\nname = \"x\"\ntcp = [1.0, 2.0, 3.0]\n").is_err());
    }
}
