// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_j1939`: the CAN_J1939 protocol in [`j1939`]
//! (`j1939.rs`, which is `#![forbid(unsafe_code)]`), the glue it builds on
//! (`rust/glue/`, the only place with `unsafe` code) and the shared pure
//! logic (`rcan_core`, whose `j1939` is the protocol's ABI, addressing
//! and receive matching). Nothing else lives here: the module declaration
//! must be at the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod j1939;
mod j1939_echo;
mod j1939_tp;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`).
type J1939Module = glue::module::Scoped<j1939::J1939Module>;

// `alias`: what rcan_pf requests on socket(PF_CAN, SOCK_DGRAM, CAN_J1939)
// while no module has registered protocol 7 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-7`.
module! {
    type: J1939Module,
    name: "rcan_j1939",
    author: "rcan developers",
    description: "CAN_J1939: SocketCAN-compatible SAE J1939",
    license: "GPL",
    alias: ["rcan-proto-7"],
}
