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
//! * The binding (issue 39, "A mapping past its binding" in
//!   architecture.rst): every [`IoMem`] and [`Enabled`] of one probe
//!   shares that probe's [`Binding`], which the glue's `remove`
//!   trampoline revokes after `T::remove` returns (and the `probe`
//!   trampoline, if `T::probe` fails). Revoking clears its `live` flag and
//!   waits for an RCU grace period (`synchronize_rcu`), then disables the
//!   device for each [`Enabled`] still alive. A register access tests the
//!   flag inside an RCU read-side section (every accessor; the only way
//!   to the registers): one that began before the revocation ends before
//!   `remove` returns, one that begins after it reads all-ones (as
//!   absent hardware does) or writes nothing, and never touches the
//!   device. So safe code that keeps an `IoMem` or an `Enabled` past
//!   `remove` (in a `static`, or in a network device whose registration
//!   it forgot) cannot program a device another driver may own by then,
//!   or whatever a hot removal's range was given to. The mapping itself
//!   stays valid until the `IoMem`'s drop unmaps it. This is upstream's
//!   `Devres`/`Revocable` idea with one revocation per binding.
//!
//!   Cost: with interrupts, preemption or softirqs off (the drivers'
//!   hot paths run under their chip's spinlock, interrupts off) that
//!   region is the read-side section already (since v5.0
//!   `synchronize_rcu` waits for it): an access costs one call
//!   (`rcan_may_sleep`) and a load more. Elsewhere it takes and releases
//!   the RCU read lock (two calls into the RCU core under `PREEMPT_RCU`).
//!   [`IoMem::access`] lends the registers for several accesses behind
//!   one check, under the RCU read lock.
//!
//! Modelled on upstream's `rust/kernel/pci.rs` (Adapter + id table +
//! drvdata) and `rust/kernel/devres.rs`, with 6.12's C API.

use super::bindings;
use super::iomap::IoRange;
use super::module::{ExitTable, ModuleScope, SweepKind};
use super::sync::RcuReadGuard;
use core::cell::UnsafeCell;
use core::marker::PhantomData;
use core::ops::Deref;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicBool, Ordering};
use kernel::error::{code, Result};
use kernel::ffi;
use kernel::new_mutex;
use kernel::prelude::*;
use kernel::sync::{Arc, Mutex};

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

/// The device being probed, and the binding its probe starts.
pub(crate) struct Device {
    pdev: NonNull<bindings::pci_dev>,
    binding: Arc<Binding>,
}

impl Device {
    pub(crate) fn as_ptr(&self) -> *mut bindings::pci_dev {
        self.pdev.as_ptr()
    }

    /// `pci_enable_device`; disabled again when the guard is dropped, or
    /// at the end of this binding if the guard is still alive then (see
    /// [`Enabled`]). Process context (probe).
    pub(crate) fn enable(&self) -> Result<Enabled> {
        // Under the lock, as every change of the count: the enable and
        // its count are one step for a revocation (none runs during the
        // probe, the only place a `Device` exists, but the type does not
        // rest on that).
        let mut en = self.binding.enables.lock();
        if en.revoked {
            return Err(code::ENODEV);
        }
        // SAFETY: a live device during probe.
        super::to_result(unsafe { bindings::pci_enable_device(self.as_ptr()) })?;
        en.live += 1;
        drop(en);
        // INVARIANT: counted in `live` above, after a successful enable.
        Ok(Enabled(self.binding.clone()))
    }

