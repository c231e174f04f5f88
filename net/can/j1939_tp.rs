// SPDX-License-Identifier: GPL-2.0

//! The J1939 transport protocols of rcan_j1939 on one interface (issue 42,
//! step 2c; J1939-21 5.10): TP with RTS/CTS (9..=1785 bytes), its
//! broadcast form BAM, and ETP (up to 117,440,505 bytes), both directions
//! (mainline's `net/can/j1939/transport.c`). The session machines are
//! `rcan_core::j1939_tp_tx::TxSession` and `rcan_core::j1939_tp_rx::RxSession`,
//! host-tested; this file gives them a table, a timer, frames and sockets.
//!
//! * [`Tp`], one per interface state ([`IfaceState::tp`], `BhLock` class
//!   `j1939_tp`): the active sessions, at most [`MAX_SESSIONS`], one per
//!   key (source, destination, TP or ETP, direction; mainline's rule: a
//!   second gets `EBUSY`), each with what it owns: a sender's message
//!   and its socket (a counted reference), a receiver's reassembly
//!   buffer (the skb the message is delivered in). Taken by the receive
//!   softirq (frames), the timer's softirq, and in process context by
//!   `sendmsg` (a new sender), unbinding and the interface going down
//!   (cancels). Nothing else is locked inside it but the job timer's own
//!   `rearm` lock ([`arm`]); frames are sent, messages delivered and
//!   sockets told after it is released ([`After`]).
//! * The interface's job timer (timer [`TP_TIMER`] of
//!   [`IfaceJob`]): one for all sessions, armed for the earliest
//!   deadline ([`Tp::armed`]); its callback ([`on_timer`], HRTIMER
//!   softirq) runs every session that is due. A deadline that moved
//!   later makes an early expiry, which does nothing but re-arm.
//! * A sender's end wakes the writers waiting in `sendmsg` or `release`
//!   for their socket's session to end ([`super::j1939::WAITQ`]); a
//!   socket has at most one sender at a time
//!   ([`super::j1939::J1939Shared::tx_busy`]).
//!
//! Frames reach the sessions by [`on_frame`] (from the interface's
//! kernel receiver, NET_RX softirq), routed as mainline's
//! `j1939_tp_recv`: what the originator sends (RTS, BAM, DPO, data) to
//! a local address or to broadcast goes to the receiver's session (an
//! RTS or BAM with none starts one), what the responder sends back (CTS,
//! EOMA) to a local address to the sender's, an abort to a local address
//! to either; the echo of a data packet a local address sent goes to its
//! sender (which waits for the last one's). Between two local sockets
//! every frame comes back once, as its echo, and plays both parts.
//!
//! The error queue (`SO_J1939_ERRQUEUE`): a sender's socket is told of
//! its session's TX ACK, TX SCHED (each CTS after data) and abort, the
//! sockets a message would reach of its RTS, DPO and abort
//! (`rcan_core::j1939_errqueue`), once the `tp` lock is released.
//!
//! Not yet (Documentation/networking/rcan/j1939.rst, "The module"):
//! mainline's per-socket queue of messages (ours: one at a time per
//! socket, the next `sendmsg` waits), module parameters for the block
//! size, packet delay and largest message. (Single frames' error queue
//! events are [`super::j1939_echo`]'s.)
#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::sync::atomic::Ordering;
use kernel::alloc::{flags::GFP_KERNEL, KVVec, KVec};
use kernel::prelude::*;

use glue::jobtimer::{JobCallback, JobRef};
use glue::netdev::{DevRef, NetDev};
use glue::skb::UniqueSkb;
use glue::sock::{ErrNote, Sock, SockRef, SockView};
use rcan_core::j1939::{Frame, Id, RxMeta, J1939_NO_NAME, EAGAIN, EADDRNOTAVAIL, EBUSY, EMSGSIZE, ESHUTDOWN, MAX_ETP_SIZE};
use rcan_core::j1939_errqueue::{note, Event, Session as NoteSession};
use rcan_core::j1939_tp::{
    abort, classify, from_originator, Key, Msg, Notify, Outcome, Params, Sessions, Step, TimerCmd,
    CMD_ABORT, ETP_CMD_RTS, TP_CMD_BAM, TP_CMD_RTS,
};
use rcan_core::j1939_tp_rx::RxSession;
use rcan_core::j1939_tp_tx::TxSession;

