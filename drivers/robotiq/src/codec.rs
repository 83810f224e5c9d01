//! The FT 300's wire formats without I/O: the 16-byte stream frame (encode, decode, a resynchronising
//! byte-stream decoder), the Modbus CRC-16, the register map and the one place where device units
//! become SI.
//!
//! Stream frame: `0x20 0x4E | Fx·100 | Fy·100 | Fz·100 | Mx·1000 | My·1000 | Mz·1000 | CRC`, every value an
//! `i16` little-endian, CRC-16/Modbus over the first 14 bytes, low byte first.

use core::fmt;

use hal::Wrench;

/// The sensor's Modbus slave address.
pub const SLAVE: u8 = 9;
/// Serial bit rate, bit/s (8N1).
pub const BAUD: u32 = 19_200;
/// First holding register of the wrench (Fx, Fy, Fz, Mx, My, Mz).
pub const REG_WRENCH: u16 = 180;
/// First holding register of the accelerometer (Ax, Ay, Az, 1/1000 g).
pub const REG_ACCEL: u16 = 190;
/// The register whose write starts the stream.
pub const REG_STREAM: u16 = 410;
/// The value written to [`REG_STREAM`] to start the stream.
pub const STREAM_START: u16 = 0x0200;
/// First of the three firmware registers.
pub const REG_FIRMWARE: u16 = 500;
/// First of the four serial-number registers.
pub const REG_SERIAL: u16 = 510;
/// The production-year register.
pub const REG_YEAR: u16 = 514;
/// Bytes of one stream frame.
pub const FRAME_LEN: usize = 16;
/// The two bytes every stream frame starts with.
pub const HEADER: [u8; 2] = [0x20, 0x4E];
/// The byte that, sent about 50 times, stops the stream.
pub const STOP_BYTE: u8 = 0xFF;
/// How many stop bytes the driver sends (≈ 26 ms at 19 200 bit/s; the manual asks for about 50).
pub const STOP_COUNT: usize = 50;
/// Counts per newton of the force channels.
pub const COUNTS_PER_N: f64 = 100.0;
/// Counts per newton-metre of the torque channels.
pub const COUNTS_PER_NM: f64 = 1000.0;

/// CRC-16/Modbus (reflected polynomial 0xA001, initial value 0xFFFF).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in data {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// The six channels in device units: forces in 1/100 N, torques in 1/1000 N·m.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Counts(pub [i16; 6]);

/// A wrench that does not fit the device's i16 range (or is not finite).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfRange {
    /// Channel 0..6 (Fx Fy Fz Mx My Mz).
    pub channel: usize,
    /// The value, N or N·m.
    pub value: f64,
}

impl fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "channel {} value {} is outside the FT 300's range",
            self.channel, self.value
        )
    }
}

impl std::error::Error for OutOfRange {}

impl Counts {
    /// To SI: N and N·m. The only place the driver converts device units.
    pub fn to_wrench(self) -> Wrench {
        let c = self.0.map(f64::from);
        Wrench::from_array([
            c[0] / COUNTS_PER_N,
            c[1] / COUNTS_PER_N,
            c[2] / COUNTS_PER_N,
            c[3] / COUNTS_PER_NM,
            c[4] / COUNTS_PER_NM,
            c[5] / COUNTS_PER_NM,
        ])
    }

    /// From SI, rounded to the nearest count (the device's quantisation: 0.01 N, 0.001 N·m).
    pub fn from_wrench(w: &Wrench) -> Result<Self, OutOfRange> {
        let a = w.to_array();
        let mut out = [0i16; 6];
        for (i, v) in a.iter().enumerate() {
            let scale = if i < 3 { COUNTS_PER_N } else { COUNTS_PER_NM };
            let c = (v * scale).round();
            if !c.is_finite() || c < f64::from(i16::MIN) || c > f64::from(i16::MAX) {
                return Err(OutOfRange {
                    channel: i,
                    value: *v,
                });
            }
            out[i] = c as i16;
        }
        Ok(Self(out))
    }

    /// From the six holding registers 180..=185 (each an i16 in a big-endian Modbus word).
    pub fn from_registers(regs: &[u16]) -> Result<Self, RegisterError> {
        let regs: &[u16; 6] = regs.try_into().map_err(|_| RegisterError::Length {
            expected: 6,
            got: regs.len(),
        })?;
        Ok(Self(regs.map(|r| r as i16)))
    }

    /// The six holding registers 180..=185.
    pub fn to_registers(self) -> [u16; 6] {
        self.0.map(|c| c as u16)
    }
}

/// Why a 16-byte frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The first two bytes are not `0x20 0x4E`.
    Header([u8; 2]),
    /// The CRC does not match.
    Crc {
        /// CRC in the frame.
        received: u16,
        /// CRC of the first 14 bytes.
        computed: u16,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Header(h) => write!(f, "frame header {:02X} {:02X}", h[0], h[1]),
            Self::Crc { received, computed } => {
                write!(f, "frame CRC 0x{received:04X}, computed 0x{computed:04X}")
            }
        }
    }
}

