// SPDX-License-Identifier: GPL-2.0

//! The DSOR protocol engine: all protocol state of `rcan_dsor` in one
//! [`Engine`], one while the module is loaded, under one lock,
//! [`ENGINE`]. It runs the pure machines of `rcan_core::dsor_tx` (a
//! [`FdTransfer`] per outgoing message, channels and sequence bits in
//! [`TxStreams`], the FD-or-classic memory of the peers in [`FdPeers`])
//! and `rcan_core::dsor_rx` (the [`Reassembler`]), feeds them frames
//! (from `rx.rs`) and time (from `timers.rs`), and queues the frames they
//! produce on a ring that `timers.rs` sends.
//!
//! CAN FD bodies (dsor-wire.rst, "Message transfer with CAN FD bodies"):
//! used only while the DSOR interface is in CAN FD mode (MTU 72,
//! `Engine::fd_iface`); then the receiver answers FD headers choosing
//! 64-byte bodies, and a message longer than 8 bytes goes out with an FD
//! header offering 64 unless [`FdPeers`] knows its destination as classic.
//!
//! Locks: [`ENGINE`] (BH spinlock) protects every field of the engine and
//! is taken in process context, NET_RX softirq, HRTIMER_SOFTIRQ and
//! canip0's transmit path (the list and the lock order are in
//! `candsor.rs`). [`WAITQ`] has its own lock; it is woken after ENGINE is
//! dropped.

#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox, KVec};
use kernel::c_str;
use kernel::prelude::*;

use crate::glue::hrtimer::ktime_get_mono_ns;
use crate::glue::lock::{BhSpinLock, WaitQueue};
use crate::glue::netdev::DevRef;
use crate::glue::neterr;
use crate::glue::ring::Ring;
use crate::glue::sock::SockRef;
use crate::params::{Config, PARAM_REASM_TIMEOUT_MS};
use crate::rcan_core::dsor_addr::DsorAddr;
use crate::rcan_core::dsor_fd::{BodySize, FdPeers, FdStep, FdTransfer};
use crate::rcan_core::dsor_rx::{Incoming, Limits, Reassembler};
use crate::rcan_core::dsor_tx::{TxError, TxStreams};
use crate::rcan_core::dsor_wire::{AckStatus, DsorId, FdFrame, FrameType, Header};
use crate::rx::{accept, deliver, wanted, RxBuf};
use crate::socket::DsorProto;
use crate::stats::Stats;
use crate::timers::TIMER;
use crate::udpip;

/// Reassembly slots (concurrent incoming messages, Done states included).
pub(crate) const RX_SLOTS: usize = 64;
/// Concurrent outgoing messages (all sockets and canip0 together).
const TX_SLOTS: usize = 64;
/// Frames queued for [`Tick`](crate::timers::Tick) to send.
const OUT_LEN: usize = 256;

/// Who waits for an outgoing message.
pub(crate) enum Owner {
    /// A blocking `sendmsg`, sleeping on [`WAITQ`] for [`TxEntry::Finished`].
    Waiter,
    /// A non-blocking `sendmsg`: a failure is reported on the socket.
    Sock(SockRef<DsorProto>),
    /// `canip0`: failures are counted on the device.
    Canip,
}

/// A running outgoing message.
pub(crate) struct TxRun {
    t: FdTransfer,
    msg: KVec<u8>,
    dst: u8,
    chan: u8,
    pub(crate) gen: u32,
    owner: Owner,
}

pub(crate) enum TxEntry {
    Free,
    Running(TxRun),
    /// Finished; kept until its blocking sender collects the result
    /// (0 or a negative errno).
    Finished {
        gen: u32,
        result: i32,
    },
}

/// A bound socket.
pub(crate) struct Bind {
    /// The bound socket: the reference keeps it valid for the receive
    /// path until `remove_bind` (from its release) drops the Bind.
    pub(crate) sk: SockRef<DsorProto>,
    pub(crate) addr: DsorAddr,
}

