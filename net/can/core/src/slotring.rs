// SPDX-License-Identifier: GPL-2.0
//! A fixed-capacity FIFO of non-zero tokens for one producer and one
//! consumer that run on different CPUs at the same time, without a lock.
//!
//! Each slot is an atomic word: 0 means empty, anything else is a token (the
//! kernel's `glue::ring::SkbRing` stores an skb's address). The producer
//! writes the slot at its own index `tail` if that slot is empty; the
//! consumer takes the slot at its own index `head` if it is full. So the
//! slot itself says who may touch it next, and the two sides share nothing
//! else: each index is written by its side only (a FIFO in the manner of
//! FastForward, Giacomoni et al., PPoPP 2008).
//!
//! Ordering: a push stores its token with `Release`, a pop takes it with
//! `Acquire`, so everything the producer wrote into the object behind the
//! token before pushing is visible to the consumer that pops it.
//!
//! Misuse is never unsound, only less useful: the slot changes are atomic
//! (a compare-and-exchange from 0 to push, a swap to 0 to pop), so even
//! two producers or two consumers at once never duplicate a token, and
//! every token pushed stays in its slot until something takes it
//! ([`SlotRing::take_any`] finds it at teardown); but the indices may then
//! drift, so tokens may come out of order or wait in a slot the consumer
//! reaches only after a wrap, and a push may find no room that exists. Callers that need the FIFO order
//! serialise each side (canloop's producer is its `start_xmit`, under the
//! device's TX lock; its consumer is the NAPI poll, which never runs
//! concurrently with itself).
//!
//! The storage is the caller's (`S`, anything that derefs to a slice of
//! atomic words: a `KVec` in the kernel, a `Vec` in the tests), so this
//! file stays allocation-free.

use core::num::NonZeroUsize;
use core::ops::Deref;
use core::sync::atomic::{AtomicUsize, Ordering};

/// A ring of `slots.len()` (a power of two) token slots with the
/// producer's and the consumer's indices.
#[derive(Debug)]
pub struct SlotRing<S> {
    slots: S,
    /// The consumer's next slot (written by the consumer only).
    head: AtomicUsize,
    /// The producer's next slot (written by the producer only).
    tail: AtomicUsize,
}

impl<S: Deref<Target = [AtomicUsize]>> SlotRing<S> {
    /// A ring over `slots`, which must all be 0 (empty) and be a power of
    /// two in number (the index wraps by a mask); `None` otherwise.
    pub fn new(slots: S) -> Option<Self> {
        let s: &[AtomicUsize] = &slots;
        if !s.len().is_power_of_two() || s.iter().any(|v| v.load(Ordering::Relaxed) != 0) {
            return None;
        }
        Some(SlotRing {
            slots,
            head: AtomicUsize::new(0),
            tail: AtomicUsize::new(0),
        })
    }

    /// The slot for index `i`.
    #[inline]
    fn slot(&self, i: usize) -> &AtomicUsize {
        let s: &[AtomicUsize] = &self.slots;
        // In range: the length is a non-zero power of two (new).
        &s[i & (s.len() - 1)]
    }

    /// Appends `token` as the newest entry (producer side); gives it back
    /// if the ring is full.
    #[inline]
    pub fn push(&self, token: NonZeroUsize) -> Result<(), NonZeroUsize> {
        let t = self.tail.load(Ordering::Relaxed);
        match self
            .slot(t)
            .compare_exchange(0, token.get(), Ordering::Release, Ordering::Relaxed)
        {
            Ok(_) => {
                self.tail.store(t.wrapping_add(1), Ordering::Relaxed);
                Ok(())
            }
            Err(_) => Err(token),
        }
    }

    /// Takes the oldest entry (consumer side), `None` if the ring is
    /// empty.
    #[inline]
    pub fn pop(&self) -> Option<NonZeroUsize> {
        let h = self.head.load(Ordering::Relaxed);
        let token = NonZeroUsize::new(self.slot(h).swap(0, Ordering::Acquire))?;
        self.head.store(h.wrapping_add(1), Ordering::Relaxed);
        Some(token)
    }

