//! Where the balls come from: the launcher's nine settings, or real human
//! strokes. The human strokes are 15,792 ball states measured right after
//! real strokes (Google DeepMind's competitive table-tennis release, CC-BY
//! 4.0; `data/human-strokes/README.md`): the 11,999 rally strokes and the
//! 2,704 serves that head towards the robot, in the table frame
//! (x_T = −y, y_T = x, z_T = z of their frame). A ball draws one state,
//! seeded, and flies it with the world's physics: rally strokes straight
//! to the robot's half, serves through their first bounce on the server's
//! half. Draws that never bounce on the robot's half (the net, long, wide,
//! a serve that misses its own half) are redrawn and counted, never
//! judged as misses.
//!
//! A human ball is labelled with the [`Setting`] its state resembles: the
//! spin type by the largest of its topspin and sidespin components, the
//! power by its speed (below 5 m/s low, below 6.5 m/s medium, else high).

use std::fmt;
use std::str::FromStr;
use std::sync::OnceLock;

use rand::Rng;

use topspin_core::calib::StrikeCalib;
use topspin_core::physics::{BallState, Event, Propagator, StopAt, Vec3};

use crate::launcher::{Launch, NoValidShot, Power, Setting, SpinAxis, SpinType, accepted, launch_until};
use crate::truth::Truth;

/// The balls' source.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum Strokes {
    /// The launcher's nine settings, aimed at the robot's half.
    #[default]
    Launcher,
    /// The same, aimed as a lab aims its launcher at its robot: every
    /// ball passes through the hitting volume's window.
    AimedLauncher,
    /// Human rally strokes.
    HumanRally,
    /// Human serves.
    HumanServe,
    /// Both, as often as the data holds them (about one serve in five).
    Human,
}

impl Strokes {
    /// Every source, in declaration order.
    pub const ALL: [Strokes; 5] =
        [Strokes::Launcher, Strokes::AimedLauncher, Strokes::HumanRally, Strokes::HumanServe, Strokes::Human];

    /// One of the launcher's sources (its settings, not human states).
    pub fn is_launcher(self) -> bool {
        matches!(self, Strokes::Launcher | Strokes::AimedLauncher)
    }

    fn name(self) -> &'static str {
        match self {
            Strokes::Launcher => "launcher",
            Strokes::AimedLauncher => "aimed-launcher",
            Strokes::HumanRally => "human-rally",
            Strokes::HumanServe => "human-serve",
            Strokes::Human => "human",
        }
    }

    /// The human states this source draws from (empty for the launcher).
    fn pool(self) -> &'static [HumanState] {
        let all = human_states();
        let serves = all.partition_point(|s| !s.serve);
        match self {
            Strokes::Launcher | Strokes::AimedLauncher => &[],
            Strokes::HumanRally => &all[..serves],
            Strokes::HumanServe => &all[serves..],
            Strokes::Human => all,
        }
    }
}

impl serde::Serialize for Strokes {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl fmt::Display for Strokes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A stroke source name that is not one of [`Strokes::ALL`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown strokes `{0}` (expected launcher, aimed-launcher, human-rally, human-serve or human)")]
pub struct UnknownStrokes(pub String);

impl FromStr for Strokes {
    type Err = UnknownStrokes;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let name = s.trim().to_ascii_lowercase();
        Strokes::ALL.into_iter().find(|k| k.name() == name).ok_or_else(|| UnknownStrokes(s.to_owned()))
    }
}

/// One measured state right after a human stroke, in the table frame.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HumanState {
    /// The data set's id.
    pub id: u32,
    /// A serve (else a rally stroke).
    pub serve: bool,
    /// The ball's position (m), velocity (m/s) and spin (rad/s) right after the stroke, table frame.
    pub state: BallState,
}

/// The data set as shipped (see `data/human-strokes/README.md`).
const STATES_CSV: &str = include_str!("../data/human-strokes/states.csv");

/// The human strokes heading towards the robot, rally strokes first, in
/// the file's order (parsed once).
pub fn human_states() -> &'static [HumanState] {
    static STATES: OnceLock<Vec<HumanState>> = OnceLock::new();
    STATES.get_or_init(|| {
        let mut out: Vec<HumanState> = STATES_CSV.lines().skip(1).filter_map(parse_row).collect();
        out.retain(|s| s.state.vel.x > 0.0);
        out.sort_by_key(|s| s.serve);
        out
    })
}

/// One row `kind,id,pos_x,…,w_vel_z` in the data's frame, mapped into the
/// table frame; `None` for a row that does not parse (none in the file).
fn parse_row(line: &str) -> Option<HumanState> {
    let mut f = line.split(',');
    let serve = match f.next()? {
        "serve" => true,
        "rally" => false,
        _ => return None,
    };
    let id = f.next()?.parse().ok()?;
    let mut v = [0.0f64; 9];
    for x in &mut v {
        *x = f.next()?.parse().ok()?;
    }
    // Theirs: x along the net, y along the table; ours: x along the table
    // towards the robot, y = z × x. A rotation by 90° about z.
    let to_table = |i: usize| Vec3::new(-v[i + 1], v[i], v[i + 2]);
    let state = BallState::new(to_table(0), to_table(3), to_table(6));
    state.is_finite().then_some(HumanState { id, serve, state })
}

