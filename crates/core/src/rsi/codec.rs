//! The RSI datagrams (DESIGN §5.3): `<Rob>` (controller → sensor) and
//! `<Sen>` (sensor → controller), each with `parse` and `emit`.
//!
//! Parsing is tolerant — any element order, extra elements, `Type` or
//! `TYPE`, white space and comments anywhere, optional elements missing —
//! and rejects what is not RSI with a typed [`CodecError`]. Emitting writes
//! into the caller's buffer and never allocates; numbers are written with a
//! fixed number of decimals (the ETHERNET object's `Precision`). Neither
//! direction panics on any input (property-tested in `tests/rsi_codec.rs`).
//!
//! Units are KUKA's: mm and degrees, A/B/C = rotations about Z/Y/X. The
//! conversion from SI happens in [`crate::rsi::session`], nowhere else.
//!
//! A `<Sen>` carries one of two corrections, as the RSI context is built:
//! `<RKorr X Y Z A B C>` (Cartesian, object POSCORR) or `<AKorr A1..A6>`
//! (axis angles in degrees, object AXISCORR).

use super::xml::{Attrs, Scanner, Token, XmlError, attr, trim};

/// The most decimals [`SenFrame::emit`] writes.
pub const MAX_PRECISION: u8 = 9;
/// The largest magnitude a number may have to be emitted.
pub(crate) const MAX_ABS_VALUE: f64 = 1e9;
/// The longest `Type` / `EStr` text accepted for emitting.
pub(crate) const MAX_TEXT_LEN: usize = 64;

/// A Cartesian pose as KUKA writes it: X, Y, Z in mm; A, B, C in degrees.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct KukaPose {
    /// X position, mm.
    pub x: f64,
    /// Y position, mm.
    pub y: f64,
    /// Z position, mm.
    pub z: f64,
    /// A: rotation about Z, degrees.
    pub a: f64,
    /// B: rotation about Y, degrees.
    pub b: f64,
    /// C: rotation about X, degrees.
    pub c: f64,
}

impl KukaPose {
    /// As `[x, y, z, a, b, c]`.
    pub fn to_array(self) -> [f64; 6] {
        [self.x, self.y, self.z, self.a, self.b, self.c]
    }
    /// From `[x, y, z, a, b, c]`.
    pub fn from_array(v: [f64; 6]) -> Self {
        KukaPose { x: v[0], y: v[1], z: v[2], a: v[3], b: v[4], c: v[5] }
    }

    /// As a frame (m, rad; R = Rz(A)·Ry(B)·Rx(C)).
    pub fn to_pose(self) -> crate::kinematics::Pose {
        crate::kinematics::Pose::from_xyz_abc(
            [self.x, self.y, self.z].map(|v| v * 1e-3),
            [self.a, self.b, self.c].map(f64::to_radians),
        )
    }

    /// A frame in KUKA's units (mm, degrees; angles as [`Pose::abc`](crate::kinematics::Pose::abc)).
    pub fn from_pose(p: &crate::kinematics::Pose) -> Self {
        let [a, b, c] = p.abc().map(f64::to_degrees);
        KukaPose { x: p.position.x * 1e3, y: p.position.y * 1e3, z: p.position.z * 1e3, a, b, c }
    }
}

/// Axis angles A1..A6 in degrees.
pub type Axes = [f64; 6];

/// Why a datagram could not be parsed or emitted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    /// The bytes are not XML the scanner can follow.
    #[error(transparent)]
    Xml(#[from] XmlError),
    /// The root element is not the expected `<Rob>` / `<Sen>`.
    #[error("not an RSI datagram (expected <{expected}>)")]
    NotRsi {
        /// The root element name that was expected (`Rob` or `Sen`).
        expected: &'static str,
    },
    /// The root element is not closed.
    #[error("truncated datagram: no </{root}>")]
    Truncated {
        /// The root element left open (`Rob` or `Sen`).
        root: &'static str,
    },
    /// No `<IPOC>` (every RSI datagram carries one).
    #[error("no <IPOC>")]
    MissingIpoc,
    /// An element lacks an attribute it must have.
    #[error("<{element}> has no attribute {attr}")]
    MissingAttribute {
        /// The element missing the attribute.
        element: &'static str,
        /// The attribute name that is missing.
        attr: &'static str,
    },
    /// A number that does not parse or is not finite.
    #[error("bad number in <{element}>")]
    BadNumber {
        /// The element whose attribute or text holds the bad number.
        element: &'static str,
    },
    /// The output buffer is too small.
    #[error("output buffer too small")]
    BufferTooSmall,
    /// A value to emit is not finite or larger than `MAX_ABS_VALUE`.
    #[error("value not finite or out of range")]
    ValueOutOfRange,
    /// A text to emit is too long or contains `<`, `>`, `&`, `"` or `'`.
    #[error("text not allowed in RSI XML")]
    BadText,
    /// The precision asked for exceeds [`MAX_PRECISION`].
    #[error("precision above {MAX_PRECISION}")]
    BadPrecision,
}

