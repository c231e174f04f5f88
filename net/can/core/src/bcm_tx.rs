// SPDX-License-Identifier: GPL-2.0
//! One BCM transmit operation (`TX_SETUP`) as a pure state machine over
//! virtual time: mainline's `bcm_tx_setup`, `bcm_can_tx`,
//! `bcm_tx_set_expiry` and `bcm_tx_timeout_handler`, rewritten.
//!
//! One [`TxOp`] exists per (can_id, ifindex, CAN FD) key of a socket. It
//! holds only the schedule; the frames live with the caller (the kernel
//! module's allocation, a test's array) and are passed in where needed.
//! Effects go to a [`TxOut`]: "send frame i", "queue this message for user
//! space", "arm the timer at t", "cancel the timer". The caller serializes
//! all calls on one operation (the module holds the operation's lock).
//! Nothing here sleeps or allocates, so any context may call it; in the
//! module `setup` and `read` run in process context (`sendmsg`) and
//! `timer_expired` in the hrtimer's softirq context (mainline arms its
//! timers `HRTIMER_MODE_*_SOFT`).
//!
//! The schedule: while `count` > 0 and `ival1` != 0 each expiry sends one
//! frame and decrements `count`; then every `ival2` (if != 0) sends one
//! frame forever. Every transmission, including the immediate one of
//! [`TX_ANNOUNCE`]/[`STARTTIMER`], advances the frame index (cycling
//! through the frames) and decrements a positive `count`. `TX_EXPIRED` is
//! sent (with [`TX_COUNTEVT`]) only from an expiry whose transmission
//! brought `count` to 0: a `count` used up by the announce transmission
//! alone produces none, as in mainline.

use super::bcm::{
    BcmTimeval, MsgHead, SETTIMER, STARTTIMER, TX_ANNOUNCE, TX_COUNTEVT, TX_EXPIRED,
    TX_RESET_MULTI_IDX, TX_STATUS,
};

/// Where a [`TxOp`] sends its effects.
pub trait TxOut {
    /// Transmit frame `index` of the operation now (with loopback).
    /// Returns whether the interface exists: mainline advances the frame
    /// index and the count only then.
    fn send(&mut self, index: usize) -> bool;
    /// Queue a message for user space (`TX_EXPIRED`, `TX_STATUS`);
    /// `with_frames`: append the operation's `head.nframes` frames.
    fn to_user(&mut self, head: &MsgHead, with_frames: bool);
    /// Arm the operation's timer to expire at `at` (ns, monotonic).
    fn arm(&mut self, at: u64);
    /// Cancel the timer (and wait for a running expiry).
    fn cancel(&mut self);
}

/// State of one transmit operation; protected by the operation's lock in
/// the kernel module (`bcm_tx_lock` in mainline).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TxOp {
    /// The identifier that names the operation.
    pub can_id: u32,
    /// Flags of the last setup (plus [`TX_ANNOUNCE`] after a
    /// [`STARTTIMER`], as mainline keeps it).
    pub flags: u32,
    /// Transmissions left at `ival1`.
    pub count: u32,
    /// First interval as user space gave it ([`TxOp::ival1`]).
    ival1: BcmTimeval,
    /// Second interval as user space gave it ([`TxOp::ival2`]).
    ival2: BcmTimeval,
    /// `ival1` and `ival2` in nanoseconds ([`BcmTimeval::to_ns`]), kept
    /// in step with them by [`TxOp::setup`], their only writer: the
    /// schedule reads them on every expiry.
    ival_ns: [u64; 2],
    /// Frames in the sequence (1..=256).
    pub nframes: u32,
    /// Index of the next frame to send.
    pub currframe: u32,
    /// When the timer expires, if armed.
    pub expires: Option<u64>,
}

impl TxOp {
    /// A new operation from a checked `TX_SETUP` head
    /// ([`super::bcm::check_tx_setup`]); then call [`TxOp::setup`] to run
    /// its flags. `count` is taken only with [`SETTIMER`].
    pub fn new(head: &MsgHead) -> Self {
        Self {
            can_id: head.can_id,
            flags: head.flags,
            count: 0,
            ival1: BcmTimeval::default(),
            ival2: BcmTimeval::default(),
            ival_ns: [0, 0],
            nframes: head.nframes,
            currframe: 0,
            expires: None,
        }
    }

