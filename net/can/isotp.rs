// SPDX-License-Identifier: GPL-2.0

//! rcan_isotp: CAN_ISOTP (ISO 15765-2), mainline SocketCAN's ISO-TP
//! transport, on the rcan stack (issue 41, step 2).
//!
//! `socket(PF_CAN, SOCK_DGRAM, CAN_ISOTP)`, options at `SOL_CAN_ISOTP`,
//! `bind()` with `sockaddr_can.can_addr.tp = {rx_id, tx_id}` and an
//! interface; then one PDU per `write()` and per `read()`. The option ABI,
//! the bind checks, the frame formats and both state machines (sender and
//! receiver, with their timers as pure state) are `rcan_core::isotp*`,
//! host-tested; this file gives them a socket, a receive subscription, two
//! timers, a transmit path and the blocking of `sendmsg`. See
//! Documentation/networking/rcan/isotp.rst.
//!
//! Objects and their locks (lock order: RTNL, socket lock, `eng`):
//!
//! * [`IsotpSock`] (socket lock): the options as set before `bind`, the
//!   binding. Process context only.
//! * [`IsotpShared::eng`], allocated by the first `bind`: the [`Engine`]
//!   (sender and receiver state, the PDU buffers, the copy of the options
//!   and addresses in effect, the timers) under a `BhLock`
//!   (`spin_lock_bh`, lockdep class `isotp_engine`; mainline's
//!   `so->rx_lock`). Taken by `bind`, `sendmsg`, `release` and the
//!   netdevice notifier (process context), the receive callback (NET_RX
//!   softirq) and the timer callbacks (HRTIMER_SOFTIRQ softirq); never in
//!   hardirq context, so it disables bottom halves, not interrupts.
//!
//! Every event of a socket (a received frame, an echo of its own frame, a
//! timer expiry, a send request) runs its state machine under `eng`; the
//! machine writes the frame it asks for into the engine's one frame
//! buffer ([`Engine::frame`]), from which the frame's image (16 or 72
//! bytes) is made before `eng` is released; the frame is sent, the socket
//! error reported and the waiters woken after that (the driver's transmit
//! path runs outside it). A frame sent from the receive callback goes out
//! on the device the received frame came in on (the bound one), which
//! the receive path holds for the callback: no lookup by index per frame.
//!
//! Timers: one [`JobTimers`] per socket (slot [`TX_TIMER`] for the sender,
//! [`RX_TIMER`] for the receiver), made by the first `bind` and kept in
//! the engine; its data is a counted reference on the sock, so a callback
//! always finds the sock. `release` takes it out of the engine and drops
//! it, which cancels both timers and waits for a running callback before
//! the memory goes (rust/glue/jobtimer.rs); that also breaks the
//! reference cycle sock -> engine -> job -> sock. A cancellation that
//! loses a race with a running callback (`try_cancel` under `eng`) is
//! harmless: the machines ignore an expiry before their recorded deadline
//! or with none armed. Timers follow the machines' deadlines lazily
//! ([`sync_timer`]): a deadline that moves later leaves the timer queued
//! for the earlier expiry, whose callback starts it again for the new
//! deadline; so a burst transfer starts each timer about once per PDU,
//! not once per frame.
//!
//! Blocking: `sendmsg` sleeps on the module's wait queue [`WAITQ`] until
//! the sender is idle (a new transfer may start) or, with
//! `CAN_ISOTP_WAIT_TX_DONE`, until its own transfer ended; every end of a
//! transfer wakes the queue (all ISO-TP sockets share it; each waiter
//! re-checks its own socket) and the socket's pollers: `poll` reports
//! EPOLLOUT only while the sender is idle (`Proto::writable`).

#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::sync::atomic::{AtomicBool, Ordering};
use kernel::prelude::*;

use crate::glue::module::{ModuleScope, ScopedModule};
use glue::hrtimer::ktime_get_mono_ns;
use glue::jobtimer::{JobCallback, JobRef, JobTimers, OnceBox};
use glue::lock::{new_bh_spinlock, BhLock, WaitQueue, Waited};
use glue::netdev::{DevRef, NetDev};
use glue::neterr;
use glue::params::Param;
use glue::skb::{Skb, UniqueSkb};
use glue::sock::{Msg, OptIn, OptOut, Sock, SockRef, SockView};
use glue::sync::Rtnl;
use kernel::alloc::KVVec;
use kernel::c_str;
use rcan_api::{
    CanProtocol, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter, RxSkb, Sockets,
    RX_FILTER_CAN_ID, SOCK_DGRAM,
};
use rcan_core::frame::AnyFrame;
use rcan_core::isotp::{
    clamp_max_pdu_size, pdu_limit, route, single_mask, Config, IsotpOptions, LlOptions, Route, Timeouts,
    TpAddr, CAN_ISOTP, CAN_ISOTP_LL_OPTS, CAN_ISOTP_OPTS, CAN_ISOTP_RECV_FC, CAN_ISOTP_RX_STMIN,
    CAN_ISOTP_TX_STMIN, CAN_ISOTP_WAIT_TX_DONE, ISOTP_MIN_NAMELEN, MAX_OPTLEN, SOL_CAN_ISOTP,
};
use rcan_core::isotp_pci::LlFrame;
use rcan_core::isotp_rx::{Rx, RxEvent};
use rcan_core::isotp_tx::Tx;

