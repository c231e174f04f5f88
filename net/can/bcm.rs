// SPDX-License-Identifier: GPL-2.0

//! rcan_bcm: CAN_BCM, mainline SocketCAN's broadcast manager, on the rcan
//! stack (DESIGN decision 12, issue 13).
//!
//! `socket(PF_CAN, SOCK_DGRAM, CAN_BCM)`, `connect()` to an interface
//! (ifindex 0: any), then one `struct bcm_msg_head` plus frames per
//! `write()`; replies and notifications come back from `read()` in the
//! same format. The message checks, the transmit schedule and the receive
//! change detection are the pure, host-tested state machines of
//! `rcan_core::bcm`, `bcm_tx` and `bcm_rx`; this file gives them sockets,
//! timers, a receive subscription and a transmit path. See
//! Documentation/networking/rcan/bcm.rst.
//!
//! Objects and their locks (lock order: RTNL, socket lock, `rx_ops`,
//! an operation's `state`; the receive table's mutex inside `rx_set` is
//! only taken with the socket lock and neither spinlock held):
//!
//! * [`BcmSock`] (socket lock): connection, transmit operations.
//! * [`BcmShared`]: `bound` (atomic, the lockless ENOTCONN check of
//!   sendmsg) and the receive operations `rx_ops`, a `BhLock`
//!   (`spin_lock_bh`, lockdep class `bcm_rx_ops`) because the receive
//!   callback walks them in NET_RX softirq context; only process context
//!   with the socket lock held changes the list.
//! * An operation ([`OpData`], one [`JobTimers`] with two timers) holds
//!   its state machine, frames and last received frames under `state`, a
//!   `BhLock` of class `bcm_op_state`, taken by sendmsg (process), the
//!   receive callback (NET_RX softirq) and its timer callbacks
//!   (HRTIMER_SOFTIRQ softirq).
//!
//! No hardirq handler takes either lock, so they disable bottom halves,
//! not interrupts (mainline's `bcm_rx_update_lock` and `bcm_tx_lock` are
//! `spin_lock_bh` locks too). Messages for user space are queued under
//! `state` (`sock_queue_rcv_skb`: it takes the receive queue's lock with
//! interrupts saved, may run a socket filter and wakes readers, all of
//! which softirq context allows; mainline queues RX_CHANGED under
//! `bcm_rx_update_lock` in the same way), so one operation's messages
//! keep their order. Frames are sent after `state` is released: the driver's
//! transmit path runs outside the operation's lock, as in mainline. A
//! transmit operation's frame is copied out of the operation under `state`
//! ([`TxFrame`], mainline's "read currframe under lock protection") and its
//! skb built and sent after the lock is released (mainline `bcm_can_tx`);
//! remote-frame replies of receive operations are built under `state` and
//! sent after it (`Pending`).
//!
//! Contexts: system calls and the netdevice notifier run in process
//! context; [`BcmProto::rx`] in NET_RX softirq under RCU; the timer
//! callbacks ([`BcmOp::expired`]) in the HRTIMER_SOFTIRQ softirq (the
//! timers are `HRTIMER_MODE_ABS_SOFT` on CLOCK_MONOTONIC, like mainline's
//! `_SOFT` timers).
//!
//! Timers never outlive their socket: every operation holds a counted
//! reference on the sock; `release` unsubscribes the socket, takes every
//! operation off its lists and drops it, and dropping a [`JobTimers`]
//! cancels its timers and waits for a running callback before the memory
//! goes (rust/glue/jobtimer.rs). A callback that lost a race with a
//! cancellation (it was already running when sendmsg or the notifier
//! cancelled without waiting) finds the operation's recorded expiry gone
//! or in the future and does nothing. The module cannot be unloaded while
//! a socket exists (each socket holds a module reference).

#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::fmt::Write;
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use kernel::prelude::*;

use glue::hrtimer::ktime_get_mono_ns;
use glue::jobtimer::{JobCallback, JobRef, JobTimers, OnceBox};
use glue::lock::{new_bh_spinlock, BhLock};
use glue::net::Net;
use glue::netdev::{DevRef, NetDev};
use glue::neterr;
use glue::procfs::{NetProcDir, NetProcDirReg, ProcEntry, ProcShow, SeqFile};
use glue::skb::UniqueSkb;
use glue::sock::{Msg, OptIn, OptOut, Sock, SockRef, SockView};
use glue::sync::Rtnl;
use crate::glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use kernel::str::CString;
use rcan_api::{
    CanProtocol, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter, RxSkb, Sockets,
    RX_FILTER_CAN_ID, SOCK_DGRAM,
};
use rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK};
use rcan_core::bcm::{
    self as wire, MsgHead, OpKey, Request, CAN_FD_FRAME, MAX_NFRAMES, MHSIZ, RX_CHECK_DLC,
    RX_DELETE, RX_READ, RX_RTR_FRAME, RX_SETUP, TX_CP_CAN_ID, TX_DELETE, TX_READ, TX_SEND,
    TX_SETUP,
};
use rcan_core::bcm_rx::{RxOp, RxOut, RxSlot, TRAFFIC_LOCAL, TRAFFIC_OWN};
use rcan_core::bcm_tx::{TxOp, TxOut};
use rcan_core::frame::{AnyFrame, CanFdFrame, CANFD_MTU};

/// `CAN_BCM` in `<linux/can.h>`.
const CAN_BCM: i32 = 2;
/// Bytes of `struct sockaddr_can` BCM requires and returns
/// (`BCM_MIN_NAMELEN`: family, padding, ifindex).
const BCM_MIN_NAMELEN: usize = 8;
/// The CAN FD flags mainline leaves in a frame it hands to user space
/// (`BCM_CAN_FLAGS_MASK`).
const CAN_FLAGS_MASK: u8 = 0x07;

/// Timer slots of an operation: a transmit operation uses its first as
/// the cyclic timer; a receive operation its first for the timeout
/// (`ival1`) and its second for the throttle (`ival2`).
const TX_TIMER: usize = 0;
const RX_TIMEOUT_TIMER: usize = 0;
const RX_THROTTLE_TIMER: usize = 1;

