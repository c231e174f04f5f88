// SPDX-License-Identifier: GPL-2.0

//! Heap-allocated objects with their own high-resolution timers: one
//! [`JobTimers`] per job of a protocol (a CAN_BCM operation has a
//! transmit timer, or a timeout and a throttle timer), created and dropped
//! at run time, unlike [`super::hrtimer::HrTimer`], which lives in a
//! static.
//!
//! A `JobTimers<H>` owns one allocation holding [`JOB_TIMERS`] `struct
//! hrtimer`s and the job's data (`H::Data`). The timers run on
//! `CLOCK_MONOTONIC` in `HRTIMER_MODE_ABS_SOFT`: callbacks run in the
//! `HRTIMER_SOFTIRQ` softirq (bottom halves disabled, must not sleep; may
//! send frames and queue skbs), as mainline's `can-bcm` timers do. A
//! callback gets a [`JobRef`]: the data and the right to re-arm or cancel
//! the job's timers, and re-arms its own timer cheapest by returning the
//! next expiry (the trampoline sets it and returns `HRTIMER_RESTART`, as
//! mainline's `bcm_tx_timeout_handler` does, instead of a second
//! `hrtimer_start` with the timer base lock taken again).
//!
//! Restart against a concurrent [`JobRef::start`]: the expiry of a queued
//! timer must never be written without the timer base lock. A job has one
//! `rearm` lock (irqsave, lockdep class `jobtimer_rearm`): `start` holds it
//! around `hrtimer_start_range_ns`; the trampoline takes it after the
//! callback and writes the new expiry only if the timer is not queued
//! (nobody started it meanwhile) and the job is not dying, else it
//! returns `HRTIMER_NORESTART` (the `start` wins). Once the trampoline has
//! released the lock, a `start` finds the timer unqueued with its callback
//! running, sets its own expiry under the base lock and queues it; the
//! hrtimer core then sees it queued and does not queue it again. Only
//! `start` and the core's restart queue a job timer, so under `rearm`
//! "not queued" stays true until the trampoline returns.
//!
//! Teardown: dropping the `JobTimers` (process context, never from one of
//! its own callbacks) marks the job dying, so that [`JobRef::start`] arms
//! nothing any more, then cancels every timer twice with `hrtimer_cancel`
//! (which waits for a running callback): the first pass waits for every
//! callback that could have missed the mark (one of them may re-arm a
//! timer that pass already cancelled); the second removes what they armed
//! and waits for callbacks that started later, which see the mark. Only
//! then is the allocation, data included, freed: no timer is queued and no
//! callback runs when the memory goes.
//!
//! A job never dropped (`mem::forget`, a leaked owner) is killed by its
//! module's exit: every live job is on the module's [`JOBS`] list (a node
//! in its allocation), and the exit's sweep
//! ([`Scoped`](super::module::Scoped), step 3) marks each job left there
//! dying and cancels its timers as the drop does, but frees nothing (its
//! owner may still hold it): the memory leaks (marked for kmemleak as a
//! leak on purpose), no timer fires into the module's freed text.
//! [`JobTimers::new`] takes the evidence that its module's exit is the
//! glue's ([`InScopedModule`]).

use super::bindings;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox};
use kernel::error::{code, Result};
use kernel::types::Opaque;

use super::lock::{new_irq_spinlock, IrqSpinLock};
use super::module::{ExitList, ExitNode, InScopedModule, SweepKind};

/// Timers per job.
pub(crate) const JOB_TIMERS: usize = 2;

/// The callback of a job's timers.
pub(crate) trait JobCallback: Sized + 'static {
    /// The job's data, shared by its owner and its callbacks (which may
    /// run on any CPU, concurrently with the owner): lock what changes.
    type Data: Send + Sync;

    /// Timer `which` (`0..JOB_TIMERS`) of `job` expired. `HRTIMER_SOFTIRQ`
    /// softirq context; must not sleep. Callbacks of one timer never
    /// overlap; those of two timers of a job may.
    fn expired(job: JobRef<'_, Self>, which: usize);

    /// What the timer core calls: [`JobCallback::expired`], unless a job
    /// overrides this to re-arm the timer by its return value, the expiry
    /// (CLOCK_MONOTONIC ns) to run again at, or `None`. A `start` of this
    /// timer made meanwhile (also by the callback itself) wins over the
    /// returned expiry (module documentation). Context as `expired`.
    fn expired_restart(job: JobRef<'_, Self>, which: usize) -> Option<u64> {
        Self::expired(job, which);
        None
    }
}

