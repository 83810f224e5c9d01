//! A robot's message layout, learnt from its last well-formed `<Rob>`: a controller sends the same
//! bytes every cycle but for the values. A message whose every byte between the values is the learnt
//! message's, and whose values parse, is that message with new values: it is read by comparing the
//! bytes between the values and parsing the values, without the XML scanner. Anything else (another
//! element order, whitespace, a missing or extra element, a value that does not parse) is read by the
//! strict parser, which then learns the new layout if the message is well-formed; the result is the
//! same either way (`tests/codec_props.rs` checks it against the strict parser).
//!
//! Why: the strict scanner is 70 % of the instructions an RSI cycle costs on the PC (`callgrind` of
//! `examples/rsi_answer`), and the cycle's turnaround is what the robot waits for.

use crate::codec::{
    Frame, Ipoc, MAX_SLOTS, Schema, ValueType, decimal_prefix, parse_value, plain_decimal_len,
};
use crate::xml::ParseError;

/// Where one value lay in a message: its start, length and what it is (`None`: the IPOC).
type Spot = (u32, u32, Option<(u8, ValueType)>);

/// The values of one strictly parsed message, in document order.
#[derive(Clone, Debug)]
pub(crate) struct Recorded {
    spots: [Spot; MAX_SLOTS + 1],
    n: usize,
    /// More values than fit (never for a valid schema): no layout.
    overflow: bool,
}

impl Recorded {
    fn new() -> Self {
        Self {
            spots: [(0, 0, None); MAX_SLOTS + 1],
            n: 0,
            overflow: false,
        }
    }

    pub(crate) fn clear(&mut self) {
        self.n = 0;
        self.overflow = false;
    }

    pub(crate) fn push(&mut self, at: usize, len: usize, what: Option<(usize, ValueType)>) {
        let (Ok(at), Ok(len)) = (u32::try_from(at), u32::try_from(len)) else {
            self.overflow = true;
            return;
        };
        match self.spots.get_mut(self.n) {
            Some(s) => {
                *s = (at, len, what.map(|(slot, ty)| (slot as u8, ty)));
                self.n += 1;
            }
            None => self.overflow = true,
        }
    }
}

/// What the reader does at one value of the learnt message: compare the bytes `from..to` of the
/// learnt text (those before the value), then read the value up to the byte `stop`.
#[derive(Clone, Copy, Debug, Default)]
struct Step {
    from: u32,
    to: u32,
    stop: u8,
    op: Op,
    slot: u8,
    ty: Option<ValueType>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum Op {
    /// A decimal whose value is read.
    #[default]
    Convert,
    /// A decimal nobody reads: checked, not converted.
    Check,
    /// Another type, or (`ty` `None`) the IPOC.
    Other,
}

/// The learnt layout of one direction's messages (allocated once, at the largest message accepted).
#[derive(Clone, Debug)]
pub struct Layout {
    /// The message it was learnt from (`len` bytes of it; 0: nothing learnt).
    text: Box<[u8]>,
    len: usize,
    learnt: Recorded,
    scratch: Recorded,
    /// The slots the learnt message fills.
    present: u128,
    /// The slots whose values are converted; the others' are only checked (see [`Layout::reading`]).
    wanted: u128,
    /// The learnt message as steps (`n_steps` of them), and where its text after the last value
    /// starts.
    steps: Box<[Step; MAX_SLOTS + 1]>,
    n_steps: usize,
    tail: usize,
}

impl Layout {
    /// No layout yet, for messages of up to `max_len` bytes.
    pub fn new(max_len: usize) -> Self {
        Self::reading(max_len, u128::MAX)
    }

    /// [`Layout::new`] for a reader that only reads the slots in `wanted` (bit `slot` set): a
    /// message read through the layout then has every other decimal checked as the strict parser
    /// checks it (same acceptance, same errors) but not converted — its slot in the frame keeps an
    /// unspecified value (still marked present). A message the strict parser reads fills every slot.
    pub fn reading(max_len: usize, wanted: u128) -> Self {
        Self {
            text: vec![0; max_len].into_boxed_slice(),
            len: 0,
            learnt: Recorded::new(),
            scratch: Recorded::new(),
            present: 0,
            wanted,
            steps: Box::new([Step::default(); MAX_SLOTS + 1]),
            n_steps: 0,
            tail: 0,
        }
    }

