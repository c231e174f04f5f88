// SPDX-License-Identifier: GPL-2.0

//! ISA-style I/O windows and the interrupt autoprobe.
//!
//! * [`IoWindow`]: a claimed and mapped range of physical memory
//!   (`request_mem_region` + `ioremap`, e.g. a memory-mapped ISA card) or
//!   of I/O ports (`request_region` + `ioport_map`, e.g. a PC/104 board).
//!   Both are accessed through the kernel's `ioread*`/`iowrite*`, which
//!   take either kind of cookie. Dropping the window unmaps and releases
//!   it, so a failed probe leaves nothing behind.
//! * [`probe_irq_on`] / [`probe_irq_off`]: the kernel's legacy interrupt
//!   autoprobe (`kernel/irq/autoprobe.c`), for ISA cards whose line is not
//!   configured.
//!
//! All of it is process context (module init); the accessors may be used
//! from any context.

use super::bindings;
use super::iomap::IoRange;
use core::ops::Deref;
use core::ptr::NonNull;
use kernel::error::{code, Result};
use kernel::ffi;

/// The kind of address space of an [`IoWindow`].
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Space {
    /// Physical memory (`/proc/iomem`).
    Mem,
    /// I/O ports (`/proc/ioports`).
    Port,
}

/// A claimed, mapped I/O window.
///
/// # Invariants
///
/// `start..start + len` of `space` is claimed by this window
/// (`request_mem_region`/`request_region`) and `io` holds an iomap cookie
/// for all of it, both until Drop.
pub(crate) struct IoWindow {
    io: IoRange,
    start: usize,
    space: Space,
}

impl Deref for IoWindow {
    type Target = IoRange;

    fn deref(&self) -> &IoRange {
        &self.io
    }
}

impl IoWindow {
    /// Claims `len` bytes of `space` at `start` for `name` and maps them.
    /// EBUSY if another driver owns any of it, ENOMEM if the mapping
    /// fails (the claim is then released again). Process context.
    pub(crate) fn request(
        space: Space,
        start: usize,
        len: usize,
        name: &'static kernel::str::CStr,
    ) -> Result<IoWindow> {
        if len == 0 {
            return Err(code::EINVAL);
        }
        let (s, n) = (start as ffi::c_ulong, len as ffi::c_ulong);
        // SAFETY: claiming a resource range has no preconditions; `name`
        // is static, as the resource tree keeps the pointer.
        let claimed = unsafe {
            match space {
                Space::Mem => bindings::rcan_request_mem_region(s, n, name.as_char_ptr()),
                Space::Port => bindings::rcan_request_region(s, n, name.as_char_ptr()),
            }
        };
        if !claimed {
            return Err(code::EBUSY);
        }
        // SAFETY: the range is ours (claimed above); NULL on failure.
        let p = unsafe {
            match space {
                Space::Mem => bindings::rcan_ioremap(s, n),
                Space::Port => bindings::rcan_ioport_map(s, len as ffi::c_uint),
            }
        };
        let Some(addr) = NonNull::new(p) else {
            // SAFETY: claimed above, not mapped.
            unsafe { release(space, s, n) };
            return Err(code::ENOMEM);
        };
        // INVARIANT: claimed and mapped above.
        Ok(IoWindow {
            // SAFETY: `addr` maps `len` bytes until IoWindow's Drop unmaps
            // it, after the IoRange is last used.
            io: unsafe { IoRange::new(addr, len) },
            start,
            space,
        })
    }

    /// First address (or port) of the window.
    pub(crate) fn start(&self) -> usize {
        self.start
    }
}

/// Releases a claimed range.
///
/// # Safety
///
/// `start..start + n` of `space` was claimed by the caller and is no
/// longer mapped.
unsafe fn release(space: Space, start: ffi::c_ulong, n: ffi::c_ulong) {
    // SAFETY: the caller's guarantee.
    unsafe {
        match space {
            Space::Mem => bindings::rcan_release_mem_region(start, n),
            Space::Port => bindings::rcan_release_region(start, n),
        }
    }
}

impl Drop for IoWindow {
    fn drop(&mut self) {
        // SAFETY: mapped in `request` (invariant), unmapped once here.
        unsafe {
            match self.space {
                Space::Mem => bindings::rcan_iounmap(self.io.cookie()),
                Space::Port => bindings::rcan_ioport_unmap(self.io.cookie()),
            }
        }
        // SAFETY: claimed in `request` (invariant) and unmapped above.
        unsafe { release(self.space, self.start as _, self.io.len() as _) };
    }
}

/// Starts the legacy interrupt autoprobe (`probe_irq_on`): enables every
/// unassigned interrupt line and returns the mask to hand to
/// [`probe_irq_off`]. Process context; may sleep (about 100 ms). At most
/// one autoprobe runs at a time (the kernel serialises it).
pub(crate) fn probe_irq_on() -> ffi::c_ulong {
    // SAFETY: process context (module init); paired with probe_irq_off.
    unsafe { bindings::rcan_probe_irq_on() }
}

/// Ends the autoprobe started by [`probe_irq_on`] with `mask`: the one
/// line that fired since (`Some(Ok(n))`), several (`Some(Err(()))`) or
/// none (`None`).
pub(crate) fn probe_irq_off(mask: ffi::c_ulong) -> Option<core::result::Result<u32, ()>> {
    // SAFETY: `mask` came from probe_irq_on in the same probe.
    let r = unsafe { bindings::rcan_probe_irq_off(mask) };
    match r {
        0 => None,
        n if n > 0 => Some(Ok(n as u32)),
        _ => Some(Err(())),
    }
}

/// Busy-waits `us` microseconds. Any context.
pub(crate) fn udelay(us: u32) {
    // SAFETY: udelay may be called in any context.
    unsafe { bindings::rcan_udelay(us as _) };
}
