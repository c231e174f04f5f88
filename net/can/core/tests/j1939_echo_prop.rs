// SPDX-License-Identifier: GPL-2.0
//! `EchoWait` (the echo wait of CAN_J1939's single-frame sends) against a
//! plain reference model, for random sequences of pushes, hand-over
//! results (`sent`, `failed`), echoes, timeouts, cancels and timer
//! arming, on tables of 1..=8 slots with senders 0..3 and a few frames,
//! some of them identical. After every operation:
//!
//! - every pushed key ends exactly once (by an echo, by its sender after
//!   an echo or a cancel, by its timeout, by a cancel, or by `failed`),
//!   with the owner and frame it was pushed with, and never twice; `len`
//!   is the number of entries not ended, and a push with every slot in
//!   use gets `ENOBUFS` with its owner back;
//! - an echo takes the oldest entry of that sender with an equal frame
//!   that is being handed over (only marked) or waiting (ended), never
//!   one of another sender or another frame, nor one already marked;
//! - a timeout only ends waiting entries (`sent`, not marked) whose
//!   deadline, push time + `ECHO_TIMEOUT_NS`, has come, and leaves none
//!   of those behind;
//! - a cancel ends only waiting entries of the senders it names (all of
//!   them, one per call) and marks those being handed over;
//! - `sent` ends an entry marked by an echo as `Echoed`, one marked by a
//!   cancel as `Cancelled`, otherwise says `Waiting`; for an ended
//!   ticket it says `Gone` (and `failed` gives `None`);
//! - `to_arm` asks for the earliest deadline of the waiting entries
//!   exactly when it is earlier than what was armed since the last
//!   `fired` (or nothing was).
//!
//! At the end, cancelling everything and then resolving every
//! outstanding ticket with `sent` empties the table.

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::Config;
use rcan_core::j1939::{Frame, Id};
use rcan_core::j1939_echo::*;

const OWNERS: u32 = 3;
const SEC: u64 = 1_000_000_000;

/// The frames sent: the first two share an identifier, the first and the
/// third share data, so equal and near-equal frames are both common.
fn frames() -> [Frame; 4] {
    let id = |sa| Id {
        prio: 6,
        pgn: 0x1_2300,
        sa,
        da: 0x30,
    };
    [
        Frame::new(id(0x20), &[1, 2, 3]),
        Frame::new(id(0x20), &[1, 2, 4]),
        Frame::new(id(0x21), &[1, 2, 3]),
        Frame::new(id(0x20), &[]),
    ]
}

/// Where a model entry is in its life (the module's private `State`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum St {
    Sending,
    Sent,
    Echoed,
    Cancelled,
}

/// One pushed send; its key is its index in the model (push order).
#[derive(Debug)]
struct MEntry {
    owner: u32,
    frame: Frame,
    deadline: u64,
    ticket: Ticket,
    state: St,
    ended: bool,
}

#[derive(Clone, Debug)]
enum Op {
    /// Push a send of `frames()[frame]` by `owner`, `dt` s later.
    Push { owner: u32, frame: usize, dt: u64 },
    /// `sent` on a ticket not ended yet (`live`) or on any pushed one.
    Sent { live: bool, sel: Index },
    /// `failed` likewise.
    Failed { live: bool, sel: Index },
    /// An echo of `frames()[frame]` for `owner`.
    Echo { owner: u32, frame: usize },
    /// An echo of the frame and owner of a pushed entry.
    EchoOf(Index),
    /// `dt` s later, end every overdue entry.
    Expire { dt: u64 },
    /// Cancel the entries of one owner, or of all.
    Cancel(Option<u32>),
    Arm,
    Fired,
}

fn op() -> impl Strategy<Value = Op> {
    let nf = frames().len();
    prop_oneof![
        6 => (0..OWNERS, 0..nf, 0u64..4).prop_map(|(owner, frame, dt)| Op::Push { owner, frame, dt }),
        5 => (any::<bool>(), any::<Index>()).prop_map(|(live, sel)| Op::Sent { live, sel }),
        1 => (any::<bool>(), any::<Index>()).prop_map(|(live, sel)| Op::Failed { live, sel }),
        2 => (0..OWNERS, 0..nf).prop_map(|(owner, frame)| Op::Echo { owner, frame }),
        3 => any::<Index>().prop_map(Op::EchoOf),
        2 => (0u64..8).prop_map(|dt| Op::Expire { dt }),
        1 => prop::option::weighted(0.7, 0..OWNERS).prop_map(Op::Cancel),
        2 => Just(Op::Arm),
        1 => Just(Op::Fired),
    ]
}

struct Harness {
    w: EchoWait<Vec<Option<Entry<u32>>>>,
    cap: usize,
    m: Vec<MEntry>,
    now: u64,
    /// What the timer was last armed for since the last `fired`.
    armed: Option<u64>,
}

fn done(key: usize, e: &MEntry) -> Done<u32> {
    Done {
        owner: e.owner,
        key: key as u32,
        frame: e.frame,
    }
}

