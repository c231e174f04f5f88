// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`Sock::lock()` is callable from the softirq `rx`
//! callback"): a CAN protocol's receive callback runs in NET_RX softirq,
//! inside pf_can's RCU read-side section; `lock_sock` sleeps there (and
//! deadlocks against a process-context holder of the lock on the same
//! CPU). The callback gets a `SockView`, which has no `lock()`.
// expect: E0599 no method named `lock` found
#![forbid(unsafe_code)]

use crate::glue::can::proto::{CanProtocol, RxSkb};
use crate::glue::sock::SockView;

/// What a protocol's `rx` would do to reach its locked state.
pub(crate) fn rx<T: CanProtocol>(sk: &SockView<T>, skb: RxSkb<'_>, _cookie: u32) {
    let g = sk.lock();
    drop(g);
    skb.done();
}