fn number(v: &[u8], element: &'static str) -> Result<f64, CodecError> {
    let s = core::str::from_utf8(trim(v)).map_err(|_| CodecError::BadNumber { element })?;
    let x: f64 = s.parse().map_err(|_| CodecError::BadNumber { element })?;
    if x.is_finite() { Ok(x) } else { Err(CodecError::BadNumber { element }) }
}

fn integer(v: &[u8], element: &'static str) -> Result<u64, CodecError> {
    let s = core::str::from_utf8(trim(v)).map_err(|_| CodecError::BadNumber { element })?;
    s.parse().map_err(|_| CodecError::BadNumber { element })
}

fn attrs_named<const N: usize>(
    attrs: &[u8],
    element: &'static str,
    names: [&'static str; N],
) -> Result<[f64; N], CodecError> {
    let mut out = [0.0; N];
    let mut seen = [false; N];
    for a in Attrs::new(attrs) {
        let (n, v) = a?;
        if let Some(k) = names.iter().position(|m| n.eq_ignore_ascii_case(m.as_bytes())) {
            out[k] = number(v, element)?;
            seen[k] = true;
        }
    }
    if let Some(k) = seen.iter().position(|s| !s) {
        return Err(CodecError::MissingAttribute { element, attr: names[k] });
    }
    Ok(out)
}

const POSE_ATTRS: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];
const AXIS_ATTRS: [&str; 6] = ["A1", "A2", "A3", "A4", "A5", "A6"];

/// Reads the root element's start tag, skipping leading text; `Err` if the
/// first element is not `root`.
fn expect_root<'a>(s: &mut Scanner<'a>, root: &'static str) -> Result<&'a [u8], CodecError> {
    while let Some(t) = s.next_token() {
        match t? {
            Token::Text(_) => continue,
            Token::Start { name, attrs, empty } if name == root.as_bytes() && !empty => {
                return Ok(attrs);
            }
            _ => break,
        }
    }
    Err(CodecError::NotRsi { expected: root })
}

/// Reads the text of an element whose start tag was just consumed.
fn text_of<'a>(s: &mut Scanner<'a>, empty: bool) -> Result<&'a [u8], CodecError> {
    if empty {
        return Ok(b"");
    }
    match s.next_token() {
        Some(Ok(Token::Text(t))) => Ok(t),
        Some(Ok(_)) | None => Ok(b""),
        Some(Err(e)) => Err(e.into()),
    }
}

/// One `<Rob>` datagram, as the controller sends it.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct RobFrame {
    /// The controller's interpolation cycle counter (ms); must be echoed.
    pub ipoc: u64,
    /// Actual TCP pose (`DEF_RIst`).
    pub rist: Option<KukaPose>,
    /// Commanded TCP pose (`DEF_RSol`).
    pub rsol: Option<KukaPose>,
    /// Actual axis angles (`DEF_AIPos`).
    pub aipos: Option<Axes>,
    /// Commanded axis angles (`DEF_ASPos`).
    pub aspos: Option<Axes>,
    /// Late packets counted by the controller (`DEF_Delay`).
    pub delay: Option<u64>,
}

/// The elements a `<Rob>` may carry, in the SEND list's terms.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum RobElement {
    /// `<RIst>`: actual TCP pose (`DEF_RIst`).
    RIst,
    /// `<RSol>`: commanded TCP pose (`DEF_RSol`).
    RSol,
    /// `<AIPos>`: actual axis angles (`DEF_AIPos`).
    AIPos,
    /// `<ASPos>`: commanded axis angles (`DEF_ASPos`).
    ASPos,
    /// `<Delay>`: the controller's late-packet counter (`DEF_Delay`).
    Delay,
}

