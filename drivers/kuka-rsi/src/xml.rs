//! The small part of XML that RSI speaks, scanned without allocating.
//!
//! Two users share the byte-level pieces here ([`Cursor`]): the strict two-level scanner for the
//! cyclic `<Rob>`/`<Sen>` datagrams ([`scan_message`]) and the nested, comment-tolerant reader of the
//! robot's Ethernet config (in `config.rs`).
//!
//! Tolerated: whitespace (including CRLF) between tags and around `=`, any attribute order, `/>` with
//! or without a space, single or double quotes, an optional `<?xml …?>` declaration.
//! Rejected: anything non-ASCII or a control character, `<!…>` (DOCTYPE, CDATA, comments) and `&`
//! (entities) in a message, nesting deeper than two levels, duplicate attributes, trailing content.

use core::fmt;

/// Why a datagram (or config) was rejected. `Copy` and allocation-free so the hot path can keep it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ParseError {
    /// Zero bytes (RSI 2.x sends an empty first frame).
    Empty,
    /// A byte outside printable ASCII (plus tab, CR, LF) at this offset.
    NonAscii {
        /// Byte offset.
        at: usize,
    },
    /// The input ended inside the document: a truncated datagram.
    Truncated,
    /// `<!…>`: DOCTYPE, CDATA or a comment, which RSI never sends.
    Markup {
        /// Byte offset.
        at: usize,
    },
    /// `&`: an entity or character reference, which RSI never sends.
    Entity {
        /// Byte offset.
        at: usize,
    },
    /// The XML is not well formed here.
    Syntax {
        /// Byte offset.
        at: usize,
        /// What was expected.
        expected: &'static str,
    },
    /// An element inside a child element (RSI messages are two levels deep).
    TooDeep {
        /// Byte offset.
        at: usize,
    },
    /// The same attribute twice on one element.
    DuplicateAttribute {
        /// Byte offset of the second one.
        at: usize,
    },
    /// More attributes on one element than [`MAX_ATTRIBUTES`].
    TooManyAttributes {
        /// Byte offset.
        at: usize,
    },
    /// The root element is not the one expected (`Rob` or `Sen`).
    WrongRoot,
    /// The `Type` attribute of `<Sen>` differs from the configured `SENTYPE`.
    WrongType,
    /// An element the config names appears twice.
    DuplicateElement {
        /// Index of the element in the schema.
        element: u8,
    },
    /// An element or attribute the config names is missing.
    MissingElement {
        /// Index of the element in the schema.
        element: u8,
    },
    /// A value is empty, not a plain decimal number, out of range, or non-finite.
    BadNumber {
        /// Byte offset of the value.
        at: usize,
    },
    /// `<IPOC>` is missing.
    MissingIpoc,
    /// `<IPOC>` is not 1–20 decimal digits that fit in a u64.
    BadIpoc,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Empty => f.write_str("empty datagram"),
            Self::NonAscii { at } => write!(f, "non-ASCII or control byte at offset {at}"),
            Self::Truncated => f.write_str("truncated: the document ends early"),
            Self::Markup { at } => write!(
                f,
                "DOCTYPE, CDATA or comment at offset {at} (RSI never sends them)"
            ),
            Self::Entity { at } => write!(f, "entity reference at offset {at} (not accepted)"),
            Self::Syntax { at, expected } => write!(f, "expected {expected} at offset {at}"),
            Self::TooDeep { at } => write!(f, "element nested deeper than 2 levels at offset {at}"),
            Self::DuplicateAttribute { at } => write!(f, "duplicate attribute at offset {at}"),
            Self::TooManyAttributes { at } => write!(
                f,
                "more than {MAX_ATTRIBUTES} attributes on one element at offset {at}"
            ),
            Self::WrongRoot => f.write_str("unexpected root element"),
            Self::WrongType => f.write_str("Type attribute does not match the configured SENTYPE"),
            Self::DuplicateElement { element } => {
                write!(f, "configured element #{element} appears twice")
            }
            Self::MissingElement { element } => {
                write!(
                    f,
                    "configured element #{element} (or one of its attributes) is missing"
                )
            }
            Self::BadNumber { at } => write!(
                f,
                "value at offset {at} is not a finite plain decimal number"
            ),
            Self::MissingIpoc => f.write_str("no <IPOC> element"),
            Self::BadIpoc => f.write_str("<IPOC> is not an unsigned decimal integer"),
        }
    }
}

impl std::error::Error for ParseError {}

impl hal::Error for ParseError {
    fn kind(&self) -> hal::ErrorKind {
        hal::ErrorKind::Malformed
    }
}

/// The most attributes one element may carry. RSI's own bounds: an ETHERNET object carries at most
/// 64 channels each way (all of which may be attributes of one element, `Out.o1` … `Out.o64`), and
/// the internal `DEF_Tech.C`/`DEF_Tech.T` generators add 10 attributes each to `<Tech>` (six of
/// each, 60 per prefix, on a KR C4). 64 channels plus 60 internal values is 124; the scanner keeps
/// 128 on the stack (1 KiB), no allocation. See `docs/wire-rsi.md`.
pub const MAX_ATTRIBUTES: usize = 128;