pub(crate) struct Engine {
    pub(crate) cfg: Config,
    rx: KBox<Reassembler<RxBuf, RX_SLOTS>>,
    pub(crate) streams: KBox<TxStreams>,
    pub(crate) tx: KVec<TxEntry>,
    next_gen: u32,
    /// Frames to send, oldest first ([`OUT_LEN`] at most).
    out: Ring<FdFrame>,
    pub(crate) binds: KVec<Bind>,
    /// canip0 while it is registered (a counted reference, set by
    /// `udpip::Canip::register`, taken back before it unregisters).
    pub(crate) canip: Option<DevRef>,
    pub(crate) stats: Stats,
    /// Whether the DSOR interface was in CAN FD mode (MTU 72) when last
    /// seen: by a `sendmsg` (set right before [`Engine::start`]) or by a
    /// received frame; false after it went down. canip0's transmit path
    /// uses it as it is.
    pub(crate) fd_iface: bool,
    /// What the sender knows of each node: FD (acked an FD header),
    /// classic (a fallback), unknown. Forgotten when the DSOR interface
    /// goes down or away ([`Engine::fail_all`]).
    peers: FdPeers,
    /// A drainer ([`drain_locked`](crate::timers::drain_locked), from
    /// [`Tick`](crate::timers::Tick) or from the receive callback) is
    /// running and will take every frame queued before it finds the queue
    /// empty (it checks and clears this in one critical section), so
    /// queuing a frame needs no [`Engine::kick`]. At most one drainer runs at a
    /// time, so frames leave in queue order.
    pub(crate) draining: bool,
    /// The expiry (monotonic ns) [`TIMER`] was last started for, if no
    /// run of [`Tick`](crate::timers::Tick) has begun since (each run
    /// clears it under this lock first): the timer is then queued for that
    /// time, or its run is about to take the lock. `None`: not known to be
    /// armed. The timer is started only under this lock ([`Engine::arm`]),
    /// so this is exact; it lets [`Engine::arm_for_deadline`] leave a
    /// timer alone that fires early enough, instead of re-queuing it after
    /// every frame.
    pub(crate) timer_at: Option<i64>,
    /// A lower bound (monotonic ms) of every protocol deadline set since
    /// the drainer last held the deadlines against the timer
    /// ([`Engine::arm_after_drain`]); `None`: none set since. A step of the
    /// machines at `now` sets deadlines no earlier than `now` +
    /// [`Engine::min_timeout_ms`] (T_ack for a transfer, T_reasm for a
    /// reassembly state), so [`Engine::note_step`] keeps this without
    /// looking at the machines.
    deadline_floor: Option<u64>,
    /// min(T_ack, T_reasm) of [`Engine::cfg`], ms.
    min_timeout_ms: u64,
}

/// All protocol state; `None` outside the module's lifetime.
pub(crate) static ENGINE: BhSpinLock<Option<KBox<Engine>>> =
    BhSpinLock::new(None, c_str!("rcan_dsor::ENGINE"));

/// Blocking senders wait here.
pub(crate) static WAITQ: WaitQueue = WaitQueue::new(c_str!("rcan_dsor::WAITQ"));

/// When the module was loaded (monotonic ms), for the restart rule
/// ([`restart_over_ms`]).
pub(crate) static LOADED_MS: AtomicU64 = AtomicU64::new(0);
/// The local node, for lock-free checks.
pub(crate) static NODE: AtomicU32 = AtomicU32::new(0);

pub(crate) fn now_ms() -> u64 {
    (ktime_get_mono_ns() / 1_000_000) as u64
}

impl Engine {
    /// Kicks [`Tick`](crate::timers::Tick) to send what was queued, unless a drainer is
    /// draining the queue anyway. Called with ENGINE held (it is the
    /// `&mut self`).
    pub(crate) fn kick(&mut self) {
        if !self.draining {
            self.arm(ktime_get_mono_ns());
        }
    }

    /// Starts [`TIMER`] for `at` (monotonic ns), moving it if queued, and
    /// notes it in [`Engine::timer_at`]. Under ENGINE, so a kick is never
    /// overwritten by an older re-arm.
    pub(crate) fn arm(&mut self, at: i64) {
        TIMER.start(at);
        self.timer_at = Some(at);
    }