/// The most a write is read: a head and 257 frames of the larger kind
/// (more can never pass the checks, which then see only as many bytes as
/// mainline would have read).
const fn max_read(cfsiz: usize) -> usize {
    MHSIZ + (MAX_NFRAMES as usize + 1) * cfsiz
}

/// Mainline's `REGMASK`: the identifier with its frame format and RTR
/// bit must match exactly.
fn regmask(can_id: u32) -> u32 {
    if can_id & CAN_EFF_FLAG != 0 {
        CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG
    } else {
        CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG
    }
}

fn errno(e: i32) -> Error {
    glue::errno(e)
}

// ---------------------------------------------------------------------------
// Operations

/// An operation's timers and callbacks (the [`JobCallback`] marker).
struct BcmOp;

type Job = JobTimers<BcmOp>;

/// One operation: what names it, its socket and its locked state.
struct OpData {
    /// The socket it belongs to (a counted reference: the sock outlives
    /// the operation's timers).
    sk: SockRef<BcmProto>,
    /// Identifier, interface, CAN FD: fixed for the operation's life.
    key: OpKey,
    /// A transmit operation (`state` holds `OpState::Tx`); fixed, so that
    /// a timer callback knows its kind without taking `state` twice.
    tx: bool,
    /// Receive operations: whether it is part of the socket's receive
    /// subscription (cleared when its interface goes away). Written with
    /// the socket lock held.
    active: AtomicBool,
    /// Transmit: frames sent (the driver took them); receive: frames
    /// received. Mainline's `frames_abs`, shown in /proc/net/can-bcm.
    frames_abs: AtomicU64,
    /// Receive: RX_CHANGED messages made (mainline's `frames_filtered`).
    frames_filtered: AtomicU64,
    /// The state machine, frames and last frames. `spin_lock_bh`, lock
    /// class `bcm_op_state`: process context and softirqs, never hardirq;
    /// see the module documentation.
    state: BhLock<OpState>,
}

enum OpState {
    Tx(TxState),
    Rx(RxState),
}

struct TxState {
    op: TxOp,
    /// Interface the frames go out on (never 0).
    ifindex: i32,
    /// Bytes per frame (16, or 72 with CAN_FD_FRAME).
    cfsiz: usize,
    /// Room for the frames of the first setup (updates may use fewer).
    frames: KVec<u8>,
}

struct RxState {
    op: RxOp,
    /// Bytes per frame (16, or 72 with CAN_FD_FRAME).
    cfsiz: usize,
    /// The filter frames as set (RX_STATUS returns them), with room for
    /// the first setup's number.
    raw: KVec<u8>,
    /// The same frames in the CAN FD layout (a classic frame is the first
    /// 16 bytes of one), for the comparison.
    filters: KVec<CanFdFrame>,
    /// Last frame received per filter entry (at least one slot).
    last: KVec<RxSlot>,
    /// `skb->tstamp` (ns) of the last frame received for this operation:
    /// RX_CHANGED carries it, as mainline's `op->rx_stamp` (SO_TIMESTAMP
    /// reports the frame's reception, not the message's creation).
    rx_stamp: i64,
}

/// Remote-frame replies to send once the state lock is released: a
/// received frame makes at most one per matching operation, and at most
/// two operations of a socket match a frame (its interface's and "any"'s).
struct Pending {
    sends: [Option<(UniqueSkb, DevRef)>; 2],
}

impl Pending {
    fn new() -> Self {
        Pending {
            sends: [None, None],
        }
    }

    fn push(&mut self, skb: UniqueSkb, dev: DevRef) {
        if let Some(slot) = self.sends.iter_mut().find(|s| s.is_none()) {
            *slot = Some((skb, dev));
        }
        // Full (cannot happen, see above): the skb is freed here.
    }

    /// Sends with loopback, as mainline's BCM always does; errors are
    /// dropped as mainline's `bcm_can_tx` drops them. Process or softirq
    /// context, no spinlock held.
    ///
    /// Returns how many went out.
    fn flush(self) -> u64 {
        let mut sent = 0;
        for (skb, dev) in self.sends.into_iter().flatten() {
            if rcan_api::send(skb, &dev, true).is_ok() {
                sent += 1;
            }
        }
        sent
    }
}

/// An skb carrying one frame image (`bytes`, `cfsiz` long) for `dev`,
/// owned by `sk`. Any context (GFP_ATOMIC).
fn frame_skb(sk: &V, dev: &NetDev, bytes: &[u8]) -> Option<UniqueSkb> {
    glue::can::skb::alloc_image_for(sk, dev, bytes, glue::GFP_ATOMIC)
}

/// Queues a message (`head` and the frame bytes in `frames`) for `sk`'s
/// reader, naming `ifindex` as its source and with `flags` for recvmsg;
/// `tstamp` (ns, 0: none) becomes the skb's timestamp, which recvmsg
/// reports (SO_TIMESTAMP...). Process or softirq context (GFP_ATOMIC),
/// `state` may be held; a full receive queue drops it, as mainline.
fn to_user(sk: &V, head: &MsgHead, frames: &[&[u8]], ifindex: i32, flags: u32, tstamp: i64) {
    let len: usize = MHSIZ + frames.iter().map(|f| f.len()).sum::<usize>();
    let Some(mut skb) = UniqueSkb::alloc(len as u32, glue::GFP_ATOMIC) else {
        return;
    };
    if !skb.put_data(&head.to_bytes()) || !frames.iter().all(|f| skb.put_data(f)) {
        return;
    }
    glue::can::skb::set_rx_meta(&mut skb, ifindex, flags);
    if tstamp != 0 {
        skb.set_tstamp(tstamp);
    }
    if sk.queue_rcv(skb.into_owned()).is_err() {
        // Mainline's dropped_usr_msgs.
        sk.shared().dropped.fetch_add(1, Ordering::Relaxed);
    }
}

/// The frame a transmit operation's state machine sent in one event (at
/// most one: see [`TxOut`]): its interface (held) and its image, copied
/// out of the operation under `state`, so that the skb is built and sent
/// after the lock is released (mainline `bcm_can_tx`).
struct TxFrame {
    dev: DevRef,
    image: [u8; CANFD_MTU],
    /// Bytes of `image` in use: the operation's `cfsiz` (16 or 72).
    len: usize,
}

