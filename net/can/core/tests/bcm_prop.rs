// SPDX-License-Identifier: GPL-2.0
//! Properties of the pure BCM core (`bcm`, `bcm_tx`, `bcm_rx`): the message
//! format round-trips and never panics, the transmit schedule is mainline's
//! two-interval schedule, change detection reports exactly the masked
//! changes, throttling never reports more than once per `ival2` and never
//! loses the last change. Virtual time in nanoseconds.

use proptest::prelude::*;
use rcan_core::arb::{CAN_RTR_FLAG, EINVAL};
use rcan_core::bcm::*;
use rcan_core::bcm_rx::{RxOp, RxOut, RxSlot};
use rcan_core::bcm_tx::{TxOp, TxOut};
use rcan_core::frame::{AnyFrame, CanFdFrame, CanFrame};

const US: u64 = 1_000;

fn frame(id: u32, len: u8, data: [u8; 8]) -> CanFrame {
    CanFrame {
        can_id: id,
        len,
        data,
        ..CanFrame::default()
    }
}

/// The classic frame in the first 16 bytes of a CAN FD layout frame.
fn narrow(f: &CanFdFrame) -> CanFrame {
    CanFrame::from_bytes(f.to_bytes()[..16].try_into().unwrap())
}

fn fd_frame(id: u32, len: u8, data: [u8; 64]) -> CanFdFrame {
    CanFdFrame {
        can_id: id,
        len,
        data,
        ..CanFdFrame::default()
    }
}

fn message(head: &MsgHead, frames: &[CanFrame]) -> Vec<u8> {
    let mut v = vec![0u8; MHSIZ + frames.len() * 16];
    assert_eq!(serialize(head, frames, &mut v), Some(v.len()));
    v
}

// ---- transmit -------------------------------------------------------------

#[derive(Default)]
struct TxRec {
    now: u64,
    sends: Vec<(u64, usize)>,
    msgs: Vec<(u64, MsgHead)>,
    armed: Option<u64>,
}

impl TxOut for TxRec {
    fn send(&mut self, index: usize) -> bool {
        self.sends.push((self.now, index));
        true
    }
    fn to_user(&mut self, head: &MsgHead, _with_frames: bool) {
        self.msgs.push((self.now, *head));
    }
    fn arm(&mut self, at: u64) {
        assert!(at > self.now, "timer armed in the past");
        self.armed = Some(at);
    }
    fn cancel(&mut self) {
        self.armed = None;
    }
}

/// Runs `op`'s timer until `end`.
fn run_tx(op: &mut TxOp, rec: &mut TxRec, end: u64) {
    while let Some(at) = rec.armed.filter(|&t| t <= end) {
        assert_eq!(op.expires, Some(at));
        rec.armed = None;
        rec.now = at;
        op.timer_expired(at, rec);
    }
}

fn tx_head(flags: u32, count: u32, ival1_us: u64, ival2_us: u64, nframes: u32) -> MsgHead {
    MsgHead {
        opcode: TX_SETUP,
        flags,
        count,
        ival1: BcmTimeval::from_us(ival1_us),
        ival2: BcmTimeval::from_us(ival2_us),
        can_id: 0x123,
        nframes,
    }
}

