//! The NETCANOEM wire protocol, sans I/O: every request and every answer of the opcode table, both
//! directions (the driver encodes requests and decodes answers; the simulated node does the opposite).
//!
//! Identifiers are `(base << 4) | opcode`, 11-bit standard data frames only, all values big-endian.
//! Decoding is strict: an extended or remote frame, another base, an unknown opcode or a wrong data
//! length is an error that says which, never a panic and never a guess.

use core::fmt;

use crate::frame::Frame;

/// Opcode numbers (the low four bits of the identifier).
pub mod op {
    /// Poll the gauges; answer in two frames (this opcode and [`POLL_2`]).
    pub const POLL: u8 = 0x0;
    /// Second frame of a poll answer.
    pub const POLL_2: u8 = 0x1;
    /// Read one row of the calibration matrix; answer in three frames (`0x2`, `0x3`, `0x4`).
    pub const MATRIX: u8 = 0x2;
    /// Calibration serial number.
    pub const SERIAL: u8 = 0x5;
    /// Select the active calibration slot; the answer echoes it.
    pub const SLOT: u8 = 0x6;
    /// Counts per force unit and per torque unit (firmware ≥ 3.7).
    pub const COUNTS: u8 = 0x7;
    /// Force and torque unit codes.
    pub const UNITS: u8 = 0x8;
    /// A diagnostic ADC voltage (firmware ≥ 3.8).
    pub const ADC: u8 = 0x9;
    /// Reset the board; no answer.
    pub const RESET: u8 = 0xC;
    /// Set the base identifier for the next power-up; no answer.
    pub const SET_BASE: u8 = 0xD;
    /// Set the bit rate for the next power-up; no answer.
    pub const SET_BITRATE: u8 = 0xE;
    /// Firmware version.
    pub const FIRMWARE: u8 = 0xF;
}

/// A decoding or encoding failure. Every variant names what was wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CodecError {
    /// A 29-bit identifier: the board speaks standard frames only.
    Extended {
        /// The identifier.
        id: u32,
    },
    /// A remote (RTR) frame: the board neither sends nor answers them.
    Remote {
        /// The identifier.
        id: u32,
    },
    /// A standard frame of another base (another device).
    Foreign {
        /// The identifier.
        id: u32,
    },
    /// An opcode that has no meaning in this direction.
    Opcode {
        /// The opcode.
        opcode: u8,
    },
    /// The data length does not match the opcode.
    Dlc {
        /// The opcode.
        opcode: u8,
        /// The length the opcode requires.
        expected: u8,
        /// The length received.
        got: u8,
    },
    /// A field is out of range (a matrix row > 5, a slot > 15, a base > 0x7F, a unit code 0 or > 6).
    Value {
        /// The opcode.
        opcode: u8,
        /// The offending value.
        value: u32,
    },
}

impl fmt::Display for CodecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Extended { id } => {
                write!(f, "extended frame 0x{id:08X}: the sensor uses 11-bit ids")
            }
            Self::Remote { id } => write!(f, "remote frame 0x{id:03X}: the sensor never sends RTR"),
            Self::Foreign { id } => write!(f, "frame 0x{id:03X} belongs to another base"),
            Self::Opcode { opcode } => write!(f, "opcode 0x{opcode:X} is not valid here"),
            Self::Dlc {
                opcode,
                expected,
                got,
            } => write!(
                f,
                "opcode 0x{opcode:X} needs {expected} data bytes, got {got}"
            ),
            Self::Value { opcode, value } => {
                write!(f, "opcode 0x{opcode:X}: value {value} out of range")
            }
        }
    }
}

impl std::error::Error for CodecError {}

/// A 7-bit base identifier: the sensor's identifiers are `base << 4 | opcode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Base(u8);

impl Base {
    /// The factory default, 0x20 (identifiers 0x200..=0x20F).
    pub const DEFAULT: Base = Base(0x20);

    /// A base, `None` above 0x7F.
    pub const fn new(base: u8) -> Option<Self> {
        if base <= 0x7F { Some(Self(base)) } else { None }
    }

    /// The 7-bit value.
    pub fn get(self) -> u8 {
        self.0
    }