impl TxFrame {
    /// Builds the skb (owned by `sk`) and sends it with loopback, as
    /// mainline's BCM always does; errors are dropped as mainline's
    /// `bcm_can_tx` drops them. Process or softirq context, no spinlock
    /// held. Returns whether the driver took the frame.
    fn send(self, sk: &V) -> bool {
        let Some(image) = self.image.get(..self.len) else {
            return false;
        };
        match frame_skb(sk, &self.dev, image) {
            Some(skb) => rcan_api::send(skb, &self.dev, true).is_ok(),
            None => false,
        }
    }
}

/// The effects of a transmit operation's state machine.
struct TxEffects<'a, 'p> {
    job: JobRef<'a, BcmOp>,
    sk: &'a V,
    ifindex: i32,
    cfsiz: usize,
    frames: &'a [u8],
    /// The frame to send once `state` is released.
    sent: &'p mut Option<TxFrame>,
    /// Outside the timer callback: the expiry to arm once the pending
    /// frames are sent (see [`with_tx`]); `None` arms at once.
    arm_later: Option<&'p mut Option<u64>>,
}

impl TxOut for TxEffects<'_, '_> {
    fn send(&mut self, index: usize) -> bool {
        let Some(dev) = DevRef::by_index(self.sk.net(), self.ifindex) else {
            return false;
        };
        let Some(bytes) = self
            .frames
            .get(index * self.cfsiz..(index + 1) * self.cfsiz)
        else {
            return true;
        };
        // One frame per event (TxOut); a second would be dropped, as the
        // skb of a failed allocation is.
        if self.sent.is_none() {
            let mut image = [0u8; CANFD_MTU];
            if let Some(dst) = image.get_mut(..bytes.len()) {
                dst.copy_from_slice(bytes);
                *self.sent = Some(TxFrame {
                    dev,
                    image,
                    len: bytes.len(),
                });
            }
        }
        true
    }

    fn to_user(&mut self, head: &MsgHead, with_frames: bool) {
        let n = if with_frames {
            (head.nframes as usize * self.cfsiz).min(self.frames.len())
        } else {
            0
        };
        // Mainline names no interface in transmit notifications.
        to_user(self.sk, head, &[&self.frames[..n]], 0, 0, 0);
    }

    fn arm(&mut self, at: u64) {
        match &mut self.arm_later {
            Some(later) => **later = Some(at),
            None => self.job.start(TX_TIMER, at),
        }
    }

    fn cancel(&mut self) {
        if let Some(later) = &mut self.arm_later {
            **later = None;
        }
        self.job.try_cancel(TX_TIMER);
    }
}

/// The effects of a receive operation's state machine.
struct RxEffects<'a, 'p> {
    job: JobRef<'a, BcmOp>,
    sk: &'a V,
    raw: &'a [u8],
    cfsiz: usize,
    /// The operation's `rx_stamp`, for RX_CHANGED.
    rx_stamp: i64,
    pending: &'p mut Pending,
}

impl RxOut for RxEffects<'_, '_> {
    fn to_user(&mut self, head: &MsgHead, frame: Option<(&CanFdFrame, u8)>, rx_ifindex: i32) {
        match frame {
            Some((f, traffic)) => {
                let mut f = *f;
                f.flags &= CAN_FLAGS_MASK;
                let mut flags = 0;
                if traffic & TRAFFIC_LOCAL != 0 {
                    flags |= glue::msg::DONTROUTE;
                }
                if traffic & TRAFFIC_OWN != 0 {
                    flags |= glue::msg::CONFIRM;
                }
                // RX_CHANGED: the timestamp of the last frame received
                // (mainline's bcm_rx_changed: has_timestamp).
                self.job
                    .data()
                    .frames_filtered
                    .fetch_add(1, Ordering::Relaxed);
                // The frame as received: 16 bytes, or 72 for CAN FD.
                let image = f.to_bytes();
                let n = self.cfsiz.min(image.len());
                to_user(
                    self.sk,
                    head,
                    &[&image[..n]],
                    rx_ifindex,
                    flags,
                    self.rx_stamp,
                );
            }
            None => {
                // RX_TIMEOUT, RX_STATUS: none, as mainline.
                let n = (head.nframes as usize * self.cfsiz).min(self.raw.len());
                to_user(self.sk, head, &[&self.raw[..n]], rx_ifindex, 0, 0);
            }
        }
    }

    fn send_reply(&mut self, reply: &CanFdFrame, ifindex: i32) {
        let Some(dev) = DevRef::by_index(self.sk.net(), ifindex) else {
            return;
        };
        let image = reply.to_bytes();
        let n = self.cfsiz.min(image.len());
        if let Some(skb) = frame_skb(self.sk, &dev, &image[..n]) {
            self.pending.push(skb, dev);
        }
    }

    fn arm_timeout(&mut self, at: u64) {
        self.job.start(RX_TIMEOUT_TIMER, at);
    }

    fn cancel_timeout(&mut self) {
        self.job.try_cancel(RX_TIMEOUT_TIMER);
    }

    fn arm_throttle(&mut self, at: u64) {
        self.job.start(RX_THROTTLE_TIMER, at);
    }

    fn cancel_throttle(&mut self) {
        self.job.try_cancel(RX_THROTTLE_TIMER);
    }
}

/// Runs `f` on a transmit operation's state machine with its effects;
/// sends afterwards. Any context but hardirq; `state` not held.
///
/// Outside the timer callback (`in_callback` false: sendmsg, notifier)
/// the timer is armed only after the frame of `TX_ANNOUNCE`/`STARTTIMER`
/// went out, so the first cyclic frame cannot overtake it (the callback
/// may run on another CPU as soon as the timer is armed; mainline sends
/// the announced frame before it starts the timer); returns `None`.
/// Inside the callback the expiry to re-arm at is returned, and the
/// callback hands it to the timer core (`HRTIMER_RESTART`, as mainline's
/// `bcm_tx_timeout_handler`): one timer-base lock round per cyclic frame
/// less than a second `hrtimer_start`.
fn with_tx(
    job: JobRef<'_, BcmOp>,
    in_callback: bool,
    f: impl FnOnce(&mut TxOp, &mut TxEffects<'_, '_>),
) -> Option<u64> {
    let d = job.data();
    let sk = d.sk.sock();
    let mut sent = None;
    let mut later = None;
    {
        let mut st = d.state.lock();
        if let OpState::Tx(t) = &mut *st {
            let TxState {
                op,
                ifindex,
                cfsiz,
                frames,
            } = t;
            let mut out = TxEffects {
                job,
                sk: &sk,
                ifindex: *ifindex,
                cfsiz: *cfsiz,
                frames,
                sent: &mut sent,
                arm_later: Some(&mut later),
            };
            f(op, &mut out);
        }
    }
    if sent.is_some_and(|frame| frame.send(&sk)) {
        d.frames_abs.fetch_add(1, Ordering::Relaxed);
    }
    if in_callback {
        return later;
    }
    // A callback that runs meanwhile finds the recorded expiry in the
    // future and does nothing (and re-arms nothing).
    if let Some(at) = later {
        job.start(TX_TIMER, at);
    }
    None
}

