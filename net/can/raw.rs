// SPDX-License-Identifier: GPL-2.0

//! rcan_raw: CAN_RAW, the raw protocol of mainline SocketCAN, on the rcan
//! stack (DESIGN decision 5).
//!
//! `socket(PF_CAN, SOCK_RAW, CAN_RAW)` with mainline's ABI: 16-byte
//! `struct can_frame` reads and writes, and with CAN_RAW_FD_FRAMES 72-byte
//! `struct canfd_frame` ones on CAN FD devices (MTU 72), `struct
//! sockaddr_can` (only `can_family` and `can_ifindex` are used; 8 bytes
//! are required and returned), `SOL_CAN_RAW` options. Programs written for mainline
//! (can-utils, python-can, the `socketcan` crate) run unchanged. Every
//! errno is mainline's for the same input; see
//! Documentation/networking/rcan/can-raw.rst for the reference and for the
//! few deliberate differences (no CAN XL: CAN_RAW_XL_FRAMES is accepted as
//! mainline accepts it, but no rcan device has a CAN XL MTU).
//!
//! Contexts and locks:
//!
//! * System calls run in process context. Those that change what the
//!   socket receives (bind, CAN_RAW_FILTER, CAN_RAW_ERR_FILTER,
//!   CAN_RAW_RECV_OWN_MSGS, CAN_RAW_JOIN_FILTERS) take RTNL, then the
//!   socket lock, then (inside `rcan_rx_set_reserved`, reached through
//!   the glue's `rx_set_locked`, which takes the socket lock's guard)
//!   pf_can's writers' mutex —
//!   the order of mainline raw.c; RTNL keeps the device from vanishing
//!   between the check and the registration, and serialises with the
//!   netdevice notifier.
//! * `RawProto::rx`, the receive callback, runs in NET_RX softirq under RCU, for
//!   bus frames and echoes alike (every frame comes up through the network
//!   core; a receive callback may transmit, this one only queues). It
//!   reads only its arguments (the socket's receive options travel in the
//!   registration's `cookie`, CAN_RAW_FD_FRAMES in an atomic of the
//!   socket's shared part), never the socket lock.
//! * `MODULE.sockets`, every open socket (for the notifier), is protected by
//!   RTNL.

#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use kernel::prelude::*;

use glue::netdev::{DevRef, NetDev};
use glue::neterr;
use glue::sock::{Msg, OptIn, OptOut, Sock, SockGuard, SockView};
use glue::sync::Rtnl;
use crate::glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use rcan_api::{
    CanProtocol, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter, RxSkb, Sockets,
    TableFilters, CAN_RAW, RX_FILTER_CAN_ID, SOCK_RAW,
};
use rcan_core::frame::{AnyFrame, CANFD_MTU};
use rcan_core::rxtable::CAN_ERR_MASK;
use rcan_core::sockaddr::AF_CAN;

/// `SOL_CAN_RAW` (`SOL_CAN_BASE + CAN_RAW`).
const SOL_CAN_RAW: i32 = 101;
const CAN_RAW_FILTER: i32 = 1;
const CAN_RAW_ERR_FILTER: i32 = 2;
const CAN_RAW_LOOPBACK: i32 = 3;
const CAN_RAW_RECV_OWN_MSGS: i32 = 4;
const CAN_RAW_FD_FRAMES: i32 = 5;
const CAN_RAW_JOIN_FILTERS: i32 = 6;
const CAN_RAW_XL_FRAMES: i32 = 7;
/// `SCM_CAN_RAW_ERRQUEUE`: cmsg type of error-queue messages.
const SCM_CAN_RAW_ERRQUEUE: i32 = 1;
/// Most filters one socket may set (`CAN_RAW_FILTER_MAX`).
const CAN_RAW_FILTER_MAX: usize = 512;
/// `sizeof(struct can_filter)`.
const CAN_FILTER_LEN: usize = 8;
/// CAN_RAW_FILTER reads up to this many filters without a heap buffer.
const SMALL_FILTERS: usize = 8;
/// Bytes of `struct sockaddr_can` that CAN_RAW requires and returns
/// (`can_family`, padding, `can_ifindex`).
const RAW_MIN_NAMELEN: usize = 8;
/// Mainline checks a write's size against the smallest and largest frame
/// of any CAN flavour (CAN XL header + 1 byte, and the CAN XL MTU) before
/// anything else; keeping the same bounds keeps the errnos identical.
const MIN_WRITE: usize = 13;
const MAX_WRITE: usize = 2060;