    /// Maps the first `len` bytes of BAR `bar` (`pci_iomap`), or the
    /// whole BAR if it is shorter (accesses past it then read 0xFF and
    /// are dropped, see [`IoMem`]); ENODEV if the BAR is absent. The
    /// mapping answers until the end of this binding (see [`IoMem`]).
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
        // INVARIANT: a mapping of `len` bytes of the binding's device,
        // unmapped in Drop.
        Ok(IoMem {
            // SAFETY: `addr` maps `len` bytes until IoMem's Drop unmaps it,
            // after the IoRange is last used.
            io: unsafe { IoRange::new(addr, len) },
            binding: self.binding.clone(),
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
/// with `pci_dev_put` (any context): what a [`Binding`] holds, so that
/// the device struct outlives every [`Enabled`] and [`IoMem`] of the
/// binding wherever a driver keeps them (its driver data is dropped in
/// `remove`, but a driver may move them elsewhere; a forgotten one leaks
/// the reference, never frees early).
///
/// # Invariants
///
/// Holds one reference on the device.
struct PciRef(NonNull<bindings::pci_dev>);

// SAFETY: a reference count may be dropped from any thread and context.
unsafe impl Send for PciRef {}
// SAFETY: through a shared reference only the address is read, for the C
// calls of the binding (each documents its own context).
unsafe impl Sync for PciRef {}

impl PciRef {
    /// A counted reference to `pdev` (`pci_dev_get`).
    ///
    /// # Safety
    ///
    /// `pdev` is a live device (the one the PCI core is probing).
    unsafe fn new(pdev: NonNull<bindings::pci_dev>) -> Self {
        // SAFETY: a live device (the contract); the reference taken here
        // is dropped by Drop.
        unsafe { bindings::pci_dev_get(pdev.as_ptr()) };
        // INVARIANT: one reference, taken above.
        PciRef(pdev)
    }
}

impl Drop for PciRef {
    fn drop(&mut self) {
        // SAFETY: we hold one reference (type invariant).
        unsafe { bindings::pci_dev_put(self.0.as_ptr()) };
    }
}

/// The [`Enabled`] guards of a [`Binding`], under its mutex.
struct Enables {
    /// Guards alive whose `pci_enable_device` is not undone yet.
    live: usize,
    /// Set by [`Binding::revoke`], which disabled the device for each of
    /// them: no guard disables it any more.
    revoked: bool,
}

/// One binding of a driver to a device, from its probe to its remove
/// (or to its failed probe's end): what every [`IoMem`] and [`Enabled`]
/// made by that probe shares, and what the glue's trampolines revoke at
/// the binding's end ([`Binding::revoke`]). Shared (`Arc`) by the
/// trampoline and each of them; freed with the last.
///
/// # Invariants
///
/// While `live` is true, the binding has not ended: the driver owns the
/// device. It is cleared only by [`Binding::revoke`], which then waits for
/// an RCU grace period before it returns, so an RCU read-side section
/// that saw it true has ended by the time the binding's end returns to
/// the PCI core. `enables.live` counts the [`Enabled`] guards whose
/// enable no one has undone yet; `enables.revoked` is set (once) by
/// [`Binding::revoke`] after it undid all of them.
#[pin_data]
struct Binding {
    pdev: PciRef,
    live: AtomicBool,
    #[pin]
    enables: Mutex<Enables>,
}

impl Binding {
    /// A new, live binding of `pdev`. Process context (the probe
    /// trampoline; allocates).
    ///
    /// # Safety
    ///
    /// `pdev` is a live device (the one the PCI core is probing).
    unsafe fn new(pdev: NonNull<bindings::pci_dev>) -> Result<Arc<Self>> {
        // SAFETY: a live device (the contract).
        let pdev = unsafe { PciRef::new(pdev) };
        Arc::pin_init(
            pin_init!(Binding {
                pdev,
                // INVARIANT: the binding starts with the probe.
                live: AtomicBool::new(true),
                enables <- new_mutex!(Enables { live: 0, revoked: false }, "pci::Binding::enables"),
            }),
            GFP_KERNEL,
        )
    }

    /// Ends the binding: register accesses through its [`IoMem`]s stop
    /// touching the device, and the device is disabled for each of its
    /// [`Enabled`]s still alive. When this returns, no access that
    /// started before it is still running. Process context (the
    /// trampolines, after `T::remove` or a failed `T::probe`); sleeps.
    fn revoke(&self) {
        // Relaxed, as upstream's `Revocable::revoke`: the grace period
        // below orders it against every read-side section.
        // INVARIANT: cleared here only, and the grace period follows.
        self.live.store(false, Ordering::Relaxed);
        // SAFETY: process context (documented contract of the callers,
        // both trampolines the PCI core calls with the device lock held
        // and no RCU read lock); no memory-safety precondition.
        unsafe { bindings::synchronize_rcu() };
        let mut en = self.enables.lock();
        if !en.revoked {
            for _ in 0..en.live {
                // SAFETY: each counted guard enabled the device once and
                // has not disabled it (invariant); `pdev` keeps the
                // struct alive.
                unsafe { bindings::pci_disable_device(self.pdev.0.as_ptr()) };
            }
            // INVARIANT: every counted enable is undone.
            en.live = 0;
            en.revoked = true;
        }
    }

    /// Whether the binding is live; `_rcu` proves the caller is inside a
    /// read-side section, which [`Binding::revoke`] waits for.
    #[inline]
    fn live(&self, _rcu: &RcuReadGuard) -> bool {
        self.live.load(Ordering::Relaxed)
    }

    /// Whether the binding is live, for a caller in a read-side section
    /// of another kind: interrupts, preemption or softirqs disabled, or
    /// an `rcu_read_lock()` of a caller up the stack, from before this
    /// call until after the access it guards ([`IoMem::with`]).
    #[inline]
    fn live_in_section(&self) -> bool {
        self.live.load(Ordering::Relaxed)
    }
}

/// Keeps a PCI device enabled until it is dropped or its binding ends,
/// whichever comes first: the device is disabled exactly once for it.
/// Dropping it may sleep (`pci_disable_device`): process context.
///
/// # Invariants
///
/// Counted in its binding's `enables.live` until its drop, or until the
/// binding's revocation undid its enable.
pub(crate) struct Enabled(Arc<Binding>);

impl Drop for Enabled {
    fn drop(&mut self) {
        let mut en = self.0.enables.lock();
        // The lock is held across the disable: a revocation running now
        // on another thread either sees this guard uncounted, disabled
        // already, or disables it itself and sets `revoked` before this
        // looks; never both, never after the binding's end has returned.
        if !en.revoked {
            // SAFETY: counted (invariant), so enabled by Device::enable
            // and not disabled since; the binding's reference keeps the
            // device struct alive.
            unsafe { bindings::pci_disable_device(self.0.pdev.0.as_ptr()) };
            en.live -= 1;
        }
    }
}

/// One mapped PCI BAR of a binding. Its accessors (`read8` ... `write32`,
/// [`IoMem::access`]) reach the device only while the binding lasts;
/// after its end, reads return all-ones (as absent hardware does) and
/// writes are dropped. Any context (hardirq, softirq, process); callers
/// serialise access to the device's registers themselves.
///
/// # Invariants
///
/// `io` holds a `pci_iomap` cookie for its length of `binding.pdev`,
/// valid until Drop; `binding` keeps the device struct alive until after
/// the unmap.
pub(crate) struct IoMem {
    io: IoRange,
    binding: Arc<Binding>,
}

/// Register access to a mapped BAR while its binding lasts: the
/// [`IoRange`] of an [`IoMem`], inside an RCU read-side section that
/// began while the binding was live. Any context; must not sleep while
/// held (it holds the RCU read lock), nor be held long: the binding's
/// end waits for it. Not `Send`.
///
/// # Invariants
///
/// `_rcu` began before `io`'s binding was seen live: the binding's end
/// waits for this guard's drop.
pub(crate) struct IoGuard<'a> {
    io: &'a IoRange,
    _rcu: RcuReadGuard,
}

impl Deref for IoGuard<'_> {
    type Target = IoRange;

    #[inline]
    fn deref(&self) -> &IoRange {
        self.io
    }
}

impl IoMem {
    /// The BAR's registers, if the binding has not ended: one check for
    /// several accesses (an interrupt handler's round), instead of one
    /// per access as the accessors below do. Any context.
    #[inline]
    pub(crate) fn access(&self) -> Option<IoGuard<'_>> {
        let rcu = RcuReadGuard::new();
        if self.binding.live(&rcu) {
            // INVARIANT: the section began before the check saw it live.
            Some(IoGuard {
                io: &self.io,
                _rcu: rcu,
            })
        } else {
            None
        }
    }

