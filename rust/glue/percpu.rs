// SPDX-License-Identifier: GPL-2.0

//! Per-CPU data.
//!
//! * [`CpuMarks`]: one `u64` per CPU, inline for up to 8 CPUs, else in an
//!   ordinary allocation (cheaper to make than per-CPU memory, which
//!   matters when one is made per socket).
//! * [`rx_serial_next`]: a per-CPU counter of this module, one number per
//!   frame the receive path dispatches on that CPU.

use super::bindings;
use kernel::error::Result;

/// Marks kept inside [`CpuMarks`] itself on machines with this many CPUs
/// or fewer (no allocation of their own).
const INLINE_CPUS: usize = 8;

/// One `u64` per possible CPU (`nr_cpu_ids`), zero when made, each meant to
/// be touched only by its own CPU (atomics, so a stale CPU number can only
/// mislead the caller's logic, never corrupt memory).
pub(crate) enum CpuMarks {
    /// `nr_cpu_ids <= INLINE_CPUS`.
    Inline([core::sync::atomic::AtomicU64; INLINE_CPUS]),
    /// More CPUs: one allocation of `nr_cpu_ids` marks.
    Heap(kernel::alloc::KVec<core::sync::atomic::AtomicU64>),
}

impl CpuMarks {
    /// Makes the marks, all zero. Process context (may allocate and
    /// sleep).
    pub(crate) fn new() -> Result<Self> {
        use core::sync::atomic::AtomicU64;
        use kernel::alloc::{flags::GFP_KERNEL, KVec};
        // SAFETY: reads a variable fixed at boot.
        let n = unsafe { bindings::rcan_nr_cpu_ids() } as usize;
        if n <= INLINE_CPUS {
            return Ok(CpuMarks::Inline([const { AtomicU64::new(0) }; INLINE_CPUS]));
        }
        let mut v = KVec::with_capacity(n, GFP_KERNEL)?;
        for _ in 0..n {
            v.push(AtomicU64::new(0), GFP_KERNEL)?;
        }
        Ok(CpuMarks::Heap(v))
    }

    /// Stores `v` in the current CPU's mark and returns its previous
    /// value. Meant for BH-disabled context (no migration in between);
    /// any context is memory-safe.
    pub(crate) fn xchg(&self, v: u64) -> u64 {
        // SAFETY: raw_smp_processor_id may be called in any context.
        let cpu = unsafe { bindings::rcan_raw_smp_processor_id() } as usize;
        let marks: &[core::sync::atomic::AtomicU64] = match self {
            CpuMarks::Inline(a) => a,
            CpuMarks::Heap(v) => v,
        };
        match marks.get(cpu) {
            Some(m) => m.swap(v, core::sync::atomic::Ordering::Relaxed),
            None => 0,
        }
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
