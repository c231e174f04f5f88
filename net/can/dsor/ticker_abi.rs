// SPDX-License-Identifier: GPL-2.0

//! The C entry points of the time services' parameters
//! (`ticker_params.c` calls them from its `kernel_param_ops`, process
//! context): exported symbols with the C ABI, which the
//! `#![forbid(unsafe_code)]` files may not declare, so they live here, at
//! the crate root of `rcan_time` and `rcan_rtime`, and only forward to
//! [`ticker`](crate::ticker).

use crate::ticker::{self, IfName};

/// Validates and stores integer parameter `which`; false makes the load,
/// or the sysfs write, fail with EINVAL.
#[no_mangle]
extern "C" fn rcan_timesvc_param_set(which: u32, val: u32) -> bool {
    ticker::param_set(which, val)
}

/// Reads integer parameter `which`.
#[no_mangle]
extern "C" fn rcan_timesvc_param_get(which: u32) -> u32 {
    ticker::param_get(which)
}

/// Validates and stores the `dev` parameter (while loading).
#[no_mangle]
extern "C" fn rcan_timesvc_dev_set(name: IfName) -> bool {
    ticker::dev_set(name)
}

/// Reads the `dev` parameter.
#[no_mangle]
extern "C" fn rcan_timesvc_dev_get() -> IfName {
    ticker::dev_get()
}
