// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_isotp`: the CAN_ISOTP protocol in [`isotp`]
//! (`isotp.rs`, which is `#![forbid(unsafe_code)]`), the glue it builds on
//! (`rust/glue/`, the only place with `unsafe` code) and the shared pure
//! logic (`rcan_core`, whose `isotp`, `isotp_pci`, `isotp_tx` and
//! `isotp_rx` are the protocol's option ABI, frame formats and state
//! machines). Nothing else lives here: the module declaration must be at
//! the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod isotp;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`).
type IsotpModule = glue::module::Scoped<isotp::IsotpModule>;

// `alias`: what rcan_pf requests on socket(PF_CAN, SOCK_DGRAM, CAN_ISOTP)
// while no module has registered protocol 6 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-6`.
module! {
    type: IsotpModule,
    name: "rcan_isotp",
    author: "rcan developers",
    description: "CAN_ISOTP: SocketCAN-compatible ISO 15765-2 transport",
    license: "GPL",
    alias: ["rcan-proto-6"],
}
