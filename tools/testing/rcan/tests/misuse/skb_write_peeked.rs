// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`&mut Skb` is taken to mean \"not shared\""): an
//! skb read with MSG_PEEK is still on the socket's receive queue (the
//! queue keeps its reference, the next recvmsg returns it again); writing
//! its bytes, or its control buffer, changes what another reader of the
//! queue sees, concurrently.
// expect: E0599 no method named
#![forbid(unsafe_code)]

use crate::glue::sock::{Proto, Sock};

pub(crate) fn peek_and_scribble<T: Proto>(sk: &Sock<T>) {
    let peek = crate::glue::bindings::MSG_PEEK as i32;
    if let Ok(mut skb) = sk.recv_datagram(peek) {
        skb.data_mut()[0] = 0;
        skb.set_cb_u32(0, 1);
        drop(skb);
    }
}
