// SPDX-License-Identifier: GPL-2.0

//! The C ABI between `rcan_pf` and the modules above and below it: the
//! `#[repr(C)]` structs, function-pointer types and `extern "C"`
//! declarations of the functions `rcan_pf` exports (defined in
//! `family.rs`, which only `pf_can_mod.rs` compiles, exported by
//! `pf_can_c.c`).
//!
//! Nothing outside `rust/glue/can/` uses this file: protocols and drivers
//! see the typed API of [`super::proto`] instead. It is C only because the
//! modules are separate crates linked by the kernel's module loader, which
//! checks nothing but symbol names: an installed `rcan_pf` and a module
//! built from another tree would link and disagree on these structs. So
//! the ABI is versioned: [`ABI`] is a version of its meaning
//! ([`ABI_VERSION`]) and a hash of the layout of every struct that crosses
//! ([`ABI_LAYOUT`]); `rcan_pf` exports its own ([`rcan_pf_abi`]) and every
//! module compares it with the one it was built with before it registers
//! anything with `rcan_pf` ([`check`]).
#![allow(dead_code, improper_ctypes)]

use crate::glue::bindings;
use kernel::ffi;

/// Size of the protocol table (`CANPROTO_MAX` in `<linux/can/rcan.h>`).
pub(crate) const CANPROTO_MAX: usize = 24;

/// The version of the ABI's meaning: bump it when an entry point's
/// contract changes while every layout stays the same (layout changes
/// change [`ABI_LAYOUT`] by themselves). `--cfg rcan_abi_skew` (the
/// test-only module `rcan_abiskew`, never installed) claims the next
/// version, as a module built from another tree would.
pub(crate) const ABI_VERSION: u32 = if cfg!(rcan_abi_skew) { BASE_ABI_VERSION + 1 } else { BASE_ABI_VERSION };
/// This tree's [`ABI_VERSION`].
///
/// 2: `rcan_rx_set_kernel` takes the receiver's namespace.
const BASE_ABI_VERSION: u32 = 2;

/// FNV-1a (32 bits) over the size, alignment and field offsets of every
/// struct that crosses between the modules, the size of their pointers
/// and `bool`, and [`CANPROTO_MAX`]. [`TableFilter`] is an enum, whose
/// field offsets stable Rust cannot name: its size and alignment count,
/// and a change of its meaning bumps [`ABI_VERSION`].
pub(crate) const ABI_LAYOUT: u32 = {
    use core::mem::{align_of, offset_of, size_of};
    fnv1a(&[
        CANPROTO_MAX,
        size_of::<bool>(),
        size_of::<RxFn>(),
        size_of::<ListenFn>(),
        size_of::<CreateFn>(),
        size_of::<CanProto>(),
        align_of::<CanProto>(),
        offset_of!(CanProto, protocol),
        offset_of!(CanProto, type_),
        offset_of!(CanProto, owner),
        offset_of!(CanProto, create),
        size_of::<RxFilter>(),
        align_of::<RxFilter>(),
        offset_of!(RxFilter, kind),
        offset_of!(RxFilter, id),
        offset_of!(RxFilter, mask),
        size_of::<RxSpec>(),
        align_of::<RxSpec>(),
        offset_of!(RxSpec, ifindex),
        offset_of!(RxSpec, join),
        offset_of!(RxSpec, err_mask),
        offset_of!(RxSpec, filters),
        offset_of!(RxSpec, nfilters),
        size_of::<TableFilter>(),
        align_of::<TableFilter>(),
        size_of::<RxTableSpec>(),
        align_of::<RxTableSpec>(),
        offset_of!(RxTableSpec, ifindex),
        offset_of!(RxTableSpec, join),
        offset_of!(RxTableSpec, err_mask),
        offset_of!(RxTableSpec, filters),
        offset_of!(RxTableSpec, nfilters),
    ])
};

/// The ABI this module was built with: [`ABI_VERSION`] in the high 32
/// bits, [`ABI_LAYOUT`] in the low 32; what [`rcan_pf_abi`] returns in
/// `rcan_pf`.
pub(crate) const ABI: u64 = ((ABI_VERSION as u64) << 32) | ABI_LAYOUT as u64;

/// FNV-1a of `parts`, each as 8 little-endian bytes (the same on every
/// architecture, whatever its `usize`).
const fn fnv1a(parts: &[usize]) -> u32 {
    let mut h: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < parts.len() {
        let mut v = parts[i] as u64;
        let mut b = 0;
        while b < 8 {
            h ^= (v & 0xff) as u32;
            h = h.wrapping_mul(0x0100_0193);
            v >>= 8;
            b += 1;
        }
        i += 1;
    }
    h
}