    /// True if the consumer's next slot is empty now (consumer side): a
    /// push may fill it at any time after.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.slot(self.head.load(Ordering::Relaxed))
            .load(Ordering::Relaxed)
            == 0
    }

    /// Takes any one entry, wherever it is (`None` once every slot is
    /// empty): for the owner's teardown, which must find every token even
    /// if a misuse left one outside `head..tail`. Consumer side; entries
    /// come in slot order, not FIFO order.
    pub fn take_any(&self) -> Option<NonZeroUsize> {
        self.slots
            .iter()
            .find_map(|s| NonZeroUsize::new(s.swap(0, Ordering::Acquire)))
    }

    /// The number of slots.
    pub fn capacity(&self) -> usize {
        self.slots.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;
    use std::sync::Arc;
    use std::vec::Vec;

    fn ring(n: usize) -> SlotRing<Vec<AtomicUsize>> {
        SlotRing::new((0..n).map(|_| AtomicUsize::new(0)).collect()).unwrap()
    }

    fn tok(v: usize) -> NonZeroUsize {
        NonZeroUsize::new(v).unwrap()
    }

    #[test]
    fn new_wants_a_power_of_two_of_empty_slots() {
        let v = |n: usize| (0..n).map(|_| AtomicUsize::new(0)).collect::<Vec<_>>();
        assert!(SlotRing::new(v(0)).is_none());
        assert!(SlotRing::new(v(3)).is_none());
        assert!(SlotRing::new(v(1)).is_some());
        assert!(SlotRing::new(v(512)).is_some());
        let used = v(4);
        used[2].store(7, Ordering::Relaxed);
        assert!(SlotRing::new(used).is_none());
    }

    #[test]
    fn fills_to_capacity_then_refuses() {
        let r = ring(4);
        assert!(r.is_empty());
        for i in 1..=4 {
            assert_eq!(r.push(tok(i)), Ok(()));
        }
        assert_eq!(r.push(tok(5)), Err(tok(5)));
        assert!(!r.is_empty());
        assert_eq!(r.pop(), Some(tok(1)));
        assert_eq!(r.push(tok(5)), Ok(()));
        for i in 2..=5 {
            assert_eq!(r.pop(), Some(tok(i)));
        }
        assert_eq!(r.pop(), None);
        assert!(r.is_empty());
    }

    /// Against `VecDeque` for a long pseudo-random mix of pushes and pops,
    /// past many wraps of the indices.
    #[test]
    fn matches_a_deque() {
        let r = ring(8);
        let mut d = VecDeque::new();
        let mut x: u32 = 12345;
        let mut next = 1usize;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            if x % 3 != 0 {
                let got = r.push(tok(next));
                if d.len() < 8 {
                    assert_eq!(got, Ok(()));
                    d.push_back(next);
                } else {
                    assert_eq!(got, Err(tok(next)));
                }
                next += 1;
            } else {
                assert_eq!(r.pop().map(|t| t.get()), d.pop_front());
            }
            assert_eq!(r.is_empty(), d.is_empty());
        }
    }

    /// One producer thread and one consumer thread at the same time: every
    /// token comes out once, in order, and what the producer wrote before
    /// the push is seen after the pop.
    #[test]
    fn one_producer_one_consumer_threads() {
        const N: usize = 200_000;
        let r = Arc::new(ring(16));
        let data: Arc<Vec<AtomicUsize>> = Arc::new((0..=N).map(|_| AtomicUsize::new(0)).collect());
        let (pr, pd) = (r.clone(), data.clone());
        let producer = std::thread::spawn(move || {
            let mut i = 1;
            while i <= N {
                // The "object" behind the token, written before the push.
                pd[i].store(i * 3, Ordering::Relaxed);
                match pr.push(tok(i)) {
                    Ok(()) => i += 1,
                    Err(_) => std::thread::yield_now(),
                }
            }
        });
        let mut want = 1;
        while want <= N {
            match r.pop() {
                Some(t) => {
                    assert_eq!(t.get(), want);
                    assert_eq!(data[want].load(Ordering::Relaxed), want * 3);
                    want += 1;
                }
                None => std::thread::yield_now(),
            }
        }
        producer.join().unwrap();
        assert!(r.is_empty());
    }

    #[test]
    fn take_any_empties_every_slot() {
        let r = ring(4);
        for i in 1..=3 {
            r.push(tok(i)).unwrap();
        }
        assert_eq!(r.pop(), Some(tok(1)));
        let mut got = std::vec::Vec::new();
        while let Some(t) = r.take_any() {
            got.push(t.get());
        }
        got.sort();
        assert_eq!(got, [2, 3]);
        assert!(r.is_empty());
        assert_eq!(r.pop(), None);
    }
}
