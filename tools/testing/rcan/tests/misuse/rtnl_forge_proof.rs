// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Forgeable proofs": `RtnlProof` is an unsealed safe
//! trait): a protocol declares its own proof type and reaches RTNL-protected
//! data (a protocol's socket set) without RTNL, racing the netdevice
//! notifier that walks it under RTNL.
// expect: E0277 Sealed
#![forbid(unsafe_code)]

use crate::glue::sync::{RtnlLocked, RtnlProof};

static COUNT: RtnlLocked<u32> = RtnlLocked::new(0);

struct Forged;
impl RtnlProof for Forged {}

pub(crate) fn racy() {
    *COUNT.get(&mut Forged) += 1;
}
