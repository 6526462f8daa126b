//! The servo model's fit: dead time d (whole cycles) and lag τ from the
//! corrections the controller applied and the `RIst` it reported.
//!
//! The model, per excited axis, on the IPOC timeline (one index per
//! cycle): x[n+1] = a·x\[n\] + (1 − a)·u[n − d], a = exp(−T/τ), x\[0\] = 0 (at
//! rest at the start pose, u = 0 before the start), and RIst\[n\] − start =
//! g·x\[n\] + c + noise. u\[n\] is the correction the controller applied in
//! cycle n (the answer to request n, or the previous one where that answer
//! was late). With d = 0 and τ = 0 the pose answered for request n is the
//! RIst of request n + 1: that one-cycle pipeline is in the model's
//! `n + 1`, so d counts the cycles beyond it — the mock KR C4's
//! `dead_time_cycles`.
//!
//! The fit is output error: for each d in 0..=max the model is simulated
//! from u alone and τ is found by a log-spaced grid then golden-section
//! search on the residual sum of squares, with the per-axis gain g and
//! offset c solved in closed form (linear) at every step. Output error,
//! not one-step prediction, because RIst noise on the regressor would bias
//! τ down; missing cycles need nothing special (the simulation runs
//! through them, residuals exist only where RIst was seen). d is the one
//! with the least residual; the runner-up's ratio and a likelihood over d
//! say how sure that is. τ's standard deviation is the Gauss–Newton
//! covariance σ²(JᵀJ)⁻¹ of (a, g, c), inflated by the residuals' lag-1
//! correlation ρ by (1 + ρ)/(1 − ρ) (an AR(1) residual has fewer
//! independent samples than cycles).
//!
//! Cold path: runs once after the excitation, allocates freely.

use nalgebra::DMatrix;

/// The longest lag the fit considers, s: what `[servo] lag_ms` accepts.
pub const MAX_LAG_S: f64 = crate::calib::robot::MAX_LAG_MS * 1e-3;
/// The longest dead time the fit considers, s: what `[servo]
/// dead_time_ms` accepts.
pub const MAX_DEAD_TIME_S: f64 = crate::calib::robot::MAX_DEAD_TIME_MS * 1e-3;
/// Grid points over τ before the golden-section search.
const LAG_GRID: usize = 48;
/// The shortest non-zero τ on the grid, in cycles.
const LAG_GRID_MIN_CYCLES: f64 = 0.05;
/// Below τ = T / 7 (a = e⁻⁷ < 0.1 %) a lag changes the response by less
/// than a thousandth of a step: not resolved, reported as 0.
const MIN_RESOLVED_A: f64 = 9.118_819_655_545_162e-4;
/// Golden-section iterations (the bracket shrinks by 0.618 each).
const GOLDEN_ITERATIONS: usize = 60;

/// What was sent and seen, one entry per cycle from the first request.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    /// The cycle, s.
    pub cycle_s: f64,
    /// The correction the controller applied in each cycle, mm (x, y, z).
    pub u: Vec<[f64; 3]>,
    /// RIst minus the start pose, mm, where a request was seen.
    pub y: Vec<Option<[f64; 3]>>,
    /// The axes that were excited.
    pub excited: [bool; 3],
}

/// Why the fit could not run.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ServoFitError {
    /// No axis was excited, or `u` and `y` differ in length.
    #[error("no excited axis, or the trace is inconsistent")]
    BadTrace,
    /// Fewer RIst samples than the fit needs.
    #[error("{samples} RIst samples: too few to fit")]
    TooFewSamples {
        /// The samples seen.
        samples: usize,
    },
    /// The applied correction never changed on an excited axis.
    #[error("the correction never changed on axis {axis}")]
    NoExcitation {
        /// 0, 1, 2 for x, y, z.
        axis: usize,
    },
}

