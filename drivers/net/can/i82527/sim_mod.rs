// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_i82527_sim`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`sim`] (`sim.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "i82527.rs"]
mod i82527;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_chips.rs"]
mod rcan_chips;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;
#[path = "sim.rs"]
mod sim;

use sim::SimModule;

module! {
    type: SimModule,
    name: "rcan_i82527_sim",
    author: "rcan developers",
    description: "Simulated Intel 82527 cards on a simulated CAN bus",
    license: "GPL",
}
