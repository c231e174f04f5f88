// SPDX-License-Identifier: GPL-2.0
//! Properties of the J1939 core (`j1939`, `j1939_ac`, `j1939_tp`):
//!
//! - identifiers: any extended `can_id` with a source other than 0xFF
//!   maps to (priority, PGN, source, destination) and back unchanged,
//!   and any addressing maps to an identifier and back as mainline
//!   normalises it;
//! - filters: the parsed image is the masked filter, and matching is
//!   "every masked field equal", checked against a model;
//! - the address claim table keeps one holder per address, the lowest
//!   NAME of the claims it saw, and never maps inside the claim window;
//!   settled lazily it answers as with a timer at every deadline;
//! - a sender and a receiver connected back to back over a simulated bus
//!   in virtual time transfer any message of 9..=N bytes exactly, by TP,
//!   BAM or ETP, with random block limits and packet delays, and every
//!   frame on the wire is well formed;
//! - with one frame lost on the bus both sides end, with the reason the
//!   lost frame's type predicts, and a delivered message is never wrong.

use proptest::prelude::*;
use rcan_core::arb::CAN_EFF_FLAG;
use rcan_core::j1939::*;
use rcan_core::j1939_ac::{AcTable, ClaimResult, AC_WINDOW_NS};
use rcan_core::j1939_tp::*;
use rcan_core::j1939_tp_rx::RxSession;
use rcan_core::j1939_tp_tx::TxSession;

