// SPDX-License-Identifier: GPL-2.0

//! rcan_j1939: CAN_J1939 (SAE J1939), mainline SocketCAN's J1939 socket
//! API, on the rcan stack (issue 42, steps 2a to 2c).
//!
//! `socket(PF_CAN, SOCK_DGRAM, CAN_J1939)` with mainline's ABI
//! (`<linux/can/j1939.h>` of 6.12): `bind`/`connect` with
//! `sockaddr_can.can_addr.j1939 {name, pgn, addr}` and an interface, one
//! J1939 message per `sendmsg` and per `recvmsg` (over 8 bytes by the
//! transport protocols, [`j1939_tp`]), the source address in
//! `msg_name` (24 bytes), the `SCM_J1939_DEST_ADDR`, `SCM_J1939_DEST_NAME`
//! and `SCM_J1939_PRIO` control messages, the options `SO_J1939_FILTER`,
//! `SO_J1939_PROMISC`, `SO_J1939_SEND_PRIO` and `SO_J1939_ERRQUEUE`
//! (the error queue: a transport session's events in [`j1939_tp`], a
//! single frame's in [`j1939_echo`]), and `SO_BROADCAST`'s rules. The address checks, identifier mapping, option checks and
//! receive matching are `rcan_core::j1939`, host-tested; this file gives
//! them a socket, a receive subscription and a transmit path.
//!
//! Not yet: Documentation/networking/rcan/j1939.rst, "The module".
//!
//! Objects and their locks (lock order: RTNL, socket lock, [`IFACES`],
//! `Iface::ac`, `Iface::socks`, a socket's `rx`; `Iface::tp` and
//! `Iface::echo` nest nothing of ours and are never held while another
//! is taken):
//!
//! * [`J1939Sock`] (socket lock): the binding, the peer, the options as
//!   set, the interface state joined. Process context only.
//! * [`J1939Shared::rx`], allocated by the first `bind`: what delivery
//!   matches frames against ([`RxState`], a copy of the binding, the
//!   peer, `SO_J1939_PROMISC` and the filters) under a `BhLock`
//!   (`spin_lock_bh`, lockdep class `j1939_rx`; mainline's
//!   `filters_lock`). Written in process context under the socket lock
//!   ([`publish`]), read by the receive softirq. `SO_BROADCAST` is read
//!   from the socket itself, as mainline does.
//! * [`Iface`], one per interface (and namespace) with a bound socket
//!   (mainline's `struct j1939_priv`): the address claim table
//!   (`AcTable`, `BhLock` class `j1939_ac`) and the bound sockets
//!   (`BhLock` class `j1939_socks`), the transport sessions (`BhLock`
//!   class `j1939_tp`, [`j1939_tp`], with the interface's first timer),
//!   the single frames waiting for their echo (`BhLock` class
//!   `j1939_echo`, [`j1939_echo`], with its second timer), and
//!   one kernel receiver for every
//!   extended data frame of the interface ([`IfaceUse`], in [`IFACES`]).
//!   The receiver runs in NET_RX softirq: it feeds ADDRESS_CLAIMED frames
//!   to the table, names the frame's source and destination from it once,
//!   and walks the interface's sockets with [`SockRx::accepts`]
//!   (mainline's `j1939_can_recv`, `j1939_ac_recv`, `j1939_sk_recv`).
#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use kernel::prelude::*;

use crate::glue::module::{ModuleScope, ScopedModule};
use glue::hrtimer::ktime_get_mono_ns;
use glue::jobtimer::{JobTimers, OnceBox};
use glue::lock::{new_bh_spinlock, BhLock, BhSpinLock, WaitQueue, Waited};
use glue::net::NetRef;
use glue::netdev::{DevRef, NetDev};
use glue::skb::{OwnedSkb, Skb, UniqueSkb};
use glue::sock::{Msg, OptIn, OptOut, Sock, SockRef, SockView};
use glue::sync::Rtnl;
use kernel::alloc::{flags::GFP_ATOMIC, KVVec, KVec};
use kernel::c_str;
use kernel::sync::Arc;
use rcan_api::{
    rx_set_kernel_at, CanProtocol, KernelRx, KernelRxAt, NetdevEvent, ProtoModule,
    ProtoRegistration, RxFilter, Sockets, RX_FILTER_CAN_ID, SOCK_DGRAM,
};
use rcan_core::arb::{CAN_EFF_FLAG, CAN_RTR_FLAG};
use rcan_core::frame::AnyFrame;
use rcan_core::j1939_ac::AcTable;
use rcan_core::j1939::{
    filter_count, flag_option, pgn_is_valid, Frame, prio_to_sk_priority,
    send_prio_option, sk_priority_to_prio, Filter, Id, RxMeta, SockAddr, SockRx, AF_CAN,
    CAN_J1939, DEFAULT_PRIO, EACCES, EBADFD, EDOM, J1939_NO_ADDR, J1939_NO_NAME, J1939_NO_PGN,
    J1939_PGN_ADDRESS_CLAIMED, SCM_J1939_DEST_ADDR, SCM_J1939_DEST_NAME, SCM_J1939_ERRQUEUE,
    SCM_J1939_PRIO,
    SOCKADDR_J1939_LEN, SOL_CAN_J1939, SO_J1939_ERRQUEUE, SO_J1939_FILTER, SO_J1939_PROMISC,
    SO_J1939_SEND_PRIO,
};
use rcan_core::j1939_tp::{kind_for, ETP_PGN_CTL, ETP_PGN_DAT, TP_PGN_CTL, TP_PGN_DAT};

use crate::j1939_echo::{self, EchoTable};
use crate::j1939_tp::{self, IfaceJob, Tp};

fn errno(e: i32) -> Error {
    glue::errno(e)
}

type S = Sock<J1939Proto>;

/// The largest message sent as one frame; longer ones go by a transport
/// protocol ([`j1939_tp`]).
const MAX_SINGLE: usize = 8;

/// Where `sendmsg` and `release` wait for their socket's transport session
/// to end (all CAN_J1939 sockets share it: each waiter re-checks its own
/// socket's [`J1939Shared::tx_busy`]); woken by every sender's end.
pub(crate) static WAITQ: WaitQueue = WaitQueue::new(c_str!("rcan_j1939::WAITQ"));

