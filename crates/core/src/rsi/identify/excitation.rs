//! The excitation `topspin identify` sends: a few millimetres of
//! translation along one axis at a time, as a function of the cycle index.
//!
//! Per excited axis, one block of equal length: a quiet lead-in at zero
//! (the robot at rest: the RIst noise), steps of different heights and
//! hold lengths (the dead time and the lag from clean edges), a
//! pseudo-random multi-level sequence from a fixed LFSR (every hold length
//! from none to 100 ms, so the fit sees all frequencies up to the lag's
//! corner), then back to zero and a quiet tail. Every move between two
//! levels is a half-cosine whose duration keeps its peak speed under
//! [`MAX_SPEED_MM_S`] and its peak acceleration under [`MAX_ACCEL_MM_S2`]:
//! the commanded path is continuous in velocity, starts and ends at zero,
//! and never leaves ±amplitude on its axis (and so the Euclidean
//! correction never exceeds the amplitude, one axis moving at a time).
//!
//! Deterministic: the same configuration gives the same samples, bit for
//! bit (no seed to choose). Built once, cold; [`Excitation::at`] is a
//! lookup.

use core::f64::consts::PI;

/// The largest amplitude `topspin identify` accepts, mm.
pub const MAX_AMPLITUDE_MM: f64 = 10.0;
/// The smallest amplitude worth identifying with (RIst noise is
/// 0.01–0.05 mm on a real robot), mm.
pub const MIN_AMPLITUDE_MM: f64 = 0.5;
/// The default amplitude, mm.
pub const DEFAULT_AMPLITUDE_MM: f64 = 3.0;
/// Peak commanded TCP speed of the excitation, mm/s (T1 allows 250 mm/s).
pub const MAX_SPEED_MM_S: f64 = 100.0;
/// Peak commanded TCP acceleration of the excitation, mm/s².
pub const MAX_ACCEL_MM_S2: f64 = 5000.0;
/// The quiet start at zero, s.
pub const LEAD_IN_S: f64 = 0.2;
/// The quiet end at zero (after the last move home), s.
pub const TAIL_S: f64 = 0.3;
/// The longest excitation, s.
pub const MAX_SECONDS: f64 = 120.0;

/// The steps after the lead-in: level (in amplitudes) and hold (s, after
/// the move). Different heights and holds: long holds show the settled
/// value, short ones the edges' overlap.
const STEPS: [(f64, f64); 6] =
    [(1.0, 0.30), (0.0, 0.20), (-1.0, 0.12), (-1.0 / 3.0, 0.06), (1.0 / 3.0, 0.04), (0.0, 0.16)];
/// Levels of the pseudo-random part, in amplitudes.
const PRBS_LEVELS: [f64; 8] = [-1.0, -0.5, -0.25, 0.25, 0.5, 1.0, -0.75, 0.75];
/// Holds of the pseudo-random part after each move, s.
const PRBS_HOLDS_S: [f64; 4] = [0.0, 0.012, 0.040, 0.100];
/// Seed of the 16-bit Galois LFSR (any non-zero value).
const LFSR_SEED: u16 = 0xACE1;

/// Which translational axes to excite (one after the other for `All`).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum AxisChoice {
    /// X of BASE.
    X,
    /// Y of BASE.
    Y,
    /// Z of BASE.
    Z,
    /// X, then Y, then Z, each for a third of the time.
    All,
}

impl AxisChoice {
    /// The excited axes as flags x, y, z.
    pub fn flags(self) -> [bool; 3] {
        match self {
            AxisChoice::X => [true, false, false],
            AxisChoice::Y => [false, true, false],
            AxisChoice::Z => [false, false, true],
            AxisChoice::All => [true, true, true],
        }
    }
}

/// How the excitation is set up.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ExcitationConfig {
    /// Largest correction on the moving axis, mm.
    pub amplitude_mm: f64,
    /// Which axes move.
    pub axes: AxisChoice,
    /// Total length, s (split evenly between the axes).
    pub seconds: f64,
    /// The sensor cycle, ms (4 or 12).
    pub cycle_ms: u32,
}

/// An excitation that cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ExcitationError {
    /// The amplitude is outside [`MIN_AMPLITUDE_MM`]..=[`MAX_AMPLITUDE_MM`].
    #[error("amplitude {0} mm: must be within {MIN_AMPLITUDE_MM}..={MAX_AMPLITUDE_MM} mm")]
    Amplitude(f64),
    /// The cycle is neither 4 nor 12 ms.
    #[error("cycle {0} ms: must be 4 or 12")]
    Cycle(u32),
    /// Too short for the steps on every axis, or longer than [`MAX_SECONDS`].
    #[error("{seconds} s: must be within {min_seconds:.1}..={MAX_SECONDS} s for these axes and this amplitude")]
    Seconds {
        /// What was asked for.
        seconds: f64,
        /// The shortest excitation that holds the steps on every axis.
        min_seconds: f64,
    },
}

