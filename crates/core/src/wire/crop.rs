//! The ball crop datagram, ceiling camera → daemon's logo thread (DESIGN
//! §5.2). Little-endian:
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | [u8; 4] | magic `TTI1` |
//! | 4 | u32 | sequence number |
//! | 8 | u64 | capture time, ns |
//! | 16 | f32 ×3 | ball centre u, v and radius in px (full sensor) |
//! | 28 | u16 ×2 | crop width, height (each 1..=96) |
//! | 32 | u8 | pixel format (0 = RGB8) |
//! | 33 | [u8; 3] | zero |
//! | 36 | … | width · height · 3 bytes, row-major |
//!
//! The crop's top-left pixel lies at (⌊u⌋ − width/2, ⌊v⌋ − height/2) on the
//! sensor ([`crop_origin`]). Two layers as in
//! [`super::observation`]: [`CropPacket`] is a view whose header and length
//! have been checked; [`Crop`] is the validated value, borrowing its pixels.
//! Nothing here allocates, and nothing panics on any input.

use crate::time::Instant;

/// Bytes before the pixels.
pub(crate) const CROP_HEADER_LEN: usize = 36;
/// Largest crop side, px.
pub(crate) const CROP_MAX_SIDE: u16 = 96;
/// Largest datagram: a 96 × 96 RGB8 crop.
pub const CROP_MAX_LEN: usize = CROP_HEADER_LEN + 3 * 96 * 96;
/// The four bytes every crop datagram starts with.
pub(crate) const CROP_MAGIC: [u8; 4] = *b"TTI1";
/// Pixel format 0: 8-bit R, G, B.
pub(crate) const FORMAT_RGB8: u8 = 0;
/// The largest |u|, |v| accepted, px (sensors are far smaller).
pub(crate) const CROP_MAX_COORD: f32 = 65_536.0;

/// Why a datagram is not a usable crop.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum CropError {
    /// Shorter than the header.
    #[error("crop datagram of {len} bytes (header is {CROP_HEADER_LEN})")]
    Truncated {
        /// The datagram's length, bytes.
        len: usize,
    },
    /// Does not start with `TTI1`.
    #[error("crop datagram with wrong magic {magic:02x?}")]
    WrongMagic {
        /// The first four bytes received.
        magic: [u8; 4],
    },
    /// Width or height is 0 or above `CROP_MAX_SIDE`.
    #[error("crop of {width} × {height} px (each side 1..=96)")]
    BadSize {
        /// The declared crop width, px.
        width: u16,
        /// The declared crop height, px.
        height: u16,
    },
    /// The length is not header + width · height · 3.
    #[error("crop datagram of {len} bytes (expected {expected})")]
    WrongLength {
        /// The datagram's length, bytes.
        len: usize,
        /// Header + width · height · 3, bytes.
        expected: usize,
    },
    /// Pixel format other than RGB8.
    #[error("crop pixel format {format} (only 0 = RGB8)")]
    UnknownFormat {
        /// The pixel format byte received.
        format: u8,
    },
    /// The three reserved bytes are not zero.
    #[error("crop datagram with non-zero reserved bytes")]
    Reserved,
    /// u, v or radius non-finite, radius ≤ 0, or |u|, |v| implausible.
    #[error("crop with an unusable ball circle ({u}, {v}, r {radius})")]
    BadCircle {
        /// Ball centre column as sent, px.
        u: f32,
        /// Ball centre row as sent, px.
        v: f32,
        /// Ball radius as sent, px.
        radius: f32,
    },
    /// The output buffer is too small for [`Crop::emit`].
    #[error("buffer of {len} bytes for a crop of {needed}")]
    BufferTooSmall {
        /// The buffer's length, bytes.
        len: usize,
        /// The datagram's length, bytes.
        needed: usize,
    },
}

