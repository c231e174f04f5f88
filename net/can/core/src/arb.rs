// SPDX-License-Identifier: GPL-2.0
//! The 32-bit software arbitration field of the CAN socket API
//! (thesis 5.2.2, figure 5-5) and its conversion to and from mainline
//! SocketCAN's canonical `can_id`.
//!
//! Layout of the field, host byte order:
//!
//! ```text
//!  bit 31..21  11-bit (base) identifier
//!  bit 20..3   18-bit extended identifier (zero in standard frames)
//!  bit 2       IDE (CAN_IDE, 1 = extended format frame)
//!  bit 1       RTR (CAN_RTR, 1 = remote frame)
//!  bit 0       unused, must be 0 (ARB_UNUSED)
//! ```
//!
//! Bits 31..3 of an extended frame hold its 29-bit identifier as a whole.
//! Because the field follows the order in which the bits appear on the bus,
//! a numerically smaller field wins arbitration: dominant (0) bits are
//! smaller, a standard frame beats an extended frame with the same base
//! identifier and a data frame beats the remote frame of the same identifier.

/// IDE bit: 1 = extended format frame.
pub const CAN_IDE: u32 = 0x0000_0004;
/// RTR bit: 1 = remote frame.
pub const CAN_RTR: u32 = 0x0000_0002;
/// Unused bit 0; must be 0 in an arbitration field.
pub const ARB_UNUSED: u32 = 0x0000_0001;

/// Mainline `can_id`: extended frame format flag.
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// Mainline `can_id`: remote transmission request flag.
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// Mainline `can_id`: error message frame flag.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Mainline `can_id`: standard frame format identifier mask (11 bits).
pub const CAN_SFF_MASK: u32 = 0x0000_07FF;
/// Mainline `can_id`: extended frame format identifier mask (29 bits).
pub const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;

/// Maximum data length code of a CAN 2.0 frame.
pub const MAX_DLC: usize = 8;

/// Linux `EINVAL`, the errno of every validation error in this crate.
pub const EINVAL: i32 = 22;

/// Bits 20..3: the 18 extension bits of the identifier.
const EXT_BITS: u32 = 0x001F_FFF8;
/// Shift of the 11-bit identifier of a standard frame.
const STD_SHIFT: u32 = 21;
/// Shift of the 29-bit identifier of an extended frame.
const EXT_SHIFT: u32 = 3;

/// Why a value is not a valid arbitration field.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum ArbError {
    /// Bit 0 (`ARB_UNUSED`) is set.
    UnusedBitSet,
    /// A standard frame (IDE clear) has some of bits 20..3 set.
    ExtBitsInStandard,
    /// The identifier does not fit its format (11 or 29 bits).
    IdOutOfRange,
}

impl ArbError {
    /// Positive Linux errno for this error (always `EINVAL`).
    pub const fn errno(self) -> i32 {
        EINVAL
    }
}

/// A valid arbitration field (thesis figure 5-5).
///
/// Invariants: bit 0 is clear, and if IDE is clear bits 20..3 are clear.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Hash)]
pub struct Arb(u32);

impl Arb {
    /// Validates a raw arbitration field.
    pub const fn from_raw(raw: u32) -> Result<Arb, ArbError> {
        if raw & ARB_UNUSED != 0 {
            Err(ArbError::UnusedBitSet)
        } else if raw & CAN_IDE == 0 && raw & EXT_BITS != 0 {
            Err(ArbError::ExtBitsInStandard)
        } else {
            Ok(Arb(raw))
        }
    }

    /// The raw 32-bit field.
    pub const fn raw(self) -> u32 {
        self.0
    }

    /// A standard format frame with 11-bit identifier `id`.
    pub const fn std(id: u32, rtr: bool) -> Result<Arb, ArbError> {
        if id > CAN_SFF_MASK {
            return Err(ArbError::IdOutOfRange);
        }
        Ok(Arb((id << STD_SHIFT) | rtr_bit(rtr)))
    }

    /// An extended format frame with 29-bit identifier `id`.
    pub const fn ext(id: u32, rtr: bool) -> Result<Arb, ArbError> {
        if id > CAN_EFF_MASK {
            return Err(ArbError::IdOutOfRange);
        }
        Ok(Arb((id << EXT_SHIFT) | CAN_IDE | rtr_bit(rtr)))
    }

