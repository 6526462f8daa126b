//! Calibration: the files in `calib/` (table, physics, strike, robot). The repository's `calib/` is compiled in as the
//! default; `--calib DIR` loads another folder with the same file names,
//! where each missing file falls back to the compiled default.

use std::path::{Path, PathBuf};

pub(crate) mod camera;
pub mod cell;

use serde::{Deserialize, Serialize};

use crate::physics::{PhysicsParams, Propagator, RacketModel, RacketParams, Table};

pub(crate) mod robot;
pub use camera::{CameraCalib, CameraSection, DEFAULT_CAMERA, LogoSection};
pub use robot::{
    BadKey, CellPlacement, HomePose, JointAxes, PosCorrLimits, RobotFile, RobotModel, RsiTiming, ServoModel,
    StartPolicy, TcpLimits, Workspace, lag_step,
};

/// The compiled-in defaults (the repository's `calib/` folder).
/// The repository's `calib/physics.toml`, compiled in.
pub const DEFAULT_PHYSICS: &str = include_str!("../../../../calib/physics.toml");
/// The repository's `calib/table.toml`, compiled in.
pub const DEFAULT_TABLE: &str = include_str!("../../../../calib/table.toml");
/// The repository's `calib/strike.toml`, compiled in.
pub const DEFAULT_STRIKE: &str = include_str!("../../../../calib/strike.toml");
/// The repository's `calib/robot.toml`, compiled in.
pub const DEFAULT_ROBOT: &str = include_str!("../../../../calib/robot.toml");

/// `calib/physics.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PhysicsFile {
    /// Format version of the file.
    pub version: u32,
    pub physics: PhysicsParams,
    /// `[racket]`: the bat's rubber (files written before it existed get
    /// the compiled-in rubber).
    #[serde(default)]
    pub racket: RacketParams,
}

/// `calib/table.toml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct TableFile {
    pub version: u32,
    pub table: Table,
}

/// The least share of the hitting window the arm must reach for a cell to
/// load ([`Calibration::window_reach`]).
pub const MIN_WINDOW_REACH: f64 = 0.5;

/// Where and how the robot meets the ball (`calib/strike.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrikeCalib {
    /// The hitting plane x = hit_plane_x in the table frame, m: where the
    /// robot meets the ball when it can.
    pub hit_plane_x: f64,
    /// The hitting volume's depth: the planes from x = lo to hi (m, every
    /// [`HIT_DEPTH_STEP_M`], `hit_plane_x` among them) where a ball that
    /// passes the nominal plane outside the window may be met instead,
    /// each with the same window. `None`: the nominal plane only.
    #[serde(default)]
    pub hit_depth_x: Option<[f64; 2]>,
    /// The window's y range on the volume's other planes, m (the arm
    /// reaches less of the window's width nearer the table); `None`: the
    /// window's.
    #[serde(default)]
    pub hit_depth_window_y: Option<[f64; 2]>,
    /// Hitting window on the plane: allowed y range, m (table frame).
    pub window_y: [f64; 2],
    /// Allowed z range of the hitting point, m (table frame).
    pub window_z: [f64; 2],
    /// The least time between a plan and its hit the robot can use, s.
    pub min_lead_time: f64,
    /// Bat speed towards the opponent at the hit, m/s.
    pub bat_speed: f64,
    /// ω_ref: the spin ω_y at which β reaches its topspin/backspin angle, rad/s.
    pub spin_ref: f64,
    /// β (rotation about y) for ω_y ≥ +ω_ref, degrees.
    pub beta_topspin_deg: f64,
    /// β for ω_y ≤ −ω_ref, degrees.
    pub beta_backspin_deg: f64,
    /// A (rotation about z) = a0 + a_per_y · y, degrees and degrees per m.
    pub a0_deg: f64,
    /// Slope of A with the hitting point's y (table frame), degrees per m.
    pub a_per_y_deg: f64,
    /// C (rotation about x) = c0 + c_per_y · y, degrees and degrees per m.
    pub c0_deg: f64,
    /// Slope of C with the hitting point's y (table frame), degrees per m.
    pub c_per_y_deg: f64,
    /// How the face is set: aim the return at `aim_target` through the
    /// racket contact model, or the paper's rule (files written before it
    /// existed aim).
    #[serde(default)]
    pub aim: AimMode,
    /// Where returns are aimed (x, y in T, on the opponent's half), m.
    #[serde(default = "default_aim_target")]
    pub aim_target: [f64; 2],
    /// How each ball's target is chosen ([`AimStrategy`]).
    #[serde(default)]
    pub aim_strategy: AimStrategy,
    /// The targets `pattern` cycles through, ball by ball (x, y in T), m.
    #[serde(default)]
    pub aim_pattern: Vec<[f64; 2]>,
    /// The face's tilt range the aim may use, degrees: most closed (< 0),
    /// most open (> 0).
    #[serde(default = "default_aim_tilt")]
    pub aim_tilt_deg: [f64; 2],
    /// The bat speeds the aim may use, slowest and fastest, m/s (the
    /// fastest at most `robot.toml`'s `max_bat_speed_m_s`).
    #[serde(default = "default_aim_bat_speed")]
    pub aim_bat_speed: [f64; 2],
}