/// Compares `rcan_pf`'s ABI with this module's; on a mismatch logs both
/// (the log prefix names this module) and fails with ENOEXEC, as the
/// module loader does for a module it cannot use. Every module calls it
/// before it registers anything with `rcan_pf`; cheap (one call), so the
/// registrations themselves call it. Process context.
pub(crate) fn check() -> kernel::error::Result {
    // SAFETY: takes nothing, returns a constant of `rcan_pf`.
    let theirs = unsafe { rcan_pf_abi() };
    if theirs == ABI {
        return Ok(());
    }
    kernel::pr_err!(
        "rcan ABI mismatch: this module has ABI {} (layout {:#010x}), rcan_pf has ABI {} (layout {:#010x}); build and install both from one tree\n",
        ABI_VERSION,
        ABI_LAYOUT,
        theirs >> 32,
        theirs & 0xffff_ffff
    );
    Err(kernel::error::code::ENOEXEC)
}

/// A CAN protocol (thesis `struct can_proto`, 5.3.1). Lives in a static of
/// the protocol's module (inside its [`super::proto::ProtoModule`]);
/// `owner` is that module.
#[repr(C)]
pub(crate) struct CanProto {
    pub(crate) protocol: ffi::c_int,
    /// SOCK_RAW, SOCK_DGRAM, ...: socket() with another type gets EPROTOTYPE.
    pub(crate) type_: ffi::c_int,
    pub(crate) owner: *mut bindings::module,
    /// Initialises a new socket. Process context; may sleep. Called with a
    /// reference held on `owner`.
    pub(crate) create: CreateFn,
}

/// `net_proto_family.create` / [`CanProto::create`].
pub(crate) type CreateFn = unsafe extern "C" fn(
    net: *mut bindings::net,
    sock: *mut bindings::socket,
    protocol: ffi::c_int,
    kern: ffi::c_int,
) -> ffi::c_int;

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

/// A filter in the receive table's own form (`rcan_core::rxtable::Filter`,
/// `#[repr(C)]`): what [`RxTableSpec`] carries and [`rcan_rx_filters`]
/// returns. Every module compiles the same `rcan_core` source, so the
/// layout is the same on both sides; a protocol converts its filters into
/// it once, when they are set, and pf_can takes them as they are.
pub(crate) use crate::rcan_core::rxtable::Filter as TableFilter;

/// [`RxSpec`] with the filters in the table's own form, for
/// [`rcan_rx_set_reserved`] (a socket's bind and filter changes): pf_can
/// neither converts nor checks them. `err_mask` holds the error classes
/// wanted, those of error filters included (pf_can cuts it to
/// `CAN_ERR_MASK`).
#[repr(C)]
pub(crate) struct RxTableSpec {
    pub(crate) ifindex: i32,
    pub(crate) join: bool,
    pub(crate) err_mask: u32,
    pub(crate) filters: *const TableFilter,
    pub(crate) nfilters: usize,
}

/// Receive callback. NET_RX softirq context (pf_can's ETH_P_CAN packet
/// handler), under `rcu_read_lock`; must not sleep. Called at most once
/// per frame and receiver.
///
/// `skb` is the received frame. With `owned` false it is borrowed for the
/// call; with `owned` true the callee owns the reference, the only one
/// (`!skb_shared`: an [`OwnedSkb`](crate::glue::skb::OwnedSkb); it is then
/// the last receiver). Either way `skb->dev` is the receiving device,
/// alive for the call. `owner` and `cookie` are
/// what the receiver registered: its `struct sock` ([`rcan_rx_set`]) or
/// its data ([`rcan_rx_set_kernel`]). The typed side of this is
/// [`super::proto::RxSkb`]: the flag never leaves the glue.
pub(crate) type RxFn = unsafe extern "C" fn(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    cookie: u32,
    owned: bool,
);

/// Called after every change of the filters wanted on the listener's
/// interface (process context, under pf_can's `rcan_pf_mutex`: may not
/// sleep for long; must not call back into the registry functions).
pub(crate) type ListenFn = unsafe extern "C" fn(data: *mut ffi::c_void);