/// Printable ASCII, tab, CR or LF.
fn is_text_byte(c: u8) -> bool {
    (0x20..0x7f).contains(&c) | (c == b'\t') | (c == b'\r') | (c == b'\n')
}

pub(crate) fn is_ws(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\n')
}

fn is_name_start(b: u8) -> bool {
    b.is_ascii_alphabetic() || b == b'_'
}

fn is_name_char(b: u8) -> bool {
    b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'-' | b':')
}

/// A position in a byte slice with the XML primitives both scanners need.
pub(crate) struct Cursor<'a> {
    pub(crate) b: &'a [u8],
    pub(crate) i: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(b: &'a [u8]) -> Self {
        Self { b, i: 0 }
    }

    pub(crate) fn at_end(&self) -> bool {
        self.i >= self.b.len()
    }

    pub(crate) fn peek(&self) -> Option<u8> {
        self.b.get(self.i).copied()
    }

    pub(crate) fn starts_with(&self, s: &[u8]) -> bool {
        self.b[self.i.min(self.b.len())..].starts_with(s)
    }

    pub(crate) fn skip_ws(&mut self) {
        while let Some(c) = self.peek() {
            if !is_ws(c) {
                break;
            }
            self.i += 1;
        }
    }

    fn syntax(&self, expected: &'static str) -> ParseError {
        if self.at_end() {
            ParseError::Truncated
        } else {
            ParseError::Syntax {
                at: self.i,
                expected,
            }
        }
    }

    pub(crate) fn expect(&mut self, c: u8, expected: &'static str) -> Result<(), ParseError> {
        if self.peek() == Some(c) {
            self.i += 1;
            Ok(())
        } else {
            Err(self.syntax(expected))
        }
    }

    /// Skip past the next occurrence of `end`.
    pub(crate) fn skip_past(&mut self, end: &[u8]) -> Result<(), ParseError> {
        let rest = &self.b[self.i..];
        match rest.windows(end.len()).position(|w| w == end) {
            Some(p) => {
                self.i += p + end.len();
                Ok(())
            }
            None => {
                self.i = self.b.len();
                Err(ParseError::Truncated)
            }
        }
    }

    pub(crate) fn name(&mut self) -> Result<&'a [u8], ParseError> {
        let start = self.i;
        match self.peek() {
            Some(c) if is_name_start(c) => self.i += 1,
            _ => return Err(self.syntax("a name")),
        }
        while let Some(c) = self.peek() {
            if !is_name_char(c) {
                break;
            }
            self.i += 1;
        }
        Ok(&self.b[start..self.i])
    }

    /// Attributes up to and including `>` or `/>`; calls `f(name, value, value_offset)` for each.
    /// Returns true when the tag closed itself (`/>`).
    pub(crate) fn attributes(
        &mut self,
        mut f: impl FnMut(&'a [u8], &'a [u8], usize) -> Result<(), ParseError>,
    ) -> Result<bool, ParseError> {
        let mut seen: [(u32, u32); MAX_ATTRIBUTES] = [(0, 0); MAX_ATTRIBUTES];
        let mut sigs = 0u64;
        let mut n = 0;
        loop {
            let had_ws = self.peek().is_some_and(is_ws);
            self.skip_ws();
            match self.peek() {
                None => return Err(ParseError::Truncated),
                Some(b'>') => {
                    self.i += 1;
                    return Ok(false);
                }
                Some(b'/') => {
                    self.i += 1;
                    self.expect(b'>', "'>' after '/'")?;
                    return Ok(true);
                }
                Some(_) if !had_ws => return Err(self.syntax("whitespace before an attribute")),
                Some(_) => {}
            }
            let at = self.i;
            let name = self.name()?;
            let name_range = (at as u32, self.i as u32);
            // A cheap signature (length, last byte) screens the pairwise comparison.
            let sig = 1u64 << ((name.len() * 7 + usize::from(name[name.len() - 1])) % 64);
            if sigs & sig != 0
                && seen[..n]
                    .iter()
                    .any(|&(s, e)| &self.b[s as usize..e as usize] == name)
            {
                return Err(ParseError::DuplicateAttribute { at });
            }
            sigs |= sig;
            if n == seen.len() {
                return Err(ParseError::TooManyAttributes { at });
            }
            seen[n] = name_range;
            n += 1;
            self.skip_ws();
            self.expect(b'=', "'=' after an attribute name")?;
            self.skip_ws();
            let q = match self.peek() {
                Some(q @ (b'"' | b'\'')) => q,
                _ => return Err(self.syntax("a quoted attribute value")),
            };
            self.i += 1;
            let vstart = self.i;
            loop {
                match self.peek() {
                    None => return Err(ParseError::Truncated),
                    Some(c) if c == q => break,
                    Some(b'<') => return Err(self.syntax("the closing quote")),
                    Some(_) => self.i += 1,
                }
            }
            let value = &self.b[vstart..self.i];
            self.i += 1;
            f(name, value, vstart)?;
        }
    }

    /// Text up to the next `<` (not consumed), trimmed; returns the trimmed slice and its offset.
    pub(crate) fn text(&mut self) -> (&'a [u8], usize) {
        let start = self.i;
        while let Some(c) = self.peek() {
            if c == b'<' {
                break;
            }
            self.i += 1;
        }
        trim(self.b, start, self.i)
    }
}

