//! The sans-IO RSI codec, one for both directions.
//!
//! A [`Schema`] says which elements a message carries, in which order and of which type; it is built
//! from the robot's Ethernet config ([`crate::EthernetConfig::rob_schema`] for what the robot sends,
//! [`crate::EthernetConfig::sen_schema`] for what it receives). A [`Frame`] holds one message's values
//! in numbered slots plus its IPOC, in wire units (mm, degrees) exactly as on the wire.
//!
//! * The driver parses `<Rob>` and writes `<Sen>`; the simulated controller writes `<Rob>` and parses
//!   `<Sen>` — the same [`Schema::parse`] and [`Schema::write`].
//! * Neither allocates: the frame is a fixed array, the writer fills a caller's buffer.
//! * The IPOC is kept as the digits received and echoed verbatim.
//! * Numbers are written as plain fixed-point with the schema's precision: never an exponent, NaN or inf.

use core::fmt;

use crate::layout::Recorded;
use crate::xml::{ParseError, Visitor, scan_message};

/// How many numeric values one message can hold (six internal poses, `Delay`, `Tech` and 64 user
/// channels fit with room to spare).
pub const MAX_SLOTS: usize = 128;

/// How many elements one message can name (besides `IPOC`).
pub const MAX_ELEMENTS: usize = 128;

/// The type of one value, as the config's `TYPE` attribute names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ValueType {
    /// `0`/`1` (also accepts `TRUE`/`FALSE`).
    Bool,
    /// A signed integer.
    Long,
    /// A fixed-point decimal.
    Double,
    /// Free text. The codec checks it is ASCII, does not keep it, and writes it empty.
    String,
}

impl ValueType {
    /// The config's spelling.
    pub fn as_config(self) -> &'static str {
        match self {
            Self::Bool => "BOOL",
            Self::Long => "LONG",
            Self::Double => "DOUBLE",
            Self::String => "STRING",
        }
    }

    /// Parse the config's spelling (case-insensitive).
    pub fn from_config(s: &str) -> Option<Self> {
        match s.to_ascii_uppercase().as_str() {
            "BOOL" => Some(Self::Bool),
            "LONG" => Some(Self::Long),
            "DOUBLE" => Some(Self::Double),
            "STRING" => Some(Self::String),
            _ => None,
        }
    }
}

/// One value of an element: an attribute, or the element's text.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Attribute name; empty for an element's text.
    pub name: String,
    /// Type.
    pub ty: ValueType,
    /// Slot in a [`Frame`]; `None` for strings.
    pub slot: Option<usize>,
    /// HOLDON of the config (what the robot does with this value on a late reply).
    pub holdon: bool,
    /// Decimals written for this double, when they differ from the schema's precision.
    decimals: Option<u8>,
    key: u64,
}

/// What an element carries.
#[derive(Clone, Debug, PartialEq)]
pub enum Content {
    /// `<Tag A="…" B="…"/>`.
    Attributes(Vec<Field>),
    /// `<Tag>…</Tag>`.
    Text(Field),
}

/// One element of a message.
#[derive(Clone, Debug, PartialEq)]
pub struct ElementSpec {
    /// Tag name.
    pub tag: String,
    /// Its values.
    pub content: Content,
    key: u64,
}

impl ElementSpec {
    /// The fields, attributes or text.
    pub fn fields(&self) -> &[Field] {
        match &self.content {
            Content::Attributes(f) => f,
            Content::Text(f) => core::slice::from_ref(f),
        }
    }
}

/// Which message a schema describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Robot → PC, root `<Rob>`.
    Rob,
    /// PC → robot, root `<Sen>`.
    Sen,
}

impl Direction {
    fn root(self) -> &'static [u8] {
        match self {
            Self::Rob => b"Rob",
            Self::Sen => b"Sen",
        }
    }
}

/// The layout of one message: elements in order, their slots, the `Type` attribute and precision.
#[derive(Clone, Debug, PartialEq)]
pub struct Schema {
    direction: Direction,
    type_value: String,
    elements: Vec<ElementSpec>,
    slots: usize,
    required: u128,
    precision: u8,
    /// The message's constant text, derived from the rest (see [`Schema::rebuild`]).
    template: Template,
}

/// What [`Schema::write`] writes: the constant text between the values, precomputed, so a message
/// is a few copies and its numbers.
#[derive(Clone, Debug, Default, PartialEq)]
struct Template {
    /// Everything but the values and the IPOC's digits, in order.
    text: Vec<u8>,
    /// Where each value goes in `text` (in order), and its element and field.
    values: Vec<(u32, u16, u16)>,
    /// Where the IPOC's digits go in `text`.
    ipoc_at: u32,
    /// The text's length (16 zero bytes follow it).
    len: u32,
}

impl Schema {
    /// An empty schema. `type_value` is written as the root's `Type`; for [`Direction::Sen`] a parsed
    /// message must carry exactly it (the robot's `SENTYPE`). `precision` is the number of decimals
    /// written for doubles (0–9).
    pub fn new(direction: Direction, type_value: &str, precision: u8) -> Result<Self, String> {
        if precision > 9 {
            return Err(format!("precision must be 0..=9 decimals, got {precision}"));
        }
        if type_value.is_empty()
            || !type_value
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
        {
            return Err(format!(
                "Type {type_value:?} must be non-empty ASCII letters, digits, '_' or '-'"
            ));
        }
        Ok(Self {
            direction,
            type_value: type_value.to_owned(),
            elements: Vec::new(),
            slots: 0,
            required: 0,
            precision,
            template: Template::default(),
        }
        .rebuilt())
    }

    fn rebuilt(mut self) -> Self {
        self.rebuild();
        self
    }

    /// Derive the write template from the elements (after every change to them).
    fn rebuild(&mut self) {
        let root = self.direction.root();
        let mut text = Vec::new();
        let mut values = Vec::new();
        let mark = |text: &Vec<u8>| text.len() as u32;
        text.extend_from_slice(b"<");
        text.extend_from_slice(root);
        text.extend_from_slice(b" Type=\"");
        text.extend_from_slice(self.type_value.as_bytes());
        text.extend_from_slice(b"\">");
        for (ei, e) in self.elements.iter().enumerate() {
            text.extend_from_slice(b"<");
            text.extend_from_slice(e.tag.as_bytes());
            match &e.content {
                Content::Attributes(fields) => {
                    for (fi, f) in fields.iter().enumerate() {
                        text.extend_from_slice(b" ");
                        text.extend_from_slice(f.name.as_bytes());
                        text.extend_from_slice(b"=\"");
                        values.push((mark(&text), ei as u16, fi as u16));
                        text.extend_from_slice(b"\"");
                    }
                    text.extend_from_slice(b"/>");
                }
                Content::Text(_) => {
                    text.extend_from_slice(b">");
                    values.push((mark(&text), ei as u16, 0));
                    text.extend_from_slice(b"</");
                    text.extend_from_slice(e.tag.as_bytes());
                    text.extend_from_slice(b">");
                }
            }
        }
        text.extend_from_slice(b"<IPOC>");
        let ipoc_at = mark(&text);
        text.extend_from_slice(b"</IPOC></");
        text.extend_from_slice(root);
        text.extend_from_slice(b">");
        let len = text.len() as u32;
        // Room to read a whole 16-byte block from any piece's start.
        text.extend_from_slice(&[0; 16]);
        self.template = Template {
            len,
            text,
            values,
            ipoc_at,
        };
    }

