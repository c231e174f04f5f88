// SPDX-License-Identifier: GPL-2.0

//! rcan_dsor: the DSOR higher-layer CAN protocol (thesis 5.2.6 and 5.3.3,
//! module `candsor`: `dsor/protocol.c`, `dsor/socket.c`, `dsor/udpip.c`).
//!
//! `socket(PF_CAN, SOCK_DGRAM, CANPROTO_DSOR)` sends and receives messages
//! of up to 65535 bytes, carried reliably (stop-and-wait) in header, body
//! and ack frames on one CAN interface (parameter `ifname`). The wire
//! format is Documentation/networking/rcan/dsor-wire.rst; the socket API,
//! parameters and errors are Documentation/networking/rcan/dsor.rst. The
//! protocol machines are the pure `rcan_core::dsor_tx` / `dsor_rx`; this
//! file runs them: it owns their state, feeds them frames and time, and
//! sends what they produce. `udpip.rs` adds the `canip0` device (UDP/IP
//! over DSOR).
//!
//! Contexts and locks:
//!
//! * [`ENGINE`] (a BH spinlock, lockdep class `rcan_dsor::ENGINE`) protects all
//!   protocol state: the reassembly table, the running transfers, the
//!   stream table, the bound sockets and the queue of frames to send. It is
//!   taken in process context (system calls), in the NET_RX softirq
//!   ([`DsorRx::rx`], the receive callback), in the `HRTIMER_SOFTIRQ`
//!   ([`Tick`]) and in `canip0`'s transmit path. Nothing sleeps or sends
//!   frames under it; socket receive queues (their own spinlock) are fed
//!   under it, so the order is ENGINE -> queue lock.
//! * Frames are not sent from the receive callback (which runs in NET_RX
//!   softirq and could send, see `KernelRx` in rust/glue/can/proto.rs;
//!   this protocol keeps one sender): every frame is queued on
//!   `Engine::out` and sent by [`Tick`], a soft hrtimer that is kicked to
//!   "now" whenever frames are queued and otherwise armed for the earliest
//!   protocol deadline.
//! * Blocking senders sleep on [`WAITQ`] until their
//!   transfer has finished; every finished transfer and every freed
//!   channel wakes all waiters, which re-check under the lock.
//! * [`MODULE`]`.sockets` (every open socket, for the notifier) is under
//!   RTNL, as in the other protocol modules.

#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use kernel::alloc::{flags::GFP_KERNEL, KBox, KVec};
use kernel::prelude::*;

use crate::{glue, rcan_api, rcan_core};
#[path = "udpip.rs"]
mod udpip;

use glue::bindings;
use glue::hrtimer::{ktime_get_mono_ns, ClockId, HrTimer, HrTimerCallback, HrTimerMode};
use glue::lock::{BhSpinLock, WaitQueue, Waited};
use glue::netdev::{DevRef, NetDev};
use glue::neterr;
use glue::params::{Param, ParamStr};
use glue::skb::Skb;
use glue::sock::{Msg, Sock, SockRef};
use glue::sync::Rtnl;
use kernel::c_str;
use rcan_api::{
    CanProtocol, KernelRx, KernelRxReg, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter,
    Sockets, RX_FILTER_CAN_ID, SOCK_DGRAM,
};
use rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG};
use rcan_core::dsor_addr::{self, DsorAddr, DSOR_EPHEMERAL_MIN};
use rcan_core::dsor_rx::{Delivered, Incoming, Limits, Reassembler};
use rcan_core::dsor_tx::{Transfer, TxError, TxStep, TxStreams};
use rcan_core::dsor_wire::{self, AckStatus, DsorId, Frame, FrameType, Header, MsgKind, Timers};
use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};

/// `CANPROTO_DSOR` in `<linux/can/rcan.h>`.
const CANPROTO_DSOR: i32 = 17;
/// Reassembly slots (concurrent incoming messages, Done states included).
const RX_SLOTS: usize = 64;
/// Concurrent outgoing messages (all sockets and canip0 together).
const TX_SLOTS: usize = 64;
/// Frames queued for [`Tick`] to send.
const OUT_LEN: usize = 256;
/// Frames sent per batch (taken from the queue under the lock).
const BATCH: usize = 16;
/// Frames one run of [`Tick`] sends at most before it re-arms itself for
/// "now" and returns, so that one long message (which, with the direct
/// echo, is acked within the same run: the queue then holds one frame at a
/// time) does not hold the softirq for its whole length. About the 2 ms
/// the kernel gives one softirq pass at ~2 us per frame (~8 ms under TCG).
const FRAMES_PER_RUN: usize = 1024;
/// Headroom for mainline's `struct can_skb_priv`.
const SKB_PRIV_LEN: u32 = core::mem::size_of::<bindings::can_skb_priv>() as u32;
/// Headroom of reassembly buffers: rebuilt IPv4 + UDP headers of canip0.
const RX_HEADROOM: u32 = rcan_core::dsor_udp::HDR_LEN as u32 + 2;

// ---------------------------------------------------------------------------
// Parameters (C side: candsor_c.c)

// Parameter numbers shared with candsor_c.c (its rcan_module_param and
// rcan_module_param_str).
const PARAM_NODE: Param<u32> = Param::new(0);
const PARAM_ACK_TIMEOUT_MS: Param<u32> = Param::new(1);
const PARAM_MAX_RETX: Param<u32> = Param::new(2);
const PARAM_REASM_TIMEOUT_MS: Param<u32> = Param::new(3);
const PARAM_MAX_LEN: Param<u32> = Param::new(4);
const PARAM_MAX_PER_PEER: Param<u32> = Param::new(5);
const PARAM_MAX_BYTES: Param<u32> = Param::new(6);
const PARAM_UDP_PRIO: Param<u32> = Param::new(7);
const PARAM_CANIP: Param<bool> = Param::new(8);
/// `ifname`: copied NUL-terminated, at most 15 bytes.
const PARAM_IFNAME: ParamStr = ParamStr::new(9);
/// `udp_saddr`: copied NUL-terminated, at most 15 bytes.
const PARAM_UDP_SADDR: ParamStr = ParamStr::new(10);

