// SPDX-License-Identifier: GPL-2.0
//! The echo wait of CAN_J1939's single-frame sends (messages of at most 8
//! bytes), for the error queue: mainline sends each such message as a
//! "simple" session (`J1939_SIMPLE` in `net/can/j1939/transport.c`) and
//! tells a socket with `SO_J1939_ERRQUEUE` on of `SCM_TSTAMP_SCHED` when
//! the frame went to the device (`j1939_simple_txnext`), of
//! `SCM_TSTAMP_ACK` when its echo came back (`j1939_simple_recv`, the
//! session's end), and of `J1939_EE_INFO_TX_ABORT` with `ETIME` when no
//! echo came within 10 s (`J1939_SIMPLE_ECHO_TIMEOUT_MS`, the session's
//! receive timer) or with `ESHUTDOWN` when the interface went down first
//! (`j1939_cancel_active_session`). Rewritten here as a table of the sends
//! that wait for their echo, one per interface.
//!
//! An entry lives from just before its frame is handed to the device
//! ([`EchoWait::push`]) until its echo, its timeout or a cancel. Its
//! sender resolves the hand-over once the device took the frame
//! ([`EchoWait::sent`]) or refused it ([`EchoWait::failed`]); an echo or
//! a cancel that comes before that only marks the entry, so that the
//! sender's TX SCHED, told before it resolves, always comes before the
//! entry's end (TX ACK or TX ABORT), as on mainline (whose SCHED is told
//! in the timer softirq that sends the frame, before the NET_RX softirq
//! that brings the echo).
//!
//! An echo is matched to the oldest entry of the same sender with the
//! same frame (identifier and data): a frame the device lost leaves its
//! entry to time out, and the echoes of the frames after it still end
//! their own entries (a plain FIFO would shift every later key by one).
//! Two identical frames of one sender in flight may swap keys, which
//! nobody can tell apart.
//!
//! The table has a fixed number of slots, given by its storage (any
//! slice-like buffer: the kernel's `KVec`, a host `Vec`); a send with all
//! slots in use gets `ENOBUFS`. Allocation-free and lock-free itself: the
//! kernel module holds it under one lock and tells sockets after
//! releasing it.

use core::ops::DerefMut;

use super::j1939::Frame;

/// How long a single frame waits for its echo (mainline's
/// `J1939_SIMPLE_ECHO_TIMEOUT_MS`), in ns.
pub const ECHO_TIMEOUT_NS: u64 = 10_000_000_000;

/// `ENOBUFS`: every slot is in use.
pub const ENOBUFS: i32 = 105;

/// Where an entry is in its life.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum State {
    /// Pushed; its sender has not yet said whether the device took it.
    Sending,
    /// The device took it; the echo is awaited (and the timeout runs).
    Sent,
    /// The echo came while it was `Sending`: its sender ends it.
    Echoed,
    /// Cancelled while it was `Sending`: its sender ends it.
    Cancelled,
}

/// One send waiting for its echo.
#[derive(Debug)]
pub struct Entry<T> {
    owner: T,
    key: u32,
    frame: Frame,
    deadline: u64,
    /// Order of pushing: the oldest matching entry takes an echo.
    seq: u64,
    state: State,
}

/// An entry that ended: its sender (what was pushed), the send's
/// timestamp key and the frame (the message's size is its length).
#[derive(Debug, PartialEq, Eq)]
pub struct Done<T> {
    /// The sender, as given to [`EchoWait::push`].
    pub owner: T,
    /// The send's timestamp key.
    pub key: u32,
    /// The frame sent.
    pub frame: Frame,
}

/// How an entry's sender goes on once the device took the frame
/// ([`EchoWait::sent`]).
#[derive(Debug, PartialEq, Eq)]
pub enum AfterSent<T> {
    /// The echo is awaited.
    Waiting,
    /// The echo came back meanwhile: the entry ended, acknowledged.
    Echoed(Done<T>),
    /// The interface was cancelled meanwhile: the entry ended, aborted
    /// (`ESHUTDOWN`).
    Cancelled(Done<T>),
    /// No such entry (a ticket of another table, or used twice).
    Gone,
}

/// An entry's handle for its sender: its slot and push order.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Ticket {
    slot: usize,
    seq: u64,
}

