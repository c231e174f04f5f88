// SPDX-License-Identifier: GPL-2.0
//! Property tests of the receive table (`rcan_core::rxtable`): for any set
//! of registrations and any frame, the hashed/scanned table reports exactly
//! the registrations a naive evaluation of every filter selects, each once;
//! and mainline filters behave as mainline's `can_rcv_filter` (reference
//! model written from its documented semantics).

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::filter::ArbFilter;
use rcan_core::rxtable::*;

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

#[derive(Clone, Debug)]
struct Reg {
    ifindex: i32,
    filters: Vec<Filter>,
    join: bool,
    err_mask: u32,
}

/// Ids concentrated on a few values so that filters and frames collide.
fn can_id() -> impl Strategy<Value = u32> {
    let id = prop_oneof![
        0u32..4,
        0x120u32..0x124,
        Just(CAN_SFF_MASK),
        0u32..=CAN_EFF_MASK
    ];
    (id, any::<bool>(), any::<bool>()).prop_map(|(id, eff, rtr)| {
        let mut c = if eff {
            id | CAN_EFF_FLAG
        } else {
            id & CAN_SFF_MASK
        };
        if rtr {
            c |= CAN_RTR_FLAG;
        }
        c
    })
}

fn frame_id() -> impl Strategy<Value = u32> {
    prop_oneof![
        8 => can_id(),
        1 => (1u32..0x200).prop_map(|c| c | CAN_ERR_FLAG),
    ]
}

const MASKS: [u32; 6] = [
    0,
    CAN_SFF_MASK,
    CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
    CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
    0x7F0,
    CAN_EFF_FLAG,
];

fn filter() -> impl Strategy<Value = Filter> {
    let mainline =
        (can_id(), prop::sample::select(&MASKS[..]), any::<bool>()).prop_map(|(id, mask, inv)| {
            let id = if inv { id | CAN_INV_FILTER } else { id };
            match Filter::from_can_filter(id, mask) {
                CanFilterKind::Frames(f) => f,
                CanFilterKind::Errors(_) => unreachable!(),
            }
        });
    let thesis = (
        can_id(),
        prop::sample::select(&[1u32, 3, 7, 0x00FF_FFFF, u32::MAX][..]),
    )
        .prop_map(|(id, mask)| {
            let arb = Arb::from_can_id(id).unwrap().raw();
            Filter::Arb(ArbFilter::new(arb, mask).unwrap())
        });
    prop_oneof![mainline, thesis]
}

fn reg() -> impl Strategy<Value = Reg> {
    (
        0i32..3,
        prop::collection::vec(filter(), 0..4),
        any::<bool>(),
        prop_oneof![3 => Just(0u32), 1 => 1u32..0x200],
    )
        .prop_map(|(ifindex, filters, join, err_mask)| Reg {
            ifindex,
            filters,
            join,
            err_mask,
        })
}

fn build(regs: &[Reg]) -> VecTable {
    let mut t = VecTable::default();
    for (i, r) in regs.iter().enumerate() {
        let spec = RegSpec {
            ifindex: r.ifindex,
            filters: &r.filters,
            join: r.join,
            err_mask: r.err_mask,
        };
        add_registration(&mut t, i as u32, &spec).unwrap();
    }
    t.starts = vec![0; bucket_count(t.exact.len()) + 1];
    let n = build_index(&mut t.exact, &mut t.starts);
    t.exact.truncate(n);
    t
}

/// The naive answer: evaluate every filter of every registration.
fn naive(regs: &[Reg], ifindex: i32, can_id: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for (i, r) in regs.iter().enumerate() {
        if r.ifindex != 0 && r.ifindex != ifindex {
            continue;
        }
        let want = if can_id & CAN_ERR_FLAG != 0 {
            can_id & r.err_mask != 0
        } else if r.filters.is_empty() {
            false
        } else if r.join {
            r.filters.iter().all(|f| f.matches(can_id))
        } else {
            r.filters.iter().any(|f| f.matches(can_id))
        };
        if want {
            out.push(i as u32);
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn table_equals_naive(regs in prop::collection::vec(reg(), 0..12), ifindex in 1i32..3, id in frame_id()) {
        let t = build(&regs);
        let table = Table { exact: &t.exact, starts: &t.starts, masked: &t.masked, filters: &t.filters, err: &t.err };
        let mut got = Vec::new();
        table.for_each_match(ifindex, id, |r| got.push(r));
        got.sort_unstable();
        let before = got.len();
        got.dedup();
        prop_assert_eq!(before, got.len(), "a registration was reported twice");
        prop_assert_eq!(got, naive(&regs, ifindex, id));
    }

    /// Mainline's `can_filter` semantics, written from raw(7): a frame
    /// passes when `(frame_id & mask) == (filter_id & mask)`, inverted by
    /// CAN_INV_FILTER, where a mask that checks CAN_EFF_FLAG for an SFF
    /// filter id ignores identifier bits 11..28.
    #[test]
    fn mainline_filter_reference(fid in can_id(), mask in any::<u32>(), inv in any::<bool>(), frame in can_id()) {
        let mask = mask & !CAN_ERR_FLAG;
        let id = if inv { fid | CAN_INV_FILTER } else { fid };
        let CanFilterKind::Frames(f) = Filter::from_can_filter(id, mask) else { unreachable!() };
        let mut m = mask;
        if m & CAN_EFF_FLAG != 0 && fid & CAN_EFF_FLAG == 0 {
            m &= CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        }
        let want = ((frame & m) == (fid & m)) != inv;
        prop_assert_eq!(f.matches(frame), want);
        if let Some(k) = f.exact_key() {
            // An exact filter accepts its key and nothing else.
            prop_assert!(f.matches(k));
            prop_assert_eq!(f.matches(frame), frame_key(frame) == k);
        }
    }

    /// Every bucket index is in range and the index covers every entry.
    #[test]
    fn index_partitions_entries(keys in prop::collection::vec((0i32..4, any::<u32>(), 0u32..5), 0..300)) {
        let mut entries: Vec<ExactEntry> = keys.iter().map(|&(i, id, reg)| ExactEntry { key: key(i, id), reg }).collect();
        let mut starts = vec![0u32; bucket_count(entries.len()) + 1];
        let n = build_index(&mut entries, &mut starts);
        entries.truncate(n);
        prop_assert_eq!(*starts.last().unwrap() as usize, n);
        let nb = starts.len() - 1;
        for b in 0..nb {
            prop_assert!(starts[b] <= starts[b + 1]);
            for e in &entries[starts[b] as usize..starts[b + 1] as usize] {
                prop_assert_eq!(bucket_of(e.key, nb), b);
            }
        }
        let mut uniq: Vec<_> = keys.iter().map(|&(i, id, reg)| (key(i, id), reg)).collect();
        uniq.sort_unstable();
        uniq.dedup();
        prop_assert_eq!(uniq.len(), n);
    }
}
