// SPDX-License-Identifier: GPL-2.0

//! The typed CAN protocol framework: what a protocol module (`raw`,
//! `can_proto`, DSOR) or a driver that follows the receive table sees of
//! `rcan_pf`. No raw pointer, `extern "C"` or `bindings::` item crosses
//! this API; the C ABI underneath is [`super::abi`].
//!
//! A socket protocol:
//!
//! * implements [`sock::Proto`](crate::glue::sock::Proto) (the socket
//!   calls) and [`CanProtocol`] (its number and type, its receive
//!   callback, its reaction to devices going down or away);
//! * keeps a `static` [`ProtoModule`] (sock allocator, entry in pf_can's
//!   protocol table, netdevice notifier, list of open sockets) and
//!   registers it in module init; the module's exit (the glue's) unregisters
//!   everything, whatever becomes of the returned [`ProtoRegistration`];
//! * subscribes a socket to frames with [`rx_set`] and unsubscribes it with
//!   [`rx_remove`] (at the latest in `release`), or, with a
//!   [`CanProtocol::RESERVE_RX`], with [`rx_set_locked`] / [`rx_unset_locked`]
//!   and [`rx_release`] in `release`.
//!
//! The C entry points are generic trampolines here, one source for every
//! protocol: [`create_trampoline`] (`socket()`), [`notifier_trampoline`]
//! (netdevice events), [`rx_trampoline`] (received frames), which turns
//! pf_can's "owned" flag into the type of [`RxSkb`].
//!
//! An in-kernel receiver without a socket (DSOR's engine, the time
//! services) implements [`KernelRx`] and holds a [`KernelRxReg`]; a driver
//! whose hardware filter follows the sockets implements [`FilterListener`]
//! and hands its device's registration to a [`Listening`], which owns it.

use super::abi::{self, CanProto, RxSpec, RxTableSpec, TableFilter};
// Re-exported for the protocols; not every module uses every one.
#[allow(unused_imports)]
pub(crate) use super::abi::{RxFilter, RX_FILTER_ARB, RX_FILTER_CAN_ID};
use crate::glue::bindings;
use crate::glue::module::{ExitList, ExitNode, ExitTable, InScopedModule, ModuleScope, SweepKind};
use crate::glue::net::{Net, NetRef};
use crate::glue::netdev::{self as gnetdev, NetDev};
use crate::glue::skb::{OwnedSkb, Shared, Skb, UniqueSkb};
use crate::glue::sock::{Proto, ProtoReg, SetLink, Sock, SockGuard, SockView};
use crate::glue::sync::{CCell, RcuReadGuard, Rtnl, RtnlLocked};
use crate::rcan_core::rxtable::CanFilterKind;
use core::marker::PhantomData;
use core::mem::ManuallyDrop;
use core::sync::atomic::Ordering;
use kernel::alloc::{flags::GFP_KERNEL, KBox, KVec};
use kernel::sync::Arc;
use kernel::error::{code, Result};
use kernel::ffi;

/// Mainline-compatible raw protocol (SOCK_RAW), `CAN_RAW` in `<linux/can.h>`.
pub(crate) const CAN_RAW: i32 = 1;
/// The thesis' CAN 2.0 data link protocol (SOCK_RAW).
pub(crate) const CANPROTO_CAN: i32 = 16;
/// Socket types a protocol can be registered for.
pub(crate) const SOCK_RAW: i32 = bindings::sock_type_SOCK_RAW as i32;
pub(crate) const SOCK_DGRAM: i32 = bindings::sock_type_SOCK_DGRAM as i32;

/// A received frame as a receive callback gets it, with its receiving
/// device: the receive context.
///
/// pf_can calls each matching receiver once per frame; all but the last
/// get the skb borrowed, the last one gets pf_can's reference when nobody
/// else holds one, so the common single-receiver case queues the skb
/// without cloning it. Either way the frame is read-only here (other
/// receivers, packet taps and, on a device without IFF_ECHO, the driver
/// read the same bytes); what a receiver keeps is an [`OwnedSkb`]
/// ([`RxSkb::into_owned`]), whose own fields (`cb`, timestamp) it may
/// write, never its data. The receiving device is lent for the callback
/// only ([`RxSkb::dev`]): a kept skb does not carry it.
///
/// # Invariants
///
/// Made only by the glue's receive trampolines, for the callback: during
/// `'a`, `skb->dev` is the receiving device, alive (`abi::RxFn`).
pub(crate) struct RxSkb<'a>(RxInner<'a>);

/// The two ways pf_can hands a frame over; private, so that only the glue
/// makes an [`RxSkb`].
enum RxInner<'a> {
    /// Borrowed for the call; clone it to keep it.
    Shared(&'a Skb),
    /// This receiver's own reference, the only one.
    Owned(OwnedSkb, PhantomData<&'a ()>),
}

impl<'a> RxSkb<'a> {
    /// The frame, to look at.
    #[inline]
    pub(crate) fn skb(&self) -> &Skb {
        match &self.0 {
            RxInner::Shared(s) => s,
            RxInner::Owned(s, _) => s.as_shared(),
        }
    }

    /// The device the frame arrived on, lent for the callback (`'a`): the
    /// receive path holds it meanwhile.
    #[inline]
    pub(crate) fn dev(&self) -> Option<&'a NetDev> {
        // SAFETY: during `'a`, `skb->dev` is the receiving device, alive
        // (type invariant: only `rx_trampoline` makes an `RxSkb`, lent to
        // the callback for the call, `abi::RxFn`).
        unsafe { self.skb().dev() }
    }

    /// The index of the device the frame arrived on ([`RxSkb::dev`]; 0 if
    /// none). Read now, in the callback: the device may be gone when a
    /// kept skb is read, so protocols keep the index (in `cb`), as
    /// mainline does.
    #[inline]
    pub(crate) fn ifindex(&self) -> i32 {
        self.dev().map_or(0, NetDev::ifindex)
    }

    /// An skb this receiver owns, to queue: the one handed over, or a
    /// clone (GFP_ATOMIC; `None` if that fails). Its data stays read-only
    /// (a clone shares it). Any context.
    #[inline]
    pub(crate) fn into_owned(self) -> Option<OwnedSkb> {
        match self.0 {
            RxInner::Shared(s) => s.clone_atomic(),
            RxInner::Owned(s, _) => Some(s),
        }
    }

    /// The receiver has used the frame without keeping it: an owned
    /// reference is freed as consumed (not counted as a drop).
    #[inline]
    pub(crate) fn done(self) {
        if let RxInner::Owned(s, _) = self.0 {
            s.consume();
        }
    }
}

/// A socket's reserved receiver ([`CanProtocol::RESERVE_RX`]) is pf_can's
/// handle for it, kept by the glue in the sock object itself
/// (`Sock::rx_slot`), so that no two sockets can share one: stored at
/// `socket()` (before the socket is reachable; after an ENOMEM there, at
/// the first [`rx_set_locked`], under the socket lock) and then read and
/// cleared only under the socket lock (the functions that use it take the
/// lock's guard), so a handle is never used after [`rx_release`] removed
/// its receiver. NULL: no receiver reserved (ENOMEM at `socket()` and no
/// subscription since, or released).

