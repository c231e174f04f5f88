// SPDX-License-Identifier: GPL-2.0
//! Control for the skb ownership cases (issue 39): the sound uses
//! compile. An skb the caller allocated is written; it is cloned only
//! after giving up writes (`into_owned`); a received frame is kept as an
//! `OwnedSkb` whose own fields (`cb`) are written, its device's index
//! read in the callback; a peeked or shared skb is written only after
//! `unshare` (a copy if need be); an skb handed up by a device gets that
//! device at the hand-off, never a NULL or stale one. A device's name is
//! a copy.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::can::proto::RxSkb;
use crate::glue::netdev::NetDev;
use crate::glue::skb::{OwnedSkb, UniqueSkb};
use crate::glue::sock::{Proto, Sock, SockView};

/// The device's name is read as a copy, compared and printed (the sound
/// use of `netdev_name_borrowed`).
pub(crate) fn name_copied(dev: &NetDev) -> bool {
    let name = dev.name();
    kernel::pr_info!("{}: up\n", name);
    name.as_bytes() == b"can0"
}

pub(crate) fn build_then_clone(dev: &NetDev) {
    if let Some(mut skb) = UniqueSkb::alloc(16, crate::glue::GFP_ATOMIC) {
        let _ = skb.put_zeroed(16);
        skb.data_mut()[0] = 1;
        let skb: OwnedSkb = skb.into_owned();
        let copy = skb.clone_atomic();
        drop(copy);
        dev.rx(skb);
    }
}

pub(crate) fn rx<T: Proto>(sk: &SockView<T>, skb: RxSkb<'_>) {
    let ifindex = skb.ifindex();
    if let Some(mut skb) = skb.into_owned() {
        skb.set_cb_u32(0, ifindex as u32);
        let _ = sk.queue_rcv(skb);
    }
}

pub(crate) fn peek_then_write<T: Proto>(sk: &Sock<T>) {
    let peek = crate::glue::bindings::MSG_PEEK as i32;
    if let Ok(skb) = sk.recv_datagram(peek) {
        if let Some(mut mine) = skb.unshare() {
            if let Some(b) = mine.data_mut().first_mut() {
                *b = 0;
            }
        }
    }
}
