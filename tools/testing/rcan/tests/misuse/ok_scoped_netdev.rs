// SPDX-License-Identifier: GPL-2.0
//! Control: a module whose exit the glue owns (`Scoped`) registers a
//! network device with the scope lent to its `init`, and a PCI driver
//! registered with the scope registers one in `probe` with the scope
//! lent there, as `rcan_loop` and the PCI front-ends do. If this fails,
//! `netdev_registration_forgotten` and `pci_driver_unscoped` mean
//! nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::module::ModuleScope;
use crate::glue::netdev::{Driver, Registration};
use crate::glue::pci;
use kernel::c_str;
use kernel::prelude::*;

pub(crate) fn register<T: Driver>(scope: &ModuleScope, priv_: T::Priv) -> Result<Registration<T>> {
    Registration::<T>::register(c_str!("can%d"), priv_, scope)
}

pub(crate) fn register_driver<T: pci::Driver>(
    scope: &ModuleScope,
    driver: &'static pci::Registration<T>,
    ids: &'static [pci::DeviceId],
) -> Result {
    driver.register(c_str!("kept"), ids, scope)
}

pub(crate) struct Card<T: Driver>(#[allow(dead_code)] Registration<T>);

pub(crate) fn probe<T: Driver>(
    _dev: &pci::Device,
    scope: &ModuleScope,
    priv_: T::Priv,
) -> Result<KBox<Card<T>>> {
    Ok(KBox::new(Card(register(scope, priv_)?), GFP_KERNEL)?)
}
