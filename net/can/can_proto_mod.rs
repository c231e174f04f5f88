// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_can`: the CANPROTO_CAN protocol in [`can_proto`] (`can_proto.rs`, which
//! is `#![forbid(unsafe_code)]`), the glue it builds on (`rust/glue/`, the
//! only place with `unsafe` code) and the shared pure logic
//! (`rcan_core`). Nothing else lives here: the module declaration must be
//! at the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod can_proto;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`).
type CanProtoModule = glue::module::Scoped<can_proto::CanProtoModule>;

// `alias`: what rcan_pf requests on socket(PF_CAN, ..., CANPROTO_CAN) while
// no module has registered protocol 16 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-16`.
module! {
    type: CanProtoModule,
    name: "rcan_can",
    author: "rcan developers",
    description: "CANPROTO_CAN: thesis CAN 2.0A/B socket protocol",
    license: "GPL",
    alias: ["rcan-proto-16"],
}
