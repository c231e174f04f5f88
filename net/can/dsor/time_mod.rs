// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_time`: the DSOR time service in [`time`] (`time.rs`, which is
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

mod time;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (rust/glue/module.rs).
type TimeModule = glue::module::Scoped<time::TimeModule>;

module! {
    type: TimeModule,
    name: "rcan_time",
    author: "rcan developers",
    description: "DSOR time service: the time CAN frame at every second (thesis dsor/time)",
    license: "GPL",
}
