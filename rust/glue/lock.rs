// SPDX-License-Identifier: GPL-2.0

//! Spinlocks and wait queues, each with the lockdep class of its
//! definition site.
//!
//! * [`LockClassKey`]: a lockdep class. Lockdep checks lock order per
//!   class; the kernel's `spin_lock_init` macro makes one static key per
//!   call site, and so do the constructors here (as upstream
//!   `new_spinlock!` does with `static_lock_class!`), so lockdep tells
//!   the bus lock of the simulated 82527 from a chip lock of the SJA1000
//!   driver and reports an inversion between them.
//! * [`SpinLock<T, B>`](SpinLock) (made with [`new_spinlock!`]): data
//!   under a spinlock in a value that may move (per-device, per-socket,
//!   per-job data); [`StaticSpinLock<T, B>`](StaticSpinLock): the same in
//!   a `static`. One implementation; the [`Backend`] `B` says how the lock
//!   is taken, as upstream's `Lock<T, B: Backend>`:
//!   * [`Irq`] (`spin_lock_irqsave`): data shared with a hardirq handler
//!     ([`IrqSpinLock`], [`new_irq_spinlock!`], [`StaticIrqSpinLock`]);
//!   * [`Bh`] (`spin_lock_bh`): data shared between process context and
//!     softirqs ([`BhLock`], [`new_bh_spinlock!`], [`BhSpinLock`]).
//! * [`WaitQueue`]: a `wait_queue_head` in a `static`.
//!
//! The statics are initialised in place on first use ([`Once`]): 6.12's
//! Rust cannot run `spin_lock_init` at compile time. Their methods take
//! `&'static self`, so an initialised lock or wait queue never moves (an
//! empty wait queue's list points to itself). The first use may come
//! from any context: [`Once`] initialises with local interrupts off, so
//! an interrupt never waits for an initialisation it interrupted.

use super::bindings;
use core::cell::UnsafeCell;
use core::marker::PhantomData;
use core::ops::{Deref, DerefMut};
use core::sync::atomic::{AtomicU8, Ordering};
use kernel::ffi;
use kernel::str::CStr;
use kernel::types::Opaque;

/// A lockdep class (`struct lock_class_key`). Lockdep needs it in static
/// storage for as long as locks of the class exist: put it in a `static`
/// (as [`new_irq_spinlock!`] does) or in a static lock. A key elsewhere
/// makes lockdep warn and leave the lock unchecked; it cannot corrupt
/// memory.
#[repr(transparent)]
pub(crate) struct LockClassKey(Opaque<bindings::lock_class_key>);

// SAFETY: lockdep synchronises all access to a key itself; Rust never
// reads or writes it.
unsafe impl Sync for LockClassKey {}

impl LockClassKey {
    /// A key for a `static` (lockdep wants static keys zero-filled or
    /// uninitialised; it only uses their address).
    pub(crate) const fn new() -> Self {
        LockClassKey(Opaque::uninit())
    }

    fn as_ptr(&self) -> *mut bindings::lock_class_key {
        self.0.get()
    }
}

const UNINIT: u8 = 0;
const INITIALISING: u8 = 1;
const READY: u8 = 2;

/// One-time initialisation of a static, in any context.
struct Once(AtomicU8);

impl Once {
    const fn new() -> Self {
        Once(AtomicU8::new(UNINIT))
    }

    /// Runs `init` the first time it is called; every caller returns only
    /// once `init` has completed. `init` must not sleep; it runs with
    /// local interrupts off. Any context.
    #[inline]
    fn call(&self, init: impl FnOnce()) {
        if self.0.load(Ordering::Acquire) == READY {
            return;
        }
        self.slow(init);
    }

    #[cold]
    fn slow(&self, init: impl FnOnce()) {
        // Interrupts stay off on this CPU from the claim to READY, so no
        // hardirq or softirq can interrupt the initialiser and then spin
        // below for it on the same CPU (a livelock seen when a DSOR
        // receive softirq met its wait queue's first use by a sender).
        // Spinners are therefore always on other CPUs, and `init` (a lock
        // or wait-queue init) is short and never sleeps.
        // SAFETY: paired with the restore below on every path; nothing in
        // between sleeps.
        let flags = unsafe { bindings::rcan_local_irq_save() };
        let claimed = self
            .0
            .compare_exchange(UNINIT, INITIALISING, Ordering::Acquire, Ordering::Acquire)
            .is_ok();
        if claimed {
            init();
            self.0.store(READY, Ordering::Release);
        }
        // SAFETY: restores what the save above returned, on this CPU
        // (interrupts off: no migration in between).
        unsafe { bindings::rcan_local_irq_restore(flags) };
        if !claimed {
            while self.0.load(Ordering::Acquire) != READY {
                core::hint::spin_loop();
            }
        }
    }
}