    /// The identifier of `opcode` (low four bits) on this base.
    pub fn id(self, opcode: u8) -> u16 {
        (u16::from(self.0) << 4) | u16::from(opcode & 0xF)
    }

    /// The opcode of a standard data frame on this base, or the reason the frame is not one.
    pub fn opcode_of(self, frame: &Frame) -> Result<u8, CodecError> {
        if frame.is_extended() {
            return Err(CodecError::Extended { id: frame.id() });
        }
        if frame.is_remote() {
            return Err(CodecError::Remote { id: frame.id() });
        }
        if frame.id() >> 4 != u32::from(self.0) {
            return Err(CodecError::Foreign { id: frame.id() });
        }
        Ok((frame.id() & 0xF) as u8)
    }
}

impl Default for Base {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl fmt::Display for Base {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:02X}", self.0)
    }
}

/// The board's status word, sent first in every poll answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Status(pub u16);

impl Status {
    /// Bit 0: the board was reset by its watchdog (and fell back to calibration slot 0).
    pub const WATCHDOG_RESET: u16 = 1 << 0;
    /// Bit 14: CAN bus error.
    pub const CAN_BUS_ERROR: u16 = 1 << 14;
    /// Bit 15: any error.
    pub const ANY_ERROR: u16 = 1 << 15;
    /// Bits 1–7, 11, 12: the samples are unusable while any is set.
    pub const CRITICAL: u16 = 0b0001_1000_1111_1110;
    /// Bits the manual leaves undefined (9, 10, 13); set only by a corrupted or byte-swapped word.
    pub const RESERVED: u16 = (1 << 9) | (1 << 10) | (1 << 13);

    /// True when a critical bit is set.
    pub fn is_critical(self) -> bool {
        self.0 & Self::CRITICAL != 0
    }

    /// True after a watchdog reset.
    pub fn watchdog_reset(self) -> bool {
        self.0 & Self::WATCHDOG_RESET != 0
    }

    /// The names of the set bits, for messages.
    pub fn describe(self) -> impl Iterator<Item = &'static str> {
        const NAMES: [(u16, &str); 14] = [
            (1 << 0, "watchdog reset"),
            (1 << 1, "DAC/ADC check too high"),
            (1 << 2, "DAC/ADC check too low"),
            (1 << 3, "analog ground out of range"),
            (1 << 4, "supply too high"),
            (1 << 5, "supply too low"),
            (1 << 6, "bad active calibration"),
            (1 << 7, "EEPROM failure"),
            (1 << 8, "configuration invalid"),
            (1 << 11, "temperature too high"),
            (1 << 12, "temperature too low"),
            (1 << 14, "CAN bus error"),
            (1 << 15, "any error"),
            (Status::RESERVED, "reserved bits"),
        ];
        NAMES
            .into_iter()
            .filter(move |(mask, _)| self.0 & mask != 0)
            .map(|(_, name)| name)
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:04X}", self.0)?;
        let mut sep = " (";
        for name in self.describe() {
            write!(f, "{sep}{name}")?;
            sep = ", ";
        }
        if sep == ", " {
            f.write_str(")")?;
        }
        Ok(())
    }
}

/// The six raw strain gauges, in gauge order `sg0..sg5` (the wire interleaves them over two frames).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub struct Gauges(pub [i16; 6]);

impl Gauges {
    /// True when any gauge sits at a rail (−32768 or +32767): the sample is unusable.
    pub fn is_saturated(&self) -> bool {
        self.0.iter().any(|&g| g == i16::MIN || g == i16::MAX)
    }
}

/// A request from the host to the board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    /// 0x0: status and gauges.
    Poll,
    /// 0x2: one row of the calibration matrix, 0..=5 for Fx Fy Fz Tx Ty Tz.
    MatrixRow(u8),
    /// 0x5: calibration serial number.
    Serial,
    /// 0x6: select calibration slot 0..=15.
    SelectSlot(u8),
    /// 0x7: counts per force and per torque unit.
    CountsPerUnit,
    /// 0x8: unit codes.
    Units,
    /// 0x9: diagnostic ADC voltage by index.
    AdcVoltage(u8),
    /// 0xC: reset the board (no answer).
    Reset,
    /// 0xD: base for the next power-up (no answer).
    SetBase(u8),
    /// 0xE: bit-rate code for the next power-up, rate = 2 Mbit/s / (code + 1) (no answer).
    SetBitrate(u8),
    /// 0xF: firmware version.
    Firmware,
}

