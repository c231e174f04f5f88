// SPDX-License-Identifier: GPL-2.0
//! `powerd`'s pure parts: the shutdown frame's pattern (identifier, data
//! and mask) and how a received frame is matched against it.

use crate::frame::{Frame, CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};

/// The frame that commands the shutdown.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pattern {
    /// Identifier, `CAN_EFF_FLAG` set for an extended one.
    pub id: u32,
    /// Expected data bytes (the frame must carry at least as many).
    pub data: Vec<u8>,
    /// Mask of `data`: only bits set here are compared; same length.
    pub mask: Vec<u8>,
}

/// Parses a hexadecimal identifier: extended when written with 8 digits
/// or above 0x7FF (as candump/cansend and socketcand do).
pub fn parse_id(s: &str) -> Result<u32, String> {
    let t = s.trim_start_matches("0x");
    let id = u32::from_str_radix(t, 16).map_err(|_| format!("bad CAN identifier {s}"))?;
    if t.len() == 8 || id > CAN_SFF_MASK {
        if id > CAN_EFF_MASK {
            return Err(format!("CAN identifier {s} over 29 bits"));
        }
        return Ok(id | CAN_EFF_FLAG);
    }
    Ok(id)
}

/// Parses 0 to 8 bytes written as hex digits, optionally separated by
/// `.` (as in cansend's `123#11.22`): `DEAD`, `de.ad`, `` (none).
pub fn parse_bytes(s: &str) -> Result<Vec<u8>, String> {
    let digits: String = s.chars().filter(|&c| c != '.').collect();
    if !digits.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("{s}: not hex"));
    }
    if !digits.len().is_multiple_of(2) || digits.len() > 16 {
        return Err(format!("{s}: expected 0 to 8 bytes as pairs of hex digits"));
    }
    (0..digits.len() / 2)
        .map(|i| {
            u8::from_str_radix(&digits[2 * i..2 * i + 2], 16).map_err(|_| format!("{s}: not hex"))
        })
        .collect()
}

impl Pattern {
    /// A pattern; `mask` defaults to all ones and must be as long as
    /// `data`.
    pub fn new(id: u32, data: Vec<u8>, mask: Option<Vec<u8>>) -> Result<Self, String> {
        let mask = mask.unwrap_or_else(|| vec![0xFF; data.len()]);
        if mask.len() != data.len() {
            return Err(format!(
                "the mask has {} bytes, the data {}",
                mask.len(),
                data.len()
            ));
        }
        Ok(Self { id, data, mask })
    }

    /// The CAN_RAW filter (id, mask) that lets only this identifier
    /// through, data frames of its format only.
    pub fn raw_filter(&self) -> (u32, u32) {
        let idmask = if self.id & CAN_EFF_FLAG != 0 {
            CAN_EFF_MASK
        } else {
            CAN_SFF_MASK
        };
        (self.id, CAN_EFF_FLAG | CAN_RTR_FLAG | idmask)
    }

    /// True if `f` commands the shutdown: a data frame (not remote, not
    /// error) with this identifier and format, at least `data.len()`
    /// bytes long, whose first bytes equal `data` under `mask`.
    pub fn matches(&self, f: &Frame) -> bool {
        if f.id & (CAN_RTR_FLAG | CAN_ERR_FLAG) != 0 || f.id != self.id {
            return false;
        }
        let p = f.payload();
        p.len() >= self.data.len()
            && self
                .data
                .iter()
                .zip(&self.mask)
                .zip(p)
                .all(|((d, m), b)| b & m == d & m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u32, d: &[u8]) -> Frame {
        let mut f = Frame {
            id,
            len: d.len() as u8,
            data: [0; 8],
        };
        f.data[..d.len()].copy_from_slice(d);
        f
    }

    #[test]
    fn parses() {
        assert_eq!(parse_id("7FF"), Ok(0x7FF));
        assert_eq!(parse_id("0x123"), Ok(0x123));
        assert_eq!(parse_id("00000123"), Ok(CAN_EFF_FLAG | 0x123));
        assert_eq!(parse_id("800"), Ok(CAN_EFF_FLAG | 0x800));
        assert!(parse_id("20000000").is_err());
        assert!(parse_id("xyz").is_err());
        assert_eq!(parse_bytes("de.AD"), Ok(vec![0xDE, 0xAD]));
        assert_eq!(parse_bytes(""), Ok(vec![]));
        assert!(parse_bytes("123").is_err());
        assert!(parse_bytes("001122334455667788").is_err());
        assert!(parse_bytes("zz").is_err());
        assert!(parse_bytes("ééé").is_err());
        assert!(Pattern::new(1, vec![1, 2], Some(vec![1])).is_err());
    }

    #[test]
    fn matching() {
        let p = Pattern::new(0x7E0, vec![0xDE, 0xAD], Some(vec![0xFF, 0xF0])).unwrap();
        assert!(p.matches(&frame(0x7E0, &[0xDE, 0xAD])));
        assert!(p.matches(&frame(0x7E0, &[0xDE, 0xA7, 9])));
        assert!(!p.matches(&frame(0x7E0, &[0xDE, 0xBD])));
        assert!(!p.matches(&frame(0x7E0, &[0xDE])));
        assert!(!p.matches(&frame(0x7E1, &[0xDE, 0xAD])));
        assert!(!p.matches(&frame(CAN_EFF_FLAG | 0x7E0, &[0xDE, 0xAD])));
        assert!(!p.matches(&frame(CAN_RTR_FLAG | 0x7E0, &[0xDE, 0xAD])));
        let any = Pattern::new(CAN_EFF_FLAG | 0x123, vec![], None).unwrap();
        assert!(any.matches(&frame(CAN_EFF_FLAG | 0x123, &[])));
        assert!(!any.matches(&frame(0x123, &[])));
        assert_eq!(p.raw_filter(), (0x7E0, 0xC000_07FF));
    }
}
