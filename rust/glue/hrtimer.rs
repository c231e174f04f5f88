// SPDX-License-Identifier: GPL-2.0

//! High-resolution timers (`struct hrtimer`) in static storage.
//!
//! 6.12's `kernel` crate has no hrtimer abstraction. This is the part rcan
//! needs, shaped like upstream's later `kernel::time::hrtimer` (a timer
//! type, a callback trait, [`ClockId`], [`HrTimerMode`], cancellation on
//! teardown) but on 6.12's C API: `hrtimer_init` and setting `.function`,
//! `hrtimer_start_range_ns`, `hrtimer_cancel`.
//!
//! An [`HrTimer`] lives in a `static` of the module that uses it: rcan's
//! timers belong to singleton services whose timers re-arm each other, and
//! a static needs no pinning or reference counting. Statics are never
//! dropped, so the glue owns their teardown: [`HrTimer::init`] takes the
//! module's [`ModuleScope`], which only a module whose exit the glue runs
//! ([`Scoped`](super::module::Scoped)) has, and links the timer into the
//! module's list; at exit [`kill_all`] makes every timer of the list
//! refuse [`HrTimer::start`] for good, then cancels each. When the
//! module's memory goes, no timer of it runs or is queued, whatever the
//! module's own exit did or forgot.
//!
//! Callback context: only the `*_SOFT` modes are offered, so callbacks run
//! in the `HRTIMER_SOFTIRQ` softirq (bottom halves disabled, must not
//! sleep; sending a frame is allowed). Callbacks of one timer never
//! overlap: the hrtimer core runs a timer's callback on one CPU base and
//! does not migrate a timer while its callback runs. That is why a callback
//! may own its [`HrTimerCallback::State`] mutably. Timers are one-shot: a
//! callback that wants to run again calls [`HrTimer::start`] on its own
//! timer (allowed from inside the callback), and the trampoline always
//! returns `HRTIMER_NORESTART`.

use super::bindings;
use core::cell::UnsafeCell;
use core::marker::PhantomData;
use core::mem::MaybeUninit;
use super::module::ModuleScope;
use core::ptr;
use core::sync::atomic::{AtomicI64, AtomicPtr, AtomicU32, AtomicU8, Ordering};
use kernel::error::{code, Result};
use kernel::types::Opaque;

/// The clock a timer runs on (`clockid_t`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum ClockId {
    /// `CLOCK_REALTIME`: wall-clock time; absolute timers follow clock
    /// steps (a forward step past the expiry fires the timer at once, a
    /// backward step delays it).
    RealTime,
    /// `CLOCK_MONOTONIC`: never steps.
    Monotonic,
}

impl ClockId {
    fn raw(self) -> bindings::clockid_t {
        match self {
            ClockId::RealTime => bindings::CLOCK_REALTIME as bindings::clockid_t,
            ClockId::Monotonic => bindings::CLOCK_MONOTONIC as bindings::clockid_t,
        }
    }
}

/// How [`HrTimer::start`]'s time is read; both run the callback in softirq
/// context.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum HrTimerMode {
    /// `HRTIMER_MODE_ABS_SOFT`: an absolute time of the timer's clock.
    AbsoluteSoft,
    /// `HRTIMER_MODE_REL_SOFT`: nanoseconds from now.
    RelativeSoft,
}

impl HrTimerMode {
    fn raw(self) -> bindings::hrtimer_mode {
        match self {
            HrTimerMode::AbsoluteSoft => bindings::hrtimer_mode_HRTIMER_MODE_ABS_SOFT,
            HrTimerMode::RelativeSoft => bindings::hrtimer_mode_HRTIMER_MODE_REL_SOFT,
        }
    }
}

/// A timer's callback.
pub(crate) trait HrTimerCallback: Sized + 'static {
    /// State only the callback uses, handed over at [`HrTimer::init`]. It
    /// is never dropped (the timer is a static): keep it plain data.
    type State: Send;

    /// Runs when the timer expires: `HRTIMER_SOFTIRQ` softirq context,
    /// must not sleep. Never runs concurrently with itself.
    fn run(timer: &'static HrTimer<Self>, state: &mut Self::State);
}

const UNINIT: u8 = 0;
const INITIALISING: u8 = 1;
const READY: u8 = 2;

/// `Core::gate`: set once the module's exit killed the timer.
const DEAD: u32 = 1 << 31;

/// The part of every [`HrTimer`] that does not depend on its callback, so
/// that the module's list ([`TIMERS`]) can hold timers of any callback.
///
/// # Invariants
///
/// Once `phase` is `READY`: `timer` was initialised by `hrtimer_init` with
/// a trampoline as its function and `mode` holds the mode it was
/// initialised with. `gate`'s low bits count the [`HrTimer::start`] calls
/// in progress that passed the `DEAD` check; once `DEAD` is set and that
/// count was seen at 0, the timer is never started again.
#[repr(C)]
struct Core {
    /// First field: the callback finds the `HrTimer` from the C pointer.
    timer: Opaque<bindings::hrtimer>,
    phase: AtomicU8,
    mode: AtomicU32,
    /// The absolute expiry last requested with `start` (0: never started).
    armed: AtomicI64,
    gate: AtomicU32,
    /// The next timer in the module's list (`TIMERS`), set at `init`.
    next: AtomicPtr<Core>,
}