    /// Which message this is.
    pub fn direction(&self) -> Direction {
        self.direction
    }

    /// The root's `Type` value.
    pub fn type_value(&self) -> &str {
        &self.type_value
    }

    /// Decimals written for doubles.
    pub fn precision(&self) -> u8 {
        self.precision
    }

    /// The elements in order.
    pub fn elements(&self) -> &[ElementSpec] {
        &self.elements
    }

    /// Number of slots in use.
    pub fn slots(&self) -> usize {
        self.slots
    }

    fn check_name(name: &str) -> Result<(), String> {
        let ok = name
            .bytes()
            .next()
            .is_some_and(|b| b.is_ascii_alphabetic() || b == b'_')
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
        if ok && name != "IPOC" {
            Ok(())
        } else {
            Err(format!(
                "{name:?} is not usable as an RSI tag or attribute name (ASCII letters, digits, '_', '-'; not IPOC)"
            ))
        }
    }

    fn field(&mut self, name: &str, ty: ValueType, holdon: bool) -> Result<Field, String> {
        let slot = if ty == ValueType::String {
            None
        } else {
            if self.slots == MAX_SLOTS {
                return Err(format!("more than {MAX_SLOTS} values in one message"));
            }
            self.required |= 1u128 << self.slots;
            self.slots += 1;
            Some(self.slots - 1)
        };
        Ok(Field {
            name: name.to_owned(),
            ty,
            slot,
            holdon,
            decimals: None,
            key: short_key(name.as_bytes()),
        })
    }

    /// Add attribute `name` of element `tag` (created at the end if new).
    pub fn push_attr(
        &mut self,
        tag: &str,
        name: &str,
        ty: ValueType,
        holdon: bool,
    ) -> Result<(), String> {
        Self::check_name(tag)?;
        Self::check_name(name)?;
        let idx = match self.elements.iter().position(|e| e.tag == tag) {
            Some(i) => i,
            None => {
                if self.elements.len() == MAX_ELEMENTS {
                    return Err(format!("more than {MAX_ELEMENTS} elements in one message"));
                }
                self.elements.push(ElementSpec {
                    tag: tag.to_owned(),
                    content: Content::Attributes(Vec::new()),
                    key: short_key(tag.as_bytes()),
                });
                self.elements.len() - 1
            }
        };
        if let Content::Attributes(fields) = &self.elements[idx].content {
            if fields.iter().any(|f| f.name == name) {
                return Err(format!("{tag}.{name} is configured twice"));
            }
        } else {
            return Err(format!(
                "{tag} is configured both as a text element and with attribute {name}"
            ));
        }
        let field = self.field(name, ty, holdon)?;
        if let Content::Attributes(fields) = &mut self.elements[idx].content {
            fields.push(field);
        }
        self.rebuild();
        Ok(())
    }

    /// Add a text element `<tag>value</tag>` at the end.
    pub fn push_text(&mut self, tag: &str, ty: ValueType, holdon: bool) -> Result<(), String> {
        Self::check_name(tag)?;
        if self.elements.iter().any(|e| e.tag == tag) {
            return Err(format!("{tag} is configured twice"));
        }
        if self.elements.len() == MAX_ELEMENTS {
            return Err(format!("more than {MAX_ELEMENTS} elements in one message"));
        }
        let field = self.field("", ty, holdon)?;
        self.elements.push(ElementSpec {
            tag: tag.to_owned(),
            content: Content::Text(field),
            key: short_key(tag.as_bytes()),
        });
        self.rebuild();
        Ok(())
    }

    /// Write attribute `attr` of `tag` (the text of `tag` when `attr` is empty) with `decimals`
    /// decimals instead of the schema's precision (e.g. `FcState.F`: 2). Only doubles have decimals.
    pub fn set_decimals(&mut self, tag: &str, attr: &str, decimals: u8) -> Result<(), String> {
        if decimals > 9 {
            return Err(format!("decimals must be 0..=9, got {decimals}"));
        }
        let e = self
            .elements
            .iter_mut()
            .find(|e| e.tag == tag)
            .ok_or_else(|| format!("no element {tag}"))?;
        let f = match &mut e.content {
            Content::Attributes(fields) => fields.iter_mut().find(|f| f.name == attr),
            Content::Text(f) => attr.is_empty().then_some(f),
        }
        .ok_or_else(|| format!("{tag} has no value {attr:?}"))?;
        if f.ty != ValueType::Double {
            return Err(format!("{tag}.{attr} is not a DOUBLE"));
        }
        f.decimals = Some(decimals);
        Ok(())
    }

    /// The slot of attribute `attr` of `tag`, or of the text of `tag` when `attr` is empty.
    pub fn slot(&self, tag: &str, attr: &str) -> Option<usize> {
        let e = self.elements.iter().find(|e| e.tag == tag)?;
        e.fields().iter().find(|f| f.name == attr)?.slot
    }

    /// The slots of six attributes of `tag` (e.g. `RIst` `X Y Z A B C`), if all are there.
    pub fn six(&self, tag: &str, attrs: [&str; 6]) -> Option<[usize; 6]> {
        let mut out = [0; 6];
        for (o, a) in out.iter_mut().zip(attrs) {
            *o = self.slot(tag, a)?;
        }
        Some(out)
    }

    /// The field behind a slot.
    pub fn field_of(&self, slot: usize) -> Option<&Field> {
        self.elements
            .iter()
            .flat_map(|e| e.fields())
            .find(|f| f.slot == Some(slot))
    }

    /// Name an element index from a [`ParseError`].
    pub fn element_name(&self, index: u8) -> Option<&str> {
        self.elements.get(index as usize).map(|e| e.tag.as_str())
    }

    /// Parse one message into `frame`. On error the frame's contents are unspecified.
    pub fn parse(&self, bytes: &[u8], frame: &mut Frame) -> Result<(), ParseError> {
        self.parse_recording(bytes, frame, None)
    }