/// The sender's timer slot.
const TX_TIMER: usize = 0;
/// The receiver's timer slot.
const RX_TIMER: usize = 1;

/// `max_pdu_size` (C shim `isotp_c.c`): the largest PDU sent or received,
/// read at `bind` (clamped as mainline clamps it at load, and never under
/// mainline's 8300-byte buffers: [`pdu_limit`]).
const MAX_PDU_SIZE: Param<u32> = Param::new(0);
/// `fc_timeout_ms` and `echo_timeout_ms` (C shim; test-only, not
/// mainline's): the timeouts of a socket, read at `bind`
/// ([`Timeouts::from_ms`]).
const FC_TIMEOUT_MS: Param<u32> = Param::new(1);
const ECHO_TIMEOUT_MS: Param<u32> = Param::new(2);

/// Where `sendmsg` sleeps (module documentation). Woken at every end of a
/// transfer, by `release` and by the notifier.
static WAITQ: WaitQueue = WaitQueue::new(c_str!("rcan_isotp::WAITQ"));

fn errno(e: i32) -> Error {
    glue::errno(e)
}

type S = Sock<IsotpProto>;
type Job = JobTimers<IsotpJob>;

/// The timers' callback marker; a job's data is its socket.
struct IsotpJob;

/// The state of one bound (or once bound) socket, under `eng`.
struct Engine {
    /// Options and addresses in effect (copied at `bind`; fixed while
    /// bound, as options cannot change then).
    cfg: Config,
    addr: TpAddr,
    /// Bound (false again after `release` or the device's removal):
    /// frames and timers are only acted upon while true.
    bound: bool,
    tx: Tx,
    rx: Rx,
    /// The PDU being sent (exactly its length).
    txbuf: KVVec<u8>,
    /// The reassembly buffer, `max_pdu_size` bytes (the largest PDU
    /// accepted).
    rxbuf: KVVec<u8>,
    /// Generation of the last transfer started, and of the last one
    /// ended with its result (`WAIT_TX_DONE` reports its own transfer's).
    tx_gen: u64,
    done_gen: u64,
    done_res: Result<(), i32>,
    /// The two timers; taken out (and dropped, waiting for callbacks) by
    /// `release`.
    job: Option<Job>,
    /// Where both machines write the frame they ask for (`*_into`); only
    /// `len` and the bytes before it are meaningful, [`Image::new`] reads
    /// them right after the machine, under `eng`.
    frame: LlFrame,
    /// Per timer slot, the expiry it was last started for while it may
    /// still be queued (`None`: not queued, or its callback is about to
    /// clear this). Timers are started lazily ([`sync_timer`]): a
    /// deadline that moves later (every frame moves the echo and N_Cr
    /// deadlines) leaves the timer queued for the earlier expiry, whose
    /// callback then starts it again for the machine's deadline.
    armed: [Option<u64>; 2],
}

/// What to do after `eng` is released (filled under `eng`, run after).
struct After {
    err: Option<i32>,
    wake: bool,
    deliver: Option<UniqueSkb>,
}

impl After {
    fn new() -> Self {
        After {
            err: None,
            wake: false,
            deliver: None,
        }
    }

    /// Queues a delivered PDU, reports the error, wakes senders. Process
    /// or softirq context, `eng` not held; after the step's frame was
    /// sent ([`send_frame`]).
    #[inline]
    fn run(&mut self, sk: &SockView<IsotpProto>) {
        if let Some(skb) = self.deliver.take() {
            // A full receive queue drops the PDU, as mainline.
            let _ = sk.queue_rcv(skb.into_owned());
        }
        if let Some(e) = self.err {
            sk.report_error(e);
        }
        if self.wake {
            WAITQ.wake_all();
            sk.wake_writers();
        }
    }
}