use super::j1939_echo::ECHO_TIMER;
use super::j1939::{deliver, for_each_accepting, now_ns, write_meta, IfaceState, J1939Proto, WAITQ};

/// Sessions an interface runs at once, both directions (mainline has no
/// limit; 100 concurrent sessions is a bench target). A sender over the
/// limit gets `ENOBUFS`, a receiver's RTS an abort "resources".
pub(crate) const MAX_SESSIONS: usize = 256;

/// The job timer of an interface that runs its sessions.
pub(crate) const TP_TIMER: usize = 0;

/// The parameters (mainline's defaults; module parameters are not yet).
const PARAMS: Params = Params {
    block: 255,
    packet_delay_ns: 0,
    max_size: MAX_ETP_SIZE,
};

/// Frames one timer callback sends before it lets others run (it re-arms
/// for "now" and goes on in the next one).
const BURST: usize = 64;

/// What a session owns besides its machine.
enum Machine {
    /// A local sender: its message, its addressing, its socket and the
    /// send's timestamp key (`SOF_TIMESTAMPING_OPT_ID`).
    Tx {
        m: TxSession,
        data: KVVec<u8>,
        id: Id,
        sk: SockRef<J1939Proto>,
        tskey: u32,
    },
    /// A receiver: the reassembly buffer, `m.size()` bytes of data.
    Rx { m: RxSession, buf: UniqueSkb },
}

impl Machine {
    fn deadline(&self) -> Option<u64> {
        match self {
            Machine::Tx { m, .. } => m.deadline(),
            Machine::Rx { m, .. } => m.deadline(),
        }
    }
}

/// An active session and the number that tells it from an earlier one in
/// the same slot (a refused frame is reported back by slot and number).
struct Session {
    mach: Machine,
    gen: u32,
}

/// The sessions of an interface (module documentation).
pub(crate) struct Tp {
    keys: Sessions<MAX_SESSIONS>,
    /// `MAX_SESSIONS` slots; slot `i` is active iff `keys` has slot `i`.
    slots: KVec<Option<Session>>,
    /// The expiry the timer was last started for, `None` while it is not
    /// (or its callback runs).
    armed: Option<u64>,
    gen: u32,
}

impl Tp {
    /// An empty table. Process context (allocates the slots).
    pub(crate) fn new() -> Result<KBox<Tp>> {
        let mut slots = KVec::with_capacity(MAX_SESSIONS, GFP_KERNEL)?;
        for _ in 0..MAX_SESSIONS {
            slots.push(None, GFP_KERNEL)?;
        }
        Ok(KBox::new(
            Tp {
                keys: Sessions::new(),
                slots,
                armed: None,
                gen: 0,
            },
            GFP_KERNEL,
        )?)
    }

    fn slot_of(&self, key: Key) -> Option<usize> {
        self.keys.find(key)
    }

    /// Enters `mach` under `key`: its slot and number, or `mach` back
    /// with the errno (`EAGAIN`: the key is active; `EADDRNOTAVAIL`: full).
    fn enter(&mut self, key: Key, mach: Machine) -> core::result::Result<(usize, u32), (Machine, i32)> {
        match self.keys.activate(key) {
            Ok(i) => {
                self.gen = self.gen.wrapping_add(1);
                let gen = self.gen;
                match self.slots.get_mut(i) {
                    Some(s) => {
                        *s = Some(Session { mach, gen });
                        Ok((i, gen))
                    }
                    None => {
                        self.keys.deactivate(i);
                        Err((mach, EADDRNOTAVAIL))
                    }
                }
            }
            Err(e) => Err((mach, e)),
        }
    }

    /// The earliest deadline of all sessions.
    fn earliest(&self) -> Option<u64> {
        self.slots
            .iter()
            .flatten()
            .filter_map(|s| s.mach.deadline())
            .min()
    }
}