    /// [`Schema::parse`], recording where each value lay in `bytes` into `rec` (for a [`Layout`]).
    pub(crate) fn parse_recording(
        &self,
        bytes: &[u8],
        frame: &mut Frame,
        rec: Option<&mut Recorded>,
    ) -> Result<(), ParseError> {
        frame.clear_for_parse();
        let mut st = ParseState {
            schema: self,
            frame,
            cur: Cur::Unknown,
            next_element: 0,
            next_field: 0,
            seen: 0,
            ipoc_seen: false,
            type_seen: false,
            rec,
        };
        if let Some(r) = st.rec.as_mut() {
            r.clear();
        }
        let root = scan_message(bytes, &mut st)?;
        if root != self.direction.root() {
            return Err(ParseError::WrongRoot);
        }
        if self.direction == Direction::Sen && !st.type_seen {
            return Err(ParseError::WrongType);
        }
        if !st.ipoc_seen {
            return Err(ParseError::MissingIpoc);
        }
        let missing = self.required & !st.frame.present;
        if missing != 0 {
            let slot = missing.trailing_zeros() as usize;
            let element = self
                .elements
                .iter()
                .position(|e| e.fields().iter().any(|f| f.slot == Some(slot)))
                .unwrap_or(0);
            return Err(ParseError::MissingElement {
                element: element as u8,
            });
        }
        Ok(())
    }

    /// Write one message from `frame` into `out`; returns the number of bytes written.
    pub fn write(&self, frame: &Frame, out: &mut [u8]) -> Result<usize, WriteError> {
        let mut w = Out { buf: out, n: 0 };
        let t = &self.template;
        let mut from = 0usize;
        for &(at, e, f) in &t.values {
            let at = at as usize;
            w.put_piece(&t.text, from, at)?;
            self.value(
                &mut w,
                &self.elements[usize::from(e)].fields()[usize::from(f)],
                frame,
            )?;
            from = at;
        }
        let ipoc_at = t.ipoc_at as usize;
        w.put_piece(&t.text, from, ipoc_at)?;
        w.put(frame.ipoc.digits())?;
        w.put(&t.text[ipoc_at..t.len as usize])?;
        Ok(w.n)
    }

    fn value(&self, w: &mut Out<'_>, f: &Field, frame: &Frame) -> Result<(), WriteError> {
        let Some(slot) = f.slot else {
            return Ok(());
        };
        let v = frame.values[slot];
        if !v.is_finite() {
            return Err(WriteError::NonFinite { slot });
        }
        match f.ty {
            ValueType::Bool => w.put(if v != 0.0 { b"1" } else { b"0" }),
            ValueType::Long => w.fixed(v, 0, slot),
            ValueType::Double => w.fixed(v, f.decimals.unwrap_or(self.precision), slot),
            ValueType::String => Ok(()),
        }
    }
}

/// Why a message could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WriteError {
    /// The output buffer is too small.
    BufferTooSmall,
    /// A value is NaN or infinite (never written).
    NonFinite {
        /// Slot.
        slot: usize,
    },
    /// A value is too large to write in plain fixed-point at the schema's precision.
    OutOfRange {
        /// Slot.
        slot: usize,
    },
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BufferTooSmall => f.write_str("output buffer too small for the message"),
            Self::NonFinite { slot } => write!(f, "value in slot {slot} is not finite"),
            Self::OutOfRange { slot } => {
                write!(
                    f,
                    "value in slot {slot} is too large for fixed-point output"
                )
            }
        }
    }
}

impl std::error::Error for WriteError {}

/// An IPOC: the digits as received (echoed verbatim) and their value.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Ipoc {
    value: u64,
    digits: [u8; 20],
    len: u8,
}

impl fmt::Debug for Ipoc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Ipoc({})",
            core::str::from_utf8(self.digits()).unwrap_or("?")
        )
    }
}

impl Ipoc {
    /// The canonical digits of `value`.
    pub fn new(value: u64) -> Self {
        let mut digits = [0u8; 20];
        let mut tmp = [0u8; 20];
        let mut n = 0;
        let mut v = value;
        loop {
            tmp[n] = b'0' + (v % 10) as u8;
            n += 1;
            v /= 10;
            if v == 0 {
                break;
            }
        }
        for k in 0..n {
            digits[k] = tmp[n - 1 - k];
        }
        Self {
            value,
            digits,
            len: n as u8,
        }
    }

    /// Parse 1–20 ASCII digits (leading zeros kept for the echo).
    pub fn parse(text: &[u8]) -> Result<Self, ParseError> {
        if text.is_empty() || text.len() > 20 || !text.iter().all(u8::is_ascii_digit) {
            return Err(ParseError::BadIpoc);
        }
        let mut value: u64 = 0;
        for &d in text {
            value = value
                .checked_mul(10)
                .and_then(|v| v.checked_add(u64::from(d - b'0')))
                .ok_or(ParseError::BadIpoc)?;
        }
        let mut digits = [0u8; 20];
        digits[..text.len()].copy_from_slice(text);
        Ok(Self {
            value,
            digits,
            len: text.len() as u8,
        })
    }

    /// Its value.
    pub fn value(&self) -> u64 {
        self.value
    }

    /// The digits exactly as received.
    pub fn digits(&self) -> &[u8] {
        &self.digits[..self.len as usize]
    }
}

/// One message's values in wire units, by slot, and its IPOC.
#[derive(Clone, PartialEq)]
pub struct Frame {
    values: [f64; MAX_SLOTS],
    present: u128,
    ipoc: Ipoc,
}

impl Default for Frame {
    fn default() -> Self {
        Self::new()
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = 128 - self.present.leading_zeros() as usize;
        f.debug_struct("Frame")
            .field("ipoc", &self.ipoc)
            .field("values", &&self.values[..n])
            .finish()
    }
}

impl Frame {
    /// No value present, IPOC 0: what a parse starts from.
    pub(crate) fn clear_for_parse(&mut self) {
        self.present = 0;
        self.ipoc = Ipoc::default();
    }

    /// All zeros, IPOC 0.
    pub fn new() -> Self {
        Self {
            values: [0.0; MAX_SLOTS],
            present: 0,
            ipoc: Ipoc::new(0),
        }
    }

    /// The value in `slot` (0 when never set).
    pub fn get(&self, slot: usize) -> f64 {
        self.values[slot]
    }

    /// Set the value in `slot`.
    pub fn set(&mut self, slot: usize, v: f64) {
        self.values[slot] = v;
        self.present |= 1u128 << slot;
    }

    /// Six slots at once.
    pub fn get6(&self, slots: [usize; 6]) -> [f64; 6] {
        slots.map(|s| self.values[s])
    }

    /// Set the value in `slot` without marking it present (see [`Frame::mark_present`]).
    #[inline]
    pub(crate) fn put_value(&mut self, slot: usize, v: f64) {
        self.values[slot] = v;
    }

    /// Mark the slots in `mask` present (a reader that filled all of them).
    pub(crate) fn mark_present(&mut self, mask: u128) {
        self.present |= mask;
    }

    /// Set six slots at once.
    pub fn set6(&mut self, slots: [usize; 6], v: [f64; 6]) {
        for (s, x) in slots.into_iter().zip(v) {
            self.set(s, x);
        }
    }

