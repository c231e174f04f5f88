// SPDX-License-Identifier: GPL-2.0

//! The C side of `rcan_pf`: the PF_CAN protocol family, the ETH_P_CAN
//! and ETH_P_CANFD packet handlers, and the entry points `rcan_pf` exports to the protocol
//! and driver modules ([`crate::glue::can::abi`]). Compiled into `rcan_pf` only
//! (`pf_can_mod.rs` includes it as `mod family` next to `mod glue`): the
//! `#[no_mangle]` definitions must exist once.
//!
//! Everything here is pointer work: turning the C arguments into the
//! types of the rest of the glue (skbs, devices, filter slices, counted
//! sock references), keeping the protocol table and the listener list,
//! and registering the family and the packet handler. The decisions
//! (what a frame is, who receives it, what a send checks) are pf_can's,
//! through [`Family`], implemented by `crate::PfCan`.
//!
//! Shared state and its discipline:
//!
//! * `PROTOS`, the protocol table: read under RCU (`pf_can_create`,
//!   process context); written under `WRITERS` (`rcan_pf_mutex`, process
//!   context) by `rcan_proto_register`/`_unregister`.
//! * `WRITERS` also protects the listeners (drivers that follow the receive
//!   table, [`notify_listeners`]); they are called under it, so removal
//!   (which takes it) waits for a running call.
//! * The receive table is pf_can's (`rcan_rx_mutex`, [`RX_MUTEX`]);
//!   `WRITERS` is never held together with it.
//! * [`NetTable`], the receive table of a network namespace other than the
//!   initial one (whose table is pf_can's static): published under RCU in
//!   the namespace's pernet data, made at the namespace's first
//!   subscription under `WRITERS` (not together with `rcan_rx_mutex`),
//!   unpublished at the namespace's `pre_exit` and freed at its exit, a
//!   grace period later.

use crate::glue::bindings;
use crate::glue::can::abi::{
    CanProto, ListenFn, RxFilter, RxFn, RxSpec, RxTableSpec, TableFilter, CANPROTO_MAX,
};
use crate::glue::can::rx::{RcvHandle, Receiver, RxTable};
use crate::glue::net::{Net, Pernet, PernetData, PernetReg};
use crate::glue::netdev::NetDev;
use crate::glue::skb::{OwnedSkb, Skb, UniqueSkb};
use crate::glue::sync::{CCell, CMutex, RcuPtr, RcuReadGuard, StaticMutex};
use core::ptr::NonNull;
use core::sync::atomic::{fence, AtomicUsize, Ordering};
use kernel::error::{code, Error, Result};
use kernel::ffi;
use kernel::prelude::*;

/// Waits for all pre-existing RCU readers. Process context, outside any
/// RCU read-side critical section; sleeps. Private to this file (issue
/// 39): it was a safe `pub(crate)` function of `glue::sync`, which a
/// protocol could call from its receive callback (softirq, inside
/// pf_can's read-side section), waiting for a grace period its own caller
/// holds off. Its callers are the entry points `rcan_rx_set_kernel` and
/// `rcan_proto_unregister` below, which the glue of the other modules
/// calls when a kernel receiver is registered or dropped and when a
/// protocol is unregistered at module exit. That those run in process
/// context is documented, not typed: safe code can still drop a
/// `KernelRxReg` in a timer callback, as it can call any other sleeping
/// function in atomic context (Rust-for-Linux leaves that class to static
/// checking, klint).
fn synchronize_rcu() {
    // A call in atomic context is a kernel bug the kernel reports
    // (might_sleep, and lockdep's check for a call inside a read-side
    // section), as for any sleeping function.
    // SAFETY: no memory-safety precondition of its own.
    unsafe { bindings::synchronize_rcu() };
}

/// The implementation behind the entry points: `rcan_pf`'s module type.
type Impl = crate::pf_can::PfCan;

