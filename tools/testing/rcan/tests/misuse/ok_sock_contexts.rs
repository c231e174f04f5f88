// SPDX-License-Identifier: GPL-2.0
//! Control for the socket context cases (issue 39): the receive callback
//! and a timer use what needs no lock (`shared`, `queue_rcv`,
//! `report_error`, `to_ref`), a system call takes the lock, and a `/proc`
//! read (process context, proven by its `SeqFile`) takes the lock of a
//! sock it reaches through a counted reference.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::can::proto::{CanProtocol, RxSkb};
use crate::glue::procfs::SeqFile;
use crate::glue::sock::{Proto, Sock, SockRef, SockView};

pub(crate) fn rx<T: CanProtocol>(sk: &SockView<T>, skb: RxSkb<'_>, _cookie: u32) {
    let _ = sk.shared();
    if let Some(skb) = skb.into_owned() {
        let _ = sk.queue_rcv(skb);
    }
}

pub(crate) fn expired<T: Proto>(r: &SockRef<T>) -> SockRef<T> {
    r.sock().report_error(110);
    r.sock().to_ref()
}

pub(crate) fn sendmsg<T: Proto>(sk: &Sock<T>) {
    let g = sk.lock();
    drop(g);
    // A process-context sock is also a view.
    let _ = sk.shared();
}

pub(crate) fn show<T: Proto>(r: &SockRef<T>, m: &mut SeqFile<'_>) {
    let sk = r.in_process(m.process());
    let g = sk.lock();
    m.write_kaddr(sk.kaddr());
    drop(g);
}
