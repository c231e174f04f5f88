// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties; a guard of the fix for static
//! `HrTimer`s): a module that does not let the glue own its exit makes
//! the `ModuleScope` that `HrTimer::init` asks for itself, and its timer
//! outlives it as before the fix. The scope has a private field: only
//! `Scoped` makes one.
// expect: E0451 private
#![forbid(unsafe_code)]

use crate::glue::hrtimer::{ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use crate::glue::module::ModuleScope;
use kernel::prelude::*;

struct Tick;

impl HrTimerCallback for Tick {
    type State = ();
    fn run(_timer: &'static HrTimer<Tick>, _state: &mut ()) {}
}

static TICK: HrTimer<Tick> = HrTimer::new();

pub(crate) struct Forger;

impl kernel::Module for Forger {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let scope = ModuleScope { _private: () };
        TICK.init(&scope, ClockId::Monotonic, HrTimerMode::RelativeSoft, ())?;
        TICK.start(1_000_000_000);
        Ok(Forger)
    }
}
