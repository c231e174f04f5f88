// SPDX-License-Identifier: GPL-2.0
//! Properties of the ISO-TP core (`isotp`, `isotp_pci`, `isotp_tx`,
//! `isotp_rx`): a sender and a receiver with random link-layer and flow
//! control settings run against each other over a simulated bus in
//! virtual time, and
//!
//! - the PDU arrives intact, once, and the sender reports success;
//! - every frame on the wire is exactly the frame an independent model
//!   segmenter (below, written without the crate's helpers) predicts, so
//!   each is well formed (valid CAN/CAN FD length, N_PCI, sequence
//!   number, padding, address byte);
//! - flow control comes after the FF and after every BS consecutive
//!   frames, and consecutive frames keep STmin (plus N_As) apart;
//! - an early ("stale") timer callback never changes anything;
//! - a receiver with too small a buffer answers overflow (`EMSGSIZE`
//!   at the sender), and a frame lost on the bus ends both sides with
//!   `ECOMM` and at most `ETIMEDOUT`, never with a wrong PDU.

use proptest::prelude::*;
use rcan_core::isotp::*;
use rcan_core::isotp_pci::LlFrame;
use rcan_core::isotp_rx::{Rx, RxAction, RxEvent};
use rcan_core::isotp_tx::{Tx, TxAction, TxStep};

const US: u64 = 1_000;

// ---- the independent model ------------------------------------------------

/// Valid CAN FD data lengths above 8.
const FD_LENS: [usize; 7] = [12, 16, 20, 24, 32, 48, 64];

/// The model's settings of one side, kept apart from `Config`.
#[derive(Clone, Debug)]
struct Side {
    fd: bool,
    tx_dl: usize,
    ext: Option<u8>,
    rx_ext: Option<u8>,
    txpad: Option<u8>,
    bs: u8,
    stmin: u8,
}

/// Pads `f` as ISO 15765-2 (10.4.2) and mainline want: with padding on,
/// to 8 bytes or the next CAN FD length with `pad`; without, only a CAN
/// FD frame above 8 bytes, to the next CAN FD length with 0xCC.
fn model_pad(f: &mut Vec<u8>, pad: Option<u8>) {
    let want = if f.len() <= 8 {
        if pad.is_some() {
            8
        } else {
            f.len()
        }
    } else {
        *FD_LENS.iter().find(|&&l| l >= f.len()).unwrap()
    };
    let byte = pad.unwrap_or(0xCC);
    while f.len() < want {
        f.push(byte);
    }
}

/// The frames (payloads) a sender with settings `s` puts on the wire for
/// `pdu`: one SF, or FF and CFs, each padded.
fn model_frames(s: &Side, pdu: &[u8]) -> Vec<Vec<u8>> {
    let prefix: Vec<u8> = s.ext.into_iter().collect();
    let a = prefix.len();
    let classic_sf = 7 - a;
    let sf_room = if s.tx_dl == 8 {
        classic_sf
    } else {
        s.tx_dl - 2 - a
    };
    let mut out = Vec::new();
    if pdu.len() <= sf_room {
        let mut f = prefix.clone();
        if pdu.len() <= classic_sf {
            f.push(pdu.len() as u8);
        } else {
            f.push(0);
            f.push(pdu.len() as u8);
        }
        f.extend_from_slice(pdu);
        model_pad(&mut f, s.txpad);
        out.push(f);
        return out;
    }
    let mut f = prefix.clone();
    if pdu.len() < 4096 {
        f.push(0x10 + (pdu.len() / 256) as u8);
        f.push((pdu.len() % 256) as u8);
    } else {
        f.push(0x10);
        f.push(0);
        for shift in [24, 16, 8, 0] {
            f.push((pdu.len() >> shift) as u8);
        }
    }
    let first = s.tx_dl - f.len();
    f.extend_from_slice(&pdu[..first]);
    out.push(f);
    for (i, chunk) in pdu[first..].chunks(s.tx_dl - a - 1).enumerate() {
        let mut f = prefix.clone();
        f.push(0x20 + ((i + 1) % 16) as u8);
        f.extend_from_slice(chunk);
        model_pad(&mut f, s.txpad);
        out.push(f);
    }
    out
}

