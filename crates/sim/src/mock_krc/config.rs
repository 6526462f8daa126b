//! The controller-side files of `rsi/`, read the way the mock needs them:
//! the Cartesian pair (`topspin_ethernet.xml`, `topspin.rsi.xml`: RKorr into
//! POSCORR) and the axis pair (`topspin_axis_ethernet.xml`,
//! `topspin_axis.rsi.xml`: AKorr into AXISCORR).

use std::net::{IpAddr, SocketAddr};

use topspin_core::rsi::Correction;
use topspin_core::rsi::RobElement;
use topspin_core::rsi::{Scanner, Token, XmlError, attr, trim};

/// `rsi/topspin_ethernet.xml`, compiled in.
pub(crate) const DEFAULT_ETHERNET_XML: &str = include_str!("../../../../rsi/topspin_ethernet.xml");
/// `rsi/topspin.rsi.xml`, compiled in.
pub(crate) const DEFAULT_CONTEXT_XML: &str = include_str!("../../../../rsi/topspin.rsi.xml");
/// `rsi/topspin_axis_ethernet.xml`, compiled in.
pub(crate) const AXIS_ETHERNET_XML: &str = include_str!("../../../../rsi/topspin_axis_ethernet.xml");
/// `rsi/topspin_axis.rsi.xml`, compiled in.
pub(crate) const AXIS_CONTEXT_XML: &str = include_str!("../../../../rsi/topspin_axis.rsi.xml");

/// The names of a correction's two files in `rsi/` (Ethernet, context)
/// and their compiled-in texts.
pub fn rsi_files(c: Correction) -> [(&'static str, &'static str); 2] {
    match c {
        Correction::Cartesian => {
            [("topspin_ethernet.xml", DEFAULT_ETHERNET_XML), ("topspin.rsi.xml", DEFAULT_CONTEXT_XML)]
        }
        Correction::Axis => {
            [("topspin_axis_ethernet.xml", AXIS_ETHERNET_XML), ("topspin_axis.rsi.xml", AXIS_CONTEXT_XML)]
        }
    }
}

/// Why a controller-side file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum RsiFileError {
    /// The file is not well-formed XML.
    #[error("{file}: {source}")]
    Xml {
        /// Which file (`ethernet config` or `RSI context`).
        file: &'static str,
        /// The XML error.
        source: XmlError,
    },
    /// A required element, parameter or object is absent.
    #[error("{file}: missing {what}")]
    Missing {
        /// Which file.
        file: &'static str,
        /// What is missing.
        what: &'static str,
    },
    /// A value does not parse or is out of range.
    #[error("{file}: bad value for {what}")]
    Bad {
        /// Which file.
        file: &'static str,
        /// Which value.
        what: &'static str,
    },
    /// The Ethernet configuration feeds a correction the RSI context has no object for.
    #[error("the Ethernet configuration receives {received} but the RSI context has no {object} object")]
    Mismatch {
        /// The correction received (`RKorr` or `AKorr`).
        received: &'static str,
        /// The object the context lacks (`POSCORR` or `AXISCORR`).
        object: &'static str,
    },
}

/// The ETHERNET object's configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct EthernetConfig {
    /// The sensor's IP address (`IP_NUMBER`).
    pub ip: IpAddr,
    /// The sensor's UDP port (`PORT`).
    pub port: u16,
    /// The sensor type every answer must carry as `Type` (`SENTYPE`).
    pub sentype: String,
    /// `ONLYSEND` is TRUE: the controller sends without expecting answers.
    pub only_send: bool,
    /// The SEND list, in order (unknown tags skipped).
    pub send: Vec<RobElement>,
    /// The RECEIVE tags, in order.
    pub receive: Vec<String>,
}

impl EthernetConfig {
    pub(crate) fn sensor_addr(&self) -> SocketAddr {
        SocketAddr::new(self.ip, self.port)
    }

    /// The correction the RECEIVE list takes: `AKorr.*` tags make it axis,
    /// else Cartesian (`RKorr.*`).
    pub fn correction(&self) -> Correction {
        if self.receive.iter().any(|t| t.starts_with("AKorr.")) { Correction::Axis } else { Correction::Cartesian }
    }

