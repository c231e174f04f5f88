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
//! 0. the drops of freed socks' data that the glue deferred to process
//!    context (`sock::destruct` outside process context) are waited for;
//! 1. every static [`HrTimer`](super::hrtimer::HrTimer) of the module is
//!    killed: first all of them refuse to be started again, then each is
//!    cancelled (`hrtimer_cancel` waits for a running callback), so no
//!    callback of one timer can re-arm another behind the teardown's back;
//! 2. the module's protocols
//!    ([`ProtoModule::register`](super::can::proto::ProtoModule::register))
//!    are unregistered: only the exit does that (a `ProtoRegistration`
//!    is a proof, not a guard: unregistering while a socket is open would
//!    pull the protocol from under it), and no socket is left by now
//!    (every sock pins the module); then the module's own value (`T`) is
//!    dropped: its other registrations undo themselves in their own
//!    `Drop`s;
//! 3. every registration that the module made through a
//!    scope and that is still there (its guard forgotten, or kept in a
//!    `static`, which is never dropped) is removed: the in-kernel
//!    receivers ([`rx_set_kernel`](super::can::proto::rx_set_kernel)),
//!    the network devices
//!    ([`Registration::register`](super::netdev::Registration::register))
//!    and the PCI drivers
//!    ([`pci::Registration::register`](super::pci::Registration::register)),
//!    and the job timers still alive are killed
//!    ([`JobTimers::new`](super::jobtimer::JobTimers::new)),
//!    kind by kind in [`SweepKind`]'s order, each recorded in a table
//!    ([`ExitTable`]) or a list ([`ExitList`]) of its own;
//! 4. if the module's glue queued RCU callbacks (`call_rcu`, whose
//!    functions are in the module's text), `rcu_barrier()` waits for them.
//!
//! The same runs when `T::init` fails, after its partial state is gone.
//!
//! Things that need the duties done for them take a `&ModuleScope`, which
//! only [`Scoped`] makes, and only lends to `T::init` (and, through
//! [`lend_scope`], the glue's PCI probe trampoline to the probes of a
//! driver registered with the scope): a static timer can
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

/// Evidence that the code holding it runs in a module whose exit the glue
/// owns ([`Scoped`]), for what registers itself for the exit's sweeps at
/// run time, outside `init` (a job's timers): the [`ModuleScope`] itself,
/// a socket of a protocol the module registered with it
/// (`Sock<T: CanProtocol>`: only the glue's `create` trampoline, which
/// `ProtoModule::register(.., scope)` installs, makes one), or a device
/// the module registered with it (`netdev::Dev<T>`). Sealed: only the
/// glue implements it.
pub(crate) trait InScopedModule: sealed::Sealed {}

/// The seal of [`InScopedModule`], nameable in the glue only.
pub(super) mod sealed {
    pub(crate) trait Sealed {}
}

impl sealed::Sealed for ModuleScope {}
impl InScopedModule for ModuleScope {}

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
        // The drops of freed socks' data deferred to process context
        // first: they may drop anything a protocol kept (module text runs).
        super::sock::flush_deferred_drops();
        // Timers next: from here on nothing the module does can arm one.
        super::hrtimer::kill_all();
        // The protocols next (step 2): no socket of them is left (each
        // pins the module), and none of their calls runs while the
        // module's value goes.
        run_sweep(SweepKind::Protocols);
        drop(self.module.take());
        exit_duties();
    }
}