    /// True when the last parse (or a `set`) filled `slot`.
    pub fn is_present(&self, slot: usize) -> bool {
        self.present & (1u128 << slot) != 0
    }

    /// The IPOC.
    pub fn ipoc(&self) -> &Ipoc {
        &self.ipoc
    }

    /// Set the IPOC.
    pub fn set_ipoc(&mut self, ipoc: Ipoc) {
        self.ipoc = ipoc;
    }
}

/// Names of up to 8 bytes packed into one integer (names never contain NUL, so zero padding is
/// unambiguous); 0 for longer names, which are compared byte by byte.
fn short_key(name: &[u8]) -> u64 {
    if name.is_empty() || name.len() > 8 {
        return 0;
    }
    name.iter()
        .rev()
        .fold(0u64, |k, &b| (k << 8) | u64::from(b))
}

enum Cur {
    Element(usize),
    Ipoc,
    Unknown,
}

struct ParseState<'s, 'f, 'r> {
    schema: &'s Schema,
    frame: &'f mut Frame,
    /// Where each value lay, when a layout is being learnt.
    rec: Option<&'r mut Recorded>,
    cur: Cur,
    /// Where the next element / field most likely is (messages come in config order).
    next_element: usize,
    next_field: usize,
    seen: u128,
    ipoc_seen: bool,
    type_seen: bool,
}

impl ParseState<'_, '_, '_> {
    fn store(&mut self, f: &Field, value: &[u8], at: usize) -> Result<(), ParseError> {
        let Some(slot) = f.slot else {
            return Ok(());
        };
        if f.ty == ValueType::String {
            return Ok(());
        }
        let v = parse_value(f.ty, value).ok_or(ParseError::BadNumber { at })?;
        self.frame.set(slot, v);
        if let Some(r) = self.rec.as_mut() {
            r.push(at, value.len(), Some((slot, f.ty)));
        }
        Ok(())
    }
}

/// A value of type `ty` (not `String`) in wire units.
pub(crate) fn parse_value(ty: ValueType, value: &[u8]) -> Option<f64> {
    match ty {
        ValueType::Double => parse_decimal(value),
        ValueType::Long => parse_integer(value),
        ValueType::Bool => parse_bool(value),
        ValueType::String => None,
    }
}

impl<'a> Visitor<'a> for ParseState<'_, '_, '_> {
    fn root_attr(&mut self, name: &'a [u8], value: &'a [u8], _at: usize) -> Result<(), ParseError> {
        if name.eq_ignore_ascii_case(b"type") {
            if self.schema.direction == Direction::Sen && value != self.schema.type_value.as_bytes()
            {
                return Err(ParseError::WrongType);
            }
            self.type_seen = true;
        }
        Ok(())
    }

    fn child(&mut self, tag: &'a [u8]) -> Result<(), ParseError> {
        if tag == b"IPOC" {
            if self.ipoc_seen {
                return Err(ParseError::BadIpoc);
            }
            self.cur = Cur::Ipoc;
            return Ok(());
        }
        let els = &self.schema.elements;
        let key = short_key(tag);
        let is = |e: &ElementSpec| e.key == key && (key != 0 || e.tag.as_bytes() == tag);
        let found = match els.get(self.next_element) {
            Some(e) if is(e) => Some(self.next_element),
            _ => els.iter().position(is),
        };
        self.next_field = 0;
        self.cur = match found {
            Some(i) => {
                if self.seen & (1u128 << i) != 0 {
                    return Err(ParseError::DuplicateElement { element: i as u8 });
                }
                self.seen |= 1u128 << i;
                self.next_element = i + 1;
                Cur::Element(i)
            }
            None => Cur::Unknown,
        };
        Ok(())
    }

    fn child_attr(&mut self, name: &'a [u8], value: &'a [u8], at: usize) -> Result<(), ParseError> {
        let Cur::Element(i) = self.cur else {
            return Ok(());
        };
        let schema = self.schema;
        if let Content::Attributes(fields) = &schema.elements[i].content {
            let key = short_key(name);
            let is = |f: &Field| f.key == key && (key != 0 || f.name.as_bytes() == name);
            let found = match fields.get(self.next_field) {
                Some(f) if is(f) => Some(self.next_field),
                _ => fields.iter().position(is),
            };
            if let Some(k) = found {
                self.next_field = k + 1;
                self.store(&fields[k], value, at)?;
            }
        }
        Ok(())
    }

    fn child_text(&mut self, text: &'a [u8], at: usize) -> Result<(), ParseError> {
        match self.cur {
            Cur::Ipoc => {
                self.frame.ipoc = Ipoc::parse(text)?;
                self.ipoc_seen = true;
                if let Some(r) = self.rec.as_mut() {
                    r.push(at, text.len(), None);
                }
                Ok(())
            }
            Cur::Element(i) => {
                let schema = self.schema;
                if let Content::Text(f) = &schema.elements[i].content {
                    self.store(f, text, at)?;
                }
                Ok(())
            }
            Cur::Unknown => Ok(()),
        }
    }
}

/// Exact powers of ten as f64 (10^0 ..= 10^22 are all exactly representable).
const POW10F: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// `[+-]digits[.digits]` or `[+-].digits`, finite. No exponent, no `inf`, no `nan`.
///
/// Fast path (Clinger): up to 19 digits whose value is below 2^53 with at most 22 decimals is one
/// exact integer divided by one exact power of ten — correctly rounded, like `str::parse`, which
/// handles everything else.
pub(crate) fn parse_decimal(s: &[u8]) -> Option<f64> {
    let (v, n) = decimal_prefix(s);
    if n == s.len() { v } else { None }
}

/// The plain decimal at the start of `s` (see [`parse_decimal`]), read up to the first byte that
/// cannot continue it: its value (`None`: no digit, or not finite) and the bytes it took.
///
/// Where at least 16 bytes follow the sign (a value inside a datagram, as the learnt layout reads
/// it), an RSI number of up to 7 digits before and 7 after the point is read a word at a time
/// ([`eight_digits`]); anything else, byte by byte. Both give the same result.
#[inline(always)]
pub(crate) fn decimal_prefix(s: &[u8]) -> (Option<f64>, usize) {
    let (neg, sign) = match s.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    if let Some(word) = s.get(sign..sign + 16) {
        let lo = word_at(word, 0);
        let k = digit_count(word);
        if k < 8 {
            let (frac, mant) = if word[k] == b'.' {
                let after = word_at(word, k + 1);
                let m = digit_count(&word[k + 1..]);
                if k + m <= 8 {
                    // Both runs in one word (the point taken out), converted once.
                    let int = if k == 0 {
                        0
                    } else {
                        lo & (u64::MAX >> (64 - 8 * k))
                    };
                    (m, digits_value(int | (after << (8 * k)), k + m))
                } else {
                    (
                        m,
                        digits_value(lo, k) * POW10_8[m.min(8)] + digits_value(after, m),
                    )
                }
            } else {
                (0, digits_value(lo, k))
            };
            if frac < 8 {
                let end = sign + k + usize::from(word[k] == b'.') + frac;
                if k + frac == 0 {
                    return (None, end);
                }
                // At most 14 digits: below 2^53, exact, and so is 10^frac.
                let v = mant as f64 / POW10F[frac];
                return (Some(if neg { -v } else { v }), end);
            }
        }
    }
    decimal_prefix_bytewise(s, neg, sign)
}