/// The flow control frame (continue) of a receiver with settings `s`.
fn model_fc(s: &Side) -> Vec<u8> {
    let mut f: Vec<u8> = s.ext.into_iter().collect();
    f.extend_from_slice(&[0x30, s.bs, s.stmin]);
    if let Some(p) = s.txpad {
        f.resize(8, p);
    }
    f
}

/// The model's STmin in ns (reserved values: 127 ms).
fn model_stmin(v: u8) -> u64 {
    match v {
        0..=0x7F => u64::from(v) * 1_000_000,
        0xF1..=0xF9 => u64::from(v & 0x0F) * 100_000,
        _ => 127_000_000,
    }
}

// ---- random settings ------------------------------------------------------

#[derive(Clone, Debug)]
struct Setup {
    a: Config,
    b: Config,
    ma: Side,
    mb: Side,
    /// Time a frame takes to reach the other side and to echo.
    wire: u64,
    /// The receiver's buffer.
    buflen: usize,
    /// Mainline's gap (model): frame_txtime plus STmin.
    gap: u64,
    /// The sender does not wait for flow control.
    cf_broadcast: bool,
    /// Wait frames the bus inserts before each FC continue.
    fc_waits: u8,
    /// STmin the bus puts into every FC continue but the first.
    later_stmin: Option<u8>,
    /// The gap expected after such a later FC: the first FC's unless the
    /// sender takes every FC's parameters and its STmin is not forced.
    later_gap: u64,
}