proptest! {
    /// SETTIMER|STARTTIMER: one frame at once, `count` frames in all at
    /// `ival1` (the first being the immediate one), then every `ival2`;
    /// the frames cycle in order; TX_EXPIRED once, when the timer brings
    /// count to 0 (never when the immediate frame used it up).
    #[test]
    fn tx_schedule(count in 0u32..12, ival1 in 0u64..5000, ival2 in 1u64..5000,
                   nframes in 1u32..5, evt in any::<bool>()) {
        let flags = SETTIMER | STARTTIMER | if evt { TX_COUNTEVT } else { 0 };
        let h = tx_head(flags, count, ival1, ival2, nframes);
        let mut op = TxOp::new(&h);
        let mut rec = TxRec::default();
        op.setup(&h, 0, &mut rec);
        let end = 40 * 5000 * US;
        run_tx(&mut op, &mut rec, end);
        // The expected times.
        let mut want = vec![0u64];
        let mut t = 0;
        let in_ival1 = if ival1 > 0 { count.saturating_sub(1) } else { 0 };
        for _ in 0..in_ival1 {
            t += ival1 * US;
            want.push(t);
        }
        let expired_at = (ival1 > 0 && count >= 2).then_some(t);
        while t + ival2 * US <= end {
            t += ival2 * US;
            want.push(t);
        }
        let times: Vec<u64> = rec.sends.iter().map(|s| s.0).collect();
        prop_assert_eq!(times, want);
        for (k, s) in rec.sends.iter().enumerate() {
            prop_assert_eq!(s.1, k % nframes as usize);
        }
        let expired: Vec<u64> = rec.msgs.iter().filter(|m| m.1.opcode == TX_EXPIRED).map(|m| m.0).collect();
        prop_assert_eq!(expired, if evt { expired_at.into_iter().collect() } else { vec![] });
        prop_assert_eq!(op.count, 0);
    }

    /// Without STARTTIMER nothing is scheduled; without TX_ANNOUNCE nothing
    /// is sent at setup.
    #[test]
    fn tx_setup_without_start(count in 0u32..5, ival1 in 0u64..50, ival2 in 0u64..50) {
        let h = tx_head(SETTIMER, count, ival1, ival2, 1);
        let mut op = TxOp::new(&h);
        let mut rec = TxRec::default();
        op.setup(&h, 0, &mut rec);
        prop_assert!(rec.sends.is_empty());
        prop_assert_eq!(rec.armed, None);
    }
}

#[test]
fn tx_update_keeps_running_timer_and_index() {
    let h = tx_head(SETTIMER | STARTTIMER, 0, 0, 100, 3);
    let mut op = TxOp::new(&h);
    let mut rec = TxRec::default();
    op.setup(&h, 0, &mut rec);
    run_tx(&mut op, &mut rec, 150 * US);
    assert_eq!(op.currframe, 2);
    // New data, same nframes, no flags: timer and index untouched.
    rec.now = 160 * US;
    op.setup(&tx_head(0, 0, 0, 0, 3), rec.now, &mut rec);
    assert_eq!(op.currframe, 2);
    assert_eq!(rec.armed, Some(200 * US));
    // TX_RESET_MULTI_IDX restarts the sequence.
    op.setup(&tx_head(TX_RESET_MULTI_IDX, 0, 0, 0, 3), rec.now, &mut rec);
    assert_eq!(op.currframe, 0);
    // Fewer frames restart it too.
    op.currframe = 1;
    op.setup(&tx_head(0, 0, 0, 0, 2), rec.now, &mut rec);
    assert_eq!((op.currframe, op.nframes), (0, 2));
    // SETTIMER with zero intervals stops the timer.
    op.setup(&tx_head(SETTIMER, 0, 0, 0, 2), rec.now, &mut rec);
    assert_eq!(rec.armed, None);
}

#[test]
fn tx_read_reports_state() {
    let h = tx_head(SETTIMER | STARTTIMER, 3, 10, 100, 1);
    let mut op = TxOp::new(&h);
    let mut rec = TxRec::default();
    op.setup(&h, 0, &mut rec);
    op.read(&mut rec);
    let (_, st) = rec.msgs.last().copied().unwrap();
    assert_eq!(st.opcode, TX_STATUS);
    // STARTTIMER leaves TX_ANNOUNCE set; the immediate frame used a count.
    assert_eq!(st.flags, SETTIMER | STARTTIMER | TX_ANNOUNCE);
    assert_eq!((st.count, st.nframes, st.can_id), (2, 1, 0x123));
    assert_eq!(st.ival2, BcmTimeval { sec: 0, usec: 100 });
}

// ---- receive --------------------------------------------------------------

#[derive(Default)]
struct RxRec {
    changed: Vec<(u64, CanFrame)>,
    /// The same reports in the CAN FD layout (all 64 data bytes).
    changed_fd: Vec<(u64, CanFdFrame)>,
    timeouts: Vec<u64>,
    replies: Vec<CanFdFrame>,
    timeout_at: Option<u64>,
    throttle_at: Option<u64>,
    now: u64,
}

impl RxOut for RxRec {
    fn to_user(&mut self, head: &MsgHead, frame: Option<(&CanFdFrame, u8)>, _ifindex: i32) {
        match head.opcode {
            RX_CHANGED => {
                let f = frame.unwrap().0;
                self.changed.push((self.now, narrow(f)));
                self.changed_fd.push((self.now, *f));
            }
            RX_TIMEOUT => self.timeouts.push(self.now),
            _ => {}
        }
    }
    fn send_reply(&mut self, reply: &CanFdFrame, _ifindex: i32) {
        self.replies.push(*reply);
    }
    fn arm_timeout(&mut self, at: u64) {
        self.timeout_at = Some(at);
    }
    fn cancel_timeout(&mut self) {
        self.timeout_at = None;
    }
    fn arm_throttle(&mut self, at: u64) {
        assert!(at > self.now);
        self.throttle_at = Some(at);
    }
    fn cancel_throttle(&mut self) {
        self.throttle_at = None;
    }
}

