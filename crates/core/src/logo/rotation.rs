//! Fitting the rotation to a sequence of logo positions (paper §II-E),
//! shared by every logo source (background subtraction now, a CNN later).
//!
//! Input: the logo's centre on the unit sphere per camera frame, `None`
//! where the logo was not seen, all in one fixed frame (the camera's). The
//! fit:
//!
//! 1. a plane n·p = d through the seen positions that minimises both the
//!    distances to the plane and the distances to the circle where the
//!    plane cuts the unit sphere (least-squares plane, then Gauss–Newton
//!    on the sum of both residuals);
//! 2. the positions projected on the plane and the signed angle between
//!    consecutive seen positions about n; n's sign is the one that makes
//!    the rotation positive (right hand about the axis);
//! 3. across a gap of two or more unseen frames the ball went round the
//!    back: the paper's half-revolution rule ([`GapRule::Paper`]: the large
//!    angle 2π − ω instead of the short ω), or ([`GapRule::Directed`], the
//!    default) the angle in the direction of rotation, in [0, 2π), plus the
//!    whole turns that the rate seen over short steps predicts;
//! 4. a regression line through the accumulated angle against time: its
//!    slope is the angular speed; ω = slope · n.
//!
//! The result is in the frame of the input; rotate it into the table frame
//! with the camera calibration ([`RotationFit::rotated`]). Allocation-free.

use nalgebra::{Matrix3, Rotation3, SymmetricEigen};

use crate::physics::Vec3;

/// One frame of a logo sequence: capture time (s, any fixed origin) and
/// the logo's centre on the unit sphere, or `None` when it was not seen.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LogoSample {
    /// Capture time, s (any fixed origin).
    pub t: f64,
    /// The logo's centre on the unit sphere, or `None` when not seen.
    pub pos: Option<Vec3>,
}

impl LogoSample {
    /// A sample at time `t` (s) with logo centre `pos`.
    pub fn new(t: f64, pos: Option<Vec3>) -> Self {
        LogoSample { t, pos }
    }
}

/// What a gap of two or more unseen frames means.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum GapRule {
    /// The paper: the large angle 2π − ω instead of the short angle ω.
    Paper,
    /// The angle in the rotation's direction, in [0, 2π), plus whole turns
    /// predicted by the rate seen over consecutive frames.
    Directed,
}

/// Options of the rotation fit.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RotationFitConfig {
    /// Fewest seen positions.
    pub min_seen: usize,
    /// How a gap of two or more unseen frames is bridged.
    pub gap_rule: GapRule,
    /// Gauss–Newton steps refining the plane.
    pub plane_iterations: usize,
    /// Smallest spread of the seen positions (rad, RMS about their mean)
    /// that can define a plane.
    pub min_spread: f64,
}

impl Default for RotationFitConfig {
    fn default() -> Self {
        RotationFitConfig { min_seen: 4, gap_rule: GapRule::Directed, plane_iterations: 6, min_spread: 0.03 }
    }
}

/// A fitted rotation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct RotationFit {
    /// Angular velocity, rad/s, in the input's frame.
    pub spin: Vec3,
    /// Unit rotation axis (right hand), input frame.
    pub axis: Vec3,
    /// Angular speed, rad/s (the regression slope).
    pub rate: f64,
    /// The plane's offset d (n·p = d): the logo's latitude sin about the axis.
    pub plane_offset: f64,
    /// Seen positions used.
    pub seen: usize,
    /// RMS distance of the seen positions to the fitted circle.
    pub rms_circle: f64,
    /// RMS residual of the regression line, rad.
    pub rms_angle: f64,
}

impl RotationFit {
    /// The same fit with vectors rotated by `r` (e.g. camera → table).
    pub fn rotated(&self, r: &Rotation3<f64>) -> RotationFit {
        RotationFit { spin: r * self.spin, axis: r * self.axis, ..*self }
    }
}

