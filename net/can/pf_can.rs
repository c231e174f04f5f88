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
//!   same purpose here because every writer is in process context and the
//!   receive table's writers, which share it, must allocate.
//! * `WRITERS` (`rcan_pf_mutex`) protects the registry: every receiver
//!   registration ([`Record`]), the authoritative copy from which receive
//!   tables are built.
//! * `RX`: the receive table, an immutable snapshot ([`RxTable`]) published
//!   under RCU. Read without locks in softirq (`can_rcv`); rebuilt and
//!   replaced under `WRITERS` by `rcan_rx_set` (process context); replaced
//!   snapshots and removed records are freed by `call_rcu` callbacks
//!   (softirq), so neither writers nor `close()` wait for a grace period.
//!   Each record holds a reference on its socket until that callback.
//!
//! Lock order (outermost first): RTNL, socket lock, `WRITERS`.

use core::sync::atomic::{AtomicPtr, Ordering};
use kernel::ffi;
use kernel::prelude::*;

#[path = "../../rust/glue/mod.rs"]
mod glue;
mod rcan_api;
mod rcan_core;

use glue::bindings;
use glue::netdev::NetDev;
use glue::skb::Skb;
use glue::sync::{rcu_barrier, synchronize_rcu, CCell, CMutex, RcuPtr, RcuReadGuard};
use rcan_api::{
    CanProto, ListenFn, RxFilter, RxFn, RxSpec, CANPROTO_MAX, RX_FILTER_ARB, RX_FILTER_CAN_ID,
};
use rcan_core::filter::ArbFilter;
use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
use rcan_core::rxtable::{
    self, CanFilterKind, ErrEntry, ExactEntry, Filter, MaskedEntry, RegSpec, Table, TableSink,
};

module! {
    type: PfCan,
    name: "rcan_pf",
    author: "rcan developers",
    description: "PF_CAN protocol family (thesis pf_can)",
    license: "GPL",
}

extern "C" {
    fn rcan_pf_mutex_ptr() -> *mut bindings::mutex;
}

fn pf_mutex() -> *mut bindings::mutex {
    // SAFETY: returns the address of a statically defined mutex.
    unsafe { rcan_pf_mutex_ptr() }
}

/// One receiver registration (one socket of one protocol). Owned by the
/// registry under `WRITERS`; once removed, freed by `free_record` after a
/// grace period, which also drops the socket reference.
#[repr(C)]
struct Record {
    /// For call_rcu; first so the callback can find the record.
    rcu: bindings::callback_head,
    /// The receiver's socket (held with `sock_hold` from registration until
    /// `free_record`), or for a kernel receiver its opaque data pointer.
    owner: *mut ffi::c_void,
    /// `owner` is a `struct sock` (else a kernel receiver, whose removal
    /// waits for a grace period instead of counting references).
    is_sock: bool,
    func: RxFn,
    cookie: u32,
    ifindex: i32,
    join: bool,
    err_mask: u32,
    filters: KVec<Filter>,
    /// Index of this record in the `rcvs` of the published table.
    slot: usize,
}

// SAFETY: `owner` is a counted sock reference or a kernel receiver's data
// that outlives the record; both are usable from any CPU. The rest is plain
// data.
unsafe impl Send for Record {}

impl Record {
    fn spec(&self) -> RegSpec<'_> {
        RegSpec {
            ifindex: self.ifindex,
            filters: &self.filters,
            join: self.join,
            err_mask: self.err_mask,
        }
    }
}

/// A driver that wants to know when the receive table changes (to
/// recompute its hardware filter, DESIGN decision 7).
#[derive(Clone, Copy)]
struct Listener {
    func: ListenFn,
    data: *mut ffi::c_void,
}

/// The registry: every live record, and the drivers listening for
/// changes. Protected by `WRITERS`.
struct Registry {
    recs: KVec<KBox<Record>>,
    listeners: KVec<Listener>,
}

// SAFETY: the raw pointers are opaque tokens handed back to their owners'
// callbacks; the owners guarantee their validity (rcan_api contracts).
unsafe impl Send for Registry {}

/// Serialises all writers of `PROTOS` and `RX` and protects the registry.
/// Process context.
static WRITERS: CMutex<Registry> = CMutex::new(
    pf_mutex,
    Registry {
        recs: KVec::new(),
        listeners: KVec::new(),
    },
);

/// The protocol table (RCU readers, `WRITERS` for writers).
static PROTOS: [RcuPtr<CanProto>; CANPROTO_MAX] = [const { RcuPtr::null() }; CANPROTO_MAX];

/// Where the receive path finds a receiver: a copy of its record's
/// callback, with the socket pointer cleared in place if the record had to
/// be removed without a rebuild (allocation failure).
struct RcvSlot {
    owner: AtomicPtr<ffi::c_void>,
    func: RxFn,
    cookie: u32,
}

