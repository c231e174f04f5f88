// SPDX-License-Identifier: GPL-2.0

//! A fixed-capacity FIFO of owned values ([`Ring`]), allocated once: the
//! receive queue of a driver whose interrupt (or transmit path) takes frames
//! that its NAPI poll hands up later, and the DSOR engine's queue of frames
//! to send. Safe code only; the slot arithmetic is
//! `rcan_core::ring::RingIndex`, host-tested against `VecDeque`.
//!
//! A `Ring` has no lock of its own: it lives inside the lock that guards
//! the state it belongs to (the 82527's, SJA1000's and CTU CAN FD's chip
//! locks, DSOR's `ENGINE`), and every method takes `&mut self`.
//!
//! [`SkbRing`] is a FIFO of skbs with no lock at all, for one producer
//! and one consumer at the same time (canloop's echo FIFO): the slot
//! protocol is `rcan_core::slotring::SlotRing`, host-tested with two
//! threads.

use super::skb::OwnedSkb;
use crate::rcan_core::ring::RingIndex;
use crate::rcan_core::slotring::SlotRing;
use core::sync::atomic::AtomicUsize;
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

/// A FIFO of skbs for one producer and one consumer without a lock
/// ([`SlotRing`]: each slot an atomic word holding an skb's address or 0):
/// a driver whose transmit path queues echoes that its NAPI poll hands up
/// (canloop). The producer and the consumer may run at the same time on
/// two CPUs; each side must be serialised with itself for the FIFO order
/// (canloop: `start_xmit` under the device's TX lock; the NAPI poll,
/// which never runs concurrently with itself, and `stop` after the poll
/// is disabled). A misuse (two producers at once) loses no skb and frees
/// none twice; only the order and the room are then not kept. Any context
/// (allocates only in [`SkbRing::new`]).
pub(crate) struct SkbRing {
    ring: SlotRing<KVec<AtomicUsize>>,
}

// The ring owns the skbs whose addresses its slots hold: handing the ring
// (or a reference to it) to another CPU hands them too, which an skb
// allows (it is `Send`). `SkbRing` gets `Send` and `Sync` from its atomics;
// this says why that is right.
const _: () = {
    const fn skb_is_send<T: Send>() {}
    skb_is_send::<OwnedSkb>()
};

impl SkbRing {
    /// An empty ring of `capacity` slots (a power of two; EINVAL
    /// otherwise), allocated now (`GFP_KERNEL`). Process context.
    pub(crate) fn new(capacity: usize) -> Result<Self> {
        let mut slots = KVec::with_capacity(capacity, GFP_KERNEL)?;
        for _ in 0..capacity {
            slots.push(AtomicUsize::new(0), GFP_KERNEL)?;
        }
        let ring = SlotRing::new(slots).ok_or(EINVAL)?;
        Ok(SkbRing { ring })
    }

    /// Appends `skb` as the newest entry (producer side); gives it back if
    /// the ring is full.
    #[inline]
    pub(crate) fn push(&self, skb: OwnedSkb) -> core::result::Result<(), OwnedSkb> {
        self.ring.push(skb.into_addr()).map_err(|a| {
            // SAFETY: `a` is the address `into_addr` just gave, which the
            // ring did not take: taken back once, here.
            unsafe { OwnedSkb::from_addr(a) }
        })
    }

    /// Takes the oldest entry (consumer side).
    #[inline]
    pub(crate) fn pop(&self) -> Option<OwnedSkb> {
        let a = self.ring.pop()?;
        // SAFETY: a non-zero slot holds an address from `into_addr`
        // (`push`); the swap that took it out left 0 there, so it is taken
        // back once.
        Some(unsafe { OwnedSkb::from_addr(a) })
    }

    /// True if the consumer's next slot is empty now (consumer side).
    #[inline]
    pub(crate) fn is_empty(&self) -> bool {
        self.ring.is_empty()
    }
}

impl Drop for SkbRing {
    /// Frees every skb still in a slot. Process context (the owner goes).
    fn drop(&mut self) {
        while let Some(a) = self.ring.take_any() {
            // SAFETY: as in `pop`: an address from `into_addr`, taken once.
            drop(unsafe { OwnedSkb::from_addr(a) });
        }
    }
}
