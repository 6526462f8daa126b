//! The ball launcher at the opponent's end: the paper's nine settings
//! (three spin types × three powers, as on its TTmatic machine, where faster
//! spin comes with a higher speed), each a distribution of exit speed, spin
//! and launch point, and the aiming that makes every ball clear the net,
//! bounce on the robot's half and reach the hitting plane.
//!
//! A wheel launcher grips the ball between wheels, so the spin axis is
//! perpendicular to the exit velocity: for backspin and topspin it is the
//! horizontal axis across the flight (±y rotated with the azimuth; backspin
//! ω_y < 0, topspin ω_y > 0), rolled by a few degrees at random; for
//! sidespin it is the "up" axis perpendicular to the velocity (mostly z),
//! tilted 5–20° towards backspin, with a random sign per ball (the head
//! turns either way), so both curves are exercised.
//!
//! Aiming: a target bounce point is drawn on the robot's half and the
//! elevation and azimuth are solved by shooting with the real flight model
//! (bisection on the elevation for the range, a fixed-point step on the
//! azimuth for the side), then the shot is checked with the real table and
//! net. Draws without a solution are redrawn, a bounded number of times.

use std::fmt;
use std::str::FromStr;

use rand::Rng;
use serde::{Deserialize, Serialize};

use topspin_core::physics::{BallState, Event, Propagator, StopAt, Table, Vec3, rps_to_rad};

/// The kind of spin a setting puts on the ball.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum SpinType {
    /// Backspin: about the horizontal axis across the flight, ω_y < 0.
    Backspin,
    /// Sidespin: about the mostly vertical axis perpendicular to the velocity, either sign.
    Sidespin,
    /// Topspin: about the horizontal axis across the flight, ω_y > 0.
    Topspin,
}

/// The launcher's power (speed and spin grow together).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Power {
    /// The lowest power: the slowest balls with the least spin.
    Low,
    /// The middle power.
    Medium,
    /// The highest power: the fastest balls with the most spin.
    High,
}

/// One of the nine launcher settings.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub struct Setting {
    /// The kind of spin.
    pub spin: SpinType,
    /// The power.
    pub power: Power,
}

/// A uniform range [lo, hi].
#[derive(Copy, Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Range {
    /// Lower end, in the quantity's unit.
    pub lo: f64,
    /// Upper end, in the quantity's unit.
    pub hi: f64,
}

impl Range {
    const fn new(lo: f64, hi: f64) -> Self {
        Range { lo, hi }
    }

    fn sample(&self, rng: &mut impl Rng) -> f64 {
        self.lo + (self.hi - self.lo) * rng.random::<f64>()
    }
}

/// What one setting draws for each ball.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Distribution {
    /// Exit speed, m/s.
    pub speed: Range,
    /// Spin magnitude, revolutions per second.
    pub spin_rps: Range,
    /// Roll of the spin axis about the exit velocity, degrees (±): the
    /// axis's deviation from the ideal one, staying perpendicular to the
    /// velocity.
    pub axis_roll_deg: f64,
}

/// Launch point x range (behind the opponent's end, m).
pub(crate) const LAUNCH_X: Range = Range::new(-1.60, -1.45);
/// Launch point |y| ≤ this, m.
pub(crate) const LAUNCH_Y_MAX: f64 = 0.30;
/// Launch point height of the ball centre above the table surface, m.
pub(crate) const LAUNCH_Z: Range = Range::new(0.15, 0.40);
/// Target bounce x on the robot's half, m.
pub(crate) const TARGET_X: Range = Range::new(0.25, 1.15);
/// Target bounce |y| ≤ this, m: a launcher aimed at the robot's half,
/// whose balls then cross the hitting plane within about ±0.6 m (sidespin
/// carries them further out), inside the robot's reach.
pub(crate) const TARGET_Y_MAX: f64 = 0.40;
/// Sidespin axis tilt from the "up" axis towards backspin, degrees.
pub(crate) const SIDESPIN_TILT_DEG: Range = Range::new(5.0, 20.0);
/// Draws tried per launch before giving up.
pub(crate) const MAX_ATTEMPTS: usize = 64;
/// Elevation search interval, rad.
const ELEVATION: (f64, f64) = (-0.6, 0.75);
/// Accepted miss of the target bounce point, m.
const AIM_TOLERANCE: f64 = 2e-3;
/// Longest flight considered, s.
const T_MAX: f64 = 3.0;

impl Setting {
    /// All nine settings, in the paper's order.
    pub const ALL: [Setting; 9] = {
        use Power::*;
        use SpinType::*;
        [
            Setting::new(Backspin, Low),
            Setting::new(Backspin, Medium),
            Setting::new(Backspin, High),
            Setting::new(Sidespin, Low),
            Setting::new(Sidespin, Medium),
            Setting::new(Sidespin, High),
            Setting::new(Topspin, Low),
            Setting::new(Topspin, Medium),
            Setting::new(Topspin, High),
        ]
    };