impl RobElement {
    /// From a SEND list tag (`DEF_RIst` …).
    pub fn from_def_tag(tag: &[u8]) -> Option<Self> {
        Some(match tag {
            b"DEF_RIst" => RobElement::RIst,
            b"DEF_RSol" => RobElement::RSol,
            b"DEF_AIPos" => RobElement::AIPos,
            b"DEF_ASPos" => RobElement::ASPos,
            b"DEF_Delay" => RobElement::Delay,
            _ => return None,
        })
    }
}

impl RobFrame {
    /// Parses a `<Rob>` datagram. Never panics.
    pub fn parse(bytes: &[u8]) -> Result<Self, CodecError> {
        match Self::parse_lenient(bytes)? {
            (f, None) => Ok(f),
            (_, Some(e)) => Err(e),
        }
    }

    /// As [`Self::parse`], but an element whose values cannot be read (a
    /// non-finite or missing number in `RIst`, `RSol`, `AIPos`, `ASPos` or
    /// `Delay`) is left out and its error returned beside the frame: the
    /// request still has an IPOC to answer. The XML's structure and the
    /// IPOC must be sound.
    pub fn parse_lenient(bytes: &[u8]) -> Result<(Self, Option<CodecError>), CodecError> {
        let mut s = Scanner::new(bytes);
        expect_root(&mut s, "Rob")?;
        let mut f = RobFrame::default();
        let mut ipoc = None;
        let mut bad = None;
        fn keep<T>(bad: &mut Option<CodecError>, r: Result<T, CodecError>) -> Option<T> {
            r.map_err(|e| *bad.get_or_insert(e)).ok()
        }
        while let Some(t) = s.next_token() {
            match t? {
                Token::Start { name, attrs, empty } => match name {
                    b"RIst" => {
                        f.rist = keep(&mut bad, attrs_named(attrs, "RIst", POSE_ATTRS)).map(KukaPose::from_array)
                    }
                    b"RSol" => {
                        f.rsol = keep(&mut bad, attrs_named(attrs, "RSol", POSE_ATTRS)).map(KukaPose::from_array)
                    }
                    b"AIPos" => f.aipos = keep(&mut bad, attrs_named(attrs, "AIPos", AXIS_ATTRS)),
                    b"ASPos" => f.aspos = keep(&mut bad, attrs_named(attrs, "ASPos", AXIS_ATTRS)),
                    b"Delay" => {
                        let d = attr(attrs, b"D")?;
                        f.delay = keep(
                            &mut bad,
                            d.ok_or(CodecError::MissingAttribute { element: "Delay", attr: "D" })
                                .and_then(|d| integer(d, "Delay")),
                        );
                    }
                    b"IPOC" => ipoc = Some(integer(text_of(&mut s, empty)?, "IPOC")?),
                    _ => {}
                },
                Token::End { name: b"Rob" } => {
                    f.ipoc = ipoc.ok_or(CodecError::MissingIpoc)?;
                    return Ok((f, bad));
                }
                _ => {}
            }
        }
        Err(CodecError::Truncated { root: "Rob" })
    }

    /// Writes the datagram with `elements` in that order (those whose value
    /// is `None` are left out), numbers at `precision` decimals.
    pub fn emit(&self, elements: &[RobElement], precision: u8, buf: &mut [u8]) -> Result<usize, CodecError> {
        let mut w = Writer::new(buf, precision)?;
        w.put(b"<Rob Type=\"KUKA\">")?;
        for e in elements {
            match e {
                RobElement::RIst => {
                    if let Some(p) = self.rist {
                        w.element(b"RIst", &POSE_ATTRS, &p.to_array())?;
                    }
                }
                RobElement::RSol => {
                    if let Some(p) = self.rsol {
                        w.element(b"RSol", &POSE_ATTRS, &p.to_array())?;
                    }
                }
                RobElement::AIPos => {
                    if let Some(a) = self.aipos {
                        w.element(b"AIPos", &AXIS_ATTRS, &a)?;
                    }
                }
                RobElement::ASPos => {
                    if let Some(a) = self.aspos {
                        w.element(b"ASPos", &AXIS_ATTRS, &a)?;
                    }
                }
                RobElement::Delay => {
                    if let Some(d) = self.delay {
                        w.put(b"<Delay D=\"")?;
                        w.uint(d as u128)?;
                        w.put(b"\"/>")?;
                    }
                }
            }
        }
        w.put(b"<IPOC>")?;
        w.uint(self.ipoc as u128)?;
        w.put(b"</IPOC></Rob>")?;
        Ok(w.len)
    }
}

