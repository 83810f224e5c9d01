//! A classic CAN 2.0 frame as the codec and the transports exchange it: no I/O, no allocation.

use core::fmt;

/// Largest 11-bit standard identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// Largest 29-bit extended identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// One classic CAN frame (up to 8 data bytes). Error frames are not frames here: transports report them
/// as [`crate::transport::BusEvent::Error`].
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    id: u32,
    extended: bool,
    remote: bool,
    len: u8,
    data: [u8; 8],
}

impl Frame {
    /// A standard (11-bit) data frame. `None` when `id > 0x7FF` or `data` is longer than 8 bytes.
    pub fn standard(id: u16, data: &[u8]) -> Option<Self> {
        Self::data_frame(u32::from(id), false, data)
    }

    /// An extended (29-bit) data frame. `None` when `id > 0x1FFF_FFFF` or `data` is longer than 8 bytes.
    pub fn extended(id: u32, data: &[u8]) -> Option<Self> {
        Self::data_frame(id, true, data)
    }

    /// A remote (RTR) frame with a requested length `dlc`. `None` on an out-of-range id or `dlc > 8`.
    pub fn remote(id: u32, extended: bool, dlc: u8) -> Option<Self> {
        let max = if extended {
            MAX_EXTENDED_ID
        } else {
            MAX_STANDARD_ID
        };
        (id <= max && dlc <= 8).then_some(Self {
            id,
            extended,
            remote: true,
            len: dlc,
            data: [0; 8],
        })
    }

    fn data_frame(id: u32, extended: bool, data: &[u8]) -> Option<Self> {
        let max = if extended {
            MAX_EXTENDED_ID
        } else {
            MAX_STANDARD_ID
        };
        if id > max || data.len() > 8 {
            return None;
        }
        let mut buf = [0; 8];
        buf[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            extended,
            remote: false,
            len: data.len() as u8,
            data: buf,
        })
    }

    /// The identifier (11 or 29 bits, see [`is_extended`](Self::is_extended)).
    pub fn id(&self) -> u32 {
        self.id
    }

    /// True for a 29-bit identifier.
    pub fn is_extended(&self) -> bool {
        self.extended
    }

    /// True for a remote (RTR) frame.
    pub fn is_remote(&self) -> bool {
        self.remote
    }

    /// The data length code (0..=8).
    pub fn dlc(&self) -> u8 {
        self.len
    }

    /// The data bytes (empty for a remote frame).
    pub fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..usize::from(self.len)]
        }
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

/// The `candump -L` / `cansend` notation: `200#0000F401`, `12345678#…` for extended ids, `200#R2` for RTR.
impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.extended {
            write!(f, "{:08X}#", self.id)?;
        } else {
            write!(f, "{:03X}#", self.id)?;
        }
        if self.remote {
            return write!(f, "R{}", self.len);
        }
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_refuse_out_of_range() {
        assert!(Frame::standard(0x800, &[]).is_none());
        assert!(Frame::standard(0x7FF, &[0; 9]).is_none());
        assert!(Frame::extended(0x2000_0000, &[]).is_none());
        assert!(Frame::remote(0x200, false, 9).is_none());
        let f = Frame::standard(0x201, &[1, 2, 3]).unwrap();
        assert_eq!((f.id(), f.dlc(), f.data()), (0x201, 3, &[1u8, 2, 3][..]));
    }

    #[test]
    fn display_matches_can_utils_notation() {
        assert_eq!(Frame::standard(0x200, &[]).unwrap().to_string(), "200#");
        assert_eq!(
            Frame::standard(0x201, &[0x00, 0xFA]).unwrap().to_string(),
            "201#00FA"
        );
        assert_eq!(
            Frame::extended(0x200, &[1]).unwrap().to_string(),
            "00000200#01"
        );
        assert_eq!(
            Frame::remote(0x200, false, 8).unwrap().to_string(),
            "200#R8"
        );
    }
}