    /// Notes that the machines stepped at `now` (ms): the deadlines they
    /// set are at `now` + [`Engine::min_timeout_ms`] or later.
    fn note_step(&mut self, now: u64) {
        let f = now.saturating_add(self.min_timeout_ms);
        self.deadline_floor = Some(self.deadline_floor.map_or(f, |x| x.min(f)));
    }

    /// The drainer found the queue empty: makes sure [`TIMER`] fires no
    /// later than the earliest protocol deadline. If it is armed
    /// ([`Engine::timer_at`]) no later than every deadline set since the
    /// last call ([`Engine::deadline_floor`]), nothing needs looking at:
    /// the deadlines older than those were held against it then (and a
    /// timer moved since was moved to "now" or cleared by its run).
    /// Otherwise the deadlines of all transfers and reassembly states are
    /// scanned ([`Engine::next_deadline`]) and the timer armed for the
    /// earliest if it fires later. Saves the scan of every slot per frame.
    pub(crate) fn arm_after_drain(&mut self) {
        let floor = self.deadline_floor.take();
        if let Some(t) = self.timer_at {
            if floor.is_none_or(|f| t <= (f as i64).saturating_mul(1_000_000)) {
                return;
            }
        }
        if let Some(d) = self.next_deadline() {
            self.arm_for_deadline(d);
        }
    }

    /// Arms [`TIMER`] for the protocol deadline `deadline_ms` (monotonic
    /// ms), unless it is armed for that time or earlier: a run before the
    /// deadline finds nothing due and arms the timer for the next one, so
    /// an early expiry costs one timer run, while starting the timer again
    /// after every frame (each moves the retransmission deadline later)
    /// costs an hrtimer dequeue and enqueue per frame.
    pub(crate) fn arm_for_deadline(&mut self, deadline_ms: u64) {
        let at = (deadline_ms as i64).saturating_mul(1_000_000);
        if self.timer_at.is_some_and(|t| t <= at) {
            return;
        }
        self.arm(at);
    }

    fn push_out(&mut self, f: FdFrame) {
        if self.out.push(f).is_err() {
            // The protocol recovers by retransmission.
            self.stats.out_overflow += 1;
        }
    }

    pub(crate) fn pop_out(&mut self) -> Option<FdFrame> {
        self.out.pop()
    }

    /// Ends the transfer in slot `i` with `result` (0 or a negative errno):
    /// frees its channel, tells its owner. Callers wake [`WAITQ`] after
    /// dropping the lock (a channel was freed).
    fn finish(&mut self, i: usize, result: i32) {
        let entry = core::mem::replace(&mut self.tx[i], TxEntry::Free);
        let TxEntry::Running(run) = entry else {
            self.tx[i] = entry;
            return;
        };
        self.streams.release(run.dst, run.chan, run.t.next_q());
        if result == 0 {
            self.stats.tx_ok += 1;
        } else {
            self.stats.tx_failed += 1;
        }
        match run.owner {
            Owner::Waiter => {
                self.tx[i] = TxEntry::Finished {
                    gen: run.gen,
                    result,
                }
            }
            Owner::Sock(sk) => {
                if result != 0 {
                    sk.sock().report_error(-result);
                }
            }
            Owner::Canip => {
                if result != 0 {
                    udpip::count_tx_error(self.canip.as_deref());
                }
            }
        }
    }

    /// Applies `step` of the transfer in slot `i`, first noting in
    /// [`FdPeers`] what the transfer learnt of its destination (an FD
    /// header acked, or a fallback to the classic header).
    fn apply_step(&mut self, i: usize, step: FdStep) -> bool {
        if let TxEntry::Running(r) = &self.tx[i] {
            if r.t.fell_back() {
                self.peers.on_fallback(r.dst);
            } else if r.t.fd_acked() {
                self.peers.on_fd_ack(r.dst);
            }
        }
        match step {
            FdStep::Nothing => false,
            FdStep::Send(f) => {
                self.push_out(f);
                true
            }
            FdStep::Done => {
                self.finish(i, 0);
                true
            }
            FdStep::Failed(e) => {
                self.finish(i, tx_errno(e));
                true
            }
        }
    }