    /// The setting of `spin` at `power`.
    pub const fn new(spin: SpinType, power: Power) -> Self {
        Setting { spin, power }
    }

    /// The distribution this setting draws from. Speeds 4.5–11.5 m/s and
    /// spins 20–100 rps; backspin stays slower, because with strong
    /// backspin the Magnus lift exceeds gravity and a fast ball would not
    /// come down on the table (the paper's medium and high backspin were
    /// hard to tell apart too).
    pub(crate) fn distribution(&self) -> Distribution {
        use Power::*;
        use SpinType::*;
        let (speed, spin_rps) = match (self.spin, self.power) {
            (Backspin, Low) => (Range::new(4.5, 5.5), Range::new(20.0, 30.0)),
            (Backspin, Medium) => (Range::new(5.5, 6.5), Range::new(35.0, 45.0)),
            (Backspin, High) => (Range::new(6.0, 7.0), Range::new(45.0, 55.0)),
            (Sidespin, Low) => (Range::new(5.0, 6.0), Range::new(25.0, 35.0)),
            (Sidespin, Medium) => (Range::new(6.5, 7.5), Range::new(45.0, 55.0)),
            (Sidespin, High) => (Range::new(8.0, 9.0), Range::new(65.0, 75.0)),
            (Topspin, Low) => (Range::new(6.0, 7.0), Range::new(30.0, 40.0)),
            (Topspin, Medium) => (Range::new(8.0, 9.0), Range::new(55.0, 65.0)),
            (Topspin, High) => (Range::new(10.0, 11.5), Range::new(85.0, 100.0)),
        };
        Distribution { speed, spin_rps, axis_roll_deg: 5.0 }
    }
}

impl fmt::Display for SpinType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SpinType::Backspin => "backspin",
            SpinType::Sidespin => "sidespin",
            SpinType::Topspin => "topspin",
        })
    }
}

impl fmt::Display for Power {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Power::Low => "low",
            Power::Medium => "medium",
            Power::High => "high",
        })
    }
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}-{}", self.spin, self.power)
    }
}

/// A setting name that is not one of the nine.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown launcher setting `{0}` (expected e.g. backspin-low, sidespin-medium, topspin-high)")]
pub struct UnknownSetting(pub String);

impl FromStr for Setting {
    type Err = UnknownSetting;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        Setting::ALL.into_iter().find(|k| k.to_string() == name).ok_or_else(|| UnknownSetting(s.to_owned()))
    }
}

impl Serialize for Setting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Setting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// How the launcher's spin axis stands to the exit velocity.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum SpinAxis {
    /// A wheel launcher: the axis perpendicular to the exit velocity (the
    /// nine settings as described above).
    Perpendicular,
    /// Axes as players and other machines make them: sidespin about the
    /// table's vertical (tilted towards backspin as above) whatever the
    /// elevation, so a rising ball spins partly along its flight; the
    /// other axes tipped towards the flight direction by up to `max_deg`.
    Skewed {
        /// Largest tip of the axis towards the flight direction, degrees.
        max_deg: f64,
    },
}

/// One launched ball: its setting and its state at t = 0.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Launch {
    /// The setting the ball was drawn from.
    pub setting: Setting,
    /// The ball's position (m), velocity (m/s) and spin (rad/s) at launch, table frame.
    pub state: BallState,
}

/// No draw of a setting gave a ball that bounces on the robot's half and
/// reaches the hitting plane (possible only with odd physics or geometry).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("launcher setting {setting} found no valid shot in {attempts} draws (check physics, table and hit_plane_x)")]
pub struct NoValidShot {
    /// The setting that found no shot.
    pub setting: Setting,
    /// Draws tried.
    pub attempts: usize,
}

/// One draw: what the launcher does before it is aimed.
#[derive(Copy, Clone, Debug)]
struct Draw {
    origin: Vec3,
    speed: f64,
    spin: f64,
    roll: f64,
    /// Sidespin: +1 or −1 (ω along +up or −up).
    side_sign: f64,
    /// Sidespin: tilt towards backspin, rad.
    tilt: f64,
    target: (f64, f64),
    axis: SpinAxis,
    /// Tip of the axis towards the flight direction, rad (`SpinAxis::Skewed`).
    skew: f64,
}

