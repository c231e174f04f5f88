// SPDX-License-Identifier: GPL-2.0
//! Control: the sound uses of what the misuse cases abuse compile (RTNL
//! taken and its data reached through the guard, one borrow at a time;
//! a counted sock reference used while it lives). If this fails, the
//! harness or the glue is broken, and every "refused" verdict means
//! nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::skb::OwnedSkb;
use crate::glue::sock::{Proto, SockRef};
use crate::glue::sync::{Rtnl, RtnlLocked};

static COUNT: RtnlLocked<u32> = RtnlLocked::new(0);

pub(crate) fn bump() {
    let mut rtnl = Rtnl::lock();
    *COUNT.get(&mut rtnl) += 1;
    let again = COUNT.get(&mut rtnl);
    *again += 1;
}

pub(crate) fn deliver<T: Proto>(r: SockRef<T>, skb: OwnedSkb) {
    let _ = r.sock().queue_rcv(skb);
    drop(r);
}
