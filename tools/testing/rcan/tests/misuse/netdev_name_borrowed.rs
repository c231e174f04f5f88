// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, smaller findings: "`NetDev::name_bytes` reads
//! `dev->name`, which a concurrent rename rewrites"): a name borrowed
//! from the device is a `&[u8]` over bytes that `dev_change_name` (under
//! RTNL, which a receive callback or a driver's interrupt does not hold)
//! writes meanwhile: a data race, and a slice that changes under its
//! reader. `NetDev::name` returns a copy (`IfName`), so no reference into
//! the device's name outlives the read.
// expect: E0515 cannot return value referencing temporary value
#![forbid(unsafe_code)]

use crate::glue::netdev::NetDev;

pub(crate) fn name_kept(dev: &NetDev) -> &[u8] {
    dev.name().as_bytes()
}
