// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_rtime`: the DSOR remote time service in [`rtime`] (`rtime.rs`, which is
//! `#![forbid(unsafe_code)]`), the glue it builds on (`rust/glue/`, the only
//! place with `unsafe` code) and the shared pure logic (`rcan_core`).
//! Nothing else lives here: `module!` expands to unsafe code and must be
//! at the crate root (it defines the crate's log prefix).

use kernel::prelude::*;

#[path = "../../../rust/glue/mod.rs"]
mod glue;
#[path = "../rcan_api.rs"]
mod rcan_api;
#[path = "../rcan_core.rs"]
mod rcan_core;
mod ticker;
mod ticker_abi;

mod rtime;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (rust/glue/module.rs).
type RtimeModule = glue::module::Scoped<rtime::RtimeModule>;

module! {
    type: RtimeModule,
    name: "rcan_rtime",
    author: "rcan developers",
    description: "Redundant DSOR time service: sends the time CAN frame while the usual source is silent (thesis dsor/rtime)",
    license: "GPL",
}
