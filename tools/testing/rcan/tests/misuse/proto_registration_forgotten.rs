// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties: registrations forgotten at
//! `rmmod`): a module registers its protocol and forgets the
//! `ProtoRegistration` (`mem::forget`, or keeps it in a `static`). With no
//! socket open nothing pins the module, so `rmmod` succeeds and leaves its
//! static `CanProto` in pf_can's protocol table, its `notifier_block` on
//! the netdevice chain and its `struct proto` on `proto_list`: the next
//! `ip link set can0 up` faults in `raw_notifier_call_chain` (seen with
//! `rcan_can` so changed). Now `register` takes the `ModuleScope` of a
//! module whose exit the glue owns (`Scoped`), and that exit unregisters
//! every protocol of the module still registered.
// expect: E0061 this method takes 2 arguments but 1 argument was supplied
#![forbid(unsafe_code)]

use crate::glue::can::proto::{CanProtocol, ProtoModule};
use kernel::c_str;
use kernel::prelude::*;

pub(crate) fn register_and_forget<T: CanProtocol>(m: &'static ProtoModule<T>) -> Result {
    core::mem::forget(m.register(c_str!("FORGOTTEN"))?);
    Ok(())
}