/// The fitted servo model.
#[derive(Clone, Debug, PartialEq)]
pub struct ServoFit {
    /// Dead time beyond the one-cycle pipeline, cycles.
    pub dead_time_cycles: usize,
    /// Standard deviation of the dead time, cycles, from the likelihood
    /// over d: p(d) ∝ exp(−(RSS_d − RSS_min) / (2σ²_eff)).
    pub dead_time_std_cycles: f64,
    /// The second-best dead time.
    pub runner_up_cycles: usize,
    /// RSS of the runner-up over RSS of the best (≥ 1; near 1: unsure).
    pub runner_up_ratio: f64,
    /// The residual sum of squares for each d in 0..=max, mm².
    pub rss_by_dead_time: Vec<f64>,
    /// The lag τ, s.
    pub lag_s: f64,
    /// Its standard deviation, s.
    pub lag_std_s: f64,
    /// τ fitted on each excited axis alone (with the common d), s.
    pub lag_s_per_axis: [Option<f64>; 3],
    /// Gain g per excited axis (1 for a robot that reaches the command).
    pub gain: [Option<f64>; 3],
    /// Offset c per excited axis, mm.
    pub offset_mm: [Option<f64>; 3],
    /// Root mean square of the residuals, mm.
    pub rms_mm: f64,
    /// 100 · (1 − ‖y − ŷ‖ / ‖y − ȳ‖) over the excited axes, %.
    pub fit_percent: f64,
    /// Lag-1 correlation of the residuals.
    pub residual_correlation: f64,
    /// RIst samples used (per axis, summed over the excited axes).
    pub samples: usize,
}

/// One axis's data, flattened.
struct AxisData {
    axis: usize,
    u: Vec<f64>,
    y: Vec<f64>,
    seen: Vec<bool>,
}

/// Sums for the closed-form (g, c) solve.
#[derive(Default)]
struct Sums {
    xx: f64,
    x: f64,
    n: f64,
    xy: f64,
    y: f64,
    yy: f64,
}

impl Sums {
    /// (g, c, RSS) of y ≈ g x + c.
    fn solve(&self) -> (f64, f64, f64) {
        let det = self.xx * self.n - self.x * self.x;
        if det.is_nan() || det.abs() <= 1e-12 * (self.xx * self.n).max(1e-300) {
            let c = if self.n > 0.0 { self.y / self.n } else { 0.0 };
            return (0.0, c, (self.yy - c * self.y).max(0.0));
        }
        let g = (self.xy * self.n - self.x * self.y) / det;
        let c = (self.xx * self.y - self.x * self.xy) / det;
        let rss = self.yy - g * self.xy - c * self.y;
        (g, c, rss.max(0.0))
    }
}

fn a_of(tau: f64, dt: f64) -> f64 {
    if tau <= 0.0 { 0.0 } else { (-dt / tau).exp() }
}

fn tau_of(a: f64, dt: f64) -> f64 {
    if a <= 0.0 { 0.0 } else { -dt / a.ln() }
}

/// The sums of one axis for (d, a), centred on the axis's mean y.
fn axis_sums(ax: &AxisData, d: usize, a: f64, y_mean: f64) -> Sums {
    let mut s = Sums::default();
    let mut x = 0.0;
    for n in 0..ax.u.len() {
        if ax.seen[n] {
            let y = ax.y[n] - y_mean;
            s.xx += x * x;
            s.x += x;
            s.n += 1.0;
            s.xy += x * y;
            s.y += y;
            s.yy += y * y;
        }
        let ud = if n >= d { ax.u[n - d] } else { 0.0 };
        x = a * x + (1.0 - a) * ud;
    }
    s
}