/// A frame's image as pf_can sends it, `struct can_frame` (16 bytes) or
/// `struct canfd_frame` (72), with the socket's `tx_id` and `tx_flags`;
/// made under `eng` from [`Engine::frame`], sent after.
enum Image {
    None,
    Classic([u8; 16]),
    Fd([u8; 72]),
}

impl Image {
    /// The image of the machine's frame `f` on the link layer `ll`. A
    /// classic frame's 16 bytes are built from registers (no copy of
    /// variable length, no 72-byte image): this runs once per frame.
    #[inline(always)]
    fn new(tx_id: u32, ll: LlOptions, f: &LlFrame) -> Image {
        let id = tx_id.to_ne_bytes();
        if ll.is_fd() {
            let mut img = [0u8; 72];
            img[..4].copy_from_slice(&id);
            img[4] = f.len;
            img[5] = ll.tx_flags;
            let n = usize::from(f.len).min(64);
            img[8..8 + n].copy_from_slice(&f.data[..n]);
            Image::Fd(img)
        } else {
            let d = f.classic_data();
            Image::Classic([
                id[0],
                id[1],
                id[2],
                id[3],
                f.len.min(8),
                0,
                0,
                0,
                d[0],
                d[1],
                d[2],
                d[3],
                d[4],
                d[5],
                d[6],
                d[7],
            ])
        }
    }

    /// The image made from the engine's frame if the machine wrote one.
    #[inline(always)]
    fn of(e: &Engine, frame: bool) -> Image {
        if frame {
            Image::new(e.addr.tx_id, e.cfg.ll, &e.frame)
        } else {
            Image::None
        }
    }
}

/// Sends `img` (if any) on `dev`, owned by `sk` (so that its echo names
/// it), with loopback. Process or softirq context, `eng` not held.
fn send_frame(sk: &SockView<IsotpProto>, dev: &NetDev, img: &Image) -> Result {
    let bytes: &[u8] = match img {
        Image::None => return Ok(()),
        Image::Classic(b) => b,
        Image::Fd(b) => b,
    };
    let skb = glue::can::skb::alloc_image_for(sk, dev, bytes, glue::GFP_ATOMIC).ok_or(ENOMEM)?;
    rcan_api::send(skb, dev, true)
}

/// [`send_frame`] on the device with index `ifindex` (looked up: from a
/// timer or a system call, which have no device at hand). ENXIO if it is
/// gone.
fn send_frame_by_index(sk: &SockView<IsotpProto>, ifindex: i32, img: &Image) -> Result {
    if let Image::None = img {
        return Ok(());
    }
    let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENXIO)?;
    send_frame(sk, &dev, img)
}

/// Brings timer `which` in line with its machine's deadline `want`
/// (`Tx::deadline`, `Rx::deadline`), lazily. `armed` is the expiry the
/// timer was last started for ([`Engine::armed`]). A deadline at or after
/// that expiry leaves the timer alone: it fires early, and its callback
/// (the machine ignores an expiry before its deadline) starts it again
/// for the deadline then in force. So a transfer starts each timer about
/// once, instead of once per frame (mainline restarts its echo and N_Cr
/// timers on every consecutive frame). No deadline: the timer is
/// cancelled (a callback already running finds nothing to do). `eng`
/// held.
#[inline]
fn sync_timer(job: &Option<Job>, armed: &mut Option<u64>, which: usize, want: Option<u64>) {
    let Some(job) = job else {
        return;
    };
    match (want, *armed) {
        (None, None) => {}
        (None, Some(_)) => {
            let _ = job.get().try_cancel(which);
            *armed = None;
        }
        (Some(d), Some(a)) if a <= d => {}
        (Some(d), _) => {
            job.get().start(which, d);
            *armed = Some(d);
        }
    }
}

impl Engine {
    /// Makes the sender's timer follow its deadline. `eng` held.
    fn sync_tx_timer(&mut self) {
        sync_timer(&self.job, &mut self.armed[TX_TIMER], TX_TIMER, self.tx.deadline());
    }

    /// Makes the receiver's timer follow its deadline. `eng` held.
    fn sync_rx_timer(&mut self) {
        sync_timer(&self.job, &mut self.armed[RX_TIMER], RX_TIMER, self.rx.deadline());
    }

    /// Carries out a sender step whose result is `done` (its timer
    /// command is the sender's deadline, which [`sync_timer`] follows).
    /// `eng` held. Its frame, in [`Engine::frame`], is the caller's.
    #[inline]
    fn tx_step(&mut self, done: Option<Result<(), i32>>, out: &mut After) {
        self.sync_tx_timer();
        if let Some(res) = done {
            self.done_gen = self.tx_gen;
            self.done_res = res;
            if let Err(e) = res {
                out.err = Some(e);
            }
            out.wake = true;
        }
    }

