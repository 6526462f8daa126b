//! Logo detection in one crop (paper §II-B…D): the pixels that differ from
//! the ball without its logo, projected onto the unit sphere, their
//! normalised mean, and the circular-segment correction.
//!
//! Per pixel inside the ball's circle (out to [`DetectorConfig::limb`] of
//! its radius; the rim itself mixes with the background):
//!
//! - (b) the ball without logo: a [`BallReference`], the per-cell median of
//!   the sequence's crops resampled on a grid over the ball's disc in its
//!   view frame (the logo moves from frame to frame, the shading does not);
//! - (c) colour threshold: on a coloured ball, a pixel whose chroma
//!   (max − min of R, G, B) falls below a fraction of the reference's is not
//!   ball-coloured;
//! - (d, e) the absolute difference to the reference, summed over R, G, B,
//!   above a threshold;
//! - (f) their union is the logo.
//!
//! Logo pixels are projected onto the unit sphere in the view frame
//! ([`BallView`]), averaged and normalised (the paper's centre), and where
//! the logo touches the rim, corrected as a circular segment
//! ([`super::segment`]). The hot path [`detect`] allocates nothing and
//! touches each pixel of the ball's bounding box once.

use crate::logo::segment;
use crate::logo::view::BallView;
use crate::physics::Vec3;

/// Cells per side of the reference grid over the ball's disc.
pub(crate) const REF_GRID: usize = 24;

/// An RGB8 crop placed on the sensor.
#[derive(Copy, Clone, Debug)]
pub struct CropImage<'a> {
    /// Column of the top-left pixel on the full sensor.
    pub x0: i64,
    /// Row of the top-left pixel on the full sensor.
    pub y0: i64,
    /// Crop width, px.
    pub width: usize,
    /// Crop height, px.
    pub height: usize,
    /// Row-major RGB8.
    pub rgb: &'a [u8],
}

impl<'a> CropImage<'a> {
    /// `None` unless `rgb` holds exactly width · height · 3 bytes.
    pub fn new(x0: i64, y0: i64, width: usize, height: usize, rgb: &'a [u8]) -> Option<Self> {
        (width.checked_mul(height)?.checked_mul(3)? == rgb.len()).then_some(CropImage { x0, y0, width, height, rgb })
    }

    #[inline]
    fn pixel(&self, col: usize, row: usize) -> [u8; 3] {
        let i = 3 * (row * self.width + col);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }
}

/// The ball without its logo: median appearance per cell of a grid over
/// the ball's disc (view frame, x right, y up, in ball radii).
#[derive(Clone, Debug, PartialEq)]
pub struct BallReference {
    /// Per cell: R, G, B and the chroma threshold (0 on a colourless
    /// ball), packed for one load per pixel.
    cells: [[u8; 4]; REF_GRID * REF_GRID],
    /// The ball is coloured (the colour threshold is used).
    pub coloured: bool,
}

#[inline]
fn cell_of(x: f64, y: f64) -> usize {
    let half = REF_GRID as f64 / 2.0;
    let gx = (((x + 1.0) * half) as isize).clamp(0, REF_GRID as isize - 1) as usize;
    let gy = (((1.0 - y) * half) as isize).clamp(0, REF_GRID as isize - 1) as usize;
    gy * REF_GRID + gx
}

fn chroma(p: [u8; 3]) -> u8 {
    p.iter().max().unwrap_or(&0) - p.iter().min().unwrap_or(&0)
}