/// How many bytes the plain decimal at the start of `s` takes, when [`decimal_prefix`] would read
/// one (`None` where it reads none), without converting it: where 16 bytes follow the sign, up to
/// 7 digits before and 7 after the point are checked a word at a time.
#[inline]
pub(crate) fn plain_decimal_len(s: &[u8]) -> Option<usize> {
    let sign = usize::from(matches!(s.first(), Some(b'-' | b'+')));
    if let Some(word) = s.get(sign..sign + 16) {
        let k = digit_count(word);
        if k < 8 {
            let (point, frac) = if word[k] == b'.' {
                (1, digit_count(&word[k + 1..]))
            } else {
                (0, 0)
            };
            // Fewer than 15 digits: finite.
            if frac < 8 {
                return (k + frac > 0).then_some(sign + k + point + frac);
            }
        }
    }
    plain_decimal_len_bytewise(s)
}

#[cold]
#[inline(never)]
fn plain_decimal_len_bytewise(s: &[u8]) -> Option<usize> {
    let sign = usize::from(matches!(s.first(), Some(b'-' | b'+')));
    match decimal_prefix_bytewise(s, s.first() == Some(&b'-'), sign) {
        (Some(_), n) => Some(n),
        (None, _) => None,
    }
}

/// How many of the first eight bytes of `s` (at least eight) are ASCII digits before the first
/// that is not (a mask of the bytes that are not, and its trailing zeros).
#[inline(always)]
fn digit_count(s: &[u8]) -> usize {
    let word = u64::from_le_bytes(s.first_chunk::<8>().copied().unwrap_or([0; 8]));
    const HIGH: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    let class = (word & HIGH) | ((word.wrapping_add(0x0606_0606_0606_0606) & HIGH) >> 4);
    ((class ^ 0x3333_3333_3333_3333).trailing_zeros() / 8) as usize
}

/// [`decimal_prefix`] a byte at a time, after the sign.
#[cold]
#[inline(never)]
fn decimal_prefix_bytewise(s: &[u8], neg: bool, sign: usize) -> (Option<f64>, usize) {
    // The digits before and after the point, accumulated as one integer (wrapping: only read when
    // there are at most 19 digits, which cannot overflow).
    let mut mant: u64 = 0;
    let mut i = sign;
    let mut digits_from = |i: &mut usize| {
        while let Some(d) = s.get(*i).map(|c| c.wrapping_sub(b'0')).filter(|&d| d <= 9) {
            mant = mant.wrapping_mul(10).wrapping_add(u64::from(d));
            *i += 1;
        }
    };
    digits_from(&mut i);
    let int_digits = i - sign;
    let mut frac = 0usize;
    if s.get(i) == Some(&b'.') {
        i += 1;
        digits_from(&mut i);
        frac = i - sign - int_digits - 1;
    }
    let digits = int_digits + frac;
    if digits == 0 {
        return (None, i);
    }
    if digits <= 19 && mant < (1u64 << 53) && frac < POW10F.len() {
        let v = mant as f64 / POW10F[frac];
        return (Some(if neg { -v } else { v }), i);
    }
    let v = core::str::from_utf8(&s[..i])
        .ok()
        .and_then(|t| t.parse::<f64>().ok())
        .filter(|v| v.is_finite());
    (v, i)
}

/// 10^0 ..= 10^8.
const POW10_8: [u64; 9] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
];

/// The eight bytes of `s` from `at` as a little-endian word (zero where fewer).
#[inline(always)]
fn word_at(s: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(
        s.get(at..at + 8)
            .and_then(|w| w.try_into().ok())
            .unwrap_or([0; 8]),
    )
}

/// The value of the first `n` (0..=8) bytes of `word`, ASCII digits, the first the most significant
/// (as [`eight_digits`] converts them).
#[inline(always)]
fn digits_value(word: u64, n: usize) -> u64 {
    if n == 0 {
        return 0;
    }
    let d = word.wrapping_sub(0x3030_3030_3030_3030) << (8 * (8 - n));
    let d = d.wrapping_mul(10).wrapping_add(d >> 8);
    ((d & 0x0000_00FF_0000_00FF).wrapping_mul(100 + (1_000_000 << 32))
        + ((d >> 16) & 0x0000_00FF_0000_00FF).wrapping_mul(1 + (10_000 << 32)))
        >> 32
}

/// The leading ASCII digits among the first eight bytes of `s` (at least eight): how many, and
/// their value ([`digit_count`] and [`digits_value`] together; the tests' handle on both).
#[cfg(test)]
fn eight_digits(s: &[u8]) -> (usize, u64) {
    let n = digit_count(s);
    (n, digits_value(word_at(s, 0), n))
}

/// `[+-]digits` within i64.
pub(crate) fn parse_integer(s: &[u8]) -> Option<f64> {
    let (neg, body) = match s.first()? {
        b'-' => (true, &s[1..]),
        b'+' => (false, &s[1..]),
        _ => (false, s),
    };
    if body.is_empty() || body.len() > 19 {
        return None;
    }
    let mut v: i64 = 0;
    for &c in body {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v.checked_mul(10)?.checked_add(i64::from(c - b'0'))?;
    }
    Some(if neg { -v } else { v } as f64)
}

fn parse_bool(s: &[u8]) -> Option<f64> {
    if s == b"1" || s.eq_ignore_ascii_case(b"true") {
        Some(1.0)
    } else if s == b"0" || s.eq_ignore_ascii_case(b"false") {
        Some(0.0)
    } else {
        None
    }
}

struct Out<'b> {
    buf: &'b mut [u8],
    n: usize,
}

const POW10: [u64; 10] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
    1_000_000_000,
];

