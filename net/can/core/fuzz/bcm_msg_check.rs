// SPDX-License-Identifier: GPL-2.0
//! The check both the cargo-fuzz target `bcm_msg` and the host test
//! `tests/bcm_msg_fuzz_replay.rs` run: any byte string written to a BCM
//! socket is parsed and checked as every opcode would be, on a real and on
//! the "any" interface, as a new operation and as an update, without a
//! panic and with only mainline's errno; a message that passes its
//! setup checks then drives a transmit or receive operation for a while
//! of virtual time, fed with the message's own frames (classic or, with
//! `CAN_FD_FRAME`, CAN FD; every third one as the other kind, which the
//! operation must ignore).

use rcan_core::arb::EINVAL;
use rcan_core::bcm::{self, MsgHead};
use rcan_core::bcm_rx::{RxOp, RxOut, RxSlot};
use rcan_core::bcm_tx::{TxOp, TxOut};
use rcan_core::frame::{AnyFrame, CanFdFrame, CanFrame};

/// Counts effects and checks the timers only move forward.
#[derive(Default)]
struct Sink {
    now: u64,
    timer: Option<u64>,
    throttle: Option<u64>,
    msgs: usize,
}

impl TxOut for Sink {
    fn send(&mut self, _index: usize) -> bool {
        true
    }
    fn to_user(&mut self, _head: &MsgHead, _with_frames: bool) {
        self.msgs += 1;
    }
    fn arm(&mut self, at: u64) {
        assert!(at > self.now);
        self.timer = Some(at);
    }
    fn cancel(&mut self) {
        self.timer = None;
    }
}

impl RxOut for Sink {
    fn to_user(&mut self, _head: &MsgHead, _frame: Option<(&CanFdFrame, u8)>, _ifindex: i32) {
        self.msgs += 1;
    }
    fn send_reply(&mut self, _reply: &CanFdFrame, _ifindex: i32) {}
    fn arm_timeout(&mut self, at: u64) {
        assert!(at >= self.now);
        self.timer = Some(at);
    }
    fn cancel_timeout(&mut self) {
        self.timer = None;
    }
    fn arm_throttle(&mut self, at: u64) {
        assert!(at > self.now);
        self.throttle = Some(at);
    }
    fn cancel_throttle(&mut self) {
        self.throttle = None;
    }
}

const ERRNOS: [i32; 4] = [EINVAL, bcm::EFAULT, bcm::E2BIG, bcm::ENODEV];

/// Runs the check on one input.
pub fn check(input: &[u8]) {
    let req = match bcm::parse(input) {
        Ok(r) => r,
        Err(e) => return assert_eq!(e, EINVAL),
    };
    let frames: Vec<CanFdFrame> = (0..)
        .map_while(|i| bcm::frame_at(req.payload, req.head.cfsiz(), i))
        .take(300)
        .collect();
    for existing in [None, Some(1), Some(256)] {
        for ifindex in [0, 1] {
            if let Err(e) = bcm::check_tx_setup(&req, ifindex, existing) {
                assert!(ERRNOS.contains(&e));
            }
        }
        if let Err(e) = bcm::check_rx_setup(&req, existing) {
            assert!(ERRNOS.contains(&e));
        }
    }
    if let Err(e) = bcm::check_tx_send(&req, 1) {
        assert!(ERRNOS.contains(&e));
    }
    let h = req.head;
    let fd = h.flags & bcm::CAN_FD_FRAME != 0;
    if bcm::check_tx_setup(&req, 1, None).is_ok() {
        let mut op = TxOp::new(&h);
        let mut s = Sink::default();
        op.setup(&h, 0, &mut s);
        for _ in 0..1000 {
            let Some(at) = s.timer.take() else { break };
            s.now = at;
            op.timer_expired(at, &mut s);
            assert!(op.currframe < op.nframes);
        }
    }
    if bcm::check_rx_setup(&req, None).is_ok() {
        let h = bcm::rx_setup_head(&h);
        let filters = &frames[..h.nframes as usize];
        let mut last = vec![RxSlot::default(); filters.len().max(1)];
        let mut op = RxOp::new(&h, 0);
        let mut s = Sink::default();
        op.setup(&h, 0, &mut last, &mut s);
        // Replay the message's frames (with the operation's identifier) as
        // received ones, 1 ms apart, firing due timers in between.
        for (k, f) in frames.iter().enumerate() {
            let t = (k as u64 + 1) * 1_000_000;
            loop {
                let due = [s.timer, s.throttle]
                    .into_iter()
                    .flatten()
                    .min()
                    .filter(|&d| d <= t);
                let Some(d) = due else { break };
                s.now = d;
                if s.throttle == Some(d) {
                    s.throttle = None;
                    op.throttle_expired(d, &mut last, &mut s);
                } else {
                    s.timer = None;
                    op.timeout_expired(&mut last, &mut s);
                }
            }
            s.now = t;
            let as_fd = fd != (k % 3 == 2);
            let rx = if as_fd {
                AnyFrame::Fd(CanFdFrame {
                    can_id: h.can_id,
                    len: f.len.min(64),
                    ..*f
                })
            } else {
                let b: [u8; 16] = f.to_bytes()[..16].try_into().unwrap();
                let c = CanFrame::from_bytes(&b);
                AnyFrame::Classic(CanFrame {
                    can_id: h.can_id,
                    len: c.len.min(8),
                    ..c
                })
            };
            let msgs = s.msgs;
            op.frame_received(&rx, 1 + (k as i32 & 1), 0, t, filters, &mut last, &mut s);
            if as_fd != fd {
                assert_eq!(s.msgs, msgs, "a frame of the other kind was reported");
            }
        }
    }
}
