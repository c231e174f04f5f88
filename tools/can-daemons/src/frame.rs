// SPDX-License-Identifier: GPL-2.0
//! A classic CAN frame as CAN_RAW reads and writes it (`struct can_frame`,
//! 16 bytes) and its text in can-utils' `candump -l` log format.

use std::fmt::Write;

/// Extended frame format flag of `can_id`.
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// Remote transmission request flag of `can_id`.
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// Error frame flag of `can_id`.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Identifier bits of an extended frame.
pub const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;
/// Identifier bits of a standard frame.
pub const CAN_SFF_MASK: u32 = 0x7FF;
/// Size of `struct can_frame` (CAN_MTU).
pub const CAN_MTU: usize = 16;

/// `struct can_frame`: identifier with flags, length, up to 8 data bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Frame {
    /// `can_id`, flags included.
    pub id: u32,
    /// `len` (0..=8).
    pub len: u8,
    /// `data`; bytes past `len` are zero.
    pub data: [u8; 8],
}

impl Frame {
    /// Decodes the bytes a CAN_RAW socket returned; `None` unless they are
    /// one whole classic frame with `len <= 8`.
    pub fn from_bytes(b: &[u8]) -> Option<Self> {
        if b.len() != CAN_MTU || b[4] > 8 {
            return None;
        }
        let mut data = [0u8; 8];
        let len = b[4];
        data[..len as usize].copy_from_slice(&b[8..8 + len as usize]);
        Some(Self {
            id: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
            len,
            data,
        })
    }

    /// The 16 bytes to write to a CAN_RAW socket.
    pub fn to_bytes(&self) -> [u8; CAN_MTU] {
        let mut b = [0u8; CAN_MTU];
        b[..4].copy_from_slice(&self.id.to_ne_bytes());
        b[4] = self.len;
        b[8..].copy_from_slice(&self.data);
        b
    }

    /// The data bytes in use.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len.min(8))]
    }

    /// True for an extended (29-bit) identifier.
    pub fn is_extended(&self) -> bool {
        self.id & CAN_EFF_FLAG != 0
    }

    /// Appends the frame as can-utils' `candump -l` writes it after the
    /// interface name: `123#1122`, `12345678#`, `123#R`, `123#R4` (remote
    /// frame with length 4), `20000004#0004000000000000` (error frame: the
    /// error class bits as 8 hex digits).
    pub fn write_candump(&self, out: &mut String) {
        if self.id & CAN_ERR_FLAG != 0 {
            let _ = write!(out, "{:08X}#", self.id & (CAN_EFF_MASK | CAN_ERR_FLAG));
        } else if self.is_extended() {
            let _ = write!(out, "{:08X}#", self.id & CAN_EFF_MASK);
        } else {
            let _ = write!(out, "{:03X}#", self.id & CAN_SFF_MASK);
        }
        if self.id & CAN_RTR_FLAG != 0 && self.id & CAN_ERR_FLAG == 0 {
            out.push('R');
            if (1..=8).contains(&self.len) {
                out.push(char::from(b'0' + self.len));
            }
            return;
        }
        for b in self.payload() {
            let _ = write!(out, "{b:02X}");
        }
    }
}

/// Appends one `candump -l` log line, newline included:
/// `(1700000000.123456) can0 123#1122`.
pub fn candump_line(out: &mut String, sec: i64, usec: i64, iface: &str, f: &Frame) {
    let _ = write!(out, "({sec:010}.{usec:06}) {iface} ");
    f.write_candump(out);
    out.push('\n');
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(f: Frame) -> String {
        let mut s = String::new();
        candump_line(&mut s, 1_700_000_000, 42, "can0", &f);
        s
    }

    #[test]
    fn candump_formats() {
        let mut d = [0u8; 8];
        d[..2].copy_from_slice(&[0x11, 0x22]);
        let f = Frame {
            id: 0x123,
            len: 2,
            data: d,
        };
        assert_eq!(line(f), "(1700000000.000042) can0 123#1122\n");
        let f = Frame {
            id: CAN_EFF_FLAG | 0x1234567,
            len: 0,
            data: [0; 8],
        };
        assert_eq!(line(f), "(1700000000.000042) can0 01234567#\n");
        let f = Frame {
            id: CAN_RTR_FLAG | 0x7FF,
            len: 4,
            data: [0; 8],
        };
        assert_eq!(line(f), "(1700000000.000042) can0 7FF#R4\n");
        let f = Frame {
            id: CAN_RTR_FLAG | CAN_EFF_FLAG | 5,
            len: 0,
            data: [0; 8],
        };
        assert_eq!(line(f), "(1700000000.000042) can0 00000005#R\n");
        let f = Frame {
            id: CAN_ERR_FLAG | 0x4,
            len: 8,
            data: [0, 4, 0, 0, 0, 0, 0, 0],
        };
        assert_eq!(
            line(f),
            "(1700000000.000042) can0 20000004#0004000000000000\n"
        );
    }

    #[test]
    fn bytes_round_trip() {
        let f = Frame {
            id: CAN_EFF_FLAG | 0xABCDE,
            len: 3,
            data: [1, 2, 3, 0, 0, 0, 0, 0],
        };
        assert_eq!(Frame::from_bytes(&f.to_bytes()), Some(f));
        let mut b = f.to_bytes();
        b[4] = 9;
        assert_eq!(Frame::from_bytes(&b), None);
        assert_eq!(Frame::from_bytes(&b[..8]), None);
    }
}