    /// Starts a message to `dst`; returns the slot and its generation, or
    /// `None` when no slot or no channel to `dst` is free. With the DSOR
    /// interface in FD mode ([`Engine::fd_iface`]) a message longer than 8
    /// bytes to a node not known as classic starts with an FD header
    /// offering 64-byte bodies; otherwise it is a classic transfer.
    pub(crate) fn start(
        &mut self,
        dst: u8,
        prio: u8,
        header: Header,
        msg: KVec<u8>,
        owner: Owner,
    ) -> core::result::Result<(usize, u32), (KVec<u8>, Owner)> {
        let Some(i) = self.tx.iter().position(|e| matches!(e, TxEntry::Free)) else {
            return Err((msg, owner));
        };
        let Some((chan, first_q)) = self.streams.alloc(dst) else {
            return Err((msg, owner));
        };
        let offer =
            (self.fd_iface && self.peers.use_fd_header(dst, header.len)).then_some(BodySize::MAX);
        let mut t = FdTransfer::new_fd(
            self.cfg.node,
            dst,
            chan,
            prio,
            header,
            first_q,
            &self.cfg.timers,
            offer,
        );
        let now = now_ms();
        let f = t.start(&msg, now);
        self.note_step(now);
        self.push_out(f);
        let gen = self.next_gen;
        self.next_gen = self.next_gen.wrapping_add(1);
        self.tx[i] = TxEntry::Running(TxRun {
            t,
            msg,
            dst,
            chan,
            gen,
            owner,
        });
        Ok((i, gen))
    }

    /// Aborts the running transfer `(i, gen)` of a blocking sender that
    /// stopped waiting, or collects its result if it finished meanwhile.
    pub(crate) fn abandon(&mut self, i: usize, gen: u32, errno: i32) -> i32 {
        match &self.tx[i] {
            TxEntry::Running(r) if r.gen == gen => {
                self.finish(i, errno);
                self.tx[i] = TxEntry::Free;
                errno
            }
            TxEntry::Finished { gen: g, result } if *g == gen => {
                let r = *result;
                self.tx[i] = TxEntry::Free;
                r
            }
            _ => errno,
        }
    }

    /// Fails every running transfer (the interface went down or away);
    /// forgets the interface's FD mode and what is known of the peers.
    pub(crate) fn fail_all(&mut self, errno: i32) {
        self.fd_iface = false;
        self.peers.forget_all();
        for i in 0..self.tx.len() {
            self.finish(i, errno);
        }
        self.stats.rx_flushed += self.rx.clear() as u64;
    }

    /// Handles one DSOR frame addressed to this node (its data: the
    /// payload, padding included, of a classic or FD frame), received on
    /// the DSOR interface, which is in FD mode if `fd_iface`: then FD
    /// headers are answered, choosing 64-byte bodies; else they are
    /// ignored as by a classic node.
    pub(crate) fn on_frame(&mut self, id: &DsorId, data: &[u8], fd_iface: bool, now: u64) -> bool {
        self.note_step(now);
        self.fd_iface = fd_iface;
        if self.rx.fd_body_size().is_some() != fd_iface {
            self.rx.set_fd_body_size(fd_iface.then_some(BodySize::MAX));
        }
        if matches!(id.ftype, FrameType::Ack) {
            let mut kick = false;
            for i in 0..self.tx.len() {
                let step = match &mut self.tx[i] {
                    TxEntry::Running(r) if r.dst == id.src && r.chan == id.chan => {
                        r.t.on_ack(id, data, &r.msg, now)
                    }
                    _ => continue,
                };
                kick |= self.apply_step(i, step);
                break;
            }
            return kick;
        }
        let canip_up = udpip::is_up(self.canip.as_deref());
        let Engine {
            rx,
            binds,
            cfg,
            stats,
            canip,
            ..
        } = self;
        let out = rx.on_frame_with(
            id,
            data,
            now,
            |inc: &Incoming<'_>| accept(binds, canip_up, inc),
            |d| deliver(binds, canip.as_deref(), cfg, stats, d),
        );
        match out.header_refused {
            None => {}
            Some(AckStatus::TooLong) => self.stats.rx_refused_too_long += 1,
            Some(AckStatus::NoMemory) => self.stats.rx_refused_no_memory += 1,
            Some(_) => self.stats.rx_refused_unwanted += 1,
        }
        match out.ack {
            Some(ack) => {
                self.push_out(ack.into());
                true
            }
            None => false,
        }
    }