struct Rx {
    op: RxOp,
    filters: Vec<CanFdFrame>,
    last: Vec<RxSlot>,
    rec: RxRec,
}

impl Rx {
    fn new(flags: u32, ival1_us: u64, ival2_us: u64, filters: Vec<CanFrame>) -> Rx {
        Rx::new_any(
            flags,
            ival1_us,
            ival2_us,
            filters.iter().map(widen).collect(),
        )
    }

    /// An operation whose filters are given in the CAN FD layout (with
    /// `CAN_FD_FRAME` in `flags` the message carries 72-byte frames).
    fn new_any(flags: u32, ival1_us: u64, ival2_us: u64, filters: Vec<CanFdFrame>) -> Rx {
        let raw = MsgHead {
            opcode: RX_SETUP,
            flags,
            count: 0,
            ival1: BcmTimeval::from_us(ival1_us),
            ival2: BcmTimeval::from_us(ival2_us),
            can_id: 0x42,
            nframes: filters.len() as u32,
        };
        let mut msg = vec![0u8; MHSIZ + filters.len() * raw.cfsiz()];
        assert_eq!(serialize_any(&raw, &filters, &mut msg), Some(msg.len()));
        let req = parse(&msg).unwrap();
        check_rx_setup(&req, None).unwrap();
        let h = rx_setup_head(&raw);
        let mut rx = Rx {
            op: RxOp::new(&h, 1),
            last: vec![RxSlot::default(); filters.len().max(1)],
            filters,
            rec: RxRec::default(),
        };
        rx.op.setup(&h, 0, &mut rx.last, &mut rx.rec);
        rx
    }

    /// Runs the timers due up to `t`, then delivers `f` at `t`.
    fn recv_at(&mut self, t: u64, f: &CanFrame) {
        self.recv_any_at(t, &AnyFrame::Classic(*f));
    }

    fn recv_any_at(&mut self, t: u64, f: &AnyFrame) {
        self.run_until(t);
        self.rec.now = t;
        self.op
            .frame_received(f, 1, 0, t, &self.filters, &mut self.last, &mut self.rec);
    }

    fn run_until(&mut self, end: u64) {
        loop {
            let next = [self.rec.timeout_at, self.rec.throttle_at]
                .into_iter()
                .flatten()
                .min()
                .filter(|&t| t <= end);
            let Some(t) = next else { break };
            self.rec.now = t;
            if self.rec.throttle_at == Some(t) {
                self.rec.throttle_at = None;
                self.op.throttle_expired(t, &mut self.last, &mut self.rec);
            } else {
                self.rec.timeout_at = None;
                self.op.timeout_expired(&mut self.last, &mut self.rec);
            }
        }
    }
}

fn small_frame() -> impl Strategy<Value = CanFrame> {
    (0u8..=8, prop::array::uniform8(0u8..3)).prop_map(|(len, data)| frame(0x42, len, data))
}

