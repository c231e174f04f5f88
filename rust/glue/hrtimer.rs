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
//! dropped, so the module's exit must [`HrTimer::cancel`] every timer it
//! started (after making sure that no callback starts it again); the timer
//! then neither runs nor is queued when the module's memory goes.
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
use core::sync::atomic::{AtomicI64, AtomicU32, AtomicU8, Ordering};
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

/// A high-resolution timer in static storage whose callback is `H::run`.
///
/// # Invariants
///
/// Once `phase` is `READY`: `timer` was initialised by `hrtimer_init` with
/// `run::<H>` as its function, `mode` holds the mode it was initialised
/// with, and `state` is initialised and used only by `run::<H>` (that is,
/// by one callback at a time).
#[repr(C)]
pub(crate) struct HrTimer<H: HrTimerCallback> {
    /// First field: the callback finds the `HrTimer` from the C pointer.
    timer: Opaque<bindings::hrtimer>,
    phase: AtomicU8,
    mode: AtomicU32,
    /// The absolute expiry last requested with `start` (0: never started).
    armed: AtomicI64,
    state: UnsafeCell<MaybeUninit<H::State>>,
    _h: PhantomData<H>,
}

// SAFETY: the C timer is only touched through the hrtimer API, which does
// its own locking; `state` is used by one callback at a time (type
// invariant), possibly on different CPUs over time, hence `State: Send`.
unsafe impl<H: HrTimerCallback> Sync for HrTimer<H> {}

impl<H: HrTimerCallback> HrTimer<H> {
    /// An uninitialised timer, for a `static`.
    pub(crate) const fn new() -> Self {
        HrTimer {
            timer: Opaque::uninit(),
            phase: AtomicU8::new(UNINIT),
            mode: AtomicU32::new(0),
            armed: AtomicI64::new(0),
            state: UnsafeCell::new(MaybeUninit::uninit()),
            _h: PhantomData,
        }
    }

    /// Initialises the timer on `clock` in `mode`, handing `state` to the
    /// callback. Once per timer (EBUSY after that), before any
    /// [`HrTimer::start`]. Process context.
    pub(crate) fn init(
        &'static self,
        clock: ClockId,
        mode: HrTimerMode,
        state: H::State,
    ) -> Result {
        if self
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
            bindings::hrtimer_init(self.timer.get(), clock.raw(), mode.raw());
            (*self.timer.get()).function = Some(run::<H>);
        }
        self.mode.store(mode.raw(), Ordering::Relaxed);
        // INVARIANT: timer, mode and state are initialised above; the
        // release store publishes them to `start` and `cancel`.
        self.phase.store(READY, Ordering::Release);
        Ok(())
    }

    fn ready(&self) -> bool {
        self.phase.load(Ordering::Acquire) == READY
    }

    /// Arms the timer for `expires` nanoseconds (an absolute time of its
    /// clock, or relative to now, as its mode says), with no slack. A timer
    /// already queued is moved. Does nothing before [`HrTimer::init`]. Any
    /// context, including this timer's own callback.
    pub(crate) fn start(&self, expires: i64) {
        if !self.ready() {
            return;
        }
        self.armed.store(expires, Ordering::Relaxed);
        // READY, so the timer is initialised (type invariant) with the mode
        // passed here, as hrtimer_start_range_ns requires (the soft bit must
        // match). The core serialises concurrent starts and cancels with the
        // timer base lock.
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

    /// The expiry last requested with [`HrTimer::start`] (0: never
    /// started). A racy hint when another context re-arms concurrently.
    pub(crate) fn armed_for(&self) -> i64 {
        self.armed.load(Ordering::Relaxed)
    }

    /// Cancels the timer: when this returns, it is not queued and its
    /// callback is not running (`hrtimer_cancel` waits for a running one).
    /// Returns whether it was queued or running. A callback (of any timer)
    /// may re-arm it afterwards; callers that tear down make sure none
    /// will. Process context, or a softirq that is not this timer's own
    /// callback (that would wait for itself).
    pub(crate) fn cancel(&self) -> bool {
        if !self.ready() {
            return false;
        }
        // SAFETY: READY, so the timer is initialised (type invariant).
        unsafe { bindings::hrtimer_cancel(self.timer.get()) != 0 }
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
    // CAST: `timer` is the first field of the `#[repr(C)]` `HrTimer<H>`.
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
