// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_advantech_pci`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`advantech_pci`] (`advantech_pci.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "advantech_pci.rs"]
mod advantech_pci;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
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
type AdvantechPciModule = glue::module::Scoped<advantech_pci::AdvantechPciModule>;

/// `MODULE_DEVICE_TABLE(pci, ...)`: the driver's id table
/// ([`advantech_pci::PCI_IDS`]) under the symbol name modpost looks for. modpost
/// writes one `alias: pci:v...` per entry into the module, so `modinfo`
/// shows them and udev (or `modprobe $(cat /sys/bus/pci/devices/*/modalias)`)
/// loads the module for a matching card. Never read at run time.
#[no_mangle]
#[used]
#[allow(non_upper_case_globals)]
static __mod_pci__rcan_advantech_pci_device_table: [glue::pci::DeviceId;
    advantech_pci::PCI_IDS.len()] = advantech_pci::PCI_IDS;

module! {
    type: AdvantechPciModule,
    name: "rcan_advantech_pci",
    author: "rcan developers",
    description: "SJA1000 front-end for Advantech PCM-3680I / MIOe-3680 PCI cards",
    license: "GPL",
}