/// Runs `f` on a receive operation's state machine with its effects and
/// its filters and last frames; frames to send go to `pending`.
/// `rx_stamp`: a received frame's timestamp to record first. Process or
/// softirq context; `state` not held.
fn with_rx(
    job: JobRef<'_, BcmOp>,
    pending: &mut Pending,
    rx_stamp: Option<i64>,
    f: impl FnOnce(&mut RxOp, &[CanFdFrame], &mut [RxSlot], &mut RxEffects<'_, '_>),
) {
    let d = job.data();
    let sk = d.sk.sock();
    let mut st = d.state.lock();
    if let OpState::Rx(r) = &mut *st {
        let RxState {
            op,
            cfsiz,
            raw,
            filters,
            last,
            rx_stamp: stamp,
        } = r;
        if let Some(t) = rx_stamp {
            *stamp = t;
        }
        let mut out = RxEffects {
            job,
            sk: &sk,
            raw,
            cfsiz: *cfsiz,
            rx_stamp: *stamp,
            pending,
        };
        f(op, filters, last, &mut out);
    }
}

impl JobCallback for BcmOp {
    type Data = OpData;

    /// Not called: the timer core calls [`BcmOp::expired_restart`].
    fn expired(job: JobRef<'_, Self>, which: usize) {
        if let Some(at) = Self::expired_restart(job, which) {
            job.start(which, at);
        }
    }

    /// HRTIMER_SOFTIRQ softirq. A stale expiry (the operation's record
    /// says the timer was cancelled or moved later) does nothing. A
    /// transmit operation's timer re-arms by its return value
    /// (`HRTIMER_RESTART`); receive timers are started explicitly.
    fn expired_restart(job: JobRef<'_, Self>, which: usize) -> Option<u64> {
        let now = ktime_get_mono_ns() as u64;
        let due = |at: Option<u64>| at.is_some_and(|t| t <= now);
        if job.data().tx {
            return with_tx(job, true, |op, out| {
                if which == TX_TIMER && due(op.expires) {
                    op.timer_expired(now, out);
                }
            });
        }
        let mut pending = Pending::new();
        with_rx(job, &mut pending, None, |op, _filters, last, out| {
            if which == RX_TIMEOUT_TIMER && due(op.timeout_at) {
                op.timeout_expired(last, out);
            } else if which == RX_THROTTLE_TIMER && due(op.throttle_at) {
                op.throttle_expired(now, last, out);
            }
        });
        pending.flush();
        None
    }
}

/// A new operation of `sk` with `state`. Process context.
fn new_job(sk: &S, key: OpKey, state: OpState) -> Result<Job> {
    let tx = matches!(state, OpState::Tx(_));
    let state = new_bh_spinlock!(state, "bcm_op_state")?;
    JobTimers::new(OpData {
        sk: sk.to_ref(),
        key,
        tx,
        active: AtomicBool::new(true),
        frames_abs: AtomicU64::new(0),
        frames_filtered: AtomicU64::new(0),
        state,
    }, sk)
}

// ---------------------------------------------------------------------------
// The socket

/// A socket's receive operations, walked by the receive callback.
struct RxOps {
    ops: KVec<Job>,
}

/// A CAN_BCM socket's state, protected by its socket lock.
struct BcmSock {
    /// connect() succeeded (and no device removal undid it).
    bound: bool,
    /// The interface of connect() (0: any).
    ifindex: i32,
    /// Transmit operations.
    tx_ops: KVec<Job>,
    /// `/proc/net/can-bcm/<inode>` while connected (made by connect,
    /// removed by release and by the removal of the connected interface,
    /// as mainline). Dropped only after the socket lock is released: the
    /// drop waits for readers, whose `show` takes the socket lock.
    proc: Option<ProcEntry<ProcView>>,
}

/// What the receive path and the lockless checks need.
struct BcmShared {
    /// Mirrors `BcmSock::bound` (written under the socket lock).
    bound: AtomicBool,
    /// Messages for user space dropped because the receive queue was
    /// full (mainline's `dropped_usr_msgs`).
    dropped: AtomicU64,
    /// The receive operations (`spin_lock_bh`, lock class `bcm_rx_ops`:
    /// process context and the NET_RX softirq), allocated by the first
    /// connect(). Changed only with the socket lock held.
    rx: OnceBox<BhLock<RxOps>>,
}

struct BcmProto;

/// This module's registrations (proto, CAN protocol, notifier).
static MODULE: ProtoModule<BcmProto> = ProtoModule::new();

/// `/proc/net/can-bcm` in every network namespace: one file per connected
/// socket of that namespace, named by its inode number (mainline's
/// `bcm_proc_show` format).
static PROC: NetProcDir = NetProcDir::new(c_str!("can-bcm"));

/// What `/proc/net/can-bcm/<inode>` shows: its socket (a counted
/// reference, dropped with the file).
struct ProcView {
    sk: SockRef<BcmProto>,
}

/// An interface as mainline's `bcm_proc_getifname` names it: "any" for
/// 0, "???" if it is gone. Pads (`{:<5}`) like `%-5s`.
struct IfName<'a>(i32, &'a Net);

impl core::fmt::Display for IfName<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.0 == 0 {
            return f.pad("any");
        }
        match DevRef::by_index(self.1, self.0) {
            Some(d) => f.pad(d.name().as_str()),
            None => f.pad("???"),
        }
    }
}