/// A snapshot of all receivers, published through `RX`; immutable once
/// published (but for `RcvSlot::owner`).
#[repr(C)]
struct RxTable {
    /// For call_rcu; first so the callback can find the table.
    rcu: bindings::callback_head,
    exact: KVec<ExactEntry>,
    starts: KVec<u32>,
    masked: KVec<MaskedEntry>,
    filters: KVec<Filter>,
    err: KVec<ErrEntry>,
    /// Indexed by registration number.
    rcvs: KVec<RcvSlot>,
}

// SAFETY: the owner pointers are counted references (or kernel receivers'
// data) held by the records, which outlive every table that names them
// (both freed after a grace period); the rest is plain data.
unsafe impl Send for RxTable {}
// SAFETY: as above; shared access only reads, `RcvSlot::owner` is atomic.
unsafe impl Sync for RxTable {}

impl RxTable {
    fn new() -> RxTable {
        RxTable {
            // SAFETY: an all-zero callback_head is what call_rcu expects.
            rcu: unsafe { core::mem::zeroed() },
            exact: KVec::new(),
            starts: KVec::new(),
            masked: KVec::new(),
            filters: KVec::new(),
            err: KVec::new(),
            rcvs: KVec::new(),
        }
    }

    fn view(&self) -> Table<'_> {
        Table {
            exact: &self.exact,
            starts: &self.starts,
            masked: &self.masked,
            filters: &self.filters,
            err: &self.err,
        }
    }
}

impl TableSink for RxTable {
    type Error = kernel::alloc::AllocError;
    fn exact(&mut self, e: ExactEntry) -> Result<(), Self::Error> {
        self.exact.push(e, GFP_KERNEL)
    }
    fn masked(&mut self, e: MaskedEntry) -> Result<(), Self::Error> {
        self.masked.push(e, GFP_KERNEL)
    }
    fn filter(&mut self, f: Filter) -> Result<(), Self::Error> {
        self.filters.push(f, GFP_KERNEL)
    }
    fn filters_len(&self) -> usize {
        self.filters.len()
    }
    fn err(&mut self, e: ErrEntry) -> Result<(), Self::Error> {
        self.err.push(e, GFP_KERNEL)
    }
}

/// The receive table (RCU readers in softirq, `WRITERS` for writers).
static RX: RcuPtr<RxTable> = RcuPtr::null();

/// `call_rcu` callback freeing a replaced table (softirq context).
unsafe extern "C" fn free_table(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of an `RxTable` leaked from a KBox
    // by `publish`; the grace period has ended, so no reader is left.
    drop(unsafe { KBox::from_raw(head.cast::<RxTable>()) });
}

/// `call_rcu` callback freeing a removed record and dropping its socket
/// reference (softirq context; the final `sock_put` may free the sock).
unsafe extern "C" fn free_record(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of a `Record` leaked from a KBox by
    // `retire`; no table published after its removal names it, and the
    // grace period ended, so no receive path uses it any more.
    let rec = unsafe { KBox::from_raw(head.cast::<Record>()) };
    if rec.is_sock {
        // SAFETY: the reference taken in `rx_set` when the record was made.
        unsafe { bindings::rcan_sock_put(rec.owner.cast()) };
    }
}

/// Frees a removed record after a grace period. Caller holds `WRITERS`.
fn retire(rec: KBox<Record>) {
    let p = KBox::into_raw(rec);
    // SAFETY: `p` is a valid record we own; free_record frees it once
    // every reader that could have seen it has finished.
    unsafe { bindings::call_rcu(core::ptr::addr_of_mut!((*p).rcu), Some(free_record)) };
}

/// Builds a table from the registry (registration number = index).
/// Process context, `WRITERS` held; allocates.
fn build(recs: &[KBox<Record>]) -> Result<KBox<RxTable>> {
    let mut t = RxTable::new();
    for (i, r) in recs.iter().enumerate() {
        t.rcvs.push(
            RcvSlot {
                owner: AtomicPtr::new(r.owner),
                func: r.func,
                cookie: r.cookie,
            },
            GFP_KERNEL,
        )?;
        rxtable::add_registration(&mut t, i as u32, &r.spec())?;
    }
    if !t.exact.is_empty() {
        let nbuckets = rxtable::bucket_count(t.exact.len());
        t.starts = KVec::from_elem(0u32, nbuckets + 1, GFP_KERNEL)?;
        let kept = rxtable::build_index(&mut t.exact, &mut t.starts);
        glue::kvec_truncate(&mut t.exact, kept);
    }
    Ok(KBox::new(t, GFP_KERNEL)?)
}