/// The excitation (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Excitation {
    cfg: ExcitationConfig,
    samples: Vec<[f64; 3]>,
    lead_in_cycles: usize,
    max_step_mm: f64,
}

/// Appends half-cosine moves and holds to one axis's block.
struct Block {
    v: Vec<f64>,
    x: f64,
    dt: f64,
}

/// Cycles of a half-cosine move from `from` to `to`: x(t) = x0 + Δ (1 −
/// cos(π t / T)) / 2 peaks at speed π Δ / (2T) and acceleration
/// π² Δ / (2T²).
fn move_cycles(from: f64, to: f64, dt: f64) -> usize {
    let d = (to - from).abs();
    if d == 0.0 {
        return 0;
    }
    let t_v = PI * d / (2.0 * MAX_SPEED_MM_S);
    let t_a = PI * (d / (2.0 * MAX_ACCEL_MM_S2)).sqrt();
    (t_v.max(t_a) / dt).ceil().max(1.0) as usize
}

impl Block {
    fn move_to(&mut self, to: f64) {
        let n = move_cycles(self.x, to, self.dt);
        let x0 = self.x;
        for i in 1..=n {
            self.v.push(x0 + (to - x0) * (1.0 - (PI * i as f64 / n as f64).cos()) / 2.0);
        }
        self.x = to;
    }

    fn hold(&mut self, cycles: usize) {
        self.v.extend(core::iter::repeat_n(self.x, cycles));
    }
}

fn lfsr_next(s: &mut u16) -> u16 {
    // Galois LFSR, taps 16 14 13 11 (maximal length).
    let lsb = *s & 1;
    *s >>= 1;
    if lsb != 0 {
        *s ^= 0xB400;
    }
    *s
}

impl Excitation {
    /// Builds the excitation, or says which setting is unusable.
    pub fn new(cfg: ExcitationConfig) -> Result<Self, ExcitationError> {
        let a = cfg.amplitude_mm;
        if !(a.is_finite() && (MIN_AMPLITUDE_MM..=MAX_AMPLITUDE_MM).contains(&a)) {
            return Err(ExcitationError::Amplitude(a));
        }
        if cfg.cycle_ms != 4 && cfg.cycle_ms != 12 {
            return Err(ExcitationError::Cycle(cfg.cycle_ms));
        }
        let dt = cfg.cycle_ms as f64 * 1e-3;
        let flags = cfg.axes.flags();
        let n_axes = flags.iter().filter(|f| **f).count();
        let cycles = |s: f64| (s / dt).round() as usize;
        // The deterministic part of one block and what must follow it.
        let mut fixed = Block { v: Vec::new(), x: 0.0, dt };
        fixed.hold(cycles(LEAD_IN_S));
        for (level, hold) in STEPS {
            fixed.move_to(level * a);
            fixed.hold(cycles(hold));
        }
        let return_cycles = move_cycles(a, 0.0, dt) + cycles(TAIL_S);
        let min_block = fixed.v.len() + return_cycles;
        let min_seconds = (min_block * n_axes) as f64 * dt;
        let s = cfg.seconds;
        if !(s.is_finite() && s >= min_seconds && s <= MAX_SECONDS) {
            return Err(ExcitationError::Seconds { seconds: s, min_seconds });
        }
        let block_len = cycles(s) / n_axes;
        let mut lfsr = LFSR_SEED;
        let mut samples = vec![[0.0; 3]; block_len * n_axes];
        for (k, (axis, _)) in flags.iter().enumerate().filter(|(_, f)| **f).enumerate() {
            let mut b = Block { v: fixed.v.clone(), x: fixed.x, dt };
            loop {
                let r = lfsr_next(&mut lfsr);
                let mut level = PRBS_LEVELS[(r & 7) as usize] * a;
                if level == b.x {
                    level = -level;
                }
                let hold = cycles(PRBS_HOLDS_S[((r >> 3) & 3) as usize]);
                let needed = move_cycles(b.x, level, dt) + hold + move_cycles(level, 0.0, dt) + cycles(TAIL_S);
                if b.v.len() + needed > block_len {
                    break;
                }
                b.move_to(level);
                b.hold(hold);
            }
            b.move_to(0.0);
            let rest = block_len.saturating_sub(b.v.len());
            b.hold(rest);
            for (i, x) in b.v.iter().take(block_len).enumerate() {
                samples[k * block_len + i][axis] = *x;
            }
        }
        let max_step_mm = MAX_SPEED_MM_S * dt;
        Ok(Excitation { cfg, samples, lead_in_cycles: cycles(LEAD_IN_S), max_step_mm })
    }