/// Offsets in `skb->cb` of a message queued for `recvmsg` (ours; the
/// socket layer keeps its own 4 bytes at the end of the 48): the
/// receiving interface, the PGN, source and destination address,
/// priority, the recvmsg flags (MSG_DONTROUTE), the source and
/// destination NAMEs.
const CB_IFINDEX: usize = 0;
const CB_PGN: usize = 4;
const CB_SA: usize = 8;
const CB_DA: usize = 9;
const CB_PRIO: usize = 10;
const CB_FLAGS: usize = 12;
const CB_SRC_NAME: usize = 16;
const CB_DST_NAME: usize = 24;
const CB_LEN: usize = 32;

/// What the receive callback matches a frame against: the socket's
/// binding, peer and options, copied from [`J1939Sock`] by [`publish`].
struct RxState {
    /// Bound (false again after the device's removal or `release`).
    bound: bool,
    ifindex: i32,
    /// The socket's receive side (its `broadcast` is filled per frame
    /// from SO_BROADCAST).
    rx: SockRx,
    filters: KVec<Filter>,
}

/// A CAN_J1939 socket's state under the socket lock.
pub(crate) struct J1939Sock {
    bound: bool,
    ifindex: i32,
    /// Bound NAME and address (`jsk->addr.src_name`, `.sa`).
    src_name: u64,
    sa: u8,
    /// The PGN given to `bind`, or [`J1939_NO_PGN`]: only that PGN is
    /// received (`jsk->pgn_rx_filter`).
    pgn_rx_filter: u32,
    /// `connect` was called; its NAME, address and PGN (the default
    /// destination and PGN of `send`; `jsk->addr.dst_name`, `.da`,
    /// `.pgn`).
    connected: bool,
    dst_name: u64,
    da: u8,
    pgn: u32,
    promisc: bool,
    errqueue: bool,
    /// SO_J1939_FILTER as set (values masked).
    filters: KVec<Filter>,
    /// The state of the bound interface, joined by `bind` ([`join`]),
    /// left by unbinding ([`leave`]); `Some` exactly while bound.
    iface: Option<Arc<Iface>>,
}

/// What the receive path and the lockless checks need.
pub(crate) struct J1939Shared {
    /// Mirrors `J1939Sock::bound` (written under the socket lock).
    bound: AtomicBool,
    /// A transport session of this socket is active (at most one):
    /// claimed by `sendmsg` (compare-exchange), cleared by the session's
    /// end in any context ([`j1939_tp`]), which then wakes [`WAITQ`].
    pub(crate) tx_busy: AtomicBool,
    /// SO_J1939_ERRQUEUE (written under the socket lock, read by the
    /// sessions: errors then go to the error queue, not to `sk_err`).
    pub(crate) errqueue: AtomicBool,
    /// The receive state, allocated by the first `bind` and kept until
    /// the sock is freed.
    rx: OnceBox<BhLock<RxState>>,
}

/// One interface's J1939 state (mainline's `struct j1939_priv`), shared
/// by the sockets bound to it: made by the first `bind`, dropped after
/// the last socket left ([`IFACES`]), always in process context (every
/// holder is: the registry, the sockets' bindings, the receiver's
/// registration). It is the data of the job timer that runs its
/// transport sessions ([`j1939_tp::IfaceJob`]); dropping it kills the
/// timer first.
pub(crate) struct Iface {
    job: JobTimers<IfaceJob>,
}

impl core::ops::Deref for Iface {
    type Target = IfaceState;
    fn deref(&self) -> &IfaceState {
        self.job.data()
    }
}

/// What an [`Iface`] holds.
pub(crate) struct IfaceState {
    /// The namespace of the interface (held: compared by identity with a
    /// socket's, and the sessions' timer looks the device up in it).
    pub(crate) net: NetRef,
    pub(crate) ifindex: i32,
    /// The address claim table (mainline's ECU list and address
    /// entries). `BhLock` (class `j1939_ac`): taken in process context
    /// (`bind`, `sendmsg`, unbinding, the interface going down) and by
    /// the receive softirq. Nothing else is locked inside it.
    pub(crate) ac: BhLock<KBox<AcTable>>,
    /// The sockets bound to the interface, each held by a reference
    /// (mainline's `j1939_socks`). `BhLock` (class `j1939_socks`):
    /// written in process context ([`join`], [`leave`]), walked by the
    /// receive softirq, which takes each socket's `rx` lock inside it.
    socks: BhLock<KVec<SockRef<J1939Proto>>>,
    /// The transport sessions ([`j1939_tp::Tp`]; `BhLock` class
    /// `j1939_tp`, taken in the receive and timer softirqs and in process
    /// context, with nothing of this module inside it).
    pub(crate) tp: BhLock<KBox<Tp>>,
    /// The single frames that wait for their echo ([`j1939_echo`];
    /// `BhLock` class `j1939_echo`, taken in the receive and timer
    /// softirqs and in process context, with nothing of this module
    /// inside it).
    pub(crate) echo: BhLock<EchoTable>,
    /// The number of entries of `echo`, written under its lock, read
    /// without it by the receive path ([`j1939_echo::on_echo`]).
    pub(crate) echo_used: AtomicUsize,
}

/// An interface in use: its state, how many sockets joined it, and its
/// kernel receiver, registered while the entry exists.
struct IfaceUse {
    users: usize,
    iface: Arc<Iface>,
    /// Every classic extended data frame of the interface goes to
    /// `iface` ([`Iface::rx`]); dropping it removes the receiver (process
    /// context, sleeps).
    _rx: KernelRxAt<Iface>,
}

/// The interfaces in use, in every namespace (a handful). `BhSpinLock`
/// (class `rcan_j1939::IFACES`), process context only, never held across
/// a sleep: an entry is made and dropped outside it ([`join`],
/// [`leave`]).
static IFACES: BhSpinLock<KVec<IfaceUse>> = BhSpinLock::new(KVec::new(), c_str!("rcan_j1939::IFACES"));