    /// Parses an Ethernet configuration (`rsi/*ethernet.xml`).
    pub fn parse(text: &str) -> Result<Self, RsiFileError> {
        const F: &str = "ethernet config";
        let xml = |source| RsiFileError::Xml { file: F, source };
        let mut s = Scanner::new(text.as_bytes());
        let (mut ip, mut port, mut sentype, mut only_send) = (None, None, None, false);
        let (mut send, mut receive) = (Vec::new(), Vec::new());
        let mut section = 0u8; // 1 = SEND, 2 = RECEIVE
        let mut current: &[u8] = b"";
        while let Some(t) = s.next_token() {
            match t.map_err(xml)? {
                Token::Start { name, attrs, .. } => {
                    match name {
                        b"SEND" => section = 1,
                        b"RECEIVE" => section = 2,
                        b"ELEMENT" => {
                            let tag = attr(attrs, b"TAG").map_err(xml)?.unwrap_or(b"");
                            if section == 1 {
                                if let Some(e) = RobElement::from_def_tag(tag) {
                                    send.push(e);
                                }
                            } else if section == 2 {
                                receive.push(String::from_utf8_lossy(tag).into_owned());
                            }
                        }
                        _ => {}
                    }
                    current = name;
                }
                Token::Text(x) => {
                    let v = String::from_utf8_lossy(trim(x)).into_owned();
                    match current {
                        b"IP_NUMBER" => {
                            ip = Some(v.parse().map_err(|_| RsiFileError::Bad { file: F, what: "IP_NUMBER" })?)
                        }
                        b"PORT" => port = Some(v.parse().map_err(|_| RsiFileError::Bad { file: F, what: "PORT" })?),
                        b"SENTYPE" => sentype = Some(v),
                        b"ONLYSEND" => only_send = v.eq_ignore_ascii_case("TRUE"),
                        _ => {}
                    }
                    current = b"";
                }
                Token::End { .. } => current = b"",
            }
        }
        Ok(EthernetConfig {
            ip: ip.ok_or(RsiFileError::Missing { file: F, what: "IP_NUMBER" })?,
            port: port.ok_or(RsiFileError::Missing { file: F, what: "PORT" })?,
            sentype: sentype.ok_or(RsiFileError::Missing { file: F, what: "SENTYPE" })?,
            only_send,
            send,
            receive,
        })
    }
}

/// The parts of the RSI context the mock models.
#[derive(Clone, Debug, PartialEq)]
pub struct ContextConfig {
    /// The ETHERNET object's `ConfigFile` (the Ethernet configuration's file name).
    pub config_file: String,
    /// Late answers before RSI stops (ETHERNET `Timeout`).
    pub timeout: u32,
    /// Decimals (ETHERNET `Precision`).
    pub precision: u8,
    /// POSCORR: correction limits, mm.
    pub lower_mm: [f64; 3],
    /// POSCORR: upper correction limits x, y, z, mm.
    pub upper_mm: [f64; 3],
    /// POSCORR: one total rotation limit, deg.
    pub max_rot_deg: f64,
    /// POSCORRMON: total translation / rotation that stop the robot.
    pub mon_max_trans_mm: f64,
    /// POSCORRMON: total rotation that stops the robot, deg.
    pub mon_max_rot_deg: f64,
    /// A POSCORR / an AXISCORR object is in the context.
    pub poscorr: bool,
    /// An AXISCORR object is in the context.
    pub axiscorr: bool,
    /// AXISCORR: correction limits per axis A1..A6, degrees.
    pub axis_lower_deg: [f64; 6],
    /// AXISCORR: upper correction limits per axis A1..A6, degrees.
    pub axis_upper_deg: [f64; 6],
    /// AXISCORRMON: |total correction| per axis that stops RSI, degrees.
    pub axis_mon_max_deg: [f64; 6],
}

