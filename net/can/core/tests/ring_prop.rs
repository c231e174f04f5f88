// SPDX-License-Identifier: GPL-2.0
//! `RingIndex` against `VecDeque` for random push/pop sequences: the same
//! values come out in the same order, a full ring refuses a push and an
//! empty one a pop, and no two live entries share a slot.

use proptest::prelude::*;
use rcan_core::ring::RingIndex;
use std::collections::VecDeque;

/// A ring of `cap` slots holding `u32`s, as glue::ring::Ring holds skbs.
struct Model {
    idx: RingIndex,
    slots: Vec<Option<u32>>,
}

impl Model {
    fn new(cap: usize) -> Self {
        Model {
            idx: RingIndex::new(cap),
            slots: vec![None; cap],
        }
    }

    fn push(&mut self, v: u32) -> bool {
        match self.idx.push() {
            Some(s) => {
                assert!(self.slots[s].is_none(), "slot {s} still holds an entry");
                self.slots[s] = Some(v);
                true
            }
            None => false,
        }
    }

    fn pop(&mut self) -> Option<u32> {
        let s = self.idx.pop()?;
        Some(self.slots[s].take().expect("popped slot was empty"))
    }
}

proptest! {
    #[test]
    fn ring_is_a_bounded_fifo(cap in 1usize..9, ops in prop::collection::vec(any::<Option<u32>>(), 0..200)) {
        let mut ring = Model::new(cap);
        let mut model = VecDeque::new();
        for op in ops {
            match op {
                Some(v) => {
                    let ok = ring.push(v);
                    prop_assert_eq!(ok, model.len() < cap);
                    if ok {
                        model.push_back(v);
                    }
                }
                None => prop_assert_eq!(ring.pop(), model.pop_front()),
            }
            prop_assert_eq!(ring.idx.len(), model.len());
            prop_assert_eq!(ring.idx.is_empty(), model.is_empty());
            prop_assert_eq!(ring.idx.is_full(), model.len() == cap);
            prop_assert_eq!(ring.idx.front().map(|s| ring.slots[s].unwrap()), model.front().copied());
            prop_assert_eq!(ring.slots.iter().filter(|s| s.is_some()).count(), model.len());
        }
    }
}

#[test]
fn zero_slots_is_full_and_empty() {
    let mut r = RingIndex::new(0);
    assert!(r.is_full() && r.is_empty());
    assert_eq!(r.push(), None);
    assert_eq!(r.pop(), None);
}

#[test]
fn wraps_around() {
    let mut r = RingIndex::new(3);
    assert_eq!(
        (r.push(), r.push(), r.push(), r.push()),
        (Some(0), Some(1), Some(2), None)
    );
    assert_eq!(
        (r.pop(), r.push(), r.pop(), r.pop(), r.pop()),
        (Some(0), Some(0), Some(1), Some(2), Some(0))
    );
    assert_eq!(r.pop(), None);
}