/// An empty claim table, copied into each new interface state (too big
/// to be built on the stack).
static EMPTY_AC: AcTable = AcTable::new();

/// Monotonic time for the claim table, in ns.
pub(crate) fn now_ns() -> u64 {
    ktime_get_mono_ns() as u64
}

/// Joins socket `sk` to the state of interface `ifindex` of its
/// namespace, making it (and its receiver) for the first socket. Process
/// context (sleeps: a new receiver waits a grace period). ENOMEM.
fn join(sk: &S, ifindex: i32) -> Result<Arc<Iface>> {
    let net = sk.net();
    let find = |v: &mut KVec<IfaceUse>| -> Option<Arc<Iface>> {
        let u = v
            .iter_mut()
            .find(|u| *u.iface.net == *net && u.iface.ifindex == ifindex)?;
        u.users += 1;
        Some(u.iface.clone())
    };
    // Its own statement: the guard must be gone before the `None` arm
    // (which sleeps and takes the lock again).
    let found = find(&mut IFACES.lock());
    let iface = match found {
        Some(i) => i,
        None => {
            // Made outside the registry's lock (allocations, a grace
            // period), then entered unless another bind was quicker.
            let ac = new_bh_spinlock!(glue::kbox_copy(&EMPTY_AC, GFP_KERNEL)?, "j1939_ac")?;
            let socks = new_bh_spinlock!(KVec::new(), "j1939_socks")?;
            let tp = new_bh_spinlock!(Tp::new()?, "j1939_tp")?;
            let echo = new_bh_spinlock!(j1939_echo::new_table()?, "j1939_echo")?;
            let state = IfaceState {
                net: net.hold().ok_or(ENODEV)?,
                ifindex,
                ac,
                socks,
                tp,
                echo,
                echo_used: AtomicUsize::new(0),
            };
            let job = JobTimers::new(state, sk)?;
            let iface = Arc::new(Iface { job }, GFP_KERNEL)?;
            let rx = rx_set_kernel_at(sk, net, ifindex, iface.clone(), &RX_FILTERS)?;
            let mine = IfaceUse {
                users: 1,
                iface: iface.clone(),
                _rx: rx,
            };
            let mut v = IFACES.lock();
            if let Some(theirs) = find(&mut v) {
                // Ours (and its receiver) is dropped outside the lock.
                drop(v);
                drop(mine);
                theirs
            } else if v.reserve(1, GFP_ATOMIC).is_err() {
                drop(v);
                drop(mine);
                return Err(ENOMEM);
            } else {
                // Room was reserved: the push does not allocate.
                let _ = v.push(mine, GFP_ATOMIC);
                iface
            }
        }
    };
    let r = sk.to_ref();
    let pushed = iface.socks.lock().push(r, GFP_ATOMIC);
    if let Err(e) = pushed {
        leave(sk, iface);
        return Err(e.into());
    }
    Ok(iface)
}

/// Takes socket `sk` off `iface`'s sockets and drops its use of it; the
/// last user's leaving drops the state and its receiver. Process context
/// (sleeps then: a grace period).
fn leave(sk: &S, iface: Arc<Iface>) {
    let mine = {
        let mut socks = iface.socks.lock();
        socks
            .iter()
            .position(|r| r.sock().same(sk))
            .map(|i| glue::kvec_swap_remove(&mut socks, i))
    };
    // The reference is put outside the lock.
    drop(mine);
    let (gone, emptied) = {
        let mut v = IFACES.lock();
        let gone = match v.iter().position(|u| Arc::ptr_eq(&u.iface, &iface)) {
            Some(i) => {
                let u = &mut v[i];
                u.users -= 1;
                if u.users == 0 {
                    Some(glue::kvec_swap_remove(&mut v, i))
                } else {
                    None
                }
            }
            None => None,
        };
        // An empty registry gives its buffer back: a `static` is never
        // dropped, so a buffer kept after the last interface would leak
        // when the module is unloaded (kmemleak saw it on the debug kernel).
        let emptied = if v.is_empty() {
            Some(core::mem::take(&mut *v))
        } else {
            None
        };
        (gone, emptied)
    };
    // The receiver is removed outside the lock (a grace period); the
    // buffer is freed there too.
    drop(gone);
    drop(emptied);
}

impl KernelRx for Iface {
    /// NET_RX softirq, RCU read side: a classic extended data frame of the
    /// interface (mainline's `j1939_can_recv`). ADDRESS_CLAIMED frames go
    /// to the claim table (`j1939_ac_recv`); the source and destination
    /// NAMEs come from the table. Frames of the transport protocols that
    /// involve a local address, or go to broadcast, are the transport's
    /// ([`j1939_tp::on_frame`], mainline's `j1939_tp_recv`); control frames
    /// shorter than 8 bytes, and transfers between two other nodes, are
    /// messages like any other: every bound socket whose binding, peer,
    /// options and filters accept the frame gets it, except the sender
    /// (`j1939_sk_recv`).
    fn rx(&self, skb: &Skb, dev: &NetDev) {
        let Some((can_id, data, false)) = AnyFrame::view(skb.data()) else {
            return;
        };
        let Some(id) = Id::from_can_id(can_id) else {
            return;
        };
        let now = now_ns();
        let (m, local_sa, local_da) = {
            // No timer: the table is settled whenever it is asked
            // (`AcTable::settle`).
            let mut ac = self.ac.lock();
            ac.settle(now);
            ac.on_frame(id.sa, id.pgn, data, now);
            // An ADDRESS_CLAIMED frame names its source itself (mainline's
            // `j1939_ac_process`); other frames get the NAME the table
            // maps the address to.
            let src_name = if id.pgn == J1939_PGN_ADDRESS_CLAIMED {
                <[u8; 8]>::try_from(data).map_or(J1939_NO_NAME, u64::from_le_bytes)
            } else {
                ac.addr_to_name(id.sa)
            };
            let m = RxMeta {
                id,
                src_name,
                dst_name: ac.addr_to_name(id.da),
            };
            (m, ac.is_local(id.sa), ac.is_local(id.da))
        };
        let transport = is_transport_pgn(id.pgn)
            && !(matches!(id.pgn, TP_PGN_CTL | ETP_PGN_CTL) && data.len() < 8)
            && (local_sa || local_da || id.is_broadcast());
        if transport {
            j1939_tp::on_frame(
                self,
                self.job.get(),
                dev,
                id,
                data,
                local_sa,
                local_da,
                skb.tstamp(),
            );
            return;
        }
        if skb.is_local() {
            // The echo of a local socket's single frame (mainline's
            // `j1939_simple_recv`, before the frame is delivered).
            j1939_echo::on_echo(self, skb, &Frame::new(id, data));
        }
        let ifindex = dev.ifindex();
        let flags = if skb.is_local() { glue::msg::DONTROUTE } else { 0 };
        let tstamp = skb.tstamp();
        deliver(self, ifindex, &m, Some(skb), || {
            rx_skb(data, ifindex, &m, flags, tstamp).map(UniqueSkb::into_owned)
        });
    }
}

