//! The circular-segment correction (paper §II-D).
//!
//! A logo at the edge of the visible hemisphere is seen cut: a circular
//! segment of the logo's disc. The normalised mean of its points lies inside
//! the segment, short of the logo's true centre towards the image centre.
//! With the logo's radius r known (measured on the ball) and the segment's
//! area A estimated, the segment's half-angle α solves
//! A = r²/2 · (2α − sin 2α), the distance from the disc's centre to the
//! segment's centroid is d = 4 r sin³α / (3 (2α − sin 2α)), and the centroid
//! is turned away from the view axis by d (an arc on the unit sphere).
//!
//! Two departures from the paper's text, both stated: the area comes from
//! the segmented pixels themselves (each pixel's area on the unit sphere is
//! its disc area over the surface's z, clamped), not from π × the mean
//! contour distance; and "rotate by β around (0, 0, 1)" is read as turning
//! the centroid away from the view axis z by β (a rotation about z would not
//! move it towards the rim).

use nalgebra::{Rotation3, Unit};

use crate::physics::Vec3;

/// Area of the circular segment of half-angle `alpha` of a disc of radius `r`.
pub(crate) fn segment_area(alpha: f64, r: f64) -> f64 {
    0.5 * r * r * (2.0 * alpha - (2.0 * alpha).sin())
}

/// The half-angle α ∈ [0, π] of the segment with area `area` of a disc of
/// radius `r` (clamped to the full disc). Bisection; no allocation.
pub(crate) fn segment_half_angle(area: f64, r: f64) -> f64 {
    let full = std::f64::consts::PI * r * r;
    if area.is_nan() || area <= 0.0 {
        return 0.0;
    }
    if area >= full {
        return std::f64::consts::PI;
    }
    let (mut lo, mut hi) = (0.0, std::f64::consts::PI);
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if segment_area(mid, r) < area {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Distance from a disc's centre to the centroid of its segment of
/// half-angle `alpha` (0 for the full disc).
pub(crate) fn centroid_distance(alpha: f64, r: f64) -> f64 {
    let den = 3.0 * (2.0 * alpha - (2.0 * alpha).sin());
    if den <= 1e-12 {
        // α → 0: the sliver's centroid tends to the chord at distance r.
        return r;
    }
    4.0 * r * alpha.sin().powi(3) / den
}

/// Corrects the centroid `c` (unit vector, view frame: z towards the
/// camera) of a logo cut by the visible hemisphere's edge, from the area
/// `area` seen (on the unit sphere) and the logo's radius `r` (in ball
/// radii). Returns `c` unchanged where the full logo is seen or `c` lies on
/// the view axis.
pub(crate) fn correct(c: &Vec3, area: f64, r: f64) -> Vec3 {
    let alpha = segment_half_angle(area, r);
    let d = centroid_distance(alpha, r);
    let axis = Vec3::z().cross(c);
    if d <= 0.0 || axis.norm() < 1e-9 || alpha >= std::f64::consts::PI {
        return *c;
    }
    Rotation3::from_axis_angle(&Unit::new_normalize(axis), d) * c
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn the_segment_formulas_have_their_known_values() {
        // Half disc: α = π/2, area πr²/2, centroid at 4r/(3π).
        let r = 0.25;
        assert!((segment_area(PI / 2.0, r) - PI * r * r / 2.0).abs() < 1e-12);
        assert!((segment_half_angle(PI * r * r / 2.0, r) - PI / 2.0).abs() < 1e-9);
        assert!((centroid_distance(PI / 2.0, r) - 4.0 * r / (3.0 * PI)).abs() < 1e-12);
        // Full disc: no offset.
        assert!(centroid_distance(PI, r).abs() < 1e-12);
        assert_eq!(segment_half_angle(1.0, r), PI);
        for a in [0.3, 1.0, 2.0, 2.8] {
            assert!((segment_half_angle(segment_area(a, r), r) - a).abs() < 1e-9);
        }
    }

    #[test]
    fn the_correction_turns_away_from_the_view_axis() {
        let c = Vec3::new(0.9, 0.0, 0.2).normalize();
        let r = 0.25;
        let out = correct(&c, segment_area(1.0, r), r);
        assert!((out.norm() - 1.0).abs() < 1e-12);
        assert!(out.z < c.z && out.y.abs() < 1e-12);
        let turned = c.angle(&out);
        assert!((turned - centroid_distance(1.0, r)).abs() < 1e-12);
        // A full logo is left alone.
        assert_eq!(correct(&c, PI * r * r, r), c);
    }
}
