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

/// Receive callback. NET_RX softirq context (pf_can's ETH_P_CAN packet
/// handler: every frame, bus frames and echoes alike, comes up through
/// the network core's receive path), under `rcu_read_lock`; must not
/// sleep. It may transmit, on any device including the receiving one
/// ([`rcan_send`], e.g. a gateway or a protocol's acknowledgement): no
/// device lock is held. Called at most once per frame and receiver.
///
/// `skb` is the received frame (`struct can_frame`, `skb->dev` the
/// receiving device, `skb->pkt_type` PACKET_BROADCAST, `skb->sk` the
/// sending socket for an echo of a frame a local socket sent, NULL for
/// frames from the bus and for frames the kernel sent without a socket).
/// With `owned` false it is borrowed: clone it to keep it. With `owned`
/// true the callee owns the reference and must consume or free it (it is
/// then the last receiver, and the skb is not shared). `owner` and
/// `cookie` are what the receiver registered: its `struct sock`
/// ([`rcan_rx_set`]) or its data ([`rcan_rx_set_kernel`]).
pub(crate) type RxFn = unsafe extern "C" fn(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    cookie: u32,
    owned: bool,
);

/// Called after every change of the filters wanted on the listener's
/// interface (process context, under pf_can's `WRITERS` mutex: may not
/// sleep for long; must not call back into the registry functions).
pub(crate) type ListenFn = unsafe extern "C" fn(data: *mut ffi::c_void);

extern "C" {
    /// Adds (`add`) or removes the listener (`func`, `data`), called after
    /// every change of the filters that apply to interface `ifindex`
    /// (registrations on it or on every interface). Removal returns only
    /// after any running call has finished. Process context. ENOMEM.
    pub(crate) fn rcan_rx_listen(
        func: ListenFn,
        data: *mut ffi::c_void,
        ifindex: i32,
        add: bool,
    ) -> ffi::c_int;
    /// Copies into `out` (room for `cap`) every filter that applies to
    /// frames received on `ifindex`; returns how many, or -1 if there are
    /// more than `cap` (then a driver must not filter). Any context.
    pub(crate) fn rcan_rx_filters(
        ifindex: i32,
        out: *mut crate::rcan_core::rxtable::Filter,
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
    skb.set_dev(dev);
    // SAFETY: rcan_send consumes the skb in every case; skb->dev is `dev`,
    // whose reference the caller holds until after the call returns.
    crate::glue::to_result(unsafe { rcan_send(skb.into_raw(), loopback) }).map(|_| ())
}

/// A receiver inside the kernel (no socket), registered with
/// [`rx_set_kernel`]. `rx` runs in NET_RX softirq under RCU for every
/// matching frame, with the skb borrowed and its receiving device, both
/// valid for the call; it must not sleep, and may transmit (see
/// [`RxFn`]).
pub(crate) trait KernelRx: Sync + 'static {
    fn rx(&self, skb: &crate::glue::skb::Skb, dev: &crate::glue::netdev::NetDev);
}

/// The [`RxFn`] of a [`KernelRx`].
///
/// # Safety
///
/// Called by pf_can's dispatcher as [`RxFn`] says, with the `owner` that
/// [`rx_set_kernel`] registered: a `&'static T`.
unsafe extern "C" fn kernel_rx<T: KernelRx>(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    _cookie: u32,
    owned: bool,
) {
    // SAFETY: a valid skb, our reference if `owned`, else borrowed for the
    // call (RxFn contract); ManuallyDrop keeps a borrowed one unfreed.
    let Some(skb) = (unsafe { crate::glue::skb::Skb::from_raw(skb) }) else {
        return;
    };
    let skb = core::mem::ManuallyDrop::new(skb);
    // CAST: `owner` is the `&'static T` that rx_set_kernel registered.
    let rx = owner as *const T;
    // SAFETY: that static outlives the registration, and removing the
    // registration waits for running callbacks (rcan_rx_set_kernel).
    let rx = unsafe { &*rx };
    // SAFETY: the receive path holds the receiving device for the call.
    if let Some(dev) = unsafe { skb.dev() } {
        rx.rx(&skb, dev);
    }
    if owned {
        core::mem::ManuallyDrop::into_inner(skb).consume();
    }
}