/// Gives a message received on interface `ifindex` (`m`) to every socket
/// of `st` that accepts it, except the sender of `skip` (a single frame;
/// mainline's `j1939_sk_recv`); `make` gives each its copy. A full
/// receive queue drops the message, as mainline. Softirq context.
pub(crate) fn deliver(
    st: &IfaceState,
    ifindex: i32,
    m: &RxMeta,
    skip: Option<&Skb>,
    mut make: impl FnMut() -> Option<OwnedSkb>,
) {
    for_each_accepting(st, ifindex, m, skip, |sk| {
        if let Some(out) = make() {
            let _ = sk.queue_rcv(out);
        }
    });
}

/// Calls `f` for every socket of `st` whose binding, peer, options and
/// filters accept a message `m` received on interface `ifindex` (mainline's
/// `j1939_sk_recv_match_one`), except the sender of `skip`. Softirq or
/// process context; `f` runs under the sockets' lock (`j1939_socks`).
pub(crate) fn for_each_accepting(
    st: &IfaceState,
    ifindex: i32,
    m: &RxMeta,
    skip: Option<&Skb>,
    mut f: impl FnMut(&SockView<J1939Proto>),
) {
    let socks = st.socks.lock();
    for r in socks.iter() {
        let sk = r.sock();
        if skip.is_some_and(|s| s.sent_by(sk)) {
            continue;
        }
        let Some(rxs) = sk.shared().rx.get() else {
            continue;
        };
        let broadcast = sk.broadcast();
        let accepted = {
            let g = rxs.lock();
            let mut rx = g.rx;
            rx.broadcast = broadcast;
            g.bound && g.ifindex == ifindex && rx.accepts(&g.filters, m)
        };
        if accepted {
            f(sk);
        }
    }
}

/// Unbinds `s` (the socket lock held: `s` is its data): off the
/// interface's sockets and claim table, no more frames. Process context
/// (sleeps: the last socket of an interface removes its receiver).
fn unbind(sk: &S, s: &mut J1939Sock) {
    s.bound = false;
    sk.shared().bound.store(false, Ordering::Relaxed);
    if let Some(l) = sk.shared().rx.get() {
        l.lock().bound = false;
    }
    if let Some(iface) = s.iface.take() {
        // Its transport session ends without a frame (mainline's
        // `j1939_cancel_active_session`): nothing of the socket is left in
        // the interface's table.
        j1939_tp::cancel(&iface, iface.job.get(), Some(sk));
        j1939_echo::cancel(&iface, Some(sk));
        iface.ac.lock().local_put(s.src_name, s.sa);
        leave(sk, iface);
    }
}

pub(crate) struct J1939Proto;

/// This module's registrations (proto, CAN protocol, notifier).
static MODULE: ProtoModule<J1939Proto> = ProtoModule::new();

/// Copies what the receive callback needs from `s` into the socket's
/// [`RxState`] (allocating it at the first call). Process context, socket
/// lock held (`s` is its data). ENOMEM.
fn publish(sk: &S, s: &J1939Sock) -> Result {
    let mut filters = KVec::with_capacity(s.filters.len(), GFP_KERNEL)?;
    for f in s.filters.iter() {
        filters.push(*f, GFP_KERNEL)?;
    }
    let rx = SockRx {
        promisc: s.promisc,
        broadcast: false,
        src_name: s.src_name,
        sa: s.sa,
        connected: s.connected,
        dst_name: s.dst_name,
        da: s.da,
        pgn_rx_filter: s.pgn_rx_filter,
    };
    let st = RxState {
        bound: s.bound,
        ifindex: s.ifindex,
        rx,
        filters,
    };
    match sk.shared().rx.get() {
        Some(l) => {
            let old = {
                let mut g = l.lock();
                core::mem::replace(&mut *g, st)
            };
            // The old filters are freed here, outside the spinlock.
            drop(old);
        }
        None => {
            let l = new_bh_spinlock!(st, "j1939_rx")?;
            sk.shared().rx.set(KBox::new(l, GFP_KERNEL)?)?;
        }
    }
    Ok(())
}

/// Whether `pgn` is one of the transport protocols' own PGNs (TP and ETP
/// connection management and data transfer): user space may not send
/// them (mainline's `j1939_tp_send`: `EDOM`), and their frames are not
/// messages (see `rx`).
fn is_transport_pgn(pgn: u32) -> bool {
    matches!(pgn, TP_PGN_CTL | TP_PGN_DAT | ETP_PGN_CTL | ETP_PGN_DAT)
}

/// The receive buffer of a delivered frame: its payload, the metadata in
/// the cb for `recvmsg`, the frame's timestamp. Any context (GFP_ATOMIC).
fn rx_skb(data: &[u8], ifindex: i32, m: &RxMeta, flags: u32, tstamp: i64) -> Option<UniqueSkb> {
    let mut skb = UniqueSkb::alloc(MAX_SINGLE as u32, glue::GFP_ATOMIC)?;
    if !skb.put_data(data) {
        return None;
    }
    write_meta(&mut skb, ifindex, m, flags, tstamp);
    Some(skb)
}