/// The table goes with its interface state (process context, the timer
/// dead): a sender still in it (its socket left the interface while its
/// `sendmsg` started a session) frees its socket for the next `sendmsg`
/// and `release`, which would otherwise wait for an end that never comes.
impl Drop for Tp {
    fn drop(&mut self) {
        let mut woke = false;
        for s in self.slots.iter_mut() {
            if let Some(Session {
                mach: Machine::Tx { sk, .. },
                ..
            }) = s.take()
            {
                sk.sock().shared().tx_busy.store(false, Ordering::Release);
                woke = true;
            }
        }
        if woke {
            WAITQ.wake_all();
        }
    }
}

/// The job of an interface's timers: its state is the job's data.
pub(crate) struct IfaceJob;

impl JobCallback for IfaceJob {
    type Data = IfaceState;

    /// HRTIMER softirq: runs the sessions that are due ([`TP_TIMER`]), or
    /// ends the single frames whose echo is overdue ([`ECHO_TIMER`]).
    fn expired(job: JobRef<'_, Self>, which: usize) {
        match which {
            TP_TIMER => on_timer(job),
            ECHO_TIMER => super::j1939_echo::on_timer(job),
            _ => {}
        }
    }
}

type Job<'a> = JobRef<'a, IfaceJob>;

/// Starts the timer for `at` unless it is armed for that or earlier.
/// Under the `tp` lock, so that `armed` is what the timer was last
/// started for.
fn arm(tp: &mut Tp, job: Job<'_>, at: u64) {
    if tp.armed.map_or(true, |a| at < a) {
        tp.armed = Some(at);
        job.start(TP_TIMER, at);
    }
}

/// What an event leaves to do once the `tp` lock is released.
#[derive(Default)]
struct After {
    /// A frame to send, and the session it is from (slot, number).
    frame: Option<(Frame, usize, u32)>,
    /// A message received whole: its addressing (the PGN of the session)
    /// and the buffer, the whole message.
    deliver: Option<(Id, UniqueSkb)>,
    /// The receive time of the frame that made the event (the message's
    /// timestamp), 0 if none.
    tstamp: i64,
    /// A sender that ended: its socket, and the errno to report on it
    /// (an abort, sent or received).
    tx_end: Option<(SockRef<J1939Proto>, Option<i32>)>,
    /// A sender's message, freed outside the lock.
    freed: Option<KVVec<u8>>,
    /// An error queue notification for a sender's socket.
    tx_note: Option<(SockRef<J1939Proto>, Event, NoteSession)>,
    /// An error queue notification for the sockets that would receive a
    /// message: the event, the message's addressing and size.
    rx_note: Option<(Event, Id, usize)>,
}

/// Applies `step` of the session in `slot` (number `gen`) under the `tp`
/// lock: its timer, its frame (to [`After`]), its end (the slot freed,
/// what it owned to [`After`]).
fn apply(tp: &mut Tp, job: Job<'_>, slot: usize, gen: u32, step: Step, a: &mut After) {
    if let TimerCmd::Arm(at) = step.timer {
        arm(tp, job, at);
    }
    if let Some(f) = step.frame {
        a.frame = Some((f, slot, gen));
    }
    if let (Some(n), Some(Some(s))) = (step.notify, tp.slots.get(slot)) {
        match (n, &s.mach) {
            (Notify::TxSched(acked), Machine::Tx { .. }) => {
                a.tx_note = tx_note(&s.mach, Event::TxSched, acked);
            }
            (Notify::RxRts, Machine::Rx { m, .. }) => a.rx_note = Some((Event::RxRts, m.id(), m.size())),
            (Notify::RxDpo, Machine::Rx { m, .. }) => a.rx_note = Some((Event::RxDpo, m.id(), m.size())),
            _ => {}
        }
    }
    let Some(outcome) = step.done else {
        return;
    };
    tp.keys.deactivate(slot);
    let Some(s) = tp.slots.get_mut(slot).and_then(Option::take) else {
        return;
    };
    match outcome {
        Outcome::Sent => a.tx_note = tx_note(&s.mach, Event::TxAck, u32::MAX),
        Outcome::Aborted { errno, .. } => match &s.mach {
            Machine::Tx { m, .. } => {
                a.tx_note = tx_note(&s.mach, Event::TxAbort(errno), m.acked_bytes());
            }
            Machine::Rx { m, .. } => a.rx_note = Some((Event::RxAbort(errno), m.id(), m.size())),
        },
        Outcome::Delivered(_) => {}
    }
    match s.mach {
        Machine::Tx { data, sk, .. } => {
            let err = match outcome {
                // An abort with a code (sent or received) is the sender's
                // error; a cancel (ESHUTDOWN) or a device that kept refusing
                // is not reported (mainline's `j1939_sk_send_loop_abort`).
                Outcome::Aborted {
                    errno,
                    reason: Some(_),
                } => Some(errno),
                _ => None,
            };
            a.tx_end = Some((sk, err));
            a.freed = Some(data);
        }
        Machine::Rx { m, buf } => {
            // The buffer holds exactly the announced size, all received.
            if let Outcome::Delivered(_) = outcome {
                a.deliver = Some((m.id(), buf));
            }
        }
    }
}

