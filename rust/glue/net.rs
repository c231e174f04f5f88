// SPDX-License-Identifier: GPL-2.0

//! Network namespaces.
//!
//! * [`Net`]: a borrowed `struct net`. Where one comes from says how long
//!   it lives: [`Net::init`] is `'static`; a socket's
//!   ([`Sock::net`](super::sock::Sock::net)) lives as long as the socket
//!   (a user socket holds a reference on its namespace); a device's
//!   ([`NetDev::net`](super::netdev::NetDev::net)) only inside an RCU
//!   read-side section, since a device can move to another namespace
//!   (under RTNL) and its old one can then go away after a grace period.
//! * [`Pernet`]: data of a module kept per namespace
//!   (`pernet_operations` with `id` and `size`, `net_generic`), made by
//!   [`PernetData::init`] for every namespace, dropped at the namespace's
//!   exit; [`PernetReg`] unregisters when dropped.

use super::bindings;
use super::sync::CCell;
use core::marker::PhantomData;
use core::sync::atomic::{AtomicBool, Ordering};
use kernel::error::{code, Error, Result};
use kernel::ffi;

/// A `struct net`, borrowed.
#[repr(transparent)]
pub(crate) struct Net(kernel::types::Opaque<bindings::net>);

impl Net {
    /// # Safety
    ///
    /// `ptr` is a valid namespace that stays alive for `'a`.
    pub(crate) unsafe fn from_raw<'a>(ptr: *mut bindings::net) -> &'a Net {
        // SAFETY: transparent over the C struct; validity per the contract.
        unsafe { &*ptr.cast::<Net>() }
    }

    /// The initial namespace (`init_net`), which never goes away.
    pub(crate) fn init() -> &'static Net {
        // SAFETY: `init_net` is a static of the kernel.
        unsafe { Net::from_raw(bindings::rcan_init_net()) }
    }

    pub(crate) fn as_ptr(&self) -> *mut bindings::net {
        self.0.get()
    }

    /// Whether this is the initial namespace (`net_eq(net, &init_net)`).
    #[inline]
    pub(crate) fn is_init(&self) -> bool {
        core::ptr::eq(self.as_ptr(), &raw const bindings::init_net)
    }
}

impl PartialEq for Net {
    /// `net_eq`: the same namespace.
    fn eq(&self, other: &Net) -> bool {
        core::ptr::eq(self.as_ptr(), other.as_ptr())
    }
}

impl Eq for Net {}

impl Net {
    /// A counted reference on this namespace (`maybe_get_net`), which
    /// keeps it from being dismantled until dropped; `None` if its count
    /// already reached zero (it is going away). Any context.
    pub(crate) fn hold(&self) -> Option<NetRef> {
        // SAFETY: `self` is alive while borrowed; maybe_get_net fails
        // (false) if the count already reached zero.
        if !unsafe { bindings::rcan_maybe_get_net(self.as_ptr()) } {
            return None;
        }
        // INVARIANT: the reference just taken.
        Some(NetRef(core::ptr::NonNull::from(self)))
    }
}

/// A counted reference on a namespace ([`Net::hold`]), put when dropped
/// (`put_net`; the last one schedules the namespace's cleanup, which
/// runs in a workqueue: dropping is allowed in any context).
///
/// # Invariants
///
/// The value holds one reference on the namespace it points to.
pub(crate) struct NetRef(core::ptr::NonNull<Net>);

// SAFETY: a counted reference, which may be dropped on any thread.
unsafe impl Send for NetRef {}
// SAFETY: shared access only reads the (alive) namespace's address.
unsafe impl Sync for NetRef {}

impl core::ops::Deref for NetRef {
    type Target = Net;
    fn deref(&self) -> &Net {
        // SAFETY: the reference held keeps the namespace alive (type
        // invariant).
        unsafe { self.0.as_ref() }
    }
}

impl Drop for NetRef {
    fn drop(&mut self) {
        // SAFETY: the reference taken in `Net::hold` (type invariant).
        unsafe { bindings::rcan_put_net(self.0.as_ptr().cast()) };
    }
}

/// A module's data for one namespace.
pub(crate) trait PernetData: Sized + Send + Sync + 'static {
    /// The module's [`Pernet`] static.
    fn pernet() -> &'static Pernet<Self>;

    /// Makes the data of `net`: for every namespace that exists when the
    /// module registers, and for each one created later. Process context;
    /// may sleep. An error fails the registration or the namespace's
    /// creation.
    fn init(net: &Net) -> Result<Self>;

    /// `net` is going away: its devices are gone, but readers may still
    /// be in RCU read-side sections that found the data. A grace period
    /// passes before the data is dropped. Process context; may sleep.
    fn pre_exit(&self, _net: &Net) {}
}

/// The registration of a [`PernetData`] type with the namespaces
/// (`register_pernet_subsys`): a `static` of the module.
///
/// Registered as a *subsystem*, so a namespace's data is made before its
/// devices and dropped after every device of it is unregistered or moved
/// away (mainline's `can_pernet_ops` is one too).
pub(crate) struct Pernet<T: PernetData> {
    ops: CCell<bindings::pernet_operations>,
    /// Written by the kernel at registration (`ops.id` points here).
    id: CCell<ffi::c_uint>,
    registered: AtomicBool,
    _t: PhantomData<T>,
}

// SAFETY: the C structs are written by the kernel at registration only;
// the data is reached through `get`, which hands out `&T` (`T: Sync`).
unsafe impl<T: PernetData> Sync for Pernet<T> {}