/// How the stroke sets the bat's face (`strike.aim`).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AimMode {
    /// Tilt and turn the face so the return lands at `aim_target`
    /// (`estimator::aim`), within the paper's β bounds, bat at `bat_speed`.
    #[default]
    Landing,
    /// The paper's rule: β linear in ω_y, A and C linear in y.
    Paper,
}

/// How each ball's return target is chosen (`strike.aim_strategy`).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AimStrategy {
    /// Every ball to `aim_target`.
    #[default]
    Point,
    /// Ball after ball through `aim_pattern`.
    Pattern,
    /// Away from the opponent: at `aim_target`'s depth, `aim_target`'s
    /// width from the middle on the side of the table the ball did not
    /// come from (the opponent stands behind where it was first seen).
    Away,
}

/// Most targets `strike.aim_pattern` may hold.
pub const MAX_AIM_PATTERN: usize = 16;

impl StrikeCalib {
    /// The target for ball number `ball` of the session, first seen at
    /// `first_y` (y in T, m).
    pub fn aim_target_for(&self, ball: u32, first_y: f64) -> [f64; 2] {
        match self.aim_strategy {
            AimStrategy::Point => self.aim_target,
            AimStrategy::Pattern if !self.aim_pattern.is_empty() => {
                self.aim_pattern[ball as usize % self.aim_pattern.len()]
            }
            AimStrategy::Pattern => self.aim_target,
            AimStrategy::Away => {
                let side = if first_y > 0.0 { -1.0 } else { 1.0 };
                [self.aim_target[0], side * self.aim_target[1].abs()]
            }
        }
    }
}

/// The middle of the opponent's half.
fn default_aim_target() -> [f64; 2] {
    [-0.70, 0.0]
}

/// 0.5 … 2 m/s (2 m/s: the compiled-in robot's fastest bat).
fn default_aim_bat_speed() -> [f64; 2] {
    [0.5, 2.0]
}

/// 40° closed, 43° open: inside the workspace's ±55° about home less the
/// strokes' 10° margin, with 2° to spare (`strike.toml`, `robot.toml`).
fn default_aim_tilt() -> [f64; 2] {
    [-40.0, 43.0]
}

/// The spacing of the hitting volume's planes, m.
pub const HIT_DEPTH_STEP_M: f64 = 0.05;
/// The most planes a hitting volume may hold.
pub const MAX_HITTING_PLANES: usize = 16;

impl StrikeCalib {
    /// The same strike on the plane x = `x` alone: no hitting volume
    /// around it (a question about where and when balls cross there).
    pub fn plane_alone(&self, x: f64) -> StrikeCalib {
        StrikeCalib { hit_plane_x: x, hit_depth_x: None, ..self.clone() }
    }

    /// The hitting volume's depth, [lo, hi] (the nominal plane alone where
    /// none is configured).
    pub fn depth(&self) -> [f64; 2] {
        self.hit_depth_x.unwrap_or([self.hit_plane_x; 2])
    }

    /// The hitting volume's planes, ascending: `hit_plane_x` and every
    /// [`HIT_DEPTH_STEP_M`] from it that lies within [`Self::depth`].
    pub fn hitting_planes(&self) -> heapless::Vec<f64, MAX_HITTING_PLANES> {
        let (below, above) = self.planes_around();
        let mut out = heapless::Vec::new();
        for k in -(below as i64)..=above as i64 {
            if out.push(self.hit_plane_x + k as f64 * HIT_DEPTH_STEP_M).is_err() {
                break;
            }
        }
        out
    }

