//! Ball extraction on the camera side (paper §II-A, after Tebbe et al.
//! 2018): the difference of a frame to the static background, a threshold
//! at a fraction of the strongest difference, each row filled between its
//! outermost ball pixels (so a dark logo does not punch a hole), and the
//! circle with the blob's area and centroid. What it measures is what the
//! TTI1 datagram carries as the ball's centre and radius.

/// Fraction of the strongest background difference in the crop at which a
/// pixel counts as ball.
pub(crate) const BALL_THRESHOLD_FRACTION: f32 = 0.3;

/// The least background difference (sum over R, G, B) that can be ball.
pub(crate) const BALL_THRESHOLD_MIN: u16 = 40;

/// The least area of a ball blob, px.
pub(crate) const BALL_MIN_AREA: usize = 30;

/// A measured ball circle in full-sensor pixels.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Circle {
    /// Centre column (centroid of the blob), px.
    pub u: f64,
    /// Centre row (centroid of the blob), px.
    pub v: f64,
    /// Radius of the disc with the blob's area, px.
    pub radius: f64,
}

/// Measures the ball in an RGB8 crop of `width` × `height` whose top-left
/// pixel is (x0, y0) on the sensor, against the background `bg` of the
/// same block. `None` when no blob of `BALL_MIN_AREA` pixels stands out
/// (or the buffers do not match the size). Allocates nothing.
pub fn measure_ball(rgb: &[u8], bg: &[u8], width: usize, height: usize, x0: i64, y0: i64) -> Option<Circle> {
    let n = width.checked_mul(height)?;
    if rgb.len() != 3 * n || bg.len() != 3 * n || n == 0 {
        return None;
    }
    let diff = |i: usize| -> u16 {
        (0..3).map(|c| (i16::from(rgb[3 * i + c]) - i16::from(bg[3 * i + c])).unsigned_abs()).sum()
    };
    let max = (0..n).map(diff).max()?;
    let thr = ((f32::from(max) * BALL_THRESHOLD_FRACTION) as u16).max(BALL_THRESHOLD_MIN);
    let (mut area, mut sx, mut sy) = (0usize, 0.0f64, 0.0f64);
    for row in 0..height {
        let base = row * width;
        let first = (0..width).find(|&c| diff(base + c) >= thr);
        let Some(first) = first else { continue };
        let last = (first..width).rev().find(|&c| diff(base + c) >= thr).unwrap_or(first);
        let len = last - first + 1;
        area += len;
        // Σ of the columns first..=last.
        sx += (first + last) as f64 * len as f64 / 2.0;
        sy += row as f64 * len as f64;
    }
    if area < BALL_MIN_AREA {
        return None;
    }
    let a = area as f64;
    Some(Circle { u: x0 as f64 + sx / a, v: y0 as f64 + sy / a, radius: (a / std::f64::consts::PI).sqrt() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_disc_with_a_hole_is_measured() {
        let (w, h) = (40usize, 40usize);
        let bg = vec![20u8; 3 * w * h];
        let mut rgb = bg.clone();
        let (cu, cv, r) = (18.3, 21.6, 9.0);
        for row in 0..h {
            for col in 0..w {
                let d = ((col as f64 - cu).powi(2) + (row as f64 - cv).powi(2)).sqrt();
                if d <= r {
                    // A dark "logo" inside.
                    let val = if (col as f64 - cu).abs() < 3.0 && (row as f64 - cv).abs() < 3.0 { 25 } else { 220 };
                    rgb[3 * (row * w + col)..3 * (row * w + col) + 3].fill(val);
                }
            }
        }
        let c = measure_ball(&rgb, &bg, w, h, 100, 200).unwrap();
        assert!((c.u - 100.0 - cu).abs() < 0.2 && (c.v - 200.0 - cv).abs() < 0.2, "{c:?}");
        assert!((c.radius - r).abs() < 0.5, "{c:?}");
        assert!(measure_ball(&bg, &bg, w, h, 0, 0).is_none());
        assert!(measure_ball(&rgb[..10], &bg, w, h, 0, 0).is_none());
    }
}
