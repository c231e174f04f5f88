// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_exittest`, a test-only module (never installed):
//! the module itself is [`exittest`] (`exittest.rs`, which is
//! `#![forbid(unsafe_code)]`), built on the glue (`rust/glue/`) like every
//! protocol and driver module.

use kernel::prelude::*;

mod exittest;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

/// `module!` takes a plain name: the glue's wrapper, which owns the exit
/// duties (`rust/glue/module.rs`), the subject of this module's test.
type ExitTest = glue::module::Scoped<exittest::ExitTest>;

module! {
    type: ExitTest,
    name: "rcan_exittest",
    author: "rcan developers",
    description: "test only: forgets one registration of each kind the module exit sweeps",
    license: "GPL",
}