/// A `spinlock_t` in a static, initialised on first use with its own
/// class.
///
/// # Invariants
///
/// Once `once` has run, `lock` is initialised (`rcan_spin_lock_init_key`
/// with `key` and `name`).
struct StaticRawLock {
    lock: Opaque<bindings::spinlock_t>,
    key: LockClassKey,
    name: &'static CStr,
    once: Once,
}

impl StaticRawLock {
    const fn new(name: &'static CStr) -> Self {
        StaticRawLock {
            lock: Opaque::uninit(),
            key: LockClassKey::new(),
            name,
            once: Once::new(),
        }
    }

    /// The initialised lock. Any context.
    fn get(&'static self) -> *mut bindings::spinlock_t {
        self.once.call(|| {
            // Every path to the lock goes through here, so nobody takes it
            // before; the lock, `key` and `name` are 'static (never move).
            // SAFETY: first and only initialisation (Once), of a lock that
            // nobody can have taken yet and that never moves.
            unsafe {
                bindings::rcan_spin_lock_init_key(
                    self.lock.get(),
                    self.name.as_char_ptr(),
                    self.key.as_ptr(),
                )
            }
        });
        // INVARIANT: initialised above.
        self.lock.get()
    }
}

// ---------------------------------------------------------------------------
// Backends: how a spinlock is taken

/// How a [`SpinLock`] or [`StaticSpinLock`] takes and releases its
/// `spinlock_t` (upstream's `sync::lock::Backend`, for the two flavours
/// rcan needs): [`Irq`] or [`Bh`]. Only this file implements it.
///
/// # Safety
///
/// [`Backend::lock`] takes the spinlock it is given, exclusively, until
/// [`Backend::unlock`] is called on the same CPU with the state it
/// returned.
pub(crate) unsafe trait Backend {
    /// What taking the lock saved, for releasing it (the interrupt
    /// flags of [`Irq`]).
    type State: Copy;

    /// Takes the lock.
    ///
    /// # Safety
    ///
    /// `lock` is an initialised spinlock that lives until the matching
    /// [`Backend::unlock`]; the caller's context allows this flavour.
    unsafe fn lock(lock: *mut bindings::spinlock_t) -> Self::State;

    /// Releases the lock.
    ///
    /// # Safety
    ///
    /// `lock` was taken by [`Backend::lock`] on this CPU, which returned
    /// `state`, and is still held.
    unsafe fn unlock(lock: *mut bindings::spinlock_t, state: Self::State);
}

/// `spin_lock_irqsave`: for data shared with a hardirq handler. Usable in
/// every context.
pub(crate) struct Irq;

// SAFETY: spin_lock_irqsave takes the lock until spin_unlock_irqrestore
// with the flags it saved.
unsafe impl Backend for Irq {
    type State = ffi::c_ulong;

    // `spin_lock_irqsave(lock, flags)` is, without PREEMPT_RT (which
    // rcan does not build for), `flags = _raw_spin_lock_irqsave(&lock->rlock)`
    // (out of line in both our kernels), and the `rlock` member is at
    // offset 0 of `spinlock_t`: so the exported functions are called
    // directly, without the C helper in between (one call less per lock
    // and unlock on the frame path). Lockdep sees the same lock and class.
    #[inline]
    unsafe fn lock(lock: *mut bindings::spinlock_t) -> ffi::c_ulong {
        // SAFETY: an initialised spinlock (the function's contract), whose
        // first member (offset 0) is its raw_spinlock.
        unsafe { bindings::_raw_spin_lock_irqsave(lock.cast::<bindings::raw_spinlock>()) }
    }

    #[inline]
    unsafe fn unlock(lock: *mut bindings::spinlock_t, flags: ffi::c_ulong) {
        // SAFETY: taken with these flags on this CPU (the contract); the
        // raw_spinlock at offset 0, as in `lock`.
        unsafe {
            bindings::_raw_spin_unlock_irqrestore(lock.cast::<bindings::raw_spinlock>(), flags)
        };
    }
}