/// Writes what `recvmsg` reports of a message into its buffer's cb (the
/// receiving interface, `m`, the recvmsg flags) and its timestamp (0:
/// none). Any context.
pub(crate) fn write_meta(skb: &mut UniqueSkb, ifindex: i32, m: &RxMeta, flags: u32, tstamp: i64) {
    let mut cb = [0u8; CB_LEN];
    cb[CB_IFINDEX..CB_IFINDEX + 4].copy_from_slice(&ifindex.to_ne_bytes());
    cb[CB_PGN..CB_PGN + 4].copy_from_slice(&m.id.pgn.to_ne_bytes());
    cb[CB_SA] = m.id.sa;
    cb[CB_DA] = m.id.da;
    cb[CB_PRIO] = m.id.prio;
    cb[CB_FLAGS..CB_FLAGS + 4].copy_from_slice(&flags.to_ne_bytes());
    cb[CB_SRC_NAME..CB_SRC_NAME + 8].copy_from_slice(&m.src_name.to_ne_bytes());
    cb[CB_DST_NAME..CB_DST_NAME + 8].copy_from_slice(&m.dst_name.to_ne_bytes());
    skb.cb_write(0, &cb);
    if tstamp != 0 {
        skb.set_tstamp(tstamp);
    }
}

impl CanProtocol for J1939Proto {
    const PROTOCOL: i32 = CAN_J1939;
    const SOCK_TYPE: i32 = SOCK_DGRAM;
    /// All state is in the socket; devices are looked up in the socket's
    /// namespace.
    const ALL_NAMESPACES: bool = true;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// Mainline `j1939_netdev_notify`. Process context, RTNL held. The
    /// bound device going down forgets every claimed address (mainline's
    /// `j1939_ecu_unmap_all`) and reports ENETDOWN; going away unbinds
    /// the socket without an error (mainline's
    /// `j1939_sk_netdev_event_unregister`), after which sends get EBADFD.
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
            if event == NetdevEvent::Down {
                if let Some(iface) = &s.iface {
                    // Every session of the interface ends (mainline's
                    // `j1939_cancel_active_session(priv, NULL)`), every
                    // claim is forgotten.
                    j1939_tp::cancel(iface, iface.job.get(), None);
                    j1939_echo::cancel(iface, None);
                    iface.ac.lock().unmap_all();
                }
                drop(s);
                sk.report_error(-glue::neterr::ENETDOWN().to_errno());
                return;
            }
            unbind(sk, &mut s);
        });
    }
}

/// The subscription of an interface's state: every classic extended data
/// frame (mainline's `J1939_CAN_ID`/`J1939_CAN_MASK`: EFF set, RTR clear).
const RX_FILTERS: [RxFilter; 1] = [RxFilter {
    kind: RX_FILTER_CAN_ID,
    id: CAN_EFF_FLAG,
    mask: CAN_EFF_FLAG | CAN_RTR_FLAG,
}];

impl glue::sock::Proto for J1939Proto {
    type Data = J1939Sock;
    type Shared = J1939Shared;

    /// Addresses are whole 24-byte `sockaddr_can`s.
    const SOCKADDR_CAN_NAMES: bool = true;
    /// Mainline `j1939_sk_init`: J1939 priority 6.
    const SK_PRIORITY: u32 = prio_to_sk_priority(DEFAULT_PRIO);

    fn new_shared() -> J1939Shared {
        J1939Shared {
            bound: AtomicBool::new(false),
            tx_busy: AtomicBool::new(false),
            errqueue: AtomicBool::new(false),
            rx: OnceBox::new(),
        }
    }

    /// Mainline `j1939_sk_init`: no address, no PGN.
    fn new_data() -> J1939Sock {
        J1939Sock {
            bound: false,
            ifindex: 0,
            src_name: J1939_NO_NAME,
            sa: J1939_NO_ADDR,
            pgn_rx_filter: J1939_NO_PGN,
            connected: false,
            dst_name: J1939_NO_NAME,
            da: J1939_NO_ADDR,
            pgn: J1939_NO_PGN,
            promisc: false,
            errqueue: false,
            filters: KVec::new(),
            iface: None,
        }
    }

    /// Mainline `j1939_sk_release`: waits (interruptibly) for the
    /// socket's transport session to end, then unbinds, which cancels it
    /// if a signal cut the wait short.
    fn release(sk: &S) {
        let _ = wait_idle(sk);
        let mut rtnl = Rtnl::lock();
        MODULE.sockets.get(&mut rtnl).remove(sk);
        let mut s = sk.lock();
        unbind(sk, &mut s);
    }

    /// Mainline `j1939_sk_bind`, in its order of checks: the address
    /// (`EINVAL` short or not AF_CAN, `ENODEV` no interface, `EINVAL`
    /// a PDU1 PGN with a destination byte), a second bind to another
    /// interface (`EINVAL`), the interface (`ENODEV` missing or not CAN,
    /// `ENETDOWN` down). A second bind to the same interface changes the
    /// NAME and address (and the PGN, if one is given).
    fn bind(sk: &S, addr: &[u8]) -> Result {
        let a = SockAddr::parse_for_bind(addr).map_err(errno)?;
        // RTNL before the socket lock: the device cannot go between the
        // check and the subscription, and the notifier sees the binding.
        let rtnl = Rtnl::lock();
        let mut s = sk.lock();
        if s.bound {
            if s.ifindex != a.ifindex {
                return Err(EINVAL);
            }
        } else {
            let dev = NetDev::by_index_rtnl(sk.net(), a.ifindex, &rtnl).ok_or(ENODEV)?;
            if !dev.is_can() {
                return Err(ENODEV);
            }
            if !dev.is_up() {
                return Err(glue::neterr::ENETDOWN());
            }
        }
        let old = (s.src_name, s.sa, s.pgn_rx_filter, s.bound, s.ifindex);
        // The interface's state: joined by the first bind; a NAME and
        // address are entered in its claim table (mainline's
        // `j1939_local_ecu_get`: ENOMEM when the table is full), the old
        // ones of a second bind taken out.
        let iface = match &s.iface {
            Some(i) => i.clone(),
            None => join(sk, a.ifindex)?,
        };
        let entered = {
            let mut ac = iface.ac.lock();
            ac.local_get(a.name, a.addr).map(|()| {
                if old.3 {
                    ac.local_put(old.0, old.1);
                }
            })
        };
        if let Err(e) = entered {
            if !old.3 {
                leave(sk, iface);
            }
            return Err(errno(e));
        }
        if pgn_is_valid(a.pgn) {
            s.pgn_rx_filter = a.pgn;
        }
        s.src_name = a.name;
        s.sa = a.addr;
        s.bound = true;
        s.ifindex = a.ifindex;
        // The receive state: frames are matched against the new binding
        // from now on.
        if let Err(e) = publish(sk, &s) {
            iface.ac.lock().local_put(a.name, a.addr);
            (s.src_name, s.sa, s.pgn_rx_filter, s.bound, s.ifindex) = old;
            if old.3 {
                let _ = iface.ac.lock().local_get(old.0, old.1);
                let _ = publish(sk, &s);
            } else {
                leave(sk, iface);
            }
            return Err(e);
        }
        s.iface = Some(iface);
        sk.shared().bound.store(true, Ordering::Relaxed);
        drop(s);
        drop(rtnl);
        Ok(())
    }