/// A registered [`KernelRx`]; dropping it removes the receiver and waits
/// for running callbacks (process context; sleeps).
pub(crate) struct KernelRxReg<T: KernelRx>(&'static T);

impl<T: KernelRx> Drop for KernelRxReg<T> {
    fn drop(&mut self) {
        // SAFETY: removal (NULL spec) of the receiver registered with this
        // func and data; never fails.
        unsafe {
            rcan_rx_set_kernel(
                kernel_rx::<T>,
                self.0 as *const T as *mut ffi::c_void,
                0,
                core::ptr::null(),
            )
        };
    }
}

/// Safe wrapper of [`rcan_rx_set_kernel`]: registers `rx` for frames on
/// `ifindex` (0: every CAN interface) passing any of `filters` (at least
/// one). The registration lasts until the returned guard is dropped.
/// Process context; may sleep.
pub(crate) fn rx_set_kernel<T: KernelRx>(
    rx: &'static T,
    ifindex: i32,
    filters: &[RxFilter],
) -> kernel::error::Result<KernelRxReg<T>> {
    if filters.is_empty() {
        return Err(kernel::error::code::EINVAL);
    }
    let spec = RxSpec {
        ifindex,
        join: false,
        err_mask: 0,
        filters: filters.as_ptr(),
        nfilters: filters.len(),
    };
    // `rx` is 'static: a static of the calling module, which keeps the
    // guard in its module object, so the registration is removed at module
    // exit at the latest.
    let data = rx as *const T as *mut ffi::c_void;
    // SAFETY: `spec` and its filters live for the call; `data` is 'static.
    let ret = unsafe { rcan_rx_set_kernel(kernel_rx::<T>, data, 0, &spec) };
    crate::glue::to_result(ret).map(|_| KernelRxReg(rx))
}

/// A driver whose hardware filter follows the sockets (DESIGN decision 7).
pub(crate) trait FilterListener: crate::glue::netdev::Driver {
    /// The filters wanted on this device's interface changed. Process
    /// context, may not sleep for long (pf_can's writers' mutex is held).
    fn filters_changed(dev: &crate::glue::netdev::Dev<Self>, priv_: &Self::Priv);
}

unsafe extern "C" fn listen_trampoline<T: FilterListener>(data: *mut ffi::c_void) {
    // SAFETY: `data` is the device of a live Registration<T>: the
    // Listening guard that registered it removes it (waiting for a running
    // call) before that registration can be dropped.
    let (dev, p) = unsafe { crate::glue::netdev::from_cookie::<T>(data.cast()) };
    T::filters_changed(dev, p);
}

/// Calls `T::filters_changed` for one device whenever the receive table
/// changes; stops when dropped. Must be dropped before the device's
/// Registration (declare it after the registration in a struct, or drop it
/// explicitly).
pub(crate) struct Listening<T: FilterListener> {
    dev: *mut bindings::net_device,
    ifindex: i32,
    _t: core::marker::PhantomData<T>,
}

// SAFETY: only used to unregister the listener, from any thread.
unsafe impl<T: FilterListener> Send for Listening<T> {}
// SAFETY: no shared access.
unsafe impl<T: FilterListener> Sync for Listening<T> {}

impl<T: FilterListener> Listening<T> {
    /// Starts listening for `reg`'s device. Process context.
    pub(crate) fn new(reg: &crate::glue::netdev::Registration<T>) -> kernel::error::Result<Self> {
        let dev = reg.dev().as_ptr();
        let ifindex = reg.dev().ifindex();
        // SAFETY: the trampoline's cookie is the registered device; the
        // registration outlives this guard (documented contract), whose
        // Drop removes the listener.
        crate::glue::to_result(unsafe {
            rcan_rx_listen(listen_trampoline::<T>, dev.cast(), ifindex, true)
        })?;
        Ok(Listening {
            dev,
            ifindex,
            _t: core::marker::PhantomData,
        })
    }
}

impl<T: FilterListener> Drop for Listening<T> {
    fn drop(&mut self) {
        // SAFETY: removal of the listener added in new(); returns after a
        // running call finished.
        unsafe { rcan_rx_listen(listen_trampoline::<T>, self.dev.cast(), self.ifindex, false) };
    }
}

/// Safe wrapper of [`rcan_rx_filters`]: the filters that apply to frames
/// received on `ifindex`, in `out`; `None` if there are more than fit.
/// Any context.
pub(crate) fn rx_filters(
    ifindex: i32,
    out: &mut [crate::rcan_core::rxtable::Filter],
) -> Option<usize> {
    // SAFETY: `out` has room for `out.len()` filters.
    let n = unsafe { rcan_rx_filters(ifindex, out.as_mut_ptr(), out.len()) };
    usize::try_from(n).ok()
}

/// Most filters [`wanted`] takes into account; with more, a driver's
/// hardware filter stays open (sound, just not tight). Stack use in atomic
/// context bounds it.
pub(crate) const MAX_WANTED: usize = 24;

/// What the sockets bound to `dev` (or to every interface) want, as
/// [`Wanted`](crate::rcan_core::sja1000::Wanted) sets handed to `derive`,
/// which computes a driver's hardware filter from them. `None` when the
/// hardware filter must be open: `dev` is promiscuous, or more than
/// [`MAX_WANTED`] filters apply. Any context.
pub(crate) fn wanted<T>(
    dev: &crate::glue::netdev::NetDev,
    derive: impl FnOnce(&[crate::rcan_core::sja1000::Wanted]) -> T,
) -> Option<T> {
    use crate::rcan_core::{rxtable::Filter, sja1000::Wanted};
    if dev.is_promisc() {
        return None;
    }
    let mut fs = [Filter::Id {
        id: 0,
        mask: 0,
        inv: false,
    }; MAX_WANTED];
    let n = rx_filters(dev.ifindex(), &mut fs)?;
    let mut w = [Wanted::ALL; MAX_WANTED];
    for (o, f) in w.iter_mut().zip(&fs[..n]) {
        *o = Wanted::of(f);
    }
    Some(derive(&w[..n]))
}

/// Netdevice notifier callback (`notifier_block.notifier_call`).
pub(crate) type NotifierFn = unsafe extern "C" fn(
    nb: *mut bindings::notifier_block,
    event: ffi::c_ulong,
    info: *mut ffi::c_void,
) -> ffi::c_int;

/// A set of socket addresses (`*mut sock` as `usize`): the open sockets of
/// a protocol module, for its netdevice notifier. Insertion and removal are
/// O(1) on average (hashed buckets), so closing one of n sockets does not
/// scan the other n - 1. The owner names its lock (RTNL in
/// [`ProtoModule`]).
pub(crate) struct SockSet {
    /// `SOCKSET_BUCKETS` vectors once the first socket arrives.
    buckets: kernel::alloc::KVec<kernel::alloc::KVec<usize>>,
}

const SOCKSET_BUCKETS: usize = 512;

impl SockSet {
    pub(crate) const fn new() -> Self {
        SockSet {
            buckets: kernel::alloc::KVec::new(),
        }
    }

    fn bucket(p: usize) -> usize {
        // Socks are cache-line aligned: drop the low bits, then a
        // multiplicative hash.
        (((p >> 6) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            >> (64 - SOCKSET_BUCKETS.trailing_zeros())) as usize
    }

    /// Adds `p`. Process context (allocates). ENOMEM.
    pub(crate) fn insert(&mut self, p: usize) -> kernel::error::Result {
        use kernel::alloc::{flags::GFP_KERNEL, KVec};
        if self.buckets.is_empty() {
            let mut b = KVec::with_capacity(SOCKSET_BUCKETS, GFP_KERNEL)?;
            for _ in 0..SOCKSET_BUCKETS {
                b.push(KVec::new(), GFP_KERNEL)?;
            }
            self.buckets = b;
        }
        self.buckets[Self::bucket(p)].push(p, GFP_KERNEL)?;
        Ok(())
    }

    /// Removes `p` if present.
    pub(crate) fn remove(&mut self, p: usize) {
        if let Some(b) = self.buckets.get_mut(Self::bucket(p)) {
            crate::glue::kvec_remove_all(b, p);
        }
    }

    /// Every member, in no particular order.
    pub(crate) fn iter(&self) -> impl Iterator<Item = &usize> {
        self.buckets.iter().flat_map(|b| b.iter())
    }
}

/// Everything a CAN protocol module registers, in one static: its
/// `struct proto` (sock allocator), its entry in pf_can's protocol table
/// and its netdevice notifier. [`ProtoModule::register`] in module init,
/// [`ProtoModule::unregister`] in module exit.
pub(crate) struct ProtoModule<T: crate::glue::sock::Proto> {
    /// The sock allocator, used by [`ProtoModule::create_socket`].
    pub(crate) proto: crate::glue::sock::ProtoReg<T>,
    /// Every open socket (as `*mut sock` addresses), for the netdevice
    /// notifier. Protected by RTNL; a socket is listed from
    /// `create_socket` until its `release` removes it.
    pub(crate) sockets: crate::glue::sync::RtnlLocked<SockSet>,
    canproto: crate::glue::sync::CCell<CanProto>,
    notifier: crate::glue::sync::CCell<bindings::notifier_block>,
}

impl<T: crate::glue::sock::Proto> ProtoModule<T> {
    /// Protocol `protocol` of socket type `type_` (SOCK_RAW, ...), whose
    /// sockets `create` makes and whose devices `notifier` watches.
    pub(crate) const fn new(
        protocol: i32,
        type_: i32,
        create: unsafe extern "C" fn(
            net: *mut bindings::net,
            sock: *mut bindings::socket,
            protocol: ffi::c_int,
            kern: ffi::c_int,
        ) -> ffi::c_int,
        notifier: NotifierFn,
    ) -> Self {
        ProtoModule {
            proto: crate::glue::sock::ProtoReg::new(),
            sockets: crate::glue::sync::RtnlLocked::new(SockSet::new()),
            canproto: crate::glue::sync::CCell::new(CanProto {
                protocol,
                type_,
                owner: core::ptr::null_mut(),
                create,
            }),
            notifier: crate::glue::sync::CCell::new(bindings::notifier_block {
                notifier_call: Some(notifier),
                next: core::ptr::null_mut(),
                priority: 0,
            }),
        }
    }

    /// Registers the proto, the notifier and the protocol, in that order;
    /// undoes what was done on failure. Module init only.
    pub(crate) fn register(&self, name: &'static kernel::str::CStr) -> kernel::error::Result {
        self.proto.register(name, bindings::PF_CAN as i32)?;
        // SAFETY: module init: nothing else sees the CanProto yet.
        unsafe { (*self.canproto.get()).owner = crate::glue::this_module() };
        // SAFETY: a static notifier, unregistered in `unregister`.
        let ret = unsafe { bindings::register_netdevice_notifier(self.notifier.get()) };
        if let Err(e) = crate::glue::to_result(ret) {
            self.proto.unregister();
            return Err(e);
        }
        // SAFETY: a static CanProto, unregistered in `unregister`.
        if let Err(e) = crate::glue::to_result(unsafe { rcan_proto_register(self.canproto.get()) })
        {
            // SAFETY: registered just above.
            unsafe { bindings::unregister_netdevice_notifier(self.notifier.get()) };
            self.proto.unregister();
            return Err(e);
        }
        Ok(())
    }

    /// `CanProto.create` of the protocol: allocates the sock and lists it
    /// in `sockets`. Process context.
    ///
    /// # Safety
    ///
    /// The arguments are those of pf_can's `create` call (socket layer).
    pub(crate) unsafe fn create_socket(
        &self,
        net: *mut bindings::net,
        sock: *mut bindings::socket,
        protocol: ffi::c_int,
        kern: ffi::c_int,
    ) -> ffi::c_int {
        // SAFETY: the socket layer's arguments (this function's contract).
        if let Err(e) = unsafe { self.proto.create(net, sock, protocol, kern) } {
            return e.to_errno();
        }
        // SAFETY: create succeeded, so `sock->sk` is our new sock.
        let sk = unsafe { (*sock).sk } as usize;
        let mut rtnl = crate::glue::sync::Rtnl::lock();
        if self.sockets.get(&mut rtnl).insert(sk).is_err() {
            // The socket layer calls release on failure, which copes with
            // a socket missing from the list.
            return kernel::error::code::ENOMEM.to_errno();
        }
        0
    }

    /// Undoes `register`. Module exit only: every socket holds a reference
    /// on the module, so none is left.
    pub(crate) fn unregister(&self) {
        // SAFETY: registered by `register`; rcan_proto_unregister returns
        // after a grace period, so no socket creation still sees it.
        unsafe {
            rcan_proto_unregister(self.canproto.get());
            bindings::unregister_netdevice_notifier(self.notifier.get());
        }
        self.proto.unregister();
        // Statics are never dropped: free the (empty) list's buffer.
        let mut rtnl = crate::glue::sync::Rtnl::lock();
        *self.sockets.get(&mut rtnl) = SockSet::new();
    }
}

// SAFETY: the C structs are written only in `register` (module init) and
// afterwards owned by the kernel's registries.
unsafe impl<T: crate::glue::sock::Proto> Sync for ProtoModule<T> {}