/// A socket's filters in the receive table's own form
/// ([`abi::TableFilter`]), for [`rx_set_locked`]: converted once, when the
/// protocol's filters are set (mainline `struct can_filter`s, as CAN_RAW
/// keeps them), so that a bind or any other re-subscription hands them to
/// pf_can as they are, with nothing to convert or check. One filter is
/// kept inline (a socket's common case allocates nothing).
pub(crate) struct TableFilters {
    frames: TableFrames,
    /// Error classes of the error filters (`can_mask` with `CAN_ERR_FLAG`).
    err_mask: u32,
}

enum TableFrames {
    One(TableFilter),
    /// None or several.
    Many(KVec<TableFilter>),
}

impl TableFilters {
    /// The single mainline filter `can_id`/`can_mask`. Allocates nothing.
    pub(crate) const fn can_filter(can_id: u32, can_mask: u32) -> Self {
        match TableFilter::from_can_filter(can_id, can_mask) {
            CanFilterKind::Frames(f) => TableFilters {
                frames: TableFrames::One(f),
                err_mask: 0,
            },
            CanFilterKind::Errors(m) => TableFilters {
                frames: TableFrames::Many(KVec::new()),
                err_mask: m,
            },
        }
    }

    /// No filter: no frames, no error frames.
    pub(crate) const fn none() -> Self {
        TableFilters {
            frames: TableFrames::Many(KVec::new()),
            err_mask: 0,
        }
    }

    /// The mainline filters `(can_id, can_mask)` of `filters`, each as
    /// [`TableFilters::can_filter`] converts it. Process context (may
    /// allocate). ENOMEM.
    pub(crate) fn can_filters(filters: impl ExactSizeIterator<Item = (u32, u32)>) -> Result<Self> {
        let mut v = KVec::with_capacity(filters.len(), GFP_KERNEL)?;
        let mut err_mask = 0;
        for (can_id, can_mask) in filters {
            match TableFilter::from_can_filter(can_id, can_mask) {
                CanFilterKind::Frames(f) => v.push(f, GFP_KERNEL)?,
                CanFilterKind::Errors(m) => err_mask |= m,
            }
        }
        Ok(TableFilters {
            frames: TableFrames::Many(v),
            err_mask,
        })
    }

    fn frames(&self) -> &[TableFilter] {
        match &self.frames {
            TableFrames::One(f) => core::slice::from_ref(f),
            TableFrames::Many(v) => v,
        }
    }
}

/// A netdevice event a protocol reacts to.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum NetdevEvent {
    /// The device went down (`NETDEV_DOWN`).
    Down,
    /// The device is going away (`NETDEV_UNREGISTER`).
    Unregister,
}

/// A CAN socket protocol (thesis `struct can_proto`, 5.3.1), on top of the
/// socket calls of [`Proto`].
pub(crate) trait CanProtocol: Proto {
    /// Protocol number (`socket(PF_CAN, type, PROTOCOL)`), below
    /// [`CANPROTO_MAX`].
    const PROTOCOL: i32;
    /// Socket type ([`SOCK_RAW`], [`SOCK_DGRAM`]); `socket()` with another
    /// type gets EPROTOTYPE.
    const SOCK_TYPE: i32;

    /// Each socket gets its receiver made at `socket()` time (as mainline
    /// keeps its per-socket receive state in the socket), kept by the
    /// glue in the sock, so the first registration (the bind) allocates
    /// nothing; the protocol subscribes with [`rx_set_locked`] /
    /// [`rx_unset_locked`], which find the receiver without a lookup. It
    /// must call [`rx_release`] in every `release`, bound or not (the
    /// reserved receiver holds a reference on the sock). Default: false
    /// (receivers are made by the first [`rx_set`]).
    const RESERVE_RX: bool = false;

    /// Sockets may be created in every network namespace: the protocol
    /// keeps its state in its sockets and finds devices in the socket's
    /// namespace ([`Sock::net`]). A protocol with state of its own outside
    /// the sockets (DSOR's engine and node) leaves it off, and `socket()`
    /// outside the initial namespace fails with EAFNOSUPPORT. Default: no.
    const ALL_NAMESPACES: bool = false;

    /// The protocol's registrations (a static of its module).
    fn module() -> &'static ProtoModule<Self>;

    /// A frame for socket `sk`, which subscribed with [`rx_set`] (with
    /// `cookie`). NET_RX softirq context, inside pf_can's RCU read-side
    /// section; must not sleep and must not take the socket lock (`sk`
    /// is a [`SockView`], which has no `lock()`). `sk` is
    /// alive for the call (the subscription holds a reference on it), even
    /// if the socket is being closed. May transmit ([`send`]). The default
    /// ignores the frame.
    fn rx(_sk: &SockView<Self>, skb: RxSkb<'_>, _cookie: u32) {
        skb.done();
    }

    /// A network device (any type: check [`NetDev::is_can`]) went down or
    /// is going away (unregistered, or moving to another namespace, which
    /// the kernel announces as an unregistration in the old one). Process
    /// context, RTNL held; may take socket locks (RTNL comes first in the
    /// lock order) and call [`rx_set`] / [`rx_remove`]. `sockets` are the
    /// protocol's open sockets in the device's namespace (mainline's
    /// `net_eq(dev_net(dev), sock_net(sk))` test). The default does
    /// nothing.
    fn netdev_event(_event: NetdevEvent, _dev: &NetDev, _sockets: &Sockets<'_, Self>) {}
}

/// The open sockets of a protocol module, for its netdevice notifier: a
/// doubly linked list through the socks themselves ([`SetLink`], inside
/// each sock object), so a socket joins it at `socket()` and leaves it at
/// `close()` in O(1), without an allocation and without a scan (mainline
/// raw.c keeps its `raw_notifier_list` the same way). Protected by RTNL
/// (in [`ProtoModule::sockets`]).
///
/// # Invariants
///
/// Only [`ProtoModule`] inserts, and only live socks of its protocol;
/// each is removed (under RTNL) before the sock can be freed: by the
/// protocol's `release` if it wants it off early, else by the glue's
/// release trampoline ([`release_trampoline`]) right after it, before
/// the socket's reference goes; the protocol has no duty here. `head`
/// and the links of the socks on the set are the addresses of socks on
/// the set, or 0; a sock's `listed` flag says whether it is on it.
pub(crate) struct SockSet<T: CanProtocol> {
    /// The first sock's address; 0 for an empty set.
    head: usize,
    /// Socks of `T` only: a set cannot be swapped with another protocol's.
    _t: PhantomData<fn() -> T>,
}

impl<T: CanProtocol> SockSet<T> {
    pub(crate) const fn new() -> Self {
        SockSet {
            head: 0,
            _t: PhantomData,
        }
    }

    /// Calls `f` with the set link of the sock at address `p`.
    ///
    /// # Safety
    ///
    /// `p` is the address of a sock on the set, and RTNL is held.
    unsafe fn with_link(p: usize, f: impl FnOnce(&SetLink)) {
        // SAFETY: a sock on the set is a live sock of `T` until its
        // release takes it off, which needs RTNL, held by our caller.
        let sk = unsafe { Sock::<T>::from_raw(p as *mut bindings::sock) };
        f(sk.set_link());
    }

    /// Adds `sk`, a new sock of `T` not on the set. Process context, RTNL
    /// held (`&mut self`). Never fails.
    fn insert(&mut self, sk: &Sock<T>) {
        let me = sk.as_ptr() as usize;
        let l = sk.set_link();
        l.prev.set(0);
        l.next.set(self.head);
        if self.head != 0 {
            // SAFETY: a non-zero head is a sock on the set (type
            // invariant); RTNL is held (`&mut self`).
            unsafe { Self::with_link(self.head, |h| h.prev.set(me)) };
        }
        l.listed.store(true, Ordering::Relaxed);
        // INVARIANT: `sk` is live and stays so until its release removes
        // it; every link above names a sock on the set.
        self.head = me;
    }