/// One timer of a job and the way back to the job.
#[repr(C)]
struct Slot<H: JobCallback> {
    /// First field: the C callback finds the slot from the timer pointer.
    timer: Opaque<bindings::hrtimer>,
    /// The job this timer belongs to (set before the timer is
    /// initialised, never changed).
    job: *const Inner<H>,
    which: usize,
}

struct Inner<H: JobCallback> {
    slots: [Slot<H>; JOB_TIMERS],
    /// The job on its module's [`JOBS`] list from `new` until its drop or
    /// the module's exit takes it off.
    exit: ExitNode,
    /// Set by Drop before the final cancellation: `start` arms nothing.
    dying: AtomicBool,
    /// Serialises `start` against the trampoline's restart (irqsave:
    /// `start` may run in any context; lockdep class `jobtimer_rearm`).
    rearm: IrqSpinLock<()>,
    data: H::Data,
}

/// A job with its timers. See the module documentation.
///
/// # Invariants
///
/// `inner` comes from `KBox::into_raw` and is owned by this value; every
/// slot's timer was initialised by `hrtimer_init` (CLOCK_MONOTONIC,
/// `HRTIMER_MODE_ABS_SOFT`) with `expired_trampoline::<H>` as its function
/// and `job` pointing at `inner`.
pub(crate) struct JobTimers<H: JobCallback> {
    inner: NonNull<Inner<H>>,
}

// SAFETY: the data is Send + Sync; the timers are used through the hrtimer
// API, which does its own locking; dropping from another thread is fine
// (process context required, documented).
unsafe impl<H: JobCallback> Send for JobTimers<H> {}
// SAFETY: shared access only reaches `H::Data` (Sync) and the hrtimer API.
unsafe impl<H: JobCallback> Sync for JobTimers<H> {}

/// A borrowed job: its data and its timers.
pub(crate) struct JobRef<'a, H: JobCallback> {
    inner: &'a Inner<H>,
}

impl<H: JobCallback> Clone for JobRef<'_, H> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<H: JobCallback> Copy for JobRef<'_, H> {}

impl<H: JobCallback> JobTimers<H> {
    /// A job with `data` and [`JOB_TIMERS`] idle timers, on its module's
    /// list of jobs, which the module's exit kills (`_in`: the module's
    /// exit is the glue's). Process context (allocates with GFP_KERNEL).
    pub(crate) fn new(data: H::Data, _in: &impl InScopedModule) -> Result<Self> {
        let b = KBox::new(
            Inner {
                slots: [const {
                    Slot {
                        timer: Opaque::uninit(),
                        job: core::ptr::null(),
                        which: 0,
                    }
                }; JOB_TIMERS],
                exit: ExitNode::new(),
                dying: AtomicBool::new(false),
                rearm: new_irq_spinlock!((), "jobtimer_rearm")?,
                data,
            },
            GFP_KERNEL,
        )?;
        let p = KBox::into_raw(b);
        for i in 0..JOB_TIMERS {
            // The allocation does not move from here on; nothing else knows
            // it yet, so writing the slots through the raw pointer races
            // with nobody. hrtimer_init fully initialises the C struct.
            // SAFETY: `p` is a valid, exclusively owned allocation (above).
            unsafe {
                let slot = core::ptr::addr_of_mut!((*p).slots[i]);
                (*slot).job = p;
                (*slot).which = i;
                let t = (*slot).timer.get();
                bindings::hrtimer_init(
                    t,
                    bindings::CLOCK_MONOTONIC as bindings::clockid_t,
                    bindings::hrtimer_mode_HRTIMER_MODE_ABS_SOFT,
                );
                (*t).function = Some(expired_trampoline::<H>);
            }
        }
        // The allocation stays in place until the job's drop frees it,
        // after taking it off the list; `kill::<H>` of it may run once, in
        // process context, while it is on the list (it frees nothing).
        // SAFETY: so this is push's contract.
        unsafe {
            JOBS.push(
                &(*p).exit,
                p.cast(),
                kill::<H>,
                SweepKind::Jobs,
                jobs_sweep,
            )
        };
        // INVARIANT: from KBox::into_raw; every slot initialised above.
        // SAFETY: KBox::into_raw never returns NULL.
        Ok(JobTimers {
            inner: unsafe { NonNull::new_unchecked(p) },
        })
    }

