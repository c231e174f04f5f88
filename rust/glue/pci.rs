// SPDX-License-Identifier: GPL-2.0

//! PCI drivers and their I/O regions.
//!
//! * [`Driver`] + [`Registration`]: a `struct pci_driver` from a Rust
//!   trait. `probe` returns the device's driver data (boxed, kept as the
//!   PCI drvdata); `remove` gets it back. Both run in process context.
//! * [`Device`]: the `struct pci_dev` a probe is for; [`Enabled`] keeps it
//!   enabled (`pci_disable_device` on drop); [`IoMem`] is one mapped BAR
//!   (port or memory space, through the kernel's `ioread*`/`iowrite*`),
//!   unmapped on drop.
//!
//! Modelled on upstream's `rust/kernel/pci.rs` (Adapter + id table +
//! drvdata), with 6.12's C API.

use super::bindings;
use super::iomap::IoRange;
use super::module::{ExitTable, ModuleScope, SweepKind};
use core::cell::UnsafeCell;
use core::marker::PhantomData;
use core::ops::Deref;
use core::ptr::NonNull;
use kernel::error::{code, Result};
use kernel::ffi;
use kernel::prelude::*;

/// An entry of a PCI driver's id table (`struct pci_device_id`), for the
/// tables drivers declare (made with [`id`], ended by [`ID_END`]) and the
/// `MODULE_DEVICE_TABLE` alias in their module root.
pub(crate) type DeviceId = bindings::pci_device_id;

/// A PCI device id table entry (vendor, device; any subsystem).
pub(crate) const fn id(vendor: u16, device: u16) -> bindings::pci_device_id {
    bindings::pci_device_id {
        vendor: vendor as u32,
        device: device as u32,
        subvendor: !0,
        subdevice: !0,
        class: 0,
        class_mask: 0,
        driver_data: 0,
        override_only: 0,
    }
}

/// The all-zero entry that ends an id table (the PCI core stops at the
/// first entry whose vendor, subvendor, class mask and override flag are
/// all zero).
pub(crate) const ID_END: bindings::pci_device_id = bindings::pci_device_id {
    vendor: 0,
    device: 0,
    subvendor: 0,
    subdevice: 0,
    class: 0,
    class_mask: 0,
    driver_data: 0,
    override_only: 0,
};

/// Whether `e` ends an id table for the PCI core.
const fn is_end(e: &bindings::pci_device_id) -> bool {
    e.vendor == 0 && e.subvendor == 0 && e.class_mask == 0 && e.override_only == 0
}

/// A PCI driver.
pub(crate) trait Driver: Sized + 'static {
    /// What a bound device keeps (freed after `remove`).
    type Data: Send + Sync;
    /// A device matched the id table. Process context; may sleep. The
    /// module's `scope` is lent for the call (the driver was registered
    /// with it), for what the probe registers whose teardown the module's
    /// exit owns (its network devices).
    fn probe(dev: &Device, scope: &ModuleScope) -> Result<KBox<Self::Data>>;
    /// The device goes away (driver unload or hot unplug). Process
    /// context; may sleep.
    fn remove(data: KBox<Self::Data>);
}

/// The device being probed.
pub(crate) struct Device(NonNull<bindings::pci_dev>);

impl Device {
    pub(crate) fn as_ptr(&self) -> *mut bindings::pci_dev {
        self.0.as_ptr()
    }

    /// A counted reference to this device (`pci_dev_get`).
    fn to_ref(&self) -> PciRef {
        // SAFETY: a live device during probe; the reference taken here is
        // dropped by `PciRef`'s Drop.
        unsafe { bindings::pci_dev_get(self.as_ptr()) };
        // INVARIANT: one reference, taken above.
        PciRef(self.0)
    }

    /// `pci_enable_device`; disabled again when the guard is dropped.
    pub(crate) fn enable(&self) -> Result<Enabled> {
        // SAFETY: a live device during probe.
        super::to_result(unsafe { bindings::pci_enable_device(self.as_ptr()) })?;
        Ok(Enabled(self.to_ref()))
    }

    /// Maps the first `len` bytes of BAR `bar` (`pci_iomap`), or the
    /// whole BAR if it is shorter (accesses past it then read 0xFF and
    /// are dropped, see [`IoMem`]); ENODEV if the BAR is absent.
    pub(crate) fn iomap(&self, bar: i32, len: usize) -> Result<IoMem> {
        // SAFETY: a live device; reads its resource table.
        let have = unsafe { bindings::rcan_pci_resource_len(self.as_ptr(), bar) } as usize;
        if have == 0 {
            return Err(code::ENODEV);
        }
        let len = len.min(have);
        // SAFETY: a live, enabled device; NULL on failure.
        let p = unsafe { bindings::pci_iomap(self.as_ptr(), bar, len as ffi::c_ulong) };
        let addr = NonNull::new(p).ok_or(code::ENOMEM)?;
        // INVARIANT: a mapping of `len` bytes, unmapped in Drop.
        Ok(IoMem {
            // SAFETY: `addr` maps `len` bytes until IoMem's Drop unmaps it,
            // after the IoRange is last used.
            io: unsafe { IoRange::new(addr, len) },
            pdev: self.to_ref(),
        })
    }

