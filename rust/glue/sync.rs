// SPDX-License-Identifier: GPL-2.0

//! RCU, RTNL and C-defined mutexes.
//!
//! * [`RcuReadGuard`]: an RCU read-side critical section (any context).
//! * [`RcuPtr`]: a pointer published under RCU: readers load it inside a
//!   read-side section, writers swap it under their own lock and free the
//!   old object after a grace period.
//! * [`Rtnl`]: the RTNL mutex (process context).
//! * [`CMutex`]: data protected by a `struct mutex` defined in the module's
//!   C file with `DEFINE_MUTEX` (6.12's `kernel::sync::Mutex` cannot be a
//!   plain `static`).

use super::bindings;
use core::cell::UnsafeCell;
use core::marker::PhantomData;
use core::ops::{Deref, DerefMut};
use core::sync::atomic::{AtomicPtr, Ordering};

/// An RCU read-side critical section; ends when dropped. Not `Send`: it must
/// end on the CPU and in the context that started it.
pub(crate) struct RcuReadGuard(PhantomData<*mut ()>);

impl RcuReadGuard {
    /// Enters a read-side critical section. Any context.
    pub(crate) fn new() -> Self {
        // SAFETY: rcu_read_lock() may be called in any context; the matching
        // unlock is in Drop.
        unsafe { bindings::rcan_rcu_read_lock() };
        RcuReadGuard(PhantomData)
    }

    /// The read-side section the caller is already in, as a guard that
    /// does not end it when dropped: a callback the core runs inside its
    /// own `rcu_read_lock()` (a packet handler) hands this to code that
    /// asks for a guard, and saves the nested lock and unlock (two calls
    /// into the RCU core under PREEMPT_RCU).
    ///
    /// # Safety
    ///
    /// The caller is inside an RCU read-side critical section that lasts
    /// at least as long as the returned value, on this CPU.
    #[inline]
    pub(crate) unsafe fn assume_held() -> core::mem::ManuallyDrop<Self> {
        core::mem::ManuallyDrop::new(RcuReadGuard(PhantomData))
    }
}

impl Drop for RcuReadGuard {
    fn drop(&mut self) {
        // SAFETY: paired with the rcu_read_lock() in new().
        unsafe { bindings::rcan_rcu_read_unlock() };
    }
}

/// Waits for all pending `call_rcu` callbacks. Process context; sleeps.
/// The glue's module exit calls it ([`super::module::Scoped`]) so that no
/// callback runs after the code is gone.
pub(super) fn rcu_barrier() {
    // SAFETY: callers are in process context (documented contract).
    unsafe { bindings::rcu_barrier() };
}

/// A pointer to a heap object published under RCU.
///
/// Readers: [`RcuPtr::read`] inside an [`RcuReadGuard`]. Writers: must be
/// serialised by a lock of their own (named at each `RcuPtr` definition);
/// [`RcuPtr::replace`] publishes the new object with release ordering
/// (`rcu_assign_pointer`) and returns the old one, which the writer frees only
/// after a grace period.
pub(crate) struct RcuPtr<T> {
    ptr: AtomicPtr<T>,
}

// SAFETY: the pointee is only shared through `&T` with readers on any CPU,
// and moved between CPUs by writers: `T: Send + Sync` makes that sound.
unsafe impl<T: Send + Sync> Sync for RcuPtr<T> {}

impl<T> RcuPtr<T> {
    /// An empty (NULL) pointer.
    pub(crate) const fn null() -> Self {
        RcuPtr {
            ptr: AtomicPtr::new(core::ptr::null_mut()),
        }
    }