    /// Parse `bytes` into `frame` as [`Schema::parse`] does (same result, same error), through the
    /// learnt layout when `bytes` has it; learn a well-formed message's layout.
    pub fn parse(
        &mut self,
        schema: &Schema,
        bytes: &[u8],
        frame: &mut Frame,
    ) -> Result<(), ParseError> {
        if self.len > 0 && self.read(bytes, frame) {
            return Ok(());
        }
        schema.parse_recording(bytes, frame, Some(&mut self.scratch))?;
        if self.scratch.overflow || bytes.len() > self.text.len() {
            self.len = 0;
        } else {
            self.text[..bytes.len()].copy_from_slice(bytes);
            self.len = bytes.len();
            core::mem::swap(&mut self.learnt, &mut self.scratch);
            self.present = self.learnt.spots[..self.learnt.n]
                .iter()
                .filter_map(|&(_, _, what)| what)
                .fold(0, |m, (slot, _)| m | 1u128 << slot);
            self.compile();
        }
        Ok(())
    }

    /// The learnt message's values as steps (or no layout, `len` 0, where a value ends the text).
    fn compile(&mut self) {
        let text = &self.text[..self.len];
        let mut old = 0usize;
        for (k, &(at, len, what)) in self.learnt.spots[..self.learnt.n].iter().enumerate() {
            let end = (at + len) as usize;
            // The value runs to the byte that ended it in the learnt message (a quote, `<`); a
            // value that parses holds neither.
            let Some(&stop) = text.get(end) else {
                self.len = 0;
                return;
            };
            let (op, slot, ty) = match what {
                Some((slot, ValueType::Double)) if self.wanted & (1u128 << slot) == 0 => {
                    (Op::Check, slot, Some(ValueType::Double))
                }
                Some((slot, ValueType::Double)) => (Op::Convert, slot, Some(ValueType::Double)),
                Some((slot, ty)) => (Op::Other, slot, Some(ty)),
                None => (Op::Other, 0, None),
            };
            self.steps[k] = Step {
                from: old as u32,
                to: at,
                stop,
                op,
                slot,
                ty,
            };
            old = end;
        }
        self.n_steps = self.learnt.n;
        self.tail = old;
    }