/// `cookie` bit of the registration: deliver the socket's own frames.
const COOKIE_RECV_OWN: u32 = 1;

/// Device MTUs of CAN XL (`CANXL_MIN_MTU`..=`CANXL_MAX_MTU`): mainline
/// lets CAN FD frames through to those devices too.
const CANXL_MTUS: core::ops::RangeInclusive<u32> = 76..=2060;

/// A `struct can_filter` as the user set it (`id` = `can_id`, `mask` =
/// `can_mask`), returned by getsockopt; pf_can gets the socket's filters
/// in the table's form instead ([`RawSock::table`]).
fn can_filter(can_id: u32, can_mask: u32) -> RxFilter {
    RxFilter {
        kind: RX_FILTER_CAN_ID,
        id: can_id,
        mask: can_mask,
    }
}

/// The filter of a new socket: everything (`can_mask` 0).
static DEFAULT_FILTER: [RxFilter; 1] = [RxFilter {
    kind: RX_FILTER_CAN_ID,
    id: 0,
    mask: 0,
}];

/// [`DEFAULT_FILTER`] in the table's form.
const DEFAULT_TABLE: TableFilters = TableFilters::can_filter(0, 0);

/// A CAN_RAW socket's state, protected by its socket lock.
struct RawSock {
    bound: bool,
    /// Interface given to bind (0 = all CAN interfaces).
    ifindex: i32,
    /// Filters set with CAN_RAW_FILTER, as set.
    filters: RawFilters,
    /// The same filters in the receive table's form, converted when set,
    /// so that bind and every re-subscription hand them over as they are.
    table: TableFilters,
    err_mask: u32,
    /// Option values as the user set them (mainline keeps the int).
    loopback: i32,
    recv_own_msgs: i32,
    join_filters: i32,
    /// CAN_RAW_FD_FRAMES / CAN_RAW_XL_FRAMES as set (mainline keeps the
    /// int). FD frames are sent and received with `fd_frames` (mirrored
    /// in [`RawShared::fd_frames`]); XL is accepted and kept, but no rcan
    /// device carries CAN XL frames.
    fd_frames: i32,
    xl_frames: i32,
}

/// A socket's CAN_RAW_FILTER list. One filter (the common case, as in
/// mainline's `dfilter`) is kept inline: setting it allocates nothing and
/// close frees nothing.
enum RawFilters {
    /// Never set: the default filter (everything).
    Default,
    One(RxFilter),
    /// None or several.
    Many(KVec<RxFilter>),
}

/// What sendmsg and getname need, readable without the socket lock
/// (mainline reads these fields unlocked too). Written under the socket lock, together
/// with the copies in [`RawSock`].
struct RawShared {
    /// The bound interface (0 = unbound or all).
    ifindex: AtomicI32,
    /// CAN_RAW_LOOPBACK is on.
    loopback: AtomicBool,
    /// CAN_RAW_FD_FRAMES is on (read by sendmsg and by the receive
    /// callback, as mainline reads `ro->fd_frames`).
    fd_frames: AtomicBool,
}

impl RawSock {
    fn filters(&self) -> &[RxFilter] {
        match &self.filters {
            RawFilters::Default => &DEFAULT_FILTER,
            RawFilters::One(f) => core::slice::from_ref(f),
            RawFilters::Many(v) => v,
        }
    }

    fn cookie(&self) -> u32 {
        if self.recv_own_msgs != 0 {
            COOKIE_RECV_OWN
        } else {
            0
        }
    }
}

struct RawProto;

/// This module's registrations (proto, CAN protocol, notifier).
static MODULE: ProtoModule<RawProto> = ProtoModule::new();

type S = Sock<RawProto>;