    /// Removes socket `sk` if it is on the set (a socket whose creation
    /// failed before it was inserted is not, nor one removed before).
    /// Under RTNL (`&mut self`). O(1). A protocol's `release` may call it
    /// to take its socket off the set before its own teardown (no more
    /// netdevice events for it from then on); otherwise the glue does
    /// it when `release` returns.
    pub(crate) fn remove(&mut self, sk: &Sock<T>) {
        let l = sk.set_link();
        if !l.listed.load(Ordering::Relaxed) {
            return;
        }
        let (prev, next) = (l.prev.get(), l.next.get());
        if prev != 0 {
            // SAFETY: `sk` is on the set (checked above), so its non-zero
            // neighbours are too (type invariant); RTNL is held (`&mut
            // self`).
            unsafe { Self::with_link(prev, |p| p.next.set(next)) };
        } else {
            self.head = next;
        }
        if next != 0 {
            // SAFETY: as for `prev`.
            unsafe { Self::with_link(next, |n| n.prev.set(prev)) };
        }
        l.prev.set(0);
        l.next.set(0);
        l.listed.store(false, Ordering::Relaxed);
    }
}

/// The open sockets of protocol `T` in one namespace, as its netdevice
/// notifier sees them (RTNL held for `'a`).
pub(crate) struct Sockets<'a, T: CanProtocol> {
    set: &'a SockSet<T>,
    /// The device's namespace, compared, never dereferenced: it cannot
    /// change while RTNL is held.
    net: *const bindings::net,
    _t: PhantomData<T>,
}

impl<T: CanProtocol> Sockets<'_, T> {
    /// Calls `f` for every open socket of the namespace, in no particular
    /// order. The sockets stay alive during the call: `release` needs RTNL
    /// to leave the set.
    pub(crate) fn for_each(&self, mut f: impl FnMut(&Sock<T>)) {
        let mut p = self.set.head;
        while p != 0 {
            // The borrow handed to `f` cannot outlive this call.
            // SAFETY: the set holds only live socks of `T` until their
            // release removes them under RTNL, which our caller holds for
            // 'a (SockSet invariant).
            let sk = unsafe { Sock::<T>::from_raw(p as *mut bindings::sock) };
            // Read before `f`, which cannot take a sock off the set
            // anyway (that needs a release, under the RTNL held here).
            p = sk.set_link().next.get();
            if core::ptr::eq(sk.net().as_ptr(), self.net) {
                f(&sk);
            }
        }
    }
}

/// Everything a CAN protocol module registers, in one static: its
/// `struct proto` (sock allocator), its entry in pf_can's protocol table
/// and its netdevice notifier, plus the list of its open sockets.
/// [`ProtoModule::register`] in module init; unregistered by the module's
/// exit only.
pub(crate) struct ProtoModule<T: CanProtocol> {
    proto: ProtoReg<T>,
    /// Every open socket, for the netdevice notifier. Protected by RTNL;
    /// a socket is listed from its creation until its `release` removes it
    /// ([`SockSet::remove`]).
    pub(crate) sockets: RtnlLocked<SockSet<T>>,
    canproto: CCell<CanProto>,
    notifier: CCell<bindings::notifier_block>,
}

// SAFETY: the C structs are written only in `register` (module init,
// before the kernel can see them) and afterwards owned by the kernel's
// registries; `sockets` is RTNL-protected (RtnlLocked).
unsafe impl<T: CanProtocol> Sync for ProtoModule<T> {}

impl<T: CanProtocol> ProtoModule<T> {
    /// The registrations of protocol `T`, not yet registered.
    pub(crate) const fn new() -> Self {
        ProtoModule {
            proto: ProtoReg::new(),
            sockets: RtnlLocked::new(SockSet::new()),
            canproto: CCell::new(CanProto {
                protocol: T::PROTOCOL,
                type_: T::SOCK_TYPE,
                owner: core::ptr::null_mut(),
                create: create_trampoline::<T>,
            }),
            notifier: CCell::new(bindings::notifier_block {
                notifier_call: Some(notifier_trampoline::<T>),
                next: core::ptr::null_mut(),
                priority: 0,
            }),
        }
    }

    /// Registers the proto, the notifier and the protocol, in that order;
    /// undoes what was done on failure. Module init (process context):
    /// the `scope` proves the module's exit is the glue's, which alone
    /// unregisters the protocol (the returned [`ProtoRegistration`] is a
    /// proof, not a guard). EBUSY if already registered, ENOSPC with more
    /// than `MAX_PROTOS` protocols in one module.
    pub(crate) fn register(
        &'static self,
        name: &'static kernel::str::CStr,
        _scope: &ModuleScope,
    ) -> Result<ProtoRegistration<T>> {
        // SAFETY: reading our own static; only `register` writes `owner`,
        // and registration is serialised by module init.
        if !unsafe { (*self.canproto.get()).owner }.is_null() {
            return Err(code::EBUSY);
        }
        abi::check()?;
        let me = self as *const Self as *mut ();
        // `me` is this `&'static ProtoModule<T>`, and `unregister_erased`
        // of this `T` undoes its registration once it is made, does
        // nothing before (or after: `owner` is null), in process context.
        // SAFETY: so calling it at the module's exit is sound.
        unsafe {
            PROTO_REGS.note(me, Self::unregister_erased, SweepKind::Protocols, proto_sweep)?
        };
        let r = self.register_all(name);
        if r.is_err() {
            // SAFETY: `register_all` failed and undid what it had made, so
            // nothing is left for the exit to undo.
            unsafe { PROTO_REGS.take(me, Self::unregister_erased) };
        }
        r
    }

    /// [`Self::register`]'s registrations. Module init.
    fn register_all(
        &'static self,
        name: &'static kernel::str::CStr,
    ) -> Result<ProtoRegistration<T>> {
        self.proto.register(name, bindings::PF_CAN as i32, release_trampoline::<T>)?;
        // SAFETY: module init: nothing else sees the CanProto yet.
        unsafe { (*self.canproto.get()).owner = crate::glue::this_module() };
        // SAFETY: a static notifier, unregistered in `unregister`.
        let ret = unsafe { bindings::register_netdevice_notifier(self.notifier.get()) };
        if let Err(e) = crate::glue::to_result(ret) {
            self.proto.unregister();
            // SAFETY: as above.
            unsafe { (*self.canproto.get()).owner = core::ptr::null_mut() };
            return Err(e);
        }
        // SAFETY: a static CanProto, unregistered in `unregister`.
        let ret = unsafe { abi::rcan_proto_register(self.canproto.get()) };
        if let Err(e) = crate::glue::to_result(ret) {
            // SAFETY: registered just above.
            unsafe { bindings::unregister_netdevice_notifier(self.notifier.get()) };
            self.proto.unregister();
            // SAFETY: as above.
            unsafe { (*self.canproto.get()).owner = core::ptr::null_mut() };
            return Err(e);
        }
        Ok(ProtoRegistration(PhantomData))
    }