    /// Mainline `j1939_sk_connect`: the address checks of `bind`, then
    /// `EINVAL` unbound or another interface, `EACCES` broadcast without
    /// SO_BROADCAST. Sets the default destination and PGN of `send`, and
    /// receives only from that peer.
    fn connect(sk: &S, addr: &[u8], _flags: i32) -> Result {
        let a = SockAddr::parse_for_bind(addr).map_err(errno)?;
        let mut s = sk.lock();
        if !s.bound || s.ifindex != a.ifindex {
            return Err(EINVAL);
        }
        if a.is_broadcast() && !sk.broadcast() {
            return Err(errno(EACCES));
        }
        let old = (s.dst_name, s.da, s.pgn, s.connected);
        s.dst_name = a.name;
        s.da = a.addr;
        if pgn_is_valid(a.pgn) {
            s.pgn = a.pgn;
        }
        s.connected = true;
        if let Err(e) = publish(sk, &s) {
            (s.dst_name, s.da, s.pgn, s.connected) = old;
            return Err(e);
        }
        Ok(())
    }

    /// Mainline `j1939_sk_getname`: 24 bytes, the interface, the
    /// connected PGN, and the bound (or, for the peer, the connected) NAME
    /// and address; the peer of an unconnected socket is EADDRNOTAVAIL.
    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        let s = sk.lock();
        if peer && !s.connected {
            return Err(glue::neterr::EADDRNOTAVAIL());
        }
        let (name, addr) = if peer {
            (s.dst_name, s.da)
        } else {
            (s.src_name, s.sa)
        };
        let b = SockAddr {
            ifindex: s.ifindex,
            name,
            pgn: s.pgn,
            addr,
        }
        .to_bytes();
        out.get_mut(..b.len()).ok_or(EINVAL)?.copy_from_slice(&b);
        Ok(b.len())
    }

    /// Mainline `j1939_sk_sendmsg` and its simple (single frame) path:
    /// `EBADFD` unbound or without a source address; a `msg_name`
    /// destination checked as mainline (`EINVAL`, `EBADFD`, `EINVAL`,
    /// `EACCES`), without one the connected peer (broadcast needs
    /// SO_BROADCAST: `EACCES`); `EDOM` for a transport PGN. Messages of
    /// up to 8 bytes go out as one frame (priority from
    /// SO_J1939_SEND_PRIO / SO_PRIORITY) and the call returns once the
    /// device took it (with SO_J1939_ERRQUEUE on, the send then waits for
    /// its echo: [`j1939_echo`]); longer ones start a transport session and return
    /// at once ([`send_transport`]). NAMEs are resolved, and outgoing address claims
    /// checked, by the interface's claim table (`AcTable::fixup_send`:
    /// `EADDRNOTAVAIL` while a NAME holds no address, `EPROTO`/`ENODEV`
    /// for a bad claim).
    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        let (ifindex, src_name, sa, mut dst_name, mut da, mut pgn, iface) = {
            let s = sk.lock();
            let Some(iface) = s.iface.clone() else {
                return Err(errno(EBADFD));
            };
            if s.src_name == J1939_NO_NAME && s.sa == J1939_NO_ADDR {
                return Err(errno(EBADFD));
            }
            (s.ifindex, s.src_name, s.sa, s.dst_name, s.da, s.pgn, iface)
        };
        let broadcast = sk.broadcast();
        match msg.name() {
            Some(name) => {
                let a = SockAddr::parse_for_send(name, ifindex, broadcast).map_err(errno)?;
                if a.name != J1939_NO_NAME || a.addr != J1939_NO_ADDR {
                    dst_name = a.name;
                    da = a.addr;
                }
                if pgn_is_valid(a.pgn) {
                    pgn = a.pgn;
                }
            }
            None => {
                if dst_name == J1939_NO_NAME && da == J1939_NO_ADDR && !broadcast {
                    return Err(errno(EACCES));
                }
            }
        }
        if is_transport_pgn(pgn) {
            return Err(errno(EDOM));
        }
        if len > MAX_SINGLE {
            let to = Route {
                ifindex,
                src_name,
                sa,
                dst_name,
                da,
                pgn,
            };
            return send_transport(sk, msg, len, &iface, to);
        }
        let mut data = [0u8; MAX_SINGLE];
        msg.copy_from_user(&mut data[..len])?;
        // NAMEs to addresses, and the checks of an outgoing claim, by the
        // interface's claim table (mainline's `j1939_ac_fixup`).
        let (sa, da) = {
            let mut ac = iface.ac.lock();
            ac.settle(now_ns());
            ac.fixup_send(src_name, sa, dst_name, da, pgn, &data[..len])
        }
        .map_err(errno)?;
        let id = Id {
            prio: sk_priority_to_prio(sk.priority()),
            pgn,
            sa,
            da,
        };
        let can_id = id.to_can_id();
        let idb = can_id.to_ne_bytes();
        let mut img = [0u8; 16];
        img[..4].copy_from_slice(&idb);
        img[4] = len as u8;
        img[8..8 + len].copy_from_slice(&data[..len]);
        let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENODEV)?;
        let nonblock = msg.flags() & glue::msg::DONTWAIT != 0;
        let mut skb = glue::can::skb::alloc_tx(sk, &dev, img.len(), nonblock)?;
        if !skb.put_data(&img) {
            return Err(glue::neterr::ENOBUFS());
        }
        skb.set_sock_params(sk);
        // Every send takes a timestamp key, as mainline's (whose single
        // frames are sessions too): the keys of transport sends count them.
        let key = sk.next_tskey();
        // The frame as its echo will be parsed (a PDU1 PGN without its
        // destination byte).
        let f = Frame::new(Id::from_can_id(can_id).unwrap_or(id), &data[..len]);
        j1939_echo::send(sk, iface.job.get(), &dev, skb, f, key)?;
        Ok(len)
    }

    /// Mainline `j1939_sk_recvmsg`: one message per call, `MSG_TRUNC` when
    /// the buffer is shorter; the control messages `SCM_J1939_DEST_ADDR`
    /// (unless the destination was broadcast), `SCM_J1939_DEST_NAME`
    /// (when known), `SCM_J1939_PRIO`, then the socket's timestamps; the
    /// source as a 24-byte `sockaddr_can`. Flags other than
    /// MSG_DONTWAIT, MSG_ERRQUEUE and MSG_CMSG_COMPAT are EINVAL.
    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        let allowed = glue::msg::DONTWAIT | glue::msg::ERRQUEUE | MSG_CMSG_COMPAT;
        if flags as u32 & !allowed != 0 {
            return Err(EINVAL);
        }
        if flags as u32 & glue::msg::ERRQUEUE != 0 {
            return sk.recv_errqueue(msg, len, SOL_CAN_J1939, SCM_J1939_ERRQUEUE);
        }
        let skb = sk.recv_datagram(flags)?;
        let n = skb.len() as usize;
        let size = if len < n {
            msg.add_flags(glue::msg::TRUNC);
            len
        } else {
            n
        };
        if let Err(e) = msg.copy_from_skb(&skb, 0, size) {
            sk.free_datagram(skb);
            return Err(e);
        }
        let mut cb = [0u8; CB_LEN];
        skb.cb_read(0, &mut cb);
        let u32_at = |i: usize| u32::from_ne_bytes([cb[i], cb[i + 1], cb[i + 2], cb[i + 3]]);
        let u64_at = |i: usize| {
            u64::from_ne_bytes([
                cb[i],
                cb[i + 1],
                cb[i + 2],
                cb[i + 3],
                cb[i + 4],
                cb[i + 5],
                cb[i + 6],
                cb[i + 7],
            ])
        };
        let da = cb[CB_DA];
        let dst_name = u64_at(CB_DST_NAME);
        if da != J1939_NO_ADDR {
            msg.put_cmsg(SOL_CAN_J1939, SCM_J1939_DEST_ADDR, &[da]);
        }
        if dst_name != J1939_NO_NAME {
            msg.put_cmsg(SOL_CAN_J1939, SCM_J1939_DEST_NAME, &dst_name.to_ne_bytes());
        }
        msg.put_cmsg(SOL_CAN_J1939, SCM_J1939_PRIO, &[cb[CB_PRIO]]);
        let src = SockAddr {
            ifindex: u32_at(CB_IFINDEX) as i32,
            name: u64_at(CB_SRC_NAME),
            pgn: u32_at(CB_PGN),
            addr: cb[CB_SA],
        };
        msg.set_name(&src.to_bytes());
        msg.recv_cmsgs(sk, &skb);
        msg.add_flags(u32_at(CB_FLAGS));
        sk.free_datagram(skb);
        Ok(size)
    }

    /// Mainline `j1939_sk_setsockopt`: `EINVAL` at another level;
    /// SO_J1939_FILTER (a multiple of 32 bytes, at most 512 filters, or
    /// none to remove them), SO_J1939_PROMISC and SO_J1939_ERRQUEUE (an
    /// `int`; turning the error queue off empties it), SO_J1939_SEND_PRIO
    /// (an `int` 0..7, `EDOM` otherwise, 0 and 1 need CAP_NET_ADMIN:
    /// `EPERM`); others `ENOPROTOOPT`. Process context.
    fn setsockopt(sk: &S, level: i32, name: i32, opt: &OptIn) -> Result {
        if level != SOL_CAN_J1939 {
            return Err(EINVAL);
        }
        match name {
            SO_J1939_FILTER => {
                let n = filter_count(opt.len()).map_err(errno)?;
                let mut filters = KVec::with_capacity(n, GFP_KERNEL)?;
                if n > 0 {
                    let mut raw = KVec::from_elem(0u8, n * Filter::SIZE, GFP_KERNEL)?;
                    opt.read(&mut raw)?;
                    for c in raw.chunks_exact(Filter::SIZE) {
                        let b: &[u8; Filter::SIZE] = c.try_into().map_err(|_| EINVAL)?;
                        filters.push(Filter::from_bytes(b), GFP_KERNEL)?;
                    }
                }
                let mut s = sk.lock();
                let old = core::mem::replace(&mut s.filters, filters);
                if s.bound || sk.shared().rx.get().is_some() {
                    if let Err(e) = publish(sk, &s) {
                        s.filters = old;
                        return Err(e);
                    }
                }
                Ok(())
            }
            SO_J1939_PROMISC | SO_J1939_ERRQUEUE => {
                let v = read_int(opt)?;
                let on = flag_option(&v).map_err(errno)?;
                let mut s = sk.lock();
                if name == SO_J1939_PROMISC {
                    let old = s.promisc;
                    s.promisc = on;
                    if s.bound || sk.shared().rx.get().is_some() {
                        if let Err(e) = publish(sk, &s) {
                            s.promisc = old;
                            return Err(e);
                        }
                    }
                } else {
                    s.errqueue = on;
                    sk.shared().errqueue.store(on, Ordering::Relaxed);
                    // Off: what was queued goes (mainline's
                    // skb_queue_purge). A notification whose check of
                    // the flag came before the store above may still
                    // land after the purge, as on mainline.
                    if !on {
                        sk.purge_errqueue();
                    }
                }
                Ok(())
            }
            SO_J1939_SEND_PRIO => {
                let v = read_int(opt)?;
                let prio = send_prio_option(&v, glue::netdev::capable_net_admin()).map_err(errno)?;
                let _s = sk.lock();
                sk.set_priority(prio_to_sk_priority(prio));
                Ok(())
            }
            _ => Err(glue::neterr::ENOPROTOOPT()),
        }
    }

    /// Mainline `j1939_sk_getsockopt`: `EINVAL` at another level or for a
    /// negative length; SO_J1939_PROMISC, SO_J1939_ERRQUEUE (0 or 1) and
    /// SO_J1939_SEND_PRIO as an `int`, `EFAULT` if the buffer is shorter
    /// (mainline's answer); others `ENOPROTOOPT`.
    fn getsockopt(sk: &S, level: i32, name: i32, opt: &OptOut) -> Result {
        if level != SOL_CAN_J1939 {
            return Err(EINVAL);
        }
        let ulen = opt.len()?;
        if ulen < 0 {
            return Err(EINVAL);
        }
        let v: i32 = {
            let s = sk.lock();
            match name {
                SO_J1939_PROMISC => i32::from(s.promisc),
                SO_J1939_ERRQUEUE => i32::from(s.errqueue),
                SO_J1939_SEND_PRIO => i32::from(sk_priority_to_prio(sk.priority())),
                _ => return Err(glue::neterr::ENOPROTOOPT()),
            }
        };
        if ulen < 4 {
            return Err(EFAULT);
        }
        opt.set_len(4)?;
        opt.write(&v.to_ne_bytes())
    }
}