/// What `rcan_pf` decides; the entry points below call it.
pub(crate) trait Family: 'static {
    /// Sets (`new`: a request and its receiver, replacing the previous
    /// registration of receiver `id`) or removes (`None`) a registration
    /// in the receive table of namespace `net` (the socket's; the initial
    /// one for kernel receivers), then tells the listeners
    /// ([`notify_listeners`]). Process context; may sleep. ENOMEM, EINVAL
    /// (bad filter); on error the previous registration stays.
    fn rx_set(net: &Net, id: usize, new: Option<(RxRequest<'_>, Target)>) -> Result;
    /// Makes receiver `id` (`t`) of namespace `net` ahead of its first
    /// registration, which then allocates nothing, and returns its handle
    /// for [`Family::rx_set_reserved`]; it receives nothing until set, and
    /// stays until removed for good (`rx_set_reserved` with `keep` false;
    /// `rx_set(net, id, None)` only retires its registration). Process
    /// context; may sleep. ENOMEM.
    fn rx_reserve(net: &Net, id: usize, t: Target) -> Result<RcvHandle>;
    /// Like [`Family::rx_set`] for the reserved receiver `rcv` (no lookup,
    /// no new receiver data; it is in the table it was reserved in), with
    /// the filters in the table's own form: `None` retires its
    /// registration, and the receiver stays reserved with `keep`, else it
    /// is removed for good (consuming `rcv`). Process context; may sleep.
    /// ENOMEM; on error the previous registration stays.
    fn rx_set_reserved(
        rcv: RcvHandle,
        new: Option<RxRequest<'_, TableFilter>>,
        keep: bool,
    ) -> Result;
    /// Copies the filters that apply to frames received on `dev` into
    /// `out`; `None` if there are more than fit. Any context.
    fn rx_filters(dev: &NetDev, out: &mut [crate::rcan_core::rxtable::Filter]) -> Option<usize>;
    /// `rcan_send` (see [`crate::glue::can::abi::rcan_send`]). Process or softirq
    /// context.
    /// The skb is the caller's alone and uncloned ([`UniqueSkb`]: pf_can
    /// sets `CANFD_FDF` in an FD frame's data).
    fn send(skb: UniqueSkb, dev: &NetDev, loopback: bool) -> Result;
    /// The ETH_P_CAN (`fd` false) and ETH_P_CANFD (`fd` true) packet
    /// handlers: a frame received on `dev`. NET_RX softirq, inside the
    /// core's RCU read-side section, which `rcu` stands for (the handler
    /// takes no nested one). Returns false if the frame was dropped as
    /// malformed.
    fn rcv(rcu: &RcuReadGuard, skb: Skb, dev: &NetDev, fd: bool) -> bool;
}

/// A registration request as a receiver made it: its filters as the
/// protocol gave them (`F` = [`RxFilter`], [`Family::rx_set`]) or already
/// in the table's form (`F` = [`TableFilter`],
/// [`Family::rx_set_reserved`]).
pub(crate) struct RxRequest<'a, F = RxFilter> {
    /// Interface, 0 = every CAN interface.
    pub(crate) ifindex: i32,
    /// Deliver only frames that pass every filter.
    pub(crate) join: bool,
    /// Error classes wanted (0: none), unchecked.
    pub(crate) err_mask: u32,
    /// The receiver's filters, for the duration of the call.
    pub(crate) filters: &'a [F],
    /// Handed back to the receiver with every frame.
    pub(crate) cookie: u32,
}

/// A receiver in the receive table: a protocol's socket (with a counted
/// reference on it) or an in-kernel receiver's data, and its callback.
///
/// # Invariants
///
/// `func` and `owner` come from one `rcan_rx_set` / `rcan_rx_set_kernel`
/// call. With `sock`, the Target holds one reference on the sock `owner`
/// (and, through it, on the protocol module holding `func`). Without,
/// `owner` and `func` stay valid until the receiver's removal returns,
/// which waits for a grace period after the table unlinked it
/// ([`rcan_rx_set_kernel`]).
pub(crate) struct Target {
    func: RxFn,
    owner: NonNull<ffi::c_void>,
    sock: bool,
}

// SAFETY: `owner` is a counted sock reference or a kernel receiver's
// `Sync` data; both are usable from any CPU.
unsafe impl Send for Target {}
// SAFETY: as above; shared access only calls the receiver.
unsafe impl Sync for Target {}

impl Receiver for Target {
    /// One registration per owner (a socket belongs to one protocol; a
    /// kernel receiver's data to one module).
    fn id(&self) -> usize {
        self.owner.as_ptr() as usize
    }
}

impl Target {
    /// Calls the receiver with `skb` borrowed. NET_RX softirq, inside the
    /// read-side section in which the Target was found in the table.
    pub(crate) fn deliver(&self, _rcu: &RcuReadGuard, skb: &Skb, cookie: u32) {
        // SAFETY: a live receiver (type invariant; a kernel receiver is not
        // released before a grace period that `_rcu` holds off); a valid
        // skb, borrowed (owned = false).
        unsafe { (self.func)(skb.as_ptr(), self.owner.as_ptr(), cookie, false) };
    }

    /// Calls the receiver handing it `skb` (our reference) when nobody
    /// else holds one; else borrowed, then consumed. Context as
    /// [`Target::deliver`].
    pub(crate) fn deliver_last(&self, rcu: &RcuReadGuard, skb: Skb, cookie: u32) {
        let skb: OwnedSkb = match skb.try_into_owned() {
            Ok(o) => o,
            Err(skb) => {
                self.deliver(rcu, &skb, cookie);
                skb.consume();
                return;
            }
        };
        // SAFETY: as in deliver; the callee takes our reference, the only
        // one (`OwnedSkb`), as `owned = true` promises (`abi::RxFn`).
        unsafe { (self.func)(skb.into_raw(), self.owner.as_ptr(), cookie, true) };
    }
}

impl Drop for Target {
    /// Runs in a `call_rcu` callback (softirq) or in the writer's process
    /// context; the final `sock_put` may free the sock.
    fn drop(&mut self) {
        if self.sock {
            // SAFETY: the reference this Target holds (type invariant).
            unsafe { bindings::rcan_sock_put(self.owner.as_ptr().cast()) };
        }
    }
}

