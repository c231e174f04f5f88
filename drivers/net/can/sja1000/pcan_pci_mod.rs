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
#[path = "../rcan_chips.rs"]
mod rcan_chips;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;
#[path = "sja1000.rs"]
mod sja1000;

/// The glue owns the module's exit (`Scoped`): devices and drivers it
/// left registered are undone there.
type PcanPciModule = glue::module::Scoped<pcan_pci::PcanPciModule>;

/// `MODULE_DEVICE_TABLE(pci, ...)`: the driver's id table
/// ([`pcan_pci::PCI_IDS`]) under the symbol name modpost looks for. modpost
/// writes one `alias: pci:v...` per entry into the module, so `modinfo`
/// shows them and udev (or `modprobe $(cat /sys/bus/pci/devices/*/modalias)`)
/// loads the module for a matching card. Never read at run time.
#[no_mangle]
#[used]
#[allow(non_upper_case_globals)]
static __mod_pci__rcan_pcan_pci_device_table: [glue::pci::DeviceId; pcan_pci::PCI_IDS.len()] =
    pcan_pci::PCI_IDS;

module! {
    type: PcanPciModule,
    name: "rcan_pcan_pci",
    author: "rcan developers",
    description: "SJA1000 front-end for PEAK PCAN-PCI cards",
    license: "GPL",
}