    /// Carries out a receiver step with `event`; `rcvd` is the frame
    /// received (its timestamp goes to a delivered PDU), if any. `eng`
    /// held; any context (GFP_ATOMIC). Its frame, in [`Engine::frame`], is
    /// the caller's.
    #[inline]
    fn rx_step(
        &mut self,
        event: Option<RxEvent>,
        ifindex: i32,
        rcvd: Option<&Skb>,
        out: &mut After,
    ) {
        self.sync_rx_timer();
        match event {
            Some(RxEvent::Deliver(n)) => self.deliver(n, ifindex, rcvd, out),
            Some(RxEvent::Error(e)) => out.err = Some(e),
            None => {}
        }
    }

    /// Makes the skb of a whole PDU of `n` bytes for the receive queue.
    /// Once per PDU, kept out of the per-frame path. `eng` held; any
    /// context (GFP_ATOMIC).
    #[inline(never)]
    fn deliver(&mut self, n: usize, ifindex: i32, rcvd: Option<&Skb>, out: &mut After) {
        let Some(pdu) = self.rxbuf.get(..n) else {
            return;
        };
        let Some(mut skb) = UniqueSkb::alloc(n as u32, glue::GFP_ATOMIC) else {
            return;
        };
        if !skb.put_data(pdu) {
            return;
        }
        // Mainline's isotp_rcv_skb: the cb holds the source address
        // (family and interface, the rest zero).
        let mut name = [0u8; ISOTP_MIN_NAMELEN];
        name[..2].copy_from_slice(&rcan_core::sockaddr::AF_CAN.to_ne_bytes());
        name[4..8].copy_from_slice(&ifindex.to_ne_bytes());
        skb.cb_write(0, &name);
        let tstamp = rcvd.map_or(0, Skb::tstamp);
        if tstamp != 0 {
            skb.set_tstamp(tstamp);
        }
        out.deliver = Some(skb);
    }

    /// Ends both transfers without a result and cancels the timers (the
    /// socket closes or loses its device). `eng` held.
    fn abort(&mut self, out: &mut After) {
        let _ = self.tx.abort();
        self.sync_tx_timer();
        let _ = self.rx.abort();
        self.sync_rx_timer();
        self.done_gen = self.tx_gen;
        out.wake = true;
    }
}

impl JobCallback for IsotpJob {
    type Data = SockRef<IsotpProto>;

    /// HRTIMER_SOFTIRQ softirq: the sender's (N_Bs, echo, STmin gap) or
    /// the receiver's (N_Cr) timer expired. A stale expiry does nothing
    /// (the machines check their deadline).
    fn expired(job: JobRef<'_, Self>, which: usize) {
        let sk = job.data().sock();
        let Some(eng) = sk.shared().eng.get() else {
            return;
        };
        let now = ktime_get_mono_ns() as u64;
        let mut out = After::new();
        let (ifindex, img) = {
            let mut g = eng.lock();
            let e = &mut *g;
            // This expiry dequeued the timer (a later start queued it
            // again, which a second start only moves).
            if let Some(a) = e.armed.get_mut(which) {
                *a = None;
            }
            if !e.bound {
                return;
            }
            // An early expiry (the deadline moved later, Engine::armed)
            // changes no state; the step starts the timer again.
            let frame = if which == TX_TIMER {
                let a = e.tx.on_timer_into(&e.cfg, &e.txbuf, now, &mut e.frame);
                e.tx_step(a.done, &mut out);
                a.frame
            } else {
                let st = e.rx.on_timer(now);
                e.rx_step(st.event, e.addr.ifindex, None, &mut out);
                false
            };
            (e.addr.ifindex, Image::of(e, frame))
        };
        // A CF that could not be sent ends in ECOMM (no echo).
        let _ = send_frame_by_index(sk, ifindex, &img);
        out.run(sk);
    }
}

/// A CAN_ISOTP socket's state under the socket lock.
struct IsotpSock {
    /// The options as set (copied into the engine at `bind`).
    cfg: Config,
    /// Bound to `addr` (false again after the device's removal).
    bound: bool,
    addr: TpAddr,
}

/// What the receive path, the timers and the lockless checks need.
struct IsotpShared {
    /// Mirrors `IsotpSock::bound` (written under the socket lock): the
    /// lockless "not bound" checks of sendmsg and recvmsg.
    bound: AtomicBool,
    /// The engine, allocated by the first `bind` and kept until the sock
    /// is freed.
    eng: OnceBox<BhLock<Engine>>,
}

