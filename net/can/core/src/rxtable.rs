// SPDX-License-Identifier: GPL-2.0

//! The receive table of `rcan_pf`: which receivers want a frame.
//!
//! One table serves every protocol (thesis 5.3.1; DESIGN decision 5): the
//! thesis' arbitration-field filters of CANPROTO_CAN and mainline's
//! `struct can_filter` of CAN_RAW are both [`Filter`]s, evaluated on the
//! canonical `can_id` of the frame.
//!
//! A *registration* is one receiver (one socket of one protocol): an
//! interface (0 = all), a set of filters, an optional "join" flag (the frame
//! must pass every filter, mainline `CAN_RAW_JOIN_FILTERS`) and an error
//! mask. The table reports a registration **at most once per frame**,
//! however many of its filters match.
//!
//! This file is the pure part of the incremental receive table that
//! `rust/glue/can/rx.rs` keeps under RCU: where each filter goes
//! ([`Filter::place`], [`join_scanned`]) and how it is hashed
//! ([`bucket`]). The layout, chosen so that neither a frame nor a bind
//! costs time in proportion to the receivers that want other identifiers:
//!
//! * hashed: every non-inverted mainline filter and every exact thesis
//!   filter belongs to the *group* `(ifindex, mask)` and is hashed on
//!   `(ifindex, mask, id & mask)`. A frame costs one bucket probe per group
//!   of its interface and of "all interfaces" (exact filters form one group
//!   per format; candump-style `id:mask` filters share a group per mask).
//! * scanned: inverted filters, thesis filters with don't-care bits, and
//!   joined registrations are evaluated one by one, as mainline's linear
//!   lists are.
//! * error masks (mainline `CAN_RAW_ERR_FILTER`) are kept apart; error
//!   frames (`CAN_ERR_FLAG`) are checked against them only.
//!
//! `tests/rxtable_prop.rs` checks, for random registrations and frames,
//! that a lookup through this layout selects exactly the registrations a
//! naive evaluation of every filter selects.

use super::arb::{Arb, CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
use super::filter::ArbFilter;

/// Mainline `CAN_INV_FILTER`: in a `can_filter.can_id`, inverts the filter.
pub const CAN_INV_FILTER: u32 = 0x2000_0000;
/// Mainline `CAN_ERR_MASK`: the error class bits of an error frame's id.
pub const CAN_ERR_MASK: u32 = 0x1FFF_FFFF;

const EFF_RTR: u32 = CAN_EFF_FLAG | CAN_RTR_FLAG;

/// One filter, in the form the receive path evaluates. `repr(C)`: drivers
/// receive arrays of it from `rcan_pf` across module boundaries.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Filter {
    /// Thesis filter over the arbitration field (5.2.4): mask bit 1 =
    /// don't care.
    Arb(ArbFilter),
    /// Mainline `struct can_filter`, normalised as mainline's
    /// `can_rcv_list_find` does: passes when
    /// `((can_id & mask) == id) != inv`.
    Id {
        /// Expected `can_id & mask`.
        id: u32,
        /// Bits that must match (1 = compare).
        mask: u32,
        /// Inverted filter (`CAN_INV_FILTER`).
        inv: bool,
    },
}

/// What a mainline `struct can_filter` asks for.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum CanFilterKind {
    /// Data and remote frames passing this filter.
    Frames(Filter),
    /// Error frames with any of these class bits (`can_mask` had
    /// `CAN_ERR_FLAG` set, as in mainline).
    Errors(u32),
}

impl Filter {
    /// Converts a mainline `struct can_filter {can_id, can_mask}`.
    pub const fn from_can_filter(can_id: u32, can_mask: u32) -> CanFilterKind {
        if can_mask & CAN_ERR_FLAG != 0 {
            return CanFilterKind::Errors(can_mask & CAN_ERR_MASK);
        }
        let inv = can_id & CAN_INV_FILTER != 0;
        let mut mask = can_mask;
        // A filter for standard frames that also checks the EFF bit cannot
        // care about identifier bits above the 11 bits of its format.
        if mask & CAN_EFF_FLAG != 0 && can_id & CAN_EFF_FLAG == 0 {
            mask &= CAN_SFF_MASK | EFF_RTR;
        }
        CanFilterKind::Frames(Filter::Id {
            id: can_id & mask,
            mask,
            inv,
        })
    }