/// One `<Sen>` answer.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SenFrame<'a> {
    /// `Type` attribute: must equal SENTYPE of the Ethernet configuration.
    pub sentype: &'a str,
    /// Optional `<EStr>` message shown on the controller.
    pub estr: Option<&'a str>,
    /// Cartesian correction (mm, degrees); `None` leaves `<RKorr>` out.
    pub rkorr: Option<KukaPose>,
    /// Axis correction A1..A6 (degrees); `None` leaves `<AKorr>` out.
    pub akorr: Option<Axes>,
    /// The echoed IPOC.
    pub ipoc: u64,
}

/// A parsed `<Sen>` (for the mock controller): texts are borrowed.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SenView<'a> {
    /// The root's `Type` attribute (SENTYPE); empty if absent.
    pub sentype: &'a [u8],
    /// The `<EStr>` text, if present.
    pub estr: Option<&'a [u8]>,
    /// The `<RKorr>` correction (mm, degrees), if present.
    pub rkorr: Option<KukaPose>,
    /// The `<AKorr>` correction A1..A6 (degrees), if present.
    pub akorr: Option<Axes>,
    /// The echoed IPOC.
    pub ipoc: u64,
}

/// Checks that a text can be written into RSI XML unescaped.
pub fn check_text(s: &str) -> Result<(), CodecError> {
    if s.len() > MAX_TEXT_LEN || s.bytes().any(|c| matches!(c, b'<' | b'>' | b'&' | b'"' | b'\'')) {
        Err(CodecError::BadText)
    } else {
        Ok(())
    }
}

impl<'a> SenFrame<'a> {
    /// Writes the answer into `buf` with `precision` decimals; returns its
    /// length. Never allocates.
    pub fn emit(&self, precision: u8, buf: &mut [u8]) -> Result<usize, CodecError> {
        check_text(self.sentype)?;
        let mut w = Writer::new(buf, precision)?;
        w.put(b"<Sen Type=\"")?;
        w.put(self.sentype.as_bytes())?;
        w.put(b"\">")?;
        if let Some(e) = self.estr {
            check_text(e)?;
            w.put(b"<EStr>")?;
            w.put(e.as_bytes())?;
            w.put(b"</EStr>")?;
        }
        if let Some(k) = self.rkorr {
            w.element(b"RKorr", &POSE_ATTRS, &k.to_array())?;
        }
        if let Some(a) = self.akorr {
            w.element(b"AKorr", &AXIS_ATTRS, &a)?;
        }
        w.put(b"<IPOC>")?;
        w.uint(self.ipoc as u128)?;
        w.put(b"</IPOC></Sen>")?;
        Ok(w.len)
    }

    /// Parses a `<Sen>` answer. Never panics.
    pub fn parse(bytes: &'a [u8]) -> Result<SenView<'a>, CodecError> {
        let mut s = Scanner::new(bytes);
        let root = expect_root(&mut s, "Sen")?;
        let sentype = attr(root, b"Type")?.unwrap_or(b"");
        let mut v = SenView { sentype, estr: None, rkorr: None, akorr: None, ipoc: 0 };
        let mut ipoc = None;
        while let Some(t) = s.next_token() {
            match t? {
                Token::Start { name, attrs, empty } => match name {
                    b"RKorr" => v.rkorr = Some(KukaPose::from_array(attrs_named(attrs, "RKorr", POSE_ATTRS)?)),
                    b"AKorr" => v.akorr = Some(attrs_named(attrs, "AKorr", AXIS_ATTRS)?),
                    b"EStr" => v.estr = Some(text_of(&mut s, empty)?),
                    b"IPOC" => ipoc = Some(integer(text_of(&mut s, empty)?, "IPOC")?),
                    _ => {}
                },
                Token::End { name: b"Sen" } => {
                    v.ipoc = ipoc.ok_or(CodecError::MissingIpoc)?;
                    return Ok(v);
                }
                _ => {}
            }
        }
        Err(CodecError::Truncated { root: "Sen" })
    }
}

/// Appends to a fixed buffer.
struct Writer<'b> {
    buf: &'b mut [u8],
    len: usize,
    precision: u8,
}

impl<'b> Writer<'b> {
    fn new(buf: &'b mut [u8], precision: u8) -> Result<Self, CodecError> {
        if precision > MAX_PRECISION {
            return Err(CodecError::BadPrecision);
        }
        Ok(Writer { buf, len: 0, precision })
    }

    fn put(&mut self, s: &[u8]) -> Result<(), CodecError> {
        let end = self.len + s.len();
        let dst = self.buf.get_mut(self.len..end).ok_or(CodecError::BufferTooSmall)?;
        dst.copy_from_slice(s);
        self.len = end;
        Ok(())
    }