impl std::error::Error for FrameError {}

/// One stream frame from its channels.
pub fn encode_frame(c: Counts) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    f[..2].copy_from_slice(&HEADER);
    for (i, v) in c.0.iter().enumerate() {
        f[2 + 2 * i..4 + 2 * i].copy_from_slice(&v.to_le_bytes());
    }
    let crc = crc16(&f[..14]);
    f[14..].copy_from_slice(&crc.to_le_bytes());
    f
}

/// One stream frame's channels, checked (header and CRC).
pub fn decode_frame(f: &[u8; FRAME_LEN]) -> Result<Counts, FrameError> {
    if f[..2] != HEADER {
        return Err(FrameError::Header([f[0], f[1]]));
    }
    let received = u16::from_le_bytes([f[14], f[15]]);
    let computed = crc16(&f[..14]);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    let mut c = [0i16; 6];
    for (i, v) in c.iter_mut().enumerate() {
        *v = i16::from_le_bytes([f[2 + 2 * i], f[3 + 2 * i]]);
    }
    Ok(Counts(c))
}

/// What [`StreamDecoder::push`] produced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// A frame with a good header and CRC.
    Frame(Counts),
    /// Sixteen bytes starting with the header whose CRC failed: nothing of it is used.
    CrcError,
}

/// What a [`StreamDecoder`] has counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecoderCounters {
    /// Bytes pushed.
    pub bytes: u64,
    /// Good frames.
    pub frames: u64,
    /// Header-framed candidates whose CRC failed.
    pub crc_errors: u64,
    /// Bytes skipped while looking for a header (garbage, the tails of broken frames, stop bytes).
    pub skipped: u64,
}

/// Turns a raw byte stream into frames: finds the header, checks the CRC of every candidate and, when a
/// candidate fails, looks for the next header **inside** the failed candidate (a header can occur in a
/// payload, and the real frame may start there). So a valid frame that follows garbage is found as soon
/// as its last byte arrives, and no byte of a failed candidate is ever part of a sample.
///
/// Fixed-size state, no allocation.
#[derive(Clone, Debug, Default)]
pub struct StreamDecoder {
    buf: [u8; FRAME_LEN],
    len: usize,
    counters: DecoderCounters,
}

impl StreamDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// What it counted.
    pub fn counters(&self) -> DecoderCounters {
        self.counters
    }

    /// Forget any partial frame (the counters stay).
    pub fn reset(&mut self) {
        self.skipped(self.len);
        self.len = 0;
    }

    fn skipped(&mut self, n: usize) {
        self.counters.skipped += n as u64;
    }

    /// Drop bytes from the front until the buffer starts with (a prefix of) the header.
    fn realign(&mut self, from: usize) {
        let mut start = from;
        while start < self.len {
            let rest = &self.buf[start..self.len];
            if rest[0] == HEADER[0] && (rest.len() == 1 || rest[1] == HEADER[1]) {
                break;
            }
            start += 1;
        }
        self.skipped(start);
        self.buf.copy_within(start..self.len, 0);
        self.len -= start;
    }

    /// Push one byte; returns an event when it completed a frame candidate.
    pub fn push(&mut self, byte: u8) -> Option<Event> {
        self.counters.bytes += 1;
        self.buf[self.len] = byte;
        self.len += 1;
        // Keep the buffer aligned on a (partial) header.
        if self.len <= 2 {
            if self.buf[0] != HEADER[0] || (self.len == 2 && self.buf[1] != HEADER[1]) {
                self.realign(1);
            }
            return None;
        }
        if self.len < FRAME_LEN {
            return None;
        }
        match decode_frame(&self.buf) {
            Ok(c) => {
                self.len = 0;
                self.counters.frames += 1;
                Some(Event::Frame(c))
            }
            Err(_) => {
                self.counters.crc_errors += 1;
                // The real frame may start inside this candidate: look from its second byte on.
                self.realign(1);
                Some(Event::CrcError)
            }
        }
    }

    /// Push many bytes, calling `on` for every event. Same events as pushing them one by one; a frame
    /// that starts aligned in `bytes` is checked in place (the common case: whole frames per read).
    pub fn feed(&mut self, mut bytes: &[u8], mut on: impl FnMut(Event)) {
        while let Some((&first, rest)) = bytes.split_first() {
            if self.len == 0
                && let Some(f) = bytes.first_chunk::<FRAME_LEN>()
                && f[..2] == HEADER
            {
                self.counters.bytes += FRAME_LEN as u64;
                bytes = &bytes[FRAME_LEN..];
                match decode_frame(f) {
                    Ok(c) => {
                        self.counters.frames += 1;
                        on(Event::Frame(c));
                    }
                    Err(_) => {
                        self.counters.crc_errors += 1;
                        // As in `push`: the real frame may start inside this candidate.
                        self.buf[..FRAME_LEN - 1].copy_from_slice(&f[1..]);
                        self.len = FRAME_LEN - 1;
                        self.skipped(1);
                        self.realign(0);
                        on(Event::CrcError);
                    }
                }
                continue;
            }
            if let Some(e) = self.push(first) {
                on(e);
            }
            bytes = rest;
        }
    }
}

