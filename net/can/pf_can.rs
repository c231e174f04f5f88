// SPDX-License-Identifier: GPL-2.0

//! rcan_pf: the PF_CAN protocol family (thesis 5.3.1, module `pf_can`).
//!
//! * Registers PF_CAN (29) with the socket layer and hands `socket()` to the
//!   CAN protocol registered for its protocol number, holding a reference
//!   on that protocol's module while its `create` runs.
//! * Receives every ETH_P_CAN frame (packet_type handler, NET_RX softirq)
//!   and dispatches it to the receivers whose filters match, through one
//!   receive table shared by every protocol (`rcan_core::rxtable`). This is
//!   the only way in: drivers hand up bus frames and echoes alike through
//!   the network core (`netif_rx` or NAPI), so receive callbacks always run
//!   in NET_RX softirq, with no driver lock held, and may transmit.
//! * Sends frames for the protocols (`rcan_send`, mainline `can_send`),
//!   looping them back to local receivers when the device cannot echo.
//!
//! Shared state and its discipline:
//!
//! * `PROTOS`: the protocol table. Read under RCU (`pf_can_create`, process
//!   context); written under `WRITERS` (register/unregister, process
//!   context). The thesis uses a spinlock for writers; a mutex serves the
//!   same purpose here because every writer is in process context.
//! * `WRITERS` (`rcan_pf_mutex`) also protects the list of drivers that
//!   follow the receive table ([`Listener`]); they are called under it.
//! * `TABLE`: the receive table (`glue::can::rx::RxTable`), read without
//!   locks in NET_RX softirq (`can_rcv`) and changed incrementally, one
//!   receiver at a time, under its own mutex (`rcan_rx_mutex`) by
//!   `rcan_rx_set` (process context). Removed registrations are freed by
//!   `call_rcu` callbacks, so neither writers nor `close()` wait for a grace
//!   period; each socket receiver holds a reference on its socket until
//!   then.
//!
//! Lock order (outermost first): RTNL, socket lock, `rcan_rx_mutex`;
//! `WRITERS` is never held together with `rcan_rx_mutex`.

use kernel::ffi;
use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

use glue::bindings;
use glue::can::rx::{Filters, Receiver, RxTable, Spec};
use glue::netdev::NetDev;
use glue::skb::Skb;
use glue::sync::{rcu_barrier, synchronize_rcu, CCell, CMutex, RcuPtr, RcuReadGuard};
use rcan_api::{
    CanProto, ListenFn, RxFilter, RxFn, RxSpec, CANPROTO_MAX, RX_FILTER_ARB, RX_FILTER_CAN_ID,
};
use rcan_core::filter::ArbFilter;
use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
use rcan_core::rxtable::{self, CanFilterKind, Filter};

module! {
    type: PfCan,
    name: "rcan_pf",
    author: "rcan developers",
    description: "PF_CAN protocol family (thesis pf_can)",
    license: "GPL",
}

extern "C" {
    fn rcan_pf_mutex_ptr() -> *mut bindings::mutex;
    fn rcan_rx_mutex_ptr() -> *mut bindings::mutex;
}

fn pf_mutex() -> *mut bindings::mutex {
    // SAFETY: returns the address of a statically defined mutex.
    unsafe { rcan_pf_mutex_ptr() }
}

fn rx_mutex() -> *mut bindings::mutex {
    // SAFETY: returns the address of a statically defined mutex.
    unsafe { rcan_rx_mutex_ptr() }
}

/// A receiver in the receive table: a protocol's socket (holding a
/// reference on it, dropped with the receiver after a grace period) or an
/// in-kernel receiver's data (whose removal waits for a grace period
/// instead).
struct Target {
    func: RxFn,
    owner: *mut ffi::c_void,
    is_sock: bool,
}

// SAFETY: `owner` is a counted sock reference or a kernel receiver's data
// that outlives the registration; both are usable from any CPU.
unsafe impl Send for Target {}
// SAFETY: as above; shared access only reads.
unsafe impl Sync for Target {}

impl Receiver for Target {
    /// One registration per owner (a socket belongs to one protocol; a
    /// kernel receiver's data to one module).
    fn id(&self) -> usize {
        self.owner as usize
    }
}

