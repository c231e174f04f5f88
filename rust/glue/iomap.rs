// SPDX-License-Identifier: GPL-2.0

//! Bounds-checked register access through an iomap cookie: [`IoRange`],
//! shared by PCI BAR mappings ([`super::pci::IoMem`]) and ISA windows
//! ([`super::isa::IoWindow`]). The kernel's `ioread*`/`iowrite*` take
//! either kind of cookie (memory or port). Any context.
//!
//! An ISA window lends its range for as long as it is claimed (its
//! owner, the module, is the binding). A PCI mapping lends it only
//! through a [`super::pci::IoGuard`], while its binding lasts: the range
//! checks bounds, the guard checks the binding.

use super::bindings;
use core::ptr::NonNull;
use kernel::ffi;

/// `len` bytes of I/O space behind an iomap cookie. It does not own the
/// mapping: its owner unmaps it after the last use.
///
/// # Invariants
///
/// `addr` is an iomap cookie valid for `len` bytes as long as this value
/// exists.
pub(crate) struct IoRange {
    addr: NonNull<ffi::c_void>,
    len: usize,
}

// SAFETY: the I/O accessors may be used from any thread and context;
// callers serialise access to the device registers themselves.
unsafe impl Send for IoRange {}
// SAFETY: as above.
unsafe impl Sync for IoRange {}

impl IoRange {
    /// # Safety
    ///
    /// `addr` is an iomap cookie valid for `len` bytes until the returned
    /// value is dropped.
    pub(crate) unsafe fn new(addr: NonNull<ffi::c_void>, len: usize) -> Self {
        // INVARIANT: the caller's guarantee.
        IoRange { addr, len }
    }

    /// The cookie, for the owner to unmap it.
    pub(crate) fn cookie(&self) -> *mut ffi::c_void {
        self.addr.as_ptr()
    }

    /// Length of the range.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    fn at(&self, off: usize, width: usize) -> Option<*mut ffi::c_void> {
        if off.checked_add(width)? > self.len {
            return None;
        }
        // SAFETY: `off + width <= len`, inside the mapping (invariant);
        // the result is an iomap cookie the accessors understand.
        Some(unsafe { self.addr.as_ptr().cast::<u8>().add(off).cast() })
    }

    /// `ioread8` at `off`; outside the range reads 0xFF (as
    /// absent hardware does).
    pub(crate) fn read8(&self, off: usize) -> u8 {
        match self.at(off, 1) {
            // SAFETY: inside the mapping.
            Some(p) => unsafe { bindings::ioread8(p) as u8 },
            None => 0xFF,
        }
    }

    /// `iowrite8` at `off`; ignored outside the range.
    pub(crate) fn write8(&self, off: usize, val: u8) {
        if let Some(p) = self.at(off, 1) {
            // SAFETY: inside the mapping.
            unsafe { bindings::iowrite8(val, p) };
        }
    }

    /// `ioread16` at `off` (little-endian).
    pub(crate) fn read16(&self, off: usize) -> u16 {
        match self.at(off, 2) {
            // SAFETY: inside the mapping.
            Some(p) => unsafe { bindings::ioread16(p) as u16 },
            None => !0,
        }
    }

    /// `iowrite16` at `off` (little-endian).
    pub(crate) fn write16(&self, off: usize, val: u16) {
        if let Some(p) = self.at(off, 2) {
            // SAFETY: inside the mapping.
            unsafe { bindings::iowrite16(val, p) };
        }
    }

    /// `ioread32` at `off`.
    pub(crate) fn read32(&self, off: usize) -> u32 {
        match self.at(off, 4) {
            // SAFETY: inside the mapping.
            Some(p) => unsafe { bindings::ioread32(p) },
            None => !0,
        }
    }

    /// `iowrite32` at `off`.
    pub(crate) fn write32(&self, off: usize, val: u32) {
        if let Some(p) = self.at(off, 4) {
            // SAFETY: inside the mapping.
            unsafe { bindings::iowrite32(val, p) };
        }
    }
}