mod field {
    use core::ops::Range;
    pub(super) const MAGIC: Range<usize> = 0..4;
    pub(super) const SEQ: Range<usize> = 4..8;
    pub(super) const CAPTURE: Range<usize> = 8..16;
    pub(super) const U: Range<usize> = 16..20;
    pub(super) const V: Range<usize> = 20..24;
    pub(super) const RADIUS: Range<usize> = 24..28;
    pub(super) const WIDTH: Range<usize> = 28..30;
    pub(super) const HEIGHT: Range<usize> = 30..32;
    pub(super) const FORMAT: usize = 32;
    pub(super) const RESERVED: Range<usize> = 33..36;
}

/// A view over one crop datagram. Built with [`CropPacket::new_checked`],
/// the header is in bounds and the length matches the declared size.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct CropPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> CropPacket<T> {
    /// Checks the magic, the declared size (1..=96 each side) and that the
    /// length is exactly header + pixels.
    pub fn new_checked(buffer: T) -> Result<Self, CropError> {
        let b = buffer.as_ref();
        if b.len() < CROP_HEADER_LEN {
            return Err(CropError::Truncated { len: b.len() });
        }
        let magic = [b[0], b[1], b[2], b[3]];
        if magic != CROP_MAGIC {
            return Err(CropError::WrongMagic { magic });
        }
        let p = CropPacket { buffer };
        let (width, height) = (p.width(), p.height());
        if width == 0 || height == 0 || width > CROP_MAX_SIDE || height > CROP_MAX_SIDE {
            return Err(CropError::BadSize { width, height });
        }
        let expected = CROP_HEADER_LEN + 3 * usize::from(width) * usize::from(height);
        let len = p.buffer.as_ref().len();
        if len != expected {
            return Err(CropError::WrongLength { len, expected });
        }
        Ok(p)
    }

    fn bytes<const N: usize>(&self, r: core::ops::Range<usize>) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.buffer.as_ref()[r]);
        out
    }

    /// Sequence number.
    pub fn seq(&self) -> u32 {
        u32::from_le_bytes(self.bytes(field::SEQ))
    }
    /// Capture time in ns on the camera's clock.
    pub fn capture_ns(&self) -> u64 {
        u64::from_le_bytes(self.bytes(field::CAPTURE))
    }
    /// (u, v, radius) as sent (unvalidated).
    pub fn circle(&self) -> [f32; 3] {
        [
            f32::from_le_bytes(self.bytes(field::U)),
            f32::from_le_bytes(self.bytes(field::V)),
            f32::from_le_bytes(self.bytes(field::RADIUS)),
        ]
    }
    /// Declared crop width, px.
    pub fn width(&self) -> u16 {
        u16::from_le_bytes(self.bytes(field::WIDTH))
    }
    /// Declared crop height, px.
    pub fn height(&self) -> u16 {
        u16::from_le_bytes(self.bytes(field::HEIGHT))
    }
    /// Pixel format byte (0 = RGB8).
    pub fn format(&self) -> u8 {
        self.buffer.as_ref()[field::FORMAT]
    }
    /// The three reserved bytes (zero in a valid crop).
    pub fn reserved(&self) -> [u8; 3] {
        self.bytes(field::RESERVED)
    }
    /// The pixel bytes (length checked by `new_checked`).
    pub fn pixels(&self) -> &[u8] {
        &self.buffer.as_ref()[CROP_HEADER_LEN..]
    }
}

/// A validated crop, borrowing its pixels.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Crop<'a> {
    /// Sequence number.
    pub seq: u32,
    /// Capture time on the camera's clock (as parsed; the daemon maps it
    /// to ours).
    pub capture: Instant,
    /// Ball centre column (full sensor, px); finite, |u| ≤ `CROP_MAX_COORD`.
    pub u: f32,
    /// Ball centre row (full sensor, px); finite, |v| ≤ `CROP_MAX_COORD`.
    pub v: f32,
    /// Ball radius, px; finite and > 0.
    pub radius: f32,
    /// Crop width, px (1..=96).
    pub width: u16,
    /// Crop height, px (1..=96).
    pub height: u16,
    /// RGB8, row-major, width · height · 3 bytes.
    pub pixels: &'a [u8],
}