/// A sender's notification `ev` with `acked` bytes acknowledged (at most
/// the message), for its socket (a new reference: taken under the `tp`
/// lock, told after it).
fn tx_note(mach: &Machine, ev: Event, acked: u32) -> Option<(SockRef<J1939Proto>, Event, NoteSession)> {
    let Machine::Tx {
        data, id, sk, tskey, ..
    } = mach
    else {
        return None;
    };
    let size = data.len() as u32;
    let s = NoteSession {
        size,
        acked: acked.min(size),
        pgn: id.pgn,
        src_name: J1939_NO_NAME,
        dst_name: J1939_NO_NAME,
        sa: id.sa,
        da: id.da,
        tskey: *tskey,
    };
    Some((sk.sock().to_ref(), ev, s))
}

/// Tells socket `sk` of `ev` on its error queue, if SO_J1939_ERRQUEUE is
/// on and its SO_TIMESTAMPING flags ask for it (mainline's
/// `__j1939_sk_errqueue`); a full queue drops it. Any context.
pub(crate) fn notify(sk: &SockView<J1939Proto>, ev: Event, s: &NoteSession) {
    if !sk.shared().errqueue.load(Ordering::Relaxed) {
        return;
    }
    let Some(n) = note(ev, sk.tsflags(), s) else {
        return;
    };
    let _ = sk.queue_err(&ErrNote {
        errno: n.errno,
        origin: n.origin,
        info: n.info,
        data: n.data,
        stats: n.stats(),
    });
}

/// Tells the sockets that would receive the message `id` of `size` bytes
/// of `ev` (mainline spreads receive notifications to every socket the
/// session's message matches). Softirq or process context.
fn notify_rx(st: &IfaceState, ev: Event, id: Id, size: usize) {
    let m = {
        let ac = st.ac.lock();
        RxMeta {
            id,
            src_name: ac.addr_to_name(id.sa),
            dst_name: ac.addr_to_name(id.da),
        }
    };
    let s = NoteSession {
        size: size as u32,
        acked: 0,
        pgn: id.pgn,
        src_name: m.src_name,
        dst_name: m.dst_name,
        sa: id.sa,
        da: id.da,
        tskey: 0,
    };
    for_each_accepting(st, st.ifindex, &m, None, |sk| notify(sk, ev, &s));
}

/// Sends `f` on `dev`. Any context.
fn send(dev: &NetDev, f: &Frame) -> Result {
    let mut img = [0u8; 16];
    img[..4].copy_from_slice(&f.id.to_can_id().to_ne_bytes());
    img[4] = f.len;
    img[8..].copy_from_slice(&f.data);
    let skb = glue::can::skb::alloc_image(dev, &img, glue::GFP_ATOMIC).ok_or_else(glue::neterr::ENOBUFS)?;
    rcan_api::send(skb, dev, true)
}

