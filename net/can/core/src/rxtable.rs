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
//! mask. The table guarantees that a registration is reported **at most
//! once per frame**, however many of its filters match, so the receive path
//! needs no per-socket de-duplication state.
//!
//! Layout, chosen so that the per-frame cost does not grow with the number
//! of receivers that want other identifiers:
//!
//! * `exact`: filters that accept exactly one `can_id` (mainline's "single
//!   id" filters, the thesis' all-bits-must-match filters) live in an open
//!   hash table keyed by (ifindex, can_id). A frame costs two bucket probes
//!   (its interface and "all interfaces"), whatever the number of
//!   receivers. Used for a registration whose filters are all exact (and
//!   not joined); duplicate keys of one registration are merged.
//! * `masked`: every other registration is one entry whose filters (a
//!   slice of `filters`) are scanned in order. This is mainline's linear
//!   `rx_fil`/`rx_inv`/`rx_all` lists, one entry per socket instead of one
//!   per filter.
//! * `err`: error-frame masks (mainline `CAN_RAW_ERR_FILTER`); error frames
//!   (`CAN_ERR_FLAG`) are checked against these only.
//!
//! The table is built from scratch by the writer (allocation happens in the
//! caller, through [`TableSink`]), then published read-only; the receive
//! path only reads it. Building is `O(n log n)` in the number of filters.

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

/// Hash key of (interface, canonical id).
pub const fn key(ifindex: i32, can_id: u32) -> u64 {
    ((ifindex as u32 as u64) << 32) | can_id as u64
}

/// An exact-id filter of registration `reg`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ExactEntry {
    /// [`key`] of the interface and id.
    pub key: u64,
    /// Registration number.
    pub reg: u32,
}

/// A registration evaluated by scanning its filters.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct MaskedEntry {
    /// Interface, 0 = all.
    pub ifindex: i32,
    /// Registration number.
    pub reg: u32,
    /// Its filters: `filters[first..first + count]`.
    pub first: u32,
    /// Number of filters (at least 1).
    pub count: u32,
    /// Every filter must pass (else: any).
    pub join: bool,
}

/// An error-frame mask of a registration.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ErrEntry {
    /// Interface, 0 = all.
    pub ifindex: i32,
    /// Registration number.
    pub reg: u32,
    /// Error classes wanted (`can_id & mask != 0`).
    pub mask: u32,
}

/// What a registration asks for.
#[derive(Clone, Copy, Debug)]
pub struct RegSpec<'a> {
    /// Interface, 0 = all.
    pub ifindex: i32,
    /// Filters for data and remote frames (none: no such frames).
    pub filters: &'a [Filter],
    /// Deliver only frames that pass every filter.
    pub join: bool,
    /// Error classes wanted (0: no error frames).
    pub err_mask: u32,
}

impl RegSpec<'_> {
    /// Whether the registration goes to the scanned list rather than the
    /// hash table.
    pub fn is_masked(&self) -> bool {
        (self.join && self.filters.len() > 1)
            || self.filters.iter().any(|f| f.exact_key().is_none())
    }

    /// Whether it can receive anything at all.
    pub fn is_empty(&self) -> bool {
        self.filters.is_empty() && self.err_mask == 0
    }
}

/// Where a table being built goes; implemented by the caller, which owns
/// the memory (kernel vectors, or `Vec` in tests).
pub trait TableSink {
    /// Allocation failure.
    type Error;
    /// Adds an exact entry.
    fn exact(&mut self, e: ExactEntry) -> Result<(), Self::Error>;
    /// Adds a masked entry.
    fn masked(&mut self, e: MaskedEntry) -> Result<(), Self::Error>;
    /// Appends a filter to the filter array.
    fn filter(&mut self, f: Filter) -> Result<(), Self::Error>;
    /// Number of filters appended so far.
    fn filters_len(&self) -> usize;
    /// Adds an error entry.
    fn err(&mut self, e: ErrEntry) -> Result<(), Self::Error>;
}

/// Adds registration number `reg` to a table being built. After all
/// registrations, the caller runs [`build_index`] on the exact entries.
pub fn add_registration<S: TableSink>(
    sink: &mut S,
    reg: u32,
    spec: &RegSpec<'_>,
) -> Result<(), S::Error> {
    if spec.err_mask != 0 {
        sink.err(ErrEntry {
            ifindex: spec.ifindex,
            reg,
            mask: spec.err_mask,
        })?;
    }
    if spec.filters.is_empty() {
        return Ok(());
    }
    if spec.is_masked() {
        let first = sink.filters_len() as u32;
        for f in spec.filters {
            sink.filter(*f)?;
        }
        sink.masked(MaskedEntry {
            ifindex: spec.ifindex,
            reg,
            first,
            count: spec.filters.len() as u32,
            join: spec.join && spec.filters.len() > 1,
        })?;
    } else {
        for f in spec.filters {
            if let Some(id) = f.exact_key() {
                sink.exact(ExactEntry {
                    key: key(spec.ifindex, id),
                    reg,
                })?;
            }
        }
    }
    Ok(())
}