/// The receive table's writers' mutex (`rcan_rx_mutex`, a `DEFINE_MUTEX`
/// of `pf_can_c.c` with a lockdep class of its own). Process context.
pub(crate) const RX_MUTEX: StaticMutex = {
    extern "C" {
        static mut rcan_rx_mutex: bindings::mutex;
    }
    // SAFETY: pf_can_c.c's DEFINE_MUTEX (static storage, initialised at
    // compile time), used only as the receive table's lock; only its
    // address is taken here.
    unsafe { StaticMutex::new(&raw mut rcan_rx_mutex) }
};

/// `rcan_pf_mutex` (`DEFINE_MUTEX` of `pf_can_c.c`), `WRITERS`' lock.
/// Process context.
const PF_MUTEX: StaticMutex = {
    extern "C" {
        static mut rcan_pf_mutex: bindings::mutex;
    }
    // SAFETY: pf_can_c.c's DEFINE_MUTEX (static storage, initialised at
    // compile time), used only as `WRITERS`' lock; only its address is
    // taken here.
    unsafe { StaticMutex::new(&raw mut rcan_pf_mutex) }
};

/// A driver that wants to know when the receive table changes for its
/// interface (to recompute its hardware filter, DESIGN decision 7).
#[derive(Clone, Copy)]
struct Listener {
    func: ListenFn,
    /// The device (abi contract of `rcan_rx_listen`).
    data: *mut ffi::c_void,
}

/// What `WRITERS` protects besides `PROTOS`.
struct Registry {
    listeners: KVec<Listener>,
}

// SAFETY: the raw pointers are opaque tokens handed back to their owners'
// callbacks; the owners guarantee their validity (abi contracts).
unsafe impl Send for Registry {}

/// Serialises the writers of `PROTOS` and protects the listeners. Process
/// context.
static WRITERS: CMutex<Registry> = CMutex::new(
    PF_MUTEX,
    Registry {
        listeners: KVec::new(),
    },
);

/// The number of listeners: written under `WRITERS` (in
/// `rcan_rx_listen`), read without it by [`notify_listeners`] (see the
/// fence argument there).
static NLISTENERS: AtomicUsize = AtomicUsize::new(0);

/// The protocol table (RCU readers, `WRITERS` for writers).
static PROTOS: [RcuPtr<CanProto>; CANPROTO_MAX] = [const { RcuPtr::null() }; CANPROTO_MAX];

/// Tells the drivers of the interfaces in `ifindexes` (0: all of them)
/// that their wanted filters changed. Process context; takes `WRITERS` (so
/// a listener being removed is not called after its removal returns),
/// unless no driver listens. Inline: every bind and close asks, and with
/// no listener the answer is a fence and a load, without a call
/// ([`notify_listeners_now`] when a driver listens).
#[inline(always)]
pub(crate) fn notify_listeners(ifindexes: &[Option<i32>]) {
    if ifindexes.iter().all(|i| i.is_none()) {
        return;
    }
    // Fast path: no listener, no `WRITERS` (a mutex per bind and close).
    // Store-buffering argument: our table change (made and published
    // before this call) is ordered before the load of the count by this
    // full fence; `rcan_rx_listen` raises the count and then runs the
    // paired full fence before its caller reads the table
    // (`rcan_rx_filters`). Of the two loads (our count, its table) at
    // least one sees the other side's store: either we see the new
    // listener and call it below, or it reads a table that has our change.
    // A listener being removed needs no call (skipping one is what its
    // removal asks for).
    fence(Ordering::SeqCst);
    if NLISTENERS.load(Ordering::Relaxed) == 0 {
        return;
    }
    notify_listeners_now(ifindexes);
}

/// [`notify_listeners`] once a listener is known. Process context; takes
/// `WRITERS`.
#[inline(never)]
fn notify_listeners_now(ifindexes: &[Option<i32>]) {
    let reg = WRITERS.lock();
    for l in reg.listeners.iter() {
        // The device's index now: a move to another namespace may have
        // changed it since the listener was added.
        // SAFETY: a listener's data is its registered device (abi
        // contract), valid until rcan_rx_listen removes it, which needs
        // `WRITERS` (held here).
        let now = unsafe { NetDev::from_raw(l.data.cast()) }.ifindex();
        if ifindexes.iter().flatten().any(|&i| i == 0 || i == now) {
            // SAFETY: a registered listener's data stays valid until
            // rcan_rx_listen removes it, which needs `WRITERS` (held here).
            unsafe { (l.func)(l.data) };
        }
    }
}

/// Converts a C spec into a request. NULL or empty filter arrays are no
/// filters.
///
/// # Safety
///
/// `filters` points to `nfilters` readable filters that stay valid for
/// `'a`.
unsafe fn request<'a, F>(
    ifindex: i32,
    join: bool,
    err_mask: u32,
    filters: *const F,
    nfilters: usize,
    cookie: u32,
) -> RxRequest<'a, F> {
    let filters = if nfilters == 0 || filters.is_null() {
        &[][..]
    } else {
        // SAFETY: this function's contract.
        unsafe { core::slice::from_raw_parts(filters, nfilters) }
    };
    RxRequest {
        ifindex,
        join,
        err_mask,
        filters,
        cookie,
    }
}

/// [`request`] of an [`RxSpec`].
///
/// # Safety
///
/// `spec.filters` points to `spec.nfilters` readable filters that stay
/// valid for `'a`.
unsafe fn request_of<'a>(spec: &'a RxSpec, cookie: u32) -> RxRequest<'a> {
    let s = spec;
    // SAFETY: this function's contract.
    unsafe { request(s.ifindex, s.join, s.err_mask, s.filters, s.nfilters, cookie) }
}