impl Harness {
    fn new(cap: usize) -> Self {
        Harness {
            w: EchoWait::new((0..cap).map(|_| None).collect()),
            cap,
            m: Vec::new(),
            now: 0,
            armed: None,
        }
    }

    fn live(&self) -> usize {
        self.m.iter().filter(|e| !e.ended).count()
    }

    /// The model entry `d` names, checked and ended: it must exist, not
    /// have ended, match `d`'s owner and frame, and satisfy `may`.
    fn end(&mut self, d: &Done<u32>, how: &str, may: impl Fn(&MEntry) -> bool) -> Result<(), TestCaseError> {
        let k = d.key as usize;
        prop_assert!(k < self.m.len(), "{}: unknown key {}", how, d.key);
        let e = &mut self.m[k];
        prop_assert!(!e.ended, "{}: key {} ended twice", how, k);
        prop_assert_eq!(d.owner, e.owner, "{}: key {}", how, k);
        prop_assert_eq!(d.frame, e.frame, "{}: key {}", how, k);
        prop_assert!(may(e), "{}: key {} may not end so: {:?}", how, k, e);
        e.ended = true;
        Ok(())
    }

    /// A ticket index: of an entry not ended (when `live` and there is
    /// one), else of any pushed entry; `None` before the first push.
    fn pick(&self, live: bool, sel: &Index) -> Option<usize> {
        let open: Vec<usize> = (0..self.m.len()).filter(|&k| !self.m[k].ended).collect();
        if live && !open.is_empty() {
            Some(open[sel.index(open.len())])
        } else if self.m.is_empty() {
            None
        } else {
            Some(sel.index(self.m.len()))
        }
    }

    fn push(&mut self, owner: u32, frame: Frame, dt: u64) -> Result<(), TestCaseError> {
        self.now += dt * SEC;
        let key = self.m.len() as u32;
        let full = self.live() == self.cap;
        match self.w.push(owner, key, frame, self.now) {
            Ok(ticket) => {
                prop_assert!(!full, "push into a full table of {}", self.cap);
                self.m.push(MEntry {
                    owner,
                    frame,
                    deadline: self.now + ECHO_TIMEOUT_NS,
                    ticket,
                    state: St::Sending,
                    ended: false,
                });
            }
            Err(e) => {
                prop_assert!(full, "ENOBUFS with {} of {} in use", self.live(), self.cap);
                prop_assert_eq!(e, (owner, ENOBUFS));
            }
        }
        Ok(())
    }

    fn sent(&mut self, k: usize) -> Result<(), TestCaseError> {
        let got = self.w.sent(self.m[k].ticket);
        let e = &mut self.m[k];
        let want = if e.ended {
            AfterSent::Gone
        } else {
            match e.state {
                St::Sending | St::Sent => {
                    e.state = St::Sent;
                    AfterSent::Waiting
                }
                St::Echoed => AfterSent::Echoed(done(k, e)),
                St::Cancelled => AfterSent::Cancelled(done(k, e)),
            }
        };
        prop_assert_eq!(&got, &want, "sent(key {})", k);
        if let AfterSent::Echoed(d) | AfterSent::Cancelled(d) = &got {
            self.end(d, "sent", |_| true)?;
        }
        Ok(())
    }

    fn failed(&mut self, k: usize) -> Result<(), TestCaseError> {
        let got = self.w.failed(self.m[k].ticket);
        let e = &mut self.m[k];
        if e.ended {
            prop_assert_eq!(got, None, "failed(key {}) after its end", k);
        } else {
            prop_assert_eq!(got, Some(e.owner), "failed(key {})", k);
            e.ended = true;
        }
        Ok(())
    }

    fn echo(&mut self, owner: u32, frame: Frame) -> Result<(), TestCaseError> {
        let got = self.w.on_echo(&frame, |o| *o == owner);
        // The oldest entry of `owner` with this frame, handed over or not,
        // that nothing marked yet.
        let cand = self
            .m
            .iter()
            .position(|e| !e.ended && e.owner == owner && e.frame == frame && matches!(e.state, St::Sending | St::Sent));
        match cand {
            None => prop_assert_eq!(got, None, "echo of owner {} {:?} matched nothing in the model", owner, frame),
            Some(k) if self.m[k].state == St::Sending => {
                prop_assert_eq!(got, None, "echo of key {} while being handed over", k);
                self.m[k].state = St::Echoed;
            }
            Some(k) => {
                prop_assert_eq!(got.as_ref(), Some(&done(k, &self.m[k])), "echo of owner {}", owner);
                self.end(got.as_ref().unwrap(), "echo", |e| e.state == St::Sent)?;
            }
        }
        Ok(())
    }

    fn expire(&mut self, dt: u64) -> Result<(), TestCaseError> {
        self.now += dt * SEC;
        let now = self.now;
        for _ in 0..=self.cap {
            let Some(d) = self.w.next_expired(now) else {
                break;
            };
            self.end(&d, "next_expired", |e| e.state == St::Sent && e.deadline <= now)?;
        }
        let left = self
            .m
            .iter()
            .position(|e| !e.ended && e.state == St::Sent && e.deadline <= now);
        prop_assert_eq!(left, None, "overdue entry left at {}", now);
        Ok(())
    }

