// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Lifetimes not tied to anything": `SockRef::sock()`
//! returns a `Sock<T>` that outlives the `SockRef`): the counted reference
//! is dropped (`sock_put`, perhaps the last one, freeing the sock) and the
//! sock is used afterwards, `let s = bind.sk.sock(); drop(bind);
//! s.queue_rcv(skb)`.
// expect: E0505 cannot move out of `r` because it is borrowed
#![forbid(unsafe_code)]

use crate::glue::skb::OwnedSkb;
use crate::glue::sock::{Proto, SockRef};

pub(crate) fn after_put<T: Proto>(r: SockRef<T>, skb: OwnedSkb) {
    let s = r.sock();
    drop(r);
    let _ = s.queue_rcv(skb);
}