    /// `CanProto.create`: allocates the sock and lists it in `sockets`;
    /// with [`CanProtocol::RESERVE_RX`], makes its receiver too. Process
    /// context.
    ///
    /// # Safety
    ///
    /// The arguments are those of pf_can's `create` call (socket layer).
    unsafe fn create_socket(
        &self,
        net: *mut bindings::net,
        sock: *mut bindings::socket,
        protocol: ffi::c_int,
        kern: ffi::c_int,
    ) -> ffi::c_int {
        // SAFETY: the namespace of the socket being created, alive for
        // the call.
        if !T::ALL_NAMESPACES && !unsafe { Net::from_raw(net) }.is_init() {
            return -(bindings::EAFNOSUPPORT as ffi::c_int);
        }
        // SAFETY: the socket layer's arguments (this function's contract).
        if let Err(e) = unsafe { self.proto.create(net, sock, protocol, kern) } {
            return e.to_errno();
        }
        // SAFETY: create succeeded, so `sock->sk` is our new sock.
        let sk = unsafe { (*sock).sk } as usize;
        // SAFETY: our live new sock of `T`, for this call.
        let sock = unsafe { Sock::<T>::from_raw(sk as *mut bindings::sock) };
        let mut rtnl = Rtnl::lock();
        // INVARIANT: a live sock of `T`, removed by its release.
        self.sockets.get(&mut rtnl).insert(&sock);
        drop(rtnl);
        if T::RESERVE_RX {
            // Best effort: without a reservation (ENOMEM: NULL) the first
            // rx_set_locked allocates the receiver itself. The protocol's
            // release removes it (RESERVE_RX contract), which drops the
            // reference it holds.
            // SAFETY: `sk` is our live new sock of `T`; rx_trampoline::<T>
            // expects exactly such an owner.
            let h = unsafe { abi::rcan_rx_reserve(rx_trampoline::<T>, sock.as_ptr()) };
            // Nobody else can reach the socket before create returns.
            sock.rx_slot().store(h, Ordering::Relaxed);
        }
        0
    }
}

// Only the `create` trampoline that `ProtoModule::<T>::register(..,
// scope)` installs makes a sock of `T` (`Sock::from_raw` is the glue's).
impl<T: CanProtocol> crate::glue::module::sealed::Sealed for Sock<T> {}
impl<T: CanProtocol> crate::glue::module::InScopedModule for Sock<T> {}
impl<T: CanProtocol> crate::glue::module::sealed::Sealed for SockView<T> {}
impl<T: CanProtocol> crate::glue::module::InScopedModule for SockView<T> {}