/// Why no rotation could be fitted.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum RotationFitError {
    /// Fewer seen positions than [`RotationFitConfig::min_seen`].
    #[error("logo seen in {seen} frames (need {needed})")]
    TooFewSeen {
        /// Frames in which the logo was seen.
        seen: usize,
        /// The least number needed (`min_seen`, at least 3).
        needed: usize,
    },
    /// A position is not a finite unit vector, or times do not increase.
    #[error("logo positions must be finite unit vectors at increasing times")]
    BadInput,
    /// The seen positions hardly move: no plane (the logo turns in place).
    #[error("logo positions spread only {spread_deg:.1}°: no rotation plane")]
    NoSpread {
        /// RMS spread of the seen positions about their mean, degrees.
        spread_deg: f64,
    },
    /// No two seen positions are one or two frames apart: the direction of
    /// rotation is unknown.
    #[error("no consecutive logo positions: direction of rotation unknown")]
    NoDirection,
}

fn seen(samples: &[LogoSample]) -> impl Iterator<Item = (usize, f64, Vec3)> + '_ {
    samples.iter().enumerate().filter_map(|(i, s)| s.pos.map(|p| (i, s.t, p)))
}

/// Σ of squared plane and circle residuals for the plane (n, d).
fn plane_cost(samples: &[LogoSample], n: &Vec3, d: f64) -> f64 {
    let rho = (1.0 - d * d).max(0.0).sqrt();
    seen(samples)
        .map(|(_, _, p)| {
            let h = n.dot(&p) - d;
            let q = (1.0 - n.dot(&p).powi(2)).max(0.0).sqrt();
            h * h + h * h + (q - rho).powi(2)
        })
        .sum()
}