impl Request {
    /// The opcode.
    pub fn opcode(self) -> u8 {
        match self {
            Self::Poll => op::POLL,
            Self::MatrixRow(_) => op::MATRIX,
            Self::Serial => op::SERIAL,
            Self::SelectSlot(_) => op::SLOT,
            Self::CountsPerUnit => op::COUNTS,
            Self::Units => op::UNITS,
            Self::AdcVoltage(_) => op::ADC,
            Self::Reset => op::RESET,
            Self::SetBase(_) => op::SET_BASE,
            Self::SetBitrate(_) => op::SET_BITRATE,
            Self::Firmware => op::FIRMWARE,
        }
    }

    /// The single data byte, if the request has one.
    fn argument(self) -> Option<u8> {
        match self {
            Self::MatrixRow(v)
            | Self::SelectSlot(v)
            | Self::AdcVoltage(v)
            | Self::SetBase(v)
            | Self::SetBitrate(v) => Some(v),
            _ => None,
        }
    }

    /// The data length of the request frame (0 or 1).
    pub fn data_len(self) -> u8 {
        u8::from(self.argument().is_some())
    }

    /// The frames of the answer as `(opcode, data length)`, in wire order; empty when the board does
    /// not answer.
    pub fn answer_layout(self) -> &'static [(u8, u8)] {
        match self {
            Self::Poll => &[(op::POLL, 8), (op::POLL_2, 6)],
            Self::MatrixRow(_) => &[(op::MATRIX, 8), (op::MATRIX + 1, 8), (op::MATRIX + 2, 8)],
            Self::Serial => &[(op::SERIAL, 8)],
            Self::SelectSlot(_) => &[(op::SLOT, 1)],
            Self::CountsPerUnit => &[(op::COUNTS, 8)],
            Self::Units => &[(op::UNITS, 2)],
            Self::AdcVoltage(_) => &[(op::ADC, 2)],
            Self::Reset | Self::SetBase(_) | Self::SetBitrate(_) => &[],
            Self::Firmware => &[(op::FIRMWARE, 4)],
        }
    }

    fn check_argument(opcode: u8, v: u8) -> Result<(), CodecError> {
        let max = match opcode {
            op::MATRIX => 5,
            op::SLOT => 15,
            op::SET_BASE => 0x7F,
            _ => u8::MAX,
        };
        if v > max {
            Err(CodecError::Value {
                opcode,
                value: u32::from(v),
            })
        } else {
            Ok(())
        }
    }

    /// The request as a frame on `base`. Fails only on an out-of-range argument.
    pub fn encode(self, base: Base) -> Result<Frame, CodecError> {
        let opcode = self.opcode();
        let id = base.id(opcode);
        let frame = match self.argument() {
            Some(v) => {
                Self::check_argument(opcode, v)?;
                Frame::standard(id, &[v])
            }
            None => Frame::standard(id, &[]),
        };
        // The id is at most 0x7FF and the data at most one byte: the constructor cannot refuse.
        frame.ok_or(CodecError::Opcode { opcode })
    }

    /// Decode a request (the board's side).
    pub fn decode(frame: &Frame, base: Base) -> Result<Self, CodecError> {
        let opcode = base.opcode_of(frame)?;
        let data = frame.data();
        let arg = |expected: u8| -> Result<u8, CodecError> {
            if data.len() != usize::from(expected) {
                return Err(CodecError::Dlc {
                    opcode,
                    expected,
                    got: frame.dlc(),
                });
            }
            let v = data.first().copied().unwrap_or(0);
            if expected == 1 {
                Self::check_argument(opcode, v)?;
            }
            Ok(v)
        };
        Ok(match opcode {
            op::POLL => arg(0).map(|_| Self::Poll)?,
            op::MATRIX => Self::MatrixRow(arg(1)?),
            op::SERIAL => arg(0).map(|_| Self::Serial)?,
            op::SLOT => Self::SelectSlot(arg(1)?),
            op::COUNTS => arg(0).map(|_| Self::CountsPerUnit)?,
            op::UNITS => arg(0).map(|_| Self::Units)?,
            op::ADC => Self::AdcVoltage(arg(1)?),
            op::RESET => arg(0).map(|_| Self::Reset)?,
            op::SET_BASE => Self::SetBase(arg(1)?),
            op::SET_BITRATE => Self::SetBitrate(arg(1)?),
            op::FIRMWARE => arg(0).map(|_| Self::Firmware)?,
            _ => return Err(CodecError::Opcode { opcode }),
        })
    }
}

