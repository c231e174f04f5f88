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
/// Mainline-compatible raw protocol (SOCK_RAW), `CAN_RAW` in `<linux/can.h>`.
pub(crate) const CAN_RAW: i32 = 1;
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

/// [`RxFilter::kind`]: thesis filter, `id`/`mask` are an arbitration field
/// pattern and mask (mask bit 1 = don't care, thesis 5.2.4).
pub(crate) const RX_FILTER_ARB: u32 = 0;
/// [`RxFilter::kind`]: mainline `struct can_filter` (`can_id`, `can_mask`,
/// `CAN_INV_FILTER`; a mask with `CAN_ERR_FLAG` selects error frames).
pub(crate) const RX_FILTER_CAN_ID: u32 = 1;

/// One acceptance filter of a receiver.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct RxFilter {
    pub(crate) kind: u32,
    pub(crate) id: u32,
    pub(crate) mask: u32,
}

/// What a receiver wants: frames on `ifindex` (0 = every CAN interface)
/// passing any of `filters` (all of them with `join`), and error frames
/// whose class bits meet `err_mask`.
#[repr(C)]
pub(crate) struct RxSpec {
    pub(crate) ifindex: i32,
    pub(crate) join: bool,
    pub(crate) err_mask: u32,
    pub(crate) filters: *const RxFilter,
    pub(crate) nfilters: usize,
}

/// Receive callback. NET_RX softirq context, under `rcu_read_lock`; must
/// not sleep. Called at most once per frame and receiver.
///
/// `skb` is the received frame (`struct can_frame`, `skb->dev` the
/// receiving device, `skb->sk` the sending socket for locally sent frames).
/// With `owned` false it is borrowed: clone it to keep it. With `owned`
/// true the callee owns the reference and must consume or free it (it is
/// then the last receiver, and the skb is not shared). `sk` and `cookie`
/// `owner` and `cookie` are what the receiver registered: its
/// `struct sock` ([`rcan_rx_set`]) or its data ([`rcan_rx_set_kernel`]).
pub(crate) type RxFn = unsafe extern "C" fn(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    cookie: u32,
    owned: bool,
);

extern "C" {
    /// Registers a protocol. Process context. EEXIST if the number is
    /// taken, EINVAL if out of range.
    pub(crate) fn rcan_proto_register(cp: *const CanProto) -> ffi::c_int;
    /// Unregisters a protocol; returns after a grace period, so no socket
    /// creation can still be looking at it. Process context.
    pub(crate) fn rcan_proto_unregister(cp: *const CanProto);
    /// Sets (replaces) the receiver of (`func`, `sk`): `spec` NULL, or a
    /// spec with neither filters nor error mask, removes it. The receiver
    /// holds a reference on `sk` (`sock_hold`), dropped after an RCU grace
    /// period once the receiver is removed, so `func` may run for a removed
    /// receiver until then, and the sock stays valid while it does.
    /// Process context; may sleep. On error (ENOMEM, EINVAL for a bad
    /// filter) the previous receiver stays; removal never fails.
    pub(crate) fn rcan_rx_set(
        func: RxFn,
        sk: *mut bindings::sock,
        cookie: u32,
        spec: *const RxSpec,
    ) -> ffi::c_int;
    /// Like [`rcan_rx_set`], for a receiver inside the kernel that has no
    /// socket: `data` is passed to `func` as its `owner`. No reference is
    /// taken; instead a call that removes or replaces the receiver returns
    /// only after every running callback with the old registration has
    /// finished, so the caller may free `data` then. Process context.
    pub(crate) fn rcan_rx_set_kernel(
        func: RxFn,
        data: *mut ffi::c_void,
        cookie: u32,
        spec: *const RxSpec,
    ) -> ffi::c_int;
    /// Sends one CAN frame (mainline `can_send`): `skb` holds a
    /// `struct can_frame`, `skb->dev` is the device (the caller holds a
    /// reference until this returns), `skb->sk` the sending socket. With
    /// `loopback` the frame is also delivered to local receivers (by the
    /// driver if the device has IFF_ECHO, else by a clone made here).
    /// Always consumes `skb`. Returns 0, or EINVAL (not a classic frame),
    /// EMSGSIZE, EPERM (not a CAN device), ENETDOWN, ENOBUFS (queue full),
    /// ENOMEM. Process or softirq context.
    pub(crate) fn rcan_send(skb: *mut bindings::sk_buff, loopback: bool) -> ffi::c_int;
}

/// Safe wrapper of [`rcan_rx_set`]: sets the receiver (`func`, `sk`) to
/// frames on `ifindex` passing `filters` (all of them with `join`) and
/// error frames meeting `err_mask`. Process context; may sleep.
pub(crate) fn rx_set<T: crate::glue::sock::Proto>(
    func: RxFn,
    sk: &crate::glue::sock::Sock<T>,
    cookie: u32,
    ifindex: i32,
    filters: &[RxFilter],
    join: bool,
    err_mask: u32,
) -> kernel::error::Result {
    let spec = RxSpec {
        ifindex,
        join,
        err_mask,
        filters: filters.as_ptr(),
        nfilters: filters.len(),
    };
    // SAFETY: `spec` and the filters it points to live for the call; `sk`
    // is a live sock (Sock invariant), on which pf_can takes its own
    // reference for as long as it keeps the receiver.
    crate::glue::to_result(unsafe { rcan_rx_set(func, sk.as_ptr(), cookie, &spec) }).map(|_| ())
}

/// Safe wrapper of [`rcan_rx_set`] with no spec: removes the receiver
/// (`func`, `sk`), if any. Never fails. Process context; may sleep.
pub(crate) fn rx_remove<T: crate::glue::sock::Proto>(func: RxFn, sk: &crate::glue::sock::Sock<T>) {
    // SAFETY: removal of a receiver; `sk` is a live sock (Sock invariant).
    unsafe { rcan_rx_set(func, sk.as_ptr(), 0, core::ptr::null()) };
}

/// Safe wrapper of [`rcan_send`]: sends the CAN frame in `skb` on `dev`
/// (sets `skb->dev`); `dev`'s reference covers the call. Consumes `skb`.
pub(crate) fn send(
    mut skb: crate::glue::skb::Skb,
    dev: &crate::glue::netdev::DevRef,
    loopback: bool,
) -> kernel::error::Result {
    skb.set_can(dev, bindings::PACKET_HOST as u8);
    // SAFETY: rcan_send consumes the skb in every case; skb->dev is `dev`,
    // whose reference the caller holds until after the call returns.
    crate::glue::to_result(unsafe { rcan_send(skb.into_raw(), loopback) }).map(|_| ())
}