/// `spin_lock_bh`: for data shared between process context and softirqs
/// (NET_RX, HRTIMER_SOFTIRQ), never with a hardirq handler. Usable in
/// process and softirq context and in a transmit path (BH already off);
/// not in hardirq or with interrupts disabled.
pub(crate) struct Bh;

// SAFETY: spin_lock_bh takes the lock until spin_unlock_bh.
unsafe impl Backend for Bh {
    type State = ();

    // As for `Irq`: `spin_lock_bh(lock)` and `spin_unlock_bh(lock)` are,
    // without PREEMPT_RT, `_raw_spin_lock_bh(&lock->rlock)` and
    // `_raw_spin_unlock_bh(&lock->rlock)` (out of line in both our
    // kernels: no CONFIG_INLINE_SPIN_*_BH on x86), with `rlock` at offset
    // 0: called directly, one call less per lock and unlock (CAN_ISOTP
    // takes its engine lock twice per frame). Lockdep sees the same lock.
    #[inline]
    unsafe fn lock(lock: *mut bindings::spinlock_t) {
        // SAFETY: an initialised spinlock (the function's contract), whose
        // first member (offset 0) is its raw_spinlock.
        unsafe { bindings::_raw_spin_lock_bh(lock.cast::<bindings::raw_spinlock>()) };
    }

    #[inline]
    unsafe fn unlock(lock: *mut bindings::spinlock_t, _: ()) {
        // SAFETY: taken with spin_lock_bh on this CPU (the contract); the
        // raw_spinlock at offset 0, as in `lock`.
        unsafe { bindings::_raw_spin_unlock_bh(lock.cast::<bindings::raw_spinlock>()) };
    }
}

// ---------------------------------------------------------------------------
// SpinLock: in a value that moves

/// Data protected by a spinlock taken the [`Backend`] `B` way, in a
/// value that may move before it is shared (per-device driver data, a
/// per-socket or per-job lock), of the lockdep class of its
/// [`new_spinlock!`] site. Never sleep while holding it.
///
/// The `spinlock_t` lives in its own small allocation, so the value can
/// be moved freely before it is shared.
///
/// # Invariants
///
/// `lock` is an initialised spinlock allocated by `rcan_spinlock_alloc`,
/// freed in Drop.
pub(crate) struct SpinLock<T, B: Backend> {
    lock: core::ptr::NonNull<bindings::spinlock_t>,
    data: UnsafeCell<T>,
    _backend: PhantomData<B>,
}

/// A [`SpinLock`] taken with interrupts disabled (`spin_lock_irqsave`):
/// state shared with a hardirq handler. Made with [`new_irq_spinlock!`].
pub(crate) type IrqSpinLock<T> = SpinLock<T, Irq>;

/// A [`SpinLock`] taken with bottom halves disabled (`spin_lock_bh`):
/// state shared between process context and softirqs. Made with
/// [`new_bh_spinlock!`]. Holding it, one may queue skbs on a socket and
/// wake its readers (`sock_queue_rcv_skb`), as softirqs do.
pub(crate) type BhLock<T> = SpinLock<T, Bh>;

// SAFETY: `data` is only reached through a guard holding the lock.
unsafe impl<T: Send, B: Backend> Sync for SpinLock<T, B> {}
// SAFETY: the lock allocation may be freed from any thread.
unsafe impl<T: Send, B: Backend> Send for SpinLock<T, B> {}

/// `SpinLock::<_, B>::new(data, name)` with a lockdep class of this call
/// site (shared by every lock made here, e.g. every device's chip lock).
/// Process context (allocates with GFP_KERNEL); `Result`.
#[allow(unused_macros)]
macro_rules! new_spinlock {
    ($data:expr, $name:literal, $backend:ty $(,)?) => {{
        static CLASS: $crate::glue::lock::LockClassKey = $crate::glue::lock::LockClassKey::new();
        $crate::glue::lock::SpinLock::<_, $backend>::new($data, ::kernel::c_str!($name), &CLASS)
    }};
}
#[allow(unused_imports)]
pub(crate) use new_spinlock;

/// An [`IrqSpinLock`] with a lockdep class of this call site.
// Not every module that compiles the glue has a driver.
#[allow(unused_macros)]
macro_rules! new_irq_spinlock {
    ($data:expr, $name:literal $(,)?) => {
        $crate::glue::lock::new_spinlock!($data, $name, $crate::glue::lock::Irq)
    };
}
#[allow(unused_imports)]
pub(crate) use new_irq_spinlock;

