//! The MPI lab frame → table frame T (DESIGN §2), estimated from the data,
//! and bounce detection on real trajectories.
//!
//! The transform is a small value type ([`LabToTable`]): a rotation by `yaw`
//! about z after moving the table's centre `origin` (lab coordinates) to
//! the origin, p_T = R_z(−yaw)(p_lab − origin). The numbers in use are the
//! named constant [`MPI_LAB_TO_TABLE`]; [`estimate_frame`] recomputes the
//! evidence from the data so a revision is one edit, checked by a test.
//! `docs/real-data.md` explains each number and its uncertainty.

use topspin_core::physics::Vec3;

use super::mpi::RealTrajectory;
use super::polyfit::{eval, eval_deriv, polyfit};

/// Ball radius, m: the ball's centre at contact is surface + r.
pub const BALL_RADIUS: f64 = 0.02;

/// Lab → table frame: p_T = R_z(−yaw)(p_lab − origin).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LabToTable {
    /// The angle of the table's +x axis from the lab's +x axis, about z, rad.
    pub yaw: f64,
    /// The centre of the playing surface in lab coordinates, m.
    pub origin: [f64; 3],
}

/// The transform used for the MPI launcher set (evidence and reasoning in
/// `docs/real-data.md`; [`estimate_frame`] recomputes it):
///
/// - surface z = 0.7394 m (lab): median over 73 first contacts of the
///   contact height (where the free-flight parabolas before and after
///   meet) minus r. Statistical: SE 0.2 mm, spread 1.2 mm. This is the
///   *effective* plane of the bounce model (contact at z = r); the physical
///   top may sit a few mm higher (ball compression, tracker bias), which
///   is why it is 5.5 mm below the data README's 0.745 m.
/// - yaw = 0: the lab's x axis is taken as the table's long axis. Shot
///   headings are +0.5° (median), spread 1.8°: launcher aim and table yaw
///   cannot be told apart; a 1° error moves a point 2 m away by 35 mm
///   sideways.
/// - net at lab x = 1.37 m, i.e. lab x = 0 is the opponent's end line. The
///   data bound it to [1.19, 1.68] m (first bounces on the robot's half;
///   every ball clears the net); the robot set is cut at x = 2.740 m
///   = 2 × 1.37; the launcher exit is at x ≈ 0.00–0.02 m. Uncertainty
///   ±0.1 m (judgement, not a statistic).
/// - centre line at lab y = 0 (the launcher's y ≈ 0.005 m); nothing pins
///   it better than ±0.2 m; it matters only for the table's side edges.
pub const MPI_LAB_TO_TABLE: LabToTable = LabToTable { yaw: 0.0, origin: [1.37, 0.0, 0.7394] };

impl LabToTable {
    /// A lab point in the table frame.
    pub fn point(&self, p: &Vec3) -> Vec3 {
        let d = p - Vec3::from(self.origin);
        let (s, c) = self.yaw.sin_cos();
        Vec3::new(c * d.x + s * d.y, -s * d.x + c * d.y, d.z)
    }

    /// A lab direction (velocity) in the table frame.
    pub fn vector(&self, v: &Vec3) -> Vec3 {
        let (s, c) = self.yaw.sin_cos();
        Vec3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z)
    }

    /// A table point in the lab frame (the inverse of [`Self::point`]).
    pub fn point_to_lab(&self, p: &Vec3) -> Vec3 {
        let (s, c) = self.yaw.sin_cos();
        Vec3::new(c * p.x - s * p.y, s * p.x + c * p.y, p.z) + Vec3::from(self.origin)
    }

    /// Lab samples in the table frame.
    pub fn samples(&self, s: &[(f64, Vec3)]) -> Vec<(f64, Vec3)> {
        s.iter().map(|(t, p)| (*t, self.point(p))).collect()
    }
}

/// One table contact found in recorded samples (in the frame of the
/// samples given).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DetectedBounce {
    /// Contact time, s: where the parabolas before and after meet.
    pub t: f64,
    /// Ball centre at contact.
    pub pos: Vec3,
    /// Velocity just before the contact, from the fit before it, m/s.
    pub vel_in: Vec3,
    /// Velocity just after the contact, from the fit after it, m/s.
    pub vel_out: Vec3,
    /// Index of the lowest sample.
    pub sample: usize,
    /// False when the parabolas did not intersect between the samples and
    /// the lowest sample stands in for the contact.
    pub refined: bool,
}

/// How bounces are searched for.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BounceSearch {
    /// Height of the surface in the samples' frame, m (0 in T).
    pub surface_z: f64,
    /// A lowest sample must lie below surface + r + this, m.
    pub band: f64,
    /// Most samples fitted on each side.
    pub side_samples: usize,
    /// Fewest samples on each side for a contact to be accepted.
    pub min_side_samples: usize,
    /// Samples farther than this from the sample next to the contact are
    /// not fitted, s.
    pub side_window: f64,
    /// No contact is located across a longer gap between samples, s.
    pub max_contact_gap: f64,
}