impl ContextConfig {
    /// Parses an RSI context (`rsi/*.rsi.xml`); it must hold an ETHERNET object.
    pub fn parse(text: &str) -> Result<Self, RsiFileError> {
        const F: &str = "RSI context";
        let xml = |source| RsiFileError::Xml { file: F, source };
        let mut s = Scanner::new(text.as_bytes());
        let mut obj: Vec<u8> = Vec::new();
        let mut c = ContextConfig {
            config_file: String::new(),
            timeout: 100,
            precision: 4,
            lower_mm: [f64::NEG_INFINITY; 3],
            upper_mm: [f64::INFINITY; 3],
            max_rot_deg: f64::INFINITY,
            mon_max_trans_mm: f64::INFINITY,
            mon_max_rot_deg: f64::INFINITY,
            poscorr: false,
            axiscorr: false,
            axis_lower_deg: [f64::NEG_INFINITY; 6],
            axis_upper_deg: [f64::INFINITY; 6],
            axis_mon_max_deg: [f64::INFINITY; 6],
        };
        let mut seen_ethernet = false;
        while let Some(t) = s.next_token() {
            let Token::Start { name, attrs, .. } = t.map_err(xml)? else {
                continue;
            };
            if name == b"RSIObject" {
                obj = attr(attrs, b"ObjType").map_err(xml)?.unwrap_or(b"").to_ascii_uppercase();
                seen_ethernet |= obj == b"ETHERNET";
                c.poscorr |= obj == b"POSCORR";
                c.axiscorr |= obj == b"AXISCORR";
                continue;
            }
            if name != b"Parameter" {
                continue;
            }
            let pname = attr(attrs, b"Name").map_err(xml)?.unwrap_or(b"");
            let value = attr(attrs, b"ParamValue").map_err(xml)?.unwrap_or(b"");
            let text = String::from_utf8_lossy(value).into_owned();
            let num = |what| {
                text.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(RsiFileError::Bad { file: F, what })
            };
            match (obj.as_slice(), pname) {
                (b"ETHERNET", b"ConfigFile") => c.config_file = text.clone(),
                (b"ETHERNET", b"Timeout") => c.timeout = num("Timeout")? as u32,
                (b"ETHERNET", b"Precision") => c.precision = num("Precision")? as u8,
                (b"POSCORR", b"LowerLimX") => c.lower_mm[0] = num("LowerLimX")?,
                (b"POSCORR", b"LowerLimY") => c.lower_mm[1] = num("LowerLimY")?,
                (b"POSCORR", b"LowerLimZ") => c.lower_mm[2] = num("LowerLimZ")?,
                (b"POSCORR", b"UpperLimX") => c.upper_mm[0] = num("UpperLimX")?,
                (b"POSCORR", b"UpperLimY") => c.upper_mm[1] = num("UpperLimY")?,
                (b"POSCORR", b"UpperLimZ") => c.upper_mm[2] = num("UpperLimZ")?,
                (b"POSCORR", b"MaxRotAngle") => c.max_rot_deg = num("MaxRotAngle")?,
                (b"POSCORRMON", b"MaxTrans") => c.mon_max_trans_mm = num("MaxTrans")?,
                (b"POSCORRMON", b"MaxRotAngle") => c.mon_max_rot_deg = num("MaxRotAngle")?,
                (b"AXISCORR" | b"AXISCORRMON", _) => {
                    // LowerLimA1..A6, UpperLimA1..A6, MaxA1..A6 (E1..E6: no external axes).
                    let axis = |prefix: &[u8]| {
                        pname.strip_prefix(prefix).and_then(|r| match r {
                            [b'A', d @ b'1'..=b'6'] => Some((d - b'1') as usize),
                            _ => None,
                        })
                    };
                    let what = "AXISCORR/AXISCORRMON limit";
                    if obj == b"AXISCORR" {
                        if let Some(i) = axis(b"LowerLim") {
                            c.axis_lower_deg[i] = num(what)?;
                        } else if let Some(i) = axis(b"UpperLim") {
                            c.axis_upper_deg[i] = num(what)?;
                        }
                    } else if let Some(i) = axis(b"Max") {
                        let v = num(what)?;
                        if v < 0.0 {
                            return Err(RsiFileError::Bad { file: F, what });
                        }
                        c.axis_mon_max_deg[i] = v;
                    }
                }
                _ => {}
            }
        }
        if !seen_ethernet {
            return Err(RsiFileError::Missing { file: F, what: "ETHERNET object" });
        }
        if c.precision > topspin_core::rsi::MAX_PRECISION || c.timeout == 0 {
            return Err(RsiFileError::Bad { file: F, what: "Precision/Timeout" });
        }
        if (0..6).any(|i| c.axis_lower_deg[i] > 0.0 || c.axis_upper_deg[i] < 0.0) {
            return Err(RsiFileError::Bad { file: F, what: "AXISCORR limits (lower ≤ 0 ≤ upper)" });
        }
        Ok(c)
    }