/// One answer frame from the board, decoded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Answer {
    /// 0x0 (DLC 8): status word and gauges 0, 2, 4.
    PollFirst {
        /// The status word.
        status: Status,
        /// `sg0, sg2, sg4`.
        gauges: [i16; 3],
    },
    /// 0x1 (DLC 6): gauges 1, 3, 5.
    PollSecond {
        /// `sg1, sg3, sg5`.
        gauges: [i16; 3],
    },
    /// 0x2..=0x4 (DLC 8): two coefficients of a matrix row; `part` 0..=2 gives columns `2·part, 2·part+1`.
    MatrixPart {
        /// 0, 1 or 2.
        part: u8,
        /// The two coefficients.
        coefficients: [f32; 2],
    },
    /// 0x5 (DLC 8): ASCII calibration serial number.
    Serial([u8; 8]),
    /// 0x6 (DLC 1): echo of the selected slot.
    SlotEcho(u8),
    /// 0x7 (DLC 8): counts per force unit and per torque unit.
    Counts {
        /// Counts per force unit.
        per_force: u32,
        /// Counts per torque unit.
        per_torque: u32,
    },
    /// 0x8 (DLC 2): raw force and torque unit codes (see [`crate::ForceUnit`], [`crate::TorqueUnit`]).
    Units {
        /// Force unit code.
        force: u8,
        /// Torque unit code.
        torque: u8,
    },
    /// 0x9 (DLC 2): a diagnostic ADC reading.
    Adc(u16),
    /// 0xF (DLC 4): firmware version.
    Firmware(Firmware),
}

/// A firmware version.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Firmware {
    /// Major version.
    pub major: u8,
    /// Minor version.
    pub minor: u8,
    /// Build number.
    pub build: u16,
}

impl Firmware {
    /// True when the board answers the counts-per-unit request (≥ 3.7).
    pub fn has_counts_per_unit(self) -> bool {
        (self.major, self.minor) >= (3, 7)
    }
}

impl fmt::Display for Firmware {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{} build {}", self.major, self.minor, self.build)
    }
}

fn be_i16(d: &[u8], at: usize) -> i16 {
    i16::from_be_bytes([d[at], d[at + 1]])
}

fn be_u16(d: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([d[at], d[at + 1]])
}

fn be_u32(d: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([d[at], d[at + 1], d[at + 2], d[at + 3]])
}

impl Answer {
    /// The opcode of this frame.
    pub fn opcode(&self) -> u8 {
        match self {
            Self::PollFirst { .. } => op::POLL,
            Self::PollSecond { .. } => op::POLL_2,
            Self::MatrixPart { part, .. } => op::MATRIX + part,
            Self::Serial(_) => op::SERIAL,
            Self::SlotEcho(_) => op::SLOT,
            Self::Counts { .. } => op::COUNTS,
            Self::Units { .. } => op::UNITS,
            Self::Adc(_) => op::ADC,
            Self::Firmware(_) => op::FIRMWARE,
        }
    }