/// Proof that protocol `T` is registered, for as long as its module is
/// loaded: dropping it (or forgetting it) does nothing. Only the module's
/// exit unregisters the protocol ([`proto_sweep`], before the module's
/// value is dropped, as this guard's drop in that value did), when no
/// socket of it can be left: every sock holds a reference on the module
/// (`struct proto.owner`) from `sk_alloc` until it is freed, so `rmmod`
/// cannot run while one exists.
///
/// An unregistration that safe code could trigger earlier (this guard's
/// drop did until issue 39's fix) pulled the protocol from under its open
/// sockets: no new socket, no netdevice events for the open ones, and
/// their socket set emptied under them, after which closing them in some
/// orders wrote into a freed sock ([`SockSet::remove`] following a
/// neighbour link; seen with KASAN).
pub(crate) struct ProtoRegistration<T: CanProtocol>(PhantomData<&'static ProtoModule<T>>);

impl<T: CanProtocol> ProtoModule<T> {
    /// Undoes a successful [`Self::register`]; does nothing if it is not
    /// registered (`owner` null). Process context; sleeps (a grace
    /// period). Called only by the module's exit ([`proto_sweep`]), when
    /// no sock of `T` is left ([`ProtoRegistration`]).
    fn unregister(&'static self) {
        // SAFETY: reading our own static; `owner` is written only by
        // register (module init) and here (its guard's drop or the exit,
        // which follow init).
        if unsafe { (*self.canproto.get()).owner }.is_null() {
            return;
        }
        // SAFETY: registered by `register` (owner set); rcan_proto_unregister
        // returns after a grace period, so no socket creation still sees it.
        unsafe {
            abi::rcan_proto_unregister(self.canproto.get());
            bindings::unregister_netdevice_notifier(self.notifier.get());
        }
        self.proto.unregister();
        // Statics are never dropped: free the (empty) list's buffer.
        let mut rtnl = Rtnl::lock();
        *self.sockets.get(&mut rtnl) = SockSet::new();
        // SAFETY: nothing uses the CanProto any more; allows a new register.
        unsafe { (*self.canproto.get()).owner = core::ptr::null_mut() };
    }

    /// [`Self::unregister`] for [`PROTO_REGS`], which keeps the module
    /// type-erased.
    ///
    /// # Safety
    ///
    /// `m` is a `&'static ProtoModule<T>` of this `T`.
    unsafe fn unregister_erased(m: *mut ()) {
        // SAFETY: per the contract.
        unsafe { &*m.cast::<Self>() }.unregister();
    }
}

/// Most protocols one module registers (one each today).
const MAX_PROTOS: usize = 2;

/// The protocols this module registered (the glue is compiled into each
/// module: one table per module), keyed
/// by their `&'static ProtoModule<T>` with `ProtoModule::<T>::
/// unregister_erased`; swept at exit by [`proto_sweep`]. Process context
/// only.
static PROTO_REGS: ExitTable<MAX_PROTOS> = ExitTable::new();

/// The exit's sweep ([`crate::glue::module::Scoped`], step 2, before the
/// module's value is dropped; step 3 after a failed `init`): unregisters
/// every protocol of this module. Process context; sleeps.
fn proto_sweep() {
    PROTO_REGS.sweep();
}

/// `CanProto.create` of protocol `T`: `socket(PF_CAN, T::SOCK_TYPE,
/// T::PROTOCOL)`. Process context.
///
/// # Safety
///
/// Called only by pf_can's `net_proto_family.create` with the socket
/// layer's arguments, while it holds a reference on `T`'s module.
unsafe extern "C" fn create_trampoline<T: CanProtocol>(
    net: *mut bindings::net,
    sock: *mut bindings::socket,
    protocol: ffi::c_int,
    kern: ffi::c_int,
) -> ffi::c_int {
    // SAFETY: the socket layer's arguments (this function's contract).
    unsafe { T::module().create_socket(net, sock, protocol, kern) }
}

/// `proto_ops::release` of protocol `T`: its `release`, then the sock
/// off the socket set if `release` left it on. Process context.
///
/// # Safety
///
/// The socket layer's release call for a socket of `T` (installed by
/// [`ProtoModule::register`] as `T`'s proto_ops).
unsafe extern "C" fn release_trampoline<T: CanProtocol>(sock: *mut bindings::socket) -> ffi::c_int {
    let forget = |sk: &Sock<T>| {
        // `listed` only goes from true to false (insert runs once, at
        // creation): false needs no RTNL; true is checked again under it.
        if sk.set_link().listed.load(Ordering::Relaxed) {
            T::module().sockets.get(&mut Rtnl::lock()).remove(sk);
        }
    };
    // SAFETY: our contract is `release_then`'s for `T`.
    unsafe { crate::glue::sock::release_then::<T>(sock, forget) }
}

/// The netdevice notifier of protocol `T`. Process context, RTNL held
/// (the notifier chain's contract).
///
/// # Safety
///
/// Called only by the netdevice notifier chain, `info` a
/// `netdev_notifier_info`.
unsafe extern "C" fn notifier_trampoline<T: CanProtocol>(
    _nb: *mut bindings::notifier_block,
    event: ffi::c_ulong,
    info: *mut ffi::c_void,
) -> ffi::c_int {
    let event = if event == bindings::netdev_cmd_NETDEV_DOWN as ffi::c_ulong {
        NetdevEvent::Down
    } else if event == bindings::netdev_cmd_NETDEV_UNREGISTER as ffi::c_ulong {
        NetdevEvent::Unregister
    } else {
        return bindings::NOTIFY_DONE as ffi::c_int;
    };
    // SAFETY: netdevice notifiers receive a netdev_notifier_info naming a
    // device that stays registered for the call.
    let dev = unsafe { NetDev::from_raw(bindings::rcan_netdev_notifier_dev(info)) };
    // The only proof made here is this one, kept in this frame:
    // `netdev_event` only gets `&Sockets`, and it cannot make a proof of
    // its own (`Rtnl::lock` would deadlock, not alias).
    // SAFETY: the notifier chain runs with RTNL held for this whole call
    // (call_netdevice_notifiers asserts it); one proof (above).
    let mut held = unsafe { Rtnl::assert_held() };
    let net = dev.net(&RcuReadGuard::new()).as_ptr().cast_const();
    let sockets = Sockets::<T> {
        set: T::module().sockets.get(&mut held),
        net,
        _t: PhantomData,
    };
    T::netdev_event(event, dev, &sockets);
    bindings::NOTIFY_DONE as ffi::c_int
}

/// The receive callback (`abi::RxFn`) of protocol `T`'s sockets.
///
/// # Safety
///
/// Called only by pf_can's dispatcher as `abi::RxFn` says, for a
/// subscription made by [`rx_set`]`::<T>`: `owner` is a sock of `T` on
/// which the subscription holds a reference.
unsafe extern "C" fn rx_trampoline<T: CanProtocol>(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    cookie: u32,
    owned: bool,
) {
    // SAFETY: a live sock of `T` for the call (this function's contract).
    // A view: NET_RX softirq, where the socket lock must not be taken.
    let sk = unsafe { SockView::<T>::from_raw(owner.cast()) };
    if owned {
        // SAFETY: a valid skb whose reference, the only one, is ours
        // (RxFn contract for `owned`).
        if let Some(skb) = unsafe { OwnedSkb::from_raw(skb) } {
            // INVARIANT: the receive callback's context (RxFn contract).
            T::rx(&sk, RxSkb(RxInner::Owned(skb, PhantomData)), cookie);
        }
    } else {
        // SAFETY: a valid skb borrowed for the call (RxFn contract); kept
        // from being freed by ManuallyDrop and only lent out by reference.
        if let Some(skb) = unsafe { Skb::from_raw(skb) } {
            let skb = ManuallyDrop::new(skb);
            // INVARIANT: as above.
            T::rx(&sk, RxSkb(RxInner::Shared(&skb)), cookie);
        }
    }
}

/// Subscribes socket `sk` of protocol `T` (replacing its previous
/// subscription) to frames on `ifindex` (0: every CAN interface) passing
/// `filters` (any of them, all of them with `join`) and to error frames
/// meeting `err_mask`; `T::rx` gets them with `cookie`. With neither
/// filters nor error mask this removes the subscription. The
/// subscription holds a reference on the sock until it is removed and a
/// grace period has passed. Process context; may sleep. ENOMEM, EINVAL
/// (bad filter); on error the previous subscription stays.
pub(crate) fn rx_set<T: CanProtocol>(
    sk: &Sock<T>,
    cookie: u32,
    ifindex: i32,
    filters: &[RxFilter],
    join: bool,
    err_mask: u32,
) -> Result {
    let spec = RxSpec {
        ifindex,
        join,
        err_mask,
        filters: filters.as_ptr(),
        nfilters: filters.len(),
    };
    // pf_can takes its own reference on `sk` for as long as it keeps the
    // subscription, and rx_trampoline::<T> expects exactly such an owner.
    // SAFETY: `spec` and the filters it points to live for the call; `sk`
    // is a live sock of `T` (Sock invariant).
    let ret = unsafe { abi::rcan_rx_set(rx_trampoline::<T>, sk.as_ptr(), cookie, &spec) };
    crate::glue::to_result(ret).map(|_| ())
}

/// Removes socket `sk`'s subscription, if any. Never fails. `T::rx` may
/// still run for it until a grace period has passed. Process context; may
/// sleep.
pub(crate) fn rx_remove<T: CanProtocol>(sk: &Sock<T>) {
    // SAFETY: removal of a subscription; `sk` is a live sock (Sock
    // invariant).
    unsafe { abi::rcan_rx_set(rx_trampoline::<T>, sk.as_ptr(), 0, core::ptr::null()) };
}

/// [`rx_set`] for a socket of a protocol with [`CanProtocol::RESERVE_RX`], socket lock
/// held (`s`), with its filters already in the table's form (`filters`,
/// whose error classes add to `err_mask`): its reserved receiver is set
/// without a lookup; a socket without one (ENOMEM at `socket()`) reserves
/// it now. A subscription that wants nothing retires the registration and
/// keeps the receiver. Process context; may sleep. ENOMEM; on error the
/// previous subscription stays.
pub(crate) fn rx_set_locked<T: CanProtocol>(
    s: &SockGuard<'_, T>,
    cookie: u32,
    ifindex: i32,
    filters: &TableFilters,
    join: bool,
    err_mask: u32,
) -> Result {
    let sk = s.sock();
    let rcv = match reserved(sk) {
        Some(rcv) => rcv,
        None => reserve_now(s)?,
    };
    let frames = filters.frames();
    let spec = RxTableSpec {
        ifindex,
        join,
        err_mask: err_mask | filters.err_mask,
        filters: frames.as_ptr(),
        nfilters: frames.len(),
    };
    // `rcv` is the socket's reserved receiver, not removed for good (only
    // rx_release does, clearing the slot under the socket lock `s` holds,
    // which also serialises our calls for it).
    // SAFETY: `spec` and its filters (table-form, made by `TableFilters`)
    // live for the call; `rcv` is valid, as said just above.
    let ret = unsafe { abi::rcan_rx_set_reserved(rcv, cookie, &spec, true) };
    crate::glue::to_result(ret).map(|_| ())
}

/// Reserves the receiver of a socket whose reservation failed at
/// `socket()` (ENOMEM), and stores it in its slot. Socket lock held
/// (`s`). Process context; may sleep. ENOMEM.
#[cold]
fn reserve_now<T: CanProtocol>(s: &SockGuard<'_, T>) -> Result<*mut ffi::c_void> {
    let sk = s.sock();
    if !T::RESERVE_RX {
        return Err(code::EINVAL);
    }
    // SAFETY: `sk` is a live sock of `T`; rx_trampoline::<T> expects
    // exactly such an owner. The protocol's release removes the receiver
    // (RESERVE_RX contract).
    let h = unsafe { abi::rcan_rx_reserve(rx_trampoline::<T>, sk.as_ptr()) };
    if h.is_null() {
        return Err(code::ENOMEM);
    }
    // Under the socket lock (`s`), as every later read of the slot.
    sk.rx_slot().store(h, Ordering::Relaxed);
    Ok(h)
}

/// [`rx_remove`] for a socket of a protocol with [`CanProtocol::RESERVE_RX`], socket
/// lock held (`s`): the registration goes, the reserved receiver stays for
/// a later [`rx_set_locked`]. `T::rx` may still run for the old
/// registration until a grace period has passed. Never fails. Process
/// context; may sleep.
pub(crate) fn rx_unset_locked<T: CanProtocol>(s: &SockGuard<'_, T>) {
    let sk = s.sock();
    // Without a reserved receiver the socket never subscribed
    // (rx_set_locked reserves one first): nothing to retire.
    if let Some(rcv) = reserved(sk) {
        // SAFETY: as in rx_set_locked; a NULL spec retires.
        unsafe { abi::rcan_rx_set_reserved(rcv, 0, core::ptr::null(), true) };
    }
}

/// Removes the socket's receiver for good, if it has one, from its
/// protocol's `release`, socket lock held (`s`). Never fails. Process
/// context; may sleep.
pub(crate) fn rx_release<T: CanProtocol>(s: &SockGuard<'_, T>) {
    let sk = s.sock();
    if let Some(rcv) = reserved(sk) {
        sk.rx_slot().store(core::ptr::null_mut(), Ordering::Relaxed);
        // SAFETY: as in rx_set_locked; the slot is cleared above (socket
        // lock held), so `rcv` is never used again.
        unsafe { abi::rcan_rx_set_reserved(rcv, 0, core::ptr::null(), false) };
    }
}

/// The socket's reserved receiver, if its protocol has a slot and it
/// holds one. Socket lock held by the caller (the slot changes only
/// under it, after `socket()`).
fn reserved<T: CanProtocol>(sk: &Sock<T>) -> Option<*mut ffi::c_void> {
    if !T::RESERVE_RX {
        return None;
    }
    let p = sk.rx_slot().load(Ordering::Relaxed);
    (!p.is_null()).then_some(p)
}

/// Sends the CAN frame in `skb` on `dev` (mainline `can_send`; sets
/// `skb->dev`); with `loopback` local receivers get it too. Consumes
/// `skb`. EINVAL, EMSGSIZE, EPERM, ENETDOWN, ENOBUFS, ENOMEM. Process or
/// softirq context. `dev` need only be valid for the call, as for
/// mainline's `can_send`: a counted reference
/// ([`DevRef`](gnetdev::DevRef) derefs to it) or the receiving device a
/// [`KernelRx`] callback is lent.
#[inline(always)]
///
/// The skb is the sender's alone and uncloned ([`UniqueSkb`]: pf_can may
/// set a flag in the frame), as every allocator in
/// [`crate::glue::can::skb`] returns it.
pub(crate) fn send(mut skb: UniqueSkb, dev: &NetDev, loopback: bool) -> Result {
    // SAFETY: handed to rcan_send right below, `dev` borrowed meanwhile
    // (rcan_send reads it back for the call only).
    unsafe { skb.set_dev(dev) };
    // SAFETY: rcan_send consumes the skb in every case; we give it the
    // only reference to an uncloned skb (`UniqueSkb`); skb->dev is `dev`,
    // which the borrow keeps valid until after the call returns.
    crate::glue::to_result(unsafe { abi::rcan_send(skb.into_raw(), loopback) }).map(|_| ())
}

/// A receiver inside the kernel (no socket), registered with
/// [`rx_set_kernel`]. `rx` runs in NET_RX softirq under RCU for every
/// matching frame, with the skb borrowed and its receiving device, both
/// valid for the call; it must not sleep, and may transmit ([`send`]).
pub(crate) trait KernelRx: Sync + 'static {
    fn rx(&self, skb: &Skb, dev: &NetDev);
}