    /// `rcu_dereference`: the current object, valid while `_guard` lives.
    pub(crate) fn read<'a>(&self, _guard: &'a RcuReadGuard) -> Option<&'a T> {
        let p = self.ptr.load(Ordering::Acquire);
        // SAFETY: writers publish only fully initialised objects (release
        // store in replace()) and free replaced objects only after a grace
        // period, which cannot end while `_guard` holds the read lock.
        unsafe { p.as_ref() }
    }

    /// `rcu_assign_pointer`: publishes `new` and returns the previous
    /// pointer.
    ///
    /// # Safety
    ///
    /// The caller holds the writers' lock; `new` is NULL or points to a
    /// fully initialised `T` that stays valid until it is replaced and a
    /// grace period has elapsed after that (readers get `&T` from
    /// [`RcuPtr::read`]); the caller owns the returned object and must not
    /// free it before a grace period has elapsed.
    pub(crate) unsafe fn replace(&self, new: *mut T) -> *mut T {
        self.ptr.swap(new, Ordering::AcqRel)
    }

    /// The current pointer, for writers (who hold the writers' lock).
    pub(crate) fn get_locked(&self) -> *mut T {
        self.ptr.load(Ordering::Acquire)
    }
}

/// Holding the RTNL mutex. Process context; sleeps.
///
/// # Invariants
///
/// Made only by [`Rtnl::lock`]: RTNL is held by this thread until the
/// value is dropped. Not `Send`: it must be unlocked where it was locked.
pub(crate) struct Rtnl(PhantomData<*mut ()>);

impl Rtnl {
    /// Takes the RTNL mutex.
    pub(crate) fn lock() -> Self {
        // SAFETY: process context (callers' contract); unlocked in Drop.
        // Called directly (an exported function): no C helper in between.
        unsafe { bindings::rtnl_lock() };
        // INVARIANT: locked just above.
        Rtnl(PhantomData)
    }

    /// For the glue's own trampolines that the kernel calls with RTNL
    /// already held (netdevice notifiers): a proof, for the call, that
    /// does not unlock. `ASSERT_RTNL` checks the claim where the kernel
    /// can (it warns; it cannot stop a caller).
    ///
    /// # Safety
    ///
    /// RTNL is held by this thread for all of `'a`, by a caller that uses
    /// no proof of its own meanwhile: the returned proof is then the only
    /// one in use, so the `&mut` it gives (through [`RtnlLocked::get`])
    /// aliases nothing. Safe code above the glue never holds RTNL but
    /// through an [`Rtnl`] guard or a proof the glue lends it.
    pub(in crate::glue) unsafe fn assert_held<'a>() -> RtnlHeld<'a> {
        // SAFETY: ASSERT_RTNL only reads the lock state.
        unsafe { bindings::rcan_assert_rtnl() };
        // INVARIANT: this function's contract.
        RtnlHeld(PhantomData)
    }
}

impl Drop for Rtnl {
    fn drop(&mut self) {
        // SAFETY: paired with rtnl_lock() in lock().
        unsafe { bindings::rtnl_unlock() };
    }
}

/// Proof that RTNL is held by a caller further up, for `'a` (see
/// [`Rtnl::assert_held`]): the glue makes one where the kernel calls it
/// with RTNL held, and lends it out; nothing else can make one.
///
/// # Invariants
///
/// RTNL is held by this thread for `'a`, and no other proof of it is in
/// use meanwhile. Neither `Send` nor `Sync`.
pub(crate) struct RtnlHeld<'a>(PhantomData<(&'a (), *mut ())>);

mod private {
    /// Seals [`super::RtnlProof`]: a supertrait nobody outside this file
    /// can name, so no type outside it can implement the proof trait.
    pub(crate) trait Sealed {}
    impl Sealed for super::Rtnl {}
    impl Sealed for super::RtnlHeld<'_> {}
}

/// Something that proves RTNL is held: an [`Rtnl`] guard or an
/// [`RtnlHeld`] the glue lent. Sealed: no other type can implement it,
/// so a value of it is never a forgery, and as each one is unique for
/// its holding of RTNL, borrowing it mutably (as [`RtnlLocked::get`]
/// does) gives one `&mut` at a time.
pub(crate) trait RtnlProof: private::Sealed {}
impl RtnlProof for Rtnl {}
impl RtnlProof for RtnlHeld<'_> {}

/// Data protected by RTNL.
pub(crate) struct RtnlLocked<T> {
    data: UnsafeCell<T>,
}

// SAFETY: access only through `get`, which requires proof that RTNL is held,
// so at most one thread touches `data` at a time.
unsafe impl<T: Send> Sync for RtnlLocked<T> {}

impl<T> RtnlLocked<T> {
    pub(crate) const fn new(data: T) -> Self {
        RtnlLocked {
            data: UnsafeCell::new(data),
        }
    }