    /// Decode one answer frame on `base` (the host's side). Strict: standard data frames of this base
    /// with exactly the data length of the opcode.
    pub fn decode(frame: &Frame, base: Base) -> Result<Self, CodecError> {
        let opcode = base.opcode_of(frame)?;
        let expected: u8 = match opcode {
            op::POLL | 0x2..=0x4 | op::SERIAL | op::COUNTS => 8,
            op::POLL_2 => 6,
            op::SLOT => 1,
            op::UNITS | op::ADC => 2,
            op::FIRMWARE => 4,
            _ => return Err(CodecError::Opcode { opcode }),
        };
        let d = frame.data();
        if d.len() != usize::from(expected) {
            return Err(CodecError::Dlc {
                opcode,
                expected,
                got: frame.dlc(),
            });
        }
        Ok(match opcode {
            op::POLL => Self::PollFirst {
                status: Status(be_u16(d, 0)),
                gauges: [be_i16(d, 2), be_i16(d, 4), be_i16(d, 6)],
            },
            op::POLL_2 => Self::PollSecond {
                gauges: [be_i16(d, 0), be_i16(d, 2), be_i16(d, 4)],
            },
            op::SERIAL => {
                let mut s = [0; 8];
                s.copy_from_slice(d);
                Self::Serial(s)
            }
            op::SLOT => Self::SlotEcho(d[0]),
            op::COUNTS => Self::Counts {
                per_force: be_u32(d, 0),
                per_torque: be_u32(d, 4),
            },
            op::UNITS => Self::Units {
                force: d[0],
                torque: d[1],
            },
            op::ADC => Self::Adc(be_u16(d, 0)),
            op::FIRMWARE => Self::Firmware(Firmware {
                major: d[0],
                minor: d[1],
                build: be_u16(d, 2),
            }),
            // 0x2..=0x4, the only opcodes left after the length table above.
            _ => Self::MatrixPart {
                part: opcode - op::MATRIX,
                coefficients: [f32::from_bits(be_u32(d, 0)), f32::from_bits(be_u32(d, 4))],
            },
        })
    }

    /// Encode this answer frame on `base` (the board's side). Fails on a matrix `part` above 2.
    pub fn encode(&self, base: Base) -> Result<Frame, CodecError> {
        let mut buf = [0u8; 8];
        let len = match *self {
            Self::PollFirst { status, gauges } => {
                buf[0..2].copy_from_slice(&status.0.to_be_bytes());
                for (i, g) in gauges.iter().enumerate() {
                    buf[2 + 2 * i..4 + 2 * i].copy_from_slice(&g.to_be_bytes());
                }
                8
            }
            Self::PollSecond { gauges } => {
                for (i, g) in gauges.iter().enumerate() {
                    buf[2 * i..2 + 2 * i].copy_from_slice(&g.to_be_bytes());
                }
                6
            }
            Self::MatrixPart { part, coefficients } => {
                if part > 2 {
                    return Err(CodecError::Value {
                        opcode: op::MATRIX,
                        value: u32::from(part),
                    });
                }
                buf[0..4].copy_from_slice(&coefficients[0].to_bits().to_be_bytes());
                buf[4..8].copy_from_slice(&coefficients[1].to_bits().to_be_bytes());
                8
            }
            Self::Serial(s) => {
                buf = s;
                8
            }
            Self::SlotEcho(s) => {
                buf[0] = s;
                1
            }
            Self::Counts {
                per_force,
                per_torque,
            } => {
                buf[0..4].copy_from_slice(&per_force.to_be_bytes());
                buf[4..8].copy_from_slice(&per_torque.to_be_bytes());
                8
            }
            Self::Units { force, torque } => {
                buf[0] = force;
                buf[1] = torque;
                2
            }
            Self::Adc(v) => {
                buf[0..2].copy_from_slice(&v.to_be_bytes());
                2
            }
            Self::Firmware(fw) => {
                buf[0] = fw.major;
                buf[1] = fw.minor;
                buf[2..4].copy_from_slice(&fw.build.to_be_bytes());
                4
            }
        };
        let opcode = self.opcode();
        Frame::standard(base.id(opcode), &buf[..len]).ok_or(CodecError::Opcode { opcode })
    }
}

/// Reassemble the gauges in gauge order from the two poll frames (`sg0, sg2, sg4` and `sg1, sg3, sg5`).
pub fn interleave(first: [i16; 3], second: [i16; 3]) -> Gauges {
    Gauges([
        first[0], second[0], first[1], second[1], first[2], second[2],
    ])
}