    /// Length of the mapping.
    pub(crate) fn len(&self) -> usize {
        self.io.len()
    }

    /// `f` on the BAR's registers if the binding has not ended: one
    /// check and the accesses `f` makes, all inside one read-side section
    /// that [`Binding::revoke`] waits for. Private: `f` is one of the
    /// accessors below, which neither sleep nor turn interrupts,
    /// preemption or softirqs back on. Any context.
    ///
    /// The hot paths of the drivers (interrupt handler, transmit, NAPI
    /// poll) access the registers under the chip's spinlock with
    /// interrupts off: there the section exists already, and only the
    /// check is made. Elsewhere (probe, process context without the
    /// lock) it takes the RCU read lock, as [`IoMem::access`] does.
    #[inline]
    fn with<R>(&self, f: impl FnOnce(&IoRange) -> R) -> Option<R> {
        // SAFETY: no precondition; reads the preempt count, the
        // interrupt flag and the task's RCU nesting depth.
        if unsafe { bindings::rcan_may_sleep() } {
            return self.access().map(|r| f(&r));
        }
        // Not preemptible (interrupts, preemption or softirqs off) or
        // inside an `rcu_read_lock()` of a caller: either lasts until
        // `f` returns (nothing between here and there ends it), and since
        // v5.0 `synchronize_rcu()` waits for both kinds of region
        // (`include/linux/rcupdate.h`, `synchronize_rcu`'s comment in
        // `kernel/rcu/tree.c`), so the revocation waits for this one.
        self.binding.live_in_section().then(|| f(&self.io))
    }

    /// `ioread8` at `off`; 0xFF outside the mapping or after the binding.
    #[inline]
    pub(crate) fn read8(&self, off: usize) -> u8 {
        self.with(|r| r.read8(off)).unwrap_or(0xFF)
    }