impl Out<'_> {
    /// `text[from..to]`; a piece of up to 16 bytes as one block copy where the buffer has room for
    /// the whole block (`text` has 16 readable bytes past every piece's start; the bytes past the
    /// piece are written over by what follows).
    #[inline]
    fn put_piece(&mut self, text: &[u8], from: usize, to: usize) -> Result<(), WriteError> {
        if to - from <= 16
            && let (Some(dst), Some(src)) = (
                self.buf.get_mut(self.n..self.n + 16),
                text.get(from..from + 16),
            )
        {
            dst.copy_from_slice(src);
            self.n += to - from;
            return Ok(());
        }
        self.put(&text[from..to])
    }

    fn put(&mut self, s: &[u8]) -> Result<(), WriteError> {
        let end = self.n + s.len();
        if end > self.buf.len() {
            return Err(WriteError::BufferTooSmall);
        }
        self.buf[self.n..end].copy_from_slice(s);
        self.n = end;
        Ok(())
    }

    /// Plain fixed-point with `decimals` digits after the point, rounded half away from zero.
    /// Refuses (`OutOfRange`) when `|v|·10^decimals` is not exactly representable (≥ 2^53).
    fn fixed(&mut self, v: f64, decimals: u8, slot: usize) -> Result<(), WriteError> {
        let scale = POW10[decimals as usize];
        let x = v.abs() * scale as f64;
        if x.is_nan() || x >= 9_007_199_254_740_992.0 {
            return Err(WriteError::OutOfRange { slot });
        }
        // Zero at this precision (a correction's unused axes, most of them every cycle): one block
        // copy. Below one half it rounds to 0, which is written unsigned.
        if x < 0.5 && decimals <= 14 && self.buf.len() - self.n >= 16 {
            self.buf[self.n..self.n + 16].copy_from_slice(b"0.00000000000000");
            self.n += if decimals == 0 {
                1
            } else {
                2 + usize::from(decimals)
            };
            return Ok(());
        }
        // Below 2^53 the truncation is exact, and so is the remainder: half away from zero.
        // (Through i64: one conversion instruction, where a u64 conversion is a branchy sequence.)
        let t = x as i64 as u64;
        let n = t + u64::from(x - t as i64 as f64 >= 0.5);
        let negative = v.is_sign_negative() && n != 0;
        let (int, frac) = split_decimals(n, decimals);
        // The common case, written eight digits at a time: up to 8 integer digits and 8 decimals,
        // with room for whole words (the bytes past the number are written over by what follows).
        if int < 100_000_000 && decimals <= 8 && self.buf.len() - self.n >= 24 {
            let mut at = self.n;
            if negative {
                self.buf[at] = b'-';
                at += 1;
            }
            let digits = ascii_eight(int as u32);
            // Leading zeros are the low bytes that hold '0' and precede the first other digit.
            let skip = (((digits ^ 0x3030_3030_3030_3030).trailing_zeros() / 8) as usize).min(7);
            self.buf[at..at + 8].copy_from_slice(&(digits >> (8 * skip)).to_le_bytes());
            at += 8 - skip;
            if decimals > 0 {
                self.buf[at] = b'.';
                at += 1;
                let d = usize::from(decimals);
                let digits = ascii_eight(frac as u32) >> (8 * (8 - d));
                self.buf[at..at + 8].copy_from_slice(&digits.to_le_bytes());
                at += d;
            }
            self.n = at;
            return Ok(());
        }
        // Right to left into one buffer: the decimals, the point, the integer part, the sign (at
        // most 16 digits below 2^53, a point and a sign).
        let mut tmp = [b'0'; 24];
        let mut at = tmp.len();
        let mut int = int;
        if decimals > 0 {
            let mut frac = frac;
            for _ in 0..decimals {
                at -= 1;
                tmp[at] = b'0' + (frac % 10) as u8;
                frac /= 10;
            }
            at -= 1;
            tmp[at] = b'.';
        }
        loop {
            at -= 1;
            tmp[at] = b'0' + (int % 10) as u8;
            int /= 10;
            if int == 0 {
                break;
            }
        }
        if negative {
            at -= 1;
            tmp[at] = b'-';
        }
        self.put(&tmp[at..])
    }
}

/// `n / 10^decimals` and `n % 10^decimals`, each divisor a constant (a multiplication and a shift,
/// where a division by a value read at run time is one of the slowest instructions there is).
#[inline(always)]
fn split_decimals(n: u64, decimals: u8) -> (u64, u64) {
    macro_rules! by {
        ($d:literal) => {
            (n / $d, n % $d)
        };
    }
    match decimals {
        0 => (n, 0),
        1 => by!(10),
        2 => by!(100),
        3 => by!(1_000),
        4 => by!(10_000),
        5 => by!(100_000),
        6 => by!(1_000_000),
        7 => by!(10_000_000),
        8 => by!(100_000_000),
        _ => {
            let scale = POW10[usize::from(decimals)];
            (n / scale, n % scale)
        }
    }
}

