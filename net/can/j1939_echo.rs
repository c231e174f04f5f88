// SPDX-License-Identifier: GPL-2.0

//! The error queue of rcan_j1939's single-frame sends (issue 42): a
//! message of at most 8 bytes sent by a socket with `SO_J1939_ERRQUEUE`
//! on waits, in its interface's table, for its frame's echo, as mainline's
//! "simple" sessions do (`rcan_core::j1939_echo`, host-tested). The socket
//! is told of TX SCHED once the device took the frame, of TX ACK when
//! the echo came back, and of TX ABORT with `ETIME` when no echo came
//! within 10 s, or with `ESHUTDOWN` when the interface went down or away
//! first. A socket with the queue off sends as before: nothing waits.
//!
//! * The table ([`IfaceState::echo`], `BhLock` class `j1939_echo`) is
//!   taken by `sendmsg` (process context), the receive softirq (echoes),
//!   the timer's softirq, and by unbinding and the interface going down
//!   (process context); nothing else is locked inside it but the job
//!   timer's own `rearm` lock. Sockets are told, and the table's
//!   references to them put, after it is released.
//! * [`IfaceState::echo_used`] mirrors the number of entries (written
//!   under the lock): the receive path, which sees every frame of the
//!   interface, takes the lock only while a send waits. An entry is made
//!   before its frame is handed to the device, and the frame's echo comes
//!   back through the device's receive path, so the echo's softirq sees
//!   the count that includes it.
//! * The timeout runs on timer [`ECHO_TIMER`] of the interface's job
//!   (the transport sessions have the other), armed for the earliest
//!   deadline of the waiting entries.
#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use core::sync::atomic::Ordering;
use kernel::alloc::{flags::GFP_KERNEL, KVec};
use kernel::prelude::*;

use glue::jobtimer::JobRef;
use glue::netdev::{DevRef, NetDev};
use glue::skb::{Skb, UniqueSkb};
use glue::sock::{Sock, SockRef};
use rcan_core::j1939::{Frame, J1939_NO_NAME, ESHUTDOWN, ETIME};
use rcan_core::j1939_echo::{AfterSent, Done, EchoWait, Entry};
use rcan_core::j1939_errqueue::{Event, Session as NoteSession};

use super::j1939::{now_ns, IfaceState, J1939Proto};
use super::j1939_tp::{notify, IfaceJob};

/// The job timer of an interface that times the echoes.
pub(crate) const ECHO_TIMER: usize = 1;

/// Single frames an interface's sockets may have waiting for their echo
/// at once (a send beyond gets `ENOBUFS`). A CAN device's queue holds 10
/// frames by default (`txqueuelen`), so only echoes the device lost stay
/// long; mainline's limit is the senders' socket buffers.
const SLOTS: usize = 256;

/// The table of an interface (module documentation).
pub(crate) type EchoTable = EchoWait<KVec<Option<Entry<SockRef<J1939Proto>>>>>;

/// An empty table. Process context (allocates the slots).
pub(crate) fn new_table() -> Result<EchoTable> {
    let mut slots = KVec::with_capacity(SLOTS, GFP_KERNEL)?;
    for _ in 0..SLOTS {
        slots.push(None, GFP_KERNEL)?;
    }
    Ok(EchoWait::new(slots))
}

/// What a socket is told of its single frame `f` sent with timestamp
/// key `key`: mainline's statistics for a simple session, the whole
/// message acknowledged.
fn note_of(f: &Frame, key: u32) -> NoteSession {
    NoteSession {
        size: u32::from(f.len),
        acked: u32::from(f.len),
        pgn: f.id.pgn,
        src_name: J1939_NO_NAME,
        dst_name: J1939_NO_NAME,
        sa: f.id.sa,
        da: f.id.da,
        tskey: key,
    }
}

/// Tells `d`'s socket of `ev`, then puts the table's reference to it.
/// Any context, no lock held.
fn tell(d: Done<SockRef<J1939Proto>>, ev: Event) {
    notify(d.owner.sock(), ev, &note_of(&d.frame, d.key));
}

