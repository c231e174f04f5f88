// SPDX-License-Identifier: GPL-2.0

//! A module's lifetime as a type: the exit duties the glue owns.
//!
//! A module built on the glue implements [`ScopedModule`] instead of
//! `kernel::Module`, and its crate root names [`Scoped<T>`] (through a type
//! alias: `module!` takes a plain name) as the `module!` type. `module!`
//! keeps that value for as long as the module is loaded and drops it at
//! `rmmod`; [`Scoped`]'s `Drop` then does what every module would
//! otherwise have to remember, in the order the kernel needs, whatever
//! the module's own fields and `Drop` do:
//!
//! 1. every static [`HrTimer`](super::hrtimer::HrTimer) of the module is
//!    killed: first all of them refuse to be started again, then each is
//!    cancelled (`hrtimer_cancel` waits for a running callback), so no
//!    callback of one timer can re-arm another behind the teardown's back;
//! 2. the module's own value (`T`) is dropped: its registrations undo
//!    themselves in their own `Drop`s;
//! 3. every registration with `rcan_pf` that the module made through a
//!    scope and that is still there (its guard forgotten, or kept in a
//!    `static`, which is never dropped) is removed: the in-kernel
//!    receivers ([`rx_set_kernel`](super::can::proto::rx_set_kernel)) and
//!    the protocols
//!    ([`ProtoModule::register`](super::can::proto::ProtoModule::register));
//! 4. if the module's glue queued RCU callbacks (`call_rcu`, whose
//!    functions are in the module's text), `rcu_barrier()` waits for them.
//!
//! The same runs when `T::init` fails, after its partial state is gone.
//!
//! Things that need the duties done for them take a `&ModuleScope`, which
//! only [`Scoped`] makes, and only lends to `T::init`: a static timer can
//! be initialised, and a kernel receiver or a protocol registered, only
//! by a module whose exit kills or removes it, and the lifetime keeps the scope from
//! being kept for later. `mem::forget` cannot skip steps 1, 3 or 4: the
//! value `module!` drops is the glue's, not the module's.
//!
//! Context: `init` and `drop` run in process context (`insmod`, `rmmod`),
//! may sleep; nothing else runs them.

use core::sync::atomic::{AtomicBool, AtomicPtr, Ordering};
use kernel::prelude::*;

/// Proof that the code holding it runs inside [`ScopedModule::init`] of a
/// module whose exit the glue owns ([`Scoped`]). Not constructible outside
/// this file, not `Clone`: only lent, for the length of `init`.
pub(crate) struct ModuleScope {
    _private: (),
}

/// A module whose exit duties the glue carries ([`Scoped`]).
pub(crate) trait ScopedModule: Sized + Sync + Send {
    /// Loads the module: process context, may sleep. `scope` lets it set
    /// up things whose teardown the glue owns (static timers).
    fn init(module: &'static ThisModule, scope: &ModuleScope) -> Result<Self>;
}

/// The `module!` type of a [`ScopedModule`] `T`: runs `T::init`, and at
/// exit (or when `init` fails) the duties in this file's documentation.
pub(crate) struct Scoped<T: ScopedModule> {
    /// `Some` from a successful `init` until `drop`.
    module: Option<T>,
}

impl<T: ScopedModule> kernel::Module for Scoped<T> {
    fn init(module: &'static ThisModule) -> Result<Self> {
        let scope = ModuleScope { _private: () };
        match T::init(module, &scope) {
            Ok(m) => Ok(Scoped { module: Some(m) }),
            Err(e) => {
                exit_duties();
                Err(e)
            }
        }
    }
}

impl<T: ScopedModule> Drop for Scoped<T> {
    fn drop(&mut self) {
        // Timers first: from here on nothing the module does can arm one.
        super::hrtimer::kill_all();
        drop(self.module.take());
        exit_duties();
    }
}

/// Set (never cleared: the module's statics start fresh at every load)
/// once the glue queued an RCU callback whose function is in this module.
static RCU_CALLBACKS: AtomicBool = AtomicBool::new(false);

/// The sweeps of step 3 (one per kind of registration), each stored by
/// the first registration that needs it (null: none), so that a module
/// that registers nothing with `rcan_pf` does not reference `rcan_pf`'s
/// symbols from its exit.
static SWEEPS: [AtomicPtr<()>; 2] = [const { AtomicPtr::new(core::ptr::null_mut()) }; 2];

/// Records that the exit must run `sweep` (step 3): it removes what the
/// module's glue registered and is still registered. Process context.
pub(super) fn note_sweep(sweep: fn()) {
    let f = sweep as *mut ();
    for s in SWEEPS.iter() {
        match s.compare_exchange(
            core::ptr::null_mut(),
            f,
            Ordering::AcqRel,
            Ordering::Acquire,
        ) {
            Ok(_) => return,
            Err(cur) if cur == f => return,
            Err(_) => {}
        }
    }
    // One slot per kind of registration in the glue: a new kind needs a
    // new slot (a build-time constant), not a silent skip.
    panic!("glue::module: more kinds of registration than SWEEPS has slots");
}

/// Records that the glue is about to hand a function of this module to
/// `call_rcu`, so that the exit waits for it ([`Scoped`]'s step 3). Any
/// context.
pub(super) fn note_rcu_callback() {
    RCU_CALLBACKS.store(true, Ordering::Relaxed);
}

/// Steps 1 (again: nothing may have armed a timer since, but it is
/// idempotent and cheap), 3 and 4. Process context.
fn exit_duties() {
    super::hrtimer::kill_all();
    for s in SWEEPS.iter() {
        let sweep = s.load(Ordering::Acquire);
        if !sweep.is_null() {
            // SAFETY: only `note_sweep` stores a non-null value, a `fn()`.
            let sweep: fn() = unsafe { core::mem::transmute::<*mut (), fn()>(sweep) };
            sweep();
        }
    }
    // The store in note_rcu_callback happened before the call_rcu it
    // announces, in code that finished before the module's value was
    // dropped (its registrations are gone): no ordering beyond program
    // order and the teardown's own synchronisation is needed.
    if RCU_CALLBACKS.load(Ordering::Relaxed) {
        super::sync::rcu_barrier();
    }
}