extern "C" {
    /// `rcan_pf`'s [`ABI`] (see [`check`]). Any context.
    pub(crate) fn rcan_pf_abi() -> u64;
    /// Adds (`add`) or removes the listener (`func`, `data`), called after
    /// every change of the filters that apply to the device `data` (a
    /// registered `net_device`, until the listener is removed): changes on
    /// its interface index at the time of the change (a move to another
    /// namespace may change it; `ifindex` is its index when added, kept
    /// for the record), or on every interface, in any namespace (a call
    /// too many only recomputes a filter). Removal returns only after any
    /// running call has finished. Process context. ENOMEM.
    pub(crate) fn rcan_rx_listen(
        func: ListenFn,
        data: *mut ffi::c_void,
        ifindex: i32,
        add: bool,
    ) -> ffi::c_int;
    /// Copies into `out` (room for `cap`) every filter that applies to
    /// frames received on `dev` (a valid device, in the namespace it is
    /// in now); returns how many, or -1 if there are more than `cap` (then
    /// a driver must not filter). Any context.
    pub(crate) fn rcan_rx_filters(
        dev: *const bindings::net_device,
        out: *mut TableFilter,
        cap: usize,
    ) -> isize;
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
    /// filter) the previous receiver stays; removal never fails. The
    /// receiver is in the receive table of `sk`'s namespace: `ifindex`
    /// names a device of it, 0 every CAN device of it.
    pub(crate) fn rcan_rx_set(
        func: RxFn,
        sk: *mut bindings::sock,
        cookie: u32,
        spec: *const RxSpec,
    ) -> ffi::c_int;
    /// Makes the receiver of (`func`, `sk`) ahead of its first
    /// registration (at `socket()`), so that one allocates nothing, and
    /// returns it, for [`rcan_rx_set_reserved`]. It holds a reference on
    /// `sk` as a registration does, receives nothing until set, and stays
    /// until removed for good (`rcan_rx_set_reserved` with NULL spec and
    /// `keep` false; `rcan_rx_set` with NULL spec only retires its
    /// registration): the caller must remove it before the socket can be
    /// freed (in `release`). Process
    /// context; may sleep. NULL on ENOMEM (then nothing is reserved: the
    /// first `rcan_rx_set` allocates as without reservation).
    pub(crate) fn rcan_rx_reserve(func: RxFn, sk: *mut bindings::sock) -> *mut ffi::c_void;
    /// [`rcan_rx_set`] for the receiver `rcv` that [`rcan_rx_reserve`]
    /// returned, found without a lookup, in the table it was reserved in
    /// (its socket's namespace's): `spec` (with `cookie`, filters in the
    /// table's form) replaces its registration; NULL, or a spec that wants
    /// nothing, retires it, and then the receiver stays reserved if
    /// `keep`, else it is removed for good (after which `rcv` must not be
    /// used again). The caller serialises its calls for one receiver (its
    /// socket's lock) and passes a `rcv` not yet removed for good.
    /// Process context; may sleep. ENOMEM; removal never fails.
    pub(crate) fn rcan_rx_set_reserved(
        rcv: *mut ffi::c_void,
        cookie: u32,
        spec: *const RxTableSpec,
        keep: bool,
    ) -> ffi::c_int;
    /// Like [`rcan_rx_set`], for a receiver inside the kernel that has no
    /// socket: `data` is passed to `func` as its `owner`. No reference is
    /// taken; instead every call returns only after every running callback
    /// with a registration it replaced or removed has finished, so the
    /// caller may free `data` (or unload) then. Process context. The
    /// receiver sees the devices of namespace `net` (NULL: the initial
    /// one), which the caller keeps alive until the registration is
    /// removed; a removal names the namespace the registration was made
    /// in.
    pub(crate) fn rcan_rx_set_kernel(
        func: RxFn,
        data: *mut ffi::c_void,
        cookie: u32,
        net: *mut bindings::net,
        spec: *const RxSpec,
    ) -> ffi::c_int;
    /// Sends one CAN frame (mainline `can_send`): `skb` holds a
    /// `struct can_frame` or a `struct canfd_frame` (then `CANFD_FDF` is
    /// set in it: the caller gives away a
    /// [`UniqueSkb`](crate::glue::skb::UniqueSkb), neither shared nor
    /// cloned),
    /// `skb->dev` is the device (the caller holds a
    /// reference until this returns), `skb->sk` the sending socket. With
    /// `loopback` the frame is also delivered to local receivers (by the
    /// driver if the device has IFF_ECHO, else by a clone made here).
    /// Always consumes `skb`. Returns 0, or EINVAL (neither a classic nor
    /// an FD frame), EMSGSIZE (an FD frame on a classic device), EPERM (not a CAN device), ENETDOWN, ENOBUFS (queue full),
    /// ENOMEM. Process or softirq context.
    pub(crate) fn rcan_send(skb: *mut bindings::sk_buff, loopback: bool) -> ffi::c_int;
}
