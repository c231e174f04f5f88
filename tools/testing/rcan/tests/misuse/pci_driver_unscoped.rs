// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties: "PCI drivers must call
//! `DRIVER.unregister()`"): a plain `kernel::Module` registers its static
//! PCI driver and its exit forgets to unregister it. The PCI core keeps
//! the `struct pci_driver` (module data) with `probe`/`remove` in module
//! text after `rmmod`: the next hot plug, bind or unbind calls freed
//! text, and the devices its probes registered stay registered. Now
//! `pci::Registration::register` takes the `ModuleScope` of a module whose
//! exit the glue owns (`Scoped`), and that exit unregisters the driver if
//! the module did not, before it sweeps the module's devices; the probe
//! gets the scope lent, which is how a device registered in `probe`
//! (no `init` there) belongs to the module's exit too.
// expect: E0061 this method takes 3 arguments but 2 arguments were supplied
#![forbid(unsafe_code)]

use crate::glue::pci;
use kernel::c_str;
use kernel::prelude::*;

pub(crate) struct Forgetful;

pub(crate) fn register_driver<T: pci::Driver>(
    driver: &'static pci::Registration<T>,
    ids: &'static [pci::DeviceId],
) -> Result<Forgetful> {
    driver.register(c_str!("forgetful"), ids)?;
    Ok(Forgetful)
}