/// `[n]` for classic operations, `(n)` for CAN FD ones.
fn nframes_text(flags: u32, n: u32) -> (char, u32, char) {
    if flags & CAN_FD_FRAME != 0 {
        ('(', n, ')')
    } else {
        ('[', n, ']')
    }
}

impl ProcShow for ProcView {
    /// Mainline's `bcm_proc_show`: a header, then each receive operation
    /// that has received something, then each transmit operation, newest
    /// first, then an empty line. Process context (a read of the file):
    /// takes the socket lock, the receive list's and each operation's
    /// `state` lock.
    fn show(&self, m: &mut SeqFile<'_>) {
        let sk = self.sk.in_process(m.process());
        let s = sk.lock();
        let _ = m.write_str(">>> socket ");
        m.write_kaddr(sk.socket_kaddr());
        let _ = m.write_str(" / sk ");
        m.write_kaddr(sk.kaddr());
        let _ = m.write_str(" / bo ");
        m.write_kaddr(sk.kaddr());
        let _ = writeln!(
            m,
            " / dropped {} / bound {} <<<",
            sk.shared().dropped.load(Ordering::Relaxed),
            IfName(s.ifindex, sk.net())
        );
        if let Some(list) = sk.shared().rx.get() {
            let l = list.lock();
            for j in l.ops.iter().rev() {
                let d = j.data();
                let abs = d.frames_abs.load(Ordering::Relaxed);
                if abs == 0 {
                    continue;
                }
                let filtered = d.frames_filtered.load(Ordering::Relaxed);
                let st = d.state.lock();
                let OpState::Rx(r) = &*st else {
                    continue;
                };
                let op = &r.op;
                let (o, n, c) = nframes_text(op.flags, op.nframes);
                let dlc = if op.flags & RX_CHECK_DLC != 0 {
                    'd'
                } else {
                    ' '
                };
                let _ = write!(
                    m,
                    "rx_op: {:03X} {:<5} {o}{n}{c}{dlc} ",
                    op.can_id,
                    IfName(op.ifindex, sk.net())
                );
                let (t1, t2) = (op.ival1.to_ns() / 1000, op.ival2.to_ns() / 1000);
                if t1 != 0 {
                    let _ = write!(m, "timeo={t1} ");
                }
                if t2 != 0 {
                    let _ = write!(m, "thr={t2} ");
                }
                let reduction = 100 - (filtered.saturating_mul(100) / abs) as i64;
                let near = if reduction == 100 { "near " } else { "" };
                let _ = writeln!(
                    m,
                    "# recv {filtered} ({abs}) => reduction: {near}{reduction}%"
                );
            }
        }
        for j in s.tx_ops.iter().rev() {
            let d = j.data();
            let st = d.state.lock();
            let OpState::Tx(t) = &*st else {
                continue;
            };
            let op = &t.op;
            let (o, n, c) = nframes_text(op.flags, op.nframes);
            let _ = write!(
                m,
                "tx_op: {:03X} {} {o}{n}{c} ",
                op.can_id,
                IfName(t.ifindex, sk.net())
            );
            let (t1, t2) = (op.ival1().to_ns() / 1000, op.ival2().to_ns() / 1000);
            if t1 != 0 {
                let _ = write!(m, "t1={t1} ");
            }
            if t2 != 0 {
                let _ = write!(m, "t2={t2} ");
            }
            let _ = writeln!(m, "# sent {}", d.frames_abs.load(Ordering::Relaxed));
        }
        let _ = m.write_str("\n");
    }
}

type S = Sock<BcmProto>;
/// A BCM socket in any context (the receive callback, the operations'
/// timers): no socket lock.
type V = SockView<BcmProto>;

/// Finds the position of the operation named `key` in `ops`.
fn find(ops: &[Job], key: &OpKey) -> Option<usize> {
    ops.iter().position(|j| j.data().key == *key)
}

/// (Re)subscribes `sk` to the identifiers of its active receive
/// operations, on their interface if they share one, else on all
/// (the callback then checks each operation's interface); with none, the
/// subscription goes. Process context; socket lock held (it serialises
/// changes of the list, so its length cannot change between the two
/// looks). ENOMEM.
fn rx_register(sk: &S) -> Result {
    let Some(list) = sk.shared().rx.get() else {
        rcan_api::rx_remove(sk);
        return Ok(());
    };
    let n = list.lock().ops.len();
    let mut fs: KVec<RxFilter> = KVec::with_capacity(n, GFP_KERNEL)?;
    let mut ifindex: Option<i32> = None;
    let mut mixed = false;
    {
        let l = list.lock();
        for j in l.ops.iter() {
            let d = j.data();
            if !d.active.load(Ordering::Relaxed) {
                continue;
            }
            // Within the capacity reserved above: no allocation.
            fs.push(
                RxFilter {
                    kind: RX_FILTER_CAN_ID,
                    id: d.key.can_id,
                    mask: regmask(d.key.can_id),
                },
                GFP_ATOMIC,
            )?;
            match ifindex {
                None => ifindex = Some(d.key.ifindex),
                Some(i) if i != d.key.ifindex => mixed = true,
                _ => {}
            }
        }
    }
    if fs.is_empty() {
        rcan_api::rx_remove(sk);
        return Ok(());
    }
    let ifindex = if mixed { 0 } else { ifindex.unwrap_or(0) };
    rcan_api::rx_set(sk, 0, ifindex, &fs, false, 0)
}

/// Adds `job` to the receive list. Process context; socket lock held.
fn rx_add(list: &BhLock<RxOps>, job: Job) -> Result {
    let n = list.lock().ops.len();
    // Grow outside the spinlock: move the operations into a larger vector
    // under it (no allocation there).
    let mut bigger: KVec<Job> = KVec::with_capacity(n + 1, GFP_KERNEL)?;
    let old = {
        let mut l = list.lock();
        if l.ops.len() < l.ops.capacity() {
            l.ops.push(job, GFP_ATOMIC)?;
            return Ok(());
        }
        while let Some(j) = glue::kvec_swap_remove(&mut l.ops, 0) {
            bigger.push(j, GFP_ATOMIC)?;
        }
        bigger.push(job, GFP_ATOMIC)?;
        core::mem::replace(&mut l.ops, bigger)
    };
    drop(old);
    Ok(())
}