/// A register reply of the wrong shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RegisterError {
    /// Not the number of registers asked for.
    Length {
        /// Registers expected.
        expected: usize,
        /// Registers received.
        got: usize,
    },
}

impl fmt::Display for RegisterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Length { expected, got } => {
                write!(f, "expected {expected} registers, got {got}")
            }
        }
    }
}

impl std::error::Error for RegisterError {}

/// What registers 500..=514 say about the sensor.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Identity {
    /// Registers 500..=502 as six bytes: an ASCII name ("FTS…") followed by version bytes.
    pub firmware: [u8; 6],
    /// Registers 510..=513 as eight bytes.
    pub serial: [u8; 8],
    /// Register 514.
    pub year: u16,
}

fn words_to_bytes<const N: usize>(regs: &[u16]) -> Result<[u8; N], RegisterError> {
    if regs.len() * 2 != N {
        return Err(RegisterError::Length {
            expected: N / 2,
            got: regs.len(),
        });
    }
    let mut out = [0u8; N];
    for (i, r) in regs.iter().enumerate() {
        out[2 * i..2 * i + 2].copy_from_slice(&r.to_be_bytes());
    }
    Ok(out)
}

fn bytes_to_words<const N: usize>(b: &[u8]) -> [u16; N] {
    let mut out = [0u16; N];
    for (i, w) in out.iter_mut().enumerate() {
        *w = u16::from_be_bytes([b[2 * i], b[2 * i + 1]]);
    }
    out
}

impl Identity {
    /// From the firmware (3), serial (4) and year (1) registers.
    pub fn from_registers(
        firmware: &[u16],
        serial: &[u16],
        year: &[u16],
    ) -> Result<Self, RegisterError> {
        let [year] = *year else {
            return Err(RegisterError::Length {
                expected: 1,
                got: year.len(),
            });
        };
        Ok(Self {
            firmware: words_to_bytes::<6>(firmware)?,
            serial: words_to_bytes::<8>(serial)?,
            year,
        })
    }

    /// Registers 500..=502.
    pub fn firmware_registers(&self) -> [u16; 3] {
        bytes_to_words(&self.firmware)
    }

    /// Registers 510..=513.
    pub fn serial_registers(&self) -> [u16; 4] {
        bytes_to_words(&self.serial)
    }

    /// The firmware as text: the leading ASCII letters, then the remaining bytes as a dotted version
    /// (`FTS-3.1.0`).
    pub fn firmware_text(&self) -> String {
        let name_len = self
            .firmware
            .iter()
            .take_while(|b| b.is_ascii_alphabetic())
            .count();
        let name: String = self.firmware[..name_len]
            .iter()
            .map(|&b| char::from(b))
            .collect();
        let version: Vec<String> = self.firmware[name_len..]
            .iter()
            .map(u8::to_string)
            .collect();
        format!("{name}-{}", version.join("."))
    }

    /// The serial number as the vendor's own host driver decodes registers 510..=513: three
    /// characters (the high and low bytes of 510, the high byte of 511), a dash, and the 32-bit
    /// number whose bytes are 513 high, 513 low, 512 high, 512 low, written with at least four
    /// digits; `UNKNOWN` when that number is 0. The low byte of 511 is not part of it.
    /// Registers `0x4654 0x5333 0x3030 0x3432` read `FTS-875704368`.
    pub fn serial_text(&self) -> String {
        let n = self.serial_number();
        if n == 0 {
            return "UNKNOWN".into();
        }
        let c = |b: u8| {
            if b.is_ascii_graphic() {
                char::from(b)
            } else {
                '?'
            }
        };
        format!(
            "{}{}{}-{n:04}",
            c(self.serial[0]),
            c(self.serial[1]),
            c(self.serial[2])
        )
    }

    /// The number part of the serial (see [`Identity::serial_text`]).
    pub fn serial_number(&self) -> u32 {
        let s = &self.serial;
        u32::from_be_bytes([s[6], s[7], s[4], s[5]])
    }

