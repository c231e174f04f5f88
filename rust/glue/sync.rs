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
use kernel::ffi;

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
}

impl Drop for RcuReadGuard {
    fn drop(&mut self) {
        // SAFETY: paired with the rcu_read_lock() in new().
        unsafe { bindings::rcan_rcu_read_unlock() };
    }
}

/// Waits for all pre-existing RCU readers. Process context; sleeps.
pub(crate) fn synchronize_rcu() {
    // SAFETY: callers are in process context (documented contract).
    unsafe { bindings::synchronize_rcu() };
}

/// Waits for all pending `call_rcu` callbacks. Process context; sleeps.
/// Module exit calls it so no callback runs after the code is gone.
pub(crate) fn rcu_barrier() {
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
    /// pointer. The caller holds the writers' lock and must not free the
    /// returned object before a grace period has elapsed.
    pub(crate) fn replace(&self, new: *mut T) -> *mut T {
        self.ptr.swap(new, Ordering::AcqRel)
    }

    /// The current pointer, for writers (who hold the writers' lock).
    pub(crate) fn get_locked(&self) -> *mut T {
        self.ptr.load(Ordering::Acquire)
    }
}

/// Holding the RTNL mutex. Process context; sleeps.
pub(crate) struct Rtnl(PhantomData<*mut ()>);

impl Rtnl {
    /// Takes the RTNL mutex.
    pub(crate) fn lock() -> Self {
        // SAFETY: process context (callers' contract); unlocked in Drop.
        unsafe { bindings::rcan_rtnl_lock() };
        Rtnl(PhantomData)
    }

    /// For code called by the kernel with RTNL already held (netdevice
    /// notifiers): asserts it and returns a token that does not unlock.
    pub(crate) fn assert_held() -> RtnlHeld {
        // SAFETY: ASSERT_RTNL only reads the lock state.
        unsafe { bindings::rcan_assert_rtnl() };
        RtnlHeld(PhantomData)
    }
}

impl Drop for Rtnl {
    fn drop(&mut self) {
        // SAFETY: paired with rtnl_lock() in lock().
        unsafe { bindings::rcan_rtnl_unlock() };
    }
}

/// Proof that RTNL is held by a caller further up (see [`Rtnl::assert_held`]).
pub(crate) struct RtnlHeld(PhantomData<*mut ()>);

/// Something that proves RTNL is held.
pub(crate) trait RtnlProof {}
impl RtnlProof for Rtnl {}
impl RtnlProof for RtnlHeld {}

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
        // SAFETY: RTNL is held for 'a (proof borrowed mutably, so no second
        // `&mut T` can be made from the same proof), and RTNL excludes every
        // other accessor.
        unsafe { &mut *self.data.get() }
    }
}

/// Data protected by a `struct mutex` defined in C with `DEFINE_MUTEX`.
pub(crate) struct CMutex<T> {
    lock: fn() -> *mut bindings::mutex,
    data: UnsafeCell<T>,
}

// SAFETY: `data` is only reached through a guard holding the mutex.
unsafe impl<T: Send> Sync for CMutex<T> {}

impl<T> CMutex<T> {
    /// `lock` returns the address of the C mutex.
    pub(crate) const fn new(lock: fn() -> *mut bindings::mutex, data: T) -> Self {
        CMutex {
            lock,
            data: UnsafeCell::new(data),
        }
    }

    /// Locks the mutex. Process context; sleeps.
    pub(crate) fn lock(&self) -> CMutexGuard<'_, T> {
        // SAFETY: the pointer is a statically defined, initialised mutex.
        unsafe { bindings::rcan_mutex_lock((self.lock)()) };
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
        unsafe { bindings::rcan_mutex_unlock((self.m.lock)()) };
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

/// Data protected by a spinlock taken with interrupts disabled
/// (`spin_lock_irqsave`): for state shared with a hardirq handler. Usable
/// in every context; never sleep while holding it.
///
/// The `spinlock_t` lives in its own small allocation (made and
/// initialised by a C helper), so the value can be moved freely before it
/// is shared.
///
/// # Invariants
///
/// `lock` is an initialised spinlock allocated by `rcan_spinlock_alloc`,
/// freed in Drop.
pub(crate) struct IrqSpinLock<T> {
    lock: core::ptr::NonNull<bindings::spinlock_t>,
    data: UnsafeCell<T>,
}

// SAFETY: `data` is only reached through a guard holding the lock.
unsafe impl<T: Send> Sync for IrqSpinLock<T> {}
// SAFETY: the lock allocation may be freed from any thread.
unsafe impl<T: Send> Send for IrqSpinLock<T> {}

impl<T> IrqSpinLock<T> {
    /// A new unlocked lock. Process context (allocates with GFP_KERNEL).
    pub(crate) fn new(data: T) -> kernel::error::Result<Self> {
        // SAFETY: allocates and initialises a spinlock, or returns NULL.
        let lock = unsafe { bindings::rcan_spinlock_alloc() };
        let lock = core::ptr::NonNull::new(lock).ok_or(kernel::error::code::ENOMEM)?;
        // INVARIANT: just allocated and initialised.
        Ok(IrqSpinLock {
            lock,
            data: UnsafeCell::new(data),
        })
    }

    /// Takes the lock, disabling local interrupts. Any context.
    pub(crate) fn lock(&self) -> IrqSpinGuard<'_, T> {
        // SAFETY: an initialised spinlock (invariant).
        let flags = unsafe { bindings::rcan_spin_lock_irqsave(self.lock.as_ptr()) };
        IrqSpinGuard {
            l: self,
            flags,
            _not_send: PhantomData,
        }
    }
}

