// SPDX-License-Identifier: GPL-2.0
//! Arbitration field filters of the CAN socket API (thesis 5.2.4): a frame
//! passes a filter when every bit whose mask bit is 0 ("must match") equals
//! the filter's pattern; mask bits that are 1 are "don't care".
//! Bit 0 of the arbitration field (figure 5-5) is always "don't care".

use super::arb::{Arb, ArbError, ARB_UNUSED};

/// A pattern and a mask over the arbitration field of figure 5-5.
///
/// Invariants: bit 0 of `arb` is clear and bit 0 of `mask` is set.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ArbFilter {
    arb: u32,
    mask: u32,
}

impl ArbFilter {
    /// A filter that accepts every frame.
    pub const ALL: ArbFilter = ArbFilter {
        arb: 0,
        mask: u32::MAX,
    };

    /// A filter with pattern `arb` and mask `mask` (1 bits = don't care).
    ///
    /// Rejects a pattern with bit 0 set. A pattern with IDE clear but
    /// extension bits set is accepted: with IDE or the extension bits
    /// "don't care" such a pattern is meaningful. Bit 0 of the stored mask
    /// is always set.
    pub const fn new(arb: u32, mask: u32) -> Result<ArbFilter, ArbError> {
        if arb & ARB_UNUSED != 0 {
            return Err(ArbError::UnusedBitSet);
        }
        Ok(ArbFilter {
            arb,
            mask: mask | ARB_UNUSED,
        })
    }

    /// A filter that accepts exactly the frames with arbitration field `arb`.
    pub const fn exact(arb: Arb) -> ArbFilter {
        ArbFilter {
            arb: arb.raw(),
            mask: ARB_UNUSED,
        }
    }

    /// The pattern.
    pub const fn arb(self) -> u32 {
        self.arb
    }

    /// The mask (1 bits = don't care; bit 0 always set).
    pub const fn mask(self) -> u32 {
        self.mask
    }

    /// Whether `frame` passes the filter.
    pub const fn matches(self, frame: Arb) -> bool {
        ((frame.raw() ^ self.arb) & !self.mask) == 0
    }

    /// Whether all of bits 31..1 must match, i.e. the filter accepts one
    /// arbitration field only.
    pub const fn is_exact(self) -> bool {
        self.mask == ARB_UNUSED
    }
}

/// A receiver registration: a filter bound to one interface or to all.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Receiver {
    /// Interface index; 0 means every interface.
    pub ifindex: i32,
    /// Arbitration field filter.
    pub filter: ArbFilter,
}

impl Receiver {
    /// Whether a frame with field `frame` received on `ifindex` is for
    /// this receiver.
    pub const fn matches(&self, ifindex: i32, frame: Arb) -> bool {
        (self.ifindex == 0 || self.ifindex == ifindex) && self.filter.matches(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::super::arb::{CAN_IDE, CAN_RTR};
    use super::*;

    #[test]
    fn basics() {
        assert_eq!(ArbFilter::new(1, 0), Err(ArbError::UnusedBitSet));
        let f = ArbFilter::new(0x8, 0).unwrap();
        assert_eq!(f.mask(), 1);
        assert!(f.is_exact());
        assert!(!ArbFilter::ALL.is_exact());
        let a = Arb::std(0x123, false).unwrap();
        assert_eq!(ArbFilter::exact(a), ArbFilter::new(a.raw(), 0).unwrap());
        assert!(ArbFilter::exact(a).matches(a));
        assert!(!ArbFilter::exact(a).matches(Arb::std(0x123, true).unwrap()));
    }

    #[test]
    fn ide_dont_care() {
        let f = ArbFilter::new(
            Arb::std(0x123, false).unwrap().raw(),
            CAN_IDE | 1 | 0x001F_FFF8,
        )
        .unwrap();
        assert!(f.matches(Arb::std(0x123, false).unwrap()));
        assert!(f.matches(Arb::ext(0x123 << 18, false).unwrap()));
        assert!(f.matches(Arb::ext((0x123 << 18) | 0x3FFFF, false).unwrap()));
        assert!(!f.matches(Arb::std(0x123, true).unwrap()));
        assert!(!f.matches(Arb::std(0x124, false).unwrap()));
        let r = ArbFilter::new(Arb::std(0x123, false).unwrap().raw(), CAN_RTR).unwrap();
        assert!(r.matches(Arb::std(0x123, true).unwrap()));
    }

    #[test]
    fn receiver_ifindex() {
        let r = Receiver {
            ifindex: 0,
            filter: ArbFilter::ALL,
        };
        let a = Arb::ext(5, false).unwrap();
        assert!(r.matches(3, a));
        let r = Receiver { ifindex: 2, ..r };
        assert!(r.matches(2, a));
        assert!(!r.matches(3, a));
    }
}