const SA: u8 = 0x80;
const DA: u8 = 0x20;
const PGN: u32 = 0x1_2300;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn can_id_round_trip(id in 0u32..0x2000_0000) {
        let can_id = CAN_EFF_FLAG | id;
        match Id::from_can_id(can_id) {
            None => prop_assert_eq!(id & 0xFF, 0xFF),
            Some(a) => {
                prop_assert_eq!(a.to_can_id(), can_id);
                prop_assert!(a.prio <= 7 && pgn_is_valid(a.pgn) && pgn_is_clean_pdu(a.pgn));
            }
        }
    }

    #[test]
    fn addressing_round_trip(prio in 0u8..8, pgn in 0u32..0x4_0000, sa in 0u8..0xFF, da: u8) {
        let a = Id { prio, pgn, sa, da };
        let back = Id::from_can_id(a.to_can_id()).unwrap();
        let pdu1 = pgn_is_pdu1(pgn);
        prop_assert_eq!(back.prio, prio);
        prop_assert_eq!(back.sa, sa);
        prop_assert_eq!(back.pgn, if pdu1 { pgn & 0x3_FF00 } else { pgn });
        prop_assert_eq!(back.da, if pdu1 { da } else { J1939_NO_ADDR });
    }

    #[test]
    fn filters_match_their_model(img: [u8; 32], pgn in 0u32..0x4_0000, sa: u8, name: u64) {
        let f = Filter::from_bytes(&img);
        let raw_name = u64::from_ne_bytes(img[0..8].try_into().unwrap());
        let name_mask = u64::from_ne_bytes(img[8..16].try_into().unwrap());
        let raw_pgn = u32::from_ne_bytes(img[16..20].try_into().unwrap());
        let pgn_mask = u32::from_ne_bytes(img[20..24].try_into().unwrap());
        let (raw_addr, addr_mask) = (img[24], img[25]);
        let model = (pgn & pgn_mask) == (raw_pgn & pgn_mask)
            && (sa & addr_mask) == (raw_addr & addr_mask)
            && (name & name_mask) == (raw_name & name_mask);
        prop_assert_eq!(f.matches(pgn, sa, name), model);
        prop_assert_eq!(Filter::from_bytes(&f.to_bytes()), f);
        // A filter always matches what it names.
        prop_assert!(f.matches(f.pgn, f.addr, f.name));
    }

    #[test]
    fn claim_table_stays_consistent(
        claims in prop::collection::vec((1u64..12, 0u8..6, 0u64..400), 1..60)
    ) {
        // Few NAMEs and addresses (0..4, 0xFE, 0xFF), so that they contend.
        let mut t = AcTable::new();
        let mut now = 0u64;
        // The last pending claim of each NAME: (address, valid from).
        let mut pending = std::collections::BTreeMap::new();
        for (name, a, dt) in claims {
            now += dt * 1_000_000;
            t.on_timer(now);
            // Never usable inside its window.
            for (&n, &(addr, at)) in &pending {
                if now < at {
                    prop_assert_ne!(t.addr_to_name(addr), n);
                }
            }
            let sa = match a { 4 => 0xFE, 5 => 0xFF, x => x };
            let r = t.on_claim(sa, &name.to_le_bytes(), now);
            pending.remove(&name);
            if let ClaimResult::Pending(at) = r {
                pending.insert(name, (sa, at));
                prop_assert_eq!(at, now + AC_WINDOW_NS);
                // Nobody holds it while the claim is pending.
                prop_assert_eq!(t.addr_to_name(sa), 0);
                prop_assert_eq!(t.name_to_addr(name), J1939_IDLE_ADDR);
            }
            // One holder per address, and a NAME holds at most one.
            for addr in 0..4u8 {
                let n = t.addr_to_name(addr);
                if n != 0 {
                    prop_assert_eq!(t.name_to_addr(n), addr);
                }
            }
            if let Some(d) = t.next_deadline() {
                prop_assert!(d > now);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// A table settled lazily (`settle` before each claim and question,
    /// as the module does without a timer) answers as one whose timer
    /// fires at every step (`on_timer`), whatever claims come when.
    #[test]
    fn settling_lazily_answers_as_a_timer_does(
        claims in prop::collection::vec((1u64..12, 0u8..6, 0u64..400), 1..60)
    ) {
        let mut timed = AcTable::new();
        let mut lazy = AcTable::new();
        let mut now = 0u64;
        for (name, a, dt) in claims {
            now += dt * 1_000_000;
            timed.on_timer(now);
            lazy.settle(now);
            for addr in 0..4u8 {
                prop_assert_eq!(timed.addr_to_name(addr), lazy.addr_to_name(addr));
            }
            for n in 1..12u64 {
                prop_assert_eq!(timed.name_to_addr(n), lazy.name_to_addr(n));
            }
            let sa = match a { 4 => 0xFE, 5 => 0xFF, x => x };
            let r = timed.on_claim(sa, &name.to_le_bytes(), now);
            prop_assert_eq!(lazy.on_claim(sa, &name.to_le_bytes(), now), r);
        }
    }

    /// Distinct NAMEs, each claiming one of 4 addresses once, in any
    /// order and at any times: once every window has passed, each
    /// address is held by the lowest NAME that claimed it (J1939-81's
    /// priority rule; mainline would keep whichever of two overlapping
    /// claims had its timer expire first).
    #[test]
    fn lowest_name_holds_each_address(
        claims in prop::collection::btree_map(1u64..1000, (0u8..4, 0u64..600), 1..12)
    ) {
        let mut order: Vec<(u64, u64, u8)> =
            claims.iter().map(|(&n, &(a, t))| (t * 1_000_000, n, a)).collect();
        order.sort();
        let mut t = AcTable::new();
        for &(at, name, a) in &order {
            t.on_timer(at);
            t.on_claim(a, &name.to_le_bytes(), at);
        }
        t.on_timer(u64::MAX);
        for a in 0..4u8 {
            let want = claims.iter().filter(|(_, &(x, _))| x == a).map(|(&n, _)| n).min();
            prop_assert_eq!(t.addr_to_name(a), want.unwrap_or(0), "address {}", a);
        }
    }
}

// ---- two machines over a simulated bus -------------------------------------

/// How the transfer ended on each side.
#[derive(Debug, Default)]
struct End {
    tx: Option<Outcome>,
    rx: Option<Outcome>,
    /// The receiver never started (its RTS or BAM was lost).
    rx_started: bool,
    wire: Vec<Frame>,
}

fn is_dat(f: &Frame) -> bool {
    f.id.pgn == TP_PGN_DAT || f.id.pgn == ETP_PGN_DAT
}

/// The checks every frame on the wire passes.
fn check_frame(f: &Frame, from_tx: bool) {
    assert_eq!(f.len, 8, "{f:?}");
    assert!(matches!(
        f.id.pgn,
        TP_PGN_CTL | TP_PGN_DAT | ETP_PGN_CTL | ETP_PGN_DAT
    ));
    let (sa, da) = if from_tx {
        (SA, f.id.da)
    } else {
        (f.id.sa, SA)
    };
    assert_eq!(f.id.sa, sa);
    assert_eq!(f.id.da, da);
    if !is_dat(f) && f.data[0] != 0xFF {
        assert_eq!(f.data[5..], PGN.to_le_bytes()[..3], "{f:?}");
    }
}

/// Runs `data` from SA to `da` with the given parameters, losing the
/// frame number `lose` (counted over the wire) if any; the echo of a lost
/// frame still reaches its sender (it was sent; the peer missed it).
fn transfer(data: &[u8], da: u8, p: &Params, lose: Option<usize>) -> End {
    let id = Id {
        prio: 6,
        pgn: PGN,
        sa: SA,
        da,
    };
    let mut now = 0u64;
    let (mut tx, s) = TxSession::start(p, id, data, now).unwrap();
    let mut rx: Option<RxSession> = None;
    let mut buf = vec![0u8; data.len()];
    let mut end = End::default();
    // Frames in flight: (frame, from the sender).
    let mut bus: std::collections::VecDeque<(Frame, bool)> = Default::default();
    let mut tx_step = Some(s);
    let mut rx_step: Option<Step> = None;
    for _ in 0..20_000_000 {
        // Collect what the last steps produced.
        if let Some(s) = tx_step.take() {
            if let TimerCmd::Arm(at) = s.timer {
                assert!(at >= now);
            }
            if let Some(f) = s.frame {
                check_frame(&f, true);
                bus.push_back((f, true));
            }
            if let Some(o) = s.done {
                assert!(end.tx.is_none());
                assert!(tx.is_done());
                end.tx = Some(o);
            }
        }
        if let Some(s) = rx_step.take() {
            if let Some(f) = s.frame {
                check_frame(&f, false);
                bus.push_back((f, false));
            }
            if let Some(o) = s.done {
                assert!(end.rx.is_none());
                if let Outcome::Delivered(n) = o {
                    assert_eq!(n, data.len());
                    assert_eq!(buf, data, "delivered a wrong message");
                }
                end.rx = Some(o);
            }
        }
        if let Some((f, from_tx)) = bus.pop_front() {
            let k = end.wire.len();
            end.wire.push(f);
            let lost = lose == Some(k);
            if from_tx {
                if is_dat(&f) {
                    tx_step = Some(tx.on_echo(&f.data, now));
                }
                if lost {
                    continue;
                }
                let Some(Msg::Ctl { cmd, data: d, .. }) = classify(&f.id, &f.data) else {
                    if let Some(r) = rx.as_mut() {
                        rx_step = Some(r.on_dat(&f.data, &mut buf, now));
                    }
                    continue;
                };
                match rx.as_mut() {
                    Some(r) => rx_step = Some(r.on_ctl(&d, now)),
                    None if cmd == TP_CMD_RTS || cmd == ETP_CMD_RTS || cmd == TP_CMD_BAM => {
                        let (r, s) = RxSession::on_rts(p, f.id, &d, buf.len(), now)
                            .expect("a valid RTS is accepted");
                        assert_eq!(s.notify, Some(Notify::RxRts));
                        end.rx_started = true;
                        rx = Some(r);
                        rx_step = Some(s);
                    }
                    None => {}
                }
            } else if !lost {
                if let Some(Msg::Ctl { data: d, .. }) = classify(&f.id, &f.data) {
                    assert!(tx_step.is_none());
                    tx_step = Some(tx.on_ctl(&d, data, now));
                }
            }
            continue;
        }
        // Quiet bus: the earliest timer fires.
        let rx_live = rx.as_ref().filter(|r| !r.is_done());
        let next = [
            tx.deadline().filter(|_| !tx.is_done()),
            rx_live.and_then(|r| r.deadline()),
        ]
        .into_iter()
        .flatten()
        .min();
        let Some(at) = next else { break };
        assert!(at >= now, "timer in the past");
        now = at;
        if tx.deadline().is_some_and(|d| d <= now) && !tx.is_done() {
            tx_step = Some(tx.on_timer(data, now));
        } else if let Some(r) = rx.as_mut() {
            rx_step = Some(r.on_timer(now));
        }
    }
    assert!(tx.is_done(), "sender still running");
    assert!(
        rx.as_ref().is_none_or(|r| r.is_done()),
        "receiver still running"
    );
    end
}

fn message(n: usize, seed: u8) -> Vec<u8> {
    (0..n)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed))
        .collect()
}

