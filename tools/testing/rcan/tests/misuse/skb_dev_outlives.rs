// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything": `Skb::ifindex()`
//! reads `skb->dev`, stored by `set_dev(&NetDev)` without a reference):
//! skbs kept past their device (a protocol's list, a driver's echo slot)
//! are asked for their device after `rmmod rcan_loop` freed it.
// expect: E0599 no method named `ifindex` found
#![forbid(unsafe_code)]

use crate::glue::skb::Skb;
use kernel::alloc::KVec;

pub(crate) fn later(kept: &KVec<Skb>) -> i32 {
    let mut sum = 0;
    for skb in kept.iter() {
        sum += skb.ifindex();
    }
    sum
}