fn setup() -> impl Strategy<Value = Setup> {
    (
        (any::<bool>(), 0usize..8, any::<bool>(), any::<[u8; 2]>()),
        (any::<Option<u8>>(), any::<Option<u8>>(), 0u8..3, 0u8..3),
        (
            prop_oneof![Just(0u8), 1u8..4, Just(8), Just(255)],
            prop_oneof![
                Just(0u8),
                Just(1),
                Just(0x7F),
                0xF1u8..=0xF9,
                Just(0x80),
                Just(0xFF)
            ],
            prop_oneof![Just(0u32), 1u32..200_000],
            any::<bool>(),
            prop::option::of(0u32..3_000_000),
        ),
        (any::<[bool; 4]>(), 1u64..500, any::<bool>()),
        (
            prop_oneof![3 => Just(0u8), 1 => 1u8..4],
            prop::option::of(prop_oneof![Just(0u8), Just(2), 0xF1u8..=0xF9, Just(0x90)]),
        ),
    )
        .prop_map(
            |(
                (fd, dl, ext, addr),
                (apad, bpad, achk, bchk),
                (bs, stmin, txtime, dynfc, force),
                (hd, wire, cfb),
                (fc_waits, later_stmin),
            )| {
                let tx_dl = if fd {
                    [8, 12, 16, 20, 24, 32, 48, 64][dl]
                } else {
                    8
                };
                let mtu = if fd { LL_MTU_FD } else { LL_MTU_CLASSIC };
                let mut a = Config::default();
                let mut b = Config::default();
                for c in [&mut a, &mut b] {
                    c.ll = LlOptions {
                        mtu,
                        tx_dl,
                        tx_flags: u8::from(fd),
                    };
                    c.frame_txtime = 0;
                }
                a.frame_txtime = txtime;
                b.rxfc = FcOptions {
                    bs,
                    stmin,
                    wftmax: 0,
                };
                let mut fa = 0;
                let mut fb = 0;
                if ext {
                    fa |= CAN_ISOTP_EXTEND_ADDR | CAN_ISOTP_RX_EXT_ADDR;
                    fb |= CAN_ISOTP_EXTEND_ADDR | CAN_ISOTP_RX_EXT_ADDR;
                    a.opt.ext_address = addr[0];
                    a.opt.rx_ext_address = addr[1];
                    b.opt.ext_address = addr[1];
                    b.opt.rx_ext_address = addr[0];
                }
                // The padding byte is set even with padding off: it must
                // then not show up (CAN FD pads with 0xCC regardless).
                a.opt.txpad_content = apad.unwrap_or(addr[0] ^ 0x5A);
                b.opt.txpad_content = bpad.unwrap_or(addr[1] ^ 0xA5);
                if apad.is_some() {
                    fa |= CAN_ISOTP_TX_PADDING;
                }
                if bpad.is_some() {
                    fb |= CAN_ISOTP_TX_PADDING;
                }
                // Receive checks that the peer's padding satisfies.
                let chk = |mode: u8, peer_pad: Option<u8>, c: &mut Config| -> u32 {
                    match (mode, peer_pad) {
                        (1, None) => CAN_ISOTP_CHK_PAD_LEN,
                        (1, Some(p)) | (2, Some(p)) => {
                            c.opt.rxpad_content = p;
                            CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN | CAN_ISOTP_CHK_PAD_DATA
                        }
                        _ => 0,
                    }
                };
                // An FC is 3 bytes (+ address) or padded to 8: only the
                // padded form passes a length check with RX_PADDING, the
                // short one only the optimised-length check.
                fa |= chk(achk, bpad, &mut a);
                fb |= chk(bchk, apad, &mut b);
                if dynfc {
                    fa |= CAN_ISOTP_DYN_FC_PARMS;
                }
                if let Some(f) = force {
                    fa |= CAN_ISOTP_FORCE_TXSTMIN;
                    a.force_tx_stmin = f;
                }
                if hd[0] {
                    fa |= CAN_ISOTP_HALF_DUPLEX;
                }
                if hd[1] {
                    fb |= CAN_ISOTP_HALF_DUPLEX;
                }
                if cfb {
                    fa |= CAN_ISOTP_CF_BROADCAST;
                }
                a.opt.flags = fa;
                b.opt.flags = fb;
                let side = |c: &Config, pad: Option<u8>| Side {
                    fd,
                    tx_dl: usize::from(tx_dl),
                    ext: ext.then_some(c.opt.ext_address),
                    rx_ext: ext.then_some(c.opt.rx_ext_address),
                    txpad: pad,
                    bs: c.rxfc.bs,
                    stmin: c.rxfc.stmin,
                };
                // Mainline: without flow control the gap is the forced
                // STmin alone, else N_As; with it N_As plus STmin.
                let gap = match (cfb, force) {
                    (true, Some(f)) => u64::from(f),
                    (true, None) => u64::from(txtime),
                    (false, Some(f)) => u64::from(txtime) + u64::from(f),
                    (false, None) => u64::from(txtime) + model_stmin(stmin),
                };
                Setup {
                    ma: side(&a, apad),
                    mb: side(&b, bpad),
                    a,
                    b,
                    wire: wire * US,
                    buflen: usize::MAX,
                    gap,
                    cf_broadcast: cfb,
                    fc_waits,
                    later_stmin,
                    later_gap: match (later_stmin, dynfc && force.is_none()) {
                        (Some(l), true) => u64::from(txtime) + model_stmin(l),
                        _ => gap,
                    },
                }
            },
        )
}

/// PDU lengths: short ones around the single-frame limits, around the
/// 12-bit limit and its escape, and some longer.
fn pdu_len() -> impl Strategy<Value = usize> {
    prop_oneof![
        3 => 1usize..16,
        2 => 16usize..80,
        2 => 80usize..4090,
        1 => 4090usize..4100,
        1 => 4100usize..20_000,
    ]
}

// ---- the simulated bus ----------------------------------------------------

#[derive(Debug)]
struct Wire {
    /// Sender's frames: (send time, payload).
    a_sent: Vec<(u64, Vec<u8>)>,
    /// Receiver's frames (flow control): (send time, payload).
    b_sent: Vec<(u64, Vec<u8>)>,
    a_done: Option<Result<(), i32>>,
    b_events: Vec<RxEvent>,
    delivered: Option<Vec<u8>>,
    /// When each FC continue reached the sender.
    a_cts: Vec<u64>,
}