    /// Applies a checked `TX_SETUP` at time `now` (after the caller copied
    /// `head.nframes` frames into the operation's first slots). For an
    /// existing operation: the flags are replaced; a changed frame count
    /// or [`TX_RESET_MULTI_IDX`] restarts the sequence at frame 0;
    /// [`SETTIMER`] replaces `count` and both intervals (both 0: the timer
    /// stops); a running timer otherwise keeps its expiry. Then
    /// [`STARTTIMER`] restarts the timer (and implies [`TX_ANNOUNCE`]),
    /// and [`TX_ANNOUNCE`] sends the current frame at once.
    pub fn setup(&mut self, head: &MsgHead, now: u64, out: &mut impl TxOut) {
        self.flags = head.flags;
        if self.nframes != head.nframes || self.flags & TX_RESET_MULTI_IDX != 0 {
            self.nframes = head.nframes;
            self.currframe = 0;
        }
        if self.flags & SETTIMER != 0 {
            self.count = head.count;
            self.ival1 = head.ival1;
            self.ival2 = head.ival2;
            self.ival_ns = [head.ival1.to_ns(), head.ival2.to_ns()];
            if self.ival_ns == [0, 0] {
                self.stop(out);
            }
        }
        if self.flags & STARTTIMER != 0 {
            self.stop(out);
            self.flags |= TX_ANNOUNCE;
        }
        if self.flags & TX_ANNOUNCE != 0 {
            self.transmit(out);
        }
        if self.flags & STARTTIMER != 0 {
            self.start(now, out);
        }
    }

    /// The timer expired at `now`: one transmission of the schedule,
    /// maybe `TX_EXPIRED`, and the timer re-armed for the next one.
    pub fn timer_expired(&mut self, now: u64, out: &mut impl TxOut) {
        self.expires = None;
        let [i1, i2] = self.ival_ns;
        if i1 != 0 && self.count > 0 {
            self.transmit(out);
            if self.count == 0 && self.flags & TX_COUNTEVT != 0 {
                out.to_user(&self.notification(TX_EXPIRED, 0), false);
            }
        } else if i2 != 0 {
            self.transmit(out);
        }
        self.start(now, out);
    }

    /// The first interval as user space gave it (zero before a
    /// [`SETTIMER`]).
    pub fn ival1(&self) -> BcmTimeval {
        self.ival1
    }

    /// The second interval as user space gave it (zero before a
    /// [`SETTIMER`]).
    pub fn ival2(&self) -> BcmTimeval {
        self.ival2
    }

    /// The `TX_STATUS` reply to `TX_READ` (with the frames).
    pub fn read(&self, out: &mut impl TxOut) {
        out.to_user(&self.notification(TX_STATUS, self.nframes), true);
    }

    /// The next interval: `ival1` while `count` lasts, else `ival2`, else
    /// none (mainline's `bcm_tx_set_expiry`).
    pub fn next_interval(&self) -> Option<u64> {
        let [i1, i2] = self.ival_ns;
        if i1 != 0 && self.count > 0 {
            Some(i1)
        } else if i2 != 0 {
            Some(i2)
        } else {
            None
        }
    }

    fn start(&mut self, now: u64, out: &mut impl TxOut) {
        if let Some(ival) = self.next_interval() {
            let at = now.saturating_add(ival);
            self.expires = Some(at);
            out.arm(at);
        }
    }

    fn stop(&mut self, out: &mut impl TxOut) {
        if self.expires.take().is_some() {
            out.cancel();
        }
    }

    fn transmit(&mut self, out: &mut impl TxOut) {
        if out.send(self.currframe as usize) {
            self.currframe += 1;
            if self.currframe >= self.nframes {
                self.currframe = 0;
            }
            self.count = self.count.saturating_sub(1);
        }
    }

    fn notification(&self, opcode: u32, nframes: u32) -> MsgHead {
        MsgHead {
            opcode,
            flags: self.flags,
            count: self.count,
            ival1: self.ival1,
            ival2: self.ival2,
            can_id: self.can_id,
            nframes,
        }
    }
}