    /// The PCI subsystem device id.
    pub(crate) fn subsystem_id(&self) -> u16 {
        // SAFETY: a live device; set at enumeration.
        unsafe { (*self.as_ptr()).subsystem_device }
    }

    /// Writes a 16-bit word of configuration space (`pci_write_config_word`).
    pub(crate) fn write_config_word(&self, off: i32, val: u16) -> Result {
        // SAFETY: a live device during probe; the PCI core checks `off`.
        super::to_result(unsafe { bindings::pci_write_config_word(self.as_ptr(), off, val) })?;
        Ok(())
    }

    /// The PCI device id.
    pub(crate) fn device_id(&self) -> u16 {
        // SAFETY: a live device; set at enumeration.
        unsafe { (*self.as_ptr()).device }
    }

    /// The interrupt line.
    pub(crate) fn irq(&self) -> u32 {
        // SAFETY: a live device; `irq` is set before probe.
        unsafe { (*self.as_ptr()).irq }
    }
}

/// A counted reference to a `struct pci_dev` (`pci_dev_get`), dropped
/// with `pci_dev_put` (any context): what [`Enabled`] and [`IoMem`] hold,
/// so that the device struct outlives them wherever a driver keeps them
/// (its driver data is dropped in `remove`, but a driver may move them
/// elsewhere; a forgotten one leaks the reference, never frees early).
///
/// # Invariants
///
/// Holds one reference on the device.
struct PciRef(NonNull<bindings::pci_dev>);

// SAFETY: a reference count may be dropped from any thread and context.
unsafe impl Send for PciRef {}
// SAFETY: no access through a shared reference.
unsafe impl Sync for PciRef {}

impl Drop for PciRef {
    fn drop(&mut self) {
        // SAFETY: we hold one reference (type invariant).
        unsafe { bindings::pci_dev_put(self.0.as_ptr()) };
    }
}

/// Keeps a PCI device enabled.
pub(crate) struct Enabled(PciRef);

impl Drop for Enabled {
    fn drop(&mut self) {
        // SAFETY: enabled by Device::enable; our reference keeps the
        // device struct alive until after this call (the field drops
        // after this body).
        unsafe { bindings::pci_disable_device(self.0 .0.as_ptr()) };
    }
}

/// One mapped PCI BAR.
///
/// # Invariants
///
/// `io` holds a `pci_iomap` cookie for its length of `pdev`, valid until
/// Drop; `pdev` keeps the device struct alive until after the unmap.
pub(crate) struct IoMem {
    io: IoRange,
    pdev: PciRef,
}

// SAFETY: the accessors are IoRange's (any thread and context); `pdev` is
// only used to unmap in Drop, and dropped from any thread.
unsafe impl Send for IoMem {}
// SAFETY: as above.
unsafe impl Sync for IoMem {}

impl Deref for IoMem {
    type Target = IoRange;

    fn deref(&self) -> &IoRange {
        &self.io
    }
}

impl Drop for IoMem {
    fn drop(&mut self) {
        // SAFETY: mapped by pci_iomap for this device (invariant), whose
        // struct our reference keeps alive (dropped after this body).
        unsafe { bindings::pci_iounmap(self.pdev.0.as_ptr(), self.io.cookie()) };
    }
}

/// A registered PCI driver; lives in a static of the module.
pub(crate) struct Registration<T: Driver> {
    drv: UnsafeCell<bindings::pci_driver>,
    _t: PhantomData<T>,
}

// SAFETY: the C struct is written only in `register` (module init, before
// the kernel sees it); afterwards the PCI core owns it.
unsafe impl<T: Driver> Sync for Registration<T> {}

impl<T: Driver> Registration<T> {
    pub(crate) const fn new() -> Self {
        Registration {
            // SAFETY: all-zero is a valid unregistered pci_driver.
            drv: UnsafeCell::new(unsafe { core::mem::zeroed() }),
            _t: PhantomData,
        }
    }