impl Drop for Target {
    /// Runs in a `call_rcu` callback (softirq) or in the writer's process
    /// context; the final `sock_put` may free the sock.
    fn drop(&mut self) {
        if self.is_sock {
            // SAFETY: the reference taken in `rx_set` for this Target.
            unsafe { bindings::rcan_sock_put(self.owner.cast()) };
        }
    }
}

/// A driver that wants to know when the receive table changes for its
/// interface (to recompute its hardware filter, DESIGN decision 7).
#[derive(Clone, Copy)]
struct Listener {
    func: ListenFn,
    data: *mut ffi::c_void,
    ifindex: i32,
}

/// What `WRITERS` protects besides `PROTOS`.
struct Registry {
    listeners: KVec<Listener>,
}

// SAFETY: the raw pointers are opaque tokens handed back to their owners'
// callbacks; the owners guarantee their validity (rcan_api contracts).
unsafe impl Send for Registry {}

/// Serialises the writers of `PROTOS` and protects the listeners. Process
/// context.
static WRITERS: CMutex<Registry> = CMutex::new(
    pf_mutex,
    Registry {
        listeners: KVec::new(),
    },
);

/// The protocol table (RCU readers, `WRITERS` for writers).
static PROTOS: [RcuPtr<CanProto>; CANPROTO_MAX] = [const { RcuPtr::null() }; CANPROTO_MAX];

/// The receive table (RCU readers in softirq, `rcan_rx_mutex` for
/// writers).
static TABLE: RxTable<Target> = RxTable::new(rx_mutex);

/// Converts the C filters of a spec.
fn filters_of(filters: &[RxFilter], err_mask: &mut u32) -> Result<Filters> {
    let mut v = Filters::with_capacity(filters.len())?;
    for f in filters {
        match f.kind {
            RX_FILTER_ARB => {
                let af = ArbFilter::new(f.id, f.mask).map_err(|e| glue::errno(e.errno()))?;
                v.push(Filter::Arb(af))?;
            }
            RX_FILTER_CAN_ID => match Filter::from_can_filter(f.id, f.mask) {
                CanFilterKind::Frames(x) => v.push(x)?,
                CanFilterKind::Errors(m) => *err_mask |= m,
            },
            _ => return Err(EINVAL),
        }
    }
    Ok(v)
}

/// See [`rcan_api::rcan_rx_set`]. Process context; sleeps (allocates,
/// takes the table's mutex, then `WRITERS` to tell the drivers).
fn rx_set(
    func: RxFn,
    owner: *mut ffi::c_void,
    is_sock: bool,
    cookie: u32,
    spec: Option<&RxSpec>,
) -> Result {
    let changed = match spec {
        Some(spec) => {
            let filters = if spec.nfilters == 0 || spec.filters.is_null() {
                &[][..]
            } else {
                // SAFETY: the caller passes `nfilters` readable filters
                // (rcan_api contract).
                unsafe { core::slice::from_raw_parts(spec.filters, spec.nfilters) }
            };
            let mut err_mask = spec.err_mask & rxtable::CAN_ERR_MASK;
            let filters = filters_of(filters, &mut err_mask)?;
            let s = Spec {
                ifindex: spec.ifindex,
                filters,
                join: spec.join,
                err_mask,
                cookie,
            };
            if is_sock {
                // SAFETY: the caller's `owner` is a live sock; the Target
                // keeps this reference until it is dropped.
                unsafe { bindings::rcan_sock_hold(owner.cast()) };
            }
            let t = Target {
                func,
                owner,
                is_sock,
            };
            TABLE.set(owner as usize, Some((s, t)))?
        }
        None => TABLE.set(owner as usize, None)?,
    };
    notify(&changed.ifindex);
    if changed.removed && !is_sock {
        // A kernel receiver's data may be freed by the caller once we
        // return: wait out every callback that may still use it.
        synchronize_rcu();
    }
    Ok(())
}