impl Draw {
    fn sample(setting: Setting, axis: SpinAxis, rng: &mut impl Rng) -> Draw {
        let d = setting.distribution();
        let origin =
            Vec3::new(LAUNCH_X.sample(rng), Range::new(-LAUNCH_Y_MAX, LAUNCH_Y_MAX).sample(rng), LAUNCH_Z.sample(rng));
        let speed = d.speed.sample(rng);
        let spin = rps_to_rad(d.spin_rps.sample(rng));
        let roll = Range::new(-d.axis_roll_deg, d.axis_roll_deg).sample(rng).to_radians();
        let side_sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
        let tilt = SIDESPIN_TILT_DEG.sample(rng).to_radians();
        let target = (TARGET_X.sample(rng), Range::new(-TARGET_Y_MAX, TARGET_Y_MAX).sample(rng));
        // Drawn last, and only for skewed axes: the perpendicular launcher's
        // balls stay the same draws.
        let skew = match axis {
            SpinAxis::Perpendicular => 0.0,
            SpinAxis::Skewed { max_deg } => Range::new(-max_deg, max_deg).sample(rng).to_radians(),
        };
        Draw { origin, speed, spin, roll, side_sign, tilt, target, axis, skew }
    }

    /// The state at launch for elevation `el` and azimuth `az` (rad).
    fn state(&self, spin_type: SpinType, el: f64, az: f64) -> BallState {
        let dir = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        // Across the flight (horizontal, ⟂ dir) and "up" ⟂ dir.
        let across = Vec3::new(-az.sin(), az.cos(), 0.0);
        let up = dir.cross(&across);
        let skewed = matches!(self.axis, SpinAxis::Skewed { .. });
        // Skewed sidespin turns about the table's vertical, not "up" ⟂ dir.
        let vertical = if skewed { Vec3::z() } else { up };
        let axis = match spin_type {
            SpinType::Topspin => across,
            SpinType::Backspin => -across,
            SpinType::Sidespin => vertical * (self.side_sign * self.tilt.cos()) - across * self.tilt.sin(),
        };
        // Roll about the exit velocity keeps the axis ⟂ to it.
        let mut axis = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(dir), self.roll) * axis;
        if skewed && spin_type != SpinType::Sidespin {
            // Tip towards the flight direction (about the axis ⟂ both).
            let hinge = axis.cross(&dir);
            if let Some(h) = nalgebra::Unit::try_new(hinge, 1e-9) {
                axis = nalgebra::Rotation3::from_axis_angle(&h, self.skew) * axis;
            }
        }
        BallState::new(self.origin, dir * self.speed, axis.normalize() * self.spin)
    }
}

/// Where a ball with state `s` first comes down to the table height, on an
/// unbounded table without a net: (x, y), or `None` if it never does.
fn landing(prop: &Propagator, s: &BallState) -> Option<(f64, f64)> {
    let mut p = *prop;
    p.table = Table { length: 1e4, width: 1e4, ..prop.table };
    let mut s = *s;
    let mut t = 0.0;
    match p.advance(&mut s, &mut t, &StopAt::time(T_MAX)) {
        Event::Bounce { before, .. } => Some((before.pos.x, before.pos.y)),
        _ => None,
    }
}

/// Aims `draw` at its target: elevation and azimuth, or `None`.
fn aim(draw: &Draw, spin_type: SpinType, prop: &Propagator) -> Option<(f64, f64)> {
    let (tx, ty) = draw.target;
    let o = draw.origin;
    let mut az = (ty - o.y).atan2(tx - o.x);
    for _ in 0..12 {
        // Range: landing x (along the aim) grows with the elevation.
        let range = |el: f64| -> Option<f64> {
            landing(prop, &draw.state(spin_type, el, az)).map(|(x, y)| (x - o.x) * az.cos() + (y - o.y) * az.sin())
        };
        let want = (tx - o.x) * az.cos() + (ty - o.y) * az.sin();
        let (mut lo, mut hi) = ELEVATION;
        if range(lo)? > want || range(hi)? < want {
            return None;
        }
        for _ in 0..40 {
            let el = 0.5 * (lo + hi);
            if range(el)? < want {
                lo = el;
            } else {
                hi = el;
            }
            if hi - lo < 1e-6 {
                break;
            }
        }
        let el = 0.5 * (lo + hi);
        let (x, y) = landing(prop, &draw.state(spin_type, el, az))?;
        if (x - tx).hypot(y - ty) < AIM_TOLERANCE {
            return Some((el, az));
        }
        // Turn by the angle between where it landed and the target.
        az += (ty - o.y).atan2(tx - o.x) - (y - o.y).atan2(x - o.x);
    }
    None
}

/// True when the real table and net accept the shot: first event a bounce
/// on the robot's half, then the hitting plane before anything else.
pub(crate) fn accepted(prop: &Propagator, s: &BallState, hit_plane_x: f64) -> bool {
    let stop = StopAt { t_max: T_MAX, hit_plane_x: Some(hit_plane_x), net: true };
    let (mut s, mut t) = (*s, 0.0);
    match prop.advance(&mut s, &mut t, &stop) {
        Event::Bounce { before, .. } if before.pos.x > 0.0 => {}
        _ => return false,
    }
    matches!(prop.advance(&mut s, &mut t, &stop), Event::HitPlane { .. })
}