/// A [`BhLock`] with a lockdep class of this call site.
#[allow(unused_macros)]
macro_rules! new_bh_spinlock {
    ($data:expr, $name:literal $(,)?) => {
        $crate::glue::lock::new_spinlock!($data, $name, $crate::glue::lock::Bh)
    };
}
#[allow(unused_imports)]
pub(crate) use new_bh_spinlock;

impl<T, B: Backend> SpinLock<T, B> {
    /// A new unlocked lock of class `key`, named `name` in lockdep
    /// reports. Process context (allocates with GFP_KERNEL). Use
    /// [`new_spinlock!`] (or its two flavours), which makes the key.
    pub(crate) fn new(
        data: T,
        name: &'static CStr,
        key: &'static LockClassKey,
    ) -> kernel::error::Result<Self> {
        // SAFETY: allocates and initialises a spinlock, or returns NULL;
        // `name` and `key` are 'static, as lockdep keeps them.
        let lock = unsafe { bindings::rcan_spinlock_alloc(name.as_char_ptr(), key.as_ptr()) };
        let lock = core::ptr::NonNull::new(lock).ok_or(kernel::error::code::ENOMEM)?;
        // INVARIANT: just allocated and initialised.
        Ok(SpinLock {
            lock,
            data: UnsafeCell::new(data),
            _backend: PhantomData,
        })
    }

    /// Takes the lock. Any context the backend allows ([`Irq`]: every
    /// context; [`Bh`]: process or softirq, not hardirq, not with
    /// interrupts disabled).
    #[inline]
    pub(crate) fn lock(&self) -> Guard<'_, T, B> {
        // SAFETY: an initialised spinlock (invariant) that outlives the
        // guard (borrowed by it).
        let state = unsafe { B::lock(self.lock.as_ptr()) };
        // INVARIANT: taken above with `state`.
        Guard {
            lock: self.lock,
            data: &self.data,
            state,
            _not_send: PhantomData,
        }
    }
}

impl<T, B: Backend> Drop for SpinLock<T, B> {
    fn drop(&mut self) {
        // SAFETY: nobody can hold the lock (we have `&mut self`); allocated
        // by rcan_spinlock_alloc (invariant).
        unsafe { bindings::rcan_spinlock_free(self.lock.as_ptr()) };
    }
}

// ---------------------------------------------------------------------------
// StaticSpinLock: in a static

/// Data in a `static`, protected by a spinlock taken the [`Backend`] `B`
/// way, of its own lockdep class (one per static). Never sleep while
/// holding it.
pub(crate) struct StaticSpinLock<T, B: Backend> {
    raw: StaticRawLock,
    data: UnsafeCell<T>,
    _backend: PhantomData<B>,
}

/// A [`StaticSpinLock`] taken with interrupts disabled: any context.
pub(crate) type StaticIrqSpinLock<T> = StaticSpinLock<T, Irq>;

/// A [`StaticSpinLock`] taken with bottom halves disabled: process and
/// softirq context, and a transmit path (BH already disabled).
pub(crate) type BhSpinLock<T> = StaticSpinLock<T, Bh>;

// SAFETY: `data` is only reached through a guard holding the lock.
unsafe impl<T: Send, B: Backend> Sync for StaticSpinLock<T, B> {}

impl<T, B: Backend> StaticSpinLock<T, B> {
    /// For a `static`; `name` appears in lockdep reports.
    pub(crate) const fn new(data: T, name: &'static CStr) -> Self {
        StaticSpinLock {
            raw: StaticRawLock::new(name),
            data: UnsafeCell::new(data),
            _backend: PhantomData,
        }
    }

    /// Takes the lock. Any context the backend allows (see
    /// [`SpinLock::lock`]).
    pub(crate) fn lock(&'static self) -> Guard<'static, T, B> {
        let lock = self.raw.get();
        // SAFETY: initialised by `get`, static.
        let state = unsafe { B::lock(lock) };
        // INVARIANT: taken above with `state`.
        Guard {
            // SAFETY: the address of a static is not NULL.
            lock: unsafe { core::ptr::NonNull::new_unchecked(lock) },
            data: &self.data,
            state,
            _not_send: PhantomData,
        }
    }
}

// ---------------------------------------------------------------------------
// Guard

/// A held [`SpinLock`] or [`StaticSpinLock`]: `&mut` access to the data.
///
/// # Invariants
///
/// `lock` is held, taken by `B::lock` on this CPU, which returned
/// `state`; it protects `data`.
pub(crate) struct Guard<'a, T, B: Backend> {
    lock: core::ptr::NonNull<bindings::spinlock_t>,
    data: &'a UnsafeCell<T>,
    state: B::State,
    _not_send: PhantomData<*mut ()>,
}

