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

// ---------------------------------------------------------------------
// What a set of receive filters wants, as hardware acceptance filters
// see it: the input of the SJA1000's and the 82527's filter derivation
// (`sja1000::hw_filter`, `i82527::masks_for`) and of the glue's
// `can::proto::wanted`.
// ---------------------------------------------------------------------

/// A set of wanted frames of one format as a ternary pattern over `bits`
/// bits: a frame is in it when `(frame_bits ^ value) & care == 0`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Cube {
    /// Pattern (bits outside `care` are zero).
    pub value: u32,
    /// Bits that must match.
    pub care: u32,
}

impl Cube {
    /// The cube of `value` over the bits in `care`.
    pub fn new(value: u32, care: u32) -> Cube {
        Cube {
            value: value & care,
            care,
        }
    }

    /// The smallest cube containing both.
    pub fn merge(self, o: Cube) -> Cube {
        let care = self.care & o.care & !(self.value ^ o.value);
        Cube::new(self.value, care)
    }
}

/// What one filter wants, per frame format: standard frames as a cube over
/// 12 bits (identifier bits 11..1, RTR bit 0) and extended frames over 30
/// bits (identifier bits 29..1, RTR bit 0). `None`: no frame of that
/// format.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Wanted {
    /// Standard frames.
    pub sff: Option<Cube>,
    /// Extended frames.
    pub eff: Option<Cube>,
}

impl Wanted {
    /// Every frame.
    pub const ALL: Wanted = Wanted {
        sff: Some(Cube { value: 0, care: 0 }),
        eff: Some(Cube { value: 0, care: 0 }),
    };

    /// The frames a receive filter accepts (a superset where a filter is
    /// not expressible as a cube: inverted filters want "everything").
    pub fn of(f: &super::rxtable::Filter) -> Wanted {
        use super::arb::{
            CAN_EFF_FLAG, CAN_EFF_MASK, CAN_IDE, CAN_RTR, CAN_RTR_FLAG, CAN_SFF_MASK,
        };
        use super::rxtable::Filter;
        match *f {
            Filter::Id { inv: true, .. } => Wanted::ALL,
            Filter::Id {
                id,
                mask,
                inv: false,
            } => {
                let rtr_care = u32::from(mask & CAN_RTR_FLAG != 0);
                let rtr_val = u32::from(id & CAN_RTR_FLAG != 0);
                let eff_care = mask & CAN_EFF_FLAG != 0;
                let is_eff = id & CAN_EFF_FLAG != 0;
                // Standard frames have zero identifier bits 11..28.
                let high = CAN_EFF_MASK & !CAN_SFF_MASK;
                let sff_possible = (!eff_care || !is_eff) && id & mask & high == 0;
                let sff = sff_possible.then(|| {
                    Cube::new(
                        ((id & CAN_SFF_MASK) << 1) | rtr_val,
                        ((mask & CAN_SFF_MASK) << 1) | rtr_care,
                    )
                });
                let eff = (!eff_care || is_eff).then(|| {
                    Cube::new(
                        ((id & CAN_EFF_MASK) << 1) | rtr_val,
                        ((mask & CAN_EFF_MASK) << 1) | rtr_care,
                    )
                });
                Wanted { sff, eff }
            }
            Filter::Arb(a) => {
                // Arbitration field: care = !mask (thesis: 1 = don't care).
                let (pat, care) = (a.arb(), !a.mask());
                let rtr_care = u32::from(care & CAN_RTR != 0);
                let rtr_val = u32::from(pat & CAN_RTR != 0);
                let ide_care = care & CAN_IDE != 0;
                let is_eff = pat & CAN_IDE != 0;
                // Standard frames have zero extension bits (20..3).
                let ext = 0x001F_FFF8;
                let sff_possible = (!ide_care || !is_eff) && pat & care & ext == 0;
                let sff = sff_possible.then(|| {
                    Cube::new(((pat >> 21) << 1) | rtr_val, ((care >> 21) << 1) | rtr_care)
                });
                let eff = (!ide_care || is_eff)
                    .then(|| Cube::new(((pat >> 3) << 1) | rtr_val, ((care >> 3) << 1) | rtr_care));
                Wanted { sff, eff }
            }
        }
    }
}
