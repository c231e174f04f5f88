// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties: registrations forgotten at
//! `rmmod`): a module registers an in-kernel receiver and forgets the
//! `KernelRxReg` (`mem::forget`, or keeps it in a `static`, which is never
//! dropped). Nothing pins the module, so `rmmod` succeeds and the receive
//! table keeps `kernel_rx::<T>` and the module's static: the next matching
//! frame calls freed module text from NET_RX softirq (seen: an Oops in
//! `rcv_common` after `rmmod rcan_rtime` with its registration forgotten).
//! Now `rx_set_kernel` takes the `ModuleScope` of a module whose exit the
//! glue owns (`Scoped`), and that exit removes every kernel receiver of
//! the module still registered.
// expect: E0061 this function takes 4 arguments but 3 arguments were supplied
#![forbid(unsafe_code)]

use crate::glue::can::proto::{rx_set_kernel, KernelRx, RxFilter, RX_FILTER_CAN_ID};
use crate::glue::netdev::NetDev;
use crate::glue::skb::Skb;
use kernel::prelude::*;

struct Rx;

impl KernelRx for Rx {
    fn rx(&self, _skb: &Skb, _dev: &NetDev) {}
}

static RX: Rx = Rx;

pub(crate) struct Forgetful;

impl kernel::Module for Forgetful {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let f = RxFilter {
            kind: RX_FILTER_CAN_ID,
            id: 0xc0,
            mask: 0x7ff,
        };
        core::mem::forget(rx_set_kernel(&RX, 0, &[f])?);
        Ok(Forgetful)
    }
}
