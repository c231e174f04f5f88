// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_raw`: the CAN_RAW protocol in [`raw`] (`raw.rs`, which
//! is `#![forbid(unsafe_code)]`), the glue it builds on (`rust/glue/`, the
//! only place with `unsafe` code) and the shared pure logic
//! (`rcan_core`). Nothing else lives here: the module declaration must be
//! at the crate root (`module!` defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

mod raw;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`).
type RawModule = glue::module::Scoped<raw::RawModule>;

// `alias`: what rcan_pf requests on socket(PF_CAN, ..., CAN_RAW) while
// no module has registered protocol 1 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-1`.
module! {
    type: RawModule,
    name: "rcan_raw",
    author: "rcan developers",
    description: "CAN_RAW: SocketCAN-compatible raw CAN protocol",
    license: "GPL",
    alias: ["rcan-proto-1"],
}
