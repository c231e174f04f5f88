// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_pcan_pci`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`pcan_pci`] (`pcan_pci.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "pcan_pci.rs"]
mod pcan_pci;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;
#[path = "sja1000.rs"]
mod sja1000;

use pcan_pci::PcanPciModule;

module! {
    type: PcanPciModule,
    name: "rcan_pcan_pci",
    author: "rcan developers",
    description: "SJA1000 front-end for PEAK PCAN-PCI cards",
    license: "GPL",
}