    /// Registers the driver for `ids` (ending with [`ID_END`]). Module
    /// init only: the `scope` proves the module's exit is the glue's,
    /// which unregisters the driver if [`Registration::unregister`] was
    /// not called, before it sweeps the module's devices; probes of
    /// present devices run before this returns. EBUSY if registered
    /// already, ENOSPC beyond [`MAX_PCI_DRIVERS`] drivers in one module.
    pub(crate) fn register(
        &'static self,
        name: &'static kernel::str::CStr,
        ids: &'static [bindings::pci_device_id],
        _scope: &ModuleScope,
    ) -> Result {
        // Exactly one terminator, at the end: the PCI core walks the
        // table until it finds one.
        match ids.split_last() {
            Some((last, rest)) if is_end(last) && !rest.iter().any(is_end) => {}
            _ => return Err(code::EINVAL),
        }
        let me = self.drv.get().cast::<()>();
        // SAFETY: `unregister_erased` unregisters this driver, registered
        // from just below until the slot is taken back; before that
        // (failure, below) the slot is taken back first.
        let new = unsafe {
            PCI_DRIVERS.note(me, unregister_erased, SweepKind::PciDrivers, pci_sweep)?
        };
        if !new {
            return Err(code::EBUSY);
        }
        // SAFETY: module init: nothing else references the struct yet.
        let ret = unsafe {
            let d = &mut *self.drv.get();
            d.name = name.as_char_ptr();
            d.id_table = ids.as_ptr();
            d.probe = Some(probe::<T>);
            d.remove = Some(remove::<T>);
            super::to_result(bindings::__pci_register_driver(
                d,
                super::this_module(),
                name.as_char_ptr(),
            ))
        };
        if ret.is_err() {
            // SAFETY: the registration failed: there is nothing to undo.
            unsafe { PCI_DRIVERS.take(me, unregister_erased) };
        }
        ret.map(|_| ())
    }

    /// Unregisters (calls `remove` for every bound device), if registered.
    /// Module exit; the glue's exit does it for a module that does not.
    pub(crate) fn unregister(&'static self) {
        let me = self.drv.get().cast::<()>();
        // SAFETY: a true result is followed by the unregistration below.
        if unsafe { PCI_DRIVERS.take(me, unregister_erased) } {
            // SAFETY: registered (the slot was ours to take).
            unsafe { unregister_erased(me) };
        }
    }
}

/// Most PCI drivers one module registers (one each today).
pub(crate) const MAX_PCI_DRIVERS: usize = 2;

/// The PCI drivers this module registered and has not unregistered (one
/// table per module: the glue is compiled into each), keyed by their
/// `struct pci_driver`; swept at exit by [`pci_sweep`], before the
/// module's devices. Process context.
static PCI_DRIVERS: ExitTable<MAX_PCI_DRIVERS> = ExitTable::new();

/// `pci_unregister_driver` of the driver at `drv`. Process context.
///
/// # Safety
///
/// `drv` is a registered `struct pci_driver`, unregistered only here.
unsafe fn unregister_erased(drv: *mut ()) {
    // SAFETY: per the contract.
    unsafe { bindings::pci_unregister_driver(drv.cast()) };
}

/// The exit's sweep ([`Scoped`](super::module::Scoped), step 3): every
/// PCI driver of this module still registered is unregistered. Process
/// context; sleeps.
fn pci_sweep() {
    PCI_DRIVERS.sweep();
}

unsafe extern "C" fn probe<T: Driver>(
    pdev: *mut bindings::pci_dev,
    _id: *const bindings::pci_device_id,
) -> ffi::c_int {
    let Some(p) = NonNull::new(pdev) else {
        return code::EINVAL.to_errno();
    };
    let dev = Device(p);
    // Only `Registration::register`, which takes the module's scope,
    // installs this function: the module's exit is the glue's.
    match super::module::lend_scope(|scope| T::probe(&dev, scope)) {
        Ok(data) => {
            // SAFETY: a live device; drvdata holds the box until remove.
            unsafe { bindings::rcan_pci_set_drvdata(pdev, KBox::into_raw(data).cast()) };
            0
        }
        Err(e) => e.to_errno(),
    }
}

unsafe extern "C" fn remove<T: Driver>(pdev: *mut bindings::pci_dev) {
    // SAFETY: probe succeeded for this device, so drvdata is our box.
    let data = unsafe { bindings::rcan_pci_get_drvdata(pdev) }.cast::<T::Data>();
    if data.is_null() {
        return;
    }
    // SAFETY: set in probe from KBox::into_raw; taken back exactly once.
    let data = unsafe { KBox::from_raw(data) };
    // SAFETY: clear the stale pointer.
    unsafe { bindings::rcan_pci_set_drvdata(pdev, core::ptr::null_mut()) };
    T::remove(data);
}