/// Carries out `a` (no lock held): first sends its frame (a refusal goes
/// back to the session, which retries or gives up), then delivers its
/// message and tells its sender's socket. In that order: a sender's
/// abort frame must be on its way before the socket may start its next
/// session, whose RTS would otherwise overtake it and be aborted by the
/// peer in its place. `dev` is the interface, if it is still there.
/// Softirq or process context.
fn finish(st: &IfaceState, job: Job<'_>, dev: Option<&NetDev>, mut a: After) {
    if let Some((f, slot, gen)) = a.frame.take() {
        if !dev.is_some_and(|d| send(d, &f).is_ok()) {
            // Refused (or the device is gone): the session retries after
            // 10 ms plus a jitter (its step has no frame: the retry comes
            // from the timer), and gives up after 100 refusals in a row
            // (then its end is carried out below). A frame of a session
            // that ended is not retried.
            let now = now_ns();
            let mut tp = st.tp.lock();
            let step = match tp.slots.get_mut(slot) {
                Some(Some(s)) if s.gen == gen => Some(match &mut s.mach {
                    Machine::Tx { m, .. } => m.on_refused(now, (now >> 20) as u8 & 15),
                    Machine::Rx { m, .. } => m.on_refused(now, (now >> 20) as u8 & 15),
                }),
                _ => None,
            };
            if let Some(step) = step {
                apply(&mut tp, job, slot, gen, step, &mut a);
            }
        }
    }
    if let Some((m, skb)) = a.deliver.take() {
        deliver_message(st, dev, m, skb, a.tstamp);
    }
    if let Some((ev, id, size)) = a.rx_note.take() {
        notify_rx(st, ev, id, size);
    }
    // Before the end is told: a writer woken by it finds the notification.
    if let Some((sk, ev, s)) = a.tx_note.take() {
        notify(sk.sock(), ev, &s);
    }
    if let Some((sk, err)) = a.tx_end.take() {
        let s = sk.sock();
        s.shared().tx_busy.store(false, Ordering::Release);
        if let Some(e) = err {
            if !s.shared().errqueue.load(Ordering::Relaxed) {
                s.report_error(e);
            }
        }
        drop(sk);
        WAITQ.wake_all();
    }
    drop(a.freed.take());
}

/// Delivers a message received whole to the interface's sockets that take
/// it (its NAMEs from the claim table; `MSG_DONTROUTE` when a local
/// address sent it). Softirq context.
fn deliver_message(st: &IfaceState, dev: Option<&NetDev>, id: Id, mut skb: UniqueSkb, tstamp: i64) {
    let Some(dev) = dev else {
        return;
    };
    let (m, local) = {
        let ac = st.ac.lock();
        let m = RxMeta {
            id,
            src_name: ac.addr_to_name(id.sa),
            dst_name: ac.addr_to_name(id.da),
        };
        (m, ac.is_local(id.sa))
    };
    let flags = if local { glue::msg::DONTROUTE } else { 0 };
    write_meta(&mut skb, dev.ifindex(), &m, flags, tstamp);
    let skb = skb.into_owned();
    // Each socket gets a clone: they share the data.
    deliver(st, dev.ifindex(), &m, None, || skb.clone_atomic());
}

/// Where a received frame's events run: the interface, its timer, the
/// receiving device, the time, the frame's timestamp.
struct Rx<'a> {
    st: &'a IfaceState,
    job: Job<'a>,
    dev: &'a NetDev,
    now: u64,
    tstamp: i64,
}