    /// Whether a data or remote frame with canonical id `can_id` (see
    /// [`frame_key`]) passes.
    pub const fn matches(&self, can_id: u32) -> bool {
        match *self {
            Filter::Arb(f) => match Arb::from_can_id(can_id) {
                Some(arb) => f.matches(arb),
                None => false,
            },
            Filter::Id { id, mask, inv } => ((can_id & mask) == id) != inv,
        }
    }

    /// The one `can_id` (as [`frame_key`] gives it) this filter accepts,
    /// if it accepts exactly one.
    pub const fn exact_key(&self) -> Option<u32> {
        match *self {
            Filter::Arb(f) => {
                if !f.is_exact() {
                    return None;
                }
                match Arb::from_raw(f.arb()) {
                    Ok(arb) => Some(arb.to_can_id()),
                    // IDE clear with extension bits set: matches nothing,
                    // leave it to the (correct, slower) masked path.
                    Err(_) => None,
                }
            }
            Filter::Id { id, mask, inv } => {
                // Every flag and every identifier bit of the id's format
                // must be compared.
                let full = if id & CAN_EFF_FLAG != 0 {
                    CAN_EFF_MASK | EFF_RTR
                } else {
                    CAN_SFF_MASK | EFF_RTR
                };
                if !inv && mask == full {
                    Some(id)
                } else {
                    None
                }
            }
        }
    }
}

/// The canonical id the table works on: for data and remote frames the
/// flags and the identifier bits of the frame's format (bits above an
/// 11-bit identifier, which well-behaved drivers never set, are ignored).
/// Error frames are returned unchanged.
pub const fn frame_key(can_id: u32) -> u32 {
    if can_id & CAN_ERR_FLAG != 0 {
        can_id
    } else if can_id & CAN_EFF_FLAG != 0 {
        can_id & (CAN_EFF_MASK | EFF_RTR)
    } else {
        can_id & (CAN_SFF_MASK | CAN_RTR_FLAG)
    }
}

/// Where the incremental receive table keeps a filter.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Place {
    /// The filter passes exactly the frames whose canonical id (see
    /// [`frame_key`]) satisfies `key & mask == value`: it is kept in the
    /// hash of its group `(ifindex, mask)`, under `value`. A frame costs
    /// one probe per group, whatever the number of filters in it.
    Hashed {
        /// The bits compared.
        mask: u32,
        /// Their expected value (a value with bits outside `mask` matches
        /// nothing, as the filter it stands for).
        value: u32,
    },
    /// Anything else (inverted mainline filters, thesis filters with
    /// don't-care bits): evaluated one by one on every frame, as
    /// mainline's `rx_inv` list is.
    Scanned,
}

/// The identifier bits and flags a full ("exact") filter of a format
/// compares.
const fn full_mask(can_id: u32) -> u32 {
    if can_id & CAN_EFF_FLAG != 0 {
        CAN_EFF_MASK | EFF_RTR
    } else {
        CAN_SFF_MASK | EFF_RTR
    }
}

impl Filter {
    /// Where the receive table keeps this filter. For a `Hashed` filter,
    /// `matches(key) == (frame_key(key) & mask == value)` for every data
    /// or remote frame `key`.
    pub const fn place(&self) -> Place {
        match *self {
            // `matches` is `(key & mask == id) != inv`: without `inv`,
            // exactly the hashed test.
            Filter::Id { id, mask, inv } => {
                if inv {
                    Place::Scanned
                } else {
                    Place::Hashed { mask, value: id }
                }
            }
            Filter::Arb(_) => match self.exact_key() {
                Some(k) => Place::Hashed {
                    mask: full_mask(k),
                    value: k,
                },
                None => Place::Scanned,
            },
        }
    }
}

/// log2 of the number of hash buckets of the receive table.
pub const BUCKET_BITS: u32 = 12;

/// The bucket (`0..1 << BUCKET_BITS`) of `value` in group
/// `(ifindex, mask)`.
pub const fn bucket(ifindex: i32, mask: u32, value: u32) -> usize {
    // Fibonacci hashing: the top bits of a multiplicative hash spread
    // consecutive ids (the common case) evenly; the group is mixed in so
    // that groups do not pile up in the same buckets.
    let k = ((ifindex as u32 as u64) << 32 | value as u64)
        ^ (mask as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    (k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - BUCKET_BITS)) as usize
}