struct IsotpProto;

/// This module's registrations (proto, CAN protocol, notifier).
static MODULE: ProtoModule<IsotpProto> = ProtoModule::new();

impl CanProtocol for IsotpProto {
    const PROTOCOL: i32 = CAN_ISOTP;
    const SOCK_TYPE: i32 = SOCK_DGRAM;
    /// All state is in the socket; devices are looked up in the socket's
    /// namespace.
    const ALL_NAMESPACES: bool = true;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// NET_RX softirq, RCU read side (mainline `isotp_rcv` and
    /// `isotp_rcv_echo`): frames on `rx_id` go to the machines as
    /// `route()` says; of our own frames on `tx_id` coming back, the
    /// sender takes the echo it waits for (not those of the receiver's
    /// flow control frames).
    fn rx(sk: &SockView<Self>, skb: RxSkb<'_>, _cookie: u32) {
        let s = skb.skb();
        let own = s.sent_by(sk);
        let ifindex = skb.ifindex();
        let Some((can_id, data, fd)) = AnyFrame::view(s.data()) else {
            skb.done();
            return;
        };
        let Some(eng) = sk.shared().eng.get() else {
            skb.done();
            return;
        };
        let now = ktime_get_mono_ns() as u64;
        let mut out = After::new();
        let img = {
            let mut g = eng.lock();
            let e = &mut *g;
            if !e.bound || ifindex != e.addr.ifindex {
                drop(g);
                skb.done();
                return;
            }
            let mut frame = false;
            if own {
                // Our own frame on tx_id: the echo the sender waits for,
                // or one of the receiver's flow control frames (the
                // machine tells them apart by their first bytes, as
                // mainline's `cfecho`).
                if can_id == e.addr.tx_id {
                    let a = e.tx.on_own_frame_into(&e.cfg, data, &e.txbuf, now, &mut e.frame);
                    e.tx_step(a.done, &mut out);
                    frame = a.frame;
                }
            } else if can_id == e.addr.rx_id && e.cfg.registers_rx_id() {
                match route(&e.cfg, fd, data, e.tx.is_idle(), e.rx.is_idle()) {
                    Route::Drop => {}
                    Route::Tx => {
                        let a = e.tx.on_fc_into(&e.cfg, data, &e.txbuf, now, &mut e.frame);
                        e.tx_step(a.done, &mut out);
                        frame = a.frame;
                    }
                    Route::Rx => {
                        let a = e.rx.on_frame_into(&e.cfg, data, &mut e.rxbuf, now, &mut e.frame);
                        e.rx_step(a.event, ifindex, Some(s), &mut out);
                        frame = a.frame;
                    }
                }
            }
            Image::of(e, frame)
        };
        // The frame goes out on the device it answers, the bound one
        // (checked above), which the receive path holds for this call.
        let dev = skb.dev();
        skb.done();
        if let Some(dev) = dev {
            let _ = send_frame(sk, dev, &img);
        }
        out.run(sk);
    }

    /// Mainline `isotp_notify`. Process context, RTNL held. The bound
    /// device going away unbinds the socket (ENODEV); unlike mainline,
    /// running transfers end at once (timers cancelled, waiting senders
    /// woken) instead of draining into a timeout. The bound device going
    /// down reports ENETDOWN.
    fn netdev_event(event: NetdevEvent, dev: &glue::netdev::NetDev, sockets: &Sockets<'_, Self>) {
        if !dev.is_can() {
            return;
        }
        let ifindex = dev.ifindex();
        sockets.for_each(|sk| {
            let mut s = sk.lock();
            let hit = s.bound && s.addr.ifindex == ifindex;
            if !hit {
                return;
            }
            if event == NetdevEvent::Down {
                drop(s);
                sk.report_error(-neterr::ENETDOWN().to_errno());
                return;
            }
            rcan_api::rx_remove(sk);
            // Reported before the engine is unbound: a WAIT_TX_DONE
            // sender that wakes (also spuriously, the queue is shared)
            // and finds it unbound takes this error.
            sk.report_error(-ENODEV.to_errno());
            s.bound = false;
            sk.shared().bound.store(false, Ordering::Relaxed);
            let mut out = After::new();
            if let Some(eng) = sk.shared().eng.get() {
                let mut e = eng.lock();
                e.bound = false;
                e.abort(&mut out);
            }
            drop(s);
            out.run(sk);
        });
    }
}