/// Minimizes `cost(a)` over τ ∈ [0, MAX_LAG_S]: grid, then golden section
/// in the best grid point's bracket. Returns (a, cost).
fn minimize_lag(dt: f64, mut cost: impl FnMut(f64) -> f64) -> (f64, f64) {
    let tau_min = LAG_GRID_MIN_CYCLES * dt;
    let mut taus = Vec::with_capacity(LAG_GRID + 1);
    taus.push(0.0);
    for i in 0..LAG_GRID {
        taus.push(tau_min * (MAX_LAG_S / tau_min).powf(i as f64 / (LAG_GRID - 1) as f64));
    }
    let costs: Vec<f64> = taus.iter().map(|t| cost(a_of(*t, dt))).collect();
    let best = (0..costs.len()).min_by(|i, j| costs[*i].total_cmp(&costs[*j])).unwrap_or(0);
    let lo = a_of(taus[best.saturating_sub(1)], dt);
    let hi = a_of(taus[(best + 1).min(taus.len() - 1)], dt);
    let (mut l, mut h) = (lo, hi);
    let r = (5f64.sqrt() - 1.0) / 2.0;
    let mut m1 = h - r * (h - l);
    let mut m2 = l + r * (h - l);
    let (mut c1, mut c2) = (cost(m1), cost(m2));
    for _ in 0..GOLDEN_ITERATIONS {
        if c1 < c2 {
            h = m2;
            m2 = m1;
            c2 = c1;
            m1 = h - r * (h - l);
            c1 = cost(m1);
        } else {
            l = m1;
            m1 = m2;
            c1 = c2;
            m2 = l + r * (h - l);
            c2 = cost(m2);
        }
    }
    let (a, c) = if c1 < c2 { (m1, c1) } else { (m2, c2) };
    let (a, c) = if costs[best] <= c { (a_of(taus[best], dt), costs[best]) } else { (a, c) };
    if a < MIN_RESOLVED_A { (0.0, costs[0]) } else { (a, c) }
}