/// How a registration's filters are laid out in the receive table.
///
/// A joined registration with more than one filter is one scanned entry
/// evaluated as a whole (every filter must pass). Otherwise every
/// `Hashed` filter is a hash entry of its own and the `Scanned` ones
/// together form one scanned entry (any of them passes); the table reports
/// the registration once per frame, however many entries match.
pub const fn join_scanned(filters: &[Filter], join: bool) -> bool {
    join && filters.len() > 1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raw(id: u32, mask: u32) -> Filter {
        match Filter::from_can_filter(id, mask) {
            CanFilterKind::Frames(f) => f,
            CanFilterKind::Errors(_) => panic!("error filter"),
        }
    }

    const EXACT_SFF: u32 = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
    const EXACT_EFF: u32 = CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;

    #[test]
    fn mainline_exact_filters() {
        assert_eq!(raw(0x123, EXACT_SFF).exact_key(), Some(0x123));
        assert_eq!(
            raw(0x1234_5678 | CAN_EFF_FLAG, EXACT_EFF).exact_key(),
            Some(0x1234_5678 | CAN_EFF_FLAG)
        );
        // candump's "123:7FF" does not check EFF/RTR: not exact.
        assert_eq!(raw(0x123, 0x7FF).exact_key(), None);
        // Inverted filters are never exact.
        assert_eq!(raw(0x123 | CAN_INV_FILTER, EXACT_SFF).exact_key(), None);
        // Extra id bits in the mask of an SFF filter are normalised away.
        assert_eq!(raw(0x123, 0xDFFF_FFFF).exact_key(), Some(0x123));
    }

    #[test]
    fn placement() {
        assert_eq!(
            raw(0x123, 0x7FF).place(),
            Place::Hashed {
                mask: 0x7FF,
                value: 0x123
            }
        );
        assert_eq!(raw(0, 0).place(), Place::Hashed { mask: 0, value: 0 });
        assert_eq!(raw(0x123 | CAN_INV_FILTER, 0x7FF).place(), Place::Scanned);
        let a = Arb::std(0x123, false).unwrap();
        assert_eq!(
            Filter::Arb(ArbFilter::exact(a)).place(),
            Place::Hashed {
                mask: EXACT_SFF,
                value: 0x123
            }
        );
        assert_eq!(Filter::Arb(ArbFilter::ALL).place(), Place::Scanned);
        assert!(join_scanned(&[raw(1, 1), raw(2, 2)], true));
        assert!(!join_scanned(&[raw(1, 1)], true));
        assert!(!join_scanned(&[raw(1, 1), raw(2, 2)], false));
    }

    #[test]
    fn buckets_in_range_and_spread() {
        let mut seen = [0u32; 1 << BUCKET_BITS];
        for id in 0..0x800u32 {
            let b = bucket(3, EXACT_SFF, id);
            seen[b] += 1;
        }
        assert!(seen.iter().all(|&n| n <= 2), "consecutive ids spread");
        assert_ne!(bucket(1, 0x7FF, 5), bucket(2, 0x7FF, 5));
    }

    #[test]
    fn error_filter() {
        assert_eq!(
            Filter::from_can_filter(0, CAN_ERR_FLAG | 0x4),
            CanFilterKind::Errors(4)
        );
    }

    #[test]
    fn mainline_semantics() {
        let all = raw(0, 0);
        assert!(
            all.matches(0x123) && all.matches(CAN_EFF_FLAG | 5) && all.matches(CAN_RTR_FLAG | 1)
        );
        let f = raw(0x123, 0x7FF);
        assert!(f.matches(0x123));
        assert!(f.matches(0x123 | CAN_RTR_FLAG));
        assert!(f.matches(0x123 | CAN_EFF_FLAG));
        assert!(!f.matches(0x124));
        let inv = raw(0x123 | CAN_INV_FILTER, 0x7FF);
        assert!(!inv.matches(0x123));
        assert!(inv.matches(0x124));
    }

    #[test]
    fn thesis_filters() {
        let a = Arb::std(0x123, false).unwrap();
        let f = Filter::Arb(ArbFilter::exact(a));
        assert_eq!(f.exact_key(), Some(0x123));
        assert!(f.matches(0x123));
        assert!(!f.matches(0x123 | CAN_RTR_FLAG));
        let any = Filter::Arb(ArbFilter::ALL);
        assert_eq!(any.exact_key(), None);
        assert!(any.matches(CAN_EFF_FLAG | 7));
        // Thesis filters never see error frames.
        assert!(!any.matches(CAN_ERR_FLAG | 4));
    }
}