    /// Read `bytes` through the layout; false (the frame then undefined) where it does not fit.
    fn read(&self, bytes: &[u8], frame: &mut Frame) -> bool {
        let text = &self.text[..self.len];
        frame.clear_for_parse();
        let mut new = 0usize;
        for st in &self.steps[..self.n_steps] {
            let between = &text[st.from as usize..st.to as usize];
            match bytes.get(new..new + between.len()) {
                Some(b) if same(b, between) => {}
                _ => return false,
            }
            new += between.len();
            let rest = &bytes[new..];
            let n = match st.op {
                // A decimal is read as it is scanned, and must end where the learnt one did.
                Op::Convert => match decimal_prefix(rest) {
                    (Some(v), n) if rest.get(n) == Some(&st.stop) => {
                        frame.put_value(usize::from(st.slot), v);
                        n
                    }
                    _ => return false,
                },
                Op::Check => match plain_decimal_len(rest) {
                    Some(n) if rest.get(n) == Some(&st.stop) => n,
                    _ => return false,
                },
                Op::Other => match read_other(st, rest, frame) {
                    Some(n) => n,
                    None => return false,
                },
            };
            new += n;
        }
        if bytes.get(new..) != Some(&text[self.tail..]) {
            return false;
        }
        frame.mark_present(self.present);
        true
    }
}

/// A value that is not a decimal (an integer, a bool, the IPOC) up to `st.stop`: its length.
#[inline(never)]
fn read_other(st: &Step, rest: &[u8], frame: &mut Frame) -> Option<usize> {
    let n = rest.iter().position(|&c| c == st.stop)?;
    let value = &rest[..n];
    match st.ty {
        Some(ty) => frame.put_value(usize::from(st.slot), parse_value(ty, value)?),
        None => frame.set_ipoc(Ipoc::parse(value).ok()?),
    }
    Some(n)
}

/// `a == b` for slices of the same length, without a library call for the short runs between the
/// values (a few bytes: `" Y="`, `"/><RSol X="`): two overlapping word compares.
#[inline]
fn same(a: &[u8], b: &[u8]) -> bool {
    let n = a.len();
    if n != b.len() {
        return false;
    }
    fn w8(s: &[u8], at: usize) -> u64 {
        u64::from_le_bytes(s[at..at + 8].try_into().unwrap_or([0; 8]))
    }
    fn w4(s: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(s[at..at + 4].try_into().unwrap_or([0; 4]))
    }
    match n {
        0 => true,
        1..=3 => a.iter().zip(b).all(|(x, y)| x == y),
        4..=7 => w4(a, 0) == w4(b, 0) && w4(a, n - 4) == w4(b, n - 4),
        8..=16 => w8(a, 0) == w8(b, 0) && w8(a, n - 8) == w8(b, n - 8),
        _ => a == b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{EthernetConfig, ProcessChannels};

    fn schema() -> Schema {
        EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false)
            .with_process(ProcessChannels::default())
            .rob_schema(4)
            .unwrap()
    }

    fn message(s: &Schema, v: f64, ipoc: u64) -> Vec<u8> {
        let mut f = Frame::new();
        for slot in 0..s.slots() {
            f.set(slot, (v * (slot as f64 + 1.0)).round());
        }
        f.set_ipoc(Ipoc::new(ipoc));
        let mut buf = vec![0u8; 4096];
        let n = s.write(&f, &mut buf).unwrap();
        buf.truncate(n);
        buf
    }

    #[test]
    fn values_nobody_reads_are_checked_as_strictly_but_not_converted() {
        let s = schema();
        let rist = s.six("RIst", ["X", "Y", "Z", "A", "B", "C"]).unwrap();
        let wanted = rist.iter().fold(0u128, |m, &k| m | 1u128 << k);
        let mut layout = Layout::reading(4096, wanted);
        let (mut f, mut strict) = (Frame::new(), Frame::new());
        layout.parse(&s, &message(&s, 1.0, 7), &mut f).unwrap();
        let next = message(&s, -123.0, 11);
        assert!(layout.read(&next, &mut f));
        s.parse(&next, &mut strict).unwrap();
        for slot in 0..s.slots() {
            assert!(f.is_present(slot), "slot {slot}");
            if wanted & (1u128 << slot) != 0 {
                assert_eq!(f.get(slot), strict.get(slot), "slot {slot}");
            }
        }
        assert_eq!(f.ipoc(), strict.ipoc());
        // An unread value that is no plain decimal: not this layout, and the strict parser's error.
        let aipos = s.slot("AIPos", "A1").unwrap();
        assert_eq!(wanted & (1u128 << aipos), 0);
        let text = String::from_utf8(next).unwrap();
        for bad in [
            "1e3",
            "",
            "-",
            "1.2.3",
            "0x1",
            "+.",
            "12345678901234567890123",
        ] {
            let spoiled = text.replacen("A1=\"-1599.0000\"", &format!("A1=\"{bad}\""), 1);
            assert_ne!(spoiled, text);
            let want = s.parse(spoiled.as_bytes(), &mut strict).map(|_| ());
            assert!(
                !layout.read(spoiled.as_bytes(), &mut f) || want.is_ok(),
                "{bad}"
            );
            assert_eq!(layout.parse(&s, spoiled.as_bytes(), &mut f), want, "{bad}");
        }
    }

    #[test]
    fn short_runs_compare_as_slices_do() {
        let text = b"<RIst X=\"1\" Y=\"2\"/><RSol X=\"3\" Y=\"4\"/><IPOC>5</IPOC></Rob>";
        for n in 0..=24 {
            for start in 0..text.len() - n {
                let a = &text[start..start + n];
                for other in 0..text.len() - n {
                    let b = &text[other..other + n];
                    assert_eq!(same(a, b), a == b, "{a:?} {b:?}");
                }
                // One byte changed anywhere: not the same.
                for k in 0..n {
                    let mut c = a.to_vec();
                    c[k] ^= 1;
                    assert!(!same(a, &c), "{a:?} {c:?}");
                }
            }
        }
        assert!(!same(b"abc", b"ab"));
    }

    #[test]
    fn new_values_are_read_through_the_layout_and_a_new_shape_is_not() {
        let s = schema();
        let mut layout = Layout::new(4096);
        let (mut f, mut strict) = (Frame::new(), Frame::new());
        layout.parse(&s, &message(&s, 1.0, 7), &mut f).unwrap();
        // Other values of other lengths, another IPOC: the layout reads it, as the strict parser does.
        let next = message(&s, -123.0, 1_000_000_007);
        assert!(layout.read(&next, &mut f));
        s.parse(&next, &mut strict).unwrap();
        assert_eq!(f.ipoc(), strict.ipoc());
        for slot in 0..s.slots() {
            assert_eq!(f.get(slot), strict.get(slot), "slot {slot}");
            assert_eq!(f.is_present(slot), strict.is_present(slot), "slot {slot}");
        }
        assert!(!f.is_present(s.slots()), "no slot past the schema's");
        // A space before `/>`, a value that does not parse, a message cut short: not this layout.
        let text = String::from_utf8(next.clone()).unwrap();
        let spaced = text.replacen("/>", " />", 1);
        assert!(!layout.read(spaced.as_bytes(), &mut f));
        let exponent = text.replacen("=\"-123.0000\"", "=\"-1e2\"", 1);
        assert_ne!(exponent, text);
        assert!(!layout.read(exponent.as_bytes(), &mut f));
        assert!(!layout.read(&next[..next.len() - 1], &mut f));
        // The strict parser then reads the new shape and the layout follows it.
        layout.parse(&s, spaced.as_bytes(), &mut f).unwrap();
        assert!(layout.read(spaced.as_bytes(), &mut f));
        assert!(!layout.read(&next, &mut f));
    }
}