    /// Whether this is an extended format frame (IDE set).
    pub const fn is_ext(self) -> bool {
        self.0 & CAN_IDE != 0
    }

    /// Whether this is a remote frame (RTR set).
    pub const fn is_rtr(self) -> bool {
        self.0 & CAN_RTR != 0
    }

    /// The identifier: 11 bits for standard, 29 bits for extended frames.
    pub const fn id(self) -> u32 {
        if self.is_ext() {
            self.0 >> EXT_SHIFT
        } else {
            self.0 >> STD_SHIFT
        }
    }

    /// The mainline canonical `can_id` (with `CAN_EFF_FLAG`/`CAN_RTR_FLAG`).
    pub const fn to_can_id(self) -> u32 {
        let rtr = if self.is_rtr() { CAN_RTR_FLAG } else { 0 };
        if self.is_ext() {
            self.id() | CAN_EFF_FLAG | rtr
        } else {
            self.id() | rtr
        }
    }

    /// Converts a mainline `can_id`. `None` for error frames
    /// (`CAN_ERR_FLAG`); identifier bits beyond the width of the frame's
    /// format are masked off (`CAN_SFF_MASK` / `CAN_EFF_MASK`).
    pub const fn from_can_id(can_id: u32) -> Option<Arb> {
        if can_id & CAN_ERR_FLAG != 0 {
            return None;
        }
        let rtr = rtr_bit(can_id & CAN_RTR_FLAG != 0);
        if can_id & CAN_EFF_FLAG != 0 {
            Some(Arb(((can_id & CAN_EFF_MASK) << EXT_SHIFT) | CAN_IDE | rtr))
        } else {
            Some(Arb(((can_id & CAN_SFF_MASK) << STD_SHIFT) | rtr))
        }
    }
}

/// The RTR bit of the arbitration field for `rtr`.
const fn rtr_bit(rtr: bool) -> u32 {
    if rtr {
        CAN_RTR
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout() {
        assert_eq!(Arb::std(0x123, false).unwrap().raw(), 0x123 << 21);
        assert_eq!(Arb::std(0x7FF, true).unwrap().raw(), 0xFFE0_0002);
        assert_eq!(Arb::ext(0x1ABC_DEF0, false).unwrap().raw(), 0xD5E6_F784);
        assert_eq!(Arb::ext(0x1FFF_FFFF, true).unwrap().raw(), 0xFFFF_FFFE);
        assert_eq!(Arb::std(0x800, false), Err(ArbError::IdOutOfRange));
        assert_eq!(Arb::ext(0x2000_0000, false), Err(ArbError::IdOutOfRange));
    }

    #[test]
    fn from_raw_errors() {
        assert_eq!(Arb::from_raw(1), Err(ArbError::UnusedBitSet));
        assert_eq!(Arb::from_raw(0x8), Err(ArbError::ExtBitsInStandard));
        assert_eq!(Arb::from_raw(0x8 | CAN_IDE).unwrap().id(), 1);
        assert_eq!(ArbError::UnusedBitSet.errno(), 22);
    }

    #[test]
    fn can_id() {
        let a = Arb::ext(0x1ABC_DEF0, true).unwrap();
        assert_eq!(a.to_can_id(), 0xDABC_DEF0);
        assert_eq!(Arb::from_can_id(0xDABC_DEF0), Some(a));
        assert_eq!(Arb::from_can_id(0x2000_0004), None);
        assert_eq!(
            Arb::from_can_id(0x4000_0123).unwrap().raw(),
            (0x123 << 21) | CAN_RTR
        );
        // Bits above the 11-bit identifier of a standard frame are masked.
        assert_eq!(Arb::from_can_id(0x1FFF_F923).unwrap().id(), 0x123);
    }

    #[test]
    fn priority_between_formats() {
        let s = Arb::std(0x123, false).unwrap();
        let sr = Arb::std(0x123, true).unwrap();
        let e = Arb::ext(0x123 << 18, false).unwrap();
        assert!(s.raw() < sr.raw());
        assert!(s.raw() < e.raw());
    }
}