enum Ev {
    /// A's frame `k` reaches B.
    ToB(usize),
    /// A's frame `k` echoes back to A (if A asked for it).
    EchoA(usize),
    /// A frame from B (or inserted by the bus) reaches A.
    ToA(Vec<u8>),
}

/// Runs one transfer of `pdu` from A to B; `lose`: the index of a frame
/// (A's and B's counted together, in sending order) the bus loses;
/// `stale`: also call each armed timer once early. Both sides write their
/// frames into one buffer each, reused from frame to frame and never
/// cleared (the `_into` methods, as the module calls them), so a byte a
/// machine forgets to write shows up as a stale one.
fn run(s: &Setup, pdu: &[u8], lose: Option<usize>, stale: bool) -> Wire {
    let fd = s.a.ll.is_fd();
    let mut tx = Tx::new();
    let mut rx = Rx::new();
    let mut buf = vec![0u8; s.buflen.min(pdu.len() + 100)];
    let mut w = Wire {
        a_sent: vec![],
        b_sent: vec![],
        a_done: None,
        b_events: vec![],
        delivered: None,
        a_cts: vec![],
    };
    let ae = usize::from(s.ma.ext.is_some());
    let mut queue: Vec<(u64, u64, Ev)> = Vec::new();
    let mut seq = 0u64;
    let mut nframes = 0usize;
    let mut a_echo = vec![];
    let mut now = 0u64;
    let mut fa = LlFrame {
        len: 0,
        data: [0xA7; 64],
    };
    let mut fb = LlFrame {
        len: 0,
        data: [0x5B; 64],
    };
    // A classic frame's data as the module sends it: the bytes behind
    // `len` zeroed, whatever the buffer held.
    fn classic_ok(f: &LlFrame) {
        if f.len <= 8 {
            let d = f.classic_data();
            let n = usize::from(f.len);
            assert_eq!(&d[..n], f.payload());
            assert!(d[n..].iter().all(|&b| b == 0));
        }
    }

    // The effects of one step, common to both sides.
    macro_rules! a_step {
        ($st:expr) => {{
            let st: TxAction = $st;
            if st.frame {
                let f = fa;
                classic_ok(&f);
                let k = w.a_sent.len();
                w.a_sent.push((now, f.payload().to_vec()));
                a_echo.push(st.wants_echo);
                let lost = lose == Some(nframes);
                nframes += 1;
                if !lost {
                    queue.push((now + s.wire, seq, Ev::ToB(k)));
                    seq += 1;
                    queue.push((now + s.wire, seq, Ev::EchoA(k)));
                    seq += 1;
                }
            }
            if let Some(r) = st.done {
                assert!(w.a_done.is_none(), "two results");
                w.a_done = Some(r);
            }
            assert_eq!(
                tx.deadline(),
                match st.timer {
                    TimerCmd::Arm(at) => Some(at),
                    TimerCmd::Cancel => None,
                    TimerCmd::Keep => tx.deadline(),
                }
            );
        }};
    }
    macro_rules! b_step {
        ($st:expr) => {{
            let st: RxAction = $st;
            if st.frame {
                let f = fb;
                classic_ok(&f);
                let k = w.b_sent.len();
                w.b_sent.push((now, f.payload().to_vec()));
                let lost = lose == Some(nframes);
                nframes += 1;
                if !lost {
                    let mut fc = f.payload().to_vec();
                    let mut at = now + s.wire;
                    if fc[ae] == 0x30 {
                        // Wait frames first (as another ECU may send),
                        // and a later FC with another STmin.
                        for _ in 0..s.fc_waits {
                            let mut wt = fc.clone();
                            wt[ae] = 0x31;
                            queue.push((at, seq, Ev::ToA(wt)));
                            seq += 1;
                            at += 10 * US;
                        }
                        if let Some(l) = s.later_stmin.filter(|_| k > 0) {
                            fc[ae + 2] = l;
                        }
                    }
                    queue.push((at, seq, Ev::ToA(fc)));
                    seq += 1;
                }
            }
            match st.event {
                Some(RxEvent::Deliver(n)) => {
                    assert!(w.delivered.is_none(), "delivered twice");
                    w.delivered = Some(buf[..n].to_vec());
                    w.b_events.push(RxEvent::Deliver(n));
                }
                Some(e) => w.b_events.push(e),
                None => {}
            }
        }};
    }

    a_step!(tx.start_into(&s.a, pdu, 0, &mut fa).unwrap());
    for _ in 0..1_000_000 {
        // The next thing to happen: a frame or a timer.
        let next_q = queue.iter().map(|e| (e.0, e.1)).min();
        let ta = tx.deadline();
        let tb = rx.deadline();
        let t = [next_q.map(|q| q.0), ta, tb].into_iter().flatten().min();
        let Some(t) = t else { break };
        if stale {
            // An early callback of either timer changes nothing.
            if let Some(d) = ta.filter(|&d| d > now + 1) {
                let before = tx;
                assert_eq!(
                    tx.on_timer(&s.a, pdu, (now + d) / 2),
                    TxStep {
                        frame: None,
                        wants_echo: false,
                        timer: TimerCmd::Keep,
                        done: None
                    }
                );
                assert_eq!(tx, before);
            }
            if let Some(d) = tb.filter(|&d| d > now + 1) {
                let before = rx;
                assert_eq!(rx.on_timer((now + d) / 2).event, None);
                assert_eq!(rx, before);
            }
        }
        assert!(t >= now, "time went back");
        now = t;
        if ta == Some(t) {
            a_step!(tx.on_timer_into(&s.a, pdu, now, &mut fa));
            continue;
        }
        if tb == Some(t) {
            let st = rx.on_timer(now);
            assert_eq!(st.frame, None);
            b_step!(RxAction {
                frame: false,
                timer: st.timer,
                event: st.event
            });
            continue;
        }
        let i = queue
            .iter()
            .position(|e| Some((e.0, e.1)) == next_q)
            .unwrap();
        let (_, _, ev) = queue.swap_remove(i);
        match ev {
            Ev::ToB(k) => {
                let data = w.a_sent[k].1.clone();
                match route(&s.b, fd, &data, true, rx.is_idle()) {
                    Route::Rx => b_step!(rx.on_frame_into(&s.b, &data, &mut buf, now, &mut fb)),
                    Route::Tx => panic!("receiver got an FC"),
                    Route::Drop => panic!("receiver dropped {data:x?}"),
                }
            }
            Ev::EchoA(k) => {
                // Every frame of A comes back to it, as in the module; the
                // machine takes only the echo it waits for.
                let echo = w.a_sent[k].1.clone();
                let before = tx;
                let a = tx.on_own_frame_into(&s.a, &echo, pdu, now, &mut fa);
                if !a_echo[k] {
                    assert_eq!(tx, before, "an echo not asked for moved the sender");
                }
                a_step!(a);
            }
            Ev::ToA(data) => {
                if s.cf_broadcast {
                    // Mainline does not even listen on rx_id then.
                    continue;
                }
                if data[ae] == 0x30 {
                    w.a_cts.push(now);
                }
                match route(&s.a, fd, &data, tx.is_idle(), true) {
                    Route::Tx => a_step!(tx.on_fc_into(&s.a, &data, pdu, now, &mut fa)),
                    r => panic!("sender routed an FC to {r:?}"),
                }
            }
        }
    }
    assert!(queue.is_empty(), "the bus never went quiet");
    assert!(tx.is_idle() && rx.is_idle(), "a side stayed busy");
    assert_eq!(
        (tx.deadline(), rx.deadline()),
        (None, None),
        "a timer left armed"
    );
    w
}

