// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything"): a receive
//! context made outside the glue. An `RxSkb<'a>` lends the receiving
//! device (`skb->dev`) for `'a`, which only pf_can's dispatcher can
//! vouch for (the receive path holds the device for the callback); one
//! forged around a kept skb, for `'static`, would lend a device that may
//! be gone.
// expect: E0599 no associated item named `Owned` found
#![forbid(unsafe_code)]

use crate::glue::can::proto::RxSkb;

pub(crate) fn forge(skb: crate::glue::skb::Skb) -> RxSkb<'static> {
    RxSkb::Owned(skb)
}