    /// A socket was closed (its bind is already gone): partial messages
    /// that no remaining socket wants are stopped; the next frame of each
    /// is refused, so their senders fail with ECONNREFUSED instead of
    /// sending the rest for nothing.
    pub(crate) fn refuse_orphans(&mut self) {
        let canip_up = udpip::is_up(self.canip.as_deref());
        let binds = &self.binds;
        let n = self.rx.refuse_partial(
            |inc: &Incoming<'_>| wanted(binds, canip_up, inc),
            AckStatus::Refused,
        );
        self.stats.rx_closed += n as u64;
    }

    /// Runs due timers; returns whether frames were queued.
    pub(crate) fn on_timer(&mut self, now: u64) -> bool {
        self.note_step(now);
        let mut kick = false;
        self.stats.rx_timed_out += self.rx.on_timer(now) as u64;
        for i in 0..self.tx.len() {
            let step = match &mut self.tx[i] {
                TxEntry::Running(r) if r.t.deadline().is_some_and(|d| d <= now) => {
                    r.t.on_timer(&r.msg, now)
                }
                _ => continue,
            };
            kick |= self.apply_step(i, step);
        }
        kick
    }

    pub(crate) fn next_deadline(&self) -> Option<u64> {
        let mut d = self.rx.next_deadline();
        for e in self.tx.iter() {
            if let TxEntry::Running(r) = e {
                if let Some(t) = r.t.deadline() {
                    d = Some(d.map_or(t, |x| x.min(t)));
                }
            }
        }
        d
    }
}

fn tx_errno(e: TxError) -> i32 {
    let err = match e {
        TxError::TimedOut => neterr::ETIMEDOUT(),
        TxError::Refused => neterr::ECONNREFUSED(),
        TxError::NoMemory => neterr::ENOBUFS(),
        TxError::TooLong => neterr::EMSGSIZE(),
    };
    err.to_errno()
}

/// When the restart rule (`restart_hold` in socket.rs) stops holding zero-length
/// messages (monotonic ms). Any context.
pub(crate) fn restart_over_ms() -> u64 {
    LOADED_MS.load(Ordering::Relaxed) + u64::from(PARAM_REASM_TIMEOUT_MS.get())
}

pub(crate) fn new_engine(cfg: Config) -> Result<KBox<Engine>> {
    let limits = Limits {
        max_len: cfg.limits_max_len,
        max_per_peer: cfg.max_per_peer,
        max_bytes_total: cfg.max_bytes,
    };
    let rx = KBox::new(Reassembler::new(cfg.node, limits, &cfg.timers), GFP_KERNEL)?;
    let streams = KBox::new(TxStreams::new(), GFP_KERNEL)?;
    let mut tx = KVec::with_capacity(TX_SLOTS, GFP_KERNEL)?;
    for _ in 0..TX_SLOTS {
        tx.push(TxEntry::Free, GFP_KERNEL)?;
    }
    let out = Ring::new(OUT_LEN)?;
    let min_timeout_ms = u64::from(cfg.timers.ack_timeout_ms.min(cfg.timers.reasm_timeout_ms));
    Ok(KBox::new(
        Engine {
            cfg,
            rx,
            streams,
            tx,
            next_gen: 1,
            out,
            binds: KVec::new(),
            canip: None,
            stats: Stats::default(),
            fd_iface: false,
            peers: FdPeers::new(),
            draining: false,
            timer_at: None,
            deadline_floor: None,
            min_timeout_ms,
        },
        GFP_KERNEL,
    )?)
}
