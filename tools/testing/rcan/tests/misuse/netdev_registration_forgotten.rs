// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties: registrations forgotten at
//! `rmmod`): a driver registers a network device and forgets the
//! `netdev::Registration` (`mem::forget`, a `static`, or a `Listening`
//! that owns it, forgotten). Nothing pins the module, so `rmmod`
//! succeeds and the device stays registered with `netdev_ops` and
//! `rtnl_link_ops` in freed module memory: the next `ip link show` faults
//! (seen: `rcan_loop` so changed, `rmmod rcan_loop`, `ip link show` ->
//! an Oops in `if_nlmsg_size`). Now `Registration::register` takes the
//! `ModuleScope` of a module whose exit the glue owns (`Scoped`), and
//! that exit unregisters every device of the module still registered.
// expect: E0061 this function takes 3 arguments but 2 arguments were supplied
#![forbid(unsafe_code)]

use crate::glue::netdev::{Driver, Registration};
use kernel::c_str;
use kernel::prelude::*;

pub(crate) fn register_and_forget<T: Driver>(priv_: T::Priv) -> Result {
    core::mem::forget(Registration::<T>::register(c_str!("can%d"), priv_)?);
    Ok(())
}
