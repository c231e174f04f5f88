// SPDX-License-Identifier: GPL-2.0
//! The bookkeeping of a fixed-capacity FIFO ring: which slot the next
//! entry goes to and which slot the oldest entry is in.
//!
//! The storage is the caller's (the kernel's `glue::ring::Ring` keeps a
//! `KVec<Option<T>>`), so this file stays allocation-free: entry `i`
//! (0 = oldest) of a ring with `head` and `len` is in slot
//! `(head + i) % capacity`. A driver's receive queue (canloop, the 82527
//! front-ends) is one of these under the device's lock; nothing here
//! locks.

/// Head, length and capacity of a FIFO ring of `capacity` slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RingIndex {
    head: usize,
    len: usize,
    cap: usize,
}

impl RingIndex {
    /// An empty ring of `cap` slots. A ring of 0 slots is always full.
    pub const fn new(cap: usize) -> Self {
        RingIndex {
            head: 0,
            len: 0,
            cap,
        }
    }

    /// Claims the slot for a new newest entry and returns it, or `None`
    /// if the ring is full (nothing changes then).
    pub fn push(&mut self) -> Option<usize> {
        if self.len == self.cap {
            return None;
        }
        let slot = (self.head + self.len) % self.cap;
        self.len += 1;
        Some(slot)
    }

    /// Releases the oldest entry and returns its slot, or `None` if the
    /// ring is empty.
    pub fn pop(&mut self) -> Option<usize> {
        if self.len == 0 {
            return None;
        }
        let slot = self.head;
        self.head = (self.head + 1) % self.cap;
        self.len -= 1;
        Some(slot)
    }

    /// The slot of the oldest entry, if any, without releasing it.
    pub fn front(&self) -> Option<usize> {
        if self.len == 0 {
            None
        } else {
            Some(self.head)
        }
    }

    /// Entries in the ring.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True if the ring holds no entry.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True if a push would fail.
    pub fn is_full(&self) -> bool {
        self.len == self.cap
    }

    /// Slots in the ring.
    pub fn capacity(&self) -> usize {
        self.cap
    }
}