/// The sends of one interface that wait for their echo (module
/// documentation). `S` is the storage: a slice of slots, all `None` at
/// first, whose length is the table's capacity.
#[derive(Debug)]
pub struct EchoWait<S> {
    slots: S,
    seq: u64,
    /// Entries in use.
    used: usize,
    /// The expiry the timer was last started for, `None` while it is not
    /// (or its callback runs).
    armed: Option<u64>,
}

impl<T, S: DerefMut<Target = [Option<Entry<T>>]>> EchoWait<S> {
    /// A table in `slots` (every slot should be `None`; one that is not
    /// is treated as an entry).
    pub fn new(slots: S) -> Self {
        let used = slots.iter().filter(|s| s.is_some()).count();
        EchoWait {
            slots,
            seq: 0,
            used,
            armed: None,
        }
    }

    /// Entries in use.
    pub fn len(&self) -> usize {
        self.used
    }

    /// Whether no send waits.
    pub fn is_empty(&self) -> bool {
        self.used == 0
    }

    /// Enters a send by `owner` of `frame` with timestamp key `key`, at
    /// time `now` (its echo is due by `now` + [`ECHO_TIMEOUT_NS`]): its
    /// ticket, or `ENOBUFS` (with `owner` back) when every slot is in use.
    pub fn push(&mut self, owner: T, key: u32, frame: Frame, now: u64) -> Result<Ticket, (T, i32)> {
        let Some(slot) = self.slots.iter().position(|s| s.is_none()) else {
            return Err((owner, ENOBUFS));
        };
        self.seq += 1;
        self.slots[slot] = Some(Entry {
            owner,
            key,
            frame,
            deadline: now.saturating_add(ECHO_TIMEOUT_NS),
            seq: self.seq,
            state: State::Sending,
        });
        self.used += 1;
        Ok(Ticket {
            slot,
            seq: self.seq,
        })
    }

    /// Takes the entry in `slot` out, ended.
    fn take(&mut self, slot: usize) -> Option<Done<T>> {
        let e = self.slots.get_mut(slot)?.take()?;
        self.used -= 1;
        Some(Done {
            owner: e.owner,
            key: e.key,
            frame: e.frame,
        })
    }

    /// The slot of `t`'s entry, if it is still there.
    fn find(&self, t: Ticket) -> Option<usize> {
        match self.slots.get(t.slot) {
            Some(Some(e)) if e.seq == t.seq => Some(t.slot),
            _ => None,
        }
    }

    /// The device took `t`'s frame: the entry now waits for its echo,
    /// unless the echo or a cancel came first (then it ends here).
    pub fn sent(&mut self, t: Ticket) -> AfterSent<T> {
        let Some(slot) = self.find(t) else {
            return AfterSent::Gone;
        };
        let state = match &mut self.slots[slot] {
            Some(e) => {
                if e.state == State::Sending {
                    e.state = State::Sent;
                }
                e.state
            }
            None => return AfterSent::Gone,
        };
        match (state, self.take_if_not(slot, State::Sent)) {
            (State::Echoed, Some(d)) => AfterSent::Echoed(d),
            (State::Cancelled, Some(d)) => AfterSent::Cancelled(d),
            _ => AfterSent::Waiting,
        }
    }

    /// Takes the entry in `slot` out unless it is in state `keep`.
    fn take_if_not(&mut self, slot: usize, keep: State) -> Option<Done<T>> {
        match &self.slots[slot] {
            Some(e) if e.state != keep => self.take(slot),
            _ => None,
        }
    }

    /// The device refused `t`'s frame (the sender reports that itself):
    /// the entry goes, nothing to tell. Its owner, if it was there.
    pub fn failed(&mut self, t: Ticket) -> Option<T> {
        let slot = self.find(t)?;
        self.take(slot).map(|d| d.owner)
    }

