// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Forgeable proofs": `Rtnl::assert_held()` is safe and
//! only warns): called where RTNL is not held (a socket call, a timer),
//! it still hands out the proof, and with it `&mut` to RTNL-protected data
//! that a holder of RTNL may be using at the same time.
// expect: E0624 `assert_held` is private
#![forbid(unsafe_code)]

use crate::glue::sync::{Rtnl, RtnlLocked};

static COUNT: RtnlLocked<u32> = RtnlLocked::new(0);

pub(crate) fn not_under_rtnl() {
    let mut held = Rtnl::assert_held();
    *COUNT.get(&mut held) += 1;
}
