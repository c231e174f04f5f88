// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_ctucanfd_sim`: the `module!` declaration and what
//! the module compiles in. The front-end itself is [`sim`] (`sim.rs`),
//! under `#![forbid(unsafe_code)]`; this file only wires the module
//! together (`module!` expands to unsafe code and `#[no_mangle]` entry
//! points, which a scope that forbids unsafe code rejects), beside the
//! glue (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "ctucanfd.rs"]
mod ctucanfd;
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

use sim::SimModule;

module! {
    type: SimModule,
    name: "rcan_ctucanfd_sim",
    author: "rcan developers",
    description: "Simulated CTU CAN FD cores on a simulated CAN bus, with fault injection",
    license: "GPL",
}
