// SPDX-License-Identifier: GPL-2.0
//! Control: a module whose exit the glue owns (`Scoped`) registers its
//! protocol with the scope lent to its `init` and keeps the registration
//! in its value, as `rcan_raw`, `rcan_bcm`, `rcan_can` and `rcan_dsor`
//! do. If this fails, `proto_registration_forgotten` means nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::can::proto::{CanProtocol, ProtoModule, ProtoRegistration};
use crate::glue::module::ModuleScope;
use kernel::c_str;
use kernel::prelude::*;

pub(crate) fn register<T: CanProtocol>(
    scope: &ModuleScope,
    m: &'static ProtoModule<T>,
) -> Result<ProtoRegistration<T>> {
    m.register(c_str!("KEPT"), scope)
}
