// SPDX-License-Identifier: GPL-2.0

//! Crate root of `rcan_abiskew`, a test-only module (never installed) for
//! the VM test `modules_abi_mismatch` (issue 39, "a versioned module
//! ABI"): `rcan_exittest`'s code built with `--cfg rcan_abi_skew`, which
//! makes its glue claim the next ABI version (`rust/glue/can/abi.rs`), as
//! a protocol module built from another tree would. Loading it against
//! this tree's `rcan_pf` must fail cleanly (ENOEXEC and a log line naming
//! both ABIs) before it registers anything.

use kernel::prelude::*;

#[path = "exittest.rs"]
mod exittest;
#[path = "../../../../rust/glue/mod.rs"]
mod glue;
#[path = "../../../../net/can/rcan_core.rs"]
mod rcan_core;

/// The same module as `rcan_exittest`, under its own name.
type AbiSkew = glue::module::Scoped<exittest::ExitTest>;

module! {
    type: AbiSkew,
    name: "rcan_abiskew",
    author: "rcan developers",
    description: "test only: rcan_exittest built for another ABI version; must fail to load",
    license: "GPL",
}