/// The fewest samples on each side of a bounce for the two parabolas.
pub(crate) const MIN_SIDE_SAMPLES: usize = 4;

impl BounceSearch {
    /// Search in the table frame (surface z = 0).
    pub fn table() -> Self {
        Self::at_surface(0.0)
    }

    /// A search with the default settings for a surface at height `surface_z`
    /// (m, in the samples' frame).
    pub fn at_surface(surface_z: f64) -> Self {
        BounceSearch {
            surface_z,
            band: 0.05,
            side_samples: 7,
            min_side_samples: MIN_SIDE_SAMPLES,
            side_window: 0.04,
            max_contact_gap: 0.05,
        }
    }
}

/// Quadratic fits of x, y, z against τ = t − t0 over `pts`; the z residual
/// sum of squares.
fn side_fit(pts: &[(f64, Vec3)], t0: f64) -> Option<([[f64; 3]; 3], f64)> {
    let mut c = [[0.0; 3]; 3];
    let mut buf = [(0.0, 0.0); 16];
    let n = pts.len().min(buf.len());
    for axis in 0..3 {
        for (b, (t, p)) in buf.iter_mut().zip(pts) {
            *b = (t - t0, p[axis]);
        }
        c[axis] = polyfit::<3>(&buf[..n])?;
    }
    let rss = pts.iter().map(|(t, p)| (p.z - eval(&c[2], t - t0)).powi(2)).sum();
    Some((c, rss))
}

/// Finds the table contacts in `s`: each lowest sample near the surface
/// with the ball falling before and rising after. Around it a parabola is
/// fitted to each side (both ways of assigning the lowest sample are tried,
/// the better fit kept), and the contact is where the two meet, between the
/// last sample before and the first after: a sub-sample time.
pub fn detect_bounces(s: &[(f64, Vec3)], search: &BounceSearch) -> Vec<DetectedBounce> {
    let mut out = Vec::new();
    let limit = search.surface_z + BALL_RADIUS + search.band;
    let mut i = 1;
    while i + 1 < s.len() {
        let z = s[i].1.z;
        if !(z < limit && z <= s[i - 1].1.z && z <= s[i + 1].1.z) {
            i += 1;
            continue;
        }
        if let Some(b) = bounce_at(s, i, search) {
            out.push(b);
            i += search.min_side_samples;
        } else {
            i += 1;
        }
    }
    out
}

fn bounce_at(s: &[(f64, Vec3)], i: usize, search: &BounceSearch) -> Option<DetectedBounce> {
    let t0 = s[i].0;
    let mut best: Option<(f64, DetectedBounce)> = None;
    // split = index of the first sample after the contact: i (lowest sample
    // belongs to "before") + 1, or i (it belongs to "after"). Each side's
    // window is measured from its sample next to the contact, so a dropped
    // frame at the bounce does not starve one side.
    for split in [i + 1, i] {
        if split == 0 || split >= s.len() || s[split].0 - s[split - 1].0 > search.max_contact_gap {
            continue;
        }
        let (t_before, t_after) = (s[split - 1].0, s[split].0);
        let lo = split.saturating_sub(search.side_samples);
        let before: Vec<usize> = (lo..split).filter(|&k| t_before - s[k].0 <= search.side_window).collect();
        let hi = (split + search.side_samples).min(s.len());
        let after: Vec<usize> = (split..hi).filter(|&k| s[k].0 - t_after <= search.side_window).collect();
        if before.len() < search.min_side_samples || after.len() < search.min_side_samples {
            continue;
        }
        let pts_b: Vec<_> = before.iter().map(|&k| s[k]).collect();
        let pts_a: Vec<_> = after.iter().map(|&k| s[k]).collect();
        let (Some((cb, rb)), Some((ca, ra))) = (side_fit(&pts_b, t0), side_fit(&pts_a, t0)) else {
            continue;
        };
        // Contact: z_b(τ) = z_a(τ) between the last "before" and the first
        // "after" sample (a little slack for noise).
        let (tl, tf) = (s[split - 1].0 - t0, s[split].0 - t0);
        let slack = 0.25 * (tf - tl);
        let d = [cb[2][0] - ca[2][0], cb[2][1] - ca[2][1], cb[2][2] - ca[2][2]];
        let roots = quadratic_roots(d[2], d[1], d[0]);
        let tau = roots
            .into_iter()
            .flatten()
            .filter(|r| *r >= tl - slack && *r <= tf + slack)
            .min_by(|a, b| a.abs().total_cmp(&b.abs()));
        let (tau, refined) = match tau {
            Some(t) => (t, true),
            None => (s[i].0 - t0, false),
        };
        let vel = |c: &[[f64; 3]; 3]| Vec3::new(eval_deriv(&c[0], tau), eval_deriv(&c[1], tau), eval_deriv(&c[2], tau));
        let (vel_in, vel_out) = (vel(&cb), vel(&ca));
        if !(vel_in.z < 0.0 && vel_out.z > 0.0) {
            continue;
        }
        let pos = Vec3::new(
            0.5 * (eval(&cb[0], tau) + eval(&ca[0], tau)),
            0.5 * (eval(&cb[1], tau) + eval(&ca[1], tau)),
            if refined { eval(&cb[2], tau) } else { s[i].1.z },
        );
        let score = (rb + ra) / (before.len() + after.len()) as f64 + if refined { 0.0 } else { 1.0 };
        let b = DetectedBounce { t: t0 + tau, pos, vel_in, vel_out, sample: i, refined };
        if best.as_ref().is_none_or(|(sc, _)| score < *sc) {
            best = Some((score, b));
        }
    }
    best.map(|(_, b)| b)
}