impl<T> Drop for IrqSpinLock<T> {
    fn drop(&mut self) {
        // SAFETY: nobody can hold the lock (we have `&mut self`); allocated
        // by rcan_spinlock_alloc (invariant).
        unsafe { bindings::rcan_spinlock_free(self.lock.as_ptr()) };
    }
}

/// A held [`IrqSpinLock`].
pub(crate) struct IrqSpinGuard<'a, T> {
    l: &'a IrqSpinLock<T>,
    flags: kernel::ffi::c_ulong,
    _not_send: PhantomData<*mut ()>,
}

impl<T> Deref for IrqSpinGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the lock is held while the guard lives.
        unsafe { &*self.l.data.get() }
    }
}

impl<T> DerefMut for IrqSpinGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: the lock is held while the guard lives, exclusively.
        unsafe { &mut *self.l.data.get() }
    }
}

impl<T> Drop for IrqSpinGuard<'_, T> {
    fn drop(&mut self) {
        // SAFETY: locked in IrqSpinLock::lock with these flags, on this CPU
        // (the guard is not Send).
        unsafe { bindings::rcan_spin_unlock_irqrestore(self.l.lock.as_ptr(), self.flags) };
    }
}

/// Data protected by a spinlock defined in C with `DEFINE_SPINLOCK`, taken
/// with bottom halves disabled (`spin_lock_bh`): for state shared between
/// process context and softirqs (receive path, soft hrtimers), never with a
/// hardirq handler. Usable in process and softirq context, and in a
/// transmit path (BH already disabled); never sleep while holding it.
pub(crate) struct BhSpinLock<T> {
    lock: fn() -> *mut bindings::spinlock_t,
    data: UnsafeCell<T>,
}

// SAFETY: `data` is only reached through a guard holding the lock.
unsafe impl<T: Send> Sync for BhSpinLock<T> {}

impl<T> BhSpinLock<T> {
    /// `lock` returns the address of the C spinlock.
    pub(crate) const fn new(lock: fn() -> *mut bindings::spinlock_t, data: T) -> Self {
        BhSpinLock {
            lock,
            data: UnsafeCell::new(data),
        }
    }

    /// Takes the lock with bottom halves disabled.
    pub(crate) fn lock(&self) -> BhSpinGuard<'_, T> {
        // SAFETY: the pointer is a statically defined, initialised spinlock.
        unsafe { bindings::rcan_spin_lock_bh((self.lock)()) };
        BhSpinGuard {
            l: self,
            _not_send: PhantomData,
        }
    }
}

/// A held [`BhSpinLock`].
pub(crate) struct BhSpinGuard<'a, T> {
    l: &'a BhSpinLock<T>,
    _not_send: PhantomData<*mut ()>,
}

impl<T> Deref for BhSpinGuard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the lock is held while the guard lives.
        unsafe { &*self.l.data.get() }
    }
}

impl<T> DerefMut for BhSpinGuard<'_, T> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: the lock is held while the guard lives, exclusively.
        unsafe { &mut *self.l.data.get() }
    }
}

impl<T> Drop for BhSpinGuard<'_, T> {
    fn drop(&mut self) {
        // SAFETY: locked in BhSpinLock::lock on this CPU (not Send).
        unsafe { bindings::rcan_spin_unlock_bh((self.l.lock)()) };
    }
}

/// How [`CWaitQueue::wait`] ended.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Waited {
    /// The condition became true.
    Ready,
    /// The timeout passed first.
    TimedOut,
    /// A signal arrived first.
    Interrupted,
}

/// A wait queue defined in C with `DECLARE_WAIT_QUEUE_HEAD`.
pub(crate) struct CWaitQueue {
    wq: fn() -> *mut bindings::wait_queue_head,
}

struct WaitCond<'a> {
    f: &'a dyn Fn() -> bool,
}

unsafe extern "C" fn wait_cond(arg: *mut ffi::c_void) -> bool {
    // SAFETY: `arg` is the `WaitCond` that `CWaitQueue::wait` passes, alive
    // for the whole wait.
    let c = unsafe { &*arg.cast::<WaitCond<'_>>() };
    (c.f)()
}

impl CWaitQueue {
    /// `wq` returns the address of the C wait queue head.
    pub(crate) const fn new(wq: fn() -> *mut bindings::wait_queue_head) -> Self {
        CWaitQueue { wq }
    }

    /// Sleeps (interruptibly) until `cond` is true, for at most `timeo`
    /// jiffies (`MAX_SCHEDULE_TIMEOUT`: forever). `cond` is evaluated in
    /// process context, possibly several times; it may take spinlocks but
    /// must not sleep. Process context.
    pub(crate) fn wait(&self, timeo: i64, cond: &dyn Fn() -> bool) -> Waited {
        let c = WaitCond { f: cond };
        let arg = &c as *const WaitCond<'_> as *mut ffi::c_void;
        // SAFETY: a static, initialised wait queue; `arg` outlives the call.
        let ret = unsafe {
            bindings::rcan_wait_event_timeout((self.wq)(), Some(wait_cond), arg, timeo as _)
        };
        if ret > 0 {
            Waited::Ready
        } else if ret == 0 {
            if cond() {
                Waited::Ready
            } else {
                Waited::TimedOut
            }
        } else {
            Waited::Interrupted
        }
    }

    /// Wakes every waiter (they re-check their conditions). Any context.
    pub(crate) fn wake_all(&self) {
        // SAFETY: a static, initialised wait queue.
        unsafe { bindings::rcan_wake_up_all((self.wq)()) };
    }
}