/// Where a message goes: the socket's interface, its source and
/// destination (NAMEs and addresses, before the claim table resolves
/// them), the PGN.
struct Route {
    ifindex: i32,
    src_name: u64,
    sa: u8,
    dst_name: u64,
    da: u8,
    pgn: u32,
}

/// `sendmsg` of a message over 8 bytes (mainline's `j1939_sk_send_loop`
/// and `j1939_tp_send`): `EMSGSIZE` over 117,440,505 bytes,
/// `EDESTADDRREQ` for ETP (over 1785) to broadcast, the claim table's
/// errors; then the message is copied, the socket's previous session
/// waited for (mainline queues it instead; with MSG_DONTWAIT `EAGAIN`,
/// a signal `ERESTARTSYS`, SO_SNDTIMEO `EAGAIN`), and a TP, BAM or ETP
/// session started (`EBUSY` while one with the same source, destination
/// and kind runs, from any socket). Returns `len` once the RTS or BAM
/// is out; how the session ends is reported later (an abort as the
/// socket's error). Process context.
fn send_transport(sk: &S, msg: &mut Msg, len: usize, iface: &Iface, to: Route) -> Result<usize> {
    // The kind only decides the errors here: a NAME is a unicast
    // destination whatever address it resolves to.
    let da_kind = if to.dst_name != J1939_NO_NAME { 0 } else { to.da };
    kind_for(len, da_kind).map_err(errno)?;
    let mut data = KVVec::from_elem(0u8, len, GFP_KERNEL)?;
    msg.copy_from_user(&mut data)?;
    let (sa, da) = {
        let mut ac = iface.ac.lock();
        ac.settle(now_ns());
        ac.fixup_send(to.src_name, to.sa, to.dst_name, to.da, to.pgn, &data)
    }
    .map_err(errno)?;
    let id = Id {
        prio: sk_priority_to_prio(sk.priority()),
        pgn: to.pgn,
        sa,
        da,
    };
    let dev = DevRef::by_index(sk.net(), to.ifindex).ok_or(ENODEV)?;
    claim_tx(sk, msg.flags() & glue::msg::DONTWAIT != 0)?;
    if let Err(e) = j1939_tp::start_tx(iface, iface.job.get(), &dev, sk, id, data) {
        sk.shared().tx_busy.store(false, Ordering::Release);
        WAITQ.wake_all();
        return Err(e);
    }
    Ok(len)
}

