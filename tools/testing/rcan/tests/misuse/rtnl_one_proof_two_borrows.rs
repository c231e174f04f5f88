// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Forgeable proofs": each proof yields a fresh
//! `&mut`), with one proof: the data borrows the proof mutably, so a second
//! `&mut` from the same proof waits for the first to end. A guard: this was
//! already refused before the proofs were sealed, and must stay so.
// expect: E0499 cannot borrow `rtnl` as mutable more than once
#![forbid(unsafe_code)]

use crate::glue::sync::{Rtnl, RtnlLocked};

static COUNT: RtnlLocked<u32> = RtnlLocked::new(0);

pub(crate) fn aliased() {
    let mut rtnl = Rtnl::lock();
    let a: &mut u32 = COUNT.get(&mut rtnl);
    let b: &mut u32 = COUNT.get(&mut rtnl);
    *a += 1;
    *b += 1;
}