/// See [`crate::glue::can::abi::rcan_pf_abi`]: the ABI this `rcan_pf` was
/// built with, which every module compares with its own before it
/// registers anything ([`crate::glue::can::abi::check`]).
#[no_mangle]
extern "C" fn rcan_pf_abi() -> u64 {
    crate::glue::can::abi::ABI
}

/// See [`crate::glue::can::abi::rcan_rx_set`].
///
/// # Safety
///
/// Called by a protocol module's glue through the `abi` declaration: `sk`
/// is NULL or a live sock of the caller's protocol that stays alive for
/// the call, on which `func` may be called with `cookie` until the
/// receiver is removed and a grace period has passed; `spec` is NULL or
/// points to a valid [`RxSpec`] whose `filters` point to `nfilters`
/// readable filters, all valid for the call.
#[no_mangle]
unsafe extern "C" fn rcan_rx_set(
    func: RxFn,
    sk: *mut bindings::sock,
    cookie: u32,
    spec: *const RxSpec,
) -> ffi::c_int {
    let Some(owner) = NonNull::new(sk.cast::<ffi::c_void>()) else {
        return code::EINVAL.to_errno();
    };
    let id = owner.as_ptr() as usize;
    // SAFETY: `sk` is a live sock (abi contract), which keeps its
    // namespace alive.
    let net = unsafe { Net::from_raw(bindings::rcan_sock_net(sk)) };
    // SAFETY: NULL or a valid spec, with its filters, for the duration of
    // the call (abi contract).
    let new = unsafe { spec.as_ref() }.map(|spec| {
        // SAFETY: the caller's `sk` is a live sock; the Target keeps this
        // reference until it is dropped.
        unsafe { bindings::rcan_sock_hold(sk) };
        // INVARIANT: one reference held, just taken.
        let t = Target {
            func,
            owner,
            sock: true,
        };
        // SAFETY: the spec's filters are valid for the call (above).
        (unsafe { request_of(spec, cookie) }, t)
    });
    match Impl::rx_set(net, id, new) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// See [`crate::glue::can::abi::rcan_rx_reserve`].
///
/// # Safety
///
/// As for [`rcan_rx_set`]: `sk` is NULL or a live sock of the caller's
/// protocol, valid for the call, for which `func` may be called; the
/// caller removes the returned receiver for good before the sock can be
/// freed.
#[no_mangle]
unsafe extern "C" fn rcan_rx_reserve(func: RxFn, sk: *mut bindings::sock) -> *mut ffi::c_void {
    let Some(owner) = NonNull::new(sk.cast::<ffi::c_void>()) else {
        return core::ptr::null_mut();
    };
    // SAFETY: the caller's `sk` is a live sock (abi contract); the Target
    // keeps this reference until it is dropped.
    unsafe { bindings::rcan_sock_hold(sk) };
    // INVARIANT: one reference held, just taken.
    let t = Target {
        func,
        owner,
        sock: true,
    };
    // SAFETY: as in rcan_rx_set.
    let net = unsafe { Net::from_raw(bindings::rcan_sock_net(sk)) };
    match Impl::rx_reserve(net, owner.as_ptr() as usize, t) {
        Ok(h) => h.into_raw(),
        Err(_) => core::ptr::null_mut(),
    }
}

/// See [`crate::glue::can::abi::rcan_rx_set_reserved`].
///
/// # Safety
///
/// `rcv` is NULL or what [`rcan_rx_reserve`] returned and was not yet
/// removed for good; the caller serialises its calls for one receiver
/// (its socket's lock); `spec` is NULL or points to a valid
/// [`RxTableSpec`] whose `filters` point to `nfilters` table-form filters
/// made by the glue, all valid for the call.
#[no_mangle]
unsafe extern "C" fn rcan_rx_set_reserved(
    rcv: *mut ffi::c_void,
    cookie: u32,
    spec: *const RxTableSpec,
    keep: bool,
) -> ffi::c_int {
    let Some(rcv) = NonNull::new(rcv) else {
        return code::EINVAL.to_errno();
    };
    // SAFETY: `rcv` is what rcan_rx_reserve returned, and its receiver is
    // not removed for good yet (abi contract).
    let rcv = unsafe { RcvHandle::from_raw(rcv) };
    // SAFETY: NULL or a valid spec for the duration of the call (abi
    // contract).
    let new = unsafe { spec.as_ref() }
        // SAFETY: its filters are valid table-form filters, which the
        // caller's Rust code made, for the call (abi contract).
        .map(|s| unsafe { request(s.ifindex, s.join, s.err_mask, s.filters, s.nfilters, cookie) });
    match Impl::rx_set_reserved(rcv, new, keep) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// See [`crate::glue::can::abi::rcan_rx_set_kernel`].
///
/// # Safety
///
/// `data` is NULL or the caller's data, valid (with `func`, which may be
/// called with it) until a call of this function removing or replacing
/// the registration has returned; `net` is NULL or a namespace alive
/// until then; `spec` as for [`rcan_rx_set`].
#[no_mangle]
unsafe extern "C" fn rcan_rx_set_kernel(
    func: RxFn,
    data: *mut ffi::c_void,
    cookie: u32,
    net: *mut bindings::net,
    spec: *const RxSpec,
) -> ffi::c_int {
    let net = if net.is_null() {
        Net::init()
    } else {
        // SAFETY: a namespace alive for the call (contract).
        unsafe { Net::from_raw(net) }
    };
    let Some(owner) = NonNull::new(data) else {
        return code::EINVAL.to_errno();
    };
    let id = owner.as_ptr() as usize;
    // SAFETY: as in rcan_rx_set.
    let new = unsafe { spec.as_ref() }.map(|spec| {
        // INVARIANT: the caller keeps `data` and `func` valid until a
        // removal returns; every call waits a grace period below.
        let t = Target {
            func,
            owner,
            sock: false,
        };
        // SAFETY: as in rcan_rx_set.
        (unsafe { request_of(spec, cookie) }, t)
    });
    let ret = Impl::rx_set(net, id, new);
    // A registration this call replaced or removed is unlinked now; the
    // caller may free `data` (or unload) once we return: wait out every
    // callback that may still use it.
    synchronize_rcu();
    match ret {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// See [`crate::glue::can::abi::rcan_rx_listen`].
///
/// # Safety
///
/// With `add`, `data` is a registered `net_device` that stays valid, and
/// `func` may be called with it, until a call removing the listener has
/// returned.
#[no_mangle]
unsafe extern "C" fn rcan_rx_listen(
    func: ListenFn,
    data: *mut ffi::c_void,
    _ifindex: i32,
    add: bool,
) -> ffi::c_int {
    let mut reg = WRITERS.lock();
    if let Some(i) = reg
        .listeners
        .iter()
        .position(|l| l.func as usize == func as usize && l.data == data)
    {
        crate::glue::kvec_swap_remove(&mut reg.listeners, i);
    }
    if add {
        if let Err(e) = reg.listeners.push(Listener { func, data }, GFP_KERNEL) {
            return Error::from(e).to_errno();
        }
    }
    NLISTENERS.store(reg.listeners.len(), Ordering::Relaxed);
    // Pairs with the fence in notify_listeners: the new count is visible
    // before the caller (a new listener) reads the table after we return.
    fence(Ordering::SeqCst);
    0
}

/// See [`crate::glue::can::abi::rcan_rx_filters`].
///
/// # Safety
///
/// `dev` is NULL or a valid `net_device` for the call; `out` is NULL or
/// points to room for `cap` filters, writable and used by nothing else
/// for the call.
#[no_mangle]
unsafe extern "C" fn rcan_rx_filters(
    dev: *const bindings::net_device,
    out: *mut TableFilter,
    cap: usize,
) -> isize {
    if dev.is_null() {
        return -1;
    }
    // SAFETY: the caller's device, valid for the call (abi contract).
    let dev = unsafe { NetDev::from_raw(dev.cast_mut()) };
    let out = if cap == 0 || out.is_null() {
        &mut [][..]
    } else {
        // SAFETY: the caller passes room for `cap` filters (abi contract);
        // `Filter` is plain `Copy` data, so overwriting is fine.
        unsafe { core::slice::from_raw_parts_mut(out, cap) }
    };
    match Impl::rx_filters(dev, out) {
        Some(n) => n as isize,
        None => -1,
    }
}

/// See [`crate::glue::can::abi::rcan_proto_register`].
///
/// # Safety
///
/// `cp` points to a static [`CanProto`] of the calling module, which
/// stays valid until [`rcan_proto_unregister`] of it has returned.
#[no_mangle]
unsafe extern "C" fn rcan_proto_register(cp: *const CanProto) -> ffi::c_int {
    // SAFETY: callers pass a static CanProto of their module.
    let proto = unsafe { (*cp).protocol };
    if proto < 0 || proto as usize >= CANPROTO_MAX {
        return code::EINVAL.to_errno();
    }
    let _w = WRITERS.lock();
    let slot = &PROTOS[proto as usize];
    if !slot.get_locked().is_null() {
        pr_err!("protocol {} already registered\n", proto);
        return code::EEXIST.to_errno();
    }
    // SAFETY: writers' lock held; `cp` is the module's static CanProto,
    // valid until rcan_proto_unregister takes it out and waits for a
    // grace period; the previous value is NULL (checked above).
    unsafe { slot.replace(cp as *mut CanProto) };
    0
}

/// See [`crate::glue::can::abi::rcan_proto_unregister`].
///
/// # Safety
///
/// `cp` points to a valid [`CanProto`] (the one the caller registered).
#[no_mangle]
unsafe extern "C" fn rcan_proto_unregister(cp: *const CanProto) {
    // SAFETY: as in register.
    let proto = unsafe { (*cp).protocol };
    if proto < 0 || proto as usize >= CANPROTO_MAX {
        return;
    }
    {
        let _w = WRITERS.lock();
        let slot = &PROTOS[proto as usize];
        if slot.get_locked() == cp as *mut CanProto {
            // SAFETY: writers' lock held; NULL is always valid; the old
            // value is the caller's static, used by readers until the
            // synchronize_rcu below.
            unsafe { slot.replace(core::ptr::null_mut()) };
        }
    }
    // No socket creation may still hold the old pointer after this.
    synchronize_rcu();
}

/// Whether protocol `proto` (below [`CANPROTO_MAX`]) has an entry in the
/// table now. Any context.
fn proto_registered(proto: usize) -> bool {
    let g = RcuReadGuard::new();
    PROTOS[proto].read(&g).is_some()
}

/// Loads the module of protocol `protocol` through its alias
/// `rcan-proto-<protocol>` (mainline's af_can requests `can-proto-<N>`;
/// ours must not collide with it, so that `modprobe` never picks
/// mainline's `can-raw` for our family or ours for mainline's). Process
/// context; sleeps while modprobe runs: call it with no lock held and
/// outside any RCU read-side section.
fn request_proto_module(protocol: ffi::c_int) -> Result {
    let name = kernel::str::CString::try_from_fmt(kernel::fmt!("rcan-proto-{}", protocol))?;
    crate::glue::kmod::request_module(&name)
}

/// `net_proto_family.create`: socket(PF_CAN, type, protocol). Process
/// context; may sleep (loading the protocol's module on demand).
///
/// # Safety
///
/// Called by the socket layer with its arguments.
unsafe extern "C" fn pf_can_create(
    net: *mut bindings::net,
    sock: *mut bindings::socket,
    protocol: ffi::c_int,
    kern: ffi::c_int,
) -> ffi::c_int {
    // Whether the protocol works outside the initial namespace is the
    // protocol's to say (`CanProtocol::ALL_NAMESPACES`, checked in its
    // create).
    if protocol < 0 || protocol as usize >= CANPROTO_MAX {
        return -(bindings::EPROTONOSUPPORT as ffi::c_int);
    }
    // SAFETY: `sock` is the new socket the socket layer is creating.
    let sock_type = unsafe { (*sock).type_ } as i32;
    if !proto_registered(protocol as usize) {
        // As af_can does with "can-proto-N": the protocol's module declares
        // this alias (`module!`'s `alias:`). Outside the RCU section and
        // without WRITERS: modprobe sleeps, and the module's init takes
        // WRITERS to register. Any failure ends as EPROTONOSUPPORT below,
        // when the table still has no entry.
        let _ = request_proto_module(protocol);
    }
    let (create, owner) = {
        let g = RcuReadGuard::new();
        let Some(cp) = PROTOS[protocol as usize].read(&g) else {
            return -(bindings::EPROTONOSUPPORT as ffi::c_int);
        };
        if cp.type_ != sock_type {
            return -(bindings::EPROTOTYPE as ffi::c_int);
        }
        // Pin the protocol's module before leaving the read-side section:
        // its `create` may sleep and the module may be on its way out.
        // SAFETY: `owner` is the registering module; try_module_get fails
        // once its unloading has begun.
        if !unsafe { bindings::rcan_try_module_get(cp.owner) } {
            return -(bindings::EPROTONOSUPPORT as ffi::c_int);
        }
        (cp.create, cp.owner)
    };
    // SAFETY: the module holding `create` is pinned until module_put; the
    // CanProto static lives as long as the module.
    let ret = unsafe { create(net, sock, protocol, kern) };
    // SAFETY: paired with the try_module_get above. The new socket holds
    // its own module reference through its proto_ops owner.
    unsafe { bindings::rcan_module_put(owner) };
    ret
}

/// ETH_P_CAN packet handler: every classic CAN frame received on any
/// device. NET_RX softirq context, inside the core's RCU read-side section.
///
/// # Safety
///
/// Called by the network core's receive path with one skb reference and
/// the receiving device.
unsafe extern "C" fn can_rcv(
    skb: *mut bindings::sk_buff,
    dev: *mut bindings::net_device,
    _pt: *mut bindings::packet_type,
    _orig_dev: *mut bindings::net_device,
) -> ffi::c_int {
    // SAFETY: same contract as ours.
    unsafe { rcv_common(skb, dev, false) }
}

/// ETH_P_CANFD packet handler (mainline `canfd_rcv`): every CAN FD frame
/// received on any device. NET_RX softirq context, inside the core's RCU
/// read-side section.
///
/// # Safety
///
/// As [`can_rcv`].
unsafe extern "C" fn canfd_rcv(
    skb: *mut bindings::sk_buff,
    dev: *mut bindings::net_device,
    _pt: *mut bindings::packet_type,
    _orig_dev: *mut bindings::net_device,
) -> ffi::c_int {
    // SAFETY: same contract as ours.
    unsafe { rcv_common(skb, dev, true) }
}

/// The body of both packet handlers.
///
/// # Safety
///
/// As [`can_rcv`]. One copy for both handlers, with the family's `rcv`
/// and the table's lookup inlined into it.
#[inline(never)]
unsafe fn rcv_common(
    skb: *mut bindings::sk_buff,
    dev: *mut bindings::net_device,
    fd: bool,
) -> ffi::c_int {
    // SAFETY: the core hands us one skb reference and the receiving
    // device, alive for the call.
    let (skb, dev) = unsafe {
        match Skb::from_raw(skb) {
            Some(s) => (s, NetDev::from_raw(dev)),
            None => return bindings::NET_RX_DROP as ffi::c_int,
        }
    };
    // SAFETY: the core calls packet handlers inside its rcu_read_lock()
    // (netif_receive_skb_internal, netif_receive_skb_list_internal,
    // process_backlog, netif_receive_skb_core), which lasts past our return.
    let rcu = unsafe { RcuReadGuard::assume_held() };
    if Impl::rcv(&rcu, skb, dev, fd) {
        bindings::NET_RX_SUCCESS as ffi::c_int
    } else {
        bindings::NET_RX_DROP as ffi::c_int
    }
}

/// See [`crate::glue::can::abi::rcan_send`].
///
/// # Safety
///
/// `skb` is NULL or an skb whose reference the caller gives away, the
/// only one, to an skb that is not cloned (a [`UniqueSkb`] given away:
/// [`crate::glue::can::proto::send`] is the caller), whose `dev` is NULL
/// or a device on which the caller holds a reference until this returns.
#[no_mangle]
unsafe extern "C" fn rcan_send(skb: *mut bindings::sk_buff, loopback: bool) -> ffi::c_int {
    // SAFETY: the caller gives us its reference, the only one, to an
    // uncloned skb (abi contract, kept by the caller's `UniqueSkb`).
    let Some(skb) = (unsafe { UniqueSkb::from_raw(skb) }) else {
        return code::EINVAL.to_errno();
    };
    // SAFETY: the caller holds a reference on skb->dev until we return.
    let Some(dev) = (unsafe { skb.dev() }) else {
        return code::ENODEV.to_errno();
    };
    match Impl::send(skb, dev, loopback) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// `dev_queue_xmit` of a prepared CAN skb on `dev` (sets `skb->dev`):
/// consumes `skb`; congestion (`NET_XMIT_CN`) counts as sent, a drop is
/// ENOBUFS. Process or softirq context.
#[inline]
pub(crate) fn queue_xmit(skb: OwnedSkb, dev: &NetDev) -> Result {
    let mut skb = skb;
    // SAFETY: handed to the kernel right below, `dev` borrowed meanwhile.
    unsafe { skb.set_dev(dev) };
    // SAFETY: skb->dev is `dev`, borrowed (so alive) for the call;
    // `dev_queue_xmit` (this, with no subordinate device) consumes the skb
    // in every case.
    let ret = unsafe { bindings::__dev_queue_xmit(skb.into_raw(), core::ptr::null_mut()) };
    match ret {
        r if r < 0 => Err(Error::from_errno(r)),
        0 => Ok(()),
        r if r as u32 == bindings::NET_XMIT_CN => Ok(()),
        _ => Err(crate::glue::neterr::ENOBUFS()),
    }
}

static FAMILY: CCell<bindings::net_proto_family> = CCell::new(bindings::net_proto_family {
    family: bindings::PF_CAN as i32,
    create: Some(pf_can_create),
    owner: core::ptr::null_mut(),
});

static PACKET: CCell<bindings::packet_type> = CCell::new(bindings::packet_type {
    type_: (bindings::ETH_P_CAN as u16).to_be(),
    func: Some(can_rcv),
    // SAFETY: all-zero is valid for the remaining fields (no device filter,
    // empty list head filled in by dev_add_pack).
    ..unsafe { core::mem::zeroed() }
});

static PACKET_FD: CCell<bindings::packet_type> = CCell::new(bindings::packet_type {
    type_: (bindings::ETH_P_CANFD as u16).to_be(),
    func: Some(canfd_rcv),
    // SAFETY: as for PACKET.
    ..unsafe { core::mem::zeroed() }
});

/// PF_CAN and the ETH_P_CAN and ETH_P_CANFD handlers registered, and the per-namespace
/// receive tables; dropping it unregisters the family and the handlers
/// (waiting for running handlers), then drops the namespaces' tables.
/// Process context.
pub(crate) struct FamilyReg {
    _pernet: PernetReg<NetTable>,
}

/// Registers PF_CAN with the socket layer (EEXIST if another family, e.g.
/// mainline's can.ko, has it) and the ETH_P_CAN and ETH_P_CANFD packet
/// handlers. Module
/// init only (process context); at most once at a time: EBUSY.
pub(crate) fn register() -> Result<FamilyReg> {
    // Before the family and the handler, so every namespace has its slot
    // when the first socket or frame comes. `get` (net_table*) is only
    // called from the entry points, the handler and `create`, which run
    // while the family is registered: FamilyReg unregisters those first.
    // SAFETY: see above; the registration is dropped after them.
    let pernet = unsafe { NET_TABLES.register() }?;
    // SAFETY: module init is single-threaded with respect to FAMILY:
    // nothing uses it before sock_register, and a second call while
    // registered is refused here.
    unsafe {
        if !(*FAMILY.get()).owner.is_null() {
            return Err(code::EBUSY);
        }
        (*FAMILY.get()).owner = crate::glue::this_module();
    }
    // SAFETY: FAMILY is a static, fully initialised family.
    let ret = unsafe { bindings::sock_register(FAMILY.get()) };
    if let Err(e) = crate::glue::to_result(ret) {
        // SAFETY: not registered: nothing else sees FAMILY.
        unsafe { (*FAMILY.get()).owner = core::ptr::null_mut() };
        return Err(e);
    }
    // SAFETY: PACKET and PACKET_FD are static packet_types, removed in
    // FamilyReg's Drop.
    unsafe {
        bindings::dev_add_pack(PACKET.get());
        bindings::dev_add_pack(PACKET_FD.get());
    }
    Ok(FamilyReg { _pernet: pernet })
}

impl Drop for FamilyReg {
    fn drop(&mut self) {
        // SAFETY: registered in `register`; dev_remove_pack waits for
        // running handlers (synchronize_net), sock_unregister for running
        // creates.
        unsafe {
            bindings::dev_remove_pack(PACKET_FD.get());
            bindings::dev_remove_pack(PACKET.get());
            bindings::sock_unregister(bindings::PF_CAN as i32);
            (*FAMILY.get()).owner = core::ptr::null_mut();
        }
        // `_pernet` is dropped now: every namespace's table goes.
    }
}

/// pf_can's data in each network namespace: the receive table of the
/// namespace, made at its first subscription (most namespaces never use
/// CAN, and a table is about 66 KB) and published under RCU; NULL (no
/// receivers) until then. The initial namespace's table is pf_can's
/// static one instead, which this leaves NULL. Writers (publishing it)
/// hold `WRITERS`.
pub(crate) struct NetTable {
    table: RcuPtr<RxTable<Target>>,
    /// The table unpublished at `pre_exit`, freed by Drop (exit), a grace
    /// period later.
    retired: core::sync::atomic::AtomicPtr<RxTable<Target>>,
}

static NET_TABLES: Pernet<NetTable> = Pernet::new();

impl PernetData for NetTable {
    fn pernet() -> &'static Pernet<Self> {
        &NET_TABLES
    }

    fn init(_net: &Net) -> Result<Self> {
        Ok(NetTable {
            table: RcuPtr::null(),
            retired: core::sync::atomic::AtomicPtr::new(core::ptr::null_mut()),
        })
    }

    /// Every device of the namespace is gone and no socket is left (each
    /// holds a reference on its namespace): unpublish the table, so the
    /// grace period before exit ends every reader.
    fn pre_exit(&self, _net: &Net) {
        let _w = WRITERS.lock();
        // SAFETY: writers' lock held; NULL is always valid; the old table
        // is freed by Drop, after the grace period the namespace core
        // guarantees between pre_exit and exit.
        let old = unsafe { self.table.replace(core::ptr::null_mut()) };
        self.retired
            .store(old, core::sync::atomic::Ordering::Relaxed);
    }
}

impl Drop for NetTable {
    /// The namespace's exit. Process context; sleeps.
    fn drop(&mut self) {
        let p = *self.retired.get_mut();
        if p.is_null() {
            return;
        }
        // SAFETY: made by `net_table_make` from a KVBox, unpublished in
        // pre_exit a grace period ago: nothing refers to it.
        let t = unsafe { kernel::alloc::KVBox::from_raw(p) };
        // Registrations' RCU callbacks do not touch the table itself. A
        // table with receivers left (a kernel bug elsewhere) is leaked
        // with them rather than freed under them.
        if !t.shutdown() {
            core::mem::forget(t);
        }
    }
}

/// The receive table of `net` (not the initial namespace), if it has one
/// yet. It lives until the namespace's exit, so as long as `net` is
/// borrowed alive. Any context.
pub(crate) fn net_table(net: &Net) -> Option<&RxTable<Target>> {
    let d = NET_TABLES.get(net)?;
    let g = RcuReadGuard::new();
    let t = d.table.read(&g)? as *const RxTable<Target>;
    // SAFETY: published, and freed only at the namespace's exit, which
    // cannot come while `net` is borrowed alive (a socket or device of it
    // exists).
    Some(unsafe { &*t })
}

/// The receive table of `net` (not the initial namespace), made now if it
/// has none. Process context; sleeps. ENOMEM.
pub(crate) fn net_table_make(net: &Net) -> Result<&RxTable<Target>> {
    if let Some(t) = net_table(net) {
        return Ok(t);
    }
    let d = NET_TABLES.get(net).ok_or(code::ENODEV)?;
    // Allocated outside the lock; dropped unpublished if another
    // subscription made one first.
    let fresh = RxTable::new_boxed(RX_MUTEX)?;
    let _w = WRITERS.lock();
    let cur = d.table.get_locked();
    if !cur.is_null() {
        // SAFETY: as in net_table.
        return Ok(unsafe { &*cur });
    }
    let p = kernel::alloc::KVBox::into_raw(fresh);
    // SAFETY: writers' lock held; a fully built table, freed only at the
    // namespace's exit after being unpublished (pre_exit) and a grace
    // period; the previous value is NULL (checked above).
    unsafe { d.table.replace(p) };
    // SAFETY: as in net_table.
    Ok(unsafe { &*p })
}

/// Module exit: frees the (empty) listener list; statics are never
/// dropped. Process context.
pub(crate) fn shutdown() {
    WRITERS.lock().listeners = KVec::new();
    NLISTENERS.store(0, Ordering::Relaxed);
}