impl CanProtocol for RawProto {
    const PROTOCOL: i32 = CAN_RAW;
    const SOCK_TYPE: i32 = SOCK_RAW;
    /// All state is in the socket; devices are looked up in the
    /// socket's namespace.
    const ALL_NAMESPACES: bool = true;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// The receiver is made at `socket()` (mainline allocates its
    /// per-socket receive state there too), so bind allocates nothing and
    /// finds it without a lookup; `release` always removes it.
    const RESERVE_RX: bool = true;

    /// NET_RX softirq, RCU read side. Mainline `raw_rcv`: own frames only
    /// with CAN_RAW_RECV_OWN_MSGS, CAN FD frames only with
    /// CAN_RAW_FD_FRAMES (pf_can hands up only well-formed 16- and 72-byte
    /// frames), MSG_DONTROUTE for frames sent from this host, MSG_CONFIRM
    /// for frames sent by this socket. Always inlined into the glue's
    /// receive trampoline (one function a frame, as `raw_rcv`).
    #[inline(always)]
    fn rx(sk: &SockView<Self>, skb: RxSkb<'_>, cookie: u32) {
        let local = skb.skb().is_local();
        let own = skb.skb().sent_by(sk);
        if own && cookie & COOKIE_RECV_OWN == 0 {
            skb.done();
            return;
        }
        if skb.skb().len() as usize == CANFD_MTU && !sk.shared().fd_frames.load(Ordering::Relaxed) {
            skb.done();
            return;
        }
        let mut flags = 0u32;
        if local {
            flags |= glue::msg::DONTROUTE;
        }
        if own {
            flags |= glue::msg::CONFIRM;
        }
        // The receiving device is lent for this call only: its index is
        // read now and kept in the cb.
        let ifindex = skb.ifindex();
        let Some(mut skb) = skb.into_owned() else {
            return;
        };
        glue::can::skb::set_rx_meta(&mut skb, ifindex, flags);
        // A full receive queue drops the frame (counted by the socket layer).
        let _ = sk.queue_rcv(skb);
    }

    /// Mainline `raw_notify`. Process context, RTNL held. Sockets bound to
    /// a CAN device that goes away lose their filters and get ENODEV;
    /// those bound to one that goes down get ENETDOWN.
    fn netdev_event(event: NetdevEvent, dev: &NetDev, sockets: &Sockets<'_, Self>) {
        if !dev.is_can() {
            return;
        }
        let ifindex = dev.ifindex();
        sockets.for_each(|sk| {
            let mut s = sk.lock();
            if !s.bound || s.ifindex != ifindex {
                return;
            }
            let err = if event == NetdevEvent::Unregister {
                rcan_api::rx_unset_locked(&s);
                s.bound = false;
                s.ifindex = 0;
                sk.shared().ifindex.store(0, Ordering::Relaxed);
                // Mainline forgets the filters too: a new bind receives
                // nothing until CAN_RAW_FILTER is set again.
                s.filters = RawFilters::Many(KVec::new());
                s.table = TableFilters::none();
                ENODEV
            } else {
                neterr::ENETDOWN()
            };
            drop(s);
            sk.report_error(-err.to_errno());
        });
    }
}

/// (Re)registers the socket's receiver from its current state, or retires
/// its registration when the socket is not bound. Process context; caller
/// holds RTNL and the socket lock (passes its guard in `s`).
fn register(s: &SockGuard<'_, RawProto>) -> Result {
    if !s.bound {
        rcan_api::rx_unset_locked(s);
        return Ok(());
    }
    rcan_api::rx_set_locked(
        s,
        s.cookie(),
        s.ifindex,
        &s.table,
        s.join_filters != 0,
        s.err_mask,
    )
}

/// Parses the `can_family`/`can_ifindex` part of a `struct sockaddr_can`.
fn parse_addr(addr: &[u8]) -> Result<i32> {
    if addr.len() < RAW_MIN_NAMELEN {
        return Err(EINVAL);
    }
    if u16::from_ne_bytes([addr[0], addr[1]]) != AF_CAN {
        return Err(EINVAL);
    }
    Ok(i32::from_ne_bytes([addr[4], addr[5], addr[6], addr[7]]))
}