    /// A frame came back as the echo of a send by the owner `is_owner`
    /// accepts: the oldest such entry of the same frame that is still
    /// waiting ends, acknowledged; one whose sender is still handing it
    /// over is only marked (the sender ends it). `None`: nothing ended
    /// here (no such entry, or marked).
    pub fn on_echo(&mut self, frame: &Frame, mut is_owner: impl FnMut(&T) -> bool) -> Option<Done<T>> {
        let mut best: Option<(usize, u64)> = None;
        for (i, s) in self.slots.iter().enumerate() {
            if let Some(e) = s {
                if matches!(e.state, State::Sending | State::Sent)
                    && e.frame == *frame
                    && best.is_none_or(|(_, seq)| e.seq < seq)
                    && is_owner(&e.owner)
                {
                    best = Some((i, e.seq));
                }
            }
        }
        let (slot, _) = best?;
        if let Some(e) = &mut self.slots[slot] {
            if e.state == State::Sending {
                e.state = State::Echoed;
                return None;
            }
        }
        self.take(slot)
    }

    /// Ends one waiting entry whose echo is overdue at `now` (mainline:
    /// `ETIME`), if there is one; call again for the next. Entries still
    /// being handed over are left to their senders.
    pub fn next_expired(&mut self, now: u64) -> Option<Done<T>> {
        let slot = self
            .slots
            .iter()
            .position(|s| matches!(s, Some(e) if e.state == State::Sent && e.deadline <= now))?;
        self.take(slot)
    }

    /// Cancels the entries whose owner `is_owner` accepts (mainline:
    /// `ESHUTDOWN`): those being handed over are marked (their senders
    /// end them; one whose echo already came stays acknowledged), and
    /// one waiting entry ends here, if there is one; call again for the
    /// next.
    pub fn next_cancelled(&mut self, mut is_owner: impl FnMut(&T) -> bool) -> Option<Done<T>> {
        let mut hit = None;
        for (i, s) in self.slots.iter_mut().enumerate() {
            let Some(e) = s else {
                continue;
            };
            if !is_owner(&e.owner) {
                continue;
            }
            match e.state {
                State::Sending => e.state = State::Cancelled,
                State::Sent if hit.is_none() => hit = Some(i),
                _ => {}
            }
        }
        self.take(hit?)
    }

    /// The time to start the timer for, if it must be started: the
    /// earliest deadline of the waiting entries, when the timer is not
    /// armed for that or earlier (then it is recorded as armed).
    pub fn to_arm(&mut self) -> Option<u64> {
        let at = self
            .slots
            .iter()
            .flatten()
            .filter(|e| e.state == State::Sent)
            .map(|e| e.deadline)
            .min()?;
        if self.armed.is_some_and(|a| a <= at) {
            return None;
        }
        self.armed = Some(at);
        Some(at)
    }