/// An interface name or address string of the C side: 16 bytes, NUL-padded.
#[derive(Clone, Copy)]
struct Name([u8; 16]);

impl Name {
    fn bytes(&self) -> &[u8] {
        let n = self.0.iter().position(|&b| b == 0).unwrap_or(15);
        &self.0[..n]
    }

    fn as_cstr(&self) -> &kernel::str::CStr {
        let n = self.bytes().len();
        kernel::str::CStr::from_bytes_with_nul(&self.0[..=n]).unwrap_or(c_str!("?"))
    }

    fn as_str(&self) -> &str {
        core::str::from_utf8(self.bytes()).unwrap_or("?")
    }
}

/// Settings fixed at load: the parameters, validated.
struct Config {
    node: u8,
    ifname: Name,
    timers: Timers,
    limits_max_len: u16,
    max_per_peer: u8,
    max_bytes: usize,
    udp_saddr: u32,
    udp_prio: u8,
    canip: bool,
}

/// Fails the load with EINVAL and a `dmesg` line naming the parameter, its
/// value and the allowed range (dsor.rst, "Loading").
fn bad_param(name: &str, value: impl core::fmt::Display, range: &str) -> Error {
    pr_err!("{}={}: out of range, allowed {}\n", name, value, range);
    EINVAL
}

/// The `ifname` rules of the kernel's `dev_valid_name`: 1 to 15 bytes, no
/// '/', ':' or white space, not "." or "..".
fn valid_ifname(name: &[u8]) -> bool {
    (1..IFNAMSIZ).contains(&name.len())
        && name != b"."
        && name != b".."
        && !name
            .iter()
            .any(|&c| c == b'/' || c == b':' || c.is_ascii_whitespace())
}

/// Bytes of an interface name including the NUL (`IFNAMSIZ`).
const IFNAMSIZ: usize = 16;

fn load_config() -> Result<Config> {
    let mut ifname = Name([0; 16]);
    let mut saddr = Name([0; 16]);
    let ifname_len = PARAM_IFNAME.read(&mut ifname.0);
    let saddr_len = PARAM_UDP_SADDR.read(&mut saddr.0);
    let node = PARAM_NODE.get();
    let timers = Timers {
        ack_timeout_ms: PARAM_ACK_TIMEOUT_MS.get(),
        max_retx: PARAM_MAX_RETX.get(),
        reasm_timeout_ms: PARAM_REASM_TIMEOUT_MS.get(),
    };
    let max_len = PARAM_MAX_LEN.get();
    let per_peer = PARAM_MAX_PER_PEER.get();
    let max_bytes = PARAM_MAX_BYTES.get();
    let udp_prio = PARAM_UDP_PRIO.get();
    if node > u32::from(dsor_wire::MAX_NODE) {
        return Err(bad_param("node", node, "0x00-0x7f"));
    }
    // The C side copies at most 15 bytes; the length is the whole string's.
    if ifname_len >= IFNAMSIZ || !valid_ifname(ifname.bytes()) {
        pr_err!(
            "ifname: not an interface name ({} bytes), allowed 1-15 bytes without '/', ':' or white space\n",
            ifname_len
        );
        return Err(EINVAL);
    }
    let Some(udp_saddr) =
        rcan_core::dsor_udp::parse_ipv4_addr(saddr.bytes()).filter(|_| saddr_len < IFNAMSIZ)
    else {
        pr_err!("udp_saddr: not an IPv4 address, allowed a.b.c.d\n");
        return Err(EINVAL);
    };
    if !(10..=60_000).contains(&timers.ack_timeout_ms) {
        return Err(bad_param(
            "ack_timeout_ms",
            timers.ack_timeout_ms,
            "10-60000",
        ));
    }
    if timers.max_retx > 100 {
        return Err(bad_param("max_retx", timers.max_retx, "0-100"));
    }
    let window = u64::from(timers.ack_timeout_ms) * (u64::from(timers.max_retx) + 1);
    if u64::from(timers.reasm_timeout_ms) <= window || timers.reasm_timeout_ms > 600_000 {
        pr_err!(
            "reasm_timeout_ms={}: out of range, allowed {}-600000 (more than ack_timeout_ms * (max_retx + 1))\n",
            timers.reasm_timeout_ms,
            window + 1
        );
        return Err(EINVAL);
    }
    if !(1..=dsor_wire::MAX_LEN as u32).contains(&max_len) {
        return Err(bad_param("max_len", max_len, "1-65535"));
    }
    if !(1..=(RX_SLOTS as u32)).contains(&per_peer) {
        pr_err!(
            "max_per_peer={}: out of range, allowed 1-{}\n",
            per_peer,
            RX_SLOTS
        );
        return Err(EINVAL);
    }
    if !(max_len..=MAX_BYTES_LIMIT).contains(&max_bytes) {
        pr_err!(
            "max_bytes={}: out of range, allowed max_len ({})-{}\n",
            max_bytes,
            max_len,
            MAX_BYTES_LIMIT
        );
        return Err(EINVAL);
    }
    if udp_prio > 0xff {
        return Err(bad_param("udp_prio", udp_prio, "0x00-0xff"));
    }
    Ok(Config {
        node: node as u8,
        ifname,
        timers,
        limits_max_len: max_len as u16,
        max_per_peer: per_peer as u8,
        max_bytes: max_bytes as usize,
        udp_saddr,
        udp_prio: udp_prio as u8,
        canip: PARAM_CANIP.get(),
    })
}

/// Largest `max_bytes`: 64 slots of the longest message.
const MAX_BYTES_LIMIT: u32 = RX_SLOTS as u32 * dsor_wire::MAX_LEN as u32;

// ---------------------------------------------------------------------------
// Protocol state

/// A reassembly buffer: an skb with room in front for canip0's headers.
struct RxBuf(Skb);

impl AsMut<[u8]> for RxBuf {
    fn as_mut(&mut self) -> &mut [u8] {
        self.0.data_mut()
    }
}

/// Who waits for an outgoing message.
enum Owner {
    /// A blocking `sendmsg`, sleeping on [`WAITQ`] for [`TxEntry::Finished`].
    Waiter,
    /// A non-blocking `sendmsg`: a failure is reported on the socket.
    Sock(SockRef<DsorProto>),
    /// `canip0`: failures are counted on the device.
    Canip,
}