fn params() -> impl Strategy<Value = Params> {
    (
        1u8..=255,
        prop_oneof![3 => Just(0u64), 1 => 0u64..3_000_000],
    )
        .prop_map(|(block, d)| Params {
            block,
            packet_delay_ns: d,
            max_size: MAX_ETP_SIZE,
        })
}

const EH: Option<Outcome> = Some(Outcome::Aborted {
    errno: EHOSTUNREACH,
    reason: Some(abort::TIMEOUT),
});

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn back_to_back_tp_and_etp(n in 9usize..4000, seed: u8, p in params()) {
        let data = message(n, seed);
        let end = transfer(&data, DA, &p, None);
        prop_assert_eq!(end.tx, Some(Outcome::Sent));
        prop_assert_eq!(end.rx, Some(Outcome::Delivered(n)));
        let dts: Vec<&Frame> = end.wire.iter().filter(|f| is_dat(f)).collect();
        prop_assert_eq!(dts.len(), n.div_ceil(7));
        // Windows never exceed the receiver's block.
        for f in end.wire.iter().filter(|f| !is_dat(f) && (f.data[0] == TP_CMD_CTS || f.data[0] == ETP_CMD_CTS)) {
            prop_assert!(f.data[1] >= 1 && f.data[1] <= p.block);
        }
    }

    #[test]
    fn back_to_back_bam(n in 9usize..=1785, seed: u8) {
        let data = message(n, seed);
        let end = transfer(&data, J1939_NO_ADDR, &Params::default(), None);
        prop_assert_eq!(end.tx, Some(Outcome::Sent));
        prop_assert_eq!(end.rx, Some(Outcome::Delivered(n)));
    }

    #[test]
    fn one_lost_frame(n in 9usize..2500, seed: u8, p in params(), which: prop::sample::Index, bam: bool) {
        let data = message(n, seed);
        let da = if bam && n <= MAX_TP_SIZE { J1939_NO_ADDR } else { DA };
        let clean = transfer(&data, da, &p, None);
        let k = which.index(clean.wire.len());
        let lost = clean.wire[k];
        let end = transfer(&data, da, &p, Some(k));
        let cmd = lost.data[0];
        if da == J1939_NO_ADDR {
            // The sender never knows.
            prop_assert_eq!(end.tx, Some(Outcome::Sent));
            if cmd == TP_CMD_BAM && !is_dat(&lost) {
                prop_assert!(!end.rx_started && end.rx.is_none());
            } else {
                prop_assert_eq!(end.rx, EH);
            }
        } else if is_dat(&lost) {
            // The receiver times out (T1 < T3) and aborts; the sender
            // gets the abort.
            prop_assert_eq!(end.rx, EH);
            prop_assert_eq!(end.tx, EH);
        } else {
            match cmd {
                TP_CMD_RTS | ETP_CMD_RTS => {
                    prop_assert!(!end.rx_started);
                    prop_assert_eq!(end.tx, EH);
                }
                TP_CMD_CTS | ETP_CMD_CTS => {
                    // T3 (after RTS or the last window) ends the sender
                    // first; its abort ends the receiver.
                    prop_assert_eq!(end.tx, EH);
                    prop_assert_eq!(end.rx, EH);
                }
                ETP_CMD_DPO => {
                    let fault = Some(Outcome::Aborted {
                        errno: ENOTRECOVERABLE,
                        reason: Some(abort::FAULT),
                    });
                    prop_assert_eq!(end.rx, fault);
                    prop_assert_eq!(end.tx, fault);
                }
                TP_CMD_EOMA | ETP_CMD_EOMA => {
                    prop_assert_eq!(end.rx, Some(Outcome::Delivered(n)));
                    prop_assert_eq!(end.tx, EH);
                }
                c => prop_assert!(false, "lost an unexpected frame {:#x}", c),
            }
        }
    }
}

#[test]
fn largest_tp_and_smallest_etp_with_every_block() {
    for block in [1u8, 2, 7, 254, 255] {
        for n in [1785usize, 1786] {
            let p = Params {
                block,
                ..Params::default()
            };
            let end = transfer(&message(n, block), DA, &p, None);
            assert_eq!(end.rx, Some(Outcome::Delivered(n)), "block {block} n {n}");
        }
    }
}

/// About 150,000 data packets in windows of 255: DPO offsets beyond 16
/// bits.
#[test]
fn one_mebibyte_by_etp() {
    let n = 1 << 20;
    let end = transfer(&message(n, 1), DA, &Params::default(), None);
    assert_eq!(end.rx, Some(Outcome::Delivered(n)));
}