/// `n` < 10^8 as eight ASCII digits with leading zeros, the most significant in the lowest byte
/// (the order they are written in): halves, quarters and digits split with multiplications, all
/// lanes at once.
#[inline]
fn ascii_eight(n: u32) -> u64 {
    let n = u64::from(n);
    // Two 4-digit halves in two 32-bit lanes, the high half in the low lane.
    let x = (n / 10_000) | ((n % 10_000) << 32);
    // Each lane (< 10^4) into two 2-digit lanes of 16 bits: x / 100 as (x · 5243) >> 19.
    let hi = ((x * 5243) >> 19) & 0x0000_007F_0000_007F;
    let x = hi | ((x - hi * 100) << 16);
    // Each lane (< 100) into two digits of 8 bits: x / 10 as (x · 103) >> 10.
    let hi = ((x * 103) >> 10) & 0x000F_000F_000F_000F;
    let x = hi | ((x - hi * 10) << 8);
    x | 0x3030_3030_3030_3030
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_one(v: f64, d: u8) -> String {
        let mut buf = [0u8; 64];
        let mut o = Out {
            buf: &mut buf,
            n: 0,
        };
        o.fixed(v, d, 0).unwrap();
        let n = o.n;
        String::from_utf8(buf[..n].to_vec()).unwrap()
    }

    #[test]
    fn fixed_point_output() {
        assert_eq!(write_one(0.0, 4), "0.0000");
        assert_eq!(write_one(-0.0, 4), "0.0000");
        assert_eq!(write_one(-0.00004, 4), "0.0000");
        assert_eq!(write_one(-0.00005, 4), "-0.0001");
        assert_eq!(write_one(445.0, 4), "445.0000");
        assert_eq!(write_one(-12.34567, 3), "-12.346");
        assert_eq!(write_one(1e-30, 4), "0.0000");
        assert_eq!(write_one(7.0, 0), "7");
        assert_eq!(write_one(123_456_789.5, 1), "123456789.5");
    }

    /// What rounds to zero is written as the formatter writes zero, at every precision.
    #[test]
    fn zero_is_written_unsigned_at_every_precision() {
        for d in 0..=9u8 {
            let want = format!("{:.*}", usize::from(d), 0.0);
            let half = 0.5 / POW10[usize::from(d)] as f64;
            for v in [0.0, -0.0, 1e-300, -1e-300, half * 0.999, -half * 0.999] {
                assert_eq!(write_one(v, d), want, "{v} at {d} decimals");
            }
            // Just past a half it is not zero (half away from zero).
            assert_ne!(write_one(half * 1.001, d), want);
        }
    }

    #[test]
    fn decimals_split_as_a_division_does() {
        for decimals in 0..=9u8 {
            let scale = POW10[usize::from(decimals)];
            for n in [
                0,
                1,
                scale - 1,
                scale,
                scale + 1,
                123_456_789_012,
                (1 << 53) - 1,
            ] {
                assert_eq!(
                    split_decimals(n, decimals),
                    (n / scale, n % scale),
                    "{n} {decimals}"
                );
            }
        }
    }

    #[test]
    fn eight_ascii_digits() {
        // Every value of each 4-digit half against the other half's extremes, and a stride of all.
        let check = |n: u32| {
            let want = format!("{n:08}");
            assert_eq!(&ascii_eight(n).to_le_bytes(), want.as_bytes(), "{n}");
        };
        for k in 0..10_000 {
            for other in [0, 1, 5_000, 9_999] {
                check(k * 10_000 + other);
                check(other * 10_000 + k);
            }
        }
        for n in (0..100_000_000).step_by(9_973) {
            check(n);
        }
        check(99_999_999);
    }

    #[test]
    fn both_fixed_point_paths_write_the_same() {
        // The word path (room for 24 bytes) against the digit loop (a buffer with no room to spare).
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..50_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let mag = 10f64.powi((x % 15) as i32 - 8);
            let v = ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * mag;
            for d in 0..=9u8 {
                let fast = write_one(v, d);
                let mut exact = vec![0u8; fast.len()];
                let mut o = Out {
                    buf: &mut exact,
                    n: 0,
                };
                o.fixed(v, d, 0).unwrap();
                assert_eq!(o.n, fast.len());
                assert_eq!(core::str::from_utf8(&exact).unwrap(), fast, "{v} at {d}");
                // And what the standard formatter writes, but for its rounding of ties.
                let std = format!("{:.*}", usize::from(d), v.abs());
                let std = std.trim_start_matches('-');
                assert_eq!(
                    fast.trim_start_matches('-').len(),
                    std.len(),
                    "{v} {fast} {std}"
                );
            }
        }
        assert_eq!(write_one(99_999_999.5, 0), "100000000");
        assert_eq!(write_one(-99_999_999.999_95, 4), "-100000000.0000");
        assert_eq!(write_one(12_345_678.123_456_78, 8), "12345678.12345678");
        assert_eq!(write_one(0.5, 0), "1");
        assert_eq!(write_one(-0.5, 0), "-1");
        assert_eq!(write_one(0.499_999_999_999_999_94, 0), "0");
        assert_eq!(write_one(2.5, 0), "3");
    }

    #[test]
    fn huge_values_are_refused_not_written_with_an_exponent() {
        let mut buf = [0u8; 64];
        let mut o = Out {
            buf: &mut buf,
            n: 0,
        };
        assert_eq!(
            o.fixed(1e300, 4, 3),
            Err(WriteError::OutOfRange { slot: 3 })
        );
        assert_eq!(o.n, 0, "nothing written");
    }

    #[test]
    fn decimal_parser_is_plain() {
        assert_eq!(parse_decimal(b"445.0000"), Some(445.0));
        assert_eq!(parse_decimal(b"-0.5"), Some(-0.5));
        assert_eq!(parse_decimal(b"+.5"), Some(0.5));
        assert_eq!(parse_decimal(b"3."), Some(3.0));
        for bad in [
            &b""[..],
            b"-",
            b".",
            b"1e5",
            b"inf",
            b"NaN",
            b"1.2.3",
            b"1 2",
            b"0x10",
        ] {
            assert_eq!(parse_decimal(bad), None, "{:?}", core::str::from_utf8(bad));
        }
        let huge = [b'9'; 400];
        assert_eq!(parse_decimal(&huge), None, "overflow to inf is rejected");
    }

    #[test]
    fn eight_digit_words_end_at_the_first_non_digit() {
        // Every run length, followed by each kind of byte that ends a run (below '0', above '9', the
        // point, a quote, bytes ≥ 0xFA whose word addition carries into the next byte).
        for len in 0..=8 {
            let digits: Vec<u8> = (0..len).map(|k| b"83012974"[k]).collect();
            for end in [b'/', b':', b'.', b'"', b'<', b' ', 0x00, 0x7f, 0xfa, 0xff] {
                for tail in [&b"0000000"[..], b"9999999", b"\xff\xff\xff\xff\xff\xff\xff"] {
                    let mut text = digits.clone();
                    text.push(end);
                    text.extend_from_slice(tail);
                    let (n, v) = eight_digits(&text);
                    assert_eq!(n, len, "{text:?}");
                    let want: u64 = core::str::from_utf8(&digits).unwrap().parse().unwrap_or(0);
                    assert_eq!(v, want, "{text:?}");
                }
            }
        }
        assert_eq!(eight_digits(b"00000000"), (8, 0));
        assert_eq!(eight_digits(b"99999999"), (8, 99_999_999));
        assert_eq!(eight_digits(b"00000001"), (8, 1));
    }

    /// The word-at-a-time path (16 bytes after the sign) and the bytewise one agree on every
    /// prefix, whatever follows the number.
    #[test]
    fn word_and_byte_paths_agree() {
        let numbers: Vec<String> = [
            "0",
            "7",
            "-0",
            "+3",
            "445.1234",
            "-179.9999",
            "0.0001",
            "-.5",
            "3.",
            ".",
            "-",
            "",
            "1234567.1234567",
            "12345678.1",
            "1.12345678",
            "99999999",
            "-9999999.9999999",
            "0000000.0000000",
            "1e5",
            "1.5e3",
            "12.34.56",
            "+-1",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
        for n in &numbers {
            for after in ["\"", "\" Y=\"", "/>", "<", "x", ".", "5", "\u{7f}"] {
                let mut text = format!("{n}{after}").into_bytes();
                let short = text.clone();
                text.extend_from_slice(b"0123456789abcdefghij");
                let (neg, sign) = match text.first() {
                    Some(b'-') => (true, 1),
                    Some(b'+') => (false, 1),
                    _ => (false, 0),
                };
                let fast = decimal_prefix(&text);
                let slow = decimal_prefix_bytewise(&text, neg, sign);
                assert_eq!(
                    fast.0.map(f64::to_bits),
                    slow.0.map(f64::to_bits),
                    "{text:?}"
                );
                assert_eq!(fast.1, slow.1, "{text:?}");
                // The length alone, as the checked-not-converted reader sees it.
                assert_eq!(plain_decimal_len(&text), fast.0.map(|_| fast.1), "{text:?}");
                assert_eq!(
                    plain_decimal_len(&short),
                    decimal_prefix(&short).0.map(|_| decimal_prefix(&short).1),
                    "{short:?}"
                );
                // Cut right after the number (fewer than 16 bytes left): the same reading.
                let (v, n) = decimal_prefix(&short);
                let (w, m) = decimal_prefix_bytewise(&short, neg, sign);
                assert_eq!((v.map(f64::to_bits), n), (w.map(f64::to_bits), m));
                if !after.starts_with(|c: char| c.is_ascii_digit() || c == '.') {
                    assert_eq!((v.map(f64::to_bits), n), (slow.0.map(f64::to_bits), slow.1));
                }
            }
        }
    }

    #[test]
    fn decimal_edge_cases() {
        assert_eq!(parse_decimal(b"0"), Some(0.0));
        assert_eq!(
            parse_decimal(b"-0.0000").map(f64::to_bits),
            Some((-0.0f64).to_bits())
        );
        assert_eq!(parse_decimal(b"+0012.5000"), Some(12.5));
        assert_eq!(parse_decimal(b"-179.9999"), Some(-179.9999));
        assert_eq!(
            parse_decimal(b"12345678.87654321"),
            Some(12_345_678.876_543_21)
        );
        // 19 digits (the fast path's most), 20 (the standard parser's), a long fraction.
        assert_eq!(
            parse_decimal(b"1234567890.123456789"),
            Some(1_234_567_890.123_456_8)
        );
        assert_eq!(parse_decimal(b"9999999999999999999"), Some(1e19));
        assert_eq!(
            parse_decimal(b"0.100000000000000000000000000001"),
            Some(0.1)
        );
        // 2^53 + 1 has no exact double: rounded as the standard parser rounds it.
        assert_eq!(
            parse_decimal(b"9007199254740993"),
            Some(9_007_199_254_740_992.0)
        );
        for bad in [
            &b"--1"[..],
            b"+-1",
            b"1-",
            b"1e-3",
            b"1E3",
            b"1.5e",
            b"0x1",
            b".",
            b"+.",
            b"1,5",
            b" 1",
            b"1 ",
            b"\xff1",
        ] {
            assert_eq!(parse_decimal(bad), None, "{bad:?}");
        }
        // What the layout's reader sees: the value, and the byte it stopped at.
        assert_eq!(decimal_prefix(b"445.1234\" Y="), (Some(445.1234), 8));
        assert_eq!(decimal_prefix(b"-.5<"), (Some(-0.5), 3));
        assert_eq!(decimal_prefix(b"-x"), (None, 1));
    }

    #[test]
    fn written_decimals_read_back_exactly() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..20_000 {
            // xorshift: magnitudes from 1e-6 to 1e6, both signs.
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let mag = 10f64.powi((x % 13) as i32 - 6);
            let v = ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2.0 * mag;
            for d in [0u8, 1, 3, 4, 6, 9] {
                let text = write_one(v, d);
                let scale = POW10[d as usize] as f64;
                let want = (v.abs() * scale).round() / scale;
                let got = parse_decimal(text.as_bytes()).unwrap();
                assert_eq!(got.abs(), want, "{v} at {d} decimals wrote {text}");
                assert_eq!(text.starts_with('-'), v < 0.0 && want != 0.0, "{text}");
            }
        }
    }

    proptest::proptest! {
        /// Plain decimals read as `str::parse` reads them (correctly rounded), any digit counts.
        #[test]
        fn decimals_read_as_the_standard_parser_reads_them(
            text in "[+-]?[0-9]{0,24}(\\.[0-9]{0,24})?",
        ) {
            let expected = text.parse::<f64>().ok().filter(|v| v.is_finite());
            let has_digit = text.bytes().any(|c| c.is_ascii_digit());
            let got = parse_decimal(text.as_bytes());
            proptest::prop_assert_eq!(got.map(f64::to_bits), expected.filter(|_| has_digit).map(f64::to_bits));
        }

        /// Inside a datagram (16 bytes or more follow): the value the standard parser reads, and
        /// the number's length.
        #[test]
        fn decimals_inside_a_datagram_read_as_the_standard_parser_reads_them(
            text in "[+-]?[0-9]{0,10}(\\.[0-9]{0,10})?",
            after in "[\"/<. x0-9]{16,20}",
        ) {
            let expected = text.parse::<f64>().ok().filter(|v| v.is_finite());
            let has_digit = text.bytes().any(|c| c.is_ascii_digit());
            let joined = format!("{text}{after}");
            let (got, n) = decimal_prefix(joined.as_bytes());
            proptest::prop_assert_eq!(plain_decimal_len(joined.as_bytes()), got.map(|_| n));
            if after.as_bytes()[0].is_ascii_digit() || (after.starts_with('.') && !text.contains('.')) {
                // The number runs on into what follows: compare with the bytewise reading.
                let sign = usize::from(text.starts_with(['+', '-']));
                let slow = decimal_prefix_bytewise(joined.as_bytes(), text.starts_with('-'), sign);
                proptest::prop_assert_eq!(got.map(f64::to_bits), slow.0.map(f64::to_bits));
                proptest::prop_assert_eq!(n, slow.1);
            } else {
                proptest::prop_assert_eq!(got.map(f64::to_bits), expected.filter(|_| has_digit).map(f64::to_bits));
                proptest::prop_assert_eq!(n, text.len());
            }
        }

        /// Any bytes: a decimal where the standard parser reads a plain one, nothing otherwise.
        #[test]
        fn any_bytes_read_as_plain_decimals_or_not_at_all(
            bytes in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..40),
        ) {
            let plain = bytes.iter().enumerate().all(|(k, &c)| {
                c.is_ascii_digit() || c == b'.' || (k == 0 && (c == b'+' || c == b'-'))
            }) && bytes.iter().filter(|&&c| c == b'.').count() <= 1
                && bytes.iter().any(u8::is_ascii_digit);
            let expected = core::str::from_utf8(&bytes)
                .ok()
                .filter(|_| plain)
                .and_then(|t| t.parse::<f64>().ok())
                .filter(|v| v.is_finite());
            let got = parse_decimal(&bytes);
            proptest::prop_assert_eq!(got.map(f64::to_bits), expected.map(f64::to_bits));
        }
    }

    #[test]
    fn ipoc_keeps_digits_verbatim() {
        let i = Ipoc::parse(b"000123").unwrap();
        assert_eq!(i.value(), 123);
        assert_eq!(i.digits(), b"000123");
        assert_eq!(Ipoc::new(18_446_744_073_709_551_615).value(), u64::MAX);
        assert_eq!(
            Ipoc::parse(b"18446744073709551616"),
            Err(ParseError::BadIpoc)
        );
        assert_eq!(Ipoc::parse(b""), Err(ParseError::BadIpoc));
        assert_eq!(Ipoc::parse(b"-1"), Err(ParseError::BadIpoc));
        assert_eq!(Ipoc::new(0).digits(), b"0");
        assert_eq!(Ipoc::new(4_294_967_296_123).digits(), b"4294967296123");
    }
}