pub(crate) fn trim(b: &[u8], mut s: usize, mut e: usize) -> (&[u8], usize) {
    while s < e && is_ws(b[s]) {
        s += 1;
    }
    while e > s && is_ws(b[e - 1]) {
        e -= 1;
    }
    (&b[s..e], s)
}

/// Skip an optional `<?xml …?>` declaration and the whitespace around it.
pub(crate) fn skip_declaration(c: &mut Cursor<'_>) -> Result<(), ParseError> {
    c.skip_ws();
    if c.starts_with(b"<?") {
        c.skip_past(b"?>")?;
        c.skip_ws();
    }
    Ok(())
}

/// What the strict message scanner reports, in document order.
pub(crate) trait Visitor<'a> {
    /// An attribute of the root element.
    fn root_attr(&mut self, name: &'a [u8], value: &'a [u8], at: usize) -> Result<(), ParseError>;
    /// A child element starts.
    fn child(&mut self, tag: &'a [u8]) -> Result<(), ParseError>;
    /// An attribute of the current child.
    fn child_attr(&mut self, name: &'a [u8], value: &'a [u8], at: usize) -> Result<(), ParseError>;
    /// The (trimmed) text of the current child; only called for `<tag>text</tag>`.
    fn child_text(&mut self, text: &'a [u8], at: usize) -> Result<(), ParseError>;
}

/// Scan one RSI message: `<Root attrs>` children `</Root>`, each child `<tag attrs/>` or
/// `<tag attrs>text</tag>`. Returns the root's name.
pub(crate) fn scan_message<'a>(
    b: &'a [u8],
    v: &mut impl Visitor<'a>,
) -> Result<&'a [u8], ParseError> {
    if b.is_empty() {
        return Err(ParseError::Empty);
    }
    // One branch-free (vectorisable) pass; the slow loop only runs to report where.
    let suspicious = b
        .iter()
        .fold(false, |acc, &c| acc | (c == b'&') | !is_text_byte(c));
    if suspicious {
        for (at, &c) in b.iter().enumerate() {
            if c == b'&' {
                return Err(ParseError::Entity { at });
            }
            if !is_text_byte(c) {
                return Err(ParseError::NonAscii { at });
            }
        }
    }
    let mut c = Cursor::new(b);
    skip_declaration(&mut c)?;
    if c.starts_with(b"<!") {
        return Err(ParseError::Markup { at: c.i });
    }
    c.expect(b'<', "'<' opening the root element")?;
    let root = c.name()?;
    let empty_root = c.attributes(|n, val, at| v.root_attr(n, val, at))?;
    if empty_root {
        // `<Rob/>` holds nothing, not even an IPOC; the caller reports what is missing.
        c.skip_ws();
        return if c.at_end() {
            Ok(root)
        } else {
            Err(c.syntax("end of datagram after the root element"))
        };
    }
    loop {
        c.skip_ws();
        match c.peek() {
            None => return Err(ParseError::Truncated),
            Some(b'<') => {}
            Some(_) => return Err(c.syntax("'<' (text directly inside the root)")),
        }
        if c.starts_with(b"<!") {
            return Err(ParseError::Markup { at: c.i });
        }
        if c.starts_with(b"</") {
            c.i += 2;
            let end = c.name()?;
            if c.at_end() {
                return Err(ParseError::Truncated);
            }
            if end != root {
                return Err(ParseError::Syntax {
                    at: c.i - end.len(),
                    expected: "the root's closing tag",
                });
            }
            c.skip_ws();
            c.expect(b'>', "'>'")?;
            c.skip_ws();
            return if c.at_end() {
                Ok(root)
            } else {
                Err(c.syntax("end of datagram after the root element"))
            };
        }
        c.i += 1;
        let tag = c.name()?;
        v.child(tag)?;
        let closed = c.attributes(|n, val, at| v.child_attr(n, val, at))?;
        if closed {
            continue;
        }
        let (text, at) = c.text();
        if c.at_end() {
            return Err(ParseError::Truncated);
        }
        if !c.starts_with(b"</") {
            return Err(if c.starts_with(b"<!") {
                ParseError::Markup { at: c.i }
            } else {
                ParseError::TooDeep { at: c.i }
            });
        }
        v.child_text(text, at)?;
        c.i += 2;
        let end = c.name()?;
        if c.at_end() {
            return Err(ParseError::Truncated);
        }
        if end != tag {
            return Err(ParseError::Syntax {
                at: c.i - end.len(),
                expected: "the matching closing tag",
            });
        }
        c.skip_ws();
        c.expect(b'>', "'>'")?;
    }
}
