//! The ball observation datagram, tracker → daemon (DESIGN §5.1).
//!
//! 36 bytes, little-endian:
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | [u8; 4] | magic `TTB1` |
//! | 4 | u32 | sequence number (wrapping) |
//! | 8 | u64 | capture time, ns, tracker's monotonic clock |
//! | 16 | f32 ×3 | x, y, z in m, table frame |
//! | 28 | f32 | triangulation residual in m (NaN if unknown) |
//! | 32 | u16 | number of cameras that saw the ball |
//! | 34 | u16 | flags (bit 0: valid ball; other bits 0) |
//!
//! Two layers, as in smoltcp: [`ObservationPacket`] is a view over a byte
//! buffer whose length and magic have been checked (field accessors, and
//! setters over a mutable buffer); [`Observation`] is the validated value
//! with [`Observation::parse`] and [`Observation::emit`]. Nothing here
//! allocates, and nothing panics on any input: `new_checked` and `parse`
//! accept arbitrary bytes and answer with a [`WireError`].

use crate::time::Instant;

/// Length of one observation datagram in bytes.
pub const OBSERVATION_LEN: usize = 36;

/// The four bytes every observation datagram starts with.
pub(crate) const OBSERVATION_MAGIC: [u8; 4] = *b"TTB1";

/// Flag bit 0: the tracker believes this is a ball.
pub(crate) const FLAG_VALID: u16 = 0x0001;

/// Flag bits that must be zero (all but [`FLAG_VALID`]).
pub(crate) const FLAGS_RESERVED: u16 = !FLAG_VALID;

/// The generous box around the table (table frame, m) outside which a
/// position is rejected as implausible: |x| ≤ 4, |y| ≤ 3, −1 ≤ z ≤ 4.
/// The table is 2.74 × 1.525 m, the floor 0.76 m below its surface.
pub(crate) const POSITION_BOX: PositionBox = PositionBox { min: [-4.0, -3.0, -1.0], max: [4.0, 3.0, 4.0] };