/// The module's initialised timers (every one is a `'static`, linked once
/// by its `init`), killed by [`kill_all`] at exit. Pushed with a
/// compare-exchange; never unlinked (the list dies with the module).
static TIMERS: AtomicPtr<Core> = AtomicPtr::new(ptr::null_mut());

/// A high-resolution timer in static storage whose callback is `H::run`.
///
/// # Invariants
///
/// Once `core.phase` is `READY`: `core.timer`'s function is `run::<H>`,
/// and `state` is initialised and used only by `run::<H>` (that is, by one
/// callback at a time).
#[repr(C)]
pub(crate) struct HrTimer<H: HrTimerCallback> {
    /// First field, and `timer` is its first: the callback finds the
    /// `HrTimer` from the C pointer.
    core: Core,
    state: UnsafeCell<MaybeUninit<H::State>>,
    _h: PhantomData<H>,
}

// SAFETY: the C timer is only touched through the hrtimer API, which does
// its own locking; the other fields of `core` are atomics; `state` is used
// by one callback at a time (type invariant), possibly on different CPUs
// over time, hence `State: Send`.
unsafe impl<H: HrTimerCallback> Sync for HrTimer<H> {}

// SAFETY: as for `HrTimer`: `Core` holds the C timer (used through the
// hrtimer API only) and atomics; `TIMERS` shares `&'static Core`s.
unsafe impl Sync for Core {}

impl<H: HrTimerCallback> HrTimer<H> {
    /// An uninitialised timer, for a `static`.
    pub(crate) const fn new() -> Self {
        HrTimer {
            core: Core {
                timer: Opaque::uninit(),
                phase: AtomicU8::new(UNINIT),
                mode: AtomicU32::new(0),
                armed: AtomicI64::new(0),
                gate: AtomicU32::new(0),
                next: AtomicPtr::new(ptr::null_mut()),
            },
            state: UnsafeCell::new(MaybeUninit::uninit()),
            _h: PhantomData,
        }
    }

    /// Initialises the timer on `clock` in `mode`, handing `state` to the
    /// callback, and puts it on the module's list, which the module's exit
    /// kills (`scope`: only a [`Scoped`](super::module::Scoped) module's
    /// `init` has one). Once per timer (EBUSY after that), before any
    /// [`HrTimer::start`]. Process context.
    pub(crate) fn init(
        &'static self,
        _scope: &ModuleScope,
        clock: ClockId,
        mode: HrTimerMode,
        state: H::State,
    ) -> Result {
        if self
            .core
            .phase
            .compare_exchange(UNINIT, INITIALISING, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            return Err(code::EBUSY);
        }
        // We own the INITIALISING phase, so nobody else touches the timer
        // or the state: `start` is a no-op and no callback can run before
        // READY. hrtimer_init fully initialises the C struct; `function` is
        // set before the timer can be started. The timer is a 'static, so
        // the callback's pointer stays valid.
        // SAFETY: exclusive access during INITIALISING (above).
        unsafe {
            (*self.state.get()).write(state);
            bindings::hrtimer_init(self.core.timer.get(), clock.raw(), mode.raw());
            (*self.core.timer.get()).function = Some(run::<H>);
        }
        self.core.mode.store(mode.raw(), Ordering::Relaxed);
        // INVARIANT: timer, mode and state are initialised above; the
        // release store publishes them to `start` and `cancel`.
        self.core.phase.store(READY, Ordering::Release);
        // On the module's list, once (the phase above is never UNINIT
        // again), so that the exit kills it.
        let me = ptr::from_ref(&self.core).cast_mut();
        let mut head = TIMERS.load(Ordering::Acquire);
        loop {
            self.core.next.store(head, Ordering::Relaxed);
            match TIMERS.compare_exchange(head, me, Ordering::AcqRel, Ordering::Acquire) {
                Ok(_) => break,
                Err(h) => head = h,
            }
        }
        Ok(())
    }

    /// Arms the timer for `expires` nanoseconds (an absolute time of its
    /// clock, or relative to now, as its mode says), with no slack. A timer
    /// already queued is moved. Does nothing before [`HrTimer::init`] and
    /// once the module's exit killed the timer. Any context, including
    /// this timer's own callback.
    pub(crate) fn start(&self, expires: i64) {
        self.core.start(expires);
    }

    /// The expiry last requested with [`HrTimer::start`] (0: never
    /// started). A racy hint when another context re-arms concurrently.
    pub(crate) fn armed_for(&self) -> i64 {
        self.core.armed.load(Ordering::Relaxed)
    }

    /// Cancels the timer: when this returns, it is not queued and its
    /// callback is not running (`hrtimer_cancel` waits for a running one).
    /// Returns whether it was queued or running. A callback (of any timer)
    /// may re-arm it afterwards; the module's exit needs no such call
    /// ([`kill_all`]). Process context: `hrtimer_cancel` may wait, and in
    /// this timer's own callback it would wait for itself forever.
    pub(crate) fn cancel(&self) -> bool {
        self.core.cancel()
    }
}