    /// The job, borrowed.
    pub(crate) fn get(&self) -> JobRef<'_, H> {
        // SAFETY: owned and alive while `self` is (type invariant); only
        // shared references to it are ever made.
        JobRef {
            inner: unsafe { self.inner.as_ref() },
        }
    }

    /// The job's data.
    pub(crate) fn data(&self) -> &H::Data {
        &self.get().inner.data
    }
}

impl<'a, H: JobCallback> JobRef<'a, H> {
    /// The job's data.
    pub(crate) fn data(&self) -> &'a H::Data {
        &self.inner.data
    }

    /// Arms timer `which` to expire at `at` (CLOCK_MONOTONIC nanoseconds,
    /// as [`super::hrtimer::ktime_get_mono_ns`] gives), moving it if it is
    /// queued; nothing once the job is being dropped. Any context,
    /// including the job's own callbacks. Out-of-range `which`: nothing.
    pub(crate) fn start(&self, which: usize, at: u64) {
        let Some(slot) = self.inner.slots.get(which) else {
            return;
        };
        if self.inner.dying.load(Ordering::SeqCst) {
            return;
        }
        let at = at.min(i64::MAX as u64) as i64;
        // Held across the start: the trampoline's restart sees it (module
        // documentation).
        let _rearm = self.inner.rearm.lock();
        // SAFETY: an initialised timer (JobTimers invariant) of a live job
        // (`'a`); the mode matches hrtimer_init's, as the soft bit must.
        unsafe {
            bindings::hrtimer_start_range_ns(
                slot.timer.get(),
                at,
                0,
                bindings::hrtimer_mode_HRTIMER_MODE_ABS_SOFT,
            )
        };
    }

    /// Dequeues timer `which` if it is queued, without waiting for a
    /// running callback (`hrtimer_try_to_cancel`): returns false if its
    /// callback is running right now (it will still finish; callers keep
    /// their own record of what is armed and let a stale callback see
    /// that). Any context, including under a spinlock the callback takes.
    pub(crate) fn try_cancel(&self, which: usize) -> bool {
        let Some(slot) = self.inner.slots.get(which) else {
            return true;
        };
        // SAFETY: an initialised timer of a live job.
        unsafe { bindings::hrtimer_try_to_cancel(slot.timer.get()) >= 0 }
    }
}

impl<H: JobCallback> Drop for JobTimers<H> {
    /// Process context (or any context but one of this job's own
    /// callbacks, which it would wait for); waits for running callbacks.
    fn drop(&mut self) {
        let inner = self.get().inner;
        if !JOBS.remove(&inner.exit) {
            // The module's exit took it (it is going away while this job
            // is still owned): it kills the timers and the memory leaks.
            return;
        }
        inner.kill();
        // No timer is queued or running and none can be armed (module
        // documentation), so nothing reaches the allocation any more.
        // SAFETY: from KBox::into_raw (type invariant), freed once here.
        drop(unsafe { KBox::from_raw(self.inner.as_ptr()) });
    }
}

impl<H: JobCallback> Inner<H> {
    /// Marks the job dying and cancels its timers twice (module
    /// documentation): when this returns no timer is queued or running
    /// and none can be armed again. Process context.
    fn kill(&self) {
        self.dying.store(true, Ordering::SeqCst);
        for _pass in 0..2 {
            for slot in &self.slots {
                // SAFETY: an initialised timer of a live job (JobTimers
                // invariant; `&self`).
                unsafe { bindings::hrtimer_cancel(slot.timer.get()) };
            }
        }
    }
}

/// The jobs of this module not dropped yet (the glue is compiled into each
/// module: one list per module), through the nodes in their allocations;
/// swept at exit by [`jobs_sweep`]. Unbounded (CAN_BCM has a job per
/// operation), so a list, not a table.
static JOBS: ExitList = ExitList::new(kernel::c_str!("rcan_glue_jobs"));

/// The exit's sweep ([`Scoped`](super::module::Scoped), step 3): kills
/// every job of this module still alive. Process context; waits for
/// running callbacks.
fn jobs_sweep() {
    JOBS.sweep();
}