    /// The timer's callback runs: the timer is not armed any more.
    pub fn fired(&mut self) {
        self.armed = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::j1939::Id;

    fn frame(sa: u8, b: u8) -> Frame {
        Frame::new(
            Id {
                prio: 6,
                pgn: 0x12300,
                sa,
                da: 0x30,
            },
            &[b, 1, 2],
        )
    }

    fn table(n: usize) -> EchoWait<Vec<Option<Entry<u32>>>> {
        EchoWait::new((0..n).map(|_| None).collect())
    }

    fn done(owner: u32, key: u32, f: Frame) -> Done<u32> {
        Done { owner, key, frame: f }
    }

    #[test]
    fn sent_then_echo_acks_in_order_of_sending() {
        let mut w = table(4);
        let t0 = w.push(1, 0, frame(0x20, 7), 0).unwrap();
        let t1 = w.push(1, 1, frame(0x20, 7), 0).unwrap();
        assert_eq!(w.sent(t0), AfterSent::Waiting);
        assert_eq!(w.sent(t1), AfterSent::Waiting);
        assert_eq!(w.on_echo(&frame(0x20, 7), |o| *o == 1), Some(done(1, 0, frame(0x20, 7))));
        assert_eq!(w.on_echo(&frame(0x20, 7), |o| *o == 1), Some(done(1, 1, frame(0x20, 7))));
        assert!(w.is_empty());
        assert_eq!(w.on_echo(&frame(0x20, 7), |o| *o == 1), None);
    }

    #[test]
    fn echo_before_sent_is_ended_by_the_sender() {
        let mut w = table(2);
        let t = w.push(5, 9, frame(0x20, 1), 0).unwrap();
        assert_eq!(w.on_echo(&frame(0x20, 1), |o| *o == 5), None);
        // A second echo of the same frame finds nothing waiting.
        assert_eq!(w.on_echo(&frame(0x20, 1), |o| *o == 5), None);
        assert_eq!(w.len(), 1);
        assert_eq!(w.sent(t), AfterSent::Echoed(done(5, 9, frame(0x20, 1))));
        assert!(w.is_empty());
        assert_eq!(w.sent(t), AfterSent::Gone);
    }

    #[test]
    fn a_lost_frame_times_out_and_later_echoes_keep_their_keys() {
        let mut w = table(4);
        let a = w.push(1, 0, frame(0x20, 1), 100).unwrap();
        let b = w.push(1, 1, frame(0x20, 2), 200).unwrap();
        w.sent(a);
        w.sent(b);
        // Frame 1 was lost: the echo of frame 2 ends key 1, not key 0.
        assert_eq!(w.on_echo(&frame(0x20, 2), |o| *o == 1), Some(done(1, 1, frame(0x20, 2))));
        assert_eq!(w.next_expired(100 + ECHO_TIMEOUT_NS - 1), None);
        assert_eq!(w.next_expired(100 + ECHO_TIMEOUT_NS), Some(done(1, 0, frame(0x20, 1))));
        assert_eq!(w.next_expired(u64::MAX), None);
        assert!(w.is_empty());
    }

    #[test]
    fn other_owners_and_frames_do_not_match() {
        let mut w = table(4);
        let t = w.push(1, 0, frame(0x20, 1), 0).unwrap();
        w.sent(t);
        assert_eq!(w.on_echo(&frame(0x20, 1), |o| *o == 2), None);
        assert_eq!(w.on_echo(&frame(0x20, 2), |o| *o == 1), None);
        assert_eq!(w.len(), 1);
    }

    #[test]
    fn full_table_refuses_with_enobufs_and_failed_frees() {
        let mut w = table(1);
        let t = w.push(1, 0, frame(0x20, 1), 0).unwrap();
        assert_eq!(w.push(2, 1, frame(0x20, 1), 0).unwrap_err(), (2, ENOBUFS));
        assert_eq!(w.failed(t), Some(1));
        assert_eq!(w.failed(t), None);
        assert!(w.push(2, 1, frame(0x20, 1), 0).is_ok());
    }

    #[test]
    fn cancel_ends_waiting_and_marks_sending() {
        let mut w = table(4);
        let a = w.push(1, 0, frame(0x20, 1), 0).unwrap();
        let b = w.push(1, 1, frame(0x20, 2), 0).unwrap();
        let c = w.push(2, 0, frame(0x21, 2), 0).unwrap();
        let d = w.push(1, 2, frame(0x20, 3), 0).unwrap();
        w.sent(a);
        w.sent(c);
        // d's echo came while it was being handed over.
        assert_eq!(w.on_echo(&frame(0x20, 3), |o| *o == 1), None);
        assert_eq!(w.next_cancelled(|o| *o == 1), Some(done(1, 0, frame(0x20, 1))));
        assert_eq!(w.next_cancelled(|o| *o == 1), None);
        assert_eq!(w.sent(b), AfterSent::Cancelled(done(1, 1, frame(0x20, 2))));
        assert_eq!(w.sent(d), AfterSent::Echoed(done(1, 2, frame(0x20, 3))));
        assert_eq!(w.len(), 1);
        // A cancelled entry is not matched by a late echo.
        assert_eq!(w.on_echo(&frame(0x21, 2), |o| *o == 2), Some(done(2, 0, frame(0x21, 2))));
    }

    #[test]
    fn timer_is_armed_for_the_earliest_waiting_entry_once() {
        let mut w = table(4);
        assert_eq!(w.to_arm(), None);
        let a = w.push(1, 0, frame(0x20, 1), 10).unwrap();
        // Still being handed over: nothing to time yet.
        assert_eq!(w.to_arm(), None);
        w.sent(a);
        assert_eq!(w.to_arm(), Some(10 + ECHO_TIMEOUT_NS));
        let b = w.push(1, 1, frame(0x20, 2), 20).unwrap();
        w.sent(b);
        assert_eq!(w.to_arm(), None);
        w.fired();
        assert_eq!(w.next_expired(10 + ECHO_TIMEOUT_NS), Some(done(1, 0, frame(0x20, 1))));
        assert_eq!(w.to_arm(), Some(20 + ECHO_TIMEOUT_NS));
    }
}