/// Takes the receive operation named `key` off the list. Process context;
/// socket lock held. The caller drops it after the lock is released.
fn rx_take(list: &BhLock<RxOps>, key: &OpKey) -> Option<Job> {
    let mut l = list.lock();
    let i = find(&l.ops, key)?;
    glue::kvec_swap_remove(&mut l.ops, i)
}

impl CanProtocol for BcmProto {
    const PROTOCOL: i32 = CAN_BCM;
    const SOCK_TYPE: i32 = SOCK_DGRAM;
    /// All state is in the socket; devices are looked up in the
    /// socket's namespace.
    const ALL_NAMESPACES: bool = true;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// NET_RX softirq, RCU read side (mainline `bcm_rx_handler`, for every
    /// operation of the socket the frame is for).
    fn rx(sk: &SockView<Self>, skb: RxSkb<'_>, _cookie: u32) {
        let s = skb.skb();
        // A classic or a CAN FD frame (mainline: can_is_can_skb,
        // can_is_canfd_skb); each operation takes its own kind.
        let Some(frame) = AnyFrame::parse(s.data()) else {
            skb.done();
            return;
        };
        let fd = frame.is_fd();
        let can_id = frame.can_id();
        let ifindex = skb.ifindex();
        let tstamp = s.tstamp();
        let mut traffic = 0;
        if s.is_local() {
            traffic |= TRAFFIC_LOCAL;
        }
        if s.sent_by(sk) {
            traffic |= TRAFFIC_OWN;
        }
        skb.done();
        let Some(list) = sk.shared().rx.get() else {
            return;
        };
        let now = ktime_get_mono_ns() as u64;
        let mut pending = Pending::new();
        {
            let l = list.lock();
            for j in l.ops.iter() {
                let d = j.data();
                if d.key.can_id != can_id
                    || d.key.fd != fd
                    || (d.key.ifindex != 0 && d.key.ifindex != ifindex)
                    || !d.active.load(Ordering::Relaxed)
                {
                    continue;
                }
                d.frames_abs.fetch_add(1, Ordering::Relaxed);
                with_rx(
                    j.get(),
                    &mut pending,
                    Some(tstamp),
                    |op, filters, last, out| {
                        op.frame_received(&frame, ifindex, traffic, now, filters, last, out)
                    },
                );
            }
        }
        pending.flush();
    }

    /// Mainline `bcm_notify`. Process context, RTNL held. A CAN device
    /// going away stops the transmit operations on it (timers cancelled)
    /// and unsubscribes the receive operations on it, whose timers keep
    /// running as mainline's `bcm_rx_unreg` leaves them: an armed receive
    /// timeout still fires once (RX_TIMEOUT naming the last interface a
    /// frame came from), held-back changes are still flushed by the
    /// throttle. The operations stay, as in mainline, for
    /// TX_READ/RX_READ/..._DELETE. Sockets connected to the device are
    /// disconnected (ENODEV); one going down reports ENETDOWN to them.
    fn netdev_event(event: NetdevEvent, dev: &NetDev, sockets: &Sockets<'_, Self>) {
        if !dev.is_can() {
            return;
        }
        let ifindex = dev.ifindex();
        sockets.for_each(|sk| {
            let mut s = sk.lock();
            if event == NetdevEvent::Down {
                let hit = s.bound && s.ifindex == ifindex;
                drop(s);
                if hit {
                    sk.report_error(-neterr::ENETDOWN().to_errno());
                }
                return;
            }
            for j in s.tx_ops.iter().filter(|j| j.data().key.ifindex == ifindex) {
                with_tx(j.get(), false, |op, out| {
                    if op.expires.take().is_some() {
                        out.cancel();
                    }
                });
            }
            let mut changed = false;
            if let Some(list) = sk.shared().rx.get() {
                let l = list.lock();
                for j in l.ops.iter() {
                    let d = j.data();
                    changed |= d.key.ifindex == ifindex && d.active.swap(false, Ordering::Relaxed);
                    // Release an "any" operation's claim on the vanishing
                    // interface (mainline: if_detected).
                    let mut pending = Pending::new();
                    with_rx(j.get(), &mut pending, None, |op, _, _, _| {
                        if op.ifindex == 0 && op.if_detected == ifindex {
                            op.if_detected = 0;
                        }
                    });
                }
            }
            if changed {
                // ENOMEM keeps the old subscription; the callback skips
                // inactive operations anyway.
                let _ = rx_register(sk);
            }
            let enodev = s.bound && s.ifindex == ifindex;
            let mut proc = None;
            if enodev {
                s.bound = false;
                s.ifindex = 0;
                sk.shared().bound.store(false, Ordering::Relaxed);
                proc = s.proc.take();
            }
            drop(s);
            // Mainline removes the file with the binding; waits for its
            // readers (they take the socket lock, not RTNL).
            drop(proc);
            if enodev {
                sk.report_error(-ENODEV.to_errno());
            }
        });
    }
}

/// Copies the `nframes` frames of a request into `dst` (which has room),
/// with `TX_CP_CAN_ID` applied.
fn copy_frames(req: &Request<'_>, dst: &mut [u8]) {
    let h = &req.head;
    let cfsiz = h.cfsiz();
    let n = h.nframes as usize * cfsiz;
    dst[..n].copy_from_slice(&req.payload[..n]);
    if h.flags & TX_CP_CAN_ID != 0 {
        for f in dst[..n].chunks_exact_mut(cfsiz) {
            f[..4].copy_from_slice(&h.can_id.to_ne_bytes());
        }
    }
}

/// `TX_SETUP` (mainline `bcm_tx_setup`). Process context, socket locked.
fn tx_setup(sk: &S, s: &mut BcmSock, req: &Request<'_>, ifindex: i32) -> Result<usize> {
    let h = req.head;
    let key = OpKey::of(&h, ifindex);
    let found = find(&s.tx_ops, &key);
    let existing = found.and_then(|i| match &*s.tx_ops[i].data().state.lock() {
        OpState::Tx(t) => Some(t.op.nframes),
        OpState::Rx(_) => None,
    });
    let ret = wire::check_tx_setup(req, ifindex, existing).map_err(errno)?;
    let now = ktime_get_mono_ns() as u64;
    let i = match found {
        Some(i) => {
            let mut st = s.tx_ops[i].data().state.lock();
            if let OpState::Tx(t) = &mut *st {
                copy_frames(req, &mut t.frames);
            }
            i
        }
        None => {
            let cfsiz = h.cfsiz();
            let mut frames = KVec::from_elem(0u8, h.nframes as usize * cfsiz, GFP_KERNEL)?;
            copy_frames(req, &mut frames);
            let job = new_job(
                sk,
                key,
                OpState::Tx(TxState {
                    op: TxOp::new(&h),
                    ifindex,
                    cfsiz,
                    frames,
                }),
            )?;
            s.tx_ops.push(job, GFP_KERNEL)?;
            s.tx_ops.len() - 1
        }
    };
    with_tx(s.tx_ops[i].get(), false, |op, out| op.setup(&h, now, out));
    Ok(ret)
}

