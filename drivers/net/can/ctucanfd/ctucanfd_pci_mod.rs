// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_ctucanfd_pci`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`ctucanfd_pci`] (`ctucanfd_pci.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "ctucanfd.rs"]
mod ctucanfd;
#[path = "ctucanfd_pci.rs"]
mod ctucanfd_pci;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_chips.rs"]
mod rcan_chips;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

/// The glue owns the module's exit (`Scoped`): devices and drivers it
/// left registered are undone there.
type CtuCanFdPciModule = glue::module::Scoped<ctucanfd_pci::CtuCanFdPciModule>;

/// `MODULE_DEVICE_TABLE(pci, ...)`: the driver's id table
/// ([`ctucanfd_pci::PCI_IDS`]) under the symbol name modpost looks for. modpost
/// writes one `alias: pci:v...` per entry into the module, so `modinfo`
/// shows them and udev (or `modprobe $(cat /sys/bus/pci/devices/*/modalias)`)
/// loads the module for a matching card. Never read at run time.
#[no_mangle]
#[used]
#[allow(non_upper_case_globals)]
static __mod_pci__rcan_ctucanfd_pci_device_table: [glue::pci::DeviceId;
    ctucanfd_pci::PCI_IDS.len()] = ctucanfd_pci::PCI_IDS;

module! {
    type: CtuCanFdPciModule,
    name: "rcan_ctucanfd_pci",
    author: "rcan developers",
    description: "CTU CAN FD driver for the CTU CAN FD PCI card (QEMU ctucan_pci)",
    license: "GPL",
}