/// Allocates the engine of `sk` if it has none (first `bind`). Process
/// context, socket lock held.
fn engine(sk: &S) -> Result<&BhLock<Engine>> {
    if let Some(e) = sk.shared().eng.get() {
        return Ok(e);
    }
    let job = JobTimers::new(sk.to_ref(), sk)?;
    let e = Engine {
        cfg: Config::default(),
        addr: TpAddr {
            ifindex: 0,
            rx_id: 0,
            tx_id: 0,
        },
        bound: false,
        tx: Tx::new(),
        rx: Rx::new(),
        txbuf: KVVec::new(),
        rxbuf: KVVec::new(),
        tx_gen: 0,
        done_gen: 0,
        done_res: Ok(()),
        job: Some(job),
        frame: LlFrame::default(),
        armed: [None; 2],
    };
    let l = new_bh_spinlock!(e, "isotp_engine")?;
    sk.shared().eng.set(KBox::new(l, GFP_KERNEL)?)?;
    sk.shared().eng.get().ok_or(ENOMEM)
}

/// Sleeps until `cond` holds on `eng` (interruptibly, no timeout, as
/// mainline's `wait_event_interruptible`). Process context.
fn wait_for(eng: &BhLock<Engine>, cond: impl Fn(&Engine) -> bool) -> Result {
    match WAITQ.wait(i64::MAX, &|| cond(&eng.lock())) {
        Waited::Ready => Ok(()),
        Waited::TimedOut | Waited::Interrupted => Err(ERESTARTSYS),
    }
}

impl glue::sock::Proto for IsotpProto {
    type Data = IsotpSock;
    type Shared = IsotpShared;

    /// `poll` withholds EPOLLOUT while a transfer runs (mainline
    /// `isotp_poll`); every end of a transfer wakes the socket's writers.
    const HAS_WRITABLE: bool = true;

    /// Process context (`poll`): whether the sender is idle.
    fn writable(sk: &S) -> bool {
        sk.shared()
            .eng
            .get()
            .map_or(true, |e| e.lock().tx.is_idle())
    }

    fn new_shared() -> IsotpShared {
        IsotpShared {
            bound: AtomicBool::new(false),
            eng: OnceBox::new(),
        }
    }

    fn new_data() -> IsotpSock {
        IsotpSock {
            cfg: Config::default(),
            bound: false,
            addr: TpAddr {
                ifindex: 0,
                rx_id: 0,
                tx_id: 0,
            },
        }
    }

    /// Mainline `isotp_release`: waits (interruptibly) for a running
    /// transmission to end, as mainline does (a sender that closes right
    /// after its write, as `isotpsend` does, still gets its PDU out);
    /// then unsubscribes, ends the reception and the timers go (cancelled
    /// and waited for; module documentation).
    fn release(sk: &S) {
        if let Some(eng) = sk.shared().eng.get() {
            // A signal ends the wait; the transfer is then cut short.
            let _ = wait_for(eng, |e| e.tx.is_idle() || !e.bound);
        }
        {
            let mut rtnl = Rtnl::lock();
            MODULE.sockets.get(&mut rtnl).remove(sk);
        }
        rcan_api::rx_remove(sk);
        let mut s = sk.lock();
        s.bound = false;
        sk.shared().bound.store(false, Ordering::Relaxed);
        let mut job = None;
        let mut out = After::new();
        if let Some(eng) = sk.shared().eng.get() {
            let mut e = eng.lock();
            e.bound = false;
            e.abort(&mut out);
            job = e.job.take();
        }
        drop(s);
        // Cancels both timers and waits for a running callback, which
        // finds the engine unbound and does nothing.
        drop(job);
        if out.wake {
            WAITQ.wake_all();
        }
    }

