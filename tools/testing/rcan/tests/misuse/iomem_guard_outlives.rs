// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "A mapping past its binding" in architecture.rst):
//! a driver takes the batch guard of a mapped BAR (`IoMem::access`, the
//! check of its binding done once) and drops the mapping (`pci_iounmap`)
//! while the guard is still in use, reaching an unmapped cookie. The
//! guard borrows the `IoMem`.
// expect: E0505 cannot move out of `io` because it is borrowed
#![forbid(unsafe_code)]

use crate::glue::pci::IoMem;

pub(crate) fn after_unmap(io: IoMem) -> u8 {
    let Some(regs) = io.access() else {
        return 0xFF;
    };
    drop(io);
    regs.read8(0)
}
