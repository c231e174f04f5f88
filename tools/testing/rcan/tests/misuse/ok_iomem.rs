// SPDX-License-Identifier: GPL-2.0
//! Control: a driver reads and writes the registers of a mapped BAR, one
//! checked access at a time and several behind one check
//! (`IoMem::access`), as the PCI front-ends do; the mapping and the
//! enable live in its card. If this fails, `iomem_unchecked_range` and
//! `iomem_guard_outlives` mean nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::pci::{self, IoMem};
use crate::glue::module::ModuleScope;
use kernel::prelude::*;

pub(crate) struct Card {
    io: IoMem,
    _enabled: pci::Enabled,
}

pub(crate) fn probe(dev: &pci::Device, _scope: &ModuleScope) -> Result<KBox<Card>> {
    let enabled = dev.enable()?;
    let io = dev.iomap(1, 0x20)?;
    io.write8(0, 1);
    let card = Card {
        io,
        _enabled: enabled,
    };
    Ok(KBox::new(card, GFP_KERNEL)?)
}

pub(crate) fn irq(card: &Card) -> u8 {
    let Some(regs) = card.io.access() else {
        return 0;
    };
    let status = regs.read8(3);
    regs.write8(1, status);
    status | card.io.read8(2)
}