/// A held [`IrqSpinLock`] or [`StaticIrqSpinLock`].
pub(crate) type IrqSpinGuard<'a, T> = Guard<'a, T, Irq>;
/// A held [`BhLock`].
pub(crate) type BhGuard<'a, T> = Guard<'a, T, Bh>;
/// A held [`BhSpinLock`].
pub(crate) type BhSpinGuard<T> = Guard<'static, T, Bh>;

impl<T, B: Backend> Deref for Guard<'_, T, B> {
    type Target = T;
    fn deref(&self) -> &T {
        // SAFETY: the lock is held while the guard lives (invariant).
        unsafe { &*self.data.get() }
    }
}

impl<T, B: Backend> DerefMut for Guard<'_, T, B> {
    fn deref_mut(&mut self) -> &mut T {
        // SAFETY: the lock is held while the guard lives, exclusively.
        unsafe { &mut *self.data.get() }
    }
}

impl<T, B: Backend> Drop for Guard<'_, T, B> {
    #[inline]
    fn drop(&mut self) {
        // SAFETY: taken by B::lock with `state` on this CPU (invariant;
        // the guard is not Send).
        unsafe { B::unlock(self.lock.as_ptr(), self.state) };
    }
}

// ---------------------------------------------------------------------------
// WaitQueue

/// How [`WaitQueue::wait`] ended.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Waited {
    /// The condition became true.
    Ready,
    /// The timeout passed first.
    TimedOut,
    /// A signal arrived first.
    Interrupted,
}

/// A wait queue (`wait_queue_head`) in a `static`, of its own lockdep
/// class, initialised on first use.
///
/// # Invariants
///
/// Once `once` has run, `wq` is initialised with `key` and `name`.
pub(crate) struct WaitQueue {
    wq: Opaque<bindings::wait_queue_head>,
    key: LockClassKey,
    name: &'static CStr,
    once: Once,
}

// SAFETY: the wait queue has its own lock; Rust only passes its address.
unsafe impl Sync for WaitQueue {}

struct WaitCond<'a> {
    f: &'a dyn Fn() -> bool,
}

/// # Safety
///
/// `arg` is the `WaitCond` that [`WaitQueue::wait`] passes, alive for the
/// whole wait.
unsafe extern "C" fn wait_cond(arg: *mut ffi::c_void) -> bool {
    // SAFETY: the function's contract.
    let c = unsafe { &*arg.cast::<WaitCond<'_>>() };
    (c.f)()
}

impl WaitQueue {
    /// For a `static`; `name` appears in lockdep reports.
    pub(crate) const fn new(name: &'static CStr) -> Self {
        WaitQueue {
            wq: Opaque::uninit(),
            key: LockClassKey::new(),
            name,
            once: Once::new(),
        }
    }

    fn get(&'static self) -> *mut bindings::wait_queue_head {
        self.once.call(|| {
            // SAFETY: first and only initialisation (Once), before any
            // waiter or waker reaches it (they all go through here); the
            // queue is 'static, so its self-pointing list never moves.
            unsafe {
                bindings::rcan_init_waitqueue_head_key(
                    self.wq.get(),
                    self.name.as_char_ptr(),
                    self.key.as_ptr(),
                )
            }
        });
        // INVARIANT: initialised above.
        self.wq.get()
    }

    /// Sleeps (interruptibly) until `cond` is true, for at most `timeo`
    /// jiffies (`MAX_SCHEDULE_TIMEOUT`: forever). `cond` is evaluated in
    /// process context, possibly several times; it may take spinlocks but
    /// must not sleep. Process context.
    pub(crate) fn wait(&'static self, timeo: i64, cond: &dyn Fn() -> bool) -> Waited {
        let wq = self.get();
        let c = WaitCond { f: cond };
        let arg = &c as *const WaitCond<'_> as *mut ffi::c_void;
        // SAFETY: an initialised static wait queue; `arg` is a `WaitCond`
        // that outlives the call, as `wait_cond` requires.
        let ret =
            unsafe { bindings::rcan_wait_event_timeout(wq, Some(wait_cond), arg, timeo as _) };
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
    pub(crate) fn wake_all(&'static self) {
        // SAFETY: an initialised static wait queue.
        unsafe { bindings::rcan_wake_up_all(self.get()) };
    }
}
