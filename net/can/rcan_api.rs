// SPDX-License-Identifier: GPL-2.0

//! The interface of `rcan_pf` to the CAN protocols and drivers above and
//! below it: shared `#[repr(C)]` definitions, included (`#[path]`) by every
//! module that uses them, and the functions `rcan_pf` exports (defined in
//! `pf_can.rs`, exported by `pf_can_c.c`).
//!
//! Not every includer uses every item.
#![allow(dead_code, improper_ctypes)]

use crate::glue::bindings;
use kernel::ffi;

/// Size of the protocol table (`CANPROTO_MAX` in `<linux/can/rcan.h>`).
pub(crate) const CANPROTO_MAX: usize = 24;
/// The thesis' CAN 2.0 data link protocol (SOCK_RAW).
pub(crate) const CANPROTO_CAN: i32 = 16;

/// A CAN protocol (thesis `struct can_proto`, 5.3.1). Lives in a static of
/// the protocol's module; `owner` is that module.
#[repr(C)]
pub(crate) struct CanProto {
    pub(crate) protocol: ffi::c_int,
    /// SOCK_RAW, SOCK_DGRAM, ...: socket() with another type gets EPROTOTYPE.
    pub(crate) type_: ffi::c_int,
    pub(crate) owner: *mut bindings::module,
    /// Initialises a new socket. Process context; may sleep. Called with a
    /// reference held on `owner`.
    pub(crate) create: unsafe extern "C" fn(
        net: *mut bindings::net,
        sock: *mut bindings::socket,
        protocol: ffi::c_int,
        kern: ffi::c_int,
    ) -> ffi::c_int,
}

// SAFETY: a CanProto is immutable once registered; `owner` is only passed
// to try_module_get/module_put, which are safe from any thread.
unsafe impl Send for CanProto {}
// SAFETY: as above.
unsafe impl Sync for CanProto {}

/// One acceptance filter of a receiver (thesis 5.2.4): `arb`/`mask` in the
/// thesis' arbitration-field format, `ifindex` 0 for all CAN interfaces.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct RxFilter {
    pub(crate) ifindex: i32,
    pub(crate) arb: u32,
    pub(crate) mask: u32,
}

/// Receive callback: called in softirq context (NET_RX), under
/// `rcu_read_lock`, once per matching filter, with the frame's skb borrowed:
/// clone it to keep it.
pub(crate) type RxFn = unsafe extern "C" fn(skb: *mut bindings::sk_buff, data: *mut ffi::c_void);

extern "C" {
    /// Registers a protocol. Process context. EEXIST if the number is
    /// taken, EINVAL if out of range.
    pub(crate) fn rcan_proto_register(cp: *const CanProto) -> ffi::c_int;
    /// Unregisters a protocol; returns after a grace period, so no socket
    /// creation can still be looking at it. Process context.
    pub(crate) fn rcan_proto_unregister(cp: *const CanProto);
    /// Replaces all receivers of (`func`, `data`) with `n` filters from
    /// `filters` (n = 0 removes them). When receivers were removed it
    /// returns only after every running callback with `data` has finished,
    /// so the caller may then free `data`. Process context; sleeps.
    pub(crate) fn rcan_rx_set(
        func: RxFn,
        data: *mut ffi::c_void,
        filters: *const RxFilter,
        n: usize,
    ) -> ffi::c_int;
}