/// Reads an `int` option; EINVAL unless `optlen` is exactly 4.
fn read_int(opt: &OptIn) -> Result<i32> {
    if opt.len() != 4 {
        return Err(EINVAL);
    }
    let mut b = [0u8; 4];
    opt.read(&mut b)?;
    Ok(i32::from_ne_bytes(b))
}

/// A change of what a socket receives.
enum Change {
    /// As set, and in the table's form.
    Filters(RawFilters, TableFilters),
    ErrMask(u32),
    RecvOwn(i32),
    Join(i32),
}

/// Applies `change` and re-registers the receiver if the socket is bound;
/// on failure the old state stays. Process context; takes RTNL and the
/// socket lock.
fn update(sk: &S, change: Change) -> Result {
    let _rtnl = Rtnl::lock();
    let mut s = sk.lock();
    let (err_mask, recv_own, join) = (s.err_mask, s.recv_own_msgs, s.join_filters);
    let mut old_filters = None;
    match change {
        Change::Filters(v, t) => {
            old_filters = Some((
                core::mem::replace(&mut s.filters, v),
                core::mem::replace(&mut s.table, t),
            ))
        }
        Change::ErrMask(m) => s.err_mask = m,
        Change::RecvOwn(v) => s.recv_own_msgs = v,
        Change::Join(v) => s.join_filters = v,
    }
    if s.bound {
        if let Err(e) = register(&s) {
            s.err_mask = err_mask;
            s.recv_own_msgs = recv_own;
            s.join_filters = join;
            if let Some((f, t)) = old_filters {
                s.filters = f;
                s.table = t;
            }
            return Err(e);
        }
    }
    Ok(())
}

impl glue::sock::Proto for RawProto {
    type Data = RawSock;
    type Shared = RawShared;

    fn new_shared() -> RawShared {
        RawShared {
            ifindex: AtomicI32::new(0),
            loopback: AtomicBool::new(true),
            fd_frames: AtomicBool::new(false),
        }
    }

    fn new_data() -> RawSock {
        RawSock {
            bound: false,
            ifindex: 0,
            filters: RawFilters::Default,
            table: DEFAULT_TABLE,
            err_mask: 0,
            loopback: 1,
            recv_own_msgs: 0,
            join_filters: 0,
            fd_frames: 0,
            xl_frames: 0,
        }
    }

    fn release(sk: &S) {
        let mut rtnl = Rtnl::lock();
        MODULE.sockets.get(&mut rtnl).remove(sk);
        let mut s = sk.lock();
        // Bound or not: the receiver made at socket() (RESERVE_RX) goes too.
        rcan_api::rx_release(&s);
        s.bound = false;
        s.ifindex = 0;
        s.filters = RawFilters::Default;
        s.table = DEFAULT_TABLE;
        sk.shared().ifindex.store(0, Ordering::Relaxed);
    }

    fn bind(sk: &S, addr: &[u8]) -> Result {
        let mut ifindex = parse_addr(addr)?;
        let mut enetdown = false;
        {
            let rtnl = Rtnl::lock();
            let mut s = sk.lock();
            if s.bound && s.ifindex == ifindex {
                return Ok(());
            }
            if ifindex != 0 {
                // Under RTNL, held until the registration is made: the
                // device cannot go in between, so no reference is taken.
                let dev = NetDev::by_index_rtnl(sk.net(), ifindex, &rtnl).ok_or(ENODEV)?;
                if !dev.is_can() {
                    return Err(ENODEV);
                }
                enetdown = !dev.is_up();
                ifindex = dev.ifindex();
            }
            let old = (s.bound, s.ifindex);
            s.bound = true;
            s.ifindex = ifindex;
            if let Err(e) = register(&s) {
                (s.bound, s.ifindex) = old;
                return Err(e);
            }
            sk.shared().ifindex.store(ifindex, Ordering::Relaxed);
        }
        if enetdown {
            sk.report_error(-neterr::ENETDOWN().to_errno());
        }
        Ok(())
    }