/// Publishes `table` and retires the old one. Caller holds `WRITERS`.
fn publish(table: KBox<RxTable>) {
    let old = RX.replace(KBox::into_raw(table));
    if !old.is_null() {
        // SAFETY: `old` was published by us and is now unreachable for new
        // readers; free_table runs after the current readers are done.
        unsafe { bindings::call_rcu(core::ptr::addr_of_mut!((*old).rcu), Some(free_table)) };
    }
}

/// Converts the C filters of a spec.
fn filters_of(filters: &[RxFilter], err_mask: &mut u32) -> Result<KVec<Filter>> {
    let mut v = KVec::with_capacity(filters.len(), GFP_KERNEL)?;
    for f in filters {
        match f.kind {
            RX_FILTER_ARB => {
                let af = ArbFilter::new(f.id, f.mask).map_err(|e| glue::errno(e.errno()))?;
                v.push(Filter::Arb(af), GFP_KERNEL)?;
            }
            RX_FILTER_CAN_ID => match Filter::from_can_filter(f.id, f.mask) {
                CanFilterKind::Frames(x) => v.push(x, GFP_KERNEL)?,
                CanFilterKind::Errors(m) => *err_mask |= m,
            },
            _ => return Err(EINVAL),
        }
    }
    Ok(v)
}