/// Kills the job at `inner` ([`Inner::kill`]) and leaves its memory to
/// its owner, which never frees it now (its drop finds it off the list).
///
/// # Safety
///
/// `inner` is the allocation of a live `JobTimers<H>`, taken off [`JOBS`]
/// by the caller (the exit's sweep).
unsafe fn kill<H: JobCallback>(inner: *mut ()) {
    // SAFETY: a live job's allocation (contract), which its owner no
    // longer frees (it is off the list), so it stays valid.
    unsafe { &*inner.cast::<Inner<H>>() }.kill();
    // The leak is the price of a forgotten job, not a bug of the kernel's:
    // kmemleak neither reports it nor what it points to (it still scans it).
    // SAFETY: any pointer may be passed; kmemleak looks it up.
    unsafe { bindings::rcan_kmemleak_not_leak(inner.cast_const().cast()) };
}

/// The C callback of every job timer.
///
/// # Safety
///
/// Called by the hrtimer core for a timer that `JobTimers::<H>::new`
/// initialised (the only place that installs this function), while its
/// `JobTimers` is alive (its Drop waits for running callbacks).
unsafe extern "C" fn expired_trampoline<H: JobCallback>(
    t: *mut bindings::hrtimer,
) -> bindings::hrtimer_restart {
    // CAST: `timer` is the first field of the `#[repr(C)]` `Slot<H>`.
    let slot = t as *const Slot<H>;
    // SAFETY: a slot of a live job (this function's contract); `job` and
    // `which` were written before the timer could be started.
    let (job, which) = unsafe { ((*slot).job, (*slot).which) };
    // SAFETY: as above; shared access only.
    let inner = unsafe { &*job };
    let Some(at) = H::expired_restart(JobRef { inner }, which) else {
        return bindings::hrtimer_restart_HRTIMER_NORESTART;
    };
    let at = at.min(i64::MAX as u64) as i64;
    let _rearm = inner.rearm.lock();
    if inner.dying.load(Ordering::SeqCst) {
        return bindings::hrtimer_restart_HRTIMER_NORESTART;
    }
    // `t` is this running callback's timer (contract above). Under `rearm`
    // no `start` queues it, and nothing else does (module documentation),
    // so if it is not queued now its expiry is ours to write until we
    // return, as hrtimer_set_expires in a callback does.
    // SAFETY: as just said; `state` is read as hrtimer_is_queued reads it.
    unsafe {
        let queued = core::ptr::read_volatile(core::ptr::addr_of!((*t).state)) as u32
            & bindings::HRTIMER_STATE_ENQUEUED
            != 0;
        if queued {
            return bindings::hrtimer_restart_HRTIMER_NORESTART;
        }
        (*t).node.expires = at;
        (*t)._softexpires = at;
    }
    bindings::hrtimer_restart_HRTIMER_RESTART
}

/// A value set at most once, then read-only until dropped: for state a
/// socket allocates on first use and readers without the socket lock
/// (receive callbacks) look up.
pub(crate) struct OnceBox<T: Send + Sync> {
    p: core::sync::atomic::AtomicPtr<T>,
}

// SAFETY: the value is only shared (`&T`, T: Sync) and freed with &mut.
unsafe impl<T: Send + Sync> Sync for OnceBox<T> {}
// SAFETY: owns a T: Send.
unsafe impl<T: Send + Sync> Send for OnceBox<T> {}

impl<T: Send + Sync> OnceBox<T> {
    pub(crate) const fn new() -> Self {
        OnceBox {
            p: core::sync::atomic::AtomicPtr::new(core::ptr::null_mut()),
        }
    }

    /// Sets the value; EBUSY (and `v` is dropped) if it was set before.
    /// Any context that may drop a `KBox`.
    pub(crate) fn set(&self, v: KBox<T>) -> Result {
        let p = KBox::into_raw(v);
        match self.p.compare_exchange(
            core::ptr::null_mut(),
            p,
            Ordering::AcqRel,
            Ordering::Acquire,
        ) {
            Ok(_) => Ok(()),
            Err(_) => {
                // SAFETY: `p` came from into_raw above and was not published.
                drop(unsafe { KBox::from_raw(p) });
                Err(code::EBUSY)
            }
        }
    }

    /// The value, if set. Any context.
    pub(crate) fn get(&self) -> Option<&T> {
        let p = self.p.load(Ordering::Acquire);
        // SAFETY: NULL or a published KBox that lives until `self` is
        // dropped (with &mut, so after this borrow ends).
        unsafe { p.as_ref() }
    }
}

impl<T: Send + Sync> Drop for OnceBox<T> {
    fn drop(&mut self) {
        let p = *self.p.get_mut();
        if !p.is_null() {
            // SAFETY: published by `set` from KBox::into_raw; ours alone now.
            drop(unsafe { KBox::from_raw(p) });
        }
    }
}