/// Real roots of a x² + b x + c (linear when a ≈ 0).
fn quadratic_roots(a: f64, b: f64, c: f64) -> [Option<f64>; 2] {
    if a.abs() < 1e-12 {
        return [(b.abs() > 1e-12).then(|| -c / b), None];
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return [None, None];
    }
    let q = -0.5 * (b + b.signum() * disc.sqrt());
    let r1 = q / a;
    let r2 = if q != 0.0 { c / q } else { r1 };
    [Some(r1), Some(r2)]
}

/// The evidence in the data for the lab → table transform.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameEstimate {
    /// Bounces found (first contact of each trajectory that has one).
    pub bounces: usize,
    /// Trajectories in which no contact was found (recording ends first).
    pub without_bounce: usize,
    /// Surface height: median of (contact z − r), lab frame, m.
    pub surface_z: f64,
    /// Standard error of `surface_z` (1.2533 σ/√n for a median, σ the
    /// robust spread), m.
    pub surface_se: f64,
    /// Robust spread of the contact heights (1.4826 · MAD), m.
    pub surface_spread: f64,
    /// Least-squares plane through the contacts: slope along lab x (rad);
    /// shows the tilt of the table and of the tracker's calibration.
    pub slope_x: f64,
    /// The same plane's slope along lab y, rad.
    pub slope_y: f64,
    /// Heading of the shots (atan2 of the horizontal velocity before the
    /// bounce): median, rad.
    pub heading: f64,
    /// Spread of the headings (1.4826 · MAD), rad.
    pub heading_spread: f64,
    /// Range of lab x of the first bounces.
    pub bounce_x: (f64, f64),
    /// Bounds on the net's lab x from "every first bounce lies on the
    /// robot's half": [max bounce x − L/2, min bounce x].
    pub net_x_bounds: (f64, f64),
    /// Upper bound on the net's lab x from "every ball clears the net": the
    /// smallest x at which a falling ball is below surface + net + r.
    pub net_clearance_x: f64,
    /// First sample x (launcher exit): min and median.
    pub launch_x: (f64, f64),
    /// Largest x in the robot set (it is cut there).
    pub robot_set_max_x: Option<f64>,
}

/// Height of the net above the surface, m (ITTF).
const NET_HEIGHT: f64 = 0.1525;
/// Half the table length, m (ITTF).
const HALF_LENGTH: f64 = 1.37;

/// The lab-frame surface height assumed before it is estimated (the data
/// README's 0.745 m).
pub(crate) const NOMINAL_SURFACE_Z: f64 = 0.745;

fn mad_spread(v: &[f64], centre: f64) -> f64 {
    let mut d: Vec<f64> = v.iter().map(|x| (x - centre).abs()).collect();
    1.4826 * super::mpi::median(&mut d)
}