/// See [`rcan_api::rcan_rx_set`]. Process context; sleeps (allocates,
/// takes `WRITERS`).
fn rx_set(
    func: RxFn,
    owner: *mut ffi::c_void,
    is_sock: bool,
    cookie: u32,
    spec: Option<&RxSpec>,
) -> Result {
    // Allocate before locking.
    let new = match spec {
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
            if filters.is_empty() && err_mask == 0 {
                None
            } else {
                Some(KBox::new(
                    Record {
                        // SAFETY: an all-zero callback_head is what
                        // call_rcu expects.
                        rcu: unsafe { core::mem::zeroed() },
                        owner,
                        is_sock,
                        func,
                        cookie,
                        ifindex: spec.ifindex,
                        join: spec.join,
                        err_mask,
                        filters,
                        slot: 0,
                    },
                    GFP_KERNEL,
                )?)
            }
        }
        None => None,
    };
    let removal_only = new.is_none();

    let mut reg = WRITERS.lock();
    let old = reg
        .recs
        .iter()
        .position(|r| r.owner == owner && r.func as usize == func as usize)
        .and_then(|i| glue::kvec_swap_remove(&mut reg.recs, i));
    if old.is_none() && removal_only {
        return Ok(());
    }
    let mut added = false;
    if let Some(n) = new {
        if let Err(e) = reg.recs.push(n, GFP_KERNEL) {
            if let Some(o) = old {
                // Capacity for it is there: it was just removed.
                let _ = reg.recs.push(o, GFP_KERNEL);
            }
            return Err(e.into());
        }
        if is_sock {
            // SAFETY: the caller's `owner` is a live sock; the record keeps
            // this reference until free_record.
            unsafe { bindings::rcan_sock_hold(owner.cast()) };
        }
        added = true;
    }
    match build(&reg.recs) {
        Ok(t) => {
            publish(t);
            for (i, r) in reg.recs.iter_mut().enumerate() {
                r.slot = i;
            }
            notify(&reg.listeners);
        }
        Err(e) => {
            if added {
                let last = reg.recs.len() - 1;
                if let Some(n) = glue::kvec_swap_remove(&mut reg.recs, last) {
                    // Never published: no reader can see it.
                    if n.is_sock {
                        // SAFETY: the reference taken above.
                        unsafe { bindings::rcan_sock_put(n.owner.cast()) };
                    }
                }
            }
            let Some(o) = old else { return Err(e) };
            if !removal_only {
                let _ = reg.recs.push(o, GFP_KERNEL);
                return Err(e);
            }
            // Removal must not fail: silence the receiver in the current
            // table instead; the next rebuild leaves it out.
            let g = RcuReadGuard::new();
            if let Some(t) = RX.read(&g) {
                if let Some(s) = t.rcvs.get(o.slot) {
                    s.owner.store(core::ptr::null_mut(), Ordering::Release);
                }
            }
            drop(g);
            retire(o);
            drop(reg);
            if !is_sock {
                synchronize_rcu();
            }
            return Ok(());
        }
    }
    if let Some(o) = old {
        retire(o);
        drop(reg);
        if !is_sock {
            // A kernel receiver's data may be freed by the caller once we
            // return: wait out every callback that may still use it.
            synchronize_rcu();
        }
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

/// Tells every listening driver that the receive table changed. Process
/// context, `WRITERS` held (so a listener being removed is not called
/// after its removal returns).
fn notify(listeners: &[Listener]) {
    for l in listeners {
        // SAFETY: a registered listener's data stays valid until
        // rcan_rx_listen removes it, which needs `WRITERS` (held here).
        unsafe { (l.func)(l.data) };
    }
}

#[no_mangle]
extern "C" fn rcan_rx_listen(func: ListenFn, data: *mut ffi::c_void, add: bool) -> ffi::c_int {
    let mut reg = WRITERS.lock();
    if let Some(i) = reg
        .listeners
        .iter()
        .position(|l| l.func as usize == func as usize && l.data == data)
    {
        glue::kvec_swap_remove(&mut reg.listeners, i);
    }
    if add {
        if let Err(e) = reg.listeners.push(Listener { func, data }, GFP_KERNEL) {
            return Error::from(e).to_errno();
        }
    }
    0
}

/// Collects the filters that apply to frames received on `ifindex`
/// (registrations on it and on "all interfaces"), for drivers computing a
/// hardware filter. Any context (RCU read side).
fn rx_filters(ifindex: i32, out: &mut [Filter]) -> Option<usize> {
    let g = RcuReadGuard::new();
    let Some(t) = RX.read(&g) else {
        return Some(0);
    };
    let mut n = 0;
    let mut put = |f: Filter| -> Option<()> {
        *out.get_mut(n)? = f;
        n += 1;
        Some(())
    };
    for e in t.exact.iter() {
        let (ifi, can_id) = ((e.key >> 32) as u32 as i32, e.key as u32);
        if ifi == 0 || ifi == ifindex {
            // An exact key is a fully compared mainline filter.
            let mask = if can_id & rcan_core::arb::CAN_EFF_FLAG != 0 {
                rcan_core::arb::CAN_EFF_MASK
            } else {
                rcan_core::arb::CAN_SFF_MASK
            } | rcan_core::arb::CAN_EFF_FLAG
                | rcan_core::arb::CAN_RTR_FLAG;
            put(Filter::Id {
                id: can_id,
                mask,
                inv: false,
            })?;
        }
    }
    for m in t.masked.iter() {
        if m.ifindex == 0 || m.ifindex == ifindex {
            let first = m.first as usize;
            for f in t.filters.get(first..first + m.count as usize)? {
                put(*f)?;
            }
        }
    }
    Some(n)
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
    match rx_filters(ifindex, out) {
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
    let Some(t) = RX.read(&g) else {
        skb.consume();
        return true;
    };
    let mut pending: Option<&RcvSlot> = None;
    t.view().for_each_match(dev.ifindex(), frame.can_id, |reg| {
        if let Some(slot) = t.rcvs.get(reg as usize) {
            if let Some(prev) = pending.replace(slot) {
                deliver_borrowed(prev, &skb);
            }
        }
    });
    match pending {
        Some(last) => deliver_last(last, skb),
        None => skb.consume(),
    }
    true
}

/// Calls a receiver with the skb borrowed. Softirq, RCU read side.
fn deliver_borrowed(slot: &RcvSlot, skb: &Skb) {
    let owner = slot.owner.load(Ordering::Acquire);
    if owner.is_null() {
        return;
    }
    // The slot is in the published table, so its record (and the sock
    // reference it holds, and the receiver's module through the sock; or a
    // kernel receiver's data, whose removal waits for a grace period) lives
    // until after our RCU read-side section.
    // SAFETY: live receiver (above); valid skb, borrowed (owned = false).
    unsafe { (slot.func)(skb.as_ptr(), owner, slot.cookie, false) };
}

/// Calls the last receiver, handing it our reference when nobody else
/// holds one. Softirq, RCU read side.
fn deliver_last(slot: &RcvSlot, skb: Skb) {
    let owner = slot.owner.load(Ordering::Acquire);
    if owner.is_null() {
        skb.consume();
        return;
    }
    if skb.is_shared() {
        deliver_borrowed(slot, &skb);
        skb.consume();
        return;
    }
    // SAFETY: as in deliver_borrowed; the callee takes our (only)
    // reference (RxFn contract, owned = true).
    unsafe { (slot.func)(skb.into_raw(), owner, slot.cookie, true) };
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
        let old = {
            let mut reg = WRITERS.lock();
            // Statics are never dropped: free the (empty) registry's buffers.
            reg.recs = KVec::new();
            reg.listeners = KVec::new();
            RX.replace(core::ptr::null_mut())
        };
        synchronize_rcu();
        if !old.is_null() {
            // SAFETY: unpublished and past a grace period.
            drop(unsafe { KBox::from_raw(old) });
        }
        // Let pending free_table/free_record callbacks finish before our
        // code goes.
        rcu_barrier();
        pr_info!("PF_CAN protocol family unregistered\n");
    }
}