/// Valid payload length of a frame on this link layer.
fn valid_len(fd: bool, n: usize) -> bool {
    n <= 8 || (fd && FD_LENS.contains(&n))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// A PDU arrives intact, every frame is the model's, flow control and
    /// STmin are kept.
    #[test]
    fn transfer_matches_model(s in setup(), len in pdu_len(), seed in any::<u64>(), stale in any::<bool>()) {
        let pdu: Vec<u8> = (0..len).map(|i| (i as u64).wrapping_mul(seed | 1).rotate_left(13) as u8).collect();
        let w = run(&s, &pdu, None, stale);
        prop_assert_eq!(w.a_done, Some(Ok(())));
        prop_assert_eq!(&w.b_events, &vec![RxEvent::Deliver(len)]);
        prop_assert!(w.delivered.as_deref() == Some(&pdu[..]), "PDU corrupted");

        let want = model_frames(&s.ma, &pdu);
        let got: Vec<Vec<u8>> = w.a_sent.iter().map(|(_, f)| f.clone()).collect();
        prop_assert_eq!(&got, &want);
        for f in got.iter().chain(w.b_sent.iter().map(|(_, f)| f)) {
            prop_assert!(valid_len(s.ma.fd, f.len()), "bad length {}", f.len());
            prop_assert!(f.len() <= s.ma.tx_dl.max(8));
        }
        if let Some(x) = s.ma.ext {
            prop_assert!(got.iter().all(|f| f[0] == x && Some(x) == s.mb.rx_ext));
        }

        // Flow control: after the FF and after every BS-th CF, unless the
        // PDU is complete; always the receiver's configured frame.
        let ncf = want.len() - 1;
        let fcs = if ncf == 0 {
            0
        } else if s.mb.bs == 0 {
            1
        } else {
            1 + (ncf - 1) / usize::from(s.mb.bs)
        };
        prop_assert_eq!(w.b_sent.len(), fcs);
        for (_, f) in &w.b_sent {
            prop_assert_eq!(f, &model_fc(&s.mb));
        }

        // CF spacing: within a block, the next CF leaves one wire time
        // (its predecessor's echo) plus the gap after the previous one;
        // the first CF of a block leaves when the FC continue arrives
        // (after the wait frames). The gap is the first FC's, or the
        // latest FC's with dynamic parameters.
        if !s.cf_broadcast {
            prop_assert_eq!(w.a_cts.len(), w.b_sent.len());
        }
        for k in 2..w.a_sent.len() {
            let (t0, t1) = (w.a_sent[k - 1].0, w.a_sent[k].0);
            if s.cf_broadcast || !w.a_cts.contains(&t1) {
                let fcs_before = w.a_cts.iter().filter(|&&t| t <= t0).count();
                let gap = if fcs_before >= 2 { s.later_gap } else { s.gap };
                prop_assert_eq!(t1 - t0, s.wire + gap, "CF {} spacing", k);
            }
        }
        if s.cf_broadcast && want.len() > 1 {
            prop_assert_eq!(w.a_sent[1].0, s.wire + s.gap);
        }
    }

    /// A receiver whose buffer is too small answers overflow: the sender
    /// fails with EMSGSIZE, nothing is delivered.
    #[test]
    fn overflow_is_emsgsize(mut s in setup(), len in 70usize..9000, short in 1usize..60) {
        prop_assume!(!s.cf_broadcast);
        s.buflen = len - short;
        let pdu = vec![0x5A; len];
        let w = run(&s, &pdu, None, false);
        prop_assert_eq!(w.a_done, Some(Err(EMSGSIZE)));
        prop_assert!(w.delivered.is_none());
        prop_assert_eq!(w.b_sent.len(), 1);
        prop_assert_eq!(w.b_sent[0].1[s.ma.ext.map_or(0, |_| 1)], 0x32);
    }

    /// One frame lost on the bus: the sender fails with ECOMM (no echo, or
    /// no FC), the receiver at most times out, no wrong PDU arrives.
    #[test]
    fn lost_frame_fails_cleanly(s in setup(), len in 1usize..300, at in 0usize..40) {
        // A broadcasting sender ignores flow control, so a lost FC is no
        // failure there.
        prop_assume!(!s.cf_broadcast);
        let pdu: Vec<u8> = (0..len).map(|i| i as u8).collect();
        let frames = {
            let w = run(&s, &pdu, None, false);
            w.a_sent.len() + w.b_sent.len()
        };
        let lose = at % frames;
        let w = run(&s, &pdu, Some(lose), false);
        prop_assert_eq!(w.a_done, Some(Err(ECOMM)));
        prop_assert!(w.delivered.is_none());
        for e in &w.b_events {
            prop_assert!(matches!(e, RxEvent::Error(ETIMEDOUT) | RxEvent::Error(EILSEQ)), "{:?}", e);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// The receiver alone, fed the model's frames: the PDU arrives; with
    /// one consecutive frame's sequence number changed (to any other
    /// value) it reports EILSEQ there and delivers nothing.
    #[test]
    fn receiver_takes_model_frames(
        s in setup(),
        len in pdu_len(),
        bad in prop::option::of((any::<prop::sample::Index>(), 1u8..16)),
    ) {
        let pdu: Vec<u8> = (0..len).map(|i| (i * 7 + 3) as u8).collect();
        let mut frames = model_frames(&s.ma, &pdu);
        let a = usize::from(s.ma.ext.is_some());
        let bad = bad.filter(|_| frames.len() > 1).map(|(i, d)| {
            let k = 1 + i.index(frames.len() - 1);
            frames[k][a] = 0x20 | ((frames[k][a] + d) & 0x0F);
            k
        });
        let mut rx = Rx::new();
        let mut buf = vec![0u8; len];
        let mut events = vec![];
        for (k, f) in frames.iter().enumerate() {
            prop_assert_eq!(route(&s.b, s.ma.fd, f, true, rx.is_idle()), Route::Rx);
            let st = rx.on_frame(&s.b, f, &mut buf, k as u64 * 1000);
            if let Some(e) = st.event {
                events.push((k, e));
            }
        }
        match bad {
            Some(k) => prop_assert_eq!(events, vec![(k, RxEvent::Error(EILSEQ))]),
            None => {
                prop_assert_eq!(events, vec![(frames.len() - 1, RxEvent::Deliver(len))]);
                prop_assert!(buf == pdu);
            }
        }
    }
}

/// The model itself, on hand-checked cases, so that a model bug cannot
/// hide a state machine bug of the same shape.
#[test]
fn model_sanity() {
    let s = Side {
        fd: false,
        tx_dl: 8,
        ext: None,
        rx_ext: None,
        txpad: None,
        bs: 0,
        stmin: 0,
    };
    assert_eq!(model_frames(&s, &[1, 2]), vec![vec![0x02, 1, 2]]);
    let f = model_frames(&s, &[9; 20]);
    assert_eq!(f[0], vec![0x10, 20, 9, 9, 9, 9, 9, 9]);
    assert_eq!(f[2], vec![0x22, 9, 9, 9, 9, 9, 9, 9]);
    assert_eq!(f.len(), 3);
    let s = Side {
        fd: true,
        tx_dl: 64,
        ext: Some(0xAB),
        txpad: Some(0x55),
        ..s
    };
    let f = model_frames(&s, &[1; 10]);
    assert_eq!(f[0].len(), 16);
    assert_eq!(&f[0][..3], &[0xAB, 0x00, 10]);
    assert_eq!(&f[0][13..], &[0x55; 3]);
    let f = model_frames(&s, &[1; 5000]);
    assert_eq!(&f[0][..7], &[0xAB, 0x10, 0, 0, 0, 0x13, 0x88]);
    assert_eq!(model_fc(&s), vec![0xAB, 0x30, 0, 0, 0x55, 0x55, 0x55, 0x55]);
}

/// A wait frame from the receiver (which mainline never sends, but
/// other ECUs do) delays the sender by up to N_Bs each time; any
/// number is accepted.
#[test]
fn wait_frames_extend_the_wait() {
    let c = Config::default();
    let pdu = [3u8; 20];
    let mut tx = Tx::new();
    tx.start(&c, &pdu, 0).unwrap();
    let mut now = 0;
    for _ in 0..100 {
        now += FC_TIMEOUT_NS - 1;
        assert_eq!(tx.on_timer(&c, &pdu, now).done, None);
        let st = tx.on_fc(&c, &[0x31, 0, 0], &pdu, now);
        assert_eq!(st.timer, TimerCmd::Arm(now + FC_TIMEOUT_NS));
    }
    let st = tx.on_fc(&c, &[0x30, 0, 0], &pdu, now);
    assert!(st.frame.is_some());
}
