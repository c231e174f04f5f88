// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_dsor`: the DSOR protocol and UDP/IP over CAN in
//! one file per concern, each `#![forbid(unsafe_code)]` (the list is in
//! [`candsor`], `candsor.rs`), the glue they build on (`rust/glue/`, the
//! only place with `unsafe` code) and the shared pure logic (`rcan_core`).
//! Nothing else lives here: `module!` expands to unsafe code and must be
//! at the crate root (it defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../../rust/glue/mod.rs"]
mod glue;
#[path = "../rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_core.rs"]
mod rcan_core;

mod candsor;
mod engine;
mod params;
mod rx;
mod socket;
mod stats;
mod timers;
mod udpip;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (rust/glue/module.rs).
type DsorModule = glue::module::Scoped<candsor::DsorModule>;

// `alias`: what rcan_pf requests on socket(PF_CAN, ..., CANPROTO_DSOR) while
// no module has registered protocol 17 (`request_proto_module` in
// rust/glue/can/family.rs); "rcan-" so that it never names mainline's
// `can-proto-17`.
module! {
    type: DsorModule,
    name: "rcan_dsor",
    author: "rcan developers",
    description: "CANPROTO_DSOR: the DSOR higher-layer CAN protocol and UDP/IP over CAN (thesis candsor)",
    license: "GPL",
    alias: ["rcan-proto-17"],
}