proptest! {
    /// Without throttling: RX_CHANGED for the first frame and then iff
    /// the data under the mask (for a nonzero length) or, with
    /// RX_CHECK_DLC, the length changed; it carries the new frame.
    #[test]
    fn rx_changed_iff_masked_change(mask in prop::array::uniform8(prop_oneof![Just(0u8), Just(0xffu8), any::<u8>()]),
                                    check_dlc in any::<bool>(),
                                    frames in prop::collection::vec(small_frame(), 1..40)) {
        let flags = if check_dlc { RX_CHECK_DLC } else { 0 };
        let mut rx = Rx::new(flags, 0, 0, vec![frame(0x42, 8, mask)]);
        let m = u64::from_ne_bytes(mask);
        let mut prev: Option<CanFrame> = None;
        let mut want = Vec::new();
        for (k, f) in frames.iter().enumerate() {
            let t = k as u64 * 10 * US;
            let changed = match prev {
                None => true,
                Some(p) => (f.len > 0 && m & u64::from_ne_bytes(f.data) != m & u64::from_ne_bytes(p.data))
                    || (check_dlc && f.len != p.len),
            };
            if changed {
                want.push((t, *f));
                prev = Some(*f);
            }
            rx.recv_at(t, f);
        }
        prop_assert_eq!(rx.rec.changed, want);
    }

    /// With throttling: reports are at least ival2 apart, each carries the
    /// newest change at its time, and the last change is always reported.
    #[test]
    fn rx_throttle(ival2 in 1u64..100, gaps in prop::collection::vec((1u64..150, 0u8..4), 1..60)) {
        let mut rx = Rx::new(SETTIMER, 0, ival2, vec![frame(0x42, 8, [0xff; 8])]);
        let mut t = 0;
        let mut sent = Vec::new();
        for (gap, v) in gaps {
            t += gap * US;
            let f = frame(0x42, 1, [v, 0, 0, 0, 0, 0, 0, 0]);
            rx.recv_at(t, &f);
            sent.push((t, f));
        }
        rx.run_until(u64::MAX);
        prop_assert!(rx.rec.throttle_at.is_none());
        let ch = &rx.rec.changed;
        for w in ch.windows(2) {
            prop_assert!(w[1].0 - w[0].0 >= ival2 * US, "reports {:?} closer than ival2", w);
        }
        // Each report is the frame received at its time or else the newest
        // one before it (a timer due at a frame's time runs before the
        // frame). (Two reports may carry equal data: A, B held back, A
        // again is a change against B, as in mainline.)
        for (rt, f) in ch.iter() {
            let at = sent.iter().find(|s| s.0 == *rt).map(|s| s.1);
            let before = sent.iter().rev().find(|s| s.0 < *rt).map(|s| s.1);
            prop_assert!(at == Some(*f) || before == Some(*f), "report {:?} at {}", f, rt);
        }
        // The last change is never lost: the final state was reported.
        let final_data = sent.last().unwrap().1.data;
        prop_assert_eq!(ch.last().unwrap().1.data, final_data);
    }

    /// Mux: a frame goes to the first entry whose data equals it under the
    /// mux mask; frames matching no entry are ignored.
    #[test]
    fn rx_mux_first_match(sel in prop::collection::vec(0u8..6, 1..30)) {
        let mux = frame(0x42, 8, [0xff, 0, 0, 0, 0, 0, 0, 0]);
        let entries: Vec<CanFrame> = (0..4u8).map(|i| frame(0x42, 8, [i, 0xff, 0, 0, 0, 0, 0, 0])).collect();
        let mut filters = vec![mux];
        filters.extend(&entries);
        let mut rx = Rx::new(0, 0, 0, filters);
        let mut last_per_entry = [None::<u8>; 4];
        let mut want = Vec::new();
        for (k, s) in sel.iter().enumerate() {
            let f = frame(0x42, 8, [*s, k as u8 % 3, 0, 0, 0, 0, 0, 0]);
            let t = k as u64 * US;
            if (*s as usize) < 4 {
                let e = *s as usize;
                if last_per_entry[e] != Some(f.data[1]) {
                    last_per_entry[e] = Some(f.data[1]);
                    want.push((t, f));
                }
            }
            rx.recv_at(t, &f);
        }
        prop_assert_eq!(&rx.rec.changed, &want);
    }
}

#[test]
fn rx_timeout_and_resume() {
    let mut rx = Rx::new(
        SETTIMER | STARTTIMER | RX_ANNOUNCE_RESUME,
        100,
        0,
        vec![frame(0x42, 8, [0xff; 8])],
    );
    let f = frame(0x42, 1, [7, 0, 0, 0, 0, 0, 0, 0]);
    rx.recv_at(50 * US, &f);
    rx.recv_at(120 * US, &f); // same content: no report, timer restarted
    assert_eq!(rx.rec.changed.len(), 1);
    rx.run_until(1000 * US);
    assert_eq!(rx.rec.timeouts, vec![220 * US]); // once, not re-armed
    rx.recv_at(1000 * US, &f); // same content, but announced after a timeout
    assert_eq!(rx.rec.changed.len(), 2);
}

