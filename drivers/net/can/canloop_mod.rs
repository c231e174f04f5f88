// SPDX-License-Identifier: GPL-2.0

//! Module root of `rcan_loop`: the `module!` declaration and what the module
//! compiles in. The driver itself is [`canloop`] (`canloop.rs`), under
//! `#![forbid(unsafe_code)]`; this file only wires the module together
//! (`module!` expands to unsafe code and `#[no_mangle]` entry points,
//! which a scope that forbids unsafe code rejects), beside the glue
//! (`mod glue`), the only place with `unsafe`.

use kernel::prelude::*;

#[path = "canloop.rs"]
mod canloop;
#[path = "../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../net/can/rcan_core.rs"]
mod rcan_core;

/// The glue owns the module's exit (`Scoped`): devices and drivers it
/// left registered are undone there.
type CanLoop = glue::module::Scoped<canloop::CanLoop>;

module! {
    type: CanLoop,
    name: "rcan_loop",
    author: "rcan developers",
    description: "CAN loopback device (thesis canloop)",
    license: "GPL",
}

/// Called by canloop_c.c's parameter setter (process context) before it
/// stores a value: refusing one makes the write (or the load) fail with
/// EINVAL; a valid value is recorded for the transmit path
/// (`canloop::param_set`).
#[no_mangle]
extern "C" fn rcan_loop_param_record(which: i32, val: u32) -> bool {
    canloop::param_set(which, val)
}
