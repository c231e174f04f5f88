// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_i82527_isa`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`isa`] (`isa.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "i82527.rs"]
mod i82527;
#[path = "isa.rs"]
mod isa;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_chips.rs"]
mod rcan_chips;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

/// The glue owns the module's exit (`Scoped`): devices and drivers it
/// left registered are undone there.
type IsaModule = glue::module::Scoped<isa::IsaModule>;

module! {
    type: IsaModule,
    name: "rcan_i82527_isa",
    author: "rcan developers",
    description: "Intel 82527 front-end for memory-mapped ISA cards",
    license: "GPL",
}