impl Rx<'_> {
    /// Runs `f` on the session with `key` and carries out its step; false
    /// if there is none.
    fn event(&self, key: Key, f: impl FnOnce(&mut Machine) -> Step) -> bool {
        let mut a = After {
            tstamp: self.tstamp,
            ..After::default()
        };
        {
            let mut tp = self.st.tp.lock();
            let Some(slot) = tp.slot_of(key) else {
                return false;
            };
            let Some(Some(s)) = tp.slots.get_mut(slot) else {
                return false;
            };
            let gen = s.gen;
            let step = f(&mut s.mach);
            apply(&mut tp, self.job, slot, gen, step, &mut a);
        }
        finish(self.st, self.job, Some(self.dev), a);
        true
    }

    /// An event of the sender with `key`, if there is one.
    fn tx(&self, key: Key, f: impl FnOnce(&mut TxSession, &[u8]) -> Step) {
        self.event(key, |mach| match mach {
            Machine::Tx { m, data, .. } => f(m, data),
            Machine::Rx { .. } => Step::NONE,
        });
    }

    /// An event of the receiver with `key`; false if there is none.
    fn rx(&self, key: Key, f: impl FnOnce(&mut RxSession, &mut UniqueSkb) -> Step) -> bool {
        self.event(key, |mach| match mach {
            Machine::Rx { m, buf } => f(m, buf),
            Machine::Tx { .. } => Step::NONE,
        })
    }

    /// An RTS or BAM (`d`) with no session for `key`: a receiver with a
    /// buffer of the announced size (allocated only for what may be
    /// accepted, without a warning on failure: a peer may announce 117 MB),
    /// or the refusal (an abort frame; none for BAM).
    fn start_rx(&self, id: Id, key: Key, d: &[u8; 8]) {
        let want = RxSession::wanted_buffer(&PARAMS, id, d);
        let buf = want.and_then(|n| {
            let n32 = u32::try_from(n).ok()?;
            let mut b = UniqueSkb::alloc(n32, glue::GFP_ATOMIC_NOWARN)?;
            b.put_zeroed(n32).then_some(b)
        });
        let buf_len = match (want, &buf) {
            (None, _) => usize::MAX,
            (Some(n), Some(_)) => n,
            (Some(_), None) => 0,
        };
        let mut a = After::default();
        match (RxSession::on_rts(&PARAMS, id, d, buf_len, self.now), buf) {
            (Ok((m, step)), Some(buf)) => {
                let mut tp = self.st.tp.lock();
                match tp.enter(key, Machine::Rx { m, buf }) {
                    Ok((slot, gen)) => apply(&mut tp, self.job, slot, gen, step, &mut a),
                    Err((mach, _)) => {
                        drop(tp);
                        // No room: refused as "resources" (no frame for BAM).
                        if let Machine::Rx { mut m, .. } = mach {
                            let s = m.cancel(EMSGSIZE, Some(abort::RESOURCE));
                            a.frame = s.frame.map(|f| (f, usize::MAX, 0));
                        }
                    }
                }
            }
            (Err(step), _) => a.frame = step.frame.map(|f| (f, usize::MAX, 0)),
            // Accepted without a buffer cannot be (`wanted_buffer`).
            (Ok(_), None) => {}
        }
        finish(self.st, self.job, Some(self.dev), a);
    }
}

/// A frame of a transport PGN that involves a local address or goes to
/// broadcast (`local_sa`, `local_da`: its source, its destination is
/// one of the interface's local addresses), received on `dev` at
/// `tstamp` (the interface's kernel receiver, NET_RX softirq): routed to
/// its session (module documentation).
#[allow(clippy::too_many_arguments)]
pub(crate) fn on_frame(
    st: &IfaceState,
    job: Job<'_>,
    dev: &NetDev,
    id: Id,
    data: &[u8],
    local_sa: bool,
    local_da: bool,
    tstamp: i64,
) {
    let Some(msg) = classify(&id, data) else {
        return;
    };
    let rx = Rx {
        st,
        job,
        dev,
        now: now_ns(),
        tstamp,
    };
    let now = rx.now;
    let broadcast = id.is_broadcast();
    match msg {
        Msg::Dat { etp } => {
            if local_sa {
                let key = Key {
                    sa: id.sa,
                    da: id.da,
                    etp,
                    tx: true,
                };
                rx.tx(key, |m, _| m.on_echo(data, now));
            }
            if local_da || broadcast {
                rx.rx(Key::rx_of(&id, etp), |m, buf| m.on_dat(data, buf.data_mut(), now));
            }
        }
        Msg::Ctl { etp, cmd, data: d, .. } => {
            if broadcast && cmd != TP_CMD_BAM {
                // Aborts, replies and ETP to broadcast mean nothing.
                return;
            }
            if cmd == CMD_ABORT {
                if local_da {
                    rx.tx(Key::tx_of_reply(&id, etp), |m, data| m.on_ctl(&d, data, now));
                    rx.rx(Key::rx_of(&id, etp), |m, _| m.on_ctl(&d, now));
                }
            } else if from_originator(cmd) {
                if !(local_da || broadcast) {
                    return;
                }
                let key = Key::rx_of(&id, etp);
                let found = rx.rx(key, |m, _| m.on_ctl(&d, now));
                if !found && matches!(cmd, TP_CMD_RTS | TP_CMD_BAM | ETP_CMD_RTS) {
                    rx.start_rx(id, key, &d);
                }
            } else if local_da {
                rx.tx(Key::tx_of_reply(&id, etp), |m, data| m.on_ctl(&d, data, now));
            }
        }
    }
}