    /// How it was set up.
    pub fn config(&self) -> &ExcitationConfig {
        &self.cfg
    }

    /// Its length in cycles.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether it has no cycles (never, once built).
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The correction for cycle `n` (0 = the first request), mm in x, y, z;
    /// zero after the end.
    pub fn at(&self, n: u64) -> [f64; 3] {
        usize::try_from(n).ok().and_then(|i| self.samples.get(i)).copied().unwrap_or([0.0; 3])
    }

    /// All samples, one per cycle.
    pub fn samples(&self) -> &[[f64; 3]] {
        &self.samples
    }

    /// The excited axes x, y, z.
    pub fn excited(&self) -> [bool; 3] {
        self.cfg.axes.flags()
    }

    /// Cycles of the quiet lead-in at the start of each axis's block.
    pub fn lead_in_cycles(&self) -> usize {
        self.lead_in_cycles
    }

    /// The largest change of the correction from one cycle to the next, mm
    /// (peak speed × cycle); answers are held to it even after a gap.
    pub fn max_step_mm(&self) -> f64 {
        self.max_step_mm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(axes: AxisChoice, seconds: f64, cycle_ms: u32) -> ExcitationConfig {
        ExcitationConfig { amplitude_mm: 3.0, axes, seconds, cycle_ms }
    }

    #[test]
    fn bounded_smooth_and_home_at_both_ends() {
        for (axes, seconds, cycle_ms) in [(AxisChoice::All, 12.0, 4), (AxisChoice::Z, 4.0, 4), (AxisChoice::X, 9.0, 12)]
        {
            let e = Excitation::new(cfg(axes, seconds, cycle_ms)).unwrap();
            let dt = cycle_ms as f64 * 1e-3;
            assert_eq!(
                e.len(),
                (seconds / dt).round() as usize / axes.flags().iter().filter(|f| **f).count()
                    * axes.flags().iter().filter(|f| **f).count()
            );
            assert_eq!(e.at(0), [0.0; 3]);
            assert_eq!(*e.samples().last().unwrap(), [0.0; 3]);
            assert_eq!(e.at(e.len() as u64 + 5), [0.0; 3]);
            let mut prev = [0.0; 3];
            let mut prev_v = [0.0; 3];
            let mut moved = [0.0f64; 3];
            for s in e.samples() {
                assert!(s.iter().filter(|x| **x != 0.0).count() <= 1, "one axis at a time: {s:?}");
                assert!((s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt() <= 3.0 + 1e-12);
                for i in 0..3 {
                    let v = (s[i] - prev[i]) / dt;
                    assert!(v.abs() <= MAX_SPEED_MM_S * (1.0 + 1e-9), "speed {v}");
                    // The cosine's discrete acceleration stays under the bound.
                    assert!(((v - prev_v[i]) / dt).abs() <= MAX_ACCEL_MM_S2 * 1.05, "accel {}", (v - prev_v[i]) / dt);
                    moved[i] = moved[i].max(s[i].abs());
                    prev_v[i] = v;
                }
                prev = *s;
            }
            for i in 0..3 {
                assert_eq!(moved[i] == 3.0, axes.flags()[i], "{axes:?} axis {i}: {moved:?}");
            }
        }
    }

    #[test]
    fn deterministic_and_rich() {
        let a = Excitation::new(cfg(AxisChoice::X, 4.0, 4)).unwrap();
        let b = Excitation::new(cfg(AxisChoice::X, 4.0, 4)).unwrap();
        assert_eq!(a, b);
        // The pseudo-random part visits many levels.
        let mut levels: Vec<i64> = a.samples().iter().map(|s| (s[0] * 1e6).round() as i64).collect();
        levels.sort_unstable();
        levels.dedup();
        assert!(levels.len() > 100, "{}", levels.len());
    }

    #[test]
    fn unusable_settings_are_named() {
        assert_eq!(
            Excitation::new(ExcitationConfig { amplitude_mm: 20.0, ..cfg(AxisChoice::X, 4.0, 4) }),
            Err(ExcitationError::Amplitude(20.0))
        );
        assert_eq!(Excitation::new(cfg(AxisChoice::X, 4.0, 8)), Err(ExcitationError::Cycle(8)));
        let Err(ExcitationError::Seconds { min_seconds, .. }) = Excitation::new(cfg(AxisChoice::All, 2.0, 4)) else {
            panic!("2 s for three axes must be refused");
        };
        assert!(min_seconds > 3.0 && min_seconds < 6.0, "{min_seconds}");
        assert!(Excitation::new(cfg(AxisChoice::All, min_seconds, 4)).is_ok());
        assert!(Excitation::new(cfg(AxisChoice::X, f64::NAN, 4)).is_err());
    }
}