impl<'a> Crop<'a> {
    /// Parses and validates one datagram. Never panics, whatever the bytes.
    pub fn parse(bytes: &'a [u8]) -> Result<Crop<'a>, CropError> {
        let p = CropPacket::new_checked(bytes)?;
        let format = p.format();
        if format != FORMAT_RGB8 {
            return Err(CropError::UnknownFormat { format });
        }
        if p.reserved() != [0; 3] {
            return Err(CropError::Reserved);
        }
        let [u, v, radius] = p.circle();
        let coord_ok = |c: f32| c.is_finite() && c.abs() <= CROP_MAX_COORD;
        if !(coord_ok(u) && coord_ok(v) && radius.is_finite() && radius > 0.0 && radius <= CROP_MAX_COORD) {
            return Err(CropError::BadCircle { u, v, radius });
        }
        Ok(Crop {
            seq: p.seq(),
            capture: Instant::from_nanos(p.capture_ns()),
            u,
            v,
            radius,
            width: p.width(),
            height: p.height(),
            pixels: &bytes[CROP_HEADER_LEN..],
        })
    }

    /// The bytes [`Crop::emit`] writes.
    pub fn buffer_len(&self) -> usize {
        CROP_HEADER_LEN + self.pixels.len()
    }

    /// Writes the datagram into the front of `buf`; returns its length.
    /// Fails on a buffer too small, or where `pixels` does not hold
    /// width · height · 3 bytes of a valid size. `parse` of the result
    /// succeeds when the circle is valid.
    pub fn emit(&self, buf: &mut [u8]) -> Result<usize, CropError> {
        let (w, h) = (self.width, self.height);
        if w == 0 || h == 0 || w > CROP_MAX_SIDE || h > CROP_MAX_SIDE {
            return Err(CropError::BadSize { width: w, height: h });
        }
        let expected = 3 * usize::from(w) * usize::from(h);
        if self.pixels.len() != expected {
            return Err(CropError::WrongLength {
                len: CROP_HEADER_LEN + self.pixels.len(),
                expected: CROP_HEADER_LEN + expected,
            });
        }
        let needed = self.buffer_len();
        let Some(out) = buf.get_mut(..needed) else {
            return Err(CropError::BufferTooSmall { len: buf.len(), needed });
        };
        out[field::MAGIC].copy_from_slice(&CROP_MAGIC);
        out[field::SEQ].copy_from_slice(&self.seq.to_le_bytes());
        out[field::CAPTURE].copy_from_slice(&self.capture.as_nanos().to_le_bytes());
        out[field::U].copy_from_slice(&self.u.to_le_bytes());
        out[field::V].copy_from_slice(&self.v.to_le_bytes());
        out[field::RADIUS].copy_from_slice(&self.radius.to_le_bytes());
        out[field::WIDTH].copy_from_slice(&w.to_le_bytes());
        out[field::HEIGHT].copy_from_slice(&h.to_le_bytes());
        out[field::FORMAT] = FORMAT_RGB8;
        out[field::RESERVED].fill(0);
        out[CROP_HEADER_LEN..].copy_from_slice(self.pixels);
        Ok(needed)
    }
}

/// The top-left pixel of a `size` × `size` crop around a ball measured at
/// (u, v): (⌊u⌋ − size/2, ⌊v⌋ − size/2). The convention TTI1 and the
/// `frames.csv` folders rely on to place a crop on the sensor.
pub fn crop_origin(u: f64, v: f64, width: u32, height: u32) -> (i64, i64) {
    (u.floor() as i64 - i64::from(width / 2), v.floor() as i64 - i64::from(height / 2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn layout_and_defects() {
        let pixels: Vec<u8> = (0..3 * 4 * 2).map(|i| i as u8).collect();
        let c = Crop {
            seq: 9,
            capture: Instant::from_nanos(77),
            u: 960.5,
            v: 600.25,
            radius: 23.0,
            width: 4,
            height: 2,
            pixels: &pixels,
        };
        let mut buf = [0u8; CROP_MAX_LEN];
        let n = c.emit(&mut buf).unwrap();
        assert_eq!(n, 36 + 24);
        assert_eq!(&buf[0..4], b"TTI1");
        assert_eq!(&buf[28..32], &[4, 0, 2, 0]);
        assert_eq!(buf[32], 0);
        assert_eq!(Crop::parse(&buf[..n]).unwrap(), c);

        assert_eq!(Crop::parse(&buf[..10]), Err(CropError::Truncated { len: 10 }));
        assert!(matches!(Crop::parse(&buf[..n - 1]), Err(CropError::WrongLength { .. })));
        assert!(matches!(Crop::parse(&buf[..n + 1]), Err(CropError::WrongLength { .. })));
        let mut b = buf;
        b[0] = b'X';
        assert!(matches!(Crop::parse(&b[..n]), Err(CropError::WrongMagic { .. })));
        let mut b = buf;
        b[32] = 1;
        assert_eq!(Crop::parse(&b[..n]), Err(CropError::UnknownFormat { format: 1 }));
        let mut b = buf;
        b[34] = 1;
        assert_eq!(Crop::parse(&b[..n]), Err(CropError::Reserved));
        let mut b = buf;
        b[24..28].copy_from_slice(&(-1.0f32).to_le_bytes());
        assert!(matches!(Crop::parse(&b[..n]), Err(CropError::BadCircle { .. })));
        let mut b = buf;
        b[28..30].copy_from_slice(&97u16.to_le_bytes());
        assert!(matches!(Crop::parse(&b[..n]), Err(CropError::BadSize { .. })));
        assert!(matches!(c.emit(&mut [0u8; 40]), Err(CropError::BufferTooSmall { .. })));
        assert!(matches!(Crop { width: 5, ..c }.emit(&mut buf), Err(CropError::WrongLength { .. })));
    }

    fn arb_crop() -> impl Strategy<Value = (u32, u64, f32, f32, f32, u16, u16, Vec<u8>)> {
        (1u16..=96, 1u16..=96).prop_flat_map(|(w, h)| {
            (
                any::<u32>(),
                any::<u64>(),
                -65_536.0f32..65_536.0,
                -65_536.0f32..65_536.0,
                0.001f32..1000.0,
                Just(w),
                Just(h),
                proptest::collection::vec(any::<u8>(), 3 * usize::from(w) * usize::from(h)),
            )
        })
    }

    proptest! {
        #[test]
        fn parse_after_emit_is_the_identity((seq, ns, u, v, radius, width, height, pixels) in arb_crop()) {
            let c = Crop { seq, capture: Instant::from_nanos(ns), u, v, radius, width, height, pixels: &pixels };
            let mut buf = vec![0u8; CROP_MAX_LEN];
            let n = c.emit(&mut buf).unwrap();
            prop_assert_eq!(n, c.buffer_len());
            let back = Crop::parse(&buf[..n]).unwrap();
            prop_assert_eq!(back, c);
        }

        #[test]
        fn parse_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = Crop::parse(&bytes);
        }

        #[test]
        fn parse_never_panics_with_a_valid_header(w in 0u16..100, h in 0u16..100, extra in 0usize..8, fill in any::<u8>()) {
            let mut b = vec![fill; CROP_HEADER_LEN + 3 * usize::from(w) * usize::from(h) + extra];
            b[..4].copy_from_slice(&CROP_MAGIC);
            b[28..30].copy_from_slice(&w.to_le_bytes());
            b[30..32].copy_from_slice(&h.to_le_bytes());
            if let Ok(c) = Crop::parse(&b) {
                prop_assert_eq!(c.pixels.len(), 3 * usize::from(c.width) * usize::from(c.height));
            }
        }
    }
}