/// `RX_SETUP` (mainline `bcm_rx_setup`). Process context, socket locked.
fn rx_setup(sk: &S, req: &Request<'_>, ifindex: i32) -> Result<usize> {
    let list = sk.shared().rx.get().ok_or(neterr::ENOTCONN())?;
    let h = wire::rx_setup_head(&req.head);
    let key = OpKey::of(&h, ifindex);
    let existing = {
        let l = list.lock();
        find(&l.ops, &key).and_then(|i| match &*l.ops[i].data().state.lock() {
            OpState::Rx(r) => Some(r.op.nframes),
            OpState::Tx(_) => None,
        })
    };
    let ret = wire::check_rx_setup(req, existing).map_err(errno)?;
    let cfsiz = h.cfsiz();
    let n = h.nframes as usize;
    // The frames, prepared outside the spinlocks.
    let mut raw = KVec::from_elem(0u8, n * cfsiz, GFP_KERNEL)?;
    raw.copy_from_slice(&req.payload[..n * cfsiz]);
    let mut filters = KVec::with_capacity(n, GFP_KERNEL)?;
    for i in 0..n {
        if let Some(f) = wire::frame_at(&raw, cfsiz, i) {
            filters.push(f, GFP_KERNEL)?;
        }
    }
    if h.flags & RX_RTR_FRAME != 0 {
        if let (Some(f), Some(dst)) = (filters.first_mut(), raw.get_mut(..cfsiz)) {
            *f = wire::rtr_reply_frame(&h, *f);
            let image = f.to_bytes();
            if let Some(src) = image.get(..cfsiz) {
                dst.copy_from_slice(src);
            }
        }
    }
    let now = ktime_get_mono_ns() as u64;
    if existing.is_some() {
        let mut pending = Pending::new();
        let l = list.lock();
        if let Some(i) = find(&l.ops, &key) {
            let j = l.ops[i].get();
            {
                let mut st = j.data().state.lock();
                if let OpState::Rx(r) = &mut *st {
                    if n > 0 {
                        r.raw[..n * cfsiz].copy_from_slice(&raw);
                        // Element by element: filters.len() == n <= r.filters.len(),
                        // and no length-mismatch panic path for objtool to flag.
                        for (d, s) in r.filters.iter_mut().zip(filters.iter()) {
                            *d = *s;
                        }
                        r.last.iter_mut().for_each(|s| *s = RxSlot::default());
                    }
                }
            }
            with_rx(j, &mut pending, None, |op, _, last, out| {
                op.setup(&h, now, last, out)
            });
        }
        drop(l);
        pending.flush();
        return Ok(ret);
    }
    let last = KVec::from_elem(RxSlot::default(), n.max(1), GFP_KERNEL)?;
    let job = new_job(
        sk,
        key,
        OpState::Rx(RxState {
            op: RxOp::new(&h, ifindex),
            cfsiz,
            raw,
            filters,
            last,
            rx_stamp: 0,
        }),
    )?;
    rx_add(list, job)?;
    if let Err(e) = rx_register(sk) {
        drop(rx_take(list, &key));
        return Err(e);
    }
    let mut pending = Pending::new();
    {
        let l = list.lock();
        if let Some(i) = find(&l.ops, &key) {
            with_rx(l.ops[i].get(), &mut pending, None, |op, _, last, out| {
                op.setup(&h, now, last, out)
            });
        }
    }
    pending.flush();
    Ok(ret)
}

/// `TX_SEND` (mainline `bcm_tx_send`). Process context.
fn tx_send(sk: &S, req: &Request<'_>, ifindex: i32) -> Result<usize> {
    let ret = wire::check_tx_send(req, ifindex).map_err(errno)?;
    let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENODEV)?;
    // A CAN FD frame (CAN_FD_FRAME) goes the same way: rcan_send checks
    // its length (EINVAL) and the device's MTU (EMSGSIZE on a classic
    // device), as mainline's can_send.
    let cfsiz = req.head.cfsiz();
    let skb = glue::can::skb::alloc_image_for(sk, &dev, &req.payload[..cfsiz], glue::GFP_KERNEL)
        .ok_or(ENOMEM)?;
    rcan_api::send(skb, &dev, true)?;
    Ok(ret)
}

impl glue::sock::Proto for BcmProto {
    type Data = BcmSock;
    type Shared = BcmShared;

    fn new_shared() -> BcmShared {
        BcmShared {
            bound: AtomicBool::new(false),
            dropped: AtomicU64::new(0),
            rx: OnceBox::new(),
        }
    }

    fn new_data() -> BcmSock {
        BcmSock {
            bound: false,
            ifindex: 0,
            tx_ops: KVec::new(),
            proc: None,
        }
    }

    /// Mainline `bcm_release`: unsubscribe, then every operation goes
    /// (timers cancelled and waited for, see the module documentation).
    fn release(sk: &S) {
        {
            let mut rtnl = Rtnl::lock();
            MODULE.sockets.get(&mut rtnl).remove(sk);
        }
        rcan_api::rx_remove(sk);
        let mut s = sk.lock();
        let tx = core::mem::replace(&mut s.tx_ops, KVec::new());
        let rx = match sk.shared().rx.get() {
            Some(l) => core::mem::replace(&mut l.lock().ops, KVec::new()),
            None => KVec::new(),
        };
        s.bound = false;
        s.ifindex = 0;
        sk.shared().bound.store(false, Ordering::Relaxed);
        let proc = s.proc.take();
        drop(s);
        // Waits for readers of the file (they take the socket lock).
        drop(proc);
        drop(tx);
        drop(rx);
    }