/// A running outgoing message.
struct TxRun {
    t: Transfer,
    msg: KVec<u8>,
    dst: u8,
    chan: u8,
    gen: u32,
    owner: Owner,
}

enum TxEntry {
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
struct Bind {
    /// The bound socket: the reference keeps it valid for the receive
    /// path until `remove_bind` (from its release) drops the Bind.
    sk: SockRef<DsorProto>,
    addr: DsorAddr,
}

/// Counters, printed at unload (the tests read them from dmesg). Every
/// incoming message that is not delivered is counted once, by cause.
#[derive(Default)]
struct Stats {
    tx_ok: u64,
    tx_failed: u64,
    /// Messages queued on at least one socket, or handed to canip0.
    rx_delivered: u64,
    /// Headers refused: no socket (or canip0) wants the message (REFUSED).
    rx_refused_unwanted: u64,
    /// Headers refused: over `max_len` (TOO_LONG).
    rx_refused_too_long: u64,
    /// Headers refused: over `max_per_peer` or `max_bytes`, no slot, or no
    /// memory for the buffer (NO_MEMORY).
    rx_refused_no_memory: u64,
    /// Complete messages refused with the last frame: the receive queue of
    /// every socket that wanted it was full (NO_MEMORY).
    rx_queue_full: u64,
    /// Complete messages refused with the last frame: no socket (or no
    /// canip0 up) wants it any more (REFUSED).
    rx_unwanted_at_end: u64,
    /// Partial messages stopped because the last socket that wanted them
    /// was closed (their next body is refused, REFUSED).
    rx_closed: u64,
    /// Partial messages freed after `reasm_timeout_ms` without a frame.
    rx_timed_out: u64,
    /// Partial messages freed when `ifname` went down or the module was
    /// unloaded.
    rx_flushed: u64,
    /// Extra copies (a message wanted by several sockets) that did not fit
    /// a socket's receive queue; the message reached another socket.
    rx_copies_dropped: u64,
    /// Frames not sent because the send ring was full (recovered by
    /// retransmission).
    out_overflow: u64,
    send_errors: u64,
}

struct Engine {
    cfg: Config,
    rx: KBox<Reassembler<RxBuf, RX_SLOTS>>,
    streams: KBox<TxStreams>,
    tx: KVec<TxEntry>,
    next_gen: u32,
    /// Ring of frames to send: `out[(out_head + i) % OUT_LEN]`, i < out_len.
    out: KVec<Frame>,
    out_head: usize,
    out_len: usize,
    binds: KVec<Bind>,
    /// canip0 while it is registered (a counted reference, set by
    /// `udpip::Canip::register`, taken back before it unregisters).
    canip: Option<DevRef>,
    stats: Stats,
    /// A drainer ([`drain`], from [`Tick`] or from the receive callback)
    /// is running and will take every frame queued before it finds the
    /// queue empty (it checks and clears this in one critical section), so
    /// queuing a frame needs no [`kick`]. At most one drainer runs at a
    /// time, so frames leave in queue order.
    draining: bool,
}

/// All protocol state; `None` outside the module's lifetime.
static ENGINE: BhSpinLock<Option<KBox<Engine>>> =
    BhSpinLock::new(None, c_str!("rcan_dsor::ENGINE"));

/// Blocking senders wait here.
static WAITQ: WaitQueue = WaitQueue::new(c_str!("rcan_dsor::WAITQ"));

/// Set by module exit: the timer neither sends nor re-arms.
static STOPPING: AtomicBool = AtomicBool::new(false);
/// When the module was loaded (monotonic ms), for [`restart_hold`].
static LOADED_MS: AtomicU64 = AtomicU64::new(0);
/// The local node, for lock-free checks.
static NODE: AtomicU32 = AtomicU32::new(0);

fn now_ms() -> u64 {
    (ktime_get_mono_ns() / 1_000_000) as u64
}

impl Engine {
    /// Kicks [`Tick`] to send what was queued, unless it is draining the
    /// queue anyway. Called with ENGINE held (it is the `&mut self`).
    fn kick(&self) {
        if !self.draining {
            kick();
        }
    }

    fn push_out(&mut self, f: Frame) {
        if self.out_len == OUT_LEN {
            // The protocol recovers by retransmission.
            self.stats.out_overflow += 1;
            return;
        }
        let i = (self.out_head + self.out_len) % OUT_LEN;
        self.out[i] = f;
        self.out_len += 1;
    }