/// Why a drawn human state was not played.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum OutOfPlay {
    /// It met the net.
    Net,
    /// It passed the robot's end of the table without a bounce on its half.
    Long,
    /// It left the table at a side.
    Wide,
    /// A serve that did not bounce on the server's half first.
    Serve,
}

impl fmt::Display for OutOfPlay {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            OutOfPlay::Net => "net",
            OutOfPlay::Long => "long",
            OutOfPlay::Wide => "wide",
            OutOfPlay::Serve => "serve fault",
        })
    }
}

/// Longest flight followed to its bounce, s.
const T_MAX: f64 = 3.0;

/// Follows a human stroke with `prop` (the real table and net) to its
/// bounce on the robot's half: `Ok` when it gets there the way its kind
/// must (a serve through one bounce on its own half first).
pub fn in_play(prop: &Propagator, h: &HumanState) -> Result<(), OutOfPlay> {
    let stop = StopAt { t_max: T_MAX, hit_plane_x: None, net: true };
    let (mut s, mut t) = (h.state, 0.0);
    let mut own_bounce = false;
    loop {
        match prop.advance(&mut s, &mut t, &stop) {
            Event::Bounce { before, .. } if before.pos.x > 0.0 => {
                return if h.serve && !own_bounce { Err(OutOfPlay::Serve) } else { Ok(()) };
            }
            Event::Bounce { .. } if h.serve && !own_bounce => own_bounce = true,
            Event::Bounce { .. } => return Err(if h.serve { OutOfPlay::Serve } else { OutOfPlay::Long }),
            Event::Net { .. } => return Err(OutOfPlay::Net),
            _ if h.serve && !own_bounce => return Err(OutOfPlay::Serve),
            _ => {
                let half_width = 0.5 * prop.table.width;
                return Err(if s.pos.y.abs() > half_width && s.pos.x < 0.5 * prop.table.length {
                    OutOfPlay::Wide
                } else {
                    OutOfPlay::Long
                });
            }
        }
    }
}

/// The launcher setting a human state resembles (see the module doc).
pub fn resembles(s: &BallState) -> Setting {
    let v = s.vel;
    let across = Vec3::z().cross(&v);
    let top = if across.norm() > 1e-9 { s.spin.dot(&across.normalize()) } else { 0.0 };
    let spin = if s.spin.z.abs() > top.abs() {
        SpinType::Sidespin
    } else if top >= 0.0 {
        SpinType::Topspin
    } else {
        SpinType::Backspin
    };
    let power = match v.norm() {
        x if x < 5.0 => Power::Low,
        x if x < 6.5 => Power::Medium,
        _ => Power::High,
    };
    Setting::new(spin, power)
}

/// What drawing a human ball cost: the states passed over, by reason.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Redraws {
    /// States that met the net.
    pub net: usize,
    /// States that passed the robot's end without a bounce on its half.
    pub long: usize,
    /// States that left the table at a side.
    pub wide: usize,
    /// Serves that did not bounce on the server's half first.
    pub serve: usize,
}

impl Redraws {
    fn count(&mut self, why: OutOfPlay) {
        *match why {
            OutOfPlay::Net => &mut self.net,
            OutOfPlay::Long => &mut self.long,
            OutOfPlay::Wide => &mut self.wide,
            OutOfPlay::Serve => &mut self.serve,
        } += 1;
    }

    /// All states passed over.
    pub fn total(&self) -> usize {
        self.net + self.long + self.wide + self.serve
    }
}

/// Draws to try for one ball before giving up.
const MAX_DRAWS: usize = 64;

/// Draws a human stroke of `strokes` that bounces on the robot's half with
/// `prop`, counting the states passed over; `None` for the launcher or
/// when `MAX_DRAWS` draws all miss (a world no human plays in).
pub fn draw_human(strokes: Strokes, prop: &Propagator, rng: &mut impl Rng, redraws: &mut Redraws) -> Option<Launch> {
    let pool = strokes.pool();
    if pool.is_empty() {
        return None;
    }
    for _ in 0..MAX_DRAWS {
        let h = &pool[rng.random_range(0..pool.len())];
        match in_play(prop, h) {
            Ok(()) => return Some(Launch { setting: resembles(&h.state), state: h.state }),
            Err(why) => redraws.count(why),
        }
    }
    None
}

