// SPDX-License-Identifier: GPL-2.0
//! Property tests of the receive table's layout (`rcan_core::rxtable`): for
//! any sequence of registrations set, replaced and removed, a model of the
//! kernel's incremental table (groups, hash buckets, scanned and error
//! entries) reports exactly the registrations a naive evaluation of every
//! filter selects, each once;
//! and mainline filters behave as mainline's `can_rcv_filter` (reference
//! model written from its documented semantics).

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::filter::ArbFilter;
use rcan_core::rxtable::*;
use std::collections::{BTreeMap, HashMap};

/// A host model of the kernel's incremental table (`rust/glue/can/rx.rs`):
/// the same layout (groups, hash buckets, scanned entries, error entries),
/// changed one registration at a time, looked up as the receive path does.
#[derive(Default)]
struct Model {
    /// (ifindex, mask) -> number of hashed filters in the group.
    groups: BTreeMap<(i32, u32), usize>,
    /// bucket -> entries (ifindex, mask, value, registration).
    buckets: HashMap<usize, Vec<(i32, u32, u32, usize)>>,
    /// (ifindex, registration, filters, join)
    scanned: Vec<(i32, usize, Vec<Filter>, bool)>,
    /// (ifindex, registration, mask)
    err: Vec<(i32, usize, u32)>,
}

impl Model {
    fn add(&mut self, n: usize, r: &Reg) {
        if r.err_mask != 0 {
            self.err.push((r.ifindex, n, r.err_mask));
        }
        if join_scanned(&r.filters, r.join) {
            self.scanned.push((r.ifindex, n, r.filters.clone(), true));
            return;
        }
        let mut rest = Vec::new();
        for f in &r.filters {
            match f.place() {
                Place::Hashed { mask, value } => {
                    *self.groups.entry((r.ifindex, mask)).or_default() += 1;
                    self.buckets
                        .entry(bucket(r.ifindex, mask, value))
                        .or_default()
                        .push((r.ifindex, mask, value, n));
                }
                Place::Scanned => rest.push(*f),
            }
        }
        if !rest.is_empty() {
            self.scanned.push((r.ifindex, n, rest, false));
        }
    }

    fn remove(&mut self, n: usize) {
        self.err.retain(|e| e.1 != n);
        self.scanned.retain(|e| e.1 != n);
        for b in self.buckets.values_mut() {
            b.retain(|e| {
                if e.3 != n {
                    return true;
                }
                let c = self.groups.get_mut(&(e.0, e.1)).unwrap();
                *c -= 1;
                false
            });
        }
        self.groups.retain(|_, c| *c > 0);
    }

    fn lookup(&self, ifindex: i32, can_id: u32) -> Vec<usize> {
        let on_if = |i: i32| i == 0 || i == ifindex;
        let mut got = Vec::new();
        if can_id & CAN_ERR_FLAG != 0 {
            for e in &self.err {
                if on_if(e.0) && can_id & e.2 != 0 {
                    got.push(e.1);
                }
            }
        } else {
            let k = frame_key(can_id);
            for &(gi, gm) in self.groups.keys() {
                if !on_if(gi) {
                    continue;
                }
                let v = k & gm;
                for e in self.buckets.get(&bucket(gi, gm, v)).into_iter().flatten() {
                    if e.0 == gi && e.1 == gm && e.2 == v {
                        got.push(e.3);
                    }
                }
            }
            for (i, n, fs, join) in &self.scanned {
                if !on_if(*i) {
                    continue;
                }
                let pass = if *join {
                    fs.iter().all(|f| f.matches(k))
                } else {
                    fs.iter().any(|f| f.matches(k))
                };
                if pass {
                    got.push(*n);
                }
            }
        }
        // The kernel's per-receiver, per-CPU "seen" mark.
        got.sort_unstable();
        got.dedup();
        got
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

/// The naive answer: evaluate every filter of every registration.
fn naive(regs: &[Option<Reg>], ifindex: i32, can_id: u32) -> Vec<usize> {
    let mut out = Vec::new();
    for (i, r) in regs.iter().enumerate() {
        let Some(r) = r else { continue };
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
            out.push(i);
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Registrations set, replaced and removed one at a time (as bind,
    /// setsockopt and close do): after every step, every frame selects
    /// exactly the registrations a naive evaluation selects, each once.
    #[test]
    fn incremental_table_equals_naive(
        steps in prop::collection::vec((0usize..8, prop::option::weighted(0.8, reg())), 0..24),
        frames in prop::collection::vec((1i32..3, frame_id()), 1..8),
    ) {
        let mut m = Model::default();
        let mut regs: Vec<Option<Reg>> = vec![None; 8];
        for (n, r) in steps {
            // A replacement adds the new layout before removing the old
            // one, as the kernel does; the model keeps one per number.
            m.remove(n);
            if let Some(r) = &r {
                m.add(n, r);
            }
            regs[n] = r;
            for &(ifindex, id) in &frames {
                prop_assert_eq!(m.lookup(ifindex, id), naive(&regs, ifindex, id));
            }
        }
        for n in 0..8 {
            m.remove(n);
        }
        prop_assert!(m.groups.is_empty() && m.scanned.is_empty() && m.err.is_empty());
        prop_assert!(m.buckets.values().all(|b| b.is_empty()));
    }

    /// A hashed filter selects exactly what the filter itself selects.
    #[test]
    fn placement_is_exact(f in filter(), id in can_id()) {
        if let Place::Hashed { mask, value } = f.place() {
            prop_assert_eq!(frame_key(id) & mask == value, f.matches(frame_key(id)));
        }
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
}
