// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_iomemkeep`, a test-only module (never installed):
//! the module itself is [`iomemkeep`] (`iomemkeep.rs`, which is
//! `#![forbid(unsafe_code)]`), built on the glue (`rust/glue/`) like every
//! driver module.

use kernel::prelude::*;

mod iomemkeep;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

/// The glue's wrapper owns the module's exit duties (the PCI driver's
/// unregistration among them).
type IoMemKeep = glue::module::Scoped<iomemkeep::IoMemKeep>;

module! {
    type: IoMemKeep,
    name: "rcan_iomemkeep",
    author: "rcan developers",
    description: "test only: a PCI driver that keeps its register window and enable past remove",
    license: "GPL",
}