#[test]
fn rx_timeout_without_resume_and_no_autotimer() {
    let mut rx = Rx::new(
        SETTIMER | STARTTIMER,
        100,
        0,
        vec![frame(0x42, 8, [0xff; 8])],
    );
    let f = frame(0x42, 1, [7, 0, 0, 0, 0, 0, 0, 0]);
    rx.run_until(150 * US);
    assert_eq!(rx.rec.timeouts, vec![100 * US]);
    rx.recv_at(200 * US, &f);
    rx.recv_at(400 * US, &f);
    rx.run_until(1000 * US);
    assert_eq!(rx.rec.changed.len(), 1);
    assert_eq!(rx.rec.timeouts, vec![100 * US, 300 * US, 500 * US]);

    let mut rx = Rx::new(
        SETTIMER | STARTTIMER | RX_NO_AUTOTIMER,
        100,
        0,
        vec![frame(0x42, 8, [0xff; 8])],
    );
    rx.recv_at(50 * US, &f); // cancels the timer and does not restart it
    rx.run_until(1000 * US);
    assert!(rx.rec.timeouts.is_empty());
}

#[test]
fn rx_filter_id_reports_every_frame() {
    let mut rx = Rx::new(RX_FILTER_ID, 0, 0, vec![]);
    let f = frame(0x42, 2, [1, 2, 0, 0, 0, 0, 0, 0]);
    for k in 0..5 {
        rx.recv_at(k * US, &f);
    }
    assert_eq!(rx.rec.changed.len(), 5);
    // Another identifier is not this operation's.
    rx.recv_at(10 * US, &frame(0x43, 2, [0; 8]));
    assert_eq!(rx.rec.changed.len(), 5);
}

#[test]
fn rx_rtr_reply() {
    let raw = MsgHead {
        opcode: RX_SETUP,
        flags: RX_RTR_FRAME,
        can_id: 0x42 | CAN_RTR_FLAG,
        nframes: 1,
        ..MsgHead::default()
    };
    let reply = rtr_reply_frame(
        &raw,
        widen(&frame(
            0x42 | CAN_RTR_FLAG,
            2,
            [0xab, 0xcd, 0, 0, 0, 0, 0, 0],
        )),
    );
    assert_eq!(reply.can_id, 0x42);
    let mut op = RxOp::new(&raw, 1);
    let mut rec = RxRec::default();
    let mut last = [RxSlot::default()];
    op.setup(&raw, 0, &mut last, &mut rec);
    op.frame_received(
        &AnyFrame::Classic(frame(0x42 | CAN_RTR_FLAG, 0, [0; 8])),
        1,
        0,
        0,
        &[reply],
        &mut last,
        &mut rec,
    );
    op.frame_received(
        &AnyFrame::Classic(frame(0x42, 0, [0; 8])),
        1,
        0,
        0,
        &[reply],
        &mut last,
        &mut rec,
    );
    assert_eq!(rec.replies, vec![reply]);
    assert!(rec.changed.is_empty());
    // On "any" interface there is nowhere to reply.
    let mut any = RxOp::new(&raw, 0);
    any.setup(&raw, 0, &mut last, &mut rec);
    any.frame_received(
        &AnyFrame::Classic(frame(0x42 | CAN_RTR_FLAG, 0, [0; 8])),
        1,
        0,
        0,
        &[reply],
        &mut last,
        &mut rec,
    );
    assert_eq!(rec.replies.len(), 1);
}

// ---- message format ---------------------------------------------------------

fn any_head() -> impl Strategy<Value = MsgHead> {
    (
        any::<u32>(),
        any::<u32>(),
        any::<u32>(),
        any::<[i64; 4]>(),
        any::<u32>(),
        any::<u32>(),
    )
        .prop_map(|(opcode, flags, count, iv, can_id, nframes)| MsgHead {
            opcode,
            flags,
            count,
            ival1: BcmTimeval {
                sec: iv[0],
                usec: iv[1],
            },
            ival2: BcmTimeval {
                sec: iv[2],
                usec: iv[3],
            },
            can_id,
            nframes,
        })
}