/// [`launch_with`](crate::launcher::launch_with) aimed as a lab aims its launcher at its robot: the
/// ball must also pass through the hitting volume's window (`strike`):
/// its crossing of one of the volume's planes after its bounce lies in
/// that plane's window, as the judges find it ([`Truth::meeting_in`]).
pub fn launch_into_reach(
    setting: Setting,
    axis: SpinAxis,
    prop: &Propagator,
    strike: &StrikeCalib,
    rng: &mut impl Rng,
) -> Result<Launch, NoValidShot> {
    let hit_x = strike.hit_plane_x;
    launch_until(setting, axis, prop, rng, |l| {
        accepted(prop, &l.state, hit_x) && Truth::compute(l, prop, hit_x).meeting_in(strike, prop).is_some()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use topspin_core::calib::Calibration;

    #[test]
    fn the_data_set_maps_into_the_table_frame() {
        let all = human_states();
        let serves = all.iter().filter(|s| s.serve).count();
        // The README's counts of strokes towards the robot.
        assert_eq!((all.len() - serves, serves), (11_999, 2_704));
        // The first rally row: pos (0.06, 0.88, 0.52), vel (0.78, −5.55, 0.52),
        // spin (62.81, −5.84, −7.62) in their frame.
        let first = all.iter().find(|s| s.id == 2704).unwrap().state;
        assert_eq!(first.pos, Vec3::new(-0.88, 0.06, 0.52));
        assert_eq!(first.vel, Vec3::new(5.55, 0.78, 0.52));
        assert_eq!(first.spin, Vec3::new(5.84, 62.81, -7.62));
        // What the README says these strokes are like: launched from the
        // opponent's end, mostly topspin, serves from behind the table.
        let rally = Strokes::HumanRally.pool();
        let topspin = rally.iter().filter(|h| resembles(&h.state).spin == SpinType::Topspin).count();
        assert!(topspin * 100 > 55 * rally.len(), "{topspin} of {}", rally.len());
        assert!(rally.iter().all(|h| h.state.pos.x < 0.0));
        let serves = Strokes::HumanServe.pool();
        assert!(serves.iter().all(|h| h.serve));
        let behind = serves.iter().filter(|h| h.state.pos.x < -1.2).count();
        assert!(behind * 100 > 95 * serves.len(), "{behind} of {}", serves.len());
    }

    #[test]
    fn drawn_strokes_bounce_on_the_robots_half_and_serves_on_their_own_first() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        for strokes in [Strokes::HumanRally, Strokes::HumanServe] {
            let mut rng = ChaCha8Rng::seed_from_u64(4);
            let mut redraws = Redraws::default();
            for _ in 0..40 {
                let l = draw_human(strokes, &prop, &mut rng, &mut redraws).expect("a stroke in play");
                let stop = StopAt { t_max: T_MAX, hit_plane_x: None, net: true };
                let (mut s, mut t) = (l.state, 0.0);
                let mut bounces = vec![];
                while let Event::Bounce { before, .. } = prop.advance(&mut s, &mut t, &stop) {
                    bounces.push(before.pos.x);
                    if before.pos.x > 0.0 {
                        break;
                    }
                }
                let want = if strokes == Strokes::HumanServe { 2 } else { 1 };
                assert_eq!(bounces.len(), want, "{strokes}: {bounces:?}");
                assert!(*bounces.last().unwrap() > 0.0);
            }
            // Some real strokes miss the table: passed over, counted.
            assert!(redraws.total() > 0 && redraws.total() < 40, "{strokes}: {redraws:?}");
        }
        assert!(
            draw_human(Strokes::Launcher, &prop, &mut ChaCha8Rng::seed_from_u64(1), &mut Redraws::default()).is_none()
        );
    }

    #[test]
    fn names_round_trip_and_unknown_ones_are_named() {
        for s in Strokes::ALL {
            assert_eq!(s.to_string().parse::<Strokes>(), Ok(s));
        }
        assert_eq!("elite".parse::<Strokes>(), Err(UnknownStrokes("elite".into())));
    }

    #[test]
    fn an_aimed_launcher_sends_every_setting_through_the_hitting_window() {
        let cal = Calibration::default_cell();
        let prop = cal.propagator();
        let x_hit = cal.strike.hit_plane_x;
        let (mut plain_out, mut n) = (0, 0);
        for setting in Setting::ALL {
            for seed in 0..12 {
                let l = launch_into_reach(
                    setting,
                    SpinAxis::Perpendicular,
                    &prop,
                    &cal.strike,
                    &mut ChaCha8Rng::seed_from_u64(seed),
                )
                .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
                assert!(accepted(&prop, &l.state, x_hit));
                let truth = Truth::compute(&l, &prop, x_hit);
                assert!(truth.meeting_in(&cal.strike, &prop).is_some(), "{setting} seed {seed}");
                let plain =
                    crate::launcher::launch(setting, &prop, x_hit, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
                let truth = Truth::compute(&plain, &prop, x_hit);
                plain_out += truth.meeting_in(&cal.strike, &prop).is_none() as usize;
                n += 1;
            }
        }
        // The plain launcher sends some of the same draws out of reach.
        assert!(plain_out > 0, "{plain_out} of {n}");
    }
}
