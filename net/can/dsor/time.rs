// SPDX-License-Identifier: GPL-2.0

//! rcan_time: the DSOR time service (thesis 5.3.3, `net/can/dsor/time.c`).
//!
//! Sends the time frame (DSOR wire specification, "Time frame": standard
//! identifier `vehicle`, the UNIX second big-endian, source 1) on the
//! interface `dev` at the start of every second of Linux time
//! (`CLOCK_REALTIME`), with local loopback so that programs on this host
//! see it too. The timers, the clock-step handling and the sending are in
//! `ticker.rs`; see Documentation/networking/rcan/time.rst.
//!
//! Parameters (C side, `time_c.c`): `vehicle` (default 0xc0, only bits 4-7
//! may be set), `dev` (default "can0"); both fixed at load.

#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::glue::module::{ModuleScope, ScopedModule};
use crate::ticker;

pub(crate) struct TimeModule;

impl ScopedModule for TimeModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let p = ticker::start(scope, false)?;
        pr_info!(
            "{}: sending time frame {:03x} at every second\n",
            p.dev.as_str(),
            p.vehicle
        );
        Ok(TimeModule)
    }
}

impl Drop for TimeModule {
    fn drop(&mut self) {
        ticker::stop();
        let s = ticker::stats();
        pr_info!(
            "stopped: {} frames sent, {} seconds skipped, {} seconds missed (late timer), {} backward clock steps caught\n",
            s.sent,
            s.skipped,
            s.missed,
            s.steps_back
        );
    }
}