/// Fits the rotation to `samples` (in time order). See the module doc.
pub fn fit_rotation(samples: &[LogoSample], cfg: &RotationFitConfig) -> Result<RotationFit, RotationFitError> {
    let mut count = 0usize;
    let mut mean = Vec3::zeros();
    let mut last_t = f64::NEG_INFINITY;
    for s in samples {
        if !(s.t.is_finite() && s.t > last_t) {
            return Err(RotationFitError::BadInput);
        }
        last_t = s.t;
        if let Some(p) = s.pos {
            if !(p.iter().all(|c| c.is_finite()) && (p.norm() - 1.0).abs() < 1e-6) {
                return Err(RotationFitError::BadInput);
            }
            count += 1;
            mean += p;
        }
    }
    if count < cfg.min_seen.max(3) {
        return Err(RotationFitError::TooFewSeen { seen: count, needed: cfg.min_seen.max(3) });
    }
    mean /= count as f64;
    let mut cov = Matrix3::zeros();
    for (_, _, p) in seen(samples) {
        let e = p - mean;
        cov += e * e.transpose();
    }
    cov /= count as f64;
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let spread = (eig.eigenvalues[order[1]] + eig.eigenvalues[order[2]]).max(0.0).sqrt();
    if spread < cfg.min_spread {
        return Err(RotationFitError::NoSpread { spread_deg: spread.to_degrees() });
    }
    let mut n: Vec3 = eig.eigenvectors.column(order[0]).into_owned().normalize();
    let mut d = n.dot(&mean);

    // Gauss–Newton on (tilt a, tilt b, d) with a numeric Jacobian.
    for _ in 0..cfg.plane_iterations {
        let t1 = n.cross(&if n.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() }).normalize();
        let t2 = n.cross(&t1);
        let params = |a: f64, b: f64| (n + t1 * a + t2 * b).normalize();
        let eps = 1e-6;
        let mut jtj = Matrix3::zeros();
        let mut jtr = Vec3::zeros();
        // Forward differences per residual: allocation-free.
        let n_a = params(eps, 0.0);
        let n_b = params(0.0, eps);
        let rho = |dd: f64| (1.0 - dd * dd).max(0.0).sqrt();
        for (_, _, p) in seen(samples) {
            let res = |nn: &Vec3, dd: f64| -> (f64, f64) {
                let h = nn.dot(&p) - dd;
                let q = (1.0 - nn.dot(&p).powi(2)).max(0.0).sqrt();
                (h, (q - rho(dd)).abs().hypot(h))
            };
            let r0 = res(&n, d);
            let ra = res(&n_a, d);
            let rb = res(&n_b, d);
            let rd = res(&n, d + eps);
            for (r, ja, jb, jd) in [
                (r0.0, (ra.0 - r0.0) / eps, (rb.0 - r0.0) / eps, (rd.0 - r0.0) / eps),
                (r0.1, (ra.1 - r0.1) / eps, (rb.1 - r0.1) / eps, (rd.1 - r0.1) / eps),
            ] {
                let j = Vec3::new(ja, jb, jd);
                jtj += j * j.transpose();
                jtr += j * r;
            }
        }
        let Some(step) = (jtj + Matrix3::identity() * 1e-12).lu().solve(&(-jtr)) else { break };
        let n_new = params(step.x, step.y);
        let d_new = (d + step.z).clamp(-0.999_999, 0.999_999);
        if plane_cost(samples, &n_new, d_new) <= plane_cost(samples, &n, d) {
            n = n_new;
            d = d_new;
        } else {
            break;
        }
        if step.norm() < 1e-10 {
            break;
        }
    }

    // Direction: the sign of the summed short steps (0 or 1 frame unseen).
    let proj = |p: &Vec3, n: &Vec3| p - n * n.dot(p);
    let signed = |a: &Vec3, b: &Vec3, n: &Vec3| -> f64 {
        let (qa, qb) = (proj(a, n), proj(b, n));
        qa.cross(&qb).dot(n).atan2(qa.dot(&qb))
    };
    let mut prev: Option<(usize, f64, Vec3)> = None;
    let (mut dir_sum, mut short_pairs, mut short_angle, mut short_dt) = (0.0, 0usize, 0.0, 0.0);
    for (i, t, p) in seen(samples) {
        if let Some((j, tj, pj)) = prev
            && i - j <= 2
        {
            let a = signed(&pj, &p, &n);
            dir_sum += a;
            short_pairs += 1;
            short_angle += a;
            short_dt += t - tj;
        }
        prev = Some((i, t, p));
    }
    if short_pairs == 0 {
        return Err(RotationFitError::NoDirection);
    }
    if dir_sum < 0.0 {
        n = -n;
        d = -d;
        short_angle = -short_angle;
    }
    let rate_short = short_angle / short_dt;

    // Accumulated angles and the regression line, in one pass.
    let tau = std::f64::consts::TAU;
    let (mut st, mut sp, mut stt, mut stp, mut spp, mut m) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0f64);
    let mut phi = 0.0;
    let mut prev: Option<(usize, f64, Vec3)> = None;
    let t0 = samples[0].t;
    for (i, t, p) in seen(samples) {
        if let Some((j, tj, pj)) = prev {
            let a = signed(&pj, &p, &n);
            let unseen = i - j - 1;
            let step = match (cfg.gap_rule, unseen) {
                (GapRule::Paper, 0 | 1) => a.abs(),
                (GapRule::Paper, _) => tau - a.abs(),
                (GapRule::Directed, 0 | 1) => a,
                (GapRule::Directed, _) => {
                    let fwd = a.rem_euclid(tau);
                    let turns = ((rate_short * (t - tj) - fwd) / tau).round().max(0.0);
                    fwd + turns * tau
                }
            };
            phi += step;
        }
        let x = t - t0;
        st += x;
        sp += phi;
        stt += x * x;
        stp += x * phi;
        spp += phi * phi;
        m += 1.0;
        prev = Some((i, t, p));
    }
    let var_t = stt - st * st / m;
    let slope = (stp - st * sp / m) / var_t;
    let intercept = (sp - slope * st) / m;
    let sse = (spp - 2.0 * slope * stp - 2.0 * intercept * sp
        + slope * slope * stt
        + 2.0 * slope * intercept * st
        + m * intercept * intercept)
        .max(0.0);
    let rms_circle = (plane_cost(samples, &n, d) / (2.0 * m)).sqrt();
    Ok(RotationFit {
        spin: n * slope,
        axis: n,
        rate: slope,
        plane_offset: d,
        seen: count,
        rms_circle,
        rms_angle: (sse / m).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Unit;

    /// Logo positions of a ball spinning with `w` (rad/s) from `p0`, seen
    /// where the position's z (towards the camera) exceeds `z_min`.
    fn sequence(w: Vec3, p0: Vec3, n: usize, z_min: f64) -> Vec<LogoSample> {
        (0..n)
            .map(|k| {
                let t = 0.1 + k as f64 / 380.0;
                let p = Rotation3::new(w * t) * p0;
                LogoSample::new(t, (p.z > z_min).then_some(p))
            })
            .collect()
    }

    #[test]
    fn a_fully_visible_rotation_is_recovered() {
        let w = Vec3::new(0.3, -1.0, 0.2).normalize() * 150.0;
        let axis = Unit::new_normalize(w);
        // A logo 60° from the axis, starting on the camera side.
        let p0 = Rotation3::from_axis_angle(&Unit::new_normalize(axis.cross(&Vec3::x())), 1.0) * axis.into_inner();
        let s = sequence(w, p0, 20, -2.0);
        let fit = fit_rotation(&s, &RotationFitConfig::default()).unwrap();
        assert!((fit.spin - w).norm() < 1e-6 * w.norm(), "{fit:?}");
        assert!(fit.rms_angle < 1e-9 && fit.rms_circle < 1e-9);
    }

    #[test]
    fn gaps_behind_the_ball_are_bridged() {
        // 60 rps about −y: the logo is hidden half the time.
        let w = Vec3::new(0.0, -60.0 * std::f64::consts::TAU, 0.0);
        let p0 = Vec3::new(0.0, 0.2, 1.0).normalize();
        let s = sequence(w, p0, 30, 0.05);
        assert!(s.iter().any(|x| x.pos.is_none()));
        for rule in [GapRule::Paper, GapRule::Directed] {
            let fit = fit_rotation(&s, &RotationFitConfig { gap_rule: rule, ..Default::default() }).unwrap();
            assert!((fit.spin - w).norm() < 1e-6 * w.norm(), "{rule:?} {fit:?}");
        }
        // 87 rps with the logo missed for a while: a gap longer than a
        // turn, which the directed rule bridges with the rate it saw.
        let w = Vec3::new(0.0, 87.0 * std::f64::consts::TAU, 0.0);
        let mut s = sequence(w, p0, 30, 0.05);
        for x in &mut s[9..16] {
            x.pos = None;
        }
        let fit = fit_rotation(&s, &RotationFitConfig::default()).unwrap();
        assert!((fit.spin - w).norm() < 1e-6 * w.norm(), "{fit:?}");
        let paper = fit_rotation(&s, &RotationFitConfig { gap_rule: GapRule::Paper, ..Default::default() }).unwrap();
        assert!((paper.spin - w).norm() > 0.05 * w.norm(), "{paper:?}");
    }

    #[test]
    fn bad_and_degenerate_input_is_named() {
        let cfg = RotationFitConfig::default();
        let one = [LogoSample::new(0.0, Some(Vec3::z()))];
        assert!(matches!(fit_rotation(&one, &cfg), Err(RotationFitError::TooFewSeen { seen: 1, .. })));
        let still: Vec<_> = (0..8).map(|k| LogoSample::new(k as f64, Some(Vec3::z()))).collect();
        assert!(matches!(fit_rotation(&still, &cfg), Err(RotationFitError::NoSpread { .. })));
        let nan = [LogoSample::new(0.0, Some(Vec3::new(f64::NAN, 0.0, 1.0))); 4];
        assert_eq!(fit_rotation(&nan, &cfg), Err(RotationFitError::BadInput));
        let back: Vec<_> = (0..5).map(|k| LogoSample::new(-(k as f64), Some(Vec3::z()))).collect();
        assert_eq!(fit_rotation(&back, &cfg), Err(RotationFitError::BadInput));
        // Scattered single frames: direction unknown.
        let w = Vec3::new(0.0, 200.0, 0.0);
        let sparse: Vec<_> = sequence(w, Vec3::new(0.0, 0.3, 1.0).normalize(), 40, -2.0)
            .into_iter()
            .enumerate()
            .map(|(k, s)| if k % 4 == 0 { s } else { LogoSample::new(s.t, None) })
            .collect();
        assert_eq!(fit_rotation(&sparse, &cfg), Err(RotationFitError::NoDirection));
    }
}