/// The timer's callback (HRTIMER softirq): the sessions that are due run,
/// at most [`BURST`] events (one frame each at most), then the timer is
/// armed for the next deadline (at once if some are still due).
fn on_timer(job: Job<'_>) {
    let st = job.data();
    let dev = DevRef::by_index(&st.net, st.ifindex);
    {
        st.tp.lock().armed = None;
    }
    for _ in 0..BURST {
        let now = now_ns();
        let mut a = After::default();
        {
            let mut tp = st.tp.lock();
            let due = tp.slots.iter().enumerate().find_map(|(i, s)| {
                let s = s.as_ref()?;
                (s.mach.deadline()? <= now).then_some((i, s.gen))
            });
            let Some((slot, gen)) = due else {
                break;
            };
            let step = match tp.slots.get_mut(slot) {
                Some(Some(s)) => match &mut s.mach {
                    Machine::Tx { m, data, .. } => m.on_timer(data, now),
                    Machine::Rx { m, .. } => m.on_timer(now),
                },
                _ => break,
            };
            apply(&mut tp, job, slot, gen, step, &mut a);
        }
        finish(st, job, dev.as_deref(), a);
    }
    let mut tp = st.tp.lock();
    if let Some(at) = tp.earliest() {
        arm(&mut tp, job, at);
    }
}

/// Starts sending `data` from socket `sk` as one message addressed by
/// `id` (its source and destination resolved), on the interface `st`
/// (`job` its timer) through `dev`. The caller has made `sk` busy
/// (`tx_busy`); on error it is not any more. Process context. Errors:
/// `EBUSY` while a session with the same source, destination and kind
/// runs (mainline), `ENOBUFS` when the interface runs [`MAX_SESSIONS`],
/// those of `TxSession::start`.
pub(crate) fn start_tx(
    st: &IfaceState,
    job: Job<'_>,
    dev: &NetDev,
    sk: &Sock<J1939Proto>,
    id: Id,
    data: KVVec<u8>,
) -> Result {
    let now = now_ns();
    let tskey = sk.next_tskey();
    let mut a = After::default();
    let r = {
        let mut tp = st.tp.lock();
        match TxSession::start(&PARAMS, id, &data, now) {
            Err(e) => Err(glue::errno(e)),
            Ok((m, step)) => {
                let key = m.key();
                let mach = Machine::Tx {
                    m,
                    data,
                    id,
                    sk: sk.to_ref(),
                    tskey,
                };
                match tp.enter(key, mach) {
                    Ok((slot, gen)) => {
                        apply(&mut tp, job, slot, gen, step, &mut a);
                        Ok(())
                    }
                    Err((mach, e)) => {
                        // Dropped outside the lock.
                        a.freed = match mach {
                            Machine::Tx { data, .. } => Some(data),
                            Machine::Rx { .. } => None,
                        };
                        Err(if e == EAGAIN {
                            glue::errno(EBUSY)
                        } else {
                            glue::neterr::ENOBUFS()
                        })
                    }
                }
            }
        }
    };
    finish(st, job, Some(dev), a);
    r
}

/// Ends the sessions of the interface that `which` selects (a sender's
/// socket, or all) without a frame (mainline's
/// `j1939_cancel_active_session`: `ESHUTDOWN`). Process context.
pub(crate) fn cancel(st: &IfaceState, job: Job<'_>, which: Option<&Sock<J1939Proto>>) {
    loop {
        let mut a = After::default();
        {
            let mut tp = st.tp.lock();
            let hit = tp.slots.iter().enumerate().find_map(|(i, s)| {
                let s = s.as_ref()?;
                let mine = match (&s.mach, which) {
                    (_, None) => true,
                    (Machine::Tx { sk, .. }, Some(w)) => sk.sock().same(w),
                    (Machine::Rx { .. }, Some(_)) => false,
                };
                mine.then_some((i, s.gen))
            });
            let Some((slot, gen)) = hit else {
                return;
            };
            let step = match tp.slots.get_mut(slot) {
                Some(Some(s)) => match &mut s.mach {
                    Machine::Tx { m, .. } => m.cancel(ESHUTDOWN, None),
                    Machine::Rx { m, .. } => m.cancel(ESHUTDOWN, None),
                },
                _ => return,
            };
            apply(&mut tp, job, slot, gen, step, &mut a);
        }
        // No frame; the device is not needed.
        finish(st, job, None, a);
    }
}