/// Makes `sk` the owner of a transport session (its
/// [`J1939Shared::tx_busy`]), waiting for its previous one to end:
/// `EAGAIN` if `nonblock` or SO_SNDTIMEO ran out, `ERESTARTSYS` on a
/// signal. Process context.
fn claim_tx(sk: &S, nonblock: bool) -> Result {
    let busy = &sk.shared().tx_busy;
    loop {
        if busy
            .compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire)
            .is_ok()
        {
            return Ok(());
        }
        if nonblock {
            return Err(EAGAIN);
        }
        match WAITQ.wait(sk.sndtimeo(false), &|| !busy.load(Ordering::Acquire)) {
            Waited::Ready => {}
            Waited::TimedOut => return Err(EAGAIN),
            Waited::Interrupted => return Err(ERESTARTSYS),
        }
    }
}

/// Waits (interruptibly) until `sk` has no transport session. Process
/// context.
fn wait_idle(sk: &S) -> Waited {
    let busy = &sk.shared().tx_busy;
    WAITQ.wait(i64::MAX, &|| !busy.load(Ordering::Acquire))
}

/// An `int` option's 4 bytes: `EINVAL` for another length (before the
/// value is read, as mainline), `EFAULT` on a bad pointer.
fn read_int(opt: &OptIn) -> Result<[u8; 4]> {
    if opt.len() != 4 {
        return Err(EINVAL);
    }
    let mut v = [0u8; 4];
    opt.read(&mut v)?;
    Ok(v)
}

/// `MSG_CMSG_COMPAT` of `<linux/socket.h>`.
const MSG_CMSG_COMPAT: u32 = 0x8000_0000;

/// The family of a J1939 `sockaddr_can` (checked by the core's parser).
const _: () = assert!(AF_CAN == 29 && SOCKADDR_J1939_LEN == 24);

/// The module: its registrations, undone when it is dropped (unload).
pub(crate) struct J1939Module {
    _reg: ProtoRegistration<J1939Proto>,
}

impl ScopedModule for J1939Module {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let reg = MODULE.register(c_str!("CAN_J1939"), scope)?;
        pr_info!("CAN_J1939 ({}) registered\n", CAN_J1939);
        Ok(J1939Module { _reg: reg })
    }
}