    fn bind(_sk: &S, _addr: &[u8]) -> Result {
        Err(neterr::EOPNOTSUPP())
    }

    /// Mainline `bcm_connect`.
    fn connect(sk: &S, addr: &[u8], _flags: i32) -> Result {
        if addr.len() < BCM_MIN_NAMELEN {
            return Err(EINVAL);
        }
        let mut ifindex = i32::from_ne_bytes([addr[4], addr[5], addr[6], addr[7]]);
        let mut s = sk.lock();
        if s.bound {
            return Err(neterr::EISCONN());
        }
        if ifindex != 0 {
            let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENODEV)?;
            if !dev.is_can() {
                return Err(ENODEV);
            }
            ifindex = dev.ifindex();
        }
        if sk.shared().rx.get().is_none() {
            let l = new_bh_spinlock!(RxOps { ops: KVec::new() }, "bcm_rx_ops")?;
            sk.shared().rx.set(KBox::new(l, GFP_KERNEL)?)?;
        }
        s.bound = true;
        s.ifindex = ifindex;
        sk.shared().bound.store(true, Ordering::Relaxed);
        // /proc/net/can-bcm/<inode> in the socket's namespace; as in
        // mainline, a socket without it (no directory, no memory) still
        // works.
        if let Ok(name) = CString::try_from_fmt(format_args!("{}", sk.ino())) {
            s.proc = PROC
                .entry(sk.net(), &name, ProcView { sk: sk.to_ref() })
                .ok();
        }
        Ok(())
    }

    fn getname(_sk: &S, _peer: bool, _out: &mut [u8]) -> Result<usize> {
        Err(neterr::EOPNOTSUPP())
    }

    /// Mainline `bcm_sendmsg`: the checks every message gets, then the
    /// opcode's. Returns the bytes mainline returns.
    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        if !sk.shared().bound.load(Ordering::Relaxed) {
            return Err(neterr::ENOTCONN());
        }
        if len < MHSIZ {
            return Err(EINVAL);
        }
        let mut hb = [0u8; MHSIZ];
        msg.copy_from_user(&mut hb)?;
        let head = MsgHead::from_bytes(&hb);
        let cfsiz = head.cfsiz();
        if (len - MHSIZ) % cfsiz != 0 {
            return Err(EINVAL);
        }
        let take = len.min(max_read(cfsiz));
        let mut buf = KVec::from_elem(0u8, take, GFP_KERNEL)?;
        buf[..MHSIZ].copy_from_slice(&hb);
        msg.copy_from_user(&mut buf[MHSIZ..])?;

        let mut s = sk.lock();
        if !s.bound {
            return Err(neterr::ENOTCONN());
        }
        let mut ifindex = s.ifindex;
        if ifindex == 0 {
            if let Some(name) = msg.name() {
                if name.len() < BCM_MIN_NAMELEN
                    || u16::from_ne_bytes([name[0], name[1]]) != rcan_core::sockaddr::AF_CAN
                {
                    return Err(EINVAL);
                }
                ifindex = i32::from_ne_bytes([name[4], name[5], name[6], name[7]]);
                if ifindex != 0 {
                    let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENODEV)?;
                    if !dev.is_can() {
                        return Err(ENODEV);
                    }
                }
            }
        }
        let req = wire::parse(&buf).map_err(errno)?;
        let key = OpKey::of(&req.head, ifindex);
        match req.head.opcode {
            TX_SETUP => tx_setup(sk, &mut s, &req, ifindex),
            RX_SETUP => rx_setup(sk, &req, ifindex),
            TX_DELETE => {
                let i = find(&s.tx_ops, &key).ok_or(EINVAL)?;
                let job = glue::kvec_swap_remove(&mut s.tx_ops, i);
                drop(job);
                Ok(MHSIZ)
            }
            RX_DELETE => {
                let list = sk.shared().rx.get().ok_or(EINVAL)?;
                let job = rx_take(list, &key).ok_or(EINVAL)?;
                // ENOMEM keeps the old subscription; the operation is gone
                // from the list, so its frames find nobody.
                let _ = rx_register(sk);
                drop(job);
                Ok(MHSIZ)
            }
            TX_READ => {
                let i = find(&s.tx_ops, &key).ok_or(EINVAL)?;
                with_tx(s.tx_ops[i].get(), false, |op, out| op.read(out));
                Ok(MHSIZ)
            }
            RX_READ => {
                let list = sk.shared().rx.get().ok_or(EINVAL)?;
                let mut pending = Pending::new();
                let l = list.lock();
                let i = find(&l.ops, &key).ok_or(EINVAL)?;
                with_rx(l.ops[i].get(), &mut pending, None, |op, _, _, out| {
                    op.read(out)
                });
                Ok(MHSIZ)
            }
            TX_SEND => tx_send(sk, &req, ifindex),
            _ => Err(EINVAL),
        }
    }

    /// Mainline `bcm_recvmsg`.
    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        glue::can::skb::recvmsg_queued(sk, msg, len, flags)
    }

    /// Mainline's BCM has no socket options (`sock_no_setsockopt`).
    fn setsockopt(_sk: &S, _level: i32, _name: i32, _opt: &OptIn) -> Result {
        Err(neterr::EOPNOTSUPP())
    }

    fn getsockopt(_sk: &S, _level: i32, _name: i32, _opt: &OptOut) -> Result {
        Err(neterr::EOPNOTSUPP())
    }
}

/// The module: its registrations, undone when it is dropped (unload).
pub(crate) struct BcmModule {
    _reg: ProtoRegistration<BcmProto>,
    /// Dropped after `_reg`: no socket, so no file, is left then.
    _proc: Option<NetProcDirReg>,
}

impl ScopedModule for BcmModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        // Before the protocol: a socket may connect at once.
        let proc = match PROC.register() {
            Ok(p) => Some(p),
            Err(e) => {
                pr_warn!("no /proc/net/can-bcm ({:?})\n", e);
                None
            }
        };
        let reg = MODULE.register(c_str!("CAN_BCM"), scope)?;
        pr_info!("CAN_BCM ({}) registered\n", CAN_BCM);
        Ok(BcmModule {
            _reg: reg,
            _proc: proc,
        })
    }
}