/// Number of hash buckets for `n` exact entries: a power of two, at least
/// twice `n` (short chains), at least 16.
pub fn bucket_count(n: usize) -> usize {
    n.saturating_mul(2).max(16).next_power_of_two()
}

/// Bucket of `key` in a table of `nbuckets` (a power of two) buckets.
pub fn bucket_of(key: u64, nbuckets: usize) -> usize {
    // Fibonacci hashing: the top bits of a multiplicative hash spread
    // consecutive ids (the common case) evenly.
    let bits = nbuckets.trailing_zeros();
    if bits == 0 {
        return 0;
    }
    (key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize
}

/// Turns the exact entries into a hash index: sorts them by bucket, merges
/// duplicate (key, reg) pairs and fills `starts` (length `nbuckets + 1`,
/// `nbuckets` from [`bucket_count`]) so that bucket `b` is
/// `entries[starts[b]..starts[b + 1]]`. Returns the number of entries kept
/// (the caller truncates to it).
pub fn build_index(entries: &mut [ExactEntry], starts: &mut [u32]) -> usize {
    let nbuckets = starts.len().saturating_sub(1);
    if nbuckets == 0 {
        return 0;
    }
    entries.sort_unstable_by_key(|e| (bucket_of(e.key, nbuckets), e.key, e.reg));
    // Merge duplicates (adjacent after sorting).
    let mut kept = 0;
    for i in 0..entries.len() {
        if kept == 0 || entries[kept - 1] != entries[i] {
            entries[kept] = entries[i];
            kept += 1;
        }
    }
    let mut e = 0;
    for (b, start) in starts.iter_mut().enumerate() {
        while e < kept && bucket_of(entries[e].key, nbuckets) < b {
            e += 1;
        }
        *start = e as u32;
    }
    kept
}

/// A built table, borrowed from wherever its arrays live.
#[derive(Clone, Copy, Debug)]
pub struct Table<'a> {
    /// Exact entries, indexed by `starts` (see [`build_index`]).
    pub exact: &'a [ExactEntry],
    /// Bucket starts, `nbuckets + 1` long (empty: no exact entries).
    pub starts: &'a [u32],
    /// Scanned registrations.
    pub masked: &'a [MaskedEntry],
    /// Filters of the scanned registrations.
    pub filters: &'a [Filter],
    /// Error masks.
    pub err: &'a [ErrEntry],
}