    fn connect(_sk: &S, _addr: &[u8], _flags: i32) -> Result {
        Err(neterr::EOPNOTSUPP())
    }

    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        if peer {
            return Err(neterr::EOPNOTSUPP());
        }
        // Without the socket lock, as mainline's raw_getname: the bound
        // index as of some moment during the call.
        let ifindex = sk.shared().ifindex.load(Ordering::Relaxed);
        out[..RAW_MIN_NAMELEN].fill(0);
        out[..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        out[4..RAW_MIN_NAMELEN].copy_from_slice(&ifindex.to_ne_bytes());
        Ok(RAW_MIN_NAMELEN)
    }

    #[inline]
    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        if !(MIN_WRITE..=MAX_WRITE).contains(&len) {
            return Err(EINVAL);
        }
        // No socket lock on the send path (as mainline): a racing bind or
        // setsockopt is seen before or after, either is fine.
        let sh = sk.shared();
        let (bound_ifindex, loopback) = (
            sh.ifindex.load(Ordering::Relaxed),
            sh.loopback.load(Ordering::Relaxed),
        );
        let ifindex = match msg.name() {
            Some(name) => parse_addr(name)?,
            None => bound_ifindex,
        };
        let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENXIO)?;
        let nonblock = msg.flags() & glue::msg::DONTWAIT != 0;
        let mut skb = glue::can::skb::alloc_tx(sk, &dev, len, nonblock)?;
        skb.put_from_msg(msg, len)?;
        // Mainline raw_check_txframe: a classic frame anywhere; a CAN FD
        // frame only with CAN_RAW_FD_FRAMES on a CAN FD (or CAN XL)
        // device; nothing else (no CAN XL here).
        // (`AnyFrame::kind`: the same test as `parse`, without building
        // a copy of the frame.)
        let ok = match AnyFrame::kind(skb.data()) {
            Some(false) => true,
            Some(true) => {
                let mtu = dev.mtu();
                sh.fd_frames.load(Ordering::Relaxed)
                    && (mtu == CANFD_MTU as u32 || CANXL_MTUS.contains(&mtu))
            }
            None => false,
        };
        if !ok {
            return Err(EINVAL);
        }
        skb.set_sock_params(sk);
        rcan_api::send(skb, &dev, loopback)?;
        Ok(len)
    }

    #[inline]
    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        if flags as u32 & glue::msg::ERRQUEUE != 0 {
            return sk.recv_errqueue(msg, len, SOL_CAN_RAW, SCM_CAN_RAW_ERRQUEUE);
        }
        glue::can::skb::recvmsg_queued(sk, msg, len, flags)
    }

    fn setsockopt(sk: &S, level: i32, name: i32, opt: &OptIn) -> Result {
        if level != SOL_CAN_RAW {
            return Err(EINVAL);
        }
        match name {
            CAN_RAW_FILTER => {
                let len = opt.len();
                if len % CAN_FILTER_LEN != 0 || len > CAN_RAW_FILTER_MAX * CAN_FILTER_LEN {
                    return Err(EINVAL);
                }
                // A few filters are read through a buffer on the stack,
                // more through one on the heap.
                let mut small = [0u8; SMALL_FILTERS * CAN_FILTER_LEN];
                let mut big;
                let raw: &mut [u8] = if len <= small.len() {
                    &mut small[..len]
                } else {
                    big = KVec::from_elem(0u8, len, GFP_KERNEL)?;
                    &mut big
                };
                opt.read(raw)?;
                let parse = |c: &[u8]| {
                    can_filter(
                        u32::from_ne_bytes([c[0], c[1], c[2], c[3]]),
                        u32::from_ne_bytes([c[4], c[5], c[6], c[7]]),
                    )
                };
                let (v, t) = if len == CAN_FILTER_LEN {
                    let f = parse(raw);
                    (RawFilters::One(f), TableFilters::can_filter(f.id, f.mask))
                } else {
                    let mut v = KVec::with_capacity(len / CAN_FILTER_LEN, GFP_KERNEL)?;
                    for c in raw.chunks_exact(CAN_FILTER_LEN) {
                        v.push(parse(c), GFP_KERNEL)?;
                    }
                    let t = TableFilters::can_filters(v.iter().map(|f| (f.id, f.mask)))?;
                    (RawFilters::Many(v), t)
                };
                update(sk, Change::Filters(v, t))
            }
            CAN_RAW_ERR_FILTER => {
                let m = read_int(opt)? as u32 & CAN_ERR_MASK;
                update(sk, Change::ErrMask(m))
            }
            CAN_RAW_LOOPBACK => {
                let v = read_int(opt)?;
                let mut s = sk.lock();
                s.loopback = v;
                sk.shared().loopback.store(v != 0, Ordering::Relaxed);
                Ok(())
            }
            CAN_RAW_RECV_OWN_MSGS => {
                let v = read_int(opt)?;
                update(sk, Change::RecvOwn(v))
            }
            CAN_RAW_JOIN_FILTERS => {
                let v = read_int(opt)?;
                update(sk, Change::Join(v))
            }
            // Mainline accepts these on any interface; they only widen
            // what may be written and read. Socket lock only, as mainline:
            // the receive callback and sendmsg read the atomic.
            CAN_RAW_FD_FRAMES => {
                let v = read_int(opt)?;
                let mut s = sk.lock();
                // Enabling CAN XL includes CAN FD.
                if s.xl_frames != 0 && v == 0 {
                    return Err(EINVAL);
                }
                s.fd_frames = v;
                sk.shared().fd_frames.store(v != 0, Ordering::Relaxed);
                Ok(())
            }
            CAN_RAW_XL_FRAMES => {
                let v = read_int(opt)?;
                let mut s = sk.lock();
                s.xl_frames = v;
                if v != 0 {
                    s.fd_frames = v;
                    sk.shared().fd_frames.store(true, Ordering::Relaxed);
                }
                Ok(())
            }
            _ => Err(neterr::ENOPROTOOPT()),
        }
    }

    fn getsockopt(sk: &S, level: i32, name: i32, opt: &OptOut) -> Result {
        if level != SOL_CAN_RAW {
            return Err(EINVAL);
        }
        let len = opt.len()?;
        if len < 0 {
            return Err(EINVAL);
        }
        let s = sk.lock();
        let val: i32 = match name {
            CAN_RAW_FILTER => {
                let fs = s.filters();
                let fsize = (fs.len() * CAN_FILTER_LEN) as i32;
                if fs.is_empty() {
                    return opt.set_len(0);
                }
                if len < fsize {
                    opt.set_len(fsize)?;
                    return Err(ERANGE);
                }
                let mut buf = KVec::with_capacity(fsize as usize, GFP_KERNEL)?;
                for f in fs {
                    buf.extend_from_slice(&f.id.to_ne_bytes(), GFP_KERNEL)?;
                    buf.extend_from_slice(&f.mask.to_ne_bytes(), GFP_KERNEL)?;
                }
                drop(s);
                opt.write(&buf)?;
                return opt.set_len(fsize);
            }
            CAN_RAW_ERR_FILTER => s.err_mask as i32,
            CAN_RAW_LOOPBACK => s.loopback,
            CAN_RAW_RECV_OWN_MSGS => s.recv_own_msgs,
            CAN_RAW_JOIN_FILTERS => s.join_filters,
            CAN_RAW_FD_FRAMES => s.fd_frames,
            CAN_RAW_XL_FRAMES => s.xl_frames,
            _ => return Err(neterr::ENOPROTOOPT()),
        };
        drop(s);
        let n = len.min(4);
        opt.set_len(n)?;
        opt.write(&val.to_ne_bytes()[..n as usize])
    }
}

/// The module: its registrations, undone when it is dropped (unload).
pub(crate) struct RawModule {
    _reg: ProtoRegistration<RawProto>,
}

impl ScopedModule for RawModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let reg = MODULE.register(c_str!("CAN_RAW"), scope)?;
        pr_info!("CAN_RAW ({}) registered\n", CAN_RAW);
        Ok(RawModule { _reg: reg })
    }
}
