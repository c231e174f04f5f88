// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_pf`: the PF_CAN protocol family in [`pf_can`] (`pf_can.rs`, which
//! is `#![forbid(unsafe_code)]`), the glue it builds on (`rust/glue/`, the
//! only place with `unsafe` code) and the shared pure logic
//! (`rcan_core`). Nothing else lives here: the module declaration must be
//! at the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/can/family.rs"]
mod family;
#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod pf_can;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (rust/glue/module.rs).
type PfCanModule = glue::module::Scoped<pf_can::PfCan>;

module! {
    type: PfCanModule,
    name: "rcan_pf",
    author: "rcan developers",
    description: "PF_CAN protocol family (thesis pf_can)",
    license: "GPL",
}