impl Table<'_> {
    /// Calls `deliver(reg)` once for every registration that wants the
    /// frame `can_id` received on interface `ifindex`.
    pub fn for_each_match(&self, ifindex: i32, can_id: u32, mut deliver: impl FnMut(u32)) {
        let on_if = |i: i32| i == 0 || i == ifindex;
        if can_id & CAN_ERR_FLAG != 0 {
            for e in self.err {
                if on_if(e.ifindex) && can_id & e.mask != 0 {
                    deliver(e.reg);
                }
            }
            return;
        }
        let id = frame_key(can_id);
        let nbuckets = self.starts.len().saturating_sub(1);
        if nbuckets > 0 && !self.exact.is_empty() {
            self.probe(key(ifindex, id), nbuckets, &mut deliver);
            if ifindex != 0 {
                self.probe(key(0, id), nbuckets, &mut deliver);
            }
        }
        for m in self.masked {
            if !on_if(m.ifindex) {
                continue;
            }
            let first = m.first as usize;
            let Some(fs) = self.filters.get(first..first + m.count as usize) else {
                continue;
            };
            let pass = if m.join {
                fs.iter().all(|f| f.matches(id))
            } else {
                fs.iter().any(|f| f.matches(id))
            };
            if pass {
                deliver(m.reg);
            }
        }
    }

    fn probe(&self, k: u64, nbuckets: usize, deliver: &mut impl FnMut(u32)) {
        let b = bucket_of(k, nbuckets);
        let (Some(&s), Some(&e)) = (self.starts.get(b), self.starts.get(b + 1)) else {
            return;
        };
        for x in self.exact.get(s as usize..e as usize).unwrap_or(&[]) {
            if x.key == k {
                deliver(x.reg);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    #[derive(Default)]
    struct VecTable {
        exact: Vec<ExactEntry>,
        starts: Vec<u32>,
        masked: Vec<MaskedEntry>,
        filters: Vec<Filter>,
        err: Vec<ErrEntry>,
    }

    impl TableSink for VecTable {
        type Error = ();
        fn exact(&mut self, e: ExactEntry) -> Result<(), ()> {
            self.exact.push(e);
            Ok(())
        }
        fn masked(&mut self, e: MaskedEntry) -> Result<(), ()> {
            self.masked.push(e);
            Ok(())
        }
        fn filter(&mut self, f: Filter) -> Result<(), ()> {
            self.filters.push(f);
            Ok(())
        }
        fn filters_len(&self) -> usize {
            self.filters.len()
        }
        fn err(&mut self, e: ErrEntry) -> Result<(), ()> {
            self.err.push(e);
            Ok(())
        }
    }

    fn build(specs: &[RegSpec<'_>]) -> VecTable {
        let mut t = VecTable::default();
        for (i, s) in specs.iter().enumerate() {
            add_registration(&mut t, i as u32, s).unwrap();
        }
        t.starts = vec![0; bucket_count(t.exact.len()) + 1];
        let n = build_index(&mut t.exact, &mut t.starts);
        t.exact.truncate(n);
        t
    }

    fn matches(t: &VecTable, ifindex: i32, can_id: u32) -> Vec<u32> {
        let table = Table {
            exact: &t.exact,
            starts: &t.starts,
            masked: &t.masked,
            filters: &t.filters,
            err: &t.err,
        };
        let mut v = Vec::new();
        table.for_each_match(ifindex, can_id, |r| v.push(r));
        v.sort_unstable();
        v
    }

    fn raw(id: u32, mask: u32) -> Filter {
        match Filter::from_can_filter(id, mask) {
            CanFilterKind::Frames(f) => f,
            CanFilterKind::Errors(_) => panic!("error filter"),
        }
    }

    const EXACT_SFF: u32 = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
    const EXACT_EFF: u32 = CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;

    #[test]
    fn mainline_exact_filters_are_hashed() {
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

    #[test]
    fn one_delivery_per_registration() {
        let fs = [
            raw(0x100, EXACT_SFF),
            raw(0x100, EXACT_SFF),
            raw(0x200, EXACT_SFF),
        ];
        let masked = [raw(0x100, 0x700), raw(0, 0)];
        let t = build(&[
            RegSpec {
                ifindex: 0,
                filters: &fs,
                join: false,
                err_mask: 0,
            },
            RegSpec {
                ifindex: 3,
                filters: &masked,
                join: false,
                err_mask: 0,
            },
        ]);
        assert_eq!(t.exact.len(), 2, "duplicate merged");
        assert_eq!(matches(&t, 3, 0x100), vec![0, 1]);
        assert_eq!(matches(&t, 4, 0x100), vec![0]);
        assert_eq!(matches(&t, 4, 0x300), Vec::<u32>::new());
        assert_eq!(matches(&t, 3, 0x300), vec![1]);
    }

    #[test]
    fn join() {
        let fs = [raw(0x100, 0x700), raw(0x001, 0x00F)];
        let t = build(&[RegSpec {
            ifindex: 0,
            filters: &fs,
            join: true,
            err_mask: 0,
        }]);
        assert_eq!(matches(&t, 1, 0x101), vec![0]);
        assert_eq!(matches(&t, 1, 0x102), Vec::<u32>::new());
        assert_eq!(matches(&t, 1, 0x201), Vec::<u32>::new());
    }

    #[test]
    fn errors_only_reach_err_masks() {
        let all = [raw(0, 0)];
        let t = build(&[
            RegSpec {
                ifindex: 0,
                filters: &all,
                join: false,
                err_mask: 0,
            },
            RegSpec {
                ifindex: 0,
                filters: &[],
                join: false,
                err_mask: 0x4,
            },
            RegSpec {
                ifindex: 2,
                filters: &[],
                join: false,
                err_mask: CAN_ERR_MASK,
            },
        ]);
        assert_eq!(matches(&t, 1, CAN_ERR_FLAG | 0x4), vec![1]);
        assert_eq!(matches(&t, 2, CAN_ERR_FLAG | 0x4), vec![1, 2]);
        assert_eq!(matches(&t, 2, CAN_ERR_FLAG | 0x8), vec![2]);
        assert_eq!(matches(&t, 2, 0x4), vec![0]);
    }

    #[test]
    fn empty_table() {
        let t = build(&[]);
        assert_eq!(matches(&t, 1, 0x123), Vec::<u32>::new());
        let t = VecTable::default();
        assert_eq!(matches(&t, 1, 0x123), Vec::<u32>::new());
    }

    #[test]
    fn many_exact_receivers() {
        let filters: Vec<[Filter; 1]> = (0..1000u32).map(|i| [raw(i, EXACT_SFF)]).collect();
        let specs: Vec<RegSpec<'_>> = filters
            .iter()
            .map(|f| RegSpec {
                ifindex: 5,
                filters: f,
                join: false,
                err_mask: 0,
            })
            .collect();
        let t = build(&specs);
        assert!(t.masked.is_empty());
        for i in (0..1000).step_by(37) {
            assert_eq!(matches(&t, 5, i), vec![i]);
            assert_eq!(matches(&t, 6, i), Vec::<u32>::new());
        }
    }
}