/// Launches one ball of `setting`: draws speed, spin, launch point and a
/// target bounce point, aims with `prop`, and redraws (at most
/// `MAX_ATTEMPTS` times) until the ball clears the net, bounces on the
/// robot's half and crosses `hit_plane_x`. Deterministic in `rng`.
pub fn launch(
    setting: Setting,
    prop: &Propagator,
    hit_plane_x: f64,
    rng: &mut impl Rng,
) -> Result<Launch, NoValidShot> {
    launch_with(setting, SpinAxis::Perpendicular, prop, hit_plane_x, rng)
}

/// [`launch`] with another rule for the spin axis.
pub fn launch_with(
    setting: Setting,
    axis: SpinAxis,
    prop: &Propagator,
    hit_plane_x: f64,
    rng: &mut impl Rng,
) -> Result<Launch, NoValidShot> {
    launch_until(setting, axis, prop, rng, |l| accepted(prop, &l.state, hit_plane_x))
}

/// Draws and aims shots of `setting` until `ok` takes one (at most
/// [`MAX_ATTEMPTS`] draws).
pub(crate) fn launch_until(
    setting: Setting,
    axis: SpinAxis,
    prop: &Propagator,
    rng: &mut impl Rng,
    ok: impl Fn(&Launch) -> bool,
) -> Result<Launch, NoValidShot> {
    for _ in 0..MAX_ATTEMPTS {
        let draw = Draw::sample(setting, axis, rng);
        let Some((el, az)) = aim(&draw, setting.spin, prop) else {
            continue;
        };
        let shot = Launch { setting, state: draw.state(setting.spin, el, az) };
        if ok(&shot) {
            return Ok(shot);
        }
    }
    Err(NoValidShot { setting, attempts: MAX_ATTEMPTS })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use topspin_core::calib::Calibration;

    #[test]
    fn names_round_trip() {
        for s in Setting::ALL {
            assert_eq!(s.to_string().parse::<Setting>().unwrap(), s);
        }
        assert_eq!("Topspin-High".parse::<Setting>().unwrap(), Setting::new(SpinType::Topspin, Power::High));
        assert!("topspin-max".parse::<Setting>().is_err());
        let json = serde_json::to_string(&Setting::ALL[4]).unwrap();
        assert_eq!(json, "\"sidespin-medium\"");
    }

    #[test]
    fn every_setting_bounces_on_the_robots_half_and_reaches_the_plane() {
        for physics in ["calibrated", "paper"] {
            let mut cal = Calibration::default_cell();
            if physics == "paper" {
                cal = cal.with_paper_physics();
            }
            let prop = cal.propagator();
            let x_hit = cal.strike.hit_plane_x;
            for setting in Setting::ALL {
                let d = setting.distribution();
                for seed in 0..20 {
                    let mut rng = ChaCha8Rng::seed_from_u64(seed);
                    let l = launch(setting, &prop, x_hit, &mut rng)
                        .unwrap_or_else(|e| panic!("{physics} seed {seed}: {e}"));
                    assert!(accepted(&prop, &l.state, x_hit));
                    let v = l.state.vel;
                    let w = l.state.spin;
                    // Axis ⟂ exit velocity.
                    assert!(v.dot(&w).abs() < 1e-9 * v.norm() * w.norm());
                    let speed = v.norm();
                    assert!(speed >= d.speed.lo - 1e-9 && speed <= d.speed.hi + 1e-9);
                    let rps = topspin_core::physics::rad_to_rps(w.norm());
                    assert!(rps >= d.spin_rps.lo - 1e-9 && rps <= d.spin_rps.hi + 1e-9);
                    match setting.spin {
                        SpinType::Backspin => assert!(w.y < -0.9 * w.norm()),
                        SpinType::Topspin => assert!(w.y > 0.9 * w.norm()),
                        SpinType::Sidespin => assert!(w.z.abs() > 0.8 * w.norm()),
                    }
                    let p = l.state.pos;
                    assert!(LAUNCH_X.lo <= p.x && p.x <= LAUNCH_X.hi);
                    assert!(p.y.abs() <= LAUNCH_Y_MAX && LAUNCH_Z.lo <= p.z && p.z <= LAUNCH_Z.hi);
                }
            }
        }
    }

    #[test]
    fn same_seed_same_ball() {
        let prop = Calibration::default_cell().propagator();
        let a = launch(Setting::ALL[8], &prop, 1.6, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let b = launch(Setting::ALL[8], &prop, 1.6, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        assert_eq!(a, b);
    }
}
