// SPDX-License-Identifier: GPL-2.0

//! A fixed-capacity FIFO of owned values ([`Ring`]), allocated once: the
//! receive queue of a driver whose interrupt (or transmit path) takes frames
//! that its NAPI poll hands up later, and the DSOR engine's queue of frames
//! to send. Safe code only; the slot arithmetic is
//! `rcan_core::ring::RingIndex`, host-tested against `VecDeque`.
//!
//! A `Ring` has no lock of its own: it lives inside the lock that guards
//! the state it belongs to (canloop's `IrqSpinLock<Ring<Skb>>`, the
//! 82527's, SJA1000's and CTU CAN FD's chip locks, DSOR's `ENGINE`), and
//! every method takes `&mut self`.

use crate::rcan_core::ring::RingIndex;
use kernel::prelude::*;

/// Up to `capacity` values, oldest first.
pub(crate) struct Ring<T> {
    slots: KVec<Option<T>>,
    idx: RingIndex,
}

impl<T> Ring<T> {
    /// An empty ring of `capacity` slots, allocated now (`GFP_KERNEL`).
    /// Process context.
    pub(crate) fn new(capacity: usize) -> Result<Self> {
        let mut slots = KVec::with_capacity(capacity, GFP_KERNEL)?;
        for _ in 0..capacity {
            slots.push(None, GFP_KERNEL)?;
        }
        Ok(Ring {
            slots,
            idx: RingIndex::new(capacity),
        })
    }

    /// Appends `v` as the newest value; gives it back if the ring is full.
    /// Any context (allocates nothing).
    pub(crate) fn push(&mut self, v: T) -> core::result::Result<(), T> {
        match self.idx.push() {
            Some(slot) => {
                self.slots[slot] = Some(v);
                Ok(())
            }
            None => Err(v),
        }
    }

    /// Takes the oldest value. Any context.
    pub(crate) fn pop(&mut self) -> Option<T> {
        let slot = self.idx.pop()?;
        self.slots[slot].take()
    }

    /// Values in the ring.
    pub(crate) fn len(&self) -> usize {
        self.idx.len()
    }

    /// True if the ring holds nothing.
    pub(crate) fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }
}
