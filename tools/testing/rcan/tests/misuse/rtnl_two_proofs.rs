// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Forgeable proofs": each proof yields a fresh `&mut`,
//! so two proofs give two aliasing `&mut SockSet`): RTNL really is held
//! (by the guard), and a second proof made beside it borrows the same data
//! mutably a second time.
// expect: E0624 `assert_held` is private
#![forbid(unsafe_code)]

use crate::glue::sync::{Rtnl, RtnlLocked};

static COUNT: RtnlLocked<u32> = RtnlLocked::new(0);

pub(crate) fn aliased() {
    let mut rtnl = Rtnl::lock();
    let mut held = Rtnl::assert_held();
    let a: &mut u32 = COUNT.get(&mut rtnl);
    let b: &mut u32 = COUNT.get(&mut held);
    *a += 1;
    *b += 1;
}