proptest! {
    #[test]
    fn head_round_trip(h in any_head()) {
        prop_assert_eq!(MsgHead::from_bytes(&h.to_bytes()), h);
    }

    #[test]
    fn message_round_trip(h in any_head(), n in 0usize..5) {
        let mut h = h;
        h.flags &= !CAN_FD_FRAME;
        h.opcode = TX_SETUP + h.opcode % 7;
        let frames: Vec<CanFrame> = (0..n).map(|i| frame(i as u32, i as u8, [i as u8; 8])).collect();
        let msg = message(&h, &frames);
        let req = parse(&msg).unwrap();
        prop_assert_eq!(req.head, h);
        for (i, f) in frames.iter().enumerate() {
            prop_assert_eq!(classic_frame(req.payload, i), Some(*f));
        }
        prop_assert_eq!(classic_frame(req.payload, n), None);
    }

    /// Any byte string parses or fails with an errno, never panics; so do
    /// the opcode checks on whatever parses.
    #[test]
    fn any_bytes(msg in prop::collection::vec(any::<u8>(), 0..400), ifindex in -1i32..3,
                 existing in prop::option::of(0u32..300)) {
        match parse(&msg) {
            Err(e) => prop_assert_eq!(e, EINVAL),
            Ok(req) => {
                for r in [check_tx_setup(&req, ifindex, existing), check_rx_setup(&req, existing),
                          check_tx_send(&req, ifindex)] {
                    if let Err(e) = r {
                        prop_assert!([EINVAL, EFAULT, E2BIG, ENODEV].contains(&e));
                    }
                }
            }
        }
    }
}

#[test]
fn errno_of_bad_messages() {
    let ok = tx_head(SETTIMER, 1, 0, 100, 1);
    let one = [frame(0x123, 2, [0; 8])];
    let req_of = |m: &Vec<u8>| parse(m).map(|r| (r.head, r.payload.len()));
    // Short head, partial frame, unknown and reply opcodes.
    assert_eq!(parse(&[0u8; MHSIZ - 1]), Err(EINVAL));
    let mut m = message(&ok, &one);
    m.push(0);
    assert_eq!(req_of(&m), Err(EINVAL));
    for op in [0, TX_STATUS, RX_CHANGED, 99] {
        assert_eq!(
            req_of(&message(&MsgHead { opcode: op, ..ok }, &one)),
            Err(EINVAL)
        );
    }
    // TX_SETUP: ENODEV first, then nframes, intervals, growth, missing and bad frames.
    let m = message(&ok, &one);
    let r = parse(&m).unwrap();
    assert_eq!(check_tx_setup(&r, 0, None), Err(ENODEV));
    assert_eq!(check_tx_setup(&r, 1, None), Ok(MHSIZ + 16));
    assert_eq!(check_tx_setup(&r, 1, Some(0)), Err(E2BIG));
    for n in [0, 257] {
        let m = message(&MsgHead { nframes: n, ..ok }, &one);
        assert_eq!(check_tx_setup(&parse(&m).unwrap(), 1, None), Err(EINVAL));
    }
    let m = message(&MsgHead { nframes: 2, ..ok }, &one);
    assert_eq!(check_tx_setup(&parse(&m).unwrap(), 1, None), Err(EFAULT));
    let m = message(&ok, &[frame(0x123, 9, [0; 8])]);
    assert_eq!(check_tx_setup(&parse(&m).unwrap(), 1, None), Err(EINVAL));
    for bad in [
        BcmTimeval { sec: -1, usec: 0 },
        BcmTimeval {
            sec: 0,
            usec: 1_000_000,
        },
        BcmTimeval {
            sec: BCM_TIMER_SEC_MAX + 1,
            usec: 0,
        },
    ] {
        let m = message(&MsgHead { ival2: bad, ..ok }, &one);
        assert_eq!(check_tx_setup(&parse(&m).unwrap(), 1, None), Err(EINVAL));
        // Without SETTIMER the intervals are not looked at.
        let m = message(
            &MsgHead {
                ival2: bad,
                flags: 0,
                ..ok
            },
            &one,
        );
        assert!(check_tx_setup(&parse(&m).unwrap(), 1, None).is_ok());
    }
    // TX_SEND: exactly one frame.
    let send = MsgHead {
        opcode: TX_SEND,
        ..ok
    };
    assert_eq!(
        check_tx_send(&parse(&message(&send, &one)).unwrap(), 1),
        Ok(MHSIZ + 16)
    );
    assert_eq!(
        check_tx_send(&parse(&message(&send, &one)).unwrap(), 0),
        Err(ENODEV)
    );
    assert_eq!(
        check_tx_send(&parse(&message(&send, &[one[0], one[0]])).unwrap(), 1),
        Err(EINVAL)
    );
    // RX_SETUP: FILTER_ID ignores frames; RTR needs one frame and the RTR flag.
    let rxh = MsgHead {
        opcode: RX_SETUP,
        flags: RX_FILTER_ID,
        nframes: 1,
        ..ok
    };
    assert_eq!(
        check_rx_setup(&parse(&message(&rxh, &one)).unwrap(), None),
        Ok(MHSIZ)
    );
    let rtr = MsgHead {
        opcode: RX_SETUP,
        flags: RX_RTR_FRAME,
        nframes: 1,
        can_id: 0x123,
        ..ok
    };
    assert_eq!(
        check_rx_setup(&parse(&message(&rtr, &one)).unwrap(), None),
        Err(EINVAL)
    );
    let rtr = MsgHead {
        can_id: 0x123 | CAN_RTR_FLAG,
        ..rtr
    };
    assert_eq!(
        check_rx_setup(&parse(&message(&rtr, &one)).unwrap(), None),
        Ok(MHSIZ + 16)
    );
    let mux = MsgHead {
        opcode: RX_SETUP,
        flags: 0,
        nframes: 258,
        ..ok
    };
    assert_eq!(
        check_rx_setup(&parse(&message(&mux, &[])).unwrap(), None),
        Err(EINVAL)
    );
    let mux = MsgHead {
        nframes: 257,
        ..mux
    };
    assert_eq!(
        check_rx_setup(&parse(&message(&mux, &[])).unwrap(), None),
        Err(EFAULT)
    );
    // CAN FD: 72-byte frames.
    let fd = MsgHead {
        flags: CAN_FD_FRAME,
        ..ok
    };
    assert_eq!(parse(&message(&fd, &one)).map(|_| ()), Err(EINVAL));
    let mut m = fd.to_bytes().to_vec();
    m.extend([0u8; 72]);
    assert_eq!(check_tx_setup(&parse(&m).unwrap(), 1, None), Ok(MHSIZ + 72));
}

