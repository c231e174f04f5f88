// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_sja1000_sim`: the `module!` declaration and what
//! the module compiles in. The front-end itself is [`sim`] (`sim.rs`),
//! under `#![forbid(unsafe_code)]`; this file only wires the module
//! together (`module!` expands to unsafe code and `#[no_mangle]` entry
//! points, which a scope that forbids unsafe code rejects), beside the
//! glue (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../net/can/rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_chips.rs"]
mod rcan_chips;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;
#[path = "sim.rs"]
mod sim;
#[path = "sja1000.rs"]
mod sja1000;

use sim::SimModule;

module! {
    type: SimModule,
    name: "rcan_sja1000_sim",
    author: "rcan developers",
    description: "Simulated SJA1000 cards on a simulated CAN bus, with fault injection",
    license: "GPL",
}