/// Sends `skb`, socket `sk`'s single frame `f` with timestamp key `key`,
/// on `dev`, the device of the interface whose job is `job`: with SO_J1939_ERRQUEUE on, the
/// send waits for its echo in the interface's table (module documentation). The
/// device's refusal is returned (and nothing is told). Process context.
/// `ENOBUFS` when the table is full.
pub(crate) fn send(
    sk: &Sock<J1939Proto>,
    job: JobRef<'_, IfaceJob>,
    dev: &NetDev,
    skb: UniqueSkb,
    f: Frame,
    key: u32,
) -> Result {
    let st = job.data();
    if !sk.shared().errqueue.load(Ordering::Relaxed) {
        return rcan_api::send(skb, dev, true);
    }
    let ticket = {
        let mut w = st.echo.lock();
        let t = w.push(sk.to_ref(), key, f, now_ns());
        st.echo_used.store(w.len(), Ordering::Relaxed);
        t
    };
    let ticket = match ticket {
        Ok(t) => t,
        // The reference is put outside the lock.
        Err((_owner, _)) => return Err(glue::neterr::ENOBUFS()),
    };
    if let Err(e) = rcan_api::send(skb, dev, true) {
        let owner = {
            let mut w = st.echo.lock();
            let o = w.failed(ticket);
            st.echo_used.store(w.len(), Ordering::Relaxed);
            o
        };
        drop(owner);
        return Err(e);
    }
    // Told before the entry can end: an echo or a cancel meanwhile only
    // marked it, and `sent` below ends it.
    notify(sk, Event::TxSched, &note_of(&f, key));
    let after = {
        let mut w = st.echo.lock();
        let a = w.sent(ticket);
        if let Some(at) = w.to_arm() {
            job.start(ECHO_TIMER, at);
        }
        st.echo_used.store(w.len(), Ordering::Relaxed);
        a
    };
    match after {
        AfterSent::Echoed(d) => tell(d, Event::TxAck),
        AfterSent::Cancelled(d) => tell(d, Event::TxAbort(ESHUTDOWN)),
        AfterSent::Waiting | AfterSent::Gone => {}
    }
    Ok(())
}

/// A frame `f` of interface `st` came back as the echo of a send by a
/// local socket (`skb.sk`): the send that waits for it ends, and its
/// socket is told of TX ACK (mainline's `j1939_simple_recv`). NET_RX
/// softirq.
pub(crate) fn on_echo(st: &IfaceState, skb: &Skb, f: &Frame) {
    if st.echo_used.load(Ordering::Relaxed) == 0 {
        return;
    }
    let done = {
        let mut w = st.echo.lock();
        let d = w.on_echo(f, |o| skb.sent_by(o.sock()));
        st.echo_used.store(w.len(), Ordering::Relaxed);
        d
    };
    if let Some(d) = done {
        tell(d, Event::TxAck);
    }
}

/// The echo timer of interface `job` expired: every send whose echo is
/// overdue ends, its socket told of TX ABORT `ETIME` (mainline's
/// `j1939_tp_rxtimer` for a simple session, which logs it too). HRTIMER
/// softirq.
pub(crate) fn on_timer(job: JobRef<'_, IfaceJob>) {
    let st = job.data();
    st.echo.lock().fired();
    let now = now_ns();
    let mut lost = 0u32;
    loop {
        let d = {
            let mut w = st.echo.lock();
            let d = w.next_expired(now);
            st.echo_used.store(w.len(), Ordering::Relaxed);
            d
        };
        let Some(d) = d else {
            break;
        };
        lost += 1;
        tell(d, Event::TxAbort(ETIME));
    }
    {
        let mut w = st.echo.lock();
        if let Some(at) = w.to_arm() {
            job.start(ECHO_TIMER, at);
        }
    }
    if lost > 0 {
        match DevRef::by_index(&st.net, st.ifindex) {
            Some(dev) => pr_warn!(
                "{}: {} single frame(s) not echoed within 10 s (ETIME)\n",
                dev.name(),
                lost
            ),
            None => pr_warn!(
                "ifindex {}: {} single frame(s) not echoed within 10 s (ETIME)\n",
                st.ifindex,
                lost
            ),
        }
    }
}

/// Cancels the sends of interface `st` that wait for their echo, those
/// of socket `which` or all (the interface going down or away: mainline's
/// `j1939_cancel_active_session`): each ends, its socket told of TX
/// ABORT `ESHUTDOWN`. Process context.
pub(crate) fn cancel(st: &IfaceState, which: Option<&Sock<J1939Proto>>) {
    loop {
        let d = {
            let mut w = st.echo.lock();
            let d = w.next_cancelled(|o| which.is_none_or(|s| o.sock().same(s)));
            st.echo_used.store(w.len(), Ordering::Relaxed);
            d
        };
        let Some(d) = d else {
            return;
        };
        tell(d, Event::TxAbort(ESHUTDOWN));
    }
}