// ---- CAN FD (CAN_FD_FRAME) ----------------------------------------------------

/// The CAN FD payload lengths (ISO 11898-1:2015).
const FD_LENS: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

fn small_fd_frame() -> impl Strategy<Value = CanFdFrame> {
    (
        prop::sample::select(&FD_LENS[..]),
        prop::collection::vec(0u8..3, 64),
    )
        .prop_map(|(len, d)| fd_frame(0x42, len, d.try_into().unwrap()))
}

proptest! {
    /// CAN FD change detection, stated byte by byte: after the first
    /// frame, RX_CHANGED iff some byte in the 8-byte words the received
    /// length reaches into (bytes 0 .. len rounded up to 8) differs from
    /// the last reported frame under the mask, or with RX_CHECK_DLC the
    /// length changed. The report carries all 64 bytes of the frame.
    #[test]
    fn rx_fd_changed_iff_masked_change(mask in prop::collection::vec(prop_oneof![Just(0u8), Just(0xffu8), any::<u8>()], 64),
                                       check_dlc in any::<bool>(),
                                       frames in prop::collection::vec(small_fd_frame(), 1..40)) {
        let flags = CAN_FD_FRAME | if check_dlc { RX_CHECK_DLC } else { 0 };
        let mask: [u8; 64] = mask.try_into().unwrap();
        let mut rx = Rx::new_any(flags, 0, 0, vec![fd_frame(0x42, 64, mask)]);
        let mut prev: Option<CanFdFrame> = None;
        let mut want = Vec::new();
        for (k, f) in frames.iter().enumerate() {
            let t = k as u64 * 10 * US;
            let reach = usize::from(f.len).div_ceil(8) * 8;
            let changed = match prev {
                None => true,
                Some(p) => (0..reach).any(|i| mask[i] & (f.data[i] ^ p.data[i]) != 0)
                    || (check_dlc && f.len != p.len),
            };
            if changed {
                want.push((t, *f));
                prev = Some(*f);
            }
            rx.recv_any_at(t, &AnyFrame::Fd(*f));
        }
        prop_assert_eq!(rx.rec.changed_fd, want);
    }

    /// An operation with CAN_FD_FRAME sees CAN FD frames only, one without
    /// it classic frames only, whatever their identifier and content.
    #[test]
    fn rx_kind_must_match(fd_op in any::<bool>(), filter_id in any::<bool>(),
                          frames in prop::collection::vec((any::<bool>(), small_fd_frame()), 1..30)) {
        let flags = if fd_op { CAN_FD_FRAME } else { 0 } | if filter_id { RX_FILTER_ID } else { 0 };
        let mut rx = Rx::new_any(flags, 0, 0, vec![fd_frame(0x42, 64, [0xff; 64])]);
        let mut want = 0;
        for (k, (is_fd, f)) in frames.iter().enumerate() {
            let any = if *is_fd {
                AnyFrame::Fd(*f)
            } else {
                let mut c = narrow(f);
                c.len = c.len.min(8);
                AnyFrame::Classic(c)
            };
            let before = rx.rec.changed_fd.len();
            rx.recv_any_at(k as u64 * US, &any);
            let got = rx.rec.changed_fd.len() - before;
            if *is_fd != fd_op {
                prop_assert_eq!(got, 0, "{:?} reported to an op with fd={}", any, fd_op);
            }
            want += got;
        }
        prop_assert_eq!(rx.rec.changed_fd.len(), want);
    }

    /// 72-byte frames round-trip through the message format and the
    /// frame accessor; a classic frame read as CAN FD has zero bytes past 8.
    #[test]
    fn fd_message_round_trip(h in any_head(), frames in prop::collection::vec(small_fd_frame(), 0..5)) {
        let mut h = h;
        h.flags |= CAN_FD_FRAME;
        h.opcode = TX_SETUP + h.opcode % 7;
        let mut m = vec![0u8; MHSIZ + frames.len() * 72];
        prop_assert_eq!(serialize_any(&h, &frames, &mut m), Some(m.len()));
        let req = parse(&m).unwrap();
        prop_assert_eq!(req.head, h);
        for (i, f) in frames.iter().enumerate() {
            prop_assert_eq!(frame_at(req.payload, 72, i), Some(*f));
            let c = frame_at(&req.payload[i * 72..i * 72 + 16], 16, 0).unwrap();
            prop_assert_eq!(&c.data[..8], &f.data[..8]);
            prop_assert!(c.data[8..].iter().all(|&b| b == 0));
        }
        prop_assert_eq!(frame_at(req.payload, 72, frames.len()), None);
    }
}