impl Core {
    fn ready(&self) -> bool {
        self.phase.load(Ordering::Acquire) == READY
    }

    fn start(&self, expires: i64) {
        // Counted in progress before looking at DEAD; `kill` sets DEAD
        // before looking at the count (both SeqCst): either `kill` waits
        // for this start, or this start sees DEAD.
        let gate = self.gate.fetch_add(1, Ordering::SeqCst);
        if gate & DEAD == 0 && self.ready() {
            self.armed.store(expires, Ordering::Relaxed);
            // READY, so the timer is initialised (type invariant) with the
            // mode passed here, as hrtimer_start_range_ns requires (the
            // soft bit must match). The core serialises concurrent starts
            // and cancels with the timer base lock.
            // SAFETY: initialised timer, matching mode (above).
            unsafe {
                bindings::hrtimer_start_range_ns(
                    self.timer.get(),
                    expires,
                    0,
                    self.mode.load(Ordering::Relaxed),
                )
            };
        }
        self.gate.fetch_sub(1, Ordering::SeqCst);
    }

    fn cancel(&self) -> bool {
        if !self.ready() {
            return false;
        }
        // SAFETY: READY, so the timer is initialised (type invariant).
        unsafe { bindings::hrtimer_cancel(self.timer.get()) != 0 }
    }

    /// Makes every later `start` a no-op and waits for those in progress
    /// (each is a few instructions and a `hrtimer_start`, which does not
    /// sleep; one preempted in process context resumes, the kernel being
    /// preemptible or the waiter not holding the CPU forever: it spins
    /// with preemption enabled).
    fn forbid_start(&self) {
        self.gate.fetch_or(DEAD, Ordering::SeqCst);
        while self.gate.load(Ordering::SeqCst) & !DEAD != 0 {
            core::hint::spin_loop();
        }
    }
}

/// Kills every timer of the module: none can be started any more, none is
/// queued, no callback runs. All are forbidden to start before any is
/// cancelled, so a callback of one cannot re-arm another already cancelled.
/// Idempotent. Module exit ([`Scoped`](super::module::Scoped)), process
/// context: waits for running callbacks.
pub(super) fn kill_all() {
    let head = first(&TIMERS);
    for_each(head, Core::forbid_start);
    for_each(head, |c| {
        c.cancel();
    });
}

/// The timer a link of the module's list (`TIMERS` or a `Core::next`)
/// points at, if any.
fn first(link: &AtomicPtr<Core>) -> Option<&'static Core> {
    let p = link.load(Ordering::Acquire);
    // SAFETY: the list's links hold only null or `&'static Core`s (pushed
    // by `init` from `&'static self`), never unlinked.
    unsafe { p.as_ref() }
}

/// Calls `f` on `head` and every timer after it on the module's list.
fn for_each(head: Option<&'static Core>, mut f: impl FnMut(&Core)) {
    let mut c = head;
    while let Some(t) = c {
        f(t);
        c = first(&t.next);
    }
}

/// The C callback of every [`HrTimer<H>`].
///
/// # Safety
///
/// Called by the hrtimer core, in softirq context, with a timer that
/// `HrTimer::<H>::init` set up (it is the only place that installs this
/// function).
unsafe extern "C" fn run<H: HrTimerCallback>(
    t: *mut bindings::hrtimer,
) -> bindings::hrtimer_restart {
    // CAST: `timer` is the first field of the `#[repr(C)]` `Core`, the
    // first field of the `#[repr(C)]` `HrTimer<H>`.
    let this = t as *const HrTimer<H>;
    // SAFETY: `init` installs `run::<H>` only on `HrTimer<H>`s, which are
    // 'static (init takes `&'static self`); shared access is all we need.
    let this: &'static HrTimer<H> = unsafe { &*this };
    // The timer fired, so it was started, so it is READY: the state is
    // initialised; callbacks of one timer never overlap and nothing else
    // uses the state (type invariant).
    // SAFETY: initialised state, and this is its only reference (above).
    let state = unsafe { (*this.state.get()).assume_init_mut() };
    H::run(this, state);
    bindings::hrtimer_restart_HRTIMER_NORESTART
}

/// `CLOCK_REALTIME` now, in nanoseconds (`ktime_get_real`). Any context
/// but NMI.
pub(crate) fn ktime_get_real_ns() -> i64 {
    // SAFETY: ktime_get_with_offset may be called in any non-NMI context.
    unsafe { bindings::ktime_get_with_offset(bindings::tk_offsets_TK_OFFS_REAL) }
}

/// `CLOCK_MONOTONIC` now, in nanoseconds (`ktime_get`). Any context but
/// NMI.
pub(crate) fn ktime_get_mono_ns() -> i64 {
    // SAFETY: ktime_get may be called in any non-NMI context.
    unsafe { bindings::ktime_get() }
}
