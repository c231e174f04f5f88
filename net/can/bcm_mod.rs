// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_bcm`: the CAN_BCM protocol in [`bcm`] (`bcm.rs`,
//! which is `#![forbid(unsafe_code)]`), the glue it builds on (`rust/glue/`,
//! the only place with `unsafe` code) and the shared pure logic
//! (`rcan_core`, whose `bcm`, `bcm_tx` and `bcm_rx` are the protocol's
//! state machines). Nothing else lives here: the module declaration must be
//! at the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod bcm;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`).
type BcmModule = glue::module::Scoped<bcm::BcmModule>;

// `alias`: what rcan_pf requests on socket(PF_CAN, SOCK_DGRAM, CAN_BCM)
// while no module has registered protocol 2 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-2`.
module! {
    type: BcmModule,
    name: "rcan_bcm",
    author: "rcan developers",
    description: "CAN_BCM: SocketCAN-compatible broadcast manager",
    license: "GPL",
    alias: ["rcan-proto-2"],
}