    /// The index of `hit_plane_x` among [`Self::hitting_planes`].
    pub fn nominal_plane(&self) -> usize {
        self.planes_around().0.min(MAX_HITTING_PLANES - 1)
    }

    /// The indices of [`Self::hitting_planes`] outwards from the nominal
    /// plane, the later (deeper) of two equally far first.
    pub fn planes_outwards(&self) -> impl Iterator<Item = usize> {
        let (home, n) = (self.nominal_plane(), self.hitting_planes().len());
        std::iter::once(home).chain((1..n).flat_map(move |d| [home + d, home.wrapping_sub(d)])).filter(move |k| *k < n)
    }

    /// How many planes of the volume lie below and above the nominal one.
    fn planes_around(&self) -> (usize, usize) {
        let [lo, hi] = self.depth();
        let count = |d: f64| (d / HIT_DEPTH_STEP_M + 1e-9).floor().max(0.0) as usize;
        (count(self.hit_plane_x - lo), count(hi - self.hit_plane_x))
    }

    /// True when a hitting point at (y, z) on the plane x of the hitting
    /// volume lies in that plane's window.
    pub fn in_window_at(&self, x: f64, y: f64, z: f64) -> bool {
        let wy = if x == self.hit_plane_x { self.window_y } else { self.hit_depth_window_y.unwrap_or(self.window_y) };
        (wy[0]..=wy[1]).contains(&y) && self.in_window(y, z)
    }

    /// True when a hitting point at (y, z) lies in the hitting window.
    pub fn in_window(&self, y: f64, z: f64) -> bool {
        (self.window_y[0]..=self.window_y[1]).contains(&y) && (self.window_z[0]..=self.window_z[1]).contains(&z)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct StrikeFile {
    pub version: u32,
    pub strike: StrikeCalib,
}

/// Everything calibrated, loaded and validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// Ball, air and contact constants (`calib/physics.toml`).
    pub physics: PhysicsParams,
    /// The bat's rubber (`[racket]` in `calib/physics.toml`).
    pub racket: RacketParams,
    /// Table geometry (`calib/table.toml`).
    pub table: Table,
    /// Hitting plane, window and stroke (`calib/strike.toml`).
    pub strike: StrikeCalib,
    /// The robot cell (`calib/robot.toml`).
    pub robot: RobotFile,
}

/// A calibration file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The file or folder cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid TOML of the expected shape.
    #[error("{path}: {message}")]
    Parse {
        /// The file (`<default>/NAME` for a compiled-in default).
        path: PathBuf,
        /// The parser's message, with the byte offset where known.
        message: String,
    },
    /// A physics constant is out of range.
    #[error("{path}: {source}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The offending constant.
        source: crate::physics::params::InvalidParam,
    },
    /// A value is out of range or inconsistent with the rest of the cell.
    #[error("{path}: `{key}` = {value} is out of range")]
    OutOfRange {
        /// The file.
        path: PathBuf,
        /// The offending key (`section.field`, possibly with a reason).
        key: &'static str,
        /// The offending value.
        value: f64,
    },
}

fn parse<T: for<'de> Deserialize<'de>>(text: &str, path: &Path) -> Result<T, CalibError> {
    toml::from_str(text).map_err(|e| {
        let message = match e.span().map(|s| (key_at(text, s.start), s.start)) {
            Some((Some((key, line)), _)) => format!("`{key}` (line {line}): {}", e.message()),
            Some((None, at)) => format!("{} (at byte {at})", e.message()),
            None => e.message().to_owned(),
        };
        CalibError::Parse { path: path.to_owned(), message }
    })
}

