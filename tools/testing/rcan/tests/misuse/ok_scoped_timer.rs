// SPDX-License-Identifier: GPL-2.0
//! Control: a module whose exit the glue owns (`Scoped`) initialises and
//! starts a static timer with the scope lent to its `init`, and needs no
//! exit code for it. If this fails, the misuse cases about timers and
//! scopes mean nothing.
// expect: ok
#![forbid(unsafe_code)]

use crate::glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use crate::glue::module::{ModuleScope, Scoped, ScopedModule};
use kernel::prelude::*;

struct Tick;

impl HrTimerCallback for Tick {
    type State = u32;
    fn run(timer: &'static HrTimer<Tick>, n: &mut u32) {
        *n += 1;
        timer.start(1_000_000_000);
    }
}

static TICK: HrTimer<Tick> = HrTimer::new();

pub(crate) struct Ticking;

impl ScopedModule for Ticking {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        TICK.init(scope, ClockId::Monotonic, HrTimerMode::RelativeSoft, 0)?;
        TICK.start(1_000_000_000);
        Ok(Ticking)
    }
}

/// What the crate root would name in `module!`.
pub(crate) type TickingModule = Scoped<Ticking>;