impl BallReference {
    /// The per-cell median over `crops` (each with its ball's view);
    /// `colour_fraction` sets the colour threshold. `None` without crops.
    /// Cold path (allocates).
    pub fn from_crops(crops: &[(CropImage<'_>, BallView)], colour_fraction: f32) -> Option<Self> {
        if crops.is_empty() {
            return None;
        }
        let mut cells = [[0u8; 3]; REF_GRID * REF_GRID];
        let mut values: [Vec<u8>; 3] = Default::default();
        for (idx, cell) in cells.iter_mut().enumerate() {
            let (gx, gy) = (idx % REF_GRID, idx / REF_GRID);
            let mut x = (gx as f64 + 0.5) / REF_GRID as f64 * 2.0 - 1.0;
            let mut y = 1.0 - (gy as f64 + 0.5) / REF_GRID as f64 * 2.0;
            let r = x.hypot(y);
            if r > 0.97 {
                x *= 0.97 / r;
                y *= 0.97 / r;
            }
            values.iter_mut().for_each(Vec::clear);
            for (crop, view) in crops {
                let (du, dv) = view.disc_to_pixel_offset(x, y);
                let col = (view.u + du - crop.x0 as f64).round();
                let row = (view.v + dv - crop.y0 as f64).round();
                if col >= 0.0 && row >= 0.0 && (col as usize) < crop.width && (row as usize) < crop.height {
                    let p = crop.pixel(col as usize, row as usize);
                    for c in 0..3 {
                        values[c].push(p[c]);
                    }
                }
            }
            for c in 0..3 {
                if values[c].is_empty() {
                    continue;
                }
                values[c].sort_unstable();
                cell[c] = values[c][values[c].len() / 2];
            }
        }
        // Coloured: the middle of the ball has a chroma of at least a
        // third of its brightness.
        let (mut ch, mut br, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for (idx, cell) in cells.iter().enumerate() {
            let (gx, gy) = (idx % REF_GRID, idx / REF_GRID);
            let x = (gx as f64 + 0.5) / REF_GRID as f64 * 2.0 - 1.0;
            let y = 1.0 - (gy as f64 + 0.5) / REF_GRID as f64 * 2.0;
            if x.hypot(y) < 0.7 {
                ch += f64::from(chroma(*cell));
                br += f64::from(*cell.iter().max().unwrap_or(&0));
                n += 1.0;
            }
        }
        let coloured = n > 0.0 && ch > br / 3.0;
        let cells = cells.map(|c| {
            let chroma_min = if coloured { (f32::from(chroma(c)) * colour_fraction) as u8 } else { 0 };
            [c[0], c[1], c[2], chroma_min]
        });
        Some(BallReference { cells, coloured })
    }

    /// The reference colour at (x, y) in ball radii (view frame).
    pub fn at(&self, x: f64, y: f64) -> [u8; 3] {
        let c = self.cells[cell_of(x, y)];
        [c[0], c[1], c[2]]
    }
}

/// Thresholds and the logo's size.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DetectorConfig {
    /// (e): Σ|pixel − reference| over R, G, B above this is logo.
    pub diff_threshold: u16,
    /// (c): chroma below this fraction of the reference's is logo.
    pub colour_fraction: f32,
    /// Pixels out to this fraction of the ball's radius are examined.
    pub limb: f64,
    /// Fewest logo pixels for a detection.
    pub min_pixels: u32,
    /// The logo's radius in ball radii (= its angular radius, rad).
    pub logo_radius: f64,
    /// The surface's z is clamped to this when a pixel's area on the
    /// sphere is taken (pixel area / z).
    pub area_z_min: f64,
}

impl DetectorConfig {
    /// The defaults for a logo of angular radius `logo_radius`.
    pub fn for_logo(logo_radius: f64) -> Self {
        DetectorConfig {
            diff_threshold: 100,
            colour_fraction: 0.5,
            limb: 0.95,
            min_pixels: 5,
            logo_radius,
            area_z_min: 0.15,
        }
    }
}

/// The logo found in one crop. Positions are unit vectors in the camera
/// frame.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct LogoMeasurement {
    /// Logo pixels.
    pub pixels: u32,
    /// The logo's area seen, on the unit sphere.
    pub area: f64,
    /// The logo reaches the examined rim (it may be cut).
    pub touches_limb: bool,
    /// The paper's centre: the normalised mean of the logo pixels' points.
    pub centroid: Vec3,
    /// The same with the circular-segment correction where the logo is cut.
    pub corrected: Vec3,
    /// The area-weighted mean (each point weighted by its area on the
    /// sphere), segment-corrected where cut.
    pub weighted: Vec3,
}

/// Finds the logo in `crop` whose ball is `view`, against `reference`.
/// `None` when fewer than `cfg.min_pixels` pixels are logo. Allocates
/// nothing.
pub fn detect(
    cfg: &DetectorConfig,
    reference: &BallReference,
    crop: &CropImage<'_>,
    view: &BallView,
) -> Option<LogoMeasurement> {
    let m = view.m;
    let ext_u = cfg.limb * view.m_inv[0].hypot(view.m_inv[1]);
    let ext_v = cfg.limb * view.m_inv[2].hypot(view.m_inv[3]);
    let cu = view.u - crop.x0 as f64;
    let cv = view.v - crop.y0 as f64;
    let col0 = (cu - ext_u).floor().max(0.0) as usize;
    let col1 = ((cu + ext_u).ceil().max(0.0) as usize).min(crop.width.saturating_sub(1));
    let row0 = (cv - ext_v).floor().max(0.0) as usize;
    let row1 = ((cv + ext_v).ceil().max(0.0) as usize).min(crop.height.saturating_sub(1));
    let limb2 = cfg.limb * cfg.limb;
    let thr = cfg.diff_threshold;
    let (mut sx, mut sy, mut sz) = (0.0f64, 0.0f64, 0.0f64);
    let (mut wx, mut wy, mut wz, mut area) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut pixels = 0u32;
    let mut max_rr = 0.0f64;
    let half = REF_GRID as f64 / 2.0;
    // rr(du) = A du² + 2 B du + C along a row: the span inside the limb
    // is solved per row, so the inner loop only visits the ball's pixels.
    let qa = m[0] * m[0] + m[2] * m[2];
    for row in row0..=row1 {
        let dv = row as f64 - cv;
        let (xr, yr) = (m[1] * dv, m[3] * dv);
        let qb = m[0] * xr + m[2] * yr;
        let qc = xr * xr + yr * yr - limb2;
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            continue;
        }
        let sq = disc.sqrt();
        let lo = (cu + (-qb - sq) / qa).ceil().max(col0 as f64) as usize;
        let hi = (cu + (-qb + sq) / qa).floor().min(col1 as f64);
        if hi < lo as f64 {
            continue;
        }
        let hi = hi as usize;
        let line = &crop.rgb[3 * row * crop.width..3 * (row + 1) * crop.width];
        let du0 = lo as f64 - cu;
        // Grid coordinates in 16.16 fixed point, advanced per column.
        const ONE: f64 = 65536.0;
        let mut gx = ((m[0] * du0 + xr + 1.0) * half * ONE) as i64;
        let mut gy = ((1.0 - (m[2] * du0 + yr)) * half * ONE) as i64;
        let (dgx, dgy) = ((m[0] * half * ONE) as i64, (-m[2] * half * ONE) as i64);
        for (i, p) in line[3 * lo..3 * hi + 3].chunks_exact(3).enumerate() {
            let cx = ((gx >> 16) as usize).min(REF_GRID - 1);
            let cy = ((gy >> 16) as usize).min(REF_GRID - 1);
            gx += dgx;
            gy += dgy;
            let r = reference.cells[cy * REF_GRID + cx];
            let diff = (i16::from(p[0]) - i16::from(r[0])).unsigned_abs()
                + (i16::from(p[1]) - i16::from(r[1])).unsigned_abs()
                + (i16::from(p[2]) - i16::from(r[2])).unsigned_abs();
            // (c) only on a coloured ball (r[3] = 0 otherwise).
            let colour_hit = p[0].max(p[1]).max(p[2]) - p[0].min(p[1]).min(p[2]) < r[3];
            if diff > thr || colour_hit {
                let du = (lo + i) as f64 - cu;
                let x = m[0] * du + xr;
                let y = m[2] * du + yr;
                let rr = x * x + y * y;
                let z = (1.0 - rr).max(0.0).sqrt();
                sx += x;
                sy += y;
                sz += z;
                let w = 1.0 / z.max(cfg.area_z_min);
                wx += x * w;
                wy += y * w;
                wz += z * w;
                area += w;
                pixels += 1;
                max_rr = max_rr.max(rr);
            }
        }
    }
    if pixels < cfg.min_pixels {
        return None;
    }
    let det = (m[0] * m[3] - m[1] * m[2]).abs();
    let area = area * det;
    let rim = (cfg.limb - 1.5 / view.radius).max(0.0);
    let touches_limb = max_rr > rim * rim;
    let centroid_v = Vec3::new(sx, sy, sz).normalize();
    let weighted_v = Vec3::new(wx, wy, wz).normalize();
    // Equal-area disc radius of the logo's cap (2π(1 − cos ρ) = π r²).
    let r_eff = 2.0 * (cfg.logo_radius / 2.0).sin();
    let (corrected_v, weighted_v) = if touches_limb {
        (segment::correct(&centroid_v, area, r_eff), segment::correct(&weighted_v, area, r_eff))
    } else {
        (centroid_v, weighted_v)
    };
    Some(LogoMeasurement {
        pixels,
        area,
        touches_limb,
        centroid: view.to_camera(&centroid_v),
        corrected: view.to_camera(&corrected_v),
        weighted: view.to_camera(&weighted_v),
    })
}
