// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`Sock::lock()` is callable from the softirq `rx`
//! callback", the same hole through a counted reference): a timer or
//! job callback (softirq or hardirq) holds a `SockRef` and takes the
//! socket lock through it, which sleeps. `SockRef::sock()` lends a
//! `SockView` (no `lock()`); the process-context `Sock` needs a proof of
//! process context (`SockRef::in_process`), which a timer cannot get.
// expect: E0599 no method named `lock` found
#![forbid(unsafe_code)]

use crate::glue::sock::{Proto, SockRef};

/// What a timer callback holding a counted reference would do.
pub(crate) fn expired<T: Proto>(r: &SockRef<T>) {
    let g = r.sock().lock();
    drop(g);
}
