// SPDX-License-Identifier: GPL-2.0

//! Per-CPU data.
//!
//! * [`PerCpuU64`]: one `u64` per CPU (`alloc_percpu`), read and written
//!   only on the current CPU, atomically with respect to preemption and
//!   interrupts (`this_cpu_xchg`).
//! * [`rx_serial_next`]: a per-CPU counter of this module, one number per
//!   frame the receive path dispatches on that CPU.

use super::bindings;
use core::ptr::NonNull;
use kernel::error::{code, Result};

/// One `u64` per possible CPU, zero when allocated.
///
/// # Invariants
///
/// `0` is a live `alloc_percpu(u64)` cookie, freed in `Drop`; it is never
/// dereferenced as a plain pointer.
pub(crate) struct PerCpuU64(NonNull<u64>);

// SAFETY: the cookie names memory of every CPU; each access goes through
// `this_cpu_*` on the current CPU, so any thread may hold and use it.
unsafe impl Send for PerCpuU64 {}
// SAFETY: as above; `xchg` is a single per-CPU atomic operation.
unsafe impl Sync for PerCpuU64 {}

impl PerCpuU64 {
    /// Allocates the counters, all zero. Process context (may sleep).
    pub(crate) fn new() -> Result<Self> {
        // SAFETY: allocates or returns NULL.
        let p = unsafe { bindings::rcan_percpu_u64_alloc() };
        // INVARIANT: a fresh alloc_percpu cookie.
        NonNull::new(p).map(PerCpuU64).ok_or(code::ENOMEM)
    }

    /// Stores `v` in this CPU's counter and returns its previous value.
    /// Any context. The caller decides what a CPU change between two calls
    /// means: within one NET_RX softirq run there is none.
    pub(crate) fn xchg(&self, v: u64) -> u64 {
        // SAFETY: a live cookie (invariant); this_cpu_xchg is safe in any
        // context.
        unsafe { bindings::rcan_percpu_u64_xchg(self.0.as_ptr(), v) }
    }
}

impl Drop for PerCpuU64 {
    fn drop(&mut self) {
        // SAFETY: allocated by alloc_percpu (invariant), freed once; any
        // context but NMI may free per-CPU memory.
        unsafe { bindings::rcan_percpu_u64_free(self.0.as_ptr()) };
    }
}

/// The next number of this CPU's frame counter (starts at 1, so a fresh
/// [`PerCpuU64`] never equals it). Call with BH disabled (NET_RX softirq)
/// so that the number and the marks compared with it are of one CPU.
pub(crate) fn rx_serial_next() -> u64 {
    // SAFETY: this_cpu_inc_return on this module's own per-CPU variable;
    // any context.
    unsafe { bindings::rcan_rx_serial_next() }
}