    fn cancel(&mut self, owner: Option<u32>) -> Result<(), TestCaseError> {
        let hits = move |o: u32| owner.is_none_or(|x| x == o);
        for _ in 0..=self.cap + 1 {
            let got = self.w.next_cancelled(|o| hits(*o));
            for e in self.m.iter_mut().filter(|e| !e.ended && hits(e.owner)) {
                if e.state == St::Sending {
                    e.state = St::Cancelled;
                }
            }
            let Some(d) = got else {
                break;
            };
            self.end(&d, "next_cancelled", |e| e.state == St::Sent && hits(e.owner))?;
        }
        let left = self
            .m
            .iter()
            .position(|e| !e.ended && e.state == St::Sent && hits(e.owner));
        prop_assert_eq!(left, None, "waiting entry left by cancel of {:?}", owner);
        Ok(())
    }

    fn arm(&mut self) -> Result<(), TestCaseError> {
        let got = self.w.to_arm();
        let min = self
            .m
            .iter()
            .filter(|e| !e.ended && e.state == St::Sent)
            .map(|e| e.deadline)
            .min();
        let want = match min {
            Some(at) if self.armed.is_none_or(|a| at < a) => {
                self.armed = Some(at);
                Some(at)
            }
            _ => None,
        };
        prop_assert_eq!(got, want, "to_arm (earliest waiting {:?})", min);
        Ok(())
    }

    fn apply(&mut self, op: &Op) -> Result<(), TestCaseError> {
        let fr = frames();
        match *op {
            Op::Push { owner, frame, dt } => self.push(owner, fr[frame], dt)?,
            Op::Sent { live, ref sel } => {
                if let Some(k) = self.pick(live, sel) {
                    self.sent(k)?;
                }
            }
            Op::Failed { live, ref sel } => {
                if let Some(k) = self.pick(live, sel) {
                    self.failed(k)?;
                }
            }
            Op::Echo { owner, frame } => self.echo(owner, fr[frame])?,
            Op::EchoOf(ref sel) => {
                if let Some(k) = self.pick(true, sel) {
                    let (owner, frame) = (self.m[k].owner, self.m[k].frame);
                    self.echo(owner, frame)?;
                }
            }
            Op::Expire { dt } => self.expire(dt)?,
            Op::Cancel(owner) => self.cancel(owner)?,
            Op::Arm => self.arm()?,
            Op::Fired => {
                self.w.fired();
                self.armed = None;
            }
        }
        self.check()
    }

    fn check(&self) -> Result<(), TestCaseError> {
        prop_assert_eq!(self.w.len(), self.live());
        prop_assert_eq!(self.w.is_empty(), self.live() == 0);
        prop_assert!(self.w.len() <= self.cap);
        Ok(())
    }

    /// Cancel everything, then resolve every outstanding ticket: all of
    /// them end there, and the table is empty.
    fn drain(&mut self) -> Result<(), TestCaseError> {
        self.cancel(None)?;
        self.check()?;
        for k in 0..self.m.len() {
            if self.m[k].ended {
                continue;
            }
            let st = self.m[k].state;
            prop_assert!(
                matches!(st, St::Echoed | St::Cancelled),
                "key {} still {:?} after cancelling all",
                k,
                st
            );
            self.sent(k)?;
            prop_assert!(self.m[k].ended, "key {} not ended by sent after cancel", k);
            self.check()?;
        }
        prop_assert_eq!(self.w.len(), 0);
        prop_assert!(self.w.is_empty());
        prop_assert!(self.m.iter().all(|e| e.ended));
        prop_assert_eq!(self.w.to_arm(), None);
        prop_assert_eq!(self.w.next_expired(u64::MAX), None);
        prop_assert_eq!(self.w.next_cancelled(|_| true), None);
        // Every ticket is gone now, and every slot free again.
        for k in 0..self.m.len() {
            prop_assert_eq!(self.w.sent(self.m[k].ticket), AfterSent::Gone);
            prop_assert_eq!(self.w.failed(self.m[k].ticket), None);
        }
        for i in 0..self.cap {
            let r = self.w.push(0, 1000 + i as u32, frames()[0], self.now);
            prop_assert!(r.is_ok(), "slot {} of {} not free after draining", i, self.cap);
        }
        prop_assert_eq!(self.w.push(1, 2000, frames()[0], self.now).unwrap_err(), (1, ENOBUFS));
        Ok(())
    }
}

proptest! {
    // No regressions file: a failure is reported, not persisted.
    #![proptest_config(Config { failure_persistence: None, ..Config::default() })]

    #[test]
    fn echo_wait_follows_its_model(cap in 1usize..=8, ops in prop::collection::vec(op(), 0..200)) {
        let mut h = Harness::new(cap);
        for op in &ops {
            h.apply(op)?;
        }
        h.drain()?;
    }
}