/// The dotted key (`section.key`) whose value holds byte `at` of a TOML
/// text, and the 1-based line of `at`: the last `key =` line at or before
/// it under the last `[section]` header (values may span lines, as arrays
/// do). `None` before any key.
fn key_at(text: &str, at: usize) -> Option<(String, usize)> {
    let before = text.get(..at.min(text.len()))?;
    let (mut section, mut key) = (None, None);
    for line in before.lines() {
        let line = line.trim_start();
        if line.starts_with('#') {
            continue;
        }
        let header = line.trim_start_matches('[').split(']').next().map(str::trim);
        if line.starts_with('[')
            && let Some(header) = header
            && !header.is_empty()
            && header.chars().all(|c| c.is_alphanumeric() || "_-.\" ".contains(c))
        {
            (section, key) = (Some(header), None);
        } else if let Some((k, _)) = line.split_once('=')
            && !k.trim().is_empty()
            && !k.contains(['"', ',', '['])
        {
            key = Some(k.trim());
        }
    }
    let line = before.lines().count().max(1);
    Some((section.map_or_else(|| key.map(str::to_owned), |s| key.map(|k| format!("{s}.{k}")))?, line))
}

impl Calibration {
    /// The compiled-in calibration (the repository's `calib/`).
    pub fn default_cell() -> Self {
        let at = |name: &str| PathBuf::from(format!("<default>/{name}"));
        Self::from_texts(
            (DEFAULT_PHYSICS, &at("physics.toml")),
            (DEFAULT_TABLE, &at("table.toml")),
            (DEFAULT_STRIKE, &at("strike.toml")),
            (DEFAULT_ROBOT, &at("robot.toml")),
        )
        .expect("compiled-in calibration is valid (tested)")
    }

    /// Parses and validates the four files' texts (each with the path its
    /// errors name): no file system, never panics (fuzzed:
    /// `fuzz/fuzz_targets/calib.rs`).
    pub fn from_texts(
        physics: (&str, &Path),
        table: (&str, &Path),
        strike: (&str, &Path),
        robot: (&str, &Path),
    ) -> Result<Self, CalibError> {
        let (text, path) = (physics.0, physics.1.to_owned());
        let PhysicsFile { physics, racket, .. } = parse::<PhysicsFile>(text, &path)?;
        physics.validate().map_err(|source| CalibError::Invalid { path: path.clone(), source })?;
        racket.validate(physics.mass).map_err(|source| CalibError::Invalid { path: path.clone(), source })?;

        let (text, path) = (table.0, table.1.to_owned());
        let table = parse::<TableFile>(text, &path)?.table;
        for (key, value) in [
            ("table.length", table.length),
            ("table.width", table.width),
            ("table.net_height", table.net_height),
            ("table.net_length", table.net_length),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(CalibError::OutOfRange { path, key, value });
            }
        }

