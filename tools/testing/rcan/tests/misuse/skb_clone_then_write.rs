// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`&mut Skb` is taken to mean \"not shared\""): an
//! skb the caller allocated is unique, until it is cloned: the clone
//! shares its data, so writing the original afterwards changes the bytes
//! the clone's holder (a receive queue, the driver) reads.
// expect: E0599 the method `clone_atomic` exists for struct `Skb<Unique>`, but its trait bounds were not satisfied
#![forbid(unsafe_code)]

use crate::glue::skb::Skb;

pub(crate) fn clone_then_write() {
    if let Some(mut skb) = Skb::alloc(16, crate::glue::GFP_ATOMIC) {
        let _ = skb.put_zeroed(16);
        let copy = skb.clone_atomic();
        skb.data_mut()[0] = 1;
        drop(copy);
    }
}
