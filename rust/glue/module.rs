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
//!    ([`ProtoModule::register`](super::can::proto::ProtoModule::register)),
//!    each kind recorded in a table of its own ([`ExitTable`]);
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

/// The kinds of registration whose leftovers the exit removes (step 3),
/// in the order it removes them: each kind's sweep has its own slot of
/// [`SWEEPS`], so a new kind is a new variant here (and the order is the
/// enum's, not the order in which a module happened to register things).
#[derive(Clone, Copy)]
#[repr(usize)]
pub(super) enum SweepKind {
    /// In-kernel receivers with `rcan_pf` (`can::proto::rx_set_kernel`).
    KernelRx,
    /// CAN protocols (`can::proto::ProtoModule::register`).
    Protocols,
}

/// Slots of [`SWEEPS`]: one per [`SweepKind`].
const NR_SWEEPS: usize = 2;

/// The sweeps of step 3, one slot per [`SweepKind`], each stored by the
/// first registration of its kind (null: none), so that a module that
/// registers nothing with `rcan_pf` does not reference `rcan_pf`'s
/// symbols from its exit.
static SWEEPS: [AtomicPtr<()>; NR_SWEEPS] =
    [const { AtomicPtr::new(core::ptr::null_mut()) }; NR_SWEEPS];

/// Records that the exit must run `sweep` for registrations of `kind`
/// (step 3): it removes what the module's glue registered of that kind
/// and is still registered. Any context.
pub(super) fn note_sweep(kind: SweepKind, sweep: fn()) {
    SWEEPS[kind as usize].store(sweep as *mut (), Ordering::Release);
}

/// A per-module table of registrations that the module's exit undoes if
/// their owner did not (step 3): the glue is compiled into each module,
/// so each `static` of this type is one module's. Each slot records a
/// registration by a key (the address of what was registered, never
/// null) and its type-erased undo, called with the key. A registration's
/// own teardown (a guard's `Drop`) takes its slot back with
/// [`ExitTable::take`] first; the exit's sweep ([`ExitTable::sweep`])
/// takes and undoes whatever is left, so each registration is undone
/// exactly once, by whichever comes first.
///
/// For kinds with a few registrations per module (its protocols, its
/// kernel receivers): bounded, ENOSPC beyond `N`.
///
/// # Invariants
///
/// A slot with a non-null `key` holds in `undo` an `unsafe fn(*mut ())`
/// that may be called once with that key, in process context, until the
/// slot is taken back ([`ExitTable::note`]'s contract).
pub(super) struct ExitTable<const N: usize> {
    slots: [ExitSlot; N],
}

struct ExitSlot {
    /// The registration's key; null: the slot is free.
    key: AtomicPtr<()>,
    /// Its undo (`unsafe fn(*mut ())`), valid while `key` is not null.
    undo: AtomicPtr<()>,
}

impl<const N: usize> ExitTable<N> {
    /// An empty table, for a `static`.
    pub(super) const fn new() -> Self {
        ExitTable {
            slots: [const {
                ExitSlot {
                    key: AtomicPtr::new(core::ptr::null_mut()),
                    undo: AtomicPtr::new(core::ptr::null_mut()),
                }
            }; N],
        }
    }

    /// Records the registration `(key, undo)` (once: recording it again
    /// finds its slot) and that the exit sweeps this table (`kind`,
    /// `sweep`, which calls [`ExitTable::sweep`] on it). Returns whether
    /// the slot is new; ENOSPC when all `N` are taken. Process context;
    /// notes of one table are serialised by their callers (module init,
    /// which lends the scope they need).
    ///
    /// # Safety
    ///
    /// From now until [`ExitTable::take`] returns true for `(key, undo)`,
    /// calling `undo(key)` once, in process context at the module's exit
    /// (after the module's value was dropped), is sound.
    pub(super) unsafe fn note(
        &self,
        key: *mut (),
        undo: unsafe fn(*mut ()),
        kind: SweepKind,
        sweep: fn(),
    ) -> Result<bool> {
        let undo = undo as *mut ();
        if self.find(key, undo).is_some() {
            return Ok(false);
        }
        let slot = self
            .slots
            .iter()
            .find(|s| {
                s.key
                    .compare_exchange(
                        core::ptr::null_mut(),
                        key,
                        Ordering::AcqRel,
                        Ordering::Acquire,
                    )
                    .is_ok()
            })
            .ok_or(ENOSPC)?;
        // INVARIANT: the caller's contract; `undo` is published before the
        // exit, which follows every note.
        slot.undo.store(undo, Ordering::Release);
        note_sweep(kind, sweep);
        Ok(true)
    }

    fn find(&self, key: *mut (), undo: *mut ()) -> Option<&ExitSlot> {
        self.slots.iter().find(|s| {
            s.key.load(Ordering::Acquire) == key && s.undo.load(Ordering::Acquire) == undo
        })
    }

    /// Takes back the slot of `(key, undo)`: true if it was recorded (the
    /// caller now undoes the registration itself, and the exit will not),
    /// false if it was not or the exit took it. Any context.
    pub(super) fn take(&self, key: *mut (), undo: unsafe fn(*mut ())) -> bool {
        match self.find(key, undo as *mut ()) {
            Some(s) => s
                .key
                .compare_exchange(key, core::ptr::null_mut(), Ordering::AcqRel, Ordering::Acquire)
                .is_ok(),
            None => false,
        }
    }

    /// Undoes every registration still recorded, freeing its slot. The
    /// exit's sweep of this table (step 3): process context, after the
    /// module's value was dropped; sleeps if the undos do.
    pub(super) fn sweep(&self) {
        for s in self.slots.iter() {
            let key = s.key.swap(core::ptr::null_mut(), Ordering::AcqRel);
            if key.is_null() {
                continue;
            }
            let undo = s.undo.load(Ordering::Acquire);
            // SAFETY: a non-null key was stored with an `unsafe
            // fn(*mut ())` (type invariant), published before the exit.
            let undo = unsafe { core::mem::transmute::<*mut (), unsafe fn(*mut ())>(undo) };
            // SAFETY: the slot was recorded with this key and undo, and is
            // now taken (swapped to null), so this is the one undo; we run
            // at the module's exit in process context (note's contract).
            unsafe { undo(key) };
        }
    }
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