    fn uint(&mut self, mut v: u128) -> Result<(), CodecError> {
        let mut digits = [0u8; 40];
        let mut n = 0;
        loop {
            digits[n] = b'0' + (v % 10) as u8;
            n += 1;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        digits[..n].reverse();
        self.put(&digits[..n])
    }

    /// `v` with exactly `precision` decimals, rounded half away from zero.
    fn fixed(&mut self, v: f64) -> Result<(), CodecError> {
        if !(v.is_finite() && v.abs() <= MAX_ABS_VALUE) {
            return Err(CodecError::ValueOutOfRange);
        }
        let scale = 10u128.pow(self.precision as u32);
        let scaled = (v.abs() * scale as f64).round() as u128;
        if v < 0.0 && scaled != 0 {
            self.put(b"-")?;
        }
        self.uint(scaled / scale)?;
        if self.precision > 0 {
            self.put(b".")?;
            let frac = scaled % scale;
            let mut digits = [b'0'; MAX_PRECISION as usize];
            let p = self.precision as usize;
            let mut f = frac;
            for k in (0..p).rev() {
                digits[k] = b'0' + (f % 10) as u8;
                f /= 10;
            }
            self.put(&digits[..p])?;
        }
        Ok(())
    }

    fn element(&mut self, name: &[u8], attrs: &[&str; 6], v: &[f64; 6]) -> Result<(), CodecError> {
        self.put(b"<")?;
        self.put(name)?;
        for (a, x) in attrs.iter().zip(v) {
            self.put(b" ")?;
            self.put(a.as_bytes())?;
            self.put(b"=\"")?;
            self.fixed(*x)?;
            self.put(b"\"")?;
        }
        self.put(b"/>")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DESIGN_ROB: &[u8] = br#"<Rob Type="KUKA">
 <RIst X="445.0" Y="0.0" Z="900.0" A="0.0" B="90.0" C="0.0"/>
 <RSol X="445.0" Y="0.0" Z="900.0" A="0.0" B="90.0" C="0.0"/>
 <AIPos A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="0.0" A6="0.0"/>
 <ASPos A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="0.0" A6="0.0"/>
 <Delay D="0"/>
 <IPOC>4208831</IPOC>
</Rob>"#;

    #[test]
    fn parses_the_design_example() {
        let f = RobFrame::parse(DESIGN_ROB).unwrap();
        assert_eq!(f.ipoc, 4208831);
        assert_eq!(f.rist.unwrap().b, 90.0);
        assert_eq!(f.aipos.unwrap()[1], -90.0);
        assert_eq!(f.delay, Some(0));
    }

    #[test]
    fn tolerant_of_order_case_and_extras() {
        let x = br#"<?xml version="1.0"?>
<Rob TYPE="KUKA"><IPOC> 7 </IPOC><Tech C11="0"/><DiL>3</DiL>
<RIst c="3" B="2" A="1" Z="0" Y="0" X="1e2" /></Rob>"#;
        let f = RobFrame::parse(x).unwrap();
        assert_eq!(f.ipoc, 7);
        assert_eq!(f.rist.unwrap().x, 100.0);
        assert_eq!(f.rist.unwrap().c, 3.0);
        assert!(f.rsol.is_none() && f.delay.is_none());
    }

    #[test]
    fn rejects_what_is_not_rsi() {
        assert_eq!(RobFrame::parse(b"<Sen><IPOC>1</IPOC></Sen>"), Err(CodecError::NotRsi { expected: "Rob" }));
        assert_eq!(RobFrame::parse(b"<Rob><IPOC>1</IPOC>"), Err(CodecError::Truncated { root: "Rob" }));
        assert_eq!(RobFrame::parse(b"<Rob></Rob>"), Err(CodecError::MissingIpoc));
        assert!(matches!(
            RobFrame::parse(br#"<Rob><RIst X="nan" Y="0" Z="0" A="0" B="0" C="0"/><IPOC>1</IPOC></Rob>"#),
            Err(CodecError::BadNumber { element: "RIst" })
        ));
        assert!(RobFrame::parse(b"").is_err());
    }

    #[test]
    fn emits_the_design_answer() {
        let mut buf = [0u8; 512];
        let s = SenFrame {
            sentype: "ImFree",
            estr: Some("topspin"),
            rkorr: Some(KukaPose::from_array([12.3456, -3.21, 40.0, 0.0, 28.0, -0.00001])),
            akorr: None,
            ipoc: 4208831,
        };
        let n = s.emit(4, &mut buf).unwrap();
        assert_eq!(
            &buf[..n],
            &br#"<Sen Type="ImFree"><EStr>topspin</EStr><RKorr X="12.3456" Y="-3.2100" Z="40.0000" A="0.0000" B="28.0000" C="0.0000"/><IPOC>4208831</IPOC></Sen>"#[..]
        );
        assert_eq!(s.emit(4, &mut buf[..20]), Err(CodecError::BufferTooSmall));
        let bad = SenFrame { sentype: "a<b", ..s };
        assert_eq!(bad.emit(4, &mut buf), Err(CodecError::BadText));
    }

    #[test]
    fn emits_and_parses_an_axis_correction() {
        let mut buf = [0u8; 512];
        let s = SenFrame {
            sentype: "ImFree",
            estr: None,
            rkorr: None,
            akorr: Some([1.5, -90.0, 0.00004, -0.00005, 12.25, 359.9999]),
            ipoc: 4208835,
        };
        let n = s.emit(4, &mut buf).unwrap();
        assert_eq!(
            &buf[..n],
            &br#"<Sen Type="ImFree"><AKorr A1="1.5000" A2="-90.0000" A3="0.0000" A4="-0.0001" A5="12.2500" A6="359.9999"/><IPOC>4208835</IPOC></Sen>"#[..]
        );
        let v = SenFrame::parse(&buf[..n]).unwrap();
        assert_eq!(v.akorr, Some([1.5, -90.0, 0.0, -0.0001, 12.25, 359.9999]));
        assert_eq!((v.rkorr, v.ipoc, v.sentype), (None, 4208835, &b"ImFree"[..]));
        // Any attribute order and case, white space; both corrections at once are both read.
        let x = br#"<Sen Type="ImFree"> <AKorr a6="6" A5="5" A4="4" A3="3" A2="2" A1=" 1 " />
<RKorr X="1" Y="2" Z="3" A="4" B="5" C="6"/><IPOC>9</IPOC></Sen>"#;
        let v = SenFrame::parse(x).unwrap();
        assert_eq!(v.akorr, Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        assert_eq!(v.rkorr.map(KukaPose::to_array), Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        // Out-of-range values are refused, never written.
        let bad = SenFrame { akorr: Some([0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]), ..s };
        assert_eq!(bad.emit(4, &mut buf), Err(CodecError::ValueOutOfRange));
        let big = SenFrame { akorr: Some([2e9, 0.0, 0.0, 0.0, 0.0, 0.0]), ..s };
        assert_eq!(big.emit(4, &mut buf), Err(CodecError::ValueOutOfRange));
        assert_eq!(s.emit(4, &mut buf[..60]), Err(CodecError::BufferTooSmall));
    }

    #[test]
    fn rejects_a_malformed_axis_correction() {
        let parse = |x: &[u8]| SenFrame::parse(x).map(|v| v.akorr);
        assert_eq!(
            parse(br#"<Sen Type="T"><AKorr A1="0" A2="0" A3="0" A4="0" A5="0"/><IPOC>1</IPOC></Sen>"#),
            Err(CodecError::MissingAttribute { element: "AKorr", attr: "A6" })
        );
        for bad in ["nan", "inf", "1e999", "", "1,5", "0x10", "--1"] {
            let x =
                format!(r#"<Sen Type="T"><AKorr A1="0" A2="{bad}" A3="0" A4="0" A5="0" A6="0"/><IPOC>1</IPOC></Sen>"#);
            assert_eq!(parse(x.as_bytes()), Err(CodecError::BadNumber { element: "AKorr" }), "{bad}");
        }
        assert!(matches!(parse(br#"<Sen Type="T"><AKorr A1="0" A2=0/><IPOC>1</IPOC></Sen>"#), Err(CodecError::Xml(_))));
        assert_eq!(
            parse(br#"<Sen Type="T"><AKorr A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/></Sen>"#),
            Err(CodecError::MissingIpoc)
        );
        assert_eq!(
            parse(br#"<Sen Type="T"><AKorr A1="0" A2="0" A3="0" A4="0" A5="0" A6="0"/><IPOC>1</IPOC>"#),
            Err(CodecError::Truncated { root: "Sen" })
        );
        // An element named like it is not it.
        assert_eq!(parse(br#"<Sen Type="T"><AKorrX A1="x"/><IPOC>1</IPOC></Sen>"#), Ok(None));
    }
}