    /// The data, for as long as the RTNL proof is borrowed.
    #[allow(clippy::mut_from_ref)]
    pub(crate) fn get<'a>(&'a self, _rtnl: &'a mut dyn RtnlProof) -> &'a mut T {
        // A proof can only be an `Rtnl` or an `RtnlHeld` (sealed); it is
        // borrowed mutably for 'a and is the only one in use while RTNL is
        // held (their invariants), so no second `&mut T` exists.
        // SAFETY: RTNL is held for 'a (the proof's invariant), which
        // excludes every other thread.
        unsafe { &mut *self.data.get() }
    }
}

/// A `struct mutex` defined in C with `DEFINE_MUTEX` (its own lockdep
/// class, named after its definition), known by its address (taken from
/// the C definition as an extern static, so a lock costs no call to find
/// it). Only [`StaticMutex::new`], an `unsafe fn`, makes one, so a safe
/// caller cannot hand [`CMutex`] a bad address.
#[derive(Clone, Copy)]
pub(crate) struct StaticMutex(*mut bindings::mutex);

// SAFETY: the address of a statically defined kernel mutex, which any
// thread may lock (StaticMutex::new's contract); the pointer is never
// dereferenced but by the C mutex functions.
unsafe impl Send for StaticMutex {}
// SAFETY: as for Send; a shared StaticMutex only hands out the address.
unsafe impl Sync for StaticMutex {}

impl StaticMutex {
    /// # Safety
    ///
    /// `addr` is the address of a statically defined and initialised
    /// `struct mutex` (`DEFINE_MUTEX`), which nothing uses as anything but
    /// a mutex.
    pub(crate) const unsafe fn new(addr: *mut bindings::mutex) -> Self {
        StaticMutex(addr)
    }

    fn ptr(self) -> *mut bindings::mutex {
        self.0
    }
}

/// Data protected by a C [`StaticMutex`].
pub(crate) struct CMutex<T> {
    lock: StaticMutex,
    data: UnsafeCell<T>,
}

// SAFETY: `data` is only reached through a guard holding the mutex.
unsafe impl<T: Send> Sync for CMutex<T> {}

impl<T> CMutex<T> {
    /// `data` guarded by the C mutex `lock`.
    pub(crate) const fn new(lock: StaticMutex, data: T) -> Self {
        CMutex {
            lock,
            data: UnsafeCell::new(data),
        }
    }

    /// Locks the mutex. Process context; sleeps.
    pub(crate) fn lock(&self) -> CMutexGuard<'_, T> {
        // SAFETY: a statically defined, initialised mutex (StaticMutex's
        // contract).
        unsafe { bindings::rcan_mutex_lock(self.lock.ptr()) };
        CMutexGuard {
            m: self,
            _not_send: PhantomData,
        }
    }
}

/// A held [`CMutex`].
pub(crate) struct CMutexGuard<'a, T> {
    m: &'a CMutex<T>,
    _not_send: PhantomData<*mut ()>,
}

impl<T> Deref for CMutexGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the mutex is held while the guard lives.
        unsafe { &*self.m.data.get() }
    }
}

impl<T> DerefMut for CMutexGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: the mutex is held while the guard lives, exclusively.
        unsafe { &mut *self.m.data.get() }
    }
}

impl<T> Drop for CMutexGuard<'_, T> {
    fn drop(&mut self) {
        // SAFETY: we locked it in CMutex::lock().
        unsafe { bindings::rcan_mutex_unlock(self.m.lock.ptr()) };
    }
}

/// A C struct in a `static` that the kernel links into its own lists
/// (`packet_type`, `notifier_block`, ...): mutable through raw pointers only.
pub(crate) struct CCell<T>(UnsafeCell<T>);

// SAFETY: the kernel serialises access to such structs with its own locks
// (registration under RTNL or the ptype lock); Rust only hands out the
// pointer.
unsafe impl<T> Sync for CCell<T> {}

impl<T> CCell<T> {
    pub(crate) const fn new(v: T) -> Self {
        CCell(UnsafeCell::new(v))
    }

    pub(crate) fn get(&self) -> *mut T {
        self.0.get()
    }
}