/// Runs the sweep of `kind`, if one was noted. Process context.
fn run_sweep(kind: SweepKind) {
    let sweep = SWEEPS[kind as usize].load(Ordering::Acquire);
    if !sweep.is_null() {
        // SAFETY: only `note_sweep` stores a non-null value, a `fn()`.
        let sweep: fn() = unsafe { core::mem::transmute::<*mut (), fn()>(sweep) };
        sweep();
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
    /// PCI drivers (`pci::Registration::register`): first, so that no
    /// probe adds a device behind the devices' sweep, and so that the
    /// drivers' `remove` drops the devices they own the usual way.
    PciDrivers,
    /// In-kernel receivers with `rcan_pf` (`can::proto::rx_set_kernel`).
    KernelRx,
    /// CAN protocols (`can::proto::ProtoModule::register`): all of them
    /// already at step 2 (before the module's value is dropped), so the
    /// sweep of step 3 finds none; a protocol registered by a failing
    /// `init` is unregistered here, before the devices, so that no
    /// notifier of the module runs while they go.
    Protocols,
    /// Job timers (`jobtimer::JobTimers::new`): killed (not freed), so
    /// that no callback of the module runs while its devices go.
    Jobs,
    /// Network devices (`netdev::Registration::register`), last: each
    /// with its filter listener, if a `Listening` owned it.
    Devices,
}

impl SweepKind {
    /// Every kind, in the order of step 3.
    const ALL: [SweepKind; NR_SWEEPS] = [
        SweepKind::PciDrivers,
        SweepKind::KernelRx,
        SweepKind::Protocols,
        SweepKind::Jobs,
        SweepKind::Devices,
    ];
}

/// Slots of [`SWEEPS`]: one per [`SweepKind`].
const NR_SWEEPS: usize = 5;

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
        if self.find(key as usize, undo as usize).is_some() {
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

    /// The slot recording `(key, undo)`, both compared as addresses only.
    fn find(&self, key: usize, undo: usize) -> Option<&ExitSlot> {
        self.slots.iter().find(|s| {
            s.key.load(Ordering::Acquire) as usize == key
                && s.undo.load(Ordering::Acquire) as usize == undo
        })
    }

    /// Takes back the slot of `(key, undo)`: true if it was recorded (the
    /// caller now undoes the registration itself, and the exit will not),
    /// false if it was not or the exit took it. Any context.
    ///
    /// # Safety
    ///
    /// Taking the slot takes the exit's duty: when this returns true, the
    /// registration `(key, undo)` is undone by the caller (or was never
    /// made), before the module's memory goes.
    pub(super) unsafe fn take(&self, key: *mut (), undo: unsafe fn(*mut ())) -> bool {
        match self.find(key as usize, undo as usize) {
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
    super::sock::flush_deferred_drops();
    super::hrtimer::kill_all();
    for kind in SweepKind::ALL {
        run_sweep(kind);
    }
    // Once more: a probe that ran before the PCI drivers' sweep may have
    // initialised a timer after the first kill.
    super::hrtimer::kill_all();
    // The store in note_rcu_callback happened before the call_rcu it
    // announces, in code that finished before the module's value was
    // dropped (its registrations are gone): no ordering beyond program
    // order and the teardown's own synchronisation is needed.
    if RCU_CALLBACKS.load(Ordering::Relaxed) {
        super::sync::rcu_barrier();
    }
}

/// A node of an [`ExitList`], inside the object it records (a device's
/// private area). Its fields belong to the list's lock.
pub(super) struct ExitNode(core::cell::UnsafeCell<NodeLinks>);

struct NodeLinks {
    prev: *mut ExitNode,
    next: *mut ExitNode,
    /// On the list (set by `push`, cleared by whoever unlinks it).
    on: bool,
    /// What `undo` is called with.
    key: *mut (),
    undo: Option<unsafe fn(*mut ())>,
}

// SAFETY: the links are only read or written with the owning list's lock
// held (ExitList); the node is otherwise plain data.
unsafe impl Sync for ExitNode {}
// SAFETY: as above.
unsafe impl Send for ExitNode {}

impl ExitNode {
    /// A node on no list.
    pub(super) const fn new() -> Self {
        ExitNode(core::cell::UnsafeCell::new(NodeLinks {
            prev: core::ptr::null_mut(),
            next: core::ptr::null_mut(),
            on: false,
            key: core::ptr::null_mut(),
            undo: None,
        }))
    }
}

/// The first node of an [`ExitList`].
struct ListHead(*mut ExitNode);

// SAFETY: the nodes it points to are only touched under the list's lock.
unsafe impl Send for ListHead {}

/// A per-module list of registrations that the module's exit undoes if
/// their owner did not (step 3), for kinds with no bound on their number
/// (a module's network devices: `rcan_loop` makes up to 16, a PCI driver
/// one per channel of every card): a doubly linked list through
/// [`ExitNode`]s inside the registered objects themselves, so recording
/// one allocates nothing, cannot fail, and costs O(1) both ways. Like
/// [`ExitTable`], each registration is undone exactly once, by its
/// owner ([`ExitList::remove`] true) or by the exit
/// ([`ExitList::sweep`]), whichever unlinks it first.
///
/// The lock is a spinlock taken with interrupts disabled (never slept
/// under), so `push` and `remove` work in any context.
///
/// # Invariants
///
/// Every node on the list was pushed with the contract of
/// [`ExitList::push`] and not unlinked since; `head` and the links of the
/// nodes on it name nodes on it, or are null.
pub(super) struct ExitList {
    head: super::lock::StaticIrqSpinLock<ListHead>,
}

impl ExitList {
    /// An empty list, for a `static`; `name` is its lock's lockdep name.
    pub(super) const fn new(name: &'static kernel::str::CStr) -> Self {
        ExitList {
            head: super::lock::StaticIrqSpinLock::new(ListHead(core::ptr::null_mut()), name),
        }
    }

    /// Records `node` (not on a list), to be undone by `undo(key)` at the
    /// module's exit unless [`ExitList::remove`] takes it off first, and
    /// that the exit sweeps this list (`kind`, `sweep`, which calls
    /// [`ExitList::sweep`] on it). Any context.
    ///
    /// # Safety
    ///
    /// Until `remove(node)` returns or the exit unlinks it: `node` stays
    /// at its address, and calling `undo(key)` once, in process context at
    /// the module's exit, is sound (it may free the node).
    pub(super) unsafe fn push(
        &'static self,
        node: &ExitNode,
        key: *mut (),
        undo: unsafe fn(*mut ()),
        kind: SweepKind,
        sweep: fn(),
    ) {
        note_sweep(kind, sweep);
        let me = core::ptr::from_ref(node).cast_mut();
        let mut head = self.head.lock();
        // SAFETY: the node is ours until published below; the old head, if
        // any, is on the list, whose lock we hold.
        unsafe {
            let l = &mut *node.0.get();
            l.prev = core::ptr::null_mut();
            l.next = head.0;
            l.on = true;
            l.key = key;
            l.undo = Some(undo);
            if !head.0.is_null() {
                (*(*head.0).0.get()).prev = me;
            }
        }
        // INVARIANT: pushed with push's contract (the caller's), linked
        // in front.
        head.0 = me;
    }

    /// Takes `node` off the list: true if it was on it (the caller now
    /// undoes the registration itself, and the exit will not), false if
    /// it never was or the exit took it (and undoes it, or did). Any
    /// context.
    pub(super) fn remove(&'static self, node: &ExitNode) -> bool {
        let mut head = self.head.lock();
        // SAFETY: the node's links are ours under the lock; a node on the
        // list has neighbours on it (type invariant).
        unsafe { Self::unlink(&mut head, core::ptr::from_ref(node).cast_mut()) }
    }

    /// Unlinks `n` if it is on the list; returns whether it was.
    ///
    /// # Safety
    ///
    /// `head` is this list's, locked; `n` is a valid node.
    unsafe fn unlink(head: &mut ListHead, n: *mut ExitNode) -> bool {
        // SAFETY: valid node (contract), links under the held lock.
        let l = unsafe { &mut *(*n).0.get() };
        if !l.on {
            return false;
        }
        if l.prev.is_null() {
            head.0 = l.next;
        } else {
            // SAFETY: a neighbour of a node on the list is on it.
            unsafe { (*(*l.prev).0.get()).next = l.next };
        }
        if !l.next.is_null() {
            // SAFETY: as above.
            unsafe { (*(*l.next).0.get()).prev = l.prev };
        }
        l.on = false;
        l.prev = core::ptr::null_mut();
        l.next = core::ptr::null_mut();
        true
    }

    /// Undoes every registration still on the list, one at a time: each
    /// is unlinked under the lock, then undone without it. The exit's
    /// sweep of this list (step 3): process context, after the module's
    /// value was dropped; sleeps if the undos do.
    pub(super) fn sweep(&'static self) {
        loop {
            let (key, undo) = {
                let mut head = self.head.lock();
                let n = head.0;
                if n.is_null() {
                    return;
                }
                // SAFETY: the head is a node on the list (type invariant),
                // valid until undone; its links are ours under the lock.
                unsafe {
                    let l = &*(*n).0.get();
                    let ku = (l.key, l.undo);
                    Self::unlink(&mut head, n);
                    ku
                }
            };
            if let Some(undo) = undo {
                // The node was pushed with this key and undo, and is
                // unlinked now (by us), so this is the one undo; we run at
                // the module's exit in process context. The node is not
                // touched after.
                // SAFETY: so this is push's contract.
                unsafe { undo(key) };
            }
        }
    }
}

/// Lends the module's scope to `f`, for a callback that the glue installs
/// only for a module whose exit it owns: a PCI driver's `probe`
/// (`pci::Registration::register` takes the scope, so its probes belong
/// to a [`Scoped`] module, and the exit unregisters the driver before it
/// sweeps the devices). Process context.
pub(super) fn lend_scope<R>(f: impl FnOnce(&ModuleScope) -> R) -> R {
    f(&ModuleScope { _private: () })
}