        let (text, path) = (strike.0, strike.1.to_owned());
        let strike = parse::<StrikeFile>(text, &path)?.strike;
        let s = &strike;
        let ordered = |r: [f64; 2]| r[0].is_finite() && r[1].is_finite() && r[0] < r[1];
        let checks = [
            ("strike.hit_plane_x", s.hit_plane_x, s.hit_plane_x.is_finite() && s.hit_plane_x > 0.0),
            ("strike.window_y", s.window_y[0], ordered(s.window_y)),
            ("strike.window_z", s.window_z[0], ordered(s.window_z)),
            ("strike.min_lead_time", s.min_lead_time, s.min_lead_time.is_finite() && s.min_lead_time >= 0.0),
            ("strike.bat_speed", s.bat_speed, s.bat_speed.is_finite() && (0.0..=5.0).contains(&s.bat_speed)),
            ("strike.spin_ref", s.spin_ref, s.spin_ref.is_finite() && s.spin_ref > 0.0),
            ("strike.beta_topspin_deg", s.beta_topspin_deg, s.beta_topspin_deg.abs() <= 90.0),
            ("strike.beta_backspin_deg", s.beta_backspin_deg, s.beta_backspin_deg.abs() <= 90.0),
            ("strike.a0_deg", s.a0_deg, s.a0_deg.abs() <= 180.0),
            ("strike.a_per_y_deg", s.a_per_y_deg, s.a_per_y_deg.abs() <= 180.0),
            ("strike.c0_deg", s.c0_deg, s.c0_deg.abs() <= 180.0),
            ("strike.c_per_y_deg", s.c_per_y_deg, s.c_per_y_deg.abs() <= 180.0),
            (
                "strike.aim_target (on the opponent's half)",
                s.aim_target[0],
                s.aim_target[0] < 0.0 && s.aim_target[0] > table.opponent_end_x(),
            ),
            ("strike.aim_target (on the opponent's half)", s.aim_target[1], s.aim_target[1].abs() < table.width / 2.0),
            (
                "strike.aim_tilt_deg",
                s.aim_tilt_deg[0],
                s.aim_tilt_deg[0] <= 0.0 && s.aim_tilt_deg[0] >= -80.0 && ordered(s.aim_tilt_deg),
            ),
            ("strike.aim_tilt_deg", s.aim_tilt_deg[1], s.aim_tilt_deg[1] >= 0.0 && s.aim_tilt_deg[1] <= 80.0),
            (
                "strike.aim_bat_speed",
                s.aim_bat_speed[0],
                s.aim_bat_speed[0] > 0.0 && s.aim_bat_speed[0] <= s.aim_bat_speed[1],
            ),
            ("strike.aim_bat_speed", s.aim_bat_speed[1], s.aim_bat_speed[1].is_finite()),
            (
                "strike.hit_depth_x (lo ≤ hit_plane_x ≤ hi)",
                s.depth()[0],
                s.depth().iter().all(|x| x.is_finite())
                    && s.depth()[0] <= s.hit_plane_x
                    && s.hit_plane_x <= s.depth()[1],
            ),
            (
                "strike.hit_depth_x (behind the robot's end of the table)",
                s.depth()[0],
                s.depth()[0] > table.robot_end_x(),
            ),
            (
                "strike.hit_depth_window_y (within window_y)",
                s.hit_depth_window_y.map_or(0.0, |w| w[0]),
                s.hit_depth_window_y.is_none_or(|w| ordered(w) && s.window_y[0] <= w[0] && w[1] <= s.window_y[1]),
            ),
            (
                "strike.hit_depth_x (at most 16 planes, 5 cm apart)",
                s.depth()[1] - s.depth()[0],
                s.depth()[1] - s.depth()[0] < MAX_HITTING_PLANES as f64 * HIT_DEPTH_STEP_M,
            ),
        ];
        for (key, value, ok) in checks {
            if !ok {
                return Err(CalibError::OutOfRange { path, key, value });
            }
        }
        let on_their_half =
            |t: &[f64; 2]| t[0] < 0.0 && t[0] > table.opponent_end_x() && t[1].abs() < table.width / 2.0;
        let pattern_ok = match s.aim_strategy {
            AimStrategy::Pattern => !s.aim_pattern.is_empty() && s.aim_pattern.len() <= MAX_AIM_PATTERN,
            _ => s.aim_pattern.len() <= MAX_AIM_PATTERN,
        };
        if !pattern_ok {
            let key = "strike.aim_pattern (1 to 16 targets for aim_strategy = \"pattern\")";
            return Err(CalibError::OutOfRange { path, key, value: s.aim_pattern.len() as f64 });
        }
        if let Some(t) = s.aim_pattern.iter().find(|t| !on_their_half(t)) {
            let key = "strike.aim_pattern (on the opponent's half)";
            return Err(CalibError::OutOfRange { path, key, value: if t[0] < 0.0 { t[1] } else { t[0] } });
        }
        if s.aim_strategy == AimStrategy::Away && s.aim_target[1].abs() < 0.05 {
            let key = "strike.aim_target (aim_strategy = \"away\" needs a width: |y| ≥ 0.05)";
            return Err(CalibError::OutOfRange { path, key, value: s.aim_target[1] });
        }
        let (text, path) = (robot.0, robot.1.to_owned());
        let robot = parse::<RobotFile>(text, &path)?;
        robot.validate().map_err(|b| CalibError::OutOfRange { path: path.clone(), key: b.key, value: b.value })?;
        // The hitting window's corners must lie inside the robot's workspace
        // (the base may be yawed, so check all four).
        let ws = &robot.workspace;
        let inside = |p: crate::physics::Vec3| (0..3).all(|i| (ws.min_xyz_m[i]..=ws.max_xyz_m[i]).contains(&p[i]));
        for x in strike.depth() {
            for y in strike.window_y {
                for z in strike.window_z {
                    if !inside(robot.t_to_b(crate::physics::Vec3::new(x, y, z))) {
                        let mid_z = 0.5 * (strike.window_z[0] + strike.window_z[1]);
                        let key = if !inside(robot.t_to_b(crate::physics::Vec3::new(x, 0.0, mid_z))) {
                            "strike.hit_depth_x (outside the robot's workspace)"
                        } else if inside(robot.t_to_b(crate::physics::Vec3::new(x, y, mid_z))) {
                            "strike.window_z (outside the robot's workspace)"
                        } else {
                            "strike.window_y (outside the robot's workspace)"
                        };
                        return Err(CalibError::OutOfRange {
                            path: path.clone(),
                            key,
                            value: if key.contains("window_z") {
                                z
                            } else if key.contains("window_y") {
                                y
                            } else {
                                x
                            },
                        });
                    }
                }
            }
        }
        // The aim may not ask for a faster bat than the robot gives.
        if strike.aim_bat_speed[1] > robot.limits.max_bat_speed_m_s {
            return Err(CalibError::OutOfRange {
                path,
                key: "strike.aim_bat_speed (faster than robot limits.max_bat_speed_m_s)",
                value: strike.aim_bat_speed[1],
            });
        }
        // The hitting plane must cross the robot's workspace.
        let x_b = robot.t_to_b(crate::physics::Vec3::new(strike.hit_plane_x, 0.0, 0.0)).x;
        if !(robot.workspace.min_xyz_m[0]..=robot.workspace.max_xyz_m[0]).contains(&x_b) {
            return Err(CalibError::OutOfRange {
                path,
                key: "strike.hit_plane_x (outside robot workspace)",
                value: strike.hit_plane_x,
            });
        }
        let cell = Calibration { physics, racket, table, strike, robot };
        // The arm must reach most of the window, not only its box: a base
        // measured in the wrong place leaves the box inside POSCORR but the
        // window outside the arm's joints.
        let reach = cell.window_reach();
        if reach < MIN_WINDOW_REACH {
            return Err(CalibError::OutOfRange {
                path,
                key: "strike.window_y × strike.window_z (the share of the window at strike.hit_plane_x that \
                      the arm reaches from cell.base_in_table_xyz_m within joints.min_deg / joints.max_deg; \
                      at least 0.5 needed)",
                value: reach,
            });
        }
        // And of the volume's nearest and farthest planes.
        for x in cell.strike.depth() {
            let reach = cell.window_reach_at(x);
            if reach < MIN_WINDOW_REACH {
                return Err(CalibError::OutOfRange {
                    path,
                    key: "strike.hit_depth_x (the share of the window on its nearest or farthest plane that the \
                          arm reaches within joints.min_deg / joints.max_deg; at least 0.5 needed)",
                    value: x,
                });
            }
        }
        Ok(cell)
    }

    /// The share of the hitting window the arm reaches: of a 13 × 12 grid
    /// over `strike.window_y` × `strike.window_z` on the hitting plane, the
    /// points where the bat, held as at home, has a joint solution within
    /// the software limits and off the singular wrist. The default cell
    /// reaches 0.87 of it (not the high, wide corners).
    pub fn window_reach(&self) -> f64 {
        self.window_reach_at(self.strike.hit_plane_x)
    }

    /// [`Self::window_reach`] on the plane x (m, in T).
    pub fn window_reach_at(&self, x: f64) -> f64 {
        const NY: usize = 13;
        const NZ: usize = 12;
        let arm = self.robot.arm();
        let home = self.robot.home_pose();
        let Some(home_q) = self.robot.home_joints(&arm) else { return 0.0 };
        let s = &self.strike;
        let mut reached = 0;
        for iy in 0..NY {
            for iz in 0..NZ {
                let y = s.window_y[0] + (s.window_y[1] - s.window_y[0]) * iy as f64 / (NY - 1) as f64;
                let z = s.window_z[0] + (s.window_z[1] - s.window_z[0]) * iz as f64 / (NZ - 1) as f64;
                let target = crate::kinematics::Pose {
                    position: self.robot.t_to_b(crate::physics::Vec3::new(x, y, z)),
                    rotation: home.rotation,
                };
                if arm.inverse_near(&target, &home_q).is_ok_and(|q| arm.limits.check_position(&q).is_ok()) {
                    reached += 1;
                }
            }
        }
        reached as f64 / (NY * NZ) as f64
    }

    /// The same cell with the paper's constant physics coefficients.
    pub fn with_paper_physics(mut self) -> Self {
        self.physics = PhysicsParams::paper();
        self
    }

    /// The racket contact for this cell's rubber and ball.
    pub fn racket_model(&self) -> RacketModel {
        RacketModel::new(self.racket, self.physics.mass, self.physics.radius)
    }

    /// The propagator for this cell's physics and table.
    pub fn propagator(&self) -> Propagator {
        Propagator::new(self.physics.flight_model(), self.physics.bounce_model(), self.table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default cell with `robot` as its `robot.toml`.
    fn with_robot(robot: &str) -> Result<Calibration, CalibError> {
        let p = Path::new("<test>");
        Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (DEFAULT_STRIKE, p), (robot, p))
    }

    #[test]
    fn compiled_defaults_load() {
        let c = Calibration::default_cell();
        assert!(c.strike.hit_plane_x > c.table.robot_end_x());
    }

    #[test]
    fn the_hitting_volume_is_planes_through_its_depth_and_checked() {
        let c = Calibration::default_cell();
        let planes = c.strike.hitting_planes();
        assert_eq!(planes.len(), 4, "{planes:?}");
        for (x, want) in planes.iter().zip([1.45, 1.50, 1.55, 1.60]) {
            assert!((x - want).abs() < 1e-12, "{planes:?}");
        }
        assert_eq!(planes[c.strike.nominal_plane()], c.strike.hit_plane_x);
        assert_eq!(c.strike.planes_outwards().collect::<Vec<_>>(), [3, 2, 1, 0]);
        let plane_only = StrikeCalib { hit_depth_x: None, ..c.strike.clone() };
        assert_eq!(plane_only.hitting_planes().as_slice(), &[c.strike.hit_plane_x]);
        let p = Path::new("strike.toml");
        for (depth, why) in [
            ("[1.65, 1.70]", "lo ≤ hit_plane_x"),
            ("[1.20, 1.60]", "behind the robot's end"),
            ("[1.45, 1.95]", "outside the robot's workspace"),
        ] {
            let bad = DEFAULT_STRIKE.replace("hit_depth_x = [1.45, 1.60]", &format!("hit_depth_x = {depth}"));
            let e = Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (&bad, p), (DEFAULT_ROBOT, p));
            let e = e.unwrap_err().to_string();
            assert!(e.contains("strike.hit_depth_x") && e.contains(why), "{depth}: {e}");
        }
    }

    #[test]
    fn files_from_before_the_racket_and_the_aim_still_load() {
        let p = Path::new("physics.toml");
        let old_physics = &DEFAULT_PHYSICS[..DEFAULT_PHYSICS.find("[racket]").expect("the shipped file has it")];
        let old_strike: String =
            DEFAULT_STRIKE.lines().filter(|l| !l.starts_with("aim")).map(|l| format!("{l}\n")).collect();
        let c = Calibration::from_texts((old_physics, p), (DEFAULT_TABLE, p), (&old_strike, p), (DEFAULT_ROBOT, p))
            .unwrap();
        assert_eq!(c.racket, RacketParams::default());
        assert_eq!(c.racket, Calibration::default_cell().racket, "the shipped [racket] is the default rubber");
        assert_eq!(c.strike.aim, AimMode::Landing);
        assert_eq!(c.strike, Calibration::default_cell().strike);
        // A bad rubber or aim is named.
        let bad = DEFAULT_PHYSICS.replace("friction = 0.65", "friction = -0.1");
        let e = Calibration::from_texts((&bad, p), (DEFAULT_TABLE, p), (DEFAULT_STRIKE, p), (DEFAULT_ROBOT, p));
        assert!(e.unwrap_err().to_string().contains("racket.friction"));
        let bad = DEFAULT_STRIKE.replace("aim_bat_speed = [0.5, 2.0]", "aim_bat_speed = [0.5, 3.0]");
        let e = Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (&bad, p), (DEFAULT_ROBOT, p));
        assert!(e.unwrap_err().to_string().contains("strike.aim_bat_speed"));
        let bad = DEFAULT_STRIKE.replace("aim_target = [-0.70, 0.0]", "aim_target = [0.70, 0.0]");
        let e = Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (&bad, p), (DEFAULT_ROBOT, p));
        assert!(e.unwrap_err().to_string().contains("strike.aim_target"));
    }

    #[test]
    fn each_ball_is_aimed_as_the_strategy_says_and_bad_strategies_are_named() {
        let p = Path::new("strike.toml");
        let with = |lines: &str| {
            let text = DEFAULT_STRIKE.replace("aim_strategy = \"point\"", lines);
            Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (&text, p), (DEFAULT_ROBOT, p))
        };
        let point = Calibration::default_cell().strike;
        assert_eq!(point.aim_strategy, AimStrategy::Point);
        assert_eq!((point.aim_target_for(0, 0.3), point.aim_target_for(7, -0.3)), ([-0.70, 0.0], [-0.70, 0.0]));
        let pattern = with("aim_strategy = \"pattern\"\naim_pattern = [[-0.95, 0.45], [-0.5, -0.45], [-1.0, 0.0]]")
            .unwrap()
            .strike;
        let targets: Vec<[f64; 2]> = (0..4).map(|k| pattern.aim_target_for(k, 0.2)).collect();
        assert_eq!(targets, [[-0.95, 0.45], [-0.5, -0.45], [-1.0, 0.0], [-0.95, 0.45]]);
        let away = with("aim_strategy = \"away\"").map(|_| ()).unwrap_err().to_string();
        assert!(away.contains("strike.aim_target") && away.contains("away"), "{away}");
        let text = DEFAULT_STRIKE
            .replace("aim_strategy = \"point\"", "aim_strategy = \"away\"")
            .replace("aim_target = [-0.70, 0.0]", "aim_target = [-0.90, 0.40]");
        let away =
            Calibration::from_texts((DEFAULT_PHYSICS, p), (DEFAULT_TABLE, p), (&text, p), (DEFAULT_ROBOT, p)).unwrap();
        // From the opponent's right (y > 0 in T) to their left, and back.
        assert_eq!(away.strike.aim_target_for(0, 0.3), [-0.90, -0.40]);
        assert_eq!(away.strike.aim_target_for(1, -0.3), [-0.90, 0.40]);
        for (lines, why) in [
            ("aim_strategy = \"pattern\"", "1 to 16 targets"),
            ("aim_strategy = \"pattern\"\naim_pattern = [[-0.9, 0.4], [0.5, 0.0]]", "on the opponent's half"),
            ("aim_strategy = \"sideways\"", "aim_strategy"),
        ] {
            let e = with(lines).map(|_| ()).unwrap_err().to_string();
            assert!(e.contains(why), "{lines}: {e}");
        }
    }

    #[test]
    fn a_value_of_the_wrong_type_is_named_by_its_key() {
        let robot = DEFAULT_ROBOT.replacen("speed_deg_s = [360.0,", "speed_deg_s = [\"fast\",", 1);
        let e = with_robot(&robot).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("`joints.speed_deg_s` (line ") && e.contains("\"fast\""), "{e}");
        let robot = DEFAULT_ROBOT.replacen("lag_ms = ", "lag_ms = \"15\" # ", 1);
        let e = with_robot(&robot).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("`servo.lag_ms`"), "{e}");
    }

    #[test]
    fn the_default_arm_reaches_most_of_the_window() {
        let reach = Calibration::default_cell().window_reach();
        assert!((0.85..=0.92).contains(&reach), "{reach}");
    }

    #[test]
    fn an_arm_that_cannot_reach_the_window_is_refused() {
        // A lab that fences A1 to ±20° (a narrower software limit switch)
        // keeps home and the workspace box, but the bat no longer gets wider
        // than |y_T| ≈ 0.16 m on the hitting plane.
        let robot = DEFAULT_ROBOT
            .replace("min_deg = [-170.0,", "min_deg = [-20.0,")
            .replace("max_deg = [170.0,", "max_deg = [20.0,");
        let e = with_robot(&robot).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("strike.window_y") && e.contains("joints.min_deg") && e.contains("reaches"), "{e}");
        // ±60° still reaches most of it.
        let robot = DEFAULT_ROBOT
            .replace("min_deg = [-170.0,", "min_deg = [-60.0,")
            .replace("max_deg = [170.0,", "max_deg = [60.0,");
        assert!(with_robot(&robot).is_ok());
    }
}
