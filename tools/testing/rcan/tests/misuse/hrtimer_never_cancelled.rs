// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, "Teardown duties left to safe code": static
//! `HrTimer`s must be cancelled at exit): a module starts a static timer
//! and its exit forgets to cancel it; `rmmod` frees the module's text and
//! data while the timer is queued, and its expiry calls into freed
//! memory. Now only a module whose exit the glue owns (`Scoped`, which
//! kills every timer of the module) has the `ModuleScope` that `init`
//! takes.
// expect: E0061 this method takes 4 arguments but 3 arguments were supplied
#![forbid(unsafe_code)]

use crate::glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use kernel::prelude::*;

struct Tick;

impl HrTimerCallback for Tick {
    type State = ();
    fn run(timer: &'static HrTimer<Tick>, _state: &mut ()) {
        timer.start(1_000_000_000);
    }
}

static TICK: HrTimer<Tick> = HrTimer::new();

pub(crate) struct Forgetful;

impl kernel::Module for Forgetful {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        TICK.init(ClockId::Monotonic, HrTimerMode::RelativeSoft, ())?;
        TICK.start(1_000_000_000);
        Ok(Forgetful)
    }
}