    /// The serial registers' bytes for a three-character prefix and a number, as the vendor's
    /// driver decodes them; `spare` is the low byte of register 511, which it does not read.
    pub fn serial_bytes(prefix: [u8; 3], spare: u8, number: u32) -> [u8; 8] {
        let n = number.to_be_bytes();
        [
            prefix[0], prefix[1], prefix[2], spare, n[2], n[3], n[0], n[1],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    fn golden_counts() -> Counts {
        Counts([1234, -567, -9810, 123, -45, 6])
    }

    #[test]
    fn golden_stream_frame_both_directions() {
        let golden = hex("20 4E D2 04 C9 FD AE D9 7B 00 D3 FF 06 00 07 07");
        assert_eq!(encode_frame(golden_counts()).to_vec(), golden);
        let f: [u8; 16] = golden.try_into().unwrap();
        let c = decode_frame(&f).unwrap();
        assert_eq!(c, golden_counts());
        let w = c.to_wrench().to_array();
        let want = [12.34, -5.67, -98.10, 0.123, -0.045, 0.006];
        for (a, b) in w.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{w:?}");
        }
        assert_eq!(Counts::from_wrench(&Wrench::from_array(want)), Ok(c));
    }

    #[test]
    fn golden_modbus_request_and_reply_crcs() {
        // The read of six registers from 180 and its reply, CRC low byte first.
        let req = hex("09 03 00 B4 00 06 84 A6");
        assert_eq!(crc16(&req[..6]).to_le_bytes(), [req[6], req[7]]);
        let reply = hex("09 03 0C 04 D2 FD C9 D9 AE 00 7B FF D3 00 06 40 B7");
        assert_eq!(crc16(&reply[..15]).to_le_bytes(), [reply[15], reply[16]]);
        let regs: Vec<u16> = reply[3..15]
            .chunks(2)
            .map(|w| u16::from_be_bytes([w[0], w[1]]))
            .collect();
        assert_eq!(Counts::from_registers(&regs), Ok(golden_counts()));
        assert_eq!(golden_counts().to_registers().to_vec(), regs);
        assert_eq!(REG_WRENCH, 0x00B4);
    }

    #[test]
    fn bad_crc_and_header_are_rejected() {
        let mut f = encode_frame(golden_counts());
        f[5] ^= 0x01;
        assert!(matches!(decode_frame(&f), Err(FrameError::Crc { .. })));
        let mut g = encode_frame(golden_counts());
        g[1] = 0x4F;
        assert_eq!(decode_frame(&g), Err(FrameError::Header([0x20, 0x4F])));
    }

    #[test]
    fn out_of_range_wrench_is_refused() {
        let w = Wrench::from_array([400.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(
            Counts::from_wrench(&w),
            Err(OutOfRange {
                channel: 0,
                value: 400.0
            })
        );
        let n = Wrench::from_array([0.0, 0.0, 0.0, 0.0, f64::NAN, 0.0]);
        assert_eq!(Counts::from_wrench(&n).unwrap_err().channel, 4);
    }

    #[test]
    fn decoder_finds_a_frame_whose_header_hides_in_a_broken_candidate() {
        // A false header inside garbage, then a real frame starting inside the false candidate.
        let frame = encode_frame(golden_counts());
        let mut bytes = vec![0x00, 0x20, 0x4E, 0x11, 0x22];
        bytes.extend_from_slice(&frame);
        let mut d = StreamDecoder::new();
        let mut events = Vec::new();
        d.feed(&bytes, |e| events.push(e));
        assert_eq!(events, vec![Event::CrcError, Event::Frame(golden_counts())]);
        assert_eq!(d.counters().frames, 1);
        assert_eq!(d.counters().crc_errors, 1);
    }

    #[test]
    fn identity_text() {
        let id = Identity::from_registers(
            &[0x4654, 0x5303, 0x0100],
            &[0x4654, 0x5333, 0x3030, 0x3432],
            &[2021],
        )
        .unwrap();
        assert_eq!(id.firmware_text(), "FTS-3.1.0");
        // The golden vector: what Robotiq's own host driver prints for these registers.
        assert_eq!(id.serial_text(), "FTS-875704368");
        assert_eq!(id.serial_number(), 875_704_368);
        assert_eq!(
            Identity::serial_bytes(*b"FTS", b'3', 875_704_368),
            id.serial
        );
        assert_eq!(id.serial_registers(), [0x4654, 0x5333, 0x3030, 0x3432]);
        let mut zero = id.clone();
        zero.serial = Identity::serial_bytes(*b"FTS", 0, 0);
        assert_eq!(zero.serial_text(), "UNKNOWN");
        zero.serial = Identity::serial_bytes(*b"FTS", 0, 42);
        assert_eq!(zero.serial_text(), "FTS-0042");
        assert_eq!(id.year, 2021);
        assert_eq!(id.firmware_registers(), [0x4654, 0x5303, 0x0100]);
        assert!(Identity::from_registers(&[1, 2], &[0; 4], &[1]).is_err());
    }
}