    /// Checks that the context has the object the Ethernet configuration
    /// feeds (AXISCORR for AKorr, POSCORR for RKorr).
    pub fn check_feeds(&self, e: &EthernetConfig) -> Result<(), RsiFileError> {
        match e.correction() {
            Correction::Axis if !self.axiscorr => Err(RsiFileError::Mismatch { received: "AKorr", object: "AXISCORR" }),
            Correction::Cartesian if !self.poscorr => {
                Err(RsiFileError::Mismatch { received: "RKorr", object: "POSCORR" })
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use topspin_core::calib::Calibration;

    #[test]
    fn the_shipped_files_parse_and_match_the_calibration() {
        let e = EthernetConfig::parse(DEFAULT_ETHERNET_XML).unwrap();
        assert_eq!(e.sentype, "ImFree");
        assert_eq!(e.send.len(), 5);
        assert_eq!(e.receive.len(), 6);
        assert!(!e.only_send);
        let c = ContextConfig::parse(DEFAULT_CONTEXT_XML).unwrap();
        assert_eq!(c.config_file, "topspin_ethernet.xml");
        let r = Calibration::default_cell().robot;
        assert_eq!(c.timeout, r.rsi.late_limit);
        assert_eq!(c.lower_mm, r.poscorr.lower_xyz_mm);
        assert_eq!(c.upper_mm, r.poscorr.upper_xyz_mm);
        assert_eq!(c.max_rot_deg, r.poscorr.max_rot_angle_deg);
        assert_eq!(c.mon_max_trans_mm, r.poscorr.mon_max_trans_mm);
        assert_eq!(c.mon_max_rot_deg, r.poscorr.mon_max_rot_deg);
        let src = include_str!("../../../../rsi/topspin_rsi.src");
        assert!(src.contains("RSI_ON(#ABSOLUTE, #IPO_FAST)"));
        assert!(src.contains("PTP {X 350.0, Y 0.0, Z 450.0, A 180.0, B 0.0, C 0.0}"));
        assert_eq!(e.correction(), Correction::Cartesian);
        assert!(c.poscorr && !c.axiscorr);
        c.check_feeds(&e).unwrap();
    }

    #[test]
    fn the_axis_files_parse_and_stay_inside_the_software_limits() {
        let e = EthernetConfig::parse(AXIS_ETHERNET_XML).unwrap();
        assert_eq!(e.correction(), Correction::Axis);
        assert_eq!(e.receive, ["AKorr.A1", "AKorr.A2", "AKorr.A3", "AKorr.A4", "AKorr.A5", "AKorr.A6"]);
        let cart = EthernetConfig::parse(DEFAULT_ETHERNET_XML).unwrap();
        assert_eq!((e.ip, e.port, &e.sentype, &e.send), (cart.ip, cart.port, &cart.sentype, &cart.send));
        let c = ContextConfig::parse(AXIS_CONTEXT_XML).unwrap();
        assert_eq!(c.config_file, "topspin_axis_ethernet.xml");
        assert!(c.axiscorr && !c.poscorr);
        c.check_feeds(&e).unwrap();
        assert_eq!(c.axis_lower_deg, [-90.0, -60.0, -100.0, -150.0, -66.0, -180.0]);
        assert_eq!(c.axis_upper_deg, [90.0, 90.0, 34.0, 150.0, 45.0, 180.0]);
        assert_eq!(c.axis_mon_max_deg, [95.0, 95.0, 105.0, 155.0, 70.0, 185.0]);
        let r = Calibration::default_cell().robot;
        assert_eq!(c.timeout, r.rsi.late_limit);
        // From home, AXISCORR never lets an axis past its software limit switch.
        let arm = r.arm();
        let home = r.home_joints(&arm).unwrap().degrees();
        for (i, h) in home.iter().enumerate() {
            let (lo, hi) = (arm.limits.min[i].to_degrees(), arm.limits.max[i].to_degrees());
            assert!(h + c.axis_lower_deg[i] >= lo && h + c.axis_upper_deg[i] <= hi, "A{}", i + 1);
            assert!(c.axis_mon_max_deg[i] >= c.axis_lower_deg[i].abs().max(c.axis_upper_deg[i]), "A{}", i + 1);
        }
        let src = include_str!("../../../../rsi/topspin_axis_rsi.src");
        assert!(src.contains("RSI_CREATE(\"topspin_axis.rsi\", CONTID, TRUE)"));
        assert!(src.contains("RSI_ON(#ABSOLUTE, #IPO_FAST)"));
        // A context without AXISCORR for an Ethernet configuration sending AKorr is refused.
        let cart_ctx = ContextConfig::parse(DEFAULT_CONTEXT_XML).unwrap();
        assert!(matches!(cart_ctx.check_feeds(&e), Err(RsiFileError::Mismatch { object: "AXISCORR", .. })));
        assert!(matches!(c.check_feeds(&cart), Err(RsiFileError::Mismatch { object: "POSCORR", .. })));
        // Bad limits are named.
        let bad = AXIS_CONTEXT_XML.replace(
            "\"LowerLimA3\" ParamID=\"3\" ParamValue=\"-100.0\"",
            "\"LowerLimA3\" ParamID=\"3\" ParamValue=\"x\"",
        );
        assert_ne!(bad, AXIS_CONTEXT_XML);
        assert!(matches!(ContextConfig::parse(&bad), Err(RsiFileError::Bad { .. })));
        let bad = AXIS_CONTEXT_XML.replace("ParamValue=\"34.0\"", "ParamValue=\"-5.0\"");
        assert_ne!(bad, AXIS_CONTEXT_XML);
        assert!(matches!(ContextConfig::parse(&bad), Err(RsiFileError::Bad { .. })));
    }
}
