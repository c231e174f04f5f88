// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_sja1000_isa`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`sja1000_isa`] (`sja1000_isa.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

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
#[path = "sja1000_isa.rs"]
mod sja1000_isa;

/// The glue owns the module's exit (`Scoped`): devices and drivers it
/// left registered are undone there.
type IsaModule = glue::module::Scoped<sja1000_isa::IsaModule>;

module! {
    type: IsaModule,
    name: "rcan_sja1000_isa",
    author: "rcan developers",
    description: "SJA1000 front-end for memory-mapped ISA cards",
    license: "GPL",
}
