// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "`pci::IoMem` ... nothing revokes it at unbind";
//! architecture.rst, "A mapping past its binding"): a driver reaches the
//! registers of a mapped BAR without the check of its binding, through
//! the bounds-checked range under it (`&*io`, as `IoMem`'s `Deref` to
//! `IoRange` allowed). Kept past `remove`, such a range programs a device
//! another driver may own by then. Now `IoMem` lends its range only
//! through `IoMem::access`, which refuses once the binding has ended, and
//! has no `Deref`.
// expect: E0614 cannot be dereferenced
#![forbid(unsafe_code)]

use crate::glue::iomap::IoRange;
use crate::glue::pci::IoMem;

pub(crate) fn unchecked(io: IoMem) -> u8 {
    let r: &IoRange = &*io;
    r.read8(0)
}