/// Estimates the lab → table evidence from every trajectory (lab frame).
pub fn estimate_frame(trajs: &[RealTrajectory]) -> FrameEstimate {
    let search = BounceSearch::at_surface(NOMINAL_SURFACE_Z);
    let mut contacts = Vec::new();
    let mut headings = Vec::new();
    let mut clearance = f64::INFINITY;
    let mut launch = Vec::new();
    let mut without = 0;
    for tr in trajs {
        let s = &tr.samples;
        launch.push(s[0].1.x);
        let first = detect_bounces(s, &search).into_iter().next();
        match first {
            Some(b) => {
                contacts.push(b.pos);
                headings.push(b.vel_in.y.atan2(b.vel_in.x));
            }
            None => without += 1,
        }
        // Clearance: along the falling branch before the first bounce (or
        // the end), the first x where z < surface + net + r.
        let end = first.map_or(s.len(), |b| b.sample);
        let apex = (0..end).max_by(|&a, &b| s[a].1.z.total_cmp(&s[b].1.z));
        if let Some(apex) = apex {
            let level = NOMINAL_SURFACE_Z + NET_HEIGHT + BALL_RADIUS;
            if let Some(k) = (apex..end).find(|&k| s[k].1.z < level) {
                clearance = clearance.min(s[k].1.x);
            }
        }
    }
    let mut heights: Vec<f64> = contacts.iter().map(|p| p.z - BALL_RADIUS).collect();
    let surface_z = super::mpi::median(&mut heights);
    let spread = mad_spread(&heights, surface_z);
    let n = contacts.len().max(1) as f64;
    let (slope_x, slope_y) = plane_slopes(&contacts);
    let heading = super::mpi::median(&mut headings.clone());
    let heading_spread = mad_spread(&headings, heading);
    let bx_min = contacts.iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
    let bx_max = contacts.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max);
    let robot_set_max_x = trajs
        .iter()
        .filter(|t| t.set == "robot_no_spin")
        .flat_map(|t| t.samples.iter().map(|s| s.1.x))
        .reduce(f64::max);
    FrameEstimate {
        bounces: contacts.len(),
        without_bounce: without,
        surface_z,
        surface_se: 1.2533 * spread / n.sqrt(),
        surface_spread: spread,
        slope_x,
        slope_y,
        heading,
        heading_spread,
        bounce_x: (bx_min, bx_max),
        net_x_bounds: (bx_max - HALF_LENGTH, bx_min),
        net_clearance_x: clearance,
        launch_x: (launch.iter().copied().fold(f64::INFINITY, f64::min), super::mpi::median(&mut launch)),
        robot_set_max_x,
    }
}

/// Slopes (atan) of the least-squares plane z = a + b x + c y.
fn plane_slopes(p: &[Vec3]) -> (f64, f64) {
    if p.len() < 3 {
        return (f64::NAN, f64::NAN);
    }
    let n = p.len() as f64;
    let m = p.iter().sum::<Vec3>() / n;
    let (mut sxx, mut sxy, mut syy, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for q in p {
        let d = q - m;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
        sxz += d.x * d.z;
        syz += d.y * d.z;
    }
    let det = sxx * syy - sxy * sxy;
    if det.abs() < 1e-15 {
        return (f64::NAN, f64::NAN);
    }
    let b = (sxz * syy - syz * sxy) / det;
    let c = (syz * sxx - sxz * sxy) / det;
    (b.atan(), c.atan())
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::physics::{BallState, PhysicsParams, Propagator, StopAt, Table};

    #[test]
    fn transform_round_trips() {
        let f = LabToTable { yaw: 0.3, origin: [1.0, -0.5, 0.75] };
        let p = Vec3::new(2.0, 0.3, 1.1);
        let q = f.point_to_lab(&f.point(&p));
        assert!((p - q).norm() < 1e-12);
        // The lab point at `origin` is the table's centre.
        assert!(f.point(&Vec3::from(f.origin)).norm() < 1e-12);
    }

    #[test]
    fn finds_a_simulated_bounce_to_sub_sample_time() {
        let p = PhysicsParams::paper();
        let prop = Propagator::new(p.flight_model(), p.bounce_model(), Table::default());
        let mut s = BallState::new(Vec3::new(-1.2, 0.0, 0.3), Vec3::new(5.0, 0.2, 0.5), Vec3::zeros());
        let mut t = 0.0;
        let e = prop.advance(&mut s, &mut t, &StopAt::time(2.0));
        let topspin_core::physics::Event::Bounce { t: t_b, before } = e else { panic!("{e:?}") };
        // Sample the true path at 180 Hz, with an offset phase.
        let s0 = BallState::new(Vec3::new(-1.2, 0.0, 0.3), Vec3::new(5.0, 0.2, 0.5), Vec3::zeros());
        let dt = 1.0 / 180.0;
        let mut samples = Vec::new();
        for k in 0..100 {
            let tk = 0.0013 + k as f64 * dt;
            let mut st = s0;
            let mut tt = 0.0;
            loop {
                let ev = prop.advance(&mut st, &mut tt, &StopAt::time(tk));
                if matches!(ev, topspin_core::physics::Event::TimeLimit { .. }) {
                    break;
                }
            }
            samples.push((tk, st.pos));
        }
        let found = detect_bounces(&samples, &BounceSearch::table());
        assert_eq!(found.len(), 1, "{found:?}");
        let b = found[0];
        assert!(b.refined);
        assert!((b.t - t_b).abs() < 1e-3, "t {} vs {}", b.t, t_b);
        assert!((b.pos - before.pos).norm() < 3e-3, "{:?}", b.pos - before.pos);
        assert!((b.vel_in.z - before.vel.z).abs() < 0.1);
    }
}