/// An axis-aligned box in the table frame, m.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct PositionBox {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl PositionBox {
    /// True when `p` lies inside the box (bounds included).
    pub(crate) fn contains(&self, p: &[f32; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

/// Why a datagram is not a usable observation.
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum WireError {
    /// The datagram is not exactly [`OBSERVATION_LEN`] bytes long.
    #[error("observation datagram of {len} bytes (expected {OBSERVATION_LEN})")]
    WrongLength {
        /// The datagram's actual length, bytes.
        len: usize,
    },
    /// The datagram does not start with `TTB1`.
    #[error("observation datagram with wrong magic {magic:02x?}")]
    WrongMagic {
        /// The first four bytes received.
        magic: [u8; 4],
    },
    /// A coordinate is NaN or infinite.
    #[error("observation with a non-finite coordinate")]
    NonFinite,
    /// The position lies outside `POSITION_BOX`.
    #[error("observation at ({x}, {y}, {z}) m lies outside the plausible box")]
    OutOfBox {
        /// x of the rejected position, m, table frame.
        x: f32,
        /// y of the rejected position, m, table frame.
        y: f32,
        /// z of the rejected position, m, table frame.
        z: f32,
    },
    /// The residual is negative or infinite (NaN, meaning unknown, is fine).
    #[error("observation with residual {residual} m (must be NaN or finite and ≥ 0)")]
    BadResidual {
        /// The residual received, m.
        residual: f32,
    },
    /// A reserved flag bit (any but bit 0) is set.
    #[error("observation with reserved flag bits set: {flags:#06x}")]
    ReservedFlags {
        /// The whole flags word received.
        flags: u16,
    },
}

mod field {
    use core::ops::Range;
    pub(super) const MAGIC: Range<usize> = 0..4;
    pub(super) const SEQ: Range<usize> = 4..8;
    pub(super) const CAPTURE: Range<usize> = 8..16;
    pub(super) const X: Range<usize> = 16..20;
    pub(super) const Y: Range<usize> = 20..24;
    pub(super) const Z: Range<usize> = 24..28;
    pub(super) const RESIDUAL: Range<usize> = 28..32;
    pub(super) const CAMERAS: Range<usize> = 32..34;
    pub(super) const FLAGS: Range<usize> = 34..36;
}

/// A view over the bytes of one observation datagram. Built with
/// [`ObservationPacket::new_checked`], every accessor is in bounds.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct ObservationPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> ObservationPacket<T> {
    /// Wraps `buffer` after checking its length (exactly
    /// [`OBSERVATION_LEN`]) and magic.
    pub fn new_checked(buffer: T) -> Result<Self, WireError> {
        let b = buffer.as_ref();
        if b.len() != OBSERVATION_LEN {
            return Err(WireError::WrongLength { len: b.len() });
        }
        let magic = [b[0], b[1], b[2], b[3]];
        if magic != OBSERVATION_MAGIC {
            return Err(WireError::WrongMagic { magic });
        }
        Ok(ObservationPacket { buffer })
    }

    /// The wrapped buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    fn bytes<const N: usize>(&self, r: core::ops::Range<usize>) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.buffer.as_ref()[r]);
        out
    }

    /// Sequence number (wrapping).
    pub fn seq(&self) -> u32 {
        u32::from_le_bytes(self.bytes(field::SEQ))
    }

    /// Capture time in ns on the tracker's monotonic clock.
    pub fn capture_ns(&self) -> u64 {
        u64::from_le_bytes(self.bytes(field::CAPTURE))
    }

    /// Position (x, y, z) in m, table frame, as sent (unvalidated).
    pub fn position(&self) -> [f32; 3] {
        [
            f32::from_le_bytes(self.bytes(field::X)),
            f32::from_le_bytes(self.bytes(field::Y)),
            f32::from_le_bytes(self.bytes(field::Z)),
        ]
    }

    /// Triangulation residual in m (NaN if unknown).
    pub fn residual(&self) -> f32 {
        f32::from_le_bytes(self.bytes(field::RESIDUAL))
    }

    /// Number of cameras that saw the ball.
    pub fn cameras(&self) -> u16 {
        u16::from_le_bytes(self.bytes(field::CAMERAS))
    }

    /// The raw flags word.
    pub fn flags(&self) -> u16 {
        u16::from_le_bytes(self.bytes(field::FLAGS))
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> ObservationPacket<T> {
    /// Wraps a buffer of [`OBSERVATION_LEN`] bytes for writing and stamps
    /// the magic. Fails (without touching it) on any other length.
    pub(crate) fn new_emit(mut buffer: T) -> Result<Self, WireError> {
        let len = buffer.as_ref().len();
        if len != OBSERVATION_LEN {
            return Err(WireError::WrongLength { len });
        }
        buffer.as_mut()[field::MAGIC].copy_from_slice(&OBSERVATION_MAGIC);
        Ok(ObservationPacket { buffer })
    }

    fn put(&mut self, r: core::ops::Range<usize>, bytes: &[u8]) {
        self.buffer.as_mut()[r].copy_from_slice(bytes);
    }

    /// Writes the sequence number.
    pub fn set_seq(&mut self, v: u32) {
        self.put(field::SEQ, &v.to_le_bytes());
    }

    /// Writes the capture time, ns on the tracker's monotonic clock.
    pub fn set_capture_ns(&mut self, v: u64) {
        self.put(field::CAPTURE, &v.to_le_bytes());
    }

    /// Writes the position (x, y, z) in m, table frame (not validated).
    pub fn set_position(&mut self, p: [f32; 3]) {
        self.put(field::X, &p[0].to_le_bytes());
        self.put(field::Y, &p[1].to_le_bytes());
        self.put(field::Z, &p[2].to_le_bytes());
    }

    /// Writes the triangulation residual in m (NaN if unknown).
    pub fn set_residual(&mut self, v: f32) {
        self.put(field::RESIDUAL, &v.to_le_bytes());
    }

    /// Writes the number of cameras that saw the ball.
    pub fn set_cameras(&mut self, v: u16) {
        self.put(field::CAMERAS, &v.to_le_bytes());
    }

    /// Writes the raw flags word.
    pub fn set_flags(&mut self, v: u16) {
        self.put(field::FLAGS, &v.to_le_bytes());
    }
}

/// A validated ball observation.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Observation {
    /// Sequence number (wrapping).
    pub seq: u32,
    /// Capture time on the tracker's monotonic clock.
    pub capture: Instant,
    /// Ball centre (x, y, z) in m, table frame; finite and inside
    /// `POSITION_BOX`.
    pub pos: [f32; 3],
    /// Triangulation residual in m; NaN when unknown.
    pub residual: f32,
    /// Number of cameras that saw the ball.
    pub cameras: u16,
    /// The tracker believes this is a ball (flag bit 0).
    pub valid: bool,
}

impl Observation {
    /// Parses and validates one datagram. Never panics, whatever the bytes.
    pub fn parse(bytes: &[u8]) -> Result<Observation, WireError> {
        Self::from_packet(&ObservationPacket::new_checked(bytes)?)
    }

    /// Validates the fields of a checked packet.
    pub(crate) fn from_packet<T: AsRef<[u8]>>(p: &ObservationPacket<T>) -> Result<Observation, WireError> {
        let pos = p.position();
        if !pos.iter().all(|c| c.is_finite()) {
            return Err(WireError::NonFinite);
        }
        if !POSITION_BOX.contains(&pos) {
            return Err(WireError::OutOfBox { x: pos[0], y: pos[1], z: pos[2] });
        }
        let residual = p.residual();
        if !(residual.is_nan() || (residual.is_finite() && residual >= 0.0)) {
            return Err(WireError::BadResidual { residual });
        }
        let flags = p.flags();
        if flags & FLAGS_RESERVED != 0 {
            return Err(WireError::ReservedFlags { flags });
        }
        Ok(Observation {
            seq: p.seq(),
            capture: Instant::from_nanos(p.capture_ns()),
            pos,
            residual,
            cameras: p.cameras(),
            valid: flags & FLAG_VALID != 0,
        })
    }

    /// Writes this observation into `buf`. Writes the fields as they are;
    /// `parse` of the result succeeds when the value is valid (finite
    /// position inside `POSITION_BOX`, residual NaN or ≥ 0).
    pub fn emit(&self, buf: &mut [u8; OBSERVATION_LEN]) {
        let Ok(mut p) = ObservationPacket::new_emit(&mut buf[..]) else {
            unreachable!("the buffer has exactly OBSERVATION_LEN bytes")
        };
        p.set_seq(self.seq);
        p.set_capture_ns(self.capture.as_nanos());
        p.set_position(self.pos);
        p.set_residual(self.residual);
        p.set_cameras(self.cameras);
        p.set_flags(if self.valid { FLAG_VALID } else { 0 });
    }

    /// The number of bytes [`Observation::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        OBSERVATION_LEN
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sample() -> Observation {
        Observation {
            seq: 7,
            capture: Instant::from_nanos(1_234_567_890),
            pos: [0.5, -0.25, 0.3],
            residual: f32::NAN,
            cameras: 2,
            valid: true,
        }
    }

    fn same(a: &Observation, b: &Observation) -> bool {
        a.seq == b.seq
            && a.capture == b.capture
            && a.pos == b.pos
            && a.residual.to_bits() == b.residual.to_bits()
            && a.cameras == b.cameras
            && a.valid == b.valid
    }

    #[test]
    fn layout_matches_the_design() {
        let mut buf = [0u8; OBSERVATION_LEN];
        sample().emit(&mut buf);
        assert_eq!(&buf[0..4], b"TTB1");
        assert_eq!(&buf[4..8], &7u32.to_le_bytes());
        assert_eq!(&buf[8..16], &1_234_567_890u64.to_le_bytes());
        assert_eq!(&buf[16..20], &0.5f32.to_le_bytes());
        assert_eq!(&buf[24..28], &0.3f32.to_le_bytes());
        assert!(f32::from_le_bytes(buf[28..32].try_into().unwrap()).is_nan());
        assert_eq!(&buf[32..36], &[2, 0, 1, 0]);
    }

    #[test]
    fn each_defect_has_its_error() {
        let mut buf = [0u8; OBSERVATION_LEN];
        sample().emit(&mut buf);
        assert!(same(&Observation::parse(&buf).unwrap(), &sample()));

        assert_eq!(Observation::parse(&buf[..35]), Err(WireError::WrongLength { len: 35 }));
        let mut long = [0u8; 37];
        long[..36].copy_from_slice(&buf);
        assert_eq!(Observation::parse(&long), Err(WireError::WrongLength { len: 37 }));
        assert_eq!(Observation::parse(&[]), Err(WireError::WrongLength { len: 0 }));

        let mut b = buf;
        b[3] = b'2';
        assert!(matches!(Observation::parse(&b), Err(WireError::WrongMagic { .. })));

        let mut b = buf;
        b[20..24].copy_from_slice(&f32::INFINITY.to_le_bytes());
        assert_eq!(Observation::parse(&b), Err(WireError::NonFinite));
        b[20..24].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(Observation::parse(&b), Err(WireError::NonFinite));

        let mut b = buf;
        b[24..28].copy_from_slice(&(-1.5f32).to_le_bytes());
        assert!(matches!(Observation::parse(&b), Err(WireError::OutOfBox { .. })));

        let mut b = buf;
        b[28..32].copy_from_slice(&(-0.1f32).to_le_bytes());
        assert!(matches!(Observation::parse(&b), Err(WireError::BadResidual { .. })));

        let mut b = buf;
        b[34] = 0x03;
        assert_eq!(Observation::parse(&b), Err(WireError::ReservedFlags { flags: 3 }));
        b[34] = 0;
        b[35] = 0x80;
        assert!(matches!(Observation::parse(&b), Err(WireError::ReservedFlags { .. })));

        let mut b = buf;
        b[34] = 0;
        assert!(!Observation::parse(&b).unwrap().valid);
    }

    fn arb_valid() -> impl Strategy<Value = Observation> {
        (
            any::<u32>(),
            any::<u64>(),
            (-4.0f32..=4.0, -3.0f32..=3.0, -1.0f32..=4.0),
            prop_oneof![Just(f32::NAN), 0.0f32..1.0],
            any::<u16>(),
            any::<bool>(),
        )
            .prop_map(|(seq, ns, (x, y, z), residual, cameras, valid)| Observation {
                seq,
                capture: Instant::from_nanos(ns),
                pos: [x, y, z],
                residual,
                cameras,
                valid,
            })
    }

    proptest! {
        #[test]
        fn parse_after_emit_is_the_identity(o in arb_valid()) {
            let mut buf = [0u8; OBSERVATION_LEN];
            o.emit(&mut buf);
            let back = Observation::parse(&buf).unwrap();
            prop_assert!(same(&back, &o), "{back:?} != {o:?}");
            // And emit after parse gives the same bytes back.
            let mut again = [0u8; OBSERVATION_LEN];
            back.emit(&mut again);
            prop_assert_eq!(again, buf);
        }

        #[test]
        fn parse_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
            let _ = Observation::parse(&bytes);
        }

        #[test]
        fn parse_never_panics_on_right_length_with_magic(tail in proptest::collection::vec(any::<u8>(), 32)) {
            let mut b = [0u8; OBSERVATION_LEN];
            b[..4].copy_from_slice(&OBSERVATION_MAGIC);
            b[4..].copy_from_slice(&tail);
            if let Ok(o) = Observation::parse(&b) {
                prop_assert!(POSITION_BOX.contains(&o.pos));
            }
        }
    }
}
