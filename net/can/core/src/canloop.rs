// SPDX-License-Identifier: GPL-2.0
//! Logic of the CAN loopback driver (thesis 5.3.5): simulated frame loss and
//! a one-line, allocation-free text dump of a frame for the kernel log.

use core::fmt::Write;

use super::frame::{AnyFrame, CanFdFrame, CanFrame, CANFD_BRS, CANFD_ESI};

/// Probability, in percent, that the loopback driver drops a frame.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct DropRate(u8);

impl DropRate {
    /// A drop rate of `percent` percent; `None` unless `0..=100`.
    pub const fn new(percent: u32) -> Option<DropRate> {
        if percent <= 100 {
            // percent <= 100, so this does not truncate.
            Some(DropRate(percent as u8))
        } else {
            None
        }
    }

    /// The rate in percent (0..=100).
    pub const fn percent(self) -> u8 {
        self.0
    }

    /// Whether to drop a frame, given a uniformly random `random`
    /// (e.g. `get_random_u32()`): drops iff `random % 100 < percent`.
    ///
    /// A rate of 0 never drops and 100 always drops. Since 2^32 is not a
    /// multiple of 100, residues 0..=95 are very slightly more likely than
    /// 96..=99 (by about 2.3e-8 relative); that bias is irrelevant for
    /// simulating frame loss.
    pub const fn should_drop(self, random: u32) -> bool {
        random % 100 < self.0 as u32
    }
}

/// Capacity of a [`FrameDump`]; the longest dump (a 64-byte CAN FD
/// frame) is 225 bytes.
const DUMP_CAP: usize = 232;

/// A text rendering of a frame in a fixed buffer:
///
/// - data frames: `STD 123 [2] DE AD`, `EXT 1ABCDEF0 [0]`
/// - remote frames: `STD 7FF [8] remote`
/// - error frames: `ERR 20000004` (the whole `can_id`)
///
/// - CAN FD frames: `FD STD 123 [12] BRS ESI 01 02 ...` (the payload
///   length, then the flags that are set)
///
/// Identifiers are uppercase hex, 3 digits for standard and 8 for extended
/// frames; the data length code is clamped to 8, an FD length to 64.
pub struct FrameDump {
    buf: [u8; DUMP_CAP],
    len: usize,
}

impl FrameDump {
    /// Renders `frame`.
    pub fn new(frame: &CanFrame) -> FrameDump {
        let mut w = Cursor {
            buf: [0; DUMP_CAP],
            len: 0,
        };
        // The longest dump fits the buffer, so the writes cannot fail; were
        // one to fail, the dump would merely be cut short.
        let _ = render(&mut w, frame);
        FrameDump {
            buf: w.buf,
            len: w.len,
        }
    }

    /// Renders a frame of either flavour.
    pub fn new_any(frame: &AnyFrame) -> FrameDump {
        let fd = match frame {
            AnyFrame::Classic(f) => return FrameDump::new(f),
            AnyFrame::Fd(f) => f,
        };
        let mut w = Cursor {
            buf: [0; DUMP_CAP],
            len: 0,
        };
        // As in `new`: the longest dump fits.
        let _ = render_fd(&mut w, fd);
        FrameDump {
            buf: w.buf,
            len: w.len,
        }
    }