/// The `abi::RxFn` of a [`KernelRx`].
///
/// # Safety
///
/// Called by pf_can's dispatcher as `abi::RxFn` says, with the `owner`
/// that [`rx_set_kernel`] registered: a `&'static T`.
unsafe extern "C" fn kernel_rx<T: KernelRx>(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    _cookie: u32,
    owned: bool,
) {
    // SAFETY: a valid skb, our reference if `owned`, else borrowed for the
    // call (RxFn contract); ManuallyDrop keeps a borrowed one unfreed. As
    // a `Skb`, the callback only reads it.
    let Some(skb) = (unsafe { Skb::<Shared>::from_raw(skb) }) else {
        return;
    };
    let skb = ManuallyDrop::new(skb);
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
        ManuallyDrop::into_inner(skb).consume();
    }
}

/// A registered [`KernelRx`]; dropping it removes the receiver and waits
/// for running callbacks (process context; sleeps). If it is never
/// dropped (`mem::forget`, a `static`), the module's exit removes the
/// receiver ([`Scoped`](crate::glue::module::Scoped), step 3): no frame
/// reaches the module's text after `rmmod`.
pub(crate) struct KernelRxReg<T: KernelRx>(&'static T);

impl<T: KernelRx> Drop for KernelRxReg<T> {
    fn drop(&mut self) {
        let data = self.0 as *const T as *mut ffi::c_void;
        // SAFETY: removal (NULL spec) of the receiver registered with this
        // func and data; never fails.
        unsafe { abi::rcan_rx_set_kernel(kernel_rx::<T>, data, 0, core::ptr::null_mut(), core::ptr::null()) };
        // SAFETY: the registration was removed just above.
        unsafe { KERNEL_RXS.take(data.cast(), kernel_rx_remove::<T>) };
    }
}

/// Most kernel receivers one module has registered at a time (one each
/// today: `rcan_dsor`, `rcan_rtime`).
const MAX_KERNEL_RX: usize = 4;

/// The kernel receivers this module registered and has not removed (the
/// glue is compiled into each module: one table per module), keyed by
/// their `&'static T` with [`kernel_rx_remove::<T>`]; swept at exit by
/// [`kernel_rx_sweep`]. Process context only: registration and removal
/// are; the sweep runs after the module's value is gone.
static KERNEL_RXS: ExitTable<MAX_KERNEL_RX> = ExitTable::new();

/// Removes the kernel receiver `kernel_rx::<T>` with data `data` from
/// pf_can (nothing if it is not registered), waiting out running
/// callbacks. Process context; sleeps.
///
/// # Safety
///
/// None beyond the call's: removal with a NULL spec only looks the pair
/// up; `unsafe fn` for [`ExitTable`]'s type.
unsafe fn kernel_rx_remove<T: KernelRx>(data: *mut ()) {
    // SAFETY: removal (NULL spec) of the receiver registered with this
    // func and data, or of nothing if it was removed already; never
    // fails, waits out running callbacks.
    unsafe { abi::rcan_rx_set_kernel(kernel_rx::<T>, data.cast(), 0, core::ptr::null_mut(), core::ptr::null()) };
}

/// The exit's sweep ([`crate::glue::module::Scoped`], step 3): removes
/// every kernel receiver of this module still registered. Process
/// context, after the module's value was dropped; sleeps (a grace period
/// per receiver).
fn kernel_rx_sweep() {
    KERNEL_RXS.sweep();
    KERNEL_RX_AT.sweep();
}

/// Registers `rx` for frames on `ifindex` (0: every CAN interface)
/// passing any of `filters` (at least one). The registration lasts until
/// the returned guard is dropped, and at the latest until the module's
/// exit, which the `scope` proves the glue runs ([`Scoped`]). ENOSPC with
/// more than `MAX_KERNEL_RX` receivers in one module. Process context
/// (`init`); may sleep.
///
/// [`Scoped`]: crate::glue::module::Scoped
pub(crate) fn rx_set_kernel<T: KernelRx>(
    _scope: &ModuleScope,
    rx: &'static T,
    ifindex: i32,
    filters: &[RxFilter],
) -> Result<KernelRxReg<T>> {
    if filters.is_empty() {
        return Err(code::EINVAL);
    }
    abi::check()?;
    let spec = RxSpec {
        ifindex,
        join: false,
        err_mask: 0,
        filters: filters.as_ptr(),
        nfilters: filters.len(),
    };
    // `rx` is 'static: a static of the calling module, whose exit removes
    // the registration at the latest (the sweep noted here).
    let data = rx as *const T as *mut ffi::c_void;
    // SAFETY: `kernel_rx_remove::<T>` may be called with `data` at any
    // time in process context (it removes the pair or nothing).
    let new = unsafe {
        KERNEL_RXS.note(data.cast(), kernel_rx_remove::<T>, SweepKind::KernelRx, kernel_rx_sweep)?
    };
    // SAFETY: `spec` and its filters live for the call; `data` is 'static
    // (module data), and the registration is removed by the guard's drop
    // or by the module's exit, before the module's memory goes.
    let ret = unsafe { abi::rcan_rx_set_kernel(kernel_rx::<T>, data, 0, core::ptr::null_mut(), &spec) };
    if let Err(e) = crate::glue::to_result(ret) {
        if new {
            // SAFETY: the registration failed: there is nothing to undo.
            unsafe { KERNEL_RXS.take(data.cast(), kernel_rx_remove::<T>) };
        }
        return Err(e);
    }
    Ok(KernelRxReg(rx))
}

/// A kernel receiver made at run time ([`rx_set_kernel_at`]): a
/// protocol's per-interface state (CAN_J1939's address claim table),
/// registered when a socket first binds to an interface and removed when
/// the last one leaves it, in the sockets' namespace.
///
/// Dropping it removes the receiver and waits for running callbacks
/// (process context; sleeps), then drops its `Arc<T>` and its reference
/// on the namespace. One never dropped (forgotten, or owned by something
/// leaked) is removed by the module's exit ([`KERNEL_RX_AT`]), which
/// [`InScopedModule`] evidence proves the glue runs: no frame reaches
/// the module's text after `rmmod`.
pub(crate) struct KernelRxAt<T: KernelRx + Send> {
    node: Option<KBox<AtNode<T>>>,
}

/// What [`KernelRxAt`] registers: its address is the receiver's `data`
/// (stable: boxed, and never freed while registered).
struct AtNode<T> {
    exit: ExitNode,
    rx: Arc<T>,
    /// The registration's namespace, held until the node is freed.
    net: NetRef,
}

/// The run-time kernel receivers of this module still registered (the
/// glue is compiled into each module: one list per module), through the
/// nodes in their allocations; swept at exit by [`kernel_rx_sweep`].
/// Unbounded (one per interface in use), so a list.
static KERNEL_RX_AT: ExitList = ExitList::new(kernel::c_str!("rcan_glue_kernel_rx_at"));

/// The `abi::RxFn` of a [`KernelRxAt`]: [`kernel_rx`] with the node's
/// `rx` as the receiver.
///
/// # Safety
///
/// Called by pf_can's dispatcher as `abi::RxFn` says, with the `owner`
/// that [`rx_set_kernel_at`] registered: the address of an `AtNode<T>`,
/// which stays allocated until the registration is removed (by
/// `KernelRxAt`'s drop, which frees it only afterwards, or by the exit,
/// which never frees it).
unsafe extern "C" fn kernel_rx_at<T: KernelRx + Send>(
    skb: *mut bindings::sk_buff,
    owner: *mut ffi::c_void,
    cookie: u32,
    owned: bool,
) {
    // CAST: the registered `AtNode<T>` (contract).
    let node = owner as *const AtNode<T>;
    // SAFETY: allocated while registered (contract); shared access only.
    let rx = unsafe { &*(*node).rx } as *const T;
    // SAFETY: `kernel_rx`'s contract with `rx` as the owner, alive for the
    // call (the node's Arc holds it).
    unsafe { kernel_rx::<T>(skb, rx as *mut ffi::c_void, cookie, owned) };
}

/// Removes the registration of the node at `node` from pf_can, waiting
/// out running callbacks; leaves the node's memory to its owner. Process
/// context; sleeps.
///
/// # Safety
///
/// `node` is an `AtNode<T>` registered by [`rx_set_kernel_at`], not
/// freed until this returns (its guard frees it only after taking it off
/// [`KERNEL_RX_AT`] itself; when the exit took it, never).
unsafe fn kernel_rx_at_remove<T: KernelRx + Send>(node: *mut ()) {
    // SAFETY: allocated (contract); its namespace is held by its NetRef.
    let net = unsafe { (*node.cast::<AtNode<T>>()).net.as_ptr() };
    // SAFETY: removal (NULL spec) of the receiver registered with this
    // func, data and namespace; never fails, waits out running callbacks.
    unsafe { abi::rcan_rx_set_kernel(kernel_rx_at::<T>, node.cast(), 0, net, core::ptr::null()) };
}

impl<T: KernelRx + Send> Drop for KernelRxAt<T> {
    fn drop(&mut self) {
        let Some(node) = self.node.take() else {
            return;
        };
        if KERNEL_RX_AT.remove(&node.exit) {
            let p = core::ptr::from_ref::<AtNode<T>>(&node).cast_mut().cast();
            // SAFETY: registered by rx_set_kernel_at and just taken off
            // the list by us, so nobody else removes it; freed below,
            // after the call.
            unsafe { kernel_rx_at_remove::<T>(p) };
            drop(node);
        } else {
            // The exit took it (and removes it, or did): its memory is
            // the exit's to read from now on, never freed.
            core::mem::forget(node);
        }
    }
}

/// Registers `rx` for frames on interface `ifindex` (0: every CAN
/// interface) of namespace `net` passing any of `filters` (at least
/// one), until the returned guard is dropped, and at the latest until
/// the module's exit (`_in` proves the glue owns it: a socket or device
/// of the module, or its init scope). A frame goes to `rx` once per
/// frame, in NET_RX softirq under RCU, as for [`rx_set_kernel`]. ENODEV
/// if `net` is going away; ENOMEM. Process context; sleeps (a grace
/// period).
pub(crate) fn rx_set_kernel_at<T: KernelRx + Send>(
    _in: &impl InScopedModule,
    net: &Net,
    ifindex: i32,
    rx: Arc<T>,
    filters: &[RxFilter],
) -> Result<KernelRxAt<T>> {
    if filters.is_empty() {
        return Err(code::EINVAL);
    }
    abi::check()?;
    let net = net.hold().ok_or(code::ENODEV)?;
    let node = KBox::new(
        AtNode {
            exit: ExitNode::new(),
            rx,
            net,
        },
        GFP_KERNEL,
    )?;
    let p: *mut () = core::ptr::from_ref::<AtNode<T>>(&node).cast_mut().cast();
    // The node stays at its address until the guard's drop takes it off
    // the list (boxed; a forgotten guard leaks it), and
    // SAFETY: `kernel_rx_at_remove::<T>(p)` may be called once at the
    // exit: it removes the registration or nothing, never frees the node.
    unsafe {
        KERNEL_RX_AT.push(
            &node.exit,
            p,
            kernel_rx_at_remove::<T>,
            SweepKind::KernelRx,
            kernel_rx_sweep,
        )
    };
    let spec = RxSpec {
        ifindex,
        join: false,
        err_mask: 0,
        filters: filters.as_ptr(),
        nfilters: filters.len(),
    };
    // `p` is the node, which stays allocated until the registration is
    // removed (the guard's drop removes it before freeing it; the exit
    // never frees it), and its NetRef keeps `net` alive as long.
    // SAFETY: that, and `spec` and its filters live for the call.
    let ret = unsafe {
        abi::rcan_rx_set_kernel(kernel_rx_at::<T>, p.cast(), 0, node.net.as_ptr(), &spec)
    };
    // From here the guard owns the node: dropped on error, it takes it
    // off the list and removes the (absent) registration.
    let guard = KernelRxAt { node: Some(node) };
    crate::glue::to_result(ret)?;
    Ok(guard)
}

/// Checks that the loaded `rcan_pf` speaks this module's ABI (see
/// `abi.rs`): ENOEXEC, and a log line naming both versions, if not.
/// [`ProtoModule::register`], [`rx_set_kernel`] and [`Listening::new`]
/// check by themselves; a module that only sends calls this in its init.
/// Process context.
pub(crate) fn abi_check() -> Result {
    abi::check()
}

/// A driver whose hardware filter follows the sockets (DESIGN decision 7).
pub(crate) trait FilterListener: gnetdev::Driver {
    /// The filters wanted on this device's interface changed. Process
    /// context, may not sleep for long (pf_can's writers' mutex is held).
    fn filters_changed(dev: &gnetdev::Dev<Self>, priv_: &Self::Priv);
}

/// # Safety
///
/// Called by pf_can as `abi::ListenFn` says, with the cookie that
/// [`Listening::new`] registered.
unsafe extern "C" fn listen_trampoline<T: FilterListener>(data: *mut ffi::c_void) {
    // `data` is the device of the Registration<T> that the Listening
    // which registered this call owns; its Drop removes the listener
    // (waiting for a running call) before that registration is dropped.
    // SAFETY: so the device is registered for the call.
    let (dev, p) = unsafe { gnetdev::from_cookie::<T>(data.cast()) };
    T::filters_changed(dev, p);
}

/// A registered device whose driver follows the receive table: calls
/// `T::filters_changed` for the device whenever the wanted filters of its
/// interface change, until dropped.
///
/// The listening owns the device's [`Registration`](gnetdev::Registration)
/// (lent through [`Listening::registration`]), so the order of the
/// teardown is the type's, not the order of a driver's fields: its `Drop`
/// removes the listener (waiting for a running call), then the
/// registration is dropped (the device unregistered and freed). No
/// listener can outlive its device; `mem::forget` leaks both, the device
/// staying registered as when a `Registration` alone is forgotten.
///
/// # Invariants
///
/// The listener `(listen_trampoline::<T>, reg's device)` is registered
/// with pf_can from `new` until `drop`.
pub(crate) struct Listening<T: FilterListener> {
    /// Dropped after [`Listening`]'s `Drop` (fields are dropped after the
    /// containing value's `Drop::drop` runs).
    reg: gnetdev::Registration<T>,
}

impl<T: FilterListener> Listening<T> {
    /// Starts listening for `reg`'s device, which the listening keeps
    /// registered from now on. On failure (ENOEXEC: another `rcan_pf`'s
    /// ABI; ENOMEM) `reg` is dropped: the device is unregistered. Process
    /// context.
    pub(crate) fn new(reg: gnetdev::Registration<T>) -> Result<Self> {
        abi::check()?;
        let dev = reg.dev().as_ptr();
        let ifindex = reg.dev().ifindex();
        // The returned Listening owns `reg` and drops it only after its
        // Drop removed the listener (type invariant); on failure nothing
        // was registered.
        // SAFETY: the cookie is `reg`'s registered device (above).
        crate::glue::to_result(unsafe {
            abi::rcan_rx_listen(listen_trampoline::<T>, dev.cast(), ifindex, true)
        })?;
        // If the listening is forgotten, the module's exit tears the
        // device down (its Registration's node) and removes the listener
        // first, through this hook.
        // SAFETY: `unlisten::<T>` removes exactly this listener, once,
        // in process context, before the device is unregistered.
        unsafe { reg.set_before_teardown(unlisten::<T>) };
        // INVARIANT: registered just above, for `reg`'s device.
        Ok(Listening { reg })
    }

    /// The registration of the device listened to.
    pub(crate) fn registration(&self) -> &gnetdev::Registration<T> {
        &self.reg
    }
}

/// Removes the filter listener of device `dev` of `T` (a [`Listening`]'s,
/// through its device's teardown hook); returns after a running call
/// finished. Process context.
///
/// # Safety
///
/// `dev` is a registered device of `T` whose listener
/// `(listen_trampoline::<T>, dev)` was added by [`Listening::new`] and not
/// removed since.
unsafe fn unlisten<T: FilterListener>(dev: *mut bindings::net_device) {
    // SAFETY: a registered device (contract), valid for the call.
    let ifindex = unsafe { NetDev::from_raw(dev) }.ifindex();
    // SAFETY: removal of that listener (contract).
    unsafe { abi::rcan_rx_listen(listen_trampoline::<T>, dev.cast(), ifindex, false) };
}

impl<T: FilterListener> Drop for Listening<T> {
    fn drop(&mut self) {
        // Taken back first, so the device's teardown does not remove the
        // listener a second time.
        if self.reg.take_before_teardown() {
            // The listener added in new() (type invariant), not removed
            // since (the hook was still set); `unlisten` returns after a
            // running call finished, and `self.reg` is dropped only after
            // this function returns.
            // SAFETY: so this is `unlisten`'s contract.
            unsafe { unlisten::<T>(self.reg.dev().as_ptr()) };
        }
    }
}

/// The filters that apply to frames received on `dev` (in its namespace
/// now), in `out`; `None` if there are more than fit. Any context.
pub(crate) fn rx_filters(
    dev: &NetDev,
    out: &mut [crate::rcan_core::rxtable::Filter],
) -> Option<usize> {
    // SAFETY: `dev` is valid for the call; `out` has room for `out.len()`
    // filters.
    let n = unsafe { abi::rcan_rx_filters(dev.as_ptr(), out.as_mut_ptr(), out.len()) };
    usize::try_from(n).ok()
}

/// Most filters [`wanted`] takes into account; with more, a driver's
/// hardware filter stays open (sound, just not tight). Stack use in atomic
/// context bounds it.
pub(crate) const MAX_WANTED: usize = 24;

/// What the sockets bound to `dev` (or to every interface) want, as
/// [`Wanted`](crate::rcan_core::filter::Wanted) sets handed to `derive`,
/// which computes a driver's hardware filter from them. `None` when the
/// hardware filter must be open: `dev` is promiscuous, or more than
/// [`MAX_WANTED`] filters apply. Any context.
pub(crate) fn wanted<T>(
    dev: &NetDev,
    derive: impl FnOnce(&[crate::rcan_core::filter::Wanted]) -> T,
) -> Option<T> {
    use crate::rcan_core::{filter::Wanted, rxtable::Filter};
    if dev.is_promisc() {
        return None;
    }
    let mut fs = [Filter::Id {
        id: 0,
        mask: 0,
        inv: false,
    }; MAX_WANTED];
    let n = rx_filters(dev, &mut fs)?;
    let mut w = [Wanted::ALL; MAX_WANTED];
    for (o, f) in w.iter_mut().zip(&fs[..n]) {
        *o = Wanted::of(f);
    }
    Some(derive(&w[..n]))
}
