//! A tolerant, zero-allocation XML scanner for RSI datagrams and the
//! controller-side configuration files.
//!
//! It understands exactly what RSI uses: elements with attributes
//! (`name="v"` or `name='v'`), text content, `<?…?>` declarations and
//! `<!--…-->` comments. No entities, no namespaces, no validation of
//! nesting: callers look for the elements they know and skip the rest.
//! It never panics: every index is checked, and bytes that are not XML end
//! the scan with an error.

/// One thing found in the byte stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Token<'a> {
    /// `<name attrs…>` or `<name attrs…/>` (`empty` = self-closing).
    Start {
        /// The element name.
        name: &'a [u8],
        /// The raw bytes after the name: attributes, not yet parsed.
        attrs: &'a [u8],
        /// Whether the tag is self-closing (`<name …/>`).
        empty: bool,
    },
    /// `</name>`.
    End {
        /// The element name, white space trimmed.
        name: &'a [u8],
    },
    /// Text between tags (white space included).
    Text(&'a [u8]),
}

/// The scan hit bytes that are not well-formed enough to go on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("malformed XML at byte {at}")]
pub struct XmlError {
    /// Byte offset into the input where the scan stopped.
    pub at: usize,
}

/// Iterates over the tokens of `bytes`.
#[derive(Clone, Debug)]
pub struct Scanner<'a> {
    b: &'a [u8],
    i: usize,
}

fn find(hay: &[u8], from: usize, needle: &[u8]) -> Option<usize> {
    if needle.is_empty() || from > hay.len() {
        return None;
    }
    hay.get(from..)?.windows(needle.len()).position(|w| w == needle).map(|p| p + from)
}

fn is_name_byte(c: u8) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, b'_' | b'-' | b'.' | b':')
}

impl<'a> Scanner<'a> {
    /// A scanner at the start of `b`.
    pub fn new(b: &'a [u8]) -> Self {
        Scanner { b, i: 0 }
    }

    /// The next token, `None` at the end, or an error (after which the
    /// scanner stays at the end).
    pub fn next_token(&mut self) -> Option<Result<Token<'a>, XmlError>> {
        let b = self.b;
        loop {
            if self.i >= b.len() {
                return None;
            }
            if b[self.i] != b'<' {
                let start = self.i;
                let end = find(b, start, b"<").unwrap_or(b.len());
                self.i = end;
                return Some(Ok(Token::Text(&b[start..end])));
            }
            let rest = &b[self.i..];
            if rest.starts_with(b"<?") {
                match find(b, self.i + 2, b"?>") {
                    Some(e) => {
                        self.i = e + 2;
                        continue;
                    }
                    None => return Some(self.fail()),
                }
            }
            if rest.starts_with(b"<!--") {
                match find(b, self.i + 4, b"-->") {
                    Some(e) => {
                        self.i = e + 3;
                        continue;
                    }
                    None => return Some(self.fail()),
                }
            }
            let Some(close) = self.tag_end(self.i + 1) else {
                return Some(self.fail());
            };
            let inner = &b[self.i + 1..close];
            self.i = close + 1;
            if let Some(name) = inner.strip_prefix(b"/") {
                let name = trim(name);
                if name.is_empty() || !name.iter().all(|&c| is_name_byte(c)) {
                    return Some(self.fail());
                }
                return Some(Ok(Token::End { name }));
            }
            let (inner, empty) = match inner.strip_suffix(b"/") {
                Some(x) => (x, true),
                None => (inner, false),
            };
            let n = inner.iter().take_while(|&&c| is_name_byte(c)).count();
            if n == 0 {
                return Some(self.fail());
            }
            return Some(Ok(Token::Start { name: &inner[..n], attrs: &inner[n..], empty }));
        }
    }

    /// Index of the `>` closing the tag that starts before `from`, skipping
    /// quoted attribute values.
    fn tag_end(&self, from: usize) -> Option<usize> {
        let mut quote = 0u8;
        for (k, &c) in self.b.get(from..)?.iter().enumerate() {
            if quote != 0 {
                if c == quote {
                    quote = 0;
                }
            } else if c == b'"' || c == b'\'' {
                quote = c;
            } else if c == b'>' {
                return Some(from + k);
            } else if c == b'<' {
                return None;
            }
        }
        None
    }

    fn fail<T>(&mut self) -> Result<T, XmlError> {
        let at = self.i;
        self.i = self.b.len();
        Err(XmlError { at })
    }
}

/// White space trimmed from both ends.
pub fn trim(mut s: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = s {
        if first.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    while let [rest @ .., last] = s {
        if last.is_ascii_whitespace() {
            s = rest;
        } else {
            break;
        }
    }
    s
}

/// Iterates over `name="value"` pairs of an attribute slice.
#[derive(Clone, Debug)]
pub(crate) struct Attrs<'a> {
    b: &'a [u8],
    i: usize,
}

impl<'a> Attrs<'a> {
    pub(crate) fn new(b: &'a [u8]) -> Self {
        Attrs { b, i: 0 }
    }
}

impl<'a> Iterator for Attrs<'a> {
    /// `(name, value)`, or `Err` for bytes that are not an attribute.
    type Item = Result<(&'a [u8], &'a [u8]), XmlError>;

    fn next(&mut self) -> Option<Self::Item> {
        let b = self.b;
        while self.i < b.len() && b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        if self.i >= b.len() {
            return None;
        }
        let start = self.i;
        while self.i < b.len() && is_name_byte(b[self.i]) {
            self.i += 1;
        }
        let name = &b[start..self.i];
        while self.i < b.len() && b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        let bad = |s: &mut Self| {
            let at = s.i;
            s.i = s.b.len();
            Some(Err(XmlError { at }))
        };
        if name.is_empty() || b.get(self.i) != Some(&b'=') {
            return bad(self);
        }
        self.i += 1;
        while self.i < b.len() && b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        let Some(&q) = b.get(self.i) else {
            return bad(self);
        };
        if q != b'"' && q != b'\'' {
            return bad(self);
        }
        let vstart = self.i + 1;
        let Some(vlen) = b.get(vstart..).and_then(|r| r.iter().position(|&c| c == q)) else {
            return bad(self);
        };
        self.i = vstart + vlen + 1;
        Some(Ok((name, &b[vstart..vstart + vlen])))
    }
}

/// The value of attribute `name` (ASCII case-insensitive), if present.
pub fn attr<'a>(attrs: &'a [u8], name: &[u8]) -> Result<Option<&'a [u8]>, XmlError> {
    for a in Attrs::new(attrs) {
        let (n, v) = a?;
        if n.eq_ignore_ascii_case(name) {
            return Ok(Some(v));
        }
    }
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_and_attributes() {
        let x = br#"<?xml version="1.0"?><!-- c --><Rob Type='KUKA'> <IPOC>12</IPOC><E a="1>2" b = "x"/></Rob>"#;
        let mut s = Scanner::new(x);
        let mut n = 0;
        while let Some(t) = s.next_token() {
            t.unwrap();
            n += 1;
        }
        assert_eq!(n, 7);
        assert_eq!(attr(br#" a="1>2" b = "x""#, b"B").unwrap(), Some(&b"x"[..]));
        assert!(attr(br#" a=1"#, b"a").is_err());
        assert!(Scanner::new(b"<a").next_token().unwrap().is_err());
    }
}