    /// The rendering.
    pub fn as_str(&self) -> &str {
        // Only ASCII is ever written, so this cannot fail.
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
}

fn render(w: &mut Cursor, frame: &CanFrame) -> core::fmt::Result {
    let Some(arb) = frame.arb() else {
        return write!(w, "ERR {:08X}", frame.can_id);
    };
    if arb.is_ext() {
        write!(w, "EXT {:08X}", arb.id())?;
    } else {
        write!(w, "STD {:03X}", arb.id())?;
    }
    write!(w, " [{}]", frame.dlc())?;
    if arb.is_rtr() {
        return w.write_str(" remote");
    }
    for b in frame.payload() {
        write!(w, " {b:02X}")?;
    }
    Ok(())
}

fn render_fd(w: &mut Cursor, frame: &CanFdFrame) -> core::fmt::Result {
    let classic = CanFrame {
        can_id: frame.can_id,
        ..CanFrame::default()
    };
    let Some(arb) = classic.arb() else {
        return write!(w, "FD ERR {:08X}", frame.can_id);
    };
    if arb.is_ext() {
        write!(w, "FD EXT {:08X}", arb.id())?;
    } else {
        write!(w, "FD STD {:03X}", arb.id())?;
    }
    write!(w, " [{}]", frame.payload().len())?;
    if frame.flags & CANFD_BRS != 0 {
        w.write_str(" BRS")?;
    }
    if frame.flags & CANFD_ESI != 0 {
        w.write_str(" ESI")?;
    }
    for b in frame.payload() {
        write!(w, " {b:02X}")?;
    }
    Ok(())
}

/// A `core::fmt::Write` sink into a fixed buffer. A string that does not
/// fit is rejected whole, so the buffer always holds complete strings.
struct Cursor {
    buf: [u8; DUMP_CAP],
    len: usize,
}

impl Write for Cursor {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let end = self.len + s.len();
        let dst = self.buf.get_mut(self.len..end).ok_or(core::fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::arb::Arb;
    use super::*;

    fn dump(f: &CanFrame) -> FrameDump {
        FrameDump::new(f)
    }

    #[test]
    fn drop_rate() {
        assert_eq!(DropRate::new(101), None);
        let zero = DropRate::new(0).unwrap();
        let all = DropRate::new(100).unwrap();
        let half = DropRate::new(50).unwrap();
        assert_eq!(half.percent(), 50);
        for r in [0, 1, 49, 50, 99, 100, u32::MAX] {
            assert!(!zero.should_drop(r));
            assert!(all.should_drop(r));
        }
        assert!(half.should_drop(149));
        assert!(!half.should_drop(150));
    }

    #[test]
    fn dumps() {
        let f = CanFrame::from_arb(Arb::std(0x123, false).unwrap(), 2, &[0xDE, 0xAD]).unwrap();
        assert_eq!(dump(&f).as_str(), "STD 123 [2] DE AD");
        let f = CanFrame::from_arb(Arb::ext(0x1ABC_DEF0, false).unwrap(), 0, &[]).unwrap();
        assert_eq!(dump(&f).as_str(), "EXT 1ABCDEF0 [0]");
        let f = CanFrame::from_arb(Arb::std(0x7FF, true).unwrap(), 8, &[]).unwrap();
        assert_eq!(dump(&f).as_str(), "STD 7FF [8] remote");
        let f = CanFrame::from_arb(Arb::std(0x5, false).unwrap(), 1, &[0x0A]).unwrap();
        assert_eq!(dump(&f).as_str(), "STD 005 [1] 0A");
        let f = CanFrame::from_arb(Arb::ext(0x1FFF_FFFF, false).unwrap(), 8, &[0xFF; 8]).unwrap();
        assert_eq!(
            dump(&f).as_str(),
            "EXT 1FFFFFFF [8] FF FF FF FF FF FF FF FF"
        );
        let f = CanFrame {
            can_id: 0x2000_0004,
            len: 8,
            ..CanFrame::default()
        };
        assert_eq!(dump(&f).as_str(), "ERR 20000004");
    }

    #[test]
    fn fd_dumps() {
        let mut f = CanFdFrame {
            can_id: 0x123,
            len: 3,
            flags: CANFD_BRS,
            ..CanFdFrame::default()
        };
        f.data[..3].copy_from_slice(&[1, 2, 3]);
        let d = FrameDump::new_any(&AnyFrame::Fd(f));
        assert_eq!(d.as_str(), "FD STD 123 [3] BRS 01 02 03");
        // The longest dump fits whole.
        let f = CanFdFrame {
            can_id: 0x9FFF_FFFF,
            len: 64,
            flags: CANFD_BRS | CANFD_ESI,
            data: [0xAB; 64],
            ..CanFdFrame::default()
        };
        let d = FrameDump::new_any(&AnyFrame::Fd(f));
        assert!(d.as_str().starts_with("FD EXT 1FFFFFFF [64] BRS ESI AB AB"));
        assert!(d.as_str().ends_with(" AB"));
        assert_eq!(d.as_str().len(), 28 + 64 * 3);
        let c = CanFrame::from_arb(Arb::std(0x5, false).unwrap(), 1, &[0x0A]).unwrap();
        assert_eq!(
            FrameDump::new_any(&AnyFrame::Classic(c)).as_str(),
            "STD 005 [1] 0A"
        );
    }

    #[test]
    fn cursor_rejects_overflow() {
        let mut w = Cursor {
            buf: [0; DUMP_CAP],
            len: DUMP_CAP - 1,
        };
        assert!(w.write_str("ab").is_err());
        assert_eq!(w.len, DUMP_CAP - 1);
        assert!(w.write_str("a").is_ok());
        assert_eq!(w.len, DUMP_CAP);
    }
}