/// Fits d in 0..=`max_dead_time_cycles` and τ (see the module doc).
pub fn fit(trace: &Trace, max_dead_time_cycles: usize) -> Result<ServoFit, ServoFitError> {
    let dt = trace.cycle_s;
    if trace.u.len() != trace.y.len() || !trace.excited.iter().any(|e| *e) || dt.is_nan() || dt <= 0.0 {
        return Err(ServoFitError::BadTrace);
    }
    let mut axes = Vec::new();
    for (axis, _) in trace.excited.iter().enumerate().filter(|(_, e)| **e) {
        let u: Vec<f64> = trace.u.iter().map(|v| v[axis]).collect();
        let seen: Vec<bool> = trace.y.iter().map(|v| v.is_some_and(|p| p[axis].is_finite())).collect();
        let y: Vec<f64> = trace.y.iter().map(|v| v.map_or(0.0, |p| p[axis])).collect();
        let (lo, hi) = u.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(*x), h.max(*x)));
        if hi <= lo {
            return Err(ServoFitError::NoExcitation { axis });
        }
        axes.push(AxisData { axis, u, y, seen });
    }
    let samples: usize = axes.iter().map(|a| a.seen.iter().filter(|s| **s).count()).sum();
    let params = 1 + 2 * axes.len();
    if samples < 10 * params + max_dead_time_cycles {
        return Err(ServoFitError::TooFewSamples { samples });
    }
    let means: Vec<f64> = axes
        .iter()
        .map(|ax| {
            let (s, n) = (0..ax.y.len()).filter(|n| ax.seen[*n]).fold((0.0, 0.0), |(s, k), n| (s + ax.y[n], k + 1.0));
            s / n
        })
        .collect();
    let total_rss =
        |d: usize, a: f64| -> f64 { axes.iter().zip(&means).map(|(ax, m)| axis_sums(ax, d, a, *m).solve().2).sum() };
    let max_d = max_dead_time_cycles.min(trace.u.len() / 4);
    let mut per_d = Vec::with_capacity(max_d + 1);
    for d in 0..=max_d {
        per_d.push(minimize_lag(dt, |a| total_rss(d, a)));
    }
    let rss_by_dead_time: Vec<f64> = per_d.iter().map(|p| p.1).collect();
    let mut order: Vec<usize> = (0..per_d.len()).collect();
    order.sort_by(|i, j| rss_by_dead_time[*i].total_cmp(&rss_by_dead_time[*j]));
    let d = order[0];
    let runner_up = order.get(1).copied().unwrap_or(d);
    let (a, rss) = per_d[d];

    // Residuals, gains, offsets and the Jacobian at the optimum.
    let mut gain = [None; 3];
    let mut offset_mm = [None; 3];
    let mut lag_s_per_axis = [None; 3];
    let mut jtj = DMatrix::<f64>::zeros(params, params);
    let mut residual_sq = 0.0;
    let mut spread_sq = 0.0;
    let (mut rho_num, mut rho_den) = (0.0, 0.0);
    for (k, (ax, mean)) in axes.iter().zip(&means).enumerate() {
        let (g, c, _) = axis_sums(ax, d, a, *mean).solve();
        gain[ax.axis] = Some(g);
        offset_mm[ax.axis] = Some(c + mean);
        let (ia, ig, ic) = (0, 1 + 2 * k, 2 + 2 * k);
        let (mut x, mut s) = (0.0, 0.0);
        let mut prev_r: Option<f64> = None;
        for n in 0..ax.u.len() {
            if ax.seen[n] {
                let r = ax.y[n] - mean - (g * x + c);
                residual_sq += r * r;
                spread_sq += (ax.y[n] - mean) * (ax.y[n] - mean);
                if let Some(p) = prev_r {
                    rho_num += p * r;
                }
                rho_den += r * r;
                prev_r = Some(r);
                let j = [(ia, g * s), (ig, x), (ic, 1.0)];
                for (p, vp) in j {
                    for (q, vq) in j {
                        jtj[(p, q)] += vp * vq;
                    }
                }
            } else {
                prev_r = None;
            }
            let ud = if n >= d { ax.u[n - d] } else { 0.0 };
            s = a * s + x - ud;
            x = a * x + (1.0 - a) * ud;
        }
        let (a_axis, _) = minimize_lag(dt, |a| axis_sums(ax, d, a, *mean).solve().2);
        lag_s_per_axis[ax.axis] = Some(tau_of(a_axis, dt));
    }
    let dof = (samples - params).max(1) as f64;
    let sigma2 = rss / dof;
    let rho = if rho_den > 0.0 { (rho_num / rho_den).clamp(0.0, 0.99) } else { 0.0 };
    let inflation = (1.0 + rho) / (1.0 - rho);
    let var_a = jtj.try_inverse().map_or(f64::INFINITY, |m| m[(0, 0)].max(0.0)) * sigma2 * inflation;
    let lag_s = tau_of(a, dt);
    let lag_std_s = if a > 0.0 {
        let ln = a.ln();
        dt / (a * ln * ln) * var_a.sqrt()
    } else {
        // τ at its bound 0, where dτ/da = 0: one-sided, the τ of a at one
        // standard deviation, at least the resolution T / 7.
        tau_of(var_a.sqrt().clamp(MIN_RESOLVED_A, 0.999), dt)
    };
    let sigma2_eff = (sigma2 * inflation).max(f64::MIN_POSITIVE);
    let weights: Vec<f64> = rss_by_dead_time.iter().map(|r| (-(r - rss) / (2.0 * sigma2_eff)).exp()).collect();
    let wsum: f64 = weights.iter().sum();
    let mean_d: f64 = weights.iter().enumerate().map(|(i, w)| i as f64 * w).sum::<f64>() / wsum;
    let var_d: f64 = weights.iter().enumerate().map(|(i, w)| (i as f64 - mean_d).powi(2) * w).sum::<f64>() / wsum;
    let runner_up_ratio = if rss > 0.0 { rss_by_dead_time[runner_up] / rss } else { f64::INFINITY };
    Ok(ServoFit {
        dead_time_cycles: d,
        dead_time_std_cycles: var_d.sqrt(),
        runner_up_cycles: runner_up,
        runner_up_ratio,
        rss_by_dead_time,
        lag_s,
        lag_std_s,
        lag_s_per_axis,
        gain,
        offset_mm,
        rms_mm: (residual_sq / samples as f64).sqrt(),
        fit_percent: if spread_sq > 0.0 { 100.0 * (1.0 - (residual_sq / spread_sq).sqrt()) } else { 0.0 },
        residual_correlation: rho,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// The model itself, driven by a staircase with ramps: exact data.
    fn trace(d: usize, tau: f64, noise: f64, seed: u64) -> Trace {
        let dt = 0.004;
        let n = 1500;
        let mut u = vec![[0.0; 3]; n];
        for (i, v) in u.iter_mut().enumerate() {
            let level = [0.0, 3.0, -1.0, 2.0, 0.5, -3.0, 0.0][(i / 200).min(6)];
            v[1] = level;
        }
        // Ramp the edges over 8 cycles.
        let mut smooth = u.clone();
        for i in 0..n {
            smooth[i][1] = (0..8).map(|k| u[i.saturating_sub(k)][1]).sum::<f64>() / 8.0;
        }
        let a = a_of(tau, dt);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let normal = Normal::new(0.0, noise.max(1e-300)).unwrap();
        let mut x = 0.0;
        let mut y = Vec::with_capacity(n);
        for i in 0..n {
            let e = if noise > 0.0 { normal.sample(&mut rng) } else { 0.0 };
            y.push(Some([0.01, x + e + 0.2, -0.3]));
            let ud = if i >= d { smooth[i - d][1] } else { 0.0 };
            x = a * x + (1.0 - a) * ud;
        }
        Trace { cycle_s: dt, u: smooth, y, excited: [false, true, false] }
    }

    #[test]
    fn exact_data_gives_the_exact_model() {
        for (d, tau) in [(0, 0.0), (0, 0.015), (3, 0.015), (1, 0.030), (7, 0.004), (12, 0.080)] {
            let f = fit(&trace(d, tau, 0.0, 1), 30).unwrap();
            assert_eq!(f.dead_time_cycles, d, "d {d} τ {tau}: {f:?}");
            assert!((f.lag_s - tau).abs() < 1e-6, "d {d} τ {tau}: {}", f.lag_s);
            assert!((f.gain[1].unwrap() - 1.0).abs() < 1e-6 && (f.offset_mm[1].unwrap() - 0.2).abs() < 1e-6);
            assert!(f.rms_mm < 1e-6 && f.fit_percent > 99.99);
            assert_eq!(f.gain[0], None);
        }
    }

    #[test]
    fn noise_costs_little_and_its_spread_is_reported() {
        for (d, tau, seed) in [(3, 0.015, 2), (1, 0.030, 3), (5, 0.010, 4)] {
            let f = fit(&trace(d, tau, 0.05, seed), 30).unwrap();
            assert_eq!(f.dead_time_cycles, d, "{f:?}");
            assert!(f.runner_up_ratio > 1.05, "{f:?}");
            assert!((f.lag_s - tau).abs() < 0.1 * tau, "τ {} vs {tau}", f.lag_s);
            // The error is within four reported standard deviations.
            assert!((f.lag_s - tau).abs() < 4.0 * f.lag_std_s, "{} ± {} vs {tau}", f.lag_s, f.lag_std_s);
            assert!((f.rms_mm - 0.05).abs() < 0.01, "{}", f.rms_mm);
        }
    }

    #[test]
    fn gaps_need_nothing_special() {
        let mut t = trace(4, 0.020, 0.0, 1);
        for i in (0..t.y.len()).filter(|i| i % 7 == 3 || (400..460).contains(i)) {
            t.y[i] = None;
        }
        let f = fit(&t, 30).unwrap();
        assert_eq!(f.dead_time_cycles, 4);
        assert!((f.lag_s - 0.020).abs() < 1e-6);
    }

    #[test]
    fn a_robot_that_does_not_move_has_gain_zero_and_unusable_input_is_refused() {
        let mut t = trace(2, 0.015, 0.0, 1);
        for y in &mut t.y {
            *y = Some([0.0, 0.0, 0.0]);
        }
        let f = fit(&t, 30).unwrap();
        assert!(f.gain[1].unwrap().abs() < 1e-9, "{f:?}");
        let mut flat = t.clone();
        for u in &mut flat.u {
            u[1] = 0.0;
        }
        assert_eq!(fit(&flat, 30), Err(ServoFitError::NoExcitation { axis: 1 }));
        let mut few = t.clone();
        few.y.iter_mut().skip(20).for_each(|y| *y = None);
        assert!(matches!(fit(&few, 30), Err(ServoFitError::TooFewSamples { .. })));
        assert_eq!(fit(&Trace { excited: [false; 3], ..t }, 30), Err(ServoFitError::BadTrace));
    }
}
