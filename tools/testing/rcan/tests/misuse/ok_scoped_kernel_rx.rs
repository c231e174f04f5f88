// SPDX-License-Identifier: GPL-2.0
//! Control: a module whose exit the glue owns (`Scoped`) registers an
//! in-kernel receiver with the scope lent to its `init` and keeps the
//! registration in its value (dropped at exit), as `rcan_dsor` and
//! `rcan_rtime` do. If this fails, `kernel_rx_forgotten` means nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::can::proto::{rx_set_kernel, KernelRx, KernelRxReg, RxFilter, RX_FILTER_CAN_ID};
use crate::glue::module::{ModuleScope, Scoped, ScopedModule};
use crate::glue::netdev::NetDev;
use crate::glue::skb::Skb;
use kernel::prelude::*;

struct Rx;

impl KernelRx for Rx {
    fn rx(&self, _skb: &Skb, _dev: &NetDev) {}
}

static RX: Rx = Rx;

pub(crate) struct Receiving {
    _rx: KernelRxReg<Rx>,
}

impl ScopedModule for Receiving {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let f = RxFilter {
            kind: RX_FILTER_CAN_ID,
            id: 0xc0,
            mask: 0x7ff,
        };
        Ok(Receiving {
            _rx: rx_set_kernel(scope, &RX, 0, &[f])?,
        })
    }
}

/// What the crate root would name in `module!`.
pub(crate) type ReceivingModule = Scoped<Receiving>;