#[test]
fn fd_errno_of_bad_messages() {
    let fd = MsgHead {
        opcode: TX_SETUP,
        flags: SETTIMER | CAN_FD_FRAME,
        ival2: BcmTimeval::from_us(100),
        can_id: 0x123,
        nframes: 1,
        ..MsgHead::default()
    };
    let msg = |h: &MsgHead, len: u8| {
        let mut m = vec![0u8; MHSIZ + 72];
        serialize_any(h, &[fd_frame(h.can_id, len, [0; 64])], &mut m).unwrap();
        m
    };
    // len 64 is fine, 65 is EINVAL (TX_SETUP; and the RTR reply of RX_SETUP).
    assert_eq!(
        check_tx_setup(&parse(&msg(&fd, 64)).unwrap(), 1, None),
        Ok(MHSIZ + 72)
    );
    assert_eq!(
        check_tx_setup(&parse(&msg(&fd, 65)).unwrap(), 1, None),
        Err(EINVAL)
    );
    let rtr = MsgHead {
        opcode: RX_SETUP,
        flags: RX_RTR_FRAME | CAN_FD_FRAME,
        can_id: 0x123 | CAN_RTR_FLAG,
        ..fd
    };
    assert_eq!(
        check_rx_setup(&parse(&msg(&rtr, 64)).unwrap(), None),
        Ok(MHSIZ + 72)
    );
    assert_eq!(
        check_rx_setup(&parse(&msg(&rtr, 65)).unwrap(), None),
        Err(EINVAL)
    );
    // The size must be a whole number of 72-byte frames: a classic frame
    // (16 bytes) after an FD head is EINVAL, and so is an FD frame after
    // a classic head (72 is not a multiple of 16).
    let mut m = fd.to_bytes().to_vec();
    m.extend([0u8; 16]);
    assert_eq!(parse(&m).map(|_| ()), Err(EINVAL));
    let classic = MsgHead {
        flags: SETTIMER,
        ..fd
    };
    let mut m = classic.to_bytes().to_vec();
    m.extend([0u8; 72]);
    assert_eq!(parse(&m).map(|_| ()), Err(EINVAL));
    // TX_SEND of one FD frame.
    let send = MsgHead {
        opcode: TX_SEND,
        ..fd
    };
    assert_eq!(
        check_tx_send(&parse(&msg(&send, 64)).unwrap(), 1),
        Ok(MHSIZ + 72)
    );
    // An operation's name includes CAN_FD_FRAME.
    assert_ne!(OpKey::of(&fd, 1), OpKey::of(&classic, 1));
}