#[no_mangle]
extern "C" fn rcan_rx_set(
    func: RxFn,
    sk: *mut bindings::sock,
    cookie: u32,
    spec: *const RxSpec,
) -> ffi::c_int {
    if sk.is_null() {
        return EINVAL.to_errno();
    }
    // SAFETY: NULL or a valid spec for the duration of the call (rcan_api
    // contract).
    let spec = unsafe { spec.as_ref() };
    match rx_set(func, sk.cast(), true, cookie, spec) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

#[no_mangle]
extern "C" fn rcan_rx_set_kernel(
    func: RxFn,
    data: *mut ffi::c_void,
    cookie: u32,
    spec: *const RxSpec,
) -> ffi::c_int {
    if data.is_null() {
        return EINVAL.to_errno();
    }
    // SAFETY: as in rcan_rx_set.
    let spec = unsafe { spec.as_ref() };
    match rx_set(func, data, false, cookie, spec) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

/// Tells the drivers of the interfaces in `ifindexes` (0: all of them)
/// that their wanted filters changed. Process context; takes `WRITERS` (so
/// a listener being removed is not called after its removal returns).
fn notify(ifindexes: &[Option<i32>]) {
    if ifindexes.iter().all(|i| i.is_none()) {
        return;
    }
    let reg = WRITERS.lock();
    for l in reg.listeners.iter() {
        if ifindexes
            .iter()
            .flatten()
            .any(|&i| i == 0 || i == l.ifindex)
        {
            // SAFETY: a registered listener's data stays valid until
            // rcan_rx_listen removes it, which needs `WRITERS` (held here).
            unsafe { (l.func)(l.data) };
        }
    }
}

#[no_mangle]
extern "C" fn rcan_rx_listen(
    func: ListenFn,
    data: *mut ffi::c_void,
    ifindex: i32,
    add: bool,
) -> ffi::c_int {
    let mut reg = WRITERS.lock();
    if let Some(i) = reg
        .listeners
        .iter()
        .position(|l| l.func as usize == func as usize && l.data == data)
    {
        glue::kvec_swap_remove(&mut reg.listeners, i);
    }
    if add {
        if let Err(e) = reg.listeners.push(
            Listener {
                func,
                data,
                ifindex,
            },
            GFP_KERNEL,
        ) {
            return Error::from(e).to_errno();
        }
    }
    0
}

#[no_mangle]
extern "C" fn rcan_rx_filters(ifindex: i32, out: *mut Filter, cap: usize) -> isize {
    let out = if cap == 0 || out.is_null() {
        &mut [][..]
    } else {
        // SAFETY: the caller passes room for `cap` filters (rcan_api
        // contract); `Filter` is plain `Copy` data, so overwriting is fine.
        unsafe { core::slice::from_raw_parts_mut(out, cap) }
    };
    match TABLE.filters(ifindex, out) {
        Some(n) => n as isize,
        None => -1,
    }
}

#[no_mangle]
extern "C" fn rcan_proto_register(cp: *const CanProto) -> ffi::c_int {
    // SAFETY: callers pass a static CanProto of their module.
    let proto = unsafe { (*cp).protocol };
    if proto < 0 || proto as usize >= CANPROTO_MAX {
        return EINVAL.to_errno();
    }
    let _w = WRITERS.lock();
    let slot = &PROTOS[proto as usize];
    if !slot.get_locked().is_null() {
        pr_err!("protocol {} already registered\n", proto);
        return EEXIST.to_errno();
    }
    slot.replace(cp as *mut CanProto);
    0
}

#[no_mangle]
extern "C" fn rcan_proto_unregister(cp: *const CanProto) {
    // SAFETY: as in register.
    let proto = unsafe { (*cp).protocol };
    if proto < 0 || proto as usize >= CANPROTO_MAX {
        return;
    }
    {
        let _w = WRITERS.lock();
        let slot = &PROTOS[proto as usize];
        if slot.get_locked() == cp as *mut CanProto {
            slot.replace(core::ptr::null_mut());
        }
    }
    // No socket creation may still hold the old pointer after this.
    synchronize_rcu();
}

/// `net_proto_family.create`: socket(PF_CAN, type, protocol). Process
/// context.
unsafe extern "C" fn pf_can_create(
    net: *mut bindings::net,
    sock: *mut bindings::socket,
    protocol: ffi::c_int,
    kern: ffi::c_int,
) -> ffi::c_int {
    // SAFETY: `net` is the caller's namespace, valid for the call.
    if !unsafe { bindings::rcan_net_is_init(net) } {
        return -(bindings::EAFNOSUPPORT as ffi::c_int);
    }
    if protocol < 0 || protocol as usize >= CANPROTO_MAX {
        return -(bindings::EPROTONOSUPPORT as ffi::c_int);
    }
    // SAFETY: `sock` is the new socket the socket layer is creating.
    let sock_type = unsafe { (*sock).type_ } as i32;
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

static FAMILY: CCell<bindings::net_proto_family> = CCell::new(bindings::net_proto_family {
    family: bindings::PF_CAN as i32,
    create: Some(pf_can_create),
    owner: core::ptr::null_mut(),
});

/// ETH_P_CAN packet handler: every CAN frame received on any device.
/// NET_RX softirq context, inside the core's RCU read-side section.
///
/// Each matching receiver is called once; all but the last get the skb
/// borrowed (they clone it), the last one gets our reference, so the common
/// single-receiver case queues the skb without cloning it.
unsafe extern "C" fn can_rcv(
    skb: *mut bindings::sk_buff,
    dev: *mut bindings::net_device,
    _pt: *mut bindings::packet_type,
    _orig_dev: *mut bindings::net_device,
) -> ffi::c_int {
    // SAFETY: the core hands us one skb reference and the receiving device.
    let (skb, dev) = unsafe {
        match Skb::from_raw(skb) {
            Some(s) => (s, NetDev::from_raw(dev)),
            None => return bindings::NET_RX_DROP as ffi::c_int,
        }
    };
    if dispatch(skb, dev) {
        bindings::NET_RX_SUCCESS as ffi::c_int
    } else {
        bindings::NET_RX_DROP as ffi::c_int
    }
}

/// Hands a received frame to every receiver that wants it (see
/// `can_rcv`). NET_RX softirq. Returns false if the frame was malformed
/// (dropped).
fn dispatch(skb: Skb, dev: &NetDev) -> bool {
    let Some(frame) = valid_frame(&skb, dev) else {
        drop(skb); // counted as a drop
        return false;
    };
    let g = RcuReadGuard::new();
    let mut pending: Option<(&Target, u32)> = None;
    TABLE.for_each_match(&g, dev.ifindex(), frame.can_id, |t, cookie| {
        if let Some(prev) = pending.replace((t, cookie)) {
            deliver_borrowed(prev, &skb);
        }
    });
    match pending {
        Some(last) => deliver_last(last, skb),
        None => skb.consume(),
    }
    true
}

/// Calls a receiver with the skb borrowed. Softirq, RCU read side.
fn deliver_borrowed((t, cookie): (&Target, u32), skb: &Skb) {
    // The receiver was found in the table inside our read-side section,
    // so it (with the sock reference it holds, and the receiver's module
    // through the sock; or a kernel receiver's data, whose removal waits
    // for a grace period) lives until the section ends.
    // SAFETY: live receiver (above); valid skb, borrowed (owned = false).
    unsafe { (t.func)(skb.as_ptr(), t.owner, cookie, false) };
}

/// Calls the last receiver, handing it our reference when nobody else
/// holds one. Softirq, RCU read side.
fn deliver_last((t, cookie): (&Target, u32), skb: Skb) {
    if skb.is_shared() {
        deliver_borrowed((t, cookie), &skb);
        skb.consume();
        return;
    }
    // SAFETY: as in deliver_borrowed; the callee takes our (only)
    // reference (RxFn contract, owned = true).
    unsafe { (t.func)(skb.into_raw(), t.owner, cookie, true) };
}

/// The frame in `skb` if it is a well-formed classic CAN frame from a CAN
/// device; drivers are trusted for nothing else.
fn valid_frame(skb: &Skb, dev: &NetDev) -> Option<CanFrame> {
    if !dev.is_can() {
        return None;
    }
    let bytes: &[u8; CAN_FRAME_LEN] = skb.data().try_into().ok()?;
    let frame = CanFrame::from_bytes(bytes);
    (usize::from(frame.len) <= rcan_core::arb::MAX_DLC).then_some(frame)
}

/// See [`rcan_api::rcan_send`]. Process or softirq context.
fn send(mut skb: Skb, dev: &NetDev, loopback: bool) -> Result {
    let frame_ok = <&[u8; CAN_FRAME_LEN]>::try_from(skb.data())
        .map(|b| usize::from(CanFrame::from_bytes(b).len) <= rcan_core::arb::MAX_DLC)
        .unwrap_or(false);
    if !frame_ok {
        return Err(EINVAL);
    }
    if skb.len() > dev.mtu() {
        return Err(glue::neterr::EMSGSIZE());
    }
    if !dev.is_can() {
        return Err(EPERM);
    }
    if !dev.is_up() {
        return Err(glue::neterr::ENETDOWN());
    }
    skb.set_can_tx(dev, loopback);
    // A device without IFF_ECHO cannot loop the frame back itself: local
    // receivers get a copy that still names the sending socket, marked as
    // mainline's can_send marks it (PACKET_BROADCAST), through netif_rx.
    let echo = if loopback && !dev.has_echo() {
        let mut e = skb.clone_with_owner().ok_or(ENOMEM)?;
        e.set_can_rx(dev);
        Some(e)
    } else {
        None
    };
    // SAFETY: dev_queue_xmit consumes the skb in every case; the caller
    // holds a reference on `dev` until we return.
    let ret = unsafe { bindings::rcan_dev_queue_xmit(skb.into_raw()) };
    let err = match ret {
        r if r < 0 => r,
        0 => 0,
        r if r as u32 == bindings::NET_XMIT_CN => 0,
        _ => glue::neterr::ENOBUFS().to_errno(),
    };
    if err != 0 {
        return Err(Error::from_errno(err));
    }
    if let Some(e) = echo {
        dev.rx(e);
    }
    Ok(())
}

#[no_mangle]
extern "C" fn rcan_send(skb: *mut bindings::sk_buff, loopback: bool) -> ffi::c_int {
    // SAFETY: the caller gives us its reference (rcan_api contract).
    let Some(skb) = (unsafe { Skb::from_raw(skb) }) else {
        return EINVAL.to_errno();
    };
    // SAFETY: the caller holds a reference on skb->dev until we return.
    let Some(dev) = (unsafe { skb.dev() }) else {
        return ENODEV.to_errno();
    };
    match send(skb, dev, loopback) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
    }
}

static PACKET: CCell<bindings::packet_type> = CCell::new(bindings::packet_type {
    type_: (bindings::ETH_P_CAN as u16).to_be(),
    func: Some(can_rcv),
    // SAFETY: all-zero is valid for the remaining fields (no device filter,
    // empty list head filled in by dev_add_pack).
    ..unsafe { core::mem::zeroed() }
});

struct PfCan;

impl kernel::Module for PfCan {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        // SAFETY: module init is single-threaded: nothing uses FAMILY yet.
        unsafe { (*FAMILY.get()).owner = glue::this_module() };
        // SAFETY: FAMILY is a static, fully initialised family.
        let ret = unsafe { bindings::sock_register(FAMILY.get()) };
        if ret == EEXIST.to_errno() {
            pr_err!("PF_CAN is already registered (mainline can.ko loaded?): not loading\n");
        }
        glue::to_result(ret)?;
        // SAFETY: PACKET is a static packet_type, removed in Drop.
        unsafe { bindings::dev_add_pack(PACKET.get()) };
        pr_info!("PF_CAN protocol family registered\n");
        Ok(PfCan)
    }
}

impl Drop for PfCan {
    fn drop(&mut self) {
        // Protocols and drivers that use us are unloaded already (module
        // dependencies), so no receiver or protocol is left.
        // SAFETY: registered in init; dev_remove_pack waits for running
        // handlers (synchronize_net).
        unsafe {
            bindings::dev_remove_pack(PACKET.get());
            bindings::sock_unregister(bindings::PF_CAN as i32);
        }
        TABLE.shutdown();
        // Statics are never dropped: free the (empty) listener list.
        WRITERS.lock().listeners = KVec::new();
        // Let pending call_rcu callbacks of the table finish before our
        // code goes.
        rcu_barrier();
        pr_info!("PF_CAN protocol family unregistered\n");
    }
}
