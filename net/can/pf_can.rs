// SPDX-License-Identifier: GPL-2.0

//! rcan_pf: the PF_CAN protocol family (thesis 5.3.1, module `pf_can`).
//!
//! * Registers PF_CAN (29) with the socket layer and hands `socket()` to the
//!   CAN protocol registered for its protocol number, holding a reference
//!   on that protocol's module while its `create` runs.
//! * Receives every ETH_P_CAN frame (packet_type handler, NET_RX softirq)
//!   and dispatches it to the receivers whose filters match.
//!
//! Shared state and its discipline:
//!
//! * `PROTOS`: the protocol table. Read under RCU (`pf_can_create`, process
//!   context); written under `rcan_pf_mutex` (register/unregister, process
//!   context). The thesis uses a spinlock for writers; a mutex serves the
//!   same purpose here because every writer is in process context and the
//!   receive table's writers, which share it, must allocate.
//! * `RX`: the receive table, an immutable snapshot published under RCU.
//!   Read without locks in softirq (`can_rcv`); replaced under
//!   `rcan_pf_mutex` by `rcan_rx_set` (process context), old snapshots
//!   freed by `call_rcu`.
//!
//! Lock order (outermost first): RTNL, socket lock, `rcan_pf_mutex`.

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
use rcan_api::{CanProto, RxFilter, RxFn, CANPROTO_MAX};
use rcan_core::filter::{ArbFilter, Receiver};
use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};

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

/// Serialises all writers of `PROTOS` and `RX`. Process context.
static WRITERS: CMutex<()> = CMutex::new(pf_mutex, ());

/// The protocol table (RCU readers, `WRITERS` for writers).
static PROTOS: [RcuPtr<CanProto>; CANPROTO_MAX] = [const { RcuPtr::null() }; CANPROTO_MAX];

/// One receiver: a filter and the callback it feeds.
#[derive(Clone, Copy)]
struct RxEntry {
    rx: Receiver,
    func: RxFn,
    data: *mut ffi::c_void,
}

/// A snapshot of all receivers, published through `RX`.
#[repr(C)]
struct RxTable {
    /// For call_rcu; first so the callback can find the table.
    rcu: bindings::callback_head,
    entries: KVec<RxEntry>,
}

// SAFETY: `data` pointers are opaque tokens passed back to their `func`;
// the table itself is immutable once published.
unsafe impl Send for RxTable {}
// SAFETY: as above.
unsafe impl Sync for RxTable {}

/// The receive table (RCU readers in softirq, `WRITERS` for writers).
static RX: RcuPtr<RxTable> = RcuPtr::null();

/// `call_rcu` callback freeing a replaced table (softirq context).
unsafe extern "C" fn free_table(head: *mut bindings::callback_head) {
    // SAFETY: `head` is the first field of an `RxTable` leaked from a KBox
    // by `rcan_rx_set`; the grace period has ended, so no reader is left.
    drop(unsafe { KBox::from_raw(head.cast::<RxTable>()) });
}

/// Publishes `entries` as the new table and retires the old one.
/// Caller holds `WRITERS`.
fn publish(entries: KVec<RxEntry>) -> Result {
    let table = KBox::new(
        RxTable {
            // SAFETY: an all-zero callback_head is what call_rcu expects.
            rcu: unsafe { core::mem::zeroed() },
            entries,
        },
        GFP_KERNEL,
    )?;
    let old = RX.replace(KBox::into_raw(table));
    if !old.is_null() {
        // SAFETY: `old` was published by us and is now unreachable for new
        // readers; free_table runs after the current readers are done.
        unsafe { bindings::call_rcu(core::ptr::addr_of_mut!((*old).rcu), Some(free_table)) };
    }
    Ok(())
}

/// See [`rcan_api::rcan_rx_set`]. Process context; sleeps.
fn rx_set(func: RxFn, data: *mut ffi::c_void, filters: &[RxFilter]) -> Result {
    let mut removed = false;
    {
        let _w = WRITERS.lock();
        let _g = RcuReadGuard::new();
        let cur = RX.read(&_g);
        let mut entries = KVec::new();
        if let Some(t) = cur {
            for e in t.entries.iter() {
                if e.func as usize == func as usize && e.data == data {
                    removed = true;
                } else {
                    entries.push(*e, GFP_KERNEL)?;
                }
            }
        }
        drop(_g);
        for f in filters {
            let filter = ArbFilter::new(f.arb, f.mask).map_err(|e| glue::errno(e.errno()))?;
            let rx = Receiver {
                ifindex: f.ifindex,
                filter,
            };
            entries.push(rx_entry(rx, func, data), GFP_KERNEL)?;
        }
        publish(entries)?;
    }
    if removed && filters.is_empty() {
        // The caller is about to free `data`: wait out every reader that
        // may still be calling `func` with it.
        synchronize_rcu();
    }
    Ok(())
}

fn rx_entry(rx: Receiver, func: RxFn, data: *mut ffi::c_void) -> RxEntry {
    RxEntry { rx, func, data }
}

#[no_mangle]
extern "C" fn rcan_rx_set(
    func: RxFn,
    data: *mut ffi::c_void,
    filters: *const RxFilter,
    n: usize,
) -> ffi::c_int {
    let filters = if n == 0 || filters.is_null() {
        &[][..]
    } else {
        // SAFETY: the caller passes `n` readable filters (rcan_api contract).
        unsafe { core::slice::from_raw_parts(filters, n) }
    };
    match rx_set(func, data, filters) {
        Ok(()) => 0,
        Err(e) => e.to_errno(),
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
    let Some(frame) = valid_frame(&skb, dev) else {
        drop(skb); // counted as a drop
        return bindings::NET_RX_DROP as ffi::c_int;
    };
    if let Some(arb) = frame.arb() {
        let ifindex = dev.ifindex();
        let g = RcuReadGuard::new();
        if let Some(t) = RX.read(&g) {
            for e in t.entries.iter() {
                if e.rx.matches(ifindex, arb) {
                    // SAFETY: the receiver is registered (it is in the
                    // published table), so `data` is alive until its owner
                    // removes it and waits for us (rx_set).
                    unsafe { (e.func)(skb.as_ptr(), e.data) };
                }
            }
        }
    }
    skb.consume();
    bindings::NET_RX_SUCCESS as ffi::c_int
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
            let _w = WRITERS.lock();
            RX.replace(core::ptr::null_mut())
        };
        synchronize_rcu();
        if !old.is_null() {
            // SAFETY: unpublished and past a grace period.
            drop(unsafe { KBox::from_raw(old) });
        }
        // Let pending free_table callbacks finish before our code goes.
        rcu_barrier();
        pr_info!("PF_CAN protocol family unregistered\n");
    }
}