/// Split gauges into the two poll frames' triples (the inverse of [`interleave`]).
pub fn split(g: &Gauges) -> ([i16; 3], [i16; 3]) {
    let g = g.0;
    ([g[0], g[2], g[4]], [g[1], g[3], g[5]])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, data: &[u8]) -> Frame {
        Frame::standard(id, data).unwrap()
    }

    const B: Base = Base::DEFAULT;

    // The spec's golden vectors.
    #[test]
    fn golden_poll_answer() {
        let a = Answer::decode(
            &frame(0x200, &[0x00, 0x00, 0x01, 0xF4, 0xFF, 0x9C, 0x00, 0x00]),
            B,
        );
        assert_eq!(
            a,
            Ok(Answer::PollFirst {
                status: Status(0),
                gauges: [500, -100, 0]
            })
        );
        let b = Answer::decode(&frame(0x201, &[0x00, 0xFA, 0x80, 0x00, 0x00, 0x0A]), B);
        assert_eq!(
            b,
            Ok(Answer::PollSecond {
                gauges: [250, -32768, 10]
            })
        );
        let g = interleave([500, -100, 0], [250, -32768, 10]);
        assert_eq!(g, Gauges([500, 250, -100, -32768, 0, 10]));
        assert!(g.is_saturated());
        assert_eq!(split(&g), ([500, -100, 0], [250, -32768, 10]));
    }

    #[test]
    fn golden_counts_and_matrix() {
        let c = Answer::decode(
            &frame(0x207, &[0, 0x0F, 0x42, 0x40, 0, 0x0F, 0x42, 0x40]),
            B,
        );
        assert_eq!(
            c,
            Ok(Answer::Counts {
                per_force: 1_000_000,
                per_torque: 1_000_000
            })
        );
        let m = Answer::decode(&frame(0x202, &[0x3F, 0xC0, 0, 0, 0xBE, 0x80, 0, 0]), B);
        assert_eq!(
            m,
            Ok(Answer::MatrixPart {
                part: 0,
                coefficients: [1.5, -0.25]
            })
        );
    }

    #[test]
    fn golden_vectors_encode_back_to_the_same_bytes() {
        let cases: [(u16, &[u8]); 4] = [
            (0x200, &[0x00, 0x00, 0x01, 0xF4, 0xFF, 0x9C, 0x00, 0x00]),
            (0x201, &[0x00, 0xFA, 0x80, 0x00, 0x00, 0x0A]),
            (0x207, &[0, 0x0F, 0x42, 0x40, 0, 0x0F, 0x42, 0x40]),
            (0x202, &[0x3F, 0xC0, 0, 0, 0xBE, 0x80, 0, 0]),
        ];
        for (id, data) in cases {
            let f = frame(id, data);
            let a = Answer::decode(&f, B).unwrap();
            assert_eq!(a.encode(B).unwrap(), f, "{a:?}");
        }
    }

    #[test]
    fn requests_have_the_spec_identifiers_and_lengths() {
        let cases = [
            (Request::Poll, "200#"),
            (Request::MatrixRow(5), "202#05"),
            (Request::Serial, "205#"),
            (Request::SelectSlot(3), "206#03"),
            (Request::CountsPerUnit, "207#"),
            (Request::Units, "208#"),
            (Request::AdcVoltage(1), "209#01"),
            (Request::Reset, "20C#"),
            (Request::SetBase(0x21), "20D#21"),
            (Request::SetBitrate(7), "20E#07"),
            (Request::Firmware, "20F#"),
        ];
        for (req, wire) in cases {
            let f = req.encode(B).unwrap();
            assert_eq!(f.to_string(), wire);
            assert_eq!(f.dlc(), req.data_len());
            assert_eq!(Request::decode(&f, B), Ok(req));
        }
        let other = Base::new(0x7F).unwrap();
        assert_eq!(Request::Poll.encode(other).unwrap().id(), 0x7F0);
        assert_eq!(Request::Firmware.encode(other).unwrap().id(), 0x7FF);
    }

    #[test]
    fn out_of_range_arguments_are_refused() {
        assert!(matches!(
            Request::MatrixRow(6).encode(B),
            Err(CodecError::Value {
                opcode: 2,
                value: 6
            })
        ));
        assert!(Request::SelectSlot(16).encode(B).is_err());
        assert!(Request::SetBase(0x80).encode(B).is_err());
        assert!(Request::decode(&frame(0x206, &[16]), B).is_err());
        assert!(Base::new(0x80).is_none());
    }

    #[test]
    fn strict_decoding_names_the_problem() {
        let ext = Frame::extended(0x200, &[0; 8]).unwrap();
        assert_eq!(
            Answer::decode(&ext, B),
            Err(CodecError::Extended { id: 0x200 })
        );
        let rtr = Frame::remote(0x200, false, 8).unwrap();
        assert_eq!(
            Answer::decode(&rtr, B),
            Err(CodecError::Remote { id: 0x200 })
        );
        assert_eq!(
            Answer::decode(&frame(0x210, &[0; 8]), B),
            Err(CodecError::Foreign { id: 0x210 })
        );
        assert_eq!(
            Answer::decode(&frame(0x200, &[0; 7]), B),
            Err(CodecError::Dlc {
                opcode: 0,
                expected: 8,
                got: 7
            })
        );
        assert_eq!(
            Answer::decode(&frame(0x201, &[0; 8]), B),
            Err(CodecError::Dlc {
                opcode: 1,
                expected: 6,
                got: 8
            })
        );
        for opcode in [0xA, 0xB, 0xC, 0xD, 0xE] {
            assert_eq!(
                Answer::decode(&frame(0x200 | opcode, &[]), B),
                Err(CodecError::Opcode {
                    opcode: opcode as u8
                })
            );
        }
        // A request seen by another host is not an answer.
        assert!(Answer::decode(&frame(0x200, &[]), B).is_err());
        assert!(Request::decode(&frame(0x201, &[]), B).is_err());
        assert!(Request::decode(&frame(0x200, &[0; 8]), B).is_err());
    }

    #[test]
    fn every_answer_round_trips() {
        let answers = [
            Answer::PollFirst {
                status: Status(0x8002),
                gauges: [-1, 32767, -32768],
            },
            Answer::PollSecond { gauges: [1, 2, 3] },
            Answer::MatrixPart {
                part: 2,
                coefficients: [-1.0e-3, 12345.5],
            },
            Answer::Serial(*b"FT12345 "),
            Answer::SlotEcho(15),
            Answer::Counts {
                per_force: 1_000_000,
                per_torque: 1_000,
            },
            Answer::Units {
                force: 2,
                torque: 3,
            },
            Answer::Adc(0xBEEF),
            Answer::Firmware(Firmware {
                major: 3,
                minor: 8,
                build: 513,
            }),
        ];
        for a in answers {
            let f = a.encode(B).unwrap();
            assert_eq!(Answer::decode(&f, B), Ok(a));
            let expected_len = match a {
                Answer::PollSecond { .. } => 6,
                Answer::SlotEcho(_) => 1,
                Answer::Units { .. } | Answer::Adc(_) => 2,
                Answer::Firmware(_) => 4,
                _ => 8,
            };
            assert_eq!(f.dlc(), expected_len);
        }
        assert!(
            Answer::MatrixPart {
                part: 3,
                coefficients: [0.0; 2]
            }
            .encode(B)
            .is_err()
        );
    }

    #[test]
    fn answer_layouts_match_the_encoder() {
        assert_eq!(Request::Poll.answer_layout(), &[(0, 8), (1, 6)]);
        assert_eq!(Request::MatrixRow(0).answer_layout().len(), 3);
        assert!(Request::Reset.answer_layout().is_empty());
    }

    #[test]
    fn status_word_classification() {
        assert!(!Status(0).is_critical());
        for bit in [1, 2, 3, 4, 5, 6, 7, 11, 12] {
            assert!(Status(1 << bit).is_critical(), "bit {bit}");
        }
        for bit in [0, 8, 9, 10, 13, 14, 15] {
            assert!(!Status(1 << bit).is_critical(), "bit {bit}");
        }
        assert!(Status(1).watchdog_reset());
        assert_eq!(
            Status(0x8040).to_string(),
            "0x8040 (bad active calibration, any error)"
        );
        assert_eq!(Status(0).to_string(), "0x0000");
    }

    #[test]
    fn firmware_feature_gates() {
        let fw = |major, minor| Firmware {
            major,
            minor,
            build: 0,
        };
        assert!(!fw(3, 6).has_counts_per_unit());
        assert!(fw(3, 7).has_counts_per_unit());
        assert!(fw(4, 0).has_counts_per_unit());
    }
}