    /// Mainline `isotp_bind`, in its order of checks.
    fn bind(sk: &S, addr: &[u8]) -> Result {
        let mut s = sk.lock();
        let a = TpAddr::parse(&s.cfg, addr).map_err(errno)?;
        if s.bound {
            return Err(EINVAL);
        }
        let eng = engine(sk)?;
        {
            let e = eng.lock();
            if !e.tx.is_idle() || !e.rx.is_idle() {
                return Err(EAGAIN);
            }
        }
        a.check_distinct(&s.cfg).map_err(errno)?;
        let dev = DevRef::by_index(sk.net(), a.ifindex).ok_or(ENODEV)?;
        if !dev.is_can() {
            return Err(ENODEV);
        }
        if dev.mtu() < u32::from(s.cfg.ll.mtu) {
            return Err(EINVAL);
        }
        let down = !dev.is_up();
        let ifindex = dev.ifindex();
        drop(dev);
        let max = pdu_limit(MAX_PDU_SIZE.get()) as usize;
        let mut rxbuf = KVVec::from_elem(0u8, max, GFP_KERNEL)?;
        let fs = [
            RxFilter {
                kind: RX_FILTER_CAN_ID,
                id: a.tx_id,
                mask: single_mask(a.tx_id),
            },
            RxFilter {
                kind: RX_FILTER_CAN_ID,
                id: a.rx_id,
                mask: single_mask(a.rx_id),
            },
        ];
        let n = if s.cfg.registers_rx_id() { 2 } else { 1 };
        rcan_api::rx_set(sk, 0, ifindex, &fs[..n], false, 0)?;
        {
            let mut e = eng.lock();
            e.cfg = s.cfg;
            e.cfg.timeouts = Timeouts::from_ms(FC_TIMEOUT_MS.get(), ECHO_TIMEOUT_MS.get());
            e.addr = TpAddr { ifindex, ..a };
            e.tx = Tx::new();
            e.rx = Rx::new();
            core::mem::swap(&mut e.rxbuf, &mut rxbuf);
            e.bound = true;
        }
        drop(rxbuf);
        s.addr = TpAddr { ifindex, ..a };
        s.bound = true;
        sk.shared().bound.store(true, Ordering::Relaxed);
        drop(s);
        if down {
            sk.report_error(-neterr::ENETDOWN().to_errno());
        }
        Ok(())
    }

    fn connect(_sk: &S, _addr: &[u8], _flags: i32) -> Result {
        Err(neterr::EOPNOTSUPP())
    }