    /// `iowrite8` at `off`; dropped outside the mapping or after the
    /// binding.
    #[inline]
    pub(crate) fn write8(&self, off: usize, val: u8) {
        self.with(|r| r.write8(off, val));
    }

    /// `ioread16` at `off` (little-endian); all-ones outside the mapping
    /// or after the binding.
    #[inline]
    pub(crate) fn read16(&self, off: usize) -> u16 {
        self.with(|r| r.read16(off)).unwrap_or(!0)
    }

    /// `iowrite16` at `off` (little-endian); dropped outside the mapping
    /// or after the binding.
    #[inline]
    pub(crate) fn write16(&self, off: usize, val: u16) {
        self.with(|r| r.write16(off, val));
    }

    /// `ioread32` at `off`; all-ones outside the mapping or after the
    /// binding.
    #[inline]
    pub(crate) fn read32(&self, off: usize) -> u32 {
        self.with(|r| r.read32(off)).unwrap_or(!0)
    }

    /// `iowrite32` at `off`; dropped outside the mapping or after the
    /// binding.
    #[inline]
    pub(crate) fn write32(&self, off: usize, val: u32) {
        self.with(|r| r.write32(off, val));
    }
}

impl Drop for IoMem {
    fn drop(&mut self) {
        // The unmap does not touch the device: it may run after the
        // binding's end (memory stays valid until here, see the type).
        // SAFETY: mapped by pci_iomap for this device (invariant), whose
        // struct the binding's reference keeps alive (dropped after this
        // body); no IoGuard borrows `io` any more (we have `&mut self`).
        unsafe { bindings::pci_iounmap(self.binding.pdev.0.as_ptr(), self.io.cookie()) };
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

/// What the PCI drvdata of a bound device holds: the driver's data and
/// the binding its `remove` ends. Allocated before the driver's probe
/// runs, so that nothing can fail after it succeeded.
struct Bound<D> {
    data: Option<KBox<D>>,
    binding: Arc<Binding>,
}

/// The PCI core's probe of `T`. Process context, the device lock held.
///
/// # Safety
///
/// The PCI core calls it with a live device that has no driver, for a
/// driver registered by [`Registration::register`].
unsafe extern "C" fn probe<T: Driver>(
    pdev: *mut bindings::pci_dev,
    _id: *const bindings::pci_device_id,
) -> ffi::c_int {
    let Some(p) = NonNull::new(pdev) else {
        return code::EINVAL.to_errno();
    };
    // SAFETY: the PCI core probes a live device (the contract).
    let bound = unsafe { Binding::new(p) }.and_then(|binding| {
        Ok(KBox::new(
            Bound::<T::Data> {
                data: None,
                binding,
            },
            GFP_KERNEL,
        )?)
    });
    let mut bound = match bound {
        Ok(b) => b,
        Err(e) => return e.to_errno(),
    };
    let dev = Device {
        pdev: p,
        binding: bound.binding.clone(),
    };
    // Only `Registration::register`, which takes the module's scope,
    // installs this function: the module's exit is the glue's.
    let probed = super::module::lend_scope(|scope| T::probe(&dev, scope));
    drop(dev);
    match probed {
        Ok(data) => {
            bound.data = Some(data);
            // SAFETY: a live device; drvdata holds the box until remove.
            unsafe { bindings::rcan_pci_set_drvdata(pdev, KBox::into_raw(bound).cast()) };
            0
        }
        Err(e) => {
            // The binding ends with the failed probe: what the probe kept
            // of it (a mapping in a static) must not reach the device.
            bound.binding.revoke();
            e.to_errno()
        }
    }
}

/// The PCI core's remove of `T` (unbind, driver unregistration, hot
/// removal). Process context, the device lock held.
///
/// # Safety
///
/// The PCI core calls it for a device [`probe`] bound.
unsafe extern "C" fn remove<T: Driver>(pdev: *mut bindings::pci_dev) {
    // SAFETY: probe succeeded for this device, so drvdata is our box.
    let bound = unsafe { bindings::rcan_pci_get_drvdata(pdev) }.cast::<Bound<T::Data>>();
    if bound.is_null() {
        return;
    }
    // SAFETY: set in probe from KBox::into_raw; taken back exactly once.
    let bound = unsafe { KBox::from_raw(bound) };
    // SAFETY: clear the stale pointer.
    unsafe { bindings::rcan_pci_set_drvdata(pdev, core::ptr::null_mut()) };
    let Bound { data, binding } = KBox::into_inner(bound);
    if let Some(data) = data {
        T::remove(data);
    }
    // After the driver's remove, whatever it kept: from here on nothing
    // of this binding touches the device.
    binding.revoke();
}
