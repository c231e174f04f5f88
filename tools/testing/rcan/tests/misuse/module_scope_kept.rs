// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties; a guard of the fix for static
//! `HrTimer`s): a module keeps the `ModuleScope` lent to its `init` to
//! initialise a timer later, from a context where the exit's kill of the
//! module's timers may already have run. The scope is only lent, for the
//! length of `init`.
// expect: E0521 borrowed data escapes
#![forbid(unsafe_code)]

use crate::glue::module::{ModuleScope, ScopedModule};
use kernel::prelude::*;

/// Where the module would keep it (a work item's data, a static).
fn keep(_scope: &'static ModuleScope) {}

pub(crate) struct Keeper;

impl ScopedModule for Keeper {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        keep(scope);
        Ok(Keeper)
    }
}