    /// Mainline `isotp_getname`: the bound address (16 bytes); the peer's
    /// is EOPNOTSUPP.
    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        if peer {
            return Err(neterr::EOPNOTSUPP());
        }
        let s = sk.lock();
        let b = s.addr.to_bytes();
        out.get_mut(..b.len()).ok_or(EINVAL)?.copy_from_slice(&b);
        Ok(b.len())
    }

    /// Mainline `isotp_sendmsg`: waits for (or, with MSG_DONTWAIT,
    /// refuses with EAGAIN) a running transfer, starts this one, and with
    /// `CAN_ISOTP_WAIT_TX_DONE` waits for its end and returns its result.
    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        if !sk.shared().bound.load(Ordering::Relaxed) {
            return Err(neterr::EADDRNOTAVAIL());
        }
        let eng = sk.shared().eng.get().ok_or(neterr::EADDRNOTAVAIL())?;
        let nonblock = msg.flags() & glue::msg::DONTWAIT != 0;
        let idle_or_unbound = |e: &Engine| e.tx.is_idle() || !e.bound;
        if !idle_or_unbound(&eng.lock()) {
            if nonblock {
                return Err(EAGAIN);
            }
            wait_for(eng, idle_or_unbound)?;
        }
        let (cfg, max) = {
            let e = eng.lock();
            if !e.bound {
                return Err(neterr::EADDRNOTAVAIL());
            }
            (e.cfg, e.rxbuf.len())
        };
        cfg.check_send_len(len, max as u32).map_err(errno)?;
        let mut buf = KVVec::from_elem(0u8, len, GFP_KERNEL)?;
        msg.copy_from_user(&mut buf)?;
        let now = ktime_get_mono_ns() as u64;
        loop {
            let mut out = After::new();
            let r = {
                let mut g = eng.lock();
                let e = &mut *g;
                if !e.bound {
                    return Err(neterr::EADDRNOTAVAIL());
                }
                match e.tx.start_into(&e.cfg, &buf, now, &mut e.frame) {
                    Ok(a) => {
                        core::mem::swap(&mut e.txbuf, &mut buf);
                        e.tx_gen += 1;
                        e.tx_step(a.done, &mut out);
                        Ok((e.tx_gen, e.addr.ifindex, Image::of(e, a.frame)))
                    }
                    Err(err) => Err(err),
                }
            };
            let (gen, ifindex, img) = match r {
                Ok(v) => v,
                // Another sendmsg of this socket took the sender first.
                Err(err) if err == rcan_core::isotp::EAGAIN => {
                    if nonblock {
                        return Err(EAGAIN);
                    }
                    wait_for(eng, idle_or_unbound)?;
                    continue;
                }
                Err(err) => return Err(errno(err)),
            };
            drop(buf);
            let sent = send_frame_by_index(sk, ifindex, &img);
            out.run(sk);
            if let Err(err) = sent {
                // The first frame did not go out: no transfer.
                let mut g = eng.lock();
                let e = &mut *g;
                if e.tx_gen == gen {
                    let _ = e.tx.abort();
                    e.sync_tx_timer();
                    e.done_gen = gen;
                }
                drop(g);
                WAITQ.wake_all();
                sk.wake_writers();
                return Err(err);
            }
            if !cfg.has(CAN_ISOTP_WAIT_TX_DONE) {
                return Ok(len);
            }
            let done = |e: &Engine| e.done_gen >= gen || !e.bound;
            if let Err(err) = wait_for(eng, done) {
                // Interrupted: mainline ends the transfer.
                let mut g = eng.lock();
                let e = &mut *g;
                if e.tx_gen == gen && e.done_gen < gen {
                    let _ = e.tx.abort();
                    e.sync_tx_timer();
                    e.done_gen = gen;
                }
                drop(g);
                WAITQ.wake_all();
                sk.wake_writers();
                return Err(err);
            }
            let res = {
                let e = eng.lock();
                if e.done_gen == gen && e.bound {
                    e.done_res
                } else {
                    Ok(())
                }
            };
            // Drained so that poll()/SO_ERROR see no stale error, as
            // mainline.
            let pending = sk.take_error();
            return match res {
                Err(e) => Err(errno(e)),
                Ok(()) if pending != 0 && !sk.shared().bound.load(Ordering::Relaxed) => {
                    Err(errno(pending))
                }
                Ok(()) => Ok(len),
            };
        }
    }

    /// Mainline `isotp_recvmsg`: one PDU per datagram; MSG_TRUNC when the
    /// buffer is shorter (and, asked for, the PDU's full length returned);
    /// the source address is 16 bytes (family and interface).
    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        let allowed = glue::msg::DONTWAIT | glue::msg::TRUNC | MSG_PEEK | MSG_CMSG_COMPAT;
        if flags as u32 & !allowed != 0 {
            return Err(EINVAL);
        }
        if !sk.shared().bound.load(Ordering::Relaxed) {
            return Err(neterr::EADDRNOTAVAIL());
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
        msg.recv_cmsgs(sk, &skb);
        let mut name = [0u8; ISOTP_MIN_NAMELEN];
        skb.cb_read(0, &mut name);
        msg.set_name(&name);
        sk.free_datagram(skb);
        Ok(if flags as u32 & glue::msg::TRUNC != 0 {
            n
        } else {
            size
        })
    }

    /// Mainline `isotp_setsockopt` (checks in `rcan_core::isotp`). The
    /// value is read from user memory (EFAULT) only where mainline reads
    /// it: at the right level, unbound, a known option of its exact size;
    /// otherwise the parser gets the length alone (zeros) and answers
    /// EINVAL, EISCONN or ENOPROTOOPT as mainline does. Process context.
    fn setsockopt(sk: &S, level: i32, name: i32, opt: &OptIn) -> Result {
        let size = match name {
            CAN_ISOTP_OPTS => IsotpOptions::SIZE,
            CAN_ISOTP_RECV_FC | CAN_ISOTP_LL_OPTS => 3,
            CAN_ISOTP_TX_STMIN | CAN_ISOTP_RX_STMIN => 4,
            _ => 0,
        };
        let mut val = [0u8; MAX_OPTLEN + 1];
        let n = opt.len().min(MAX_OPTLEN + 1);
        let mut s = sk.lock();
        let bound = s.bound;
        if level == SOL_CAN_ISOTP && !bound && size != 0 && n == size {
            opt.read(&mut val[..n])?;
        }
        s.cfg
            .setsockopt(level, name, &val[..n], bound)
            .map_err(errno)
    }

    /// Mainline `isotp_getsockopt`.
    fn getsockopt(sk: &S, level: i32, name: i32, opt: &OptOut) -> Result {
        let len = opt.len()?;
        let (img, n) = {
            let s = sk.lock();
            s.cfg.getsockopt(level, name, len).map_err(errno)?
        };
        opt.set_len(n as i32)?;
        opt.write(&img[..n])
    }
}

/// `MSG_PEEK` and `MSG_CMSG_COMPAT` of `<linux/socket.h>`.
const MSG_PEEK: u32 = 2;
const MSG_CMSG_COMPAT: u32 = 0x8000_0000;

/// The module: its registrations, undone when it is dropped (unload).
pub(crate) struct IsotpModule {
    _reg: ProtoRegistration<IsotpProto>,
}

impl ScopedModule for IsotpModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let reg = MODULE.register(c_str!("CAN_ISOTP"), scope)?;
        pr_info!(
            "CAN_ISOTP ({}) registered, max_pdu_size {}\n",
            CAN_ISOTP,
            clamp_max_pdu_size(MAX_PDU_SIZE.get())
        );
        Ok(IsotpModule { _reg: reg })
    }
}