impl<T: PernetData> Pernet<T> {
    pub(crate) const fn new() -> Self {
        Pernet {
            ops: CCell::new(bindings::pernet_operations {
                init: Some(init_trampoline::<T>),
                pre_exit: Some(pre_exit_trampoline::<T>),
                exit: Some(exit_trampoline::<T>),
                size: core::mem::size_of::<T>(),
                // SAFETY: all-zero is valid for the remaining fields (an
                // unlinked list head, no batch or RTNL exits, `id` set in
                // `register`).
                ..unsafe { core::mem::zeroed() }
            }),
            id: CCell::new(0),
            registered: AtomicBool::new(false),
            _t: PhantomData,
        }
    }

    /// Registers the data: `T::init` runs for every namespace now and for
    /// every one created later, until the returned registration is
    /// dropped. Process context; sleeps. EBUSY if registered already
    /// (module init is the only caller).
    ///
    /// # Safety
    ///
    /// No [`Pernet::get`] may run after the returned registration is
    /// dropped (the module drops it in its exit, after everything that
    /// could call `get` is gone).
    pub(crate) unsafe fn register(&'static self) -> Result<PernetReg<T>> {
        // The kernel allocates `size` bytes with kzalloc, which aligns to
        // at least 8.
        if core::mem::align_of::<T>() > 8 {
            return Err(code::EINVAL);
        }
        if self.registered.load(Ordering::Acquire) {
            return Err(code::EBUSY);
        }
        // SAFETY: not registered (flag above), so the kernel does not use
        // `ops`; `id` is a static the kernel writes at registration.
        let ret = unsafe {
            (*self.ops.get()).id = self.id.get();
            bindings::register_pernet_subsys(self.ops.get())
        };
        if ret < 0 {
            return Err(Error::from_errno(ret));
        }
        // Only now: before, a namespace's generic array may not have our
        // slot yet.
        self.registered.store(true, Ordering::Release);
        Ok(PernetReg(self))
    }

    /// The data of `net`, for as long as `net` is borrowed: the data
    /// lives until the namespace's exit. `None` if not registered.
    /// Any context.
    pub(crate) fn get<'a>(&'a self, net: &'a Net) -> Option<&'a T> {
        if !self.registered.load(Ordering::Acquire) {
            return None;
        }
        // SAFETY: registered (and, by `register`'s contract, not being
        // unregistered), so `id` is ours in every namespace; `net` is alive.
        let p = unsafe { bindings::rcan_net_generic(net.as_ptr(), *self.id.get()) };
        // SAFETY: `init_trampoline` wrote a `T` there before the namespace
        // became visible; it is dropped only at the namespace's exit,
        // which cannot come while `net` is borrowed alive.
        unsafe { p.cast::<T>().as_ref() }
    }
}

/// A registered [`Pernet`]; dropping it calls `pre_exit` and drops the
/// data of every namespace, then unregisters. Process context; sleeps.
pub(crate) struct PernetReg<T: PernetData>(&'static Pernet<T>);

impl<T: PernetData> Drop for PernetReg<T> {
    fn drop(&mut self) {
        self.0.registered.store(false, Ordering::Release);
        // SAFETY: registered by `register`; the kernel runs pre_exit, a
        // grace period and exit for every namespace before returning.
        unsafe { bindings::unregister_pernet_subsys(self.0.ops.get()) };
    }
}

/// The slot of `T`'s data in `net`.
///
/// # Safety
///
/// `T`'s Pernet is registered (or being registered: called from its
/// callbacks) and `net` is valid.
unsafe fn slot<T: PernetData>(net: *mut bindings::net) -> *mut T {
    // SAFETY: per the contract the id is assigned; the kernel allocated
    // `size_of::<T>()` zeroed bytes there before calling `init`.
    unsafe { bindings::rcan_net_generic(net, *T::pernet().id.get()).cast() }
}

/// `pernet_operations.init`. Process context.
///
/// # Safety
///
/// Called by the namespace core with a namespace being set up.
unsafe extern "C" fn init_trampoline<T: PernetData>(net: *mut bindings::net) -> ffi::c_int {
    // SAFETY: the namespace being set up is valid for the call.
    let n = unsafe { Net::from_raw(net) };
    match T::init(n) {
        Ok(v) => {
            // SAFETY: the slot is ours, uninitialised (zeroed) memory of
            // the right size and alignment (checked in `register`).
            unsafe { slot::<T>(net).write(v) };
            0
        }
        Err(e) => e.to_errno(),
    }
}

/// `pernet_operations.pre_exit`. Process context.
///
/// # Safety
///
/// Called by the namespace core for a namespace whose `init` succeeded.
unsafe extern "C" fn pre_exit_trampoline<T: PernetData>(net: *mut bindings::net) {
    // SAFETY: a valid namespace with initialised data (init succeeded).
    let (n, d) = unsafe { (Net::from_raw(net), &*slot::<T>(net)) };
    d.pre_exit(n);
}

/// `pernet_operations.exit`: drops the data; the kernel frees the memory
/// afterwards. Process context.
///
/// # Safety
///
/// Called by the namespace core once, after `pre_exit` and a grace
/// period, for a namespace whose `init` succeeded.
unsafe extern "C" fn exit_trampoline<T: PernetData>(net: *mut bindings::net) {
    // SAFETY: initialised data that nothing uses any more (the namespace
    // is going; readers had a grace period since pre_exit).
    unsafe { core::ptr::drop_in_place(slot::<T>(net)) };
}