    fn pop_out(&mut self) -> Option<Frame> {
        if self.out_len == 0 {
            return None;
        }
        let f = self.out[self.out_head].clone();
        self.out_head = (self.out_head + 1) % OUT_LEN;
        self.out_len -= 1;
        Some(f)
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

    fn apply_step(&mut self, i: usize, step: TxStep) -> bool {
        match step {
            TxStep::Nothing => false,
            TxStep::Send(f) => {
                self.push_out(f);
                true
            }
            TxStep::Done => {
                self.finish(i, 0);
                true
            }
            TxStep::Failed(e) => {
                self.finish(i, tx_errno(e));
                true
            }
        }
    }

    /// Starts a message to `dst`; returns the slot and its generation, or
    /// `None` when no slot or no channel to `dst` is free.
    fn start(
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
        let mut t = Transfer::new(
            self.cfg.node,
            dst,
            chan,
            prio,
            header,
            first_q,
            &self.cfg.timers,
        );
        let f = t.start(&msg, now_ms());
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
    fn abandon(&mut self, i: usize, gen: u32, errno: i32) -> i32 {
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

    /// Fails every running transfer (the interface went away).
    fn fail_all(&mut self, errno: i32) {
        for i in 0..self.tx.len() {
            self.finish(i, errno);
        }
        self.stats.rx_flushed += self.rx.clear() as u64;
    }

    /// Handles one DSOR frame addressed to this node.
    fn on_frame(&mut self, id: &DsorId, data: &[u8], now: u64) -> bool {
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
                self.push_out(ack);
                true
            }
            None => false,
        }
    }

    /// A socket was closed (its bind is already gone): partial messages
    /// that no remaining socket wants are stopped; the next frame of each
    /// is refused, so their senders fail with ECONNREFUSED instead of
    /// sending the rest for nothing.
    fn refuse_orphans(&mut self) {
        let canip_up = udpip::is_up(self.canip.as_deref());
        let binds = &self.binds;
        let n = self.rx.refuse_partial(
            |inc: &Incoming<'_>| wanted(binds, canip_up, inc),
            AckStatus::Refused,
        );
        self.stats.rx_closed += n as u64;
    }

    /// Runs due timers; returns whether frames were queued.
    fn on_timer(&mut self, now: u64) -> bool {
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

    fn next_deadline(&self) -> Option<u64> {
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

/// Hands a complete message to its sockets or to canip0, before its last
/// frame is acked (dsor-wire.rst, "Delivery rule"): `Ok` if at least one
/// socket queued it (or canip0 took it), else the status the last frame is
/// acked with: REFUSED if nobody wants it any more, NO_MEMORY if every
/// socket that wants it has a full receive queue. Counts the outcome.
/// Under ENGINE (softirq or a driver's transmit path).
fn deliver(
    binds: &[Bind],
    canip: Option<&NetDev>,
    cfg: &Config,
    stats: &mut Stats,
    d: Delivered<RxBuf>,
) -> core::result::Result<(), AckStatus> {
    let Delivered {
        src,
        prio,
        header,
        buf,
    } = d;
    let skb = buf.0;
    let mut cb = [0u8; 12];
    cb[0] = src;
    cb[1] = prio;
    let q = match header.kind {
        MsgKind::Udp { dport, daddr } => {
            udpip::deliver(canip, skb, src, cfg.udp_saddr, daddr, dport).map(|()| Queued {
                wanted: 1,
                queued: 1,
            })
        }
        MsgKind::Segm { id } => {
            cb[2] = 0;
            cb[4..8].copy_from_slice(&id.to_ne_bytes());
            Ok(queue_to(binds, skb, &cb, |a| a.segm_accepts(src, id)))
        }
        MsgKind::Port { dport, sport } => {
            cb[2] = 1;
            cb[3] = sport;
            let want = dsor_addr::make_port(cfg.node, dport);
            Ok(queue_to(
                binds,
                skb,
                &cb,
                |a| matches!(*a, DsorAddr::Port { port, .. } if port == want),
            ))
        }
    };
    match q {
        Ok(Queued {
            queued: 0,
            wanted: 0,
        })
        | Err(AckStatus::Refused) => {
            stats.rx_unwanted_at_end += 1;
            Err(AckStatus::Refused)
        }
        Ok(Queued { queued: 0, .. }) | Err(_) => {
            stats.rx_queue_full += 1;
            Err(AckStatus::NoMemory)
        }
        Ok(Queued { queued, wanted }) => {
            stats.rx_delivered += 1;
            stats.rx_copies_dropped += (wanted - queued) as u64;
            Ok(())
        }
    }
}

/// How many sockets wanted a message and how many queued it.
struct Queued {
    wanted: usize,
    queued: usize,
}

/// Queues `skb` on every bound socket whose address `want`s it (clones
/// for all but the last). Each Bind holds a reference on its socket, so
/// they are valid here; release removes them under the ENGINE lock, which
/// the caller holds.
fn queue_to(
    binds: &[Bind],
    mut skb: Skb,
    cb: &[u8; 12],
    want: impl Fn(&DsorAddr) -> bool,
) -> Queued {
    skb.cb_write(0, cb);
    skb.stamp_if_unset();
    let n = binds.iter().filter(|b| want(&b.addr)).count();
    let mut skb = Some(skb);
    let mut queued = 0;
    for (k, b) in binds.iter().filter(|b| want(&b.addr)).enumerate() {
        let one = if k + 1 == n {
            skb.take()
        } else {
            skb.as_ref().and_then(|s| s.clone_atomic())
        };
        let Some(one) = one else { continue };
        if b.sk.sock().queue_rcv(one).is_ok() {
            queued += 1;
        }
    }
    Queued { wanted: n, queued }
}

/// Whether some socket (or canip0) wants the message `inc` (under ENGINE).
fn wanted(binds: &[Bind], canip_up: bool, inc: &Incoming<'_>) -> bool {
    match inc.header.kind {
        MsgKind::Segm { id } => binds.iter().any(|b| b.addr.segm_accepts(inc.src, id)),
        MsgKind::Port { dport, .. } => binds.iter().any(
            |b| matches!(b.addr, DsorAddr::Port { port, .. } if dsor_addr::port_sub(port) == dport),
        ),
        MsgKind::Udp { .. } => canip_up,
    }
}

/// The acceptance decision for a new incoming message (under ENGINE).
fn accept(
    binds: &[Bind],
    canip_up: bool,
    inc: &Incoming<'_>,
) -> core::result::Result<RxBuf, AckStatus> {
    // The rebuilt IPv4 + UDP headers must fit in 65535 bytes.
    if matches!(inc.header.kind, MsgKind::Udp { .. })
        && usize::from(inc.header.len) > rcan_core::dsor_udp::MAX_PAYLOAD
    {
        return Err(AckStatus::TooLong);
    }
    if !wanted(binds, canip_up, inc) {
        return Err(AckStatus::Refused);
    }
    let len = u32::from(inc.header.len);
    let mut skb = Skb::alloc(RX_HEADROOM + len, glue::GFP_ATOMIC).ok_or(AckStatus::NoMemory)?;
    skb.reserve(RX_HEADROOM);
    if !skb.put_zeroed(len) {
        return Err(AckStatus::NoMemory);
    }
    Ok(RxBuf(skb))
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

/// Kicks the sender timer. Call with ENGINE held (so that a kick is never
/// overwritten by an older re-arm, see [`Tick`]).
fn kick() {
    TIMER.start(ktime_get_mono_ns());
}

// ---------------------------------------------------------------------------
// Sending frames and timers

/// The soft hrtimer that sends queued frames and runs protocol timers.
struct Tick;

static TIMER: HrTimer<Tick> = HrTimer::new();

impl HrTimerCallback for Tick {
    type State = ();

    /// HRTIMER_SOFTIRQ. Runs the protocol timers, then drains the queue
    /// unless another drainer (a receive callback on another CPU) is at
    /// it; that one re-arms the timer when it is done.
    fn run(_timer: &'static HrTimer<Self>, _state: &mut ()) {
        drain(true);
    }
}

/// Sends the queued frames. Softirq context (HRTIMER_SOFTIRQ or NET_RX).
///
/// With `timers`, first runs the protocol timers. Becomes the drainer if
/// nobody is (`draining`), else returns at once: the running drainer takes
/// what was queued. Takes frames from the queue in batches under ENGINE
/// and sends them without it (on one device reference for the whole run);
/// when the queue is empty, clears `draining` and re-arms the timer for
/// the next deadline in the same critical section, so that a frame queued
/// concurrently (also under ENGINE) is never left unsent. After
/// [`FRAMES_PER_RUN`] frames it re-arms for "now" instead.
fn drain(timers: bool) {
    let mut first = true;
    let mut wake = false;
    let mut dev: Option<DevRef> = None;
    let mut sent = 0;
    loop {
        if wake {
            WAITQ.wake_all();
            wake = false;
        }
        let mut batch: [Option<Frame>; BATCH] = Default::default();
        let mut n = 0;
        let ifname;
        {
            let mut g = ENGINE.lock();
            let Some(e) = g.as_mut() else { return };
            if STOPPING.load(Ordering::Relaxed) {
                return;
            }
            if first {
                first = false;
                if timers {
                    let before = e.stats.tx_ok + e.stats.tx_failed;
                    e.on_timer(now_ms());
                    wake = e.stats.tx_ok + e.stats.tx_failed != before;
                }
                if e.draining {
                    // The running drainer sends what on_timer queued and
                    // re-arms the timer when it finds the queue empty.
                    drop(g);
                    if wake {
                        WAITQ.wake_all();
                    }
                    return;
                }
                e.draining = true;
            }
            if sent >= FRAMES_PER_RUN {
                e.draining = false;
                kick();
                drop(g);
                if wake {
                    WAITQ.wake_all();
                }
                return;
            }
            while n < BATCH {
                match e.pop_out() {
                    Some(f) => {
                        batch[n] = Some(f);
                        n += 1;
                    }
                    None => break,
                }
            }
            ifname = e.cfg.ifname;
            if n == 0 {
                e.draining = false;
                if let Some(d) = e.next_deadline() {
                    TIMER.start((d as i64).saturating_mul(1_000_000));
                }
                drop(g);
                if wake {
                    WAITQ.wake_all();
                }
                return;
            }
        }
        sent += n;
        if dev.is_none() {
            dev = DevRef::by_name(ifname.as_cstr());
        }
        let errors = match &dev {
            Some(d) => send_batch(d, &batch[..n]),
            None => n as u64,
        };
        if errors != 0 {
            if let Some(e) = ENGINE.lock().as_mut() {
                e.stats.send_errors += errors;
            }
        }
    }
}

/// Sends frames on the DSOR interface; returns how many failed. Softirq.
fn send_batch(dev: &DevRef, frames: &[Option<Frame>]) -> u64 {
    let mut errors = 0;
    for f in frames.iter().flatten() {
        if send_frame(dev, f).is_err() {
            errors += 1;
        }
    }
    errors
}

fn send_frame(dev: &DevRef, f: &Frame) -> Result {
    if !dev.is_can() || !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    let mut cf = CanFrame {
        can_id: (f.id & CAN_EFF_MASK) | CAN_EFF_FLAG,
        len: f.len,
        ..CanFrame::default()
    };
    let n = usize::from(f.len.min(8));
    cf.data[..n].copy_from_slice(&f.data[..n]);
    let mut skb = Skb::alloc(SKB_PRIV_LEN + CAN_FRAME_LEN as u32, glue::GFP_ATOMIC)
        .ok_or(neterr::ENOBUFS())?;
    skb.reserve(SKB_PRIV_LEN);
    let mut prv = [0u8; SKB_PRIV_LEN as usize];
    prv[..4].copy_from_slice(&dev.ifindex().to_ne_bytes());
    if !skb.write_headroom(&prv) || !skb.put_data(&cf.to_bytes()) {
        return Err(neterr::ENOBUFS());
    }
    // Looped back, so that a node can talk to itself over canloop and
    // local CAN_RAW sockets see DSOR traffic.
    rcan_api::send(skb, dev, true)
}

// ---------------------------------------------------------------------------
// Receiving frames

/// The receiver of every DSOR frame addressed to this node.
struct DsorRx;

impl KernelRx for DsorRx {
    /// NET_RX softirq, under RCU. The frame's answers (acks, the next
    /// body) are queued under ENGINE and sent right here, after the lock
    /// is dropped ([`drain`]), instead of a timer hop later: a receive
    /// callback runs in NET_RX softirq with no device lock held, so it may
    /// transmit.
    fn rx(&self, skb: &Skb, dev: &NetDev) {
        let Ok(bytes) = <&[u8; CAN_FRAME_LEN]>::try_from(skb.data()) else {
            return;
        };
        let cf = CanFrame::from_bytes(bytes);
        if cf.can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG) != CAN_EFF_FLAG {
            return;
        }
        let Some(id) = DsorId::from_can_id(cf.can_id & CAN_EFF_MASK) else {
            return;
        };
        if u32::from(id.dst) != NODE.load(Ordering::Relaxed) {
            return;
        }
        let len = usize::from(cf.len.min(8));
        let now = now_ms();
        let mut g = ENGINE.lock();
        let Some(e) = g.as_mut() else { return };
        if dev.name().as_bytes() != e.cfg.ifname.bytes() {
            return;
        }
        let finished_before = e.stats.tx_ok + e.stats.tx_failed;
        let queued = e.on_frame(&id, &cf.data[..len], now);
        let finished = e.stats.tx_ok + e.stats.tx_failed != finished_before;
        drop(g);
        if finished {
            WAITQ.wake_all();
        }
        if queued {
            // Becomes the drainer unless one runs (which then takes these
            // frames too).
            drain(false);
        }
    }
}

static RX: DsorRx = DsorRx;

// ---------------------------------------------------------------------------
// Sockets

/// A DSOR socket's state, protected by its socket lock.
#[derive(Default)]
struct DsorSock {
    /// The bound address (also in `Engine::binds` while set).
    bound: Option<DsorAddr>,
    /// The default destination given to connect.
    peer: Option<DsorAddr>,
}

struct DsorProto;

static MODULE: ProtoModule<DsorProto> = ProtoModule::new();

impl CanProtocol for DsorProto {
    const PROTOCOL: i32 = CANPROTO_DSOR;
    const SOCK_TYPE: i32 = SOCK_DGRAM;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// The DSOR interface went down or away: every running transfer fails
    /// with ENETDOWN, partial messages are dropped. Process context, RTNL
    /// held. (DSOR sockets take frames through the engine's in-kernel
    /// receiver, not per socket: the default `rx` is never called.)
    fn netdev_event(_event: NetdevEvent, dev: &NetDev, _sockets: &Sockets<'_, Self>) {
        {
            let mut g = ENGINE.lock();
            if let Some(e) = g.as_mut() {
                if dev.name().as_bytes() == e.cfg.ifname.bytes() {
                    e.fail_all(neterr::ENETDOWN().to_errno());
                }
            }
        }
        WAITQ.wake_all();
    }
}

type S = Sock<DsorProto>;

fn errno(e: i32) -> kernel::error::Error {
    glue::errno(e)
}

/// Adds `sk`'s bind to the engine (EADDRINUSE for a taken port).
fn add_bind(sk: &S, addr: DsorAddr) -> Result {
    let mut g = ENGINE.lock();
    let e = g.as_mut().ok_or(ENODEV)?;
    if let DsorAddr::Port { port, .. } = addr {
        if e.binds
            .iter()
            .any(|b| matches!(b.addr, DsorAddr::Port { port: p, .. } if p == port))
        {
            return Err(neterr::EADDRINUSE());
        }
    }
    e.binds
        .push(
            Bind {
                sk: sk.to_ref(),
                addr,
            },
            kernel::alloc::flags::GFP_ATOMIC,
        )
        .map_err(|_| ENOMEM)
}

fn remove_bind(sk: &S) {
    let me = sk.as_ptr() as usize;
    let mut g = ENGINE.lock();
    if let Some(e) = g.as_mut() {
        let mut i = 0;
        let mut removed = false;
        while i < e.binds.len() {
            if e.binds[i].sk.sock().as_ptr() as usize == me {
                glue::kvec_swap_remove(&mut e.binds, i);
                removed = true;
            } else {
                i += 1;
            }
        }
        if removed {
            e.refuse_orphans();
        }
    }
}

/// Binds an unbound socket to a free ephemeral port (for port messages
/// sent before bind). Caller holds the socket lock.
fn autobind(sk: &S, s: &mut DsorSock) -> Result<u8> {
    let local = NODE.load(Ordering::Relaxed) as u8;
    for sub in (DSOR_EPHEMERAL_MIN..=u8::MAX).rev() {
        let addr = DsorAddr::Port {
            prio: 0,
            port: dsor_addr::make_port(local, sub),
        };
        match add_bind(sk, addr) {
            Ok(()) => {
                s.bound = Some(addr);
                return Ok(sub);
            }
            Err(e) if e == neterr::EADDRINUSE() => continue,
            Err(e) => return Err(e),
        }
    }
    Err(neterr::EADDRINUSE())
}

impl glue::sock::Proto for DsorProto {
    type Data = DsorSock;
    type Shared = ();

    fn new_data() -> DsorSock {
        DsorSock::default()
    }

    fn new_shared() {}

    fn release(sk: &S) {
        {
            let mut rtnl = Rtnl::lock();
            MODULE.sockets.get(&mut rtnl).remove(sk.as_ptr() as usize);
        }
        let mut s = sk.lock();
        remove_bind(sk);
        s.bound = None;
        s.peer = None;
    }

    fn bind(sk: &S, addr: &[u8]) -> Result {
        let a = DsorAddr::parse(addr).map_err(errno)?;
        a.check_bind(NODE.load(Ordering::Relaxed) as u8)
            .map_err(errno)?;
        let mut s = sk.lock();
        if s.bound.is_some() {
            return Err(EINVAL);
        }
        add_bind(sk, a)?;
        s.bound = Some(a);
        Ok(())
    }

    fn connect(sk: &S, addr: &[u8], _flags: i32) -> Result {
        if addr.len() >= 2 && u16::from_ne_bytes([addr[0], addr[1]]) == 0 {
            sk.lock().peer = None;
            return Ok(());
        }
        let a = DsorAddr::parse(addr).map_err(errno)?;
        a.check_dest().map_err(errno)?;
        sk.lock().peer = Some(a);
        Ok(())
    }

    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        let s = sk.lock();
        let a = if peer {
            s.peer.ok_or(neterr::ENOTCONN())?
        } else {
            s.bound.unwrap_or(DsorAddr::Segm {
                prio: 0,
                node: 0,
                id: 0,
            })
        };
        let (b, n) = a.encode();
        out[..n].copy_from_slice(&b[..n]);
        Ok(n)
    }

    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        let flags = msg.flags();
        if flags & bindings::MSG_OOB != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let dest = match msg.name() {
            Some(name) => {
                let a = DsorAddr::parse(name).map_err(errno)?;
                a.check_dest().map_err(errno)?;
                a
            }
            None => sk.lock().peer.ok_or(neterr::EDESTADDRREQ())?,
        };
        let max_len = {
            let g = ENGINE.lock();
            g.as_ref().map_or(0, |e| usize::from(e.cfg.limits_max_len))
        };
        if len > max_len {
            return Err(neterr::EMSGSIZE());
        }
        let (dst, prio, kind) = match dest {
            DsorAddr::Segm { prio, node, id } => (node, prio, MsgKind::Segm { id }),
            DsorAddr::Port { prio, port } => {
                let mut s = sk.lock();
                let sport = match s.bound {
                    Some(DsorAddr::Port { port: own, .. }) => dsor_addr::port_sub(own),
                    Some(DsorAddr::Segm { .. }) => return Err(EINVAL),
                    None => autobind(sk, &mut s)?,
                };
                (
                    dsor_addr::port_node(port),
                    prio,
                    MsgKind::Port {
                        dport: dsor_addr::port_sub(port),
                        sport,
                    },
                )
            }
        };
        let mut data = KVec::from_elem(0u8, len, GFP_KERNEL).map_err(|_| ENOMEM)?;
        msg.copy_from_user(&mut data)?;
        let nonblock = flags & bindings::MSG_DONTWAIT != 0;
        let timeo = sk.sndtimeo(nonblock);
        let header = Header {
            len: len as u16,
            kind,
        };
        check_device()?;
        if len == 0 {
            restart_hold(timeo)?;
        }
        let owner = if timeo == 0 {
            Owner::Sock(sk.to_ref())
        } else {
            Owner::Waiter
        };
        // Start the transfer, waiting for a free slot and channel.
        let mut pending = Some((data, owner));
        let mut started = None;
        let mut remaining = timeo;
        loop {
            let (data, owner) = pending.take().ok_or(EINVAL)?;
            {
                let mut g = ENGINE.lock();
                let e = g.as_mut().ok_or(ENODEV)?;
                match e.start(dst, prio, header.clone(), data, owner) {
                    Ok(slot) => {
                        e.kick();
                        started = Some(slot);
                    }
                    Err(back) => pending = Some(back),
                }
            }
            if started.is_some() {
                break;
            }
            if timeo == 0 {
                return Err(EAGAIN);
            }
            let t0 = glue::jiffies();
            match WAITQ.wait(remaining, &|| can_start(dst)) {
                Waited::Ready => {}
                Waited::TimedOut => return Err(neterr::ETIMEDOUT()),
                Waited::Interrupted => return Err(EINTR),
            }
            if remaining != i64::MAX {
                remaining -= glue::jiffies().wrapping_sub(t0) as i64;
            }
            if remaining <= 0 {
                return Err(neterr::ETIMEDOUT());
            }
        }
        let Some((slot, gen)) = started else {
            return Err(EINVAL);
        };
        if timeo == 0 {
            return Ok(len);
        }
        let waited = WAITQ.wait(remaining, &|| finished(slot, gen));
        let result = {
            let mut g = ENGINE.lock();
            let Some(e) = g.as_mut() else {
                return Err(ENODEV);
            };
            let abort = match waited {
                Waited::Interrupted => EINTR.to_errno(),
                _ => neterr::ETIMEDOUT().to_errno(),
            };
            e.abandon(slot, gen, abort)
        };
        // A freed slot or channel may let another sender start.
        WAITQ.wake_all();
        if result == 0 {
            Ok(len)
        } else {
            Err(kernel::error::Error::from_errno(result))
        }
    }

    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        if flags as u32 & (bindings::MSG_OOB | bindings::MSG_ERRQUEUE) != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let skb = sk.recv_datagram(flags)?;
        let total = skb.len() as usize;
        let n = total.min(len);
        if let Err(e) = msg.copy_from_skb(&skb, 0, n) {
            sk.free_datagram(skb);
            return Err(e);
        }
        if n < total {
            msg.add_flags(bindings::MSG_TRUNC);
        }
        msg.recv_cmsgs(sk, &skb);
        let mut cb = [0u8; 12];
        skb.cb_read(0, &mut cb);
        let (src, prio) = (cb[0], cb[1]);
        let addr = if cb[2] == 1 {
            DsorAddr::Port {
                prio,
                port: dsor_addr::make_port(src, cb[3]),
            }
        } else {
            DsorAddr::Segm {
                prio,
                node: src,
                id: u32::from_ne_bytes([cb[4], cb[5], cb[6], cb[7]]),
            }
        };
        let (b, an) = addr.encode();
        msg.set_name(&b[..an]);
        sk.free_datagram(skb);
        Ok(if flags as u32 & bindings::MSG_TRUNC != 0 {
            total
        } else {
            n
        })
    }
}

/// The restart rule of the wire specification ("Sequence bit"): every
/// stream starts at Q = 0 after a load, so during the first
/// `reasm_timeout_ms` a receiver may still remember a zero-length message
/// with Q = 0 that the previous instance of this module sent, and would
/// take an identical new one for its retransmission. Zero-length messages
/// therefore wait until that time has passed (longer messages cannot be
/// mistaken: a receiver restarts on every header it has not acknowledged
/// as the last frame). EAGAIN for a non-blocking sender.
/// A sleep can end up to a jiffy before `until` (the first jiffy of a
/// timeout is already partly over), so it loops until the hold is over
/// or the sender's own timeout `timeo` (jiffies, `i64::MAX` for none) is
/// used up. Process context.
fn restart_hold(timeo: i64) -> Result {
    let until = restart_over_ms();
    let mut remaining = timeo;
    loop {
        let wait_ms = until.saturating_sub(now_ms());
        if wait_ms == 0 {
            return Ok(());
        }
        if timeo == 0 {
            return Err(EAGAIN);
        }
        if remaining <= 0 {
            return Err(neterr::ETIMEDOUT());
        }
        let j = glue::msecs_to_jiffies(wait_ms as u32).clamp(1, remaining);
        let t0 = glue::jiffies();
        if let Waited::Interrupted = WAITQ.wait(j, &|| now_ms() >= until) {
            return Err(EINTR);
        }
        if remaining != i64::MAX {
            remaining -= glue::jiffies().wrapping_sub(t0) as i64;
        }
    }
}

/// When the restart rule ([`restart_hold`]) stops holding zero-length
/// messages (monotonic ms). Any context.
fn restart_over_ms() -> u64 {
    LOADED_MS.load(Ordering::Relaxed) + u64::from(PARAM_REASM_TIMEOUT_MS.get())
}

/// Whether a transfer to `dst` could start now (wait condition).
fn can_start(dst: u8) -> bool {
    let g = ENGINE.lock();
    match g.as_ref() {
        Some(e) => {
            e.tx.iter().any(|x| matches!(x, TxEntry::Free))
                && e.streams.in_use(dst) < u32::from(dsor_wire::CHANNELS)
        }
        None => true,
    }
}

/// Whether transfer `(slot, gen)` has finished (wait condition).
fn finished(slot: usize, gen: u32) -> bool {
    let g = ENGINE.lock();
    match g.as_ref() {
        Some(e) => !matches!(&e.tx[slot], TxEntry::Running(r) if r.gen == gen),
        None => true,
    }
}

/// ENODEV if the DSOR interface does not exist, ENETDOWN if it is down.
fn check_device() -> Result {
    let ifname = {
        let g = ENGINE.lock();
        g.as_ref().ok_or(ENODEV)?.cfg.ifname
    };
    let dev = DevRef::by_name(ifname.as_cstr()).ok_or(ENODEV)?;
    if !dev.is_can() {
        return Err(ENODEV);
    }
    if !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    Ok(())
}

/// Starts a UDP/IP message for canip0 (its transmit path, BH disabled).
/// Returns false when no slot or channel is free, and for an empty
/// datagram while the restart rule holds (see [`restart_hold`]; this
/// path cannot wait, and UDP may drop).
fn start_udp(dst: u8, header: Header, payload: KVec<u8>) -> bool {
    if payload.is_empty() && now_ms() < restart_over_ms() {
        return false;
    }
    let mut g = ENGINE.lock();
    let Some(e) = g.as_mut() else { return false };
    let prio = e.cfg.udp_prio;
    match e.start(dst, prio, header, payload, Owner::Canip) {
        Ok(_) => {
            e.kick();
            true
        }
        Err(_) => false,
    }
}

// ---------------------------------------------------------------------------
// Module

/// Registrations that pf_can and the network core hold; dropped in
/// this order (the protocol, then the receiver, then canip0).
struct Regs {
    _proto: ProtoRegistration<DsorProto>,
    _rx: KernelRxReg<DsorRx>,
    _canip: Option<udpip::Canip>,
}

pub(crate) struct DsorModule {
    regs: Option<Regs>,
}

/// Stops the sender timer and frees all protocol state: running transfers
/// fail (their owners are told), partial messages are freed. Process
/// context; no receiver, socket or canip0 transmit can reach the engine
/// any more.
fn teardown_engine() {
    STOPPING.store(true, Ordering::Relaxed);
    TIMER.cancel();
    let engine = ENGINE.lock().take();
    // A callback that ran before the take may have re-armed the timer.
    TIMER.cancel();
    if let Some(mut e) = engine {
        e.fail_all(neterr::ENETDOWN().to_errno());
        let s = &e.stats;
        pr_info!(
            "stopped: {} messages sent, {} failed, {} received, {} dropped, {} frames lost to a full send queue, {} send errors\n",
            s.tx_ok,
            s.tx_failed,
            s.rx_delivered,
            s.rx_refused_unwanted
                + s.rx_refused_too_long
                + s.rx_refused_no_memory
                + s.rx_queue_full
                + s.rx_unwanted_at_end
                + s.rx_closed
                + s.rx_timed_out
                + s.rx_flushed,
            s.out_overflow,
            s.send_errors
        );
        pr_info!(
            "not delivered: header refused {} no receiver, {} too long, {} no memory; last frame refused {} receive queue full, {} no receiver; {} receiver closed mid-message; {} timed out; {} flushed at ifdown/unload; {} extra copies dropped (queue full)\n",
            s.rx_refused_unwanted,
            s.rx_refused_too_long,
            s.rx_refused_no_memory,
            s.rx_queue_full,
            s.rx_unwanted_at_end,
            s.rx_closed,
            s.rx_timed_out,
            s.rx_flushed,
            s.rx_copies_dropped
        );
        drop(e);
    }
    WAITQ.wake_all();
}

fn new_engine(cfg: Config) -> Result<KBox<Engine>> {
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
    let blank = Frame {
        id: 0,
        len: 0,
        data: [0; 8],
    };
    let out = KVec::from_elem(blank, OUT_LEN, GFP_KERNEL)?;
    Ok(KBox::new(
        Engine {
            cfg,
            rx,
            streams,
            tx,
            next_gen: 1,
            out,
            out_head: 0,
            out_len: 0,
            binds: KVec::new(),
            canip: None,
            stats: Stats::default(),
            draining: false,
        },
        GFP_KERNEL,
    )?)
}

fn register_all(node: u8, canip: bool) -> Result<Regs> {
    let (fid, fmask) = dsor_wire::rx_filter(node);
    let filter = RxFilter {
        kind: RX_FILTER_CAN_ID,
        id: fid | CAN_EFF_FLAG,
        mask: fmask | CAN_EFF_FLAG | CAN_RTR_FLAG,
    };
    let rx = rcan_api::rx_set_kernel(&RX, 0, &[filter])?;
    let canip = if canip {
        Some(udpip::Canip::register()?)
    } else {
        None
    };
    let proto = MODULE.register(c_str!("CANPROTO_DSOR"))?;
    Ok(Regs {
        _proto: proto,
        _rx: rx,
        _canip: canip,
    })
}

impl kernel::Module for DsorModule {
    fn init(_module: &'static ThisModule) -> Result<Self> {
        let cfg = load_config()?;
        let (node, canip, ifname) = (cfg.node, cfg.canip, cfg.ifname);
        let engine = new_engine(cfg)?;
        NODE.store(u32::from(node), Ordering::Relaxed);
        LOADED_MS.store(now_ms(), Ordering::Relaxed);
        TIMER.init(ClockId::Monotonic, HrTimerMode::AbsoluteSoft, ())?;
        *ENGINE.lock() = Some(engine);
        match register_all(node, canip) {
            Ok(regs) => {
                pr_info!(
                    "{}: CANPROTO_DSOR ({}) node 0x{:02x}\n",
                    ifname.as_str(),
                    CANPROTO_DSOR,
                    node
                );
                Ok(DsorModule { regs: Some(regs) })
            }
            Err(e) => {
                // register_all undid its own partial work (guards dropped).
                teardown_engine();
                Err(e)
            }
        }
    }
}

impl Drop for DsorModule {
    fn drop(&mut self) {
        // Sockets hold the module, so none is left when this runs. The
        // protocol goes first (Regs' field order); no receive callback
        // runs after the receiver guard is dropped, and canip0's transmit
        // path is gone with its registration.
        self.regs = None;
        teardown_engine();
    }
}
