// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything": `set_dev(&NetDev)`
//! stores `skb->dev` without a reference): safe code points an skb it
//! keeps at a device it only borrows; once the device is gone, whatever
//! reads `skb->dev` (the skb handed to the stack later, an ifindex
//! lookup) uses freed memory. Only the glue's hand-offs may set it, right
//! before the kernel takes the skb.
// expect: E0133 is unsafe and requires unsafe
#![forbid(unsafe_code)]

use crate::glue::netdev::NetDev;
use crate::glue::skb::Skb;

pub(crate) fn point_at(dev: &NetDev) {
    if let Some(mut skb) = Skb::alloc(16, crate::glue::GFP_ATOMIC) {
        skb.set_dev(dev);
        drop(skb);
    }
}
