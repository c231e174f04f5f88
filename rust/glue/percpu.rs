// SPDX-License-Identifier: GPL-2.0

//! Per-CPU data.
//!
//! * [`CpuMarks`]: one `u64` per CPU, inline for up to 8 CPUs, else in an
//!   ordinary allocation (cheaper to make than per-CPU memory, which
//!   matters when one is made per socket).
//! * [`rx_stamp`]: a per-CPU counter of this module, one number per
//!   frame the receive path dispatches on that CPU, with the CPU's id.

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

    /// Marks `stamp`'s CPU with its frame number: true if that mark did
    /// not hold the number yet (the first time this frame meets these
    /// marks), false if it did. Meant for the BH-disabled context that took
    /// `stamp` (no migration, and nothing else on this CPU touches its
    /// mark in between, so a load and a store suffice: no locked
    /// read-modify-write); any context is memory-safe.
    #[inline]
    pub(crate) fn mark(&self, stamp: &RxStamp) -> bool {
        use core::sync::atomic::Ordering::Relaxed;
        let marks: &[core::sync::atomic::AtomicU64] = match self {
            CpuMarks::Inline(a) => a,
            CpuMarks::Heap(v) => v,
        };
        match marks.get(stamp.cpu) {
            Some(m) if m.load(Relaxed) != stamp.serial => {
                m.store(stamp.serial, Relaxed);
                true
            }
            Some(_) => false,
            // Cannot happen (cpu < nr_cpu_ids); deliver rather than lose.
            None => true,
        }
    }
}

/// One frame's number on the CPU that dispatches it, with that CPU's id.
pub(crate) struct RxStamp {
    /// The CPU's frame counter after this frame (starts at 1, so fresh
    /// [`CpuMarks`] never hold it).
    serial: u64,
    /// The CPU the number was taken on.
    cpu: usize,
}

/// The next number of this CPU's frame counter, and the CPU, in one call.
/// Call with BH disabled (NET_RX softirq), so that the frame keeps the CPU
/// while its receivers are marked.
#[inline]
pub(crate) fn rx_stamp() -> RxStamp {
    let mut cpu: u32 = 0;
    // SAFETY: this_cpu_inc_return on this module's own per-CPU variable
    // and raw_smp_processor_id, both valid in any context; `cpu` is a
    // valid place for the id.
    let serial = unsafe { bindings::rcan_rx_serial_next(&mut cpu) };
    RxStamp {
        serial,
        cpu: cpu as usize,
    }
}
