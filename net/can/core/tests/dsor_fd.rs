// SPDX-License-Identifier: GPL-2.0
//! Tests of the DSOR CAN FD bodies extension (`rcan_core::dsor_fd`,
//! `Documentation/networking/rcan/dsor-wire.rst`, "Message transfer with
//! CAN FD bodies (extension)"):
//!
//! * the worked example of the document, frame by frame;
//! * segmentation into bodies of every size and reassembly is the
//!   identity for every length 0..=2000 and random lengths up to 65535,
//!   every body has a valid CAN FD length, padding is zero and ignored;
//! * body size 8 gives exactly the classic sender's frames
//!   (`Transfer::frame`);
//! * the FD header and its ack: round trips and malformed forms.

use proptest::prelude::*;
use rcan_core::dsor_fd::*;
use rcan_core::dsor_tx::Transfer;
use rcan_core::dsor_wire::{AckStatus, DsorId, Frame, FrameType, Header, MsgKind, Timers};

fn msg_of(len: usize, seed: u8) -> Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed) ^ (i >> 8) as u8)
        .collect()
}

fn id(q: bool) -> DsorId {
    DsorId {
        prio: 0x40,
        dst: 0,
        src: 5,
        ftype: FrameType::Body,
        seq: q,
        chan: 0,
    }
}

/// Segment `msg` with body size `b` and reassemble it through
/// `store_body`, checking every frame on the way; returns the result.
fn round_trip(msg: &[u8], b: BodySize) -> Vec<u8> {
    let len = msg.len() as u16;
    let n = body_count(len, b);
    assert_eq!(n as usize, msg.len().div_ceil(b.get() as usize));
    let mut buf = vec![0xeeu8; msg.len()];
    let mut stored = 0;
    for k in 1..=n {
        let f = body_frame(&id(k & 1 == 1), msg, len, b, k);
        assert_eq!(f.fdf, b.is_fd());
        assert!(is_fd_len(f.len as usize), "length {}", f.len);
        assert!(b.is_fd() || f.len <= 8);
        let r = body_payload(len, b, k);
        if k < n {
            assert_eq!((r, f.len), (b.get() as usize, b.get()));
        } else {
            assert!(r >= 1 && r <= b.get() as usize);
            assert_eq!(Some(f.len), fd_len_round_up(r));
        }
        // Zero padding, and nothing past the length.
        assert!(f.data[r..].iter().all(|&x| x == 0));
        // A body of any other length is refused and stores nothing.
        for wrong in [0usize, 1, 8, 12, 16, 20, 24, 32, 48, 64] {
            if wrong != f.len as usize {
                let mut data = [0u8; 64];
                data[..wrong].copy_from_slice(&f.data[..wrong]);
                assert_eq!(store_body(&mut buf, len, b, k, &data[..wrong]), None);
            }
        }
        // Padding values are ignored by the receiver.
        let mut data = f.data;
        for x in &mut data[r..f.len as usize] {
            *x = 0xa5;
        }
        assert_eq!(
            store_body(&mut buf, len, b, k, &data[..f.len as usize]),
            Some(r)
        );
        stored += r;
    }
    assert_eq!(stored, msg.len());
    assert_eq!(body_frame(&id(false), msg, len, b, n + 1).len, 0);
    assert_eq!(store_body(&mut buf, len, b, n + 1, &[]), None);
    buf
}

#[test]
fn every_length_every_body_size() {
    for len in 0..=2000usize {
        let msg = msg_of(len, len as u8);
        for b in BodySize::ALL {
            assert_eq!(round_trip(&msg, b), msg, "len {len} B {}", b.get());
        }
    }
}

#[test]
fn longest_message() {
    let msg = msg_of(65535, 7);
    for b in BodySize::ALL {
        assert_eq!(round_trip(&msg, b), msg);
    }
    assert_eq!(body_count(65535, BodySize::MAX), 1024);
}

/// Body size 8 must give the classic sender's bodies, bit for bit.
fn assert_classic_unchanged(msg: &[u8], q: bool) {
    let len = msg.len() as u16;
    let h = Header {
        len,
        kind: MsgKind::Segm { id: 0x1234_5678 },
    };
    let t = Transfer::new(5, 0, 0, 0x40, h, q, &Timers::default());
    for k in 1..=rcan_core::dsor_wire::body_count(len) {
        let classic = t.frame(msg, k);
        let f = body_frame(&id(q ^ (k & 1 == 1)), msg, len, BodySize::CLASSIC, k);
        assert!(!f.fdf);
        assert_eq!(f.classic(), Some(classic));
        assert_eq!(FdFrame::from(classic), f);
    }
}

#[test]
fn classic_body_size_is_classic() {
    for len in 0..=600usize {
        assert_classic_unchanged(&msg_of(len, 3), len % 2 == 0);
    }
}

#[test]
fn fd_doc_example() {
    let msg: Vec<u8> = (0..90u8).collect();
    let h = FdHeader::new(
        Header {
            len: 90,
            kind: MsgKind::Segm { id: 0x1234_5678 },
        },
        BodySize::MAX,
    )
    .unwrap();
    let hid = DsorId {
        ftype: FrameType::Header,
        ..id(false)
    };
    let hf = h.frame(&hid);
    assert_eq!((hf.id, hf.len, hf.fdf), (0x0800_0280, 12, true));
    assert_eq!(
        hf.payload(),
        &[0x00, 0x5a, 0x12, 0x34, 0x56, 0x78, 0, 0, 6, 0x40, 0, 0]
    );
    assert_eq!(FdHeader::decode(hf.payload()), Some(h));

    let ack = FdAck {
        status: AckStatus::Ok,
        body: BodySize::MAX,
    };
    let af = ack.frame(&hid.ack_id());
    assert_eq!((af.id, af.payload()), (0x0801_4040, &[0u8, 0, 0, 0x40][..]));
    let got = FdAck::decode(af.payload(), h.max_body).unwrap();
    assert_eq!(got, ack);
    let b = got.body;

    let b1 = body_frame(&id(true), &msg, 90, b, 1);
    assert_eq!((b1.id, b1.len, b1.fdf), (0x0800_02B0, 64, true));
    assert_eq!(b1.payload(), &msg[..64]);
    let b2 = body_frame(&id(false), &msg, 90, b, 2);
    assert_eq!((b2.id, b2.len, b2.fdf), (0x0800_02A0, 32, true));
    assert_eq!(&b2.payload()[..26], &msg[64..]);
    assert_eq!(&b2.payload()[26..], &[0u8; 6]);

    let mut buf = [0u8; 90];
    assert_eq!(store_body(&mut buf, 90, b, 1, b1.payload()), Some(64));
    assert_eq!(store_body(&mut buf, 90, b, 2, b2.payload()), Some(26));
    assert_eq!(&buf[..], &msg[..]);

    // The fallback of the example: the classic header of the same message.
    let classic = Frame::header(&hid, &h.header);
    assert_eq!(
        (classic.id, classic.payload()),
        (0x0800_0280, &[0x00u8, 0x5a, 0x12, 0x34, 0x56, 0x78][..])
    );
    assert_eq!(rcan_core::dsor_wire::body_count(90), 12);
}

#[test]
fn fd_header_and_ack_malformed() {
    let hdr = |len| Header {
        len,
        kind: MsgKind::Port { dport: 1, sport: 2 },
    };
    // No FD header for L <= 8, nor with a classic B_max.
    assert_eq!(FdHeader::new(hdr(8), BodySize::MAX), None);
    assert_eq!(FdHeader::new(hdr(9), BodySize::CLASSIC), None);
    let h = FdHeader::new(hdr(9), BodySize::new(16).unwrap()).unwrap();
    let mut d = [0u8; 64];
    assert_eq!(h.encode(&mut d), 12);
    assert_eq!(&d[..12], &[0, 9, 1, 2, 0, 0, 0, 0, 4, 16, 0, 0]);
    assert_eq!(FdHeader::decode(&d[..12]), Some(h));
    // Reserved bytes are ignored.
    let mut r = d;
    r[10] = 0xff;
    r[11] = 0x01;
    assert_eq!(FdHeader::decode(&r[..12]), Some(h));
    // Wrong length, type byte, body size or L <= 8: malformed.
    for l in [0, 4, 6, 8, 11, 16, 64] {
        assert_eq!(FdHeader::decode(&d[..l]), None);
    }
    for t in [0u8, 3, 5, 7, 9, 12] {
        let mut x = d;
        x[8] = t;
        assert_eq!(FdHeader::decode(&x[..12]), None);
    }
    for bm in [0u8, 8, 9, 13, 63, 65, 255] {
        let mut x = d;
        x[9] = bm;
        assert_eq!(FdHeader::decode(&x[..12]), None);
    }
    let mut x = d;
    x[1] = 8;
    assert_eq!(FdHeader::decode(&x[..12]), None);
    // Every type round-trips.
    for kind in [
        MsgKind::Segm { id: 0xdead_beef },
        MsgKind::Port { dport: 7, sport: 9 },
        MsgKind::Udp {
            dport: 5000,
            daddr: 0xc0a8_0114,
        },
    ] {
        for b in &BodySize::ALL[1..] {
            let h = FdHeader::new(Header { len: 65535, kind }, *b).unwrap();
            let mut d = [0u8; 64];
            let l = h.encode(&mut d) as usize;
            assert_eq!(FdHeader::decode(&d[..l]), Some(h));
            assert_eq!(d[8], kind.dlc());
            assert!(d[l..].iter().all(|&x| x == 0));
        }
    }

    // Acks: index 0 only, body size a valid one not above the offer.
    let off = BodySize::new(32).unwrap();
    assert_eq!(
        FdAck::decode(&[0, 0, 0, 32], off),
        Some(FdAck {
            status: AckStatus::Ok,
            body: off
        })
    );
    assert_eq!(
        FdAck::decode(&[0, 0, 0, 8], off).map(|a| a.body),
        Some(BodySize::CLASSIC)
    );
    for bad in [
        &[0u8, 0, 0, 48][..],
        &[0, 0, 0, 9],
        &[0, 0, 0, 0],
        &[0, 1, 0, 32],
        &[0, 0, 4, 32],
        &[0, 0, 0],
        &[0, 0],
        &[0, 0, 0, 32, 0],
    ] {
        assert_eq!(FdAck::decode(bad, off), None, "{bad:?}");
    }
    let refused = FdAck {
        status: AckStatus::Refused,
        body: BodySize::CLASSIC,
    };
    let mut a = [0u8; 8];
    assert_eq!(refused.encode(&mut a), 4);
    assert_eq!(&a[..4], &[0, 0, 1, 8]);
    assert_eq!(FdAck::decode(&a[..4], off), Some(refused));
    // A classic ack of index 0 is not the ack of an FD header.
    assert_eq!(FdAck::decode(&[0, 0], off), None);
    assert_eq!(FdAck::decode(&[0, 0, 1], off), None);
}

fn body_size() -> impl Strategy<Value = BodySize> {
    prop::sample::select(BodySize::ALL.to_vec())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// FD segmentation followed by reassembly is the identity.
    #[test]
    fn fd_segmentation_is_identity(len in 0usize..=65535, seed: u8, b in body_size()) {
        let msg = msg_of(len, seed);
        prop_assert_eq!(round_trip(&msg, b), msg);
    }

    /// Body size 8 is the classic format, bit for bit.
    #[test]
    fn classic_mode_unchanged(len in 0usize..=65535, seed: u8, q: bool) {
        assert_classic_unchanged(&msg_of(len, seed), q);
    }

    /// Arbitrary bodies never panic and store nothing unless their length
    /// is right.
    #[test]
    fn arbitrary_bodies(len: u16, b in body_size(), k: u16,
                        data in prop::collection::vec(any::<u8>(), 0..=64)) {
        let mut buf = vec![0u8; len as usize];
        let res = store_body(&mut buf, len, b, k, &data);
        prop_assert_eq!(res.is_some(), body_len_ok(len, b, k, data.len()));
        if res.is_none() {
            prop_assert!(buf.iter().all(|&x| x == 0));
        }
        let _ = FdHeader::decode(&data);
        let _ = FdAck::decode(&data, b);
    }
}

// ---------------------------------------------------------------------------
// The sender, FdTransfer
// ---------------------------------------------------------------------------

fn ack_id(q: bool) -> DsorId {
    DsorId {
        prio: 0x40,
        dst: 5,
        src: 0,
        ftype: FrameType::Ack,
        seq: q,
        chan: 0,
    }
}

fn segm(len: u16) -> Header {
    Header {
        len,
        kind: MsgKind::Segm { id: 0x1234_5678 },
    }
}

#[test]
fn fd_transfer_doc_example() {
    let msg: Vec<u8> = (0..90u8).collect();
    let t0 = Timers::default();
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    let h = t.start(&msg, 0);
    assert_eq!((h.id, h.len, h.fdf), (0x0800_0280, 12, true));
    assert_eq!(
        h.payload(),
        &[0x00, 0x5a, 0x12, 0x34, 0x56, 0x78, 0, 0, 6, 0x40, 0, 0]
    );
    // A classic ack of index 0 does not answer an FD header.
    assert_eq!(t.on_ack(&ack_id(false), &[0, 0], &msg, 1), FdStep::Nothing);
    let FdStep::Send(b1) = t.on_ack(&ack_id(false), &[0, 0, 0, 0x40], &msg, 1) else {
        panic!()
    };
    assert!(t.fd_acked());
    assert_eq!((b1.id, b1.len, b1.fdf), (0x0800_02B0, 64, true));
    let FdStep::Send(b2) = t.on_ack(&ack_id(true), &[0, 1], &msg, 2) else {
        panic!()
    };
    assert_eq!((b2.id, b2.len), (0x0800_02A0, 32));
    assert!(t.last_frame_sent());
    assert_eq!(t.on_ack(&ack_id(false), &[0, 2], &msg, 3), FdStep::Done);
    assert!(t.next_q());
}

#[test]
fn fd_transfer_fallback() {
    let msg = msg_of(90, 1);
    let t0 = Timers::default();
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    let fd = t.start(&msg, 0);
    assert!(fd.fdf);
    assert_eq!(t.on_timer(&msg, 99), FdStep::Nothing);
    // The first retransmission is the classic header, same identifier.
    let FdStep::Send(c) = t.on_timer(&msg, 100) else {
        panic!()
    };
    assert!(t.fell_back() && !t.fd_acked());
    assert_eq!(
        c.classic(),
        Some(Frame::header(
            &DsorId {
                ftype: FrameType::Header,
                ..id(false)
            },
            &segm(90)
        ))
    );
    // A late ack of the FD header is ignored now; the classic one counts.
    assert_eq!(
        t.on_ack(&ack_id(false), &[0, 0, 0, 0x40], &msg, 150),
        FdStep::Nothing
    );
    let FdStep::Send(b1) = t.on_ack(&ack_id(false), &[0, 0], &msg, 150) else {
        panic!()
    };
    assert_eq!((b1.len, b1.fdf), (8, false));
    assert_eq!(t.body_size(), BodySize::CLASSIC);

    // The fallback counts against N_retx: 11 header transmissions in all.
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    t.start(&msg, 0);
    for i in 1..=10u64 {
        let FdStep::Send(f) = t.on_timer(&msg, 100 * i) else {
            panic!()
        };
        assert!(!f.fdf && f.len == 6);
    }
    assert_eq!(
        t.on_timer(&msg, 1100),
        FdStep::Failed(rcan_core::dsor_tx::TxError::TimedOut)
    );
    assert!(!t.last_frame_sent());

    // Refusal of the FD header.
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), true, &t0, Some(BodySize::MAX));
    t.start(&msg, 0);
    assert_eq!(
        t.on_ack(&ack_id(true), &[0, 0, 2, 8], &msg, 1),
        FdStep::Failed(rcan_core::dsor_tx::TxError::NoMemory)
    );
    assert!(!t.next_q());
}

/// An event for the classic-equivalence run: an ack of the frame in
/// flight (with a status), a stale ack, or the timer.
#[derive(Clone, Copy, Debug)]
enum Ev {
    Ack(u8),
    Stale,
    Timer,
}

fn ev() -> impl Strategy<Value = Ev> {
    prop_oneof![
        6 => Just(Ev::Ack(0)),
        1 => (1u8..=3).prop_map(Ev::Ack),
        1 => Just(Ev::Stale),
        2 => Just(Ev::Timer),
    ]
}

/// Mostly timers, so that retransmission budgets run out.
fn ev_timers() -> impl Strategy<Value = Ev> {
    prop_oneof![
        1 => Just(Ev::Ack(0)),
        12 => Just(Ev::Timer),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Without an offer (or for L <= 8 with one) FdTransfer sends exactly
    /// what the classic Transfer sends, event for event.
    #[test]
    fn fd_transfer_without_offer_is_classic(len in 0u16..200, q: bool, offer: bool,
                                            evs in prop_oneof![prop::collection::vec(ev(), 0..80),
                                                           prop::collection::vec(ev_timers(), 0..80)]) {
        let len = if offer { len % 9 } else { len };
        let msg = msg_of(len as usize, 9);
        let t0 = Timers::default();
        let mut c = Transfer::new(5, 0, 0, 0x40, segm(len), q, &t0);
        let mut f = FdTransfer::new_fd(5, 0, 0, 0x40, segm(len), q, &t0,
                                    offer.then_some(BodySize::MAX));
        prop_assert_eq!(FdFrame::from(c.start(&msg, 0)), f.start(&msg, 0));
        let mut now = 0u64;
        let mut index = 0u16;
        for e in evs {
            now += 100;
            let (a, b) = match e {
                Ev::Timer => (c.on_timer(&msg, now), f.on_timer(&msg, now)),
                Ev::Ack(_) | Ev::Stale => {
                    let stale = matches!(e, Ev::Stale);
                    let i = if stale { index.wrapping_sub(1) } else { index };
                    let qq = q ^ (i & 1 == 1);
                    let [x, y] = i.to_be_bytes();
                    let d = [x, y, if let Ev::Ack(s) = e { s } else { 0 }];
                    let d = if d[2] == 0 { &d[..2] } else { &d[..] };
                    (c.on_ack(&ack_id(qq), d, &msg, now), f.on_ack(&ack_id(qq), d, &msg, now))
                }
            };
            let b2 = match a {
                rcan_core::dsor_tx::TxStep::Nothing => FdStep::Nothing,
                rcan_core::dsor_tx::TxStep::Send(fr) => FdStep::Send(fr.into()),
                rcan_core::dsor_tx::TxStep::Done => FdStep::Done,
                rcan_core::dsor_tx::TxStep::Failed(e) => FdStep::Failed(e),
            };
            prop_assert_eq!(b2, b);
            if matches!(e, Ev::Ack(0)) && matches!(b, FdStep::Send(_)) {
                index += 1;
            }
            prop_assert_eq!(c.next_q(), f.next_q());
            prop_assert_eq!(c.last_frame_sent(), f.last_frame_sent());
            prop_assert_eq!(c.finished(), f.finished());
            prop_assert_eq!(c.deadline(), f.deadline());
        }
        prop_assert!(!f.fell_back());
    }

    /// FdTransfer against an ideal receiver that picks any body size up to
    /// the offer, over a lossless channel: the receiver reassembles the
    /// message from the FD bodies and the sender reports success.
    #[test]
    fn fd_transfer_end_to_end(len in 9u16..=5000, seed: u8, q: bool,
                              offer in body_size().prop_filter("FD", |b| b.is_fd()),
                              pick in 0usize..8) {
        let msg = msg_of(len as usize, seed);
        let choices: Vec<BodySize> =
            BodySize::ALL.iter().copied().filter(|b| *b <= offer).collect();
        let chosen = choices[pick % choices.len()];
        let t0 = Timers::default();
        let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(len), q, &t0, Some(offer));
        let h = t.start(&msg, 0);
        let fh = FdHeader::decode(h.payload()).unwrap();
        prop_assert_eq!((fh.header, fh.max_body), (segm(len), offer));
        let mut a = [0u8; 8];
        let n = FdAck { status: AckStatus::Ok, body: chosen }.encode(&mut a) as usize;
        let mut step = t.on_ack(&ack_id(q), &a[..n], &msg, 1);
        let mut buf = vec![0u8; len as usize];
        let mut k = 0u16;
        while let FdStep::Send(f) = step {
            k += 1;
            let did = DsorId::from_can_id(f.id).unwrap();
            prop_assert_eq!(did.ftype, FrameType::Body);
            prop_assert_eq!(did.seq, q ^ (k & 1 == 1));
            prop_assert_eq!(f.fdf, chosen.is_fd());
            prop_assert!(store_body(&mut buf, len, chosen, k, f.payload()).is_some());
            let [x, y] = k.to_be_bytes();
            step = t.on_ack(&ack_id(did.seq), &[x, y], &msg, 2);
        }
        prop_assert_eq!(step, FdStep::Done);
        prop_assert_eq!(k, body_count(len, chosen));
        prop_assert_eq!(buf, msg);
        prop_assert!(t.fd_acked() && !t.fell_back());
    }
}

// ---------------------------------------------------------------------------
// FdTransfer against the real receiver, Reassembler
// ---------------------------------------------------------------------------

use rcan_core::dsor_rx::{Limits, Reassembler};

type Rx = Reassembler<Vec<u8>, 8>;

fn rx(fd: Option<BodySize>) -> Rx {
    let mut r = Rx::new(0, Limits::DEFAULT, &Timers::default());
    r.set_fd_body_size(fd);
    r
}

/// Feed one sender frame to the receiver; returns the ack (if any) and the
/// delivered message (if any).
fn feed(r: &mut Rx, f: &FdFrame, now: u64) -> (Option<Frame>, Option<Vec<u8>>) {
    let id = DsorId::from_can_id(f.id).unwrap();
    let out = r.on_frame(&id, f.payload(), now, |inc| {
        Ok(vec![0u8; inc.header.len as usize])
    });
    (out.ack, out.delivered.map(|d| d.buf))
}

#[test]
fn fd_receiver_doc_example() {
    let msg: Vec<u8> = (0..90u8).collect();
    let mut r = rx(Some(BodySize::MAX));
    let t0 = Timers::default();
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    let mut f = t.start(&msg, 0);
    let want_acks: [(u32, &[u8]); 3] = [
        (0x0801_4040, &[0, 0, 0, 0x40]),
        (0x0801_4050, &[0, 1]),
        (0x0801_4040, &[0, 2]),
    ];
    for (i, (aid, adata)) in want_acks.iter().enumerate() {
        let (ack, got) = feed(&mut r, &f, i as u64);
        let ack = ack.unwrap();
        assert_eq!((ack.id, ack.payload()), (*aid, *adata));
        let step = t.on_ack(
            &DsorId::from_can_id(ack.id).unwrap(),
            ack.payload(),
            &msg,
            i as u64,
        );
        match step {
            FdStep::Send(n) => f = n,
            FdStep::Done => {
                assert_eq!(i, 2);
                assert_eq!(got.as_deref(), Some(&msg[..]));
            }
            s => panic!("{s:?}"),
        }
    }
    // A receiver capped at 16 chooses 16; one set to 8 chooses classic.
    for (cap, want) in [(16u8, 16u8), (8, 8)] {
        let mut r = rx(BodySize::new(cap));
        let h = FdHeader::new(segm(90), BodySize::MAX).unwrap();
        let (ack, _) = feed(&mut r, &h.frame(&id(false)), 0);
        assert_eq!(ack.unwrap().payload(), &[0, 0, 0, want]);
    }
}

#[test]
fn classic_receiver_ignores_fd_header_and_fallback_works() {
    let msg = msg_of(90, 4);
    let mut r = rx(None);
    let t0 = Timers::default();
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    let f = t.start(&msg, 0);
    assert_eq!(feed(&mut r, &f, 0), (None, None));
    assert_eq!(r.states(), 0);
    let FdStep::Send(mut f) = t.on_timer(&msg, 100) else {
        panic!()
    };
    let mut now = 100;
    loop {
        assert!(!f.fdf && f.len <= 8);
        let (ack, got) = feed(&mut r, &f, now);
        let ack = ack.unwrap();
        now += 1;
        match t.on_ack(
            &DsorId::from_can_id(ack.id).unwrap(),
            ack.payload(),
            &msg,
            now,
        ) {
            FdStep::Send(n) => f = n,
            FdStep::Done => {
                assert_eq!(got, Some(msg));
                break;
            }
            s => panic!("{s:?}"),
        }
    }
    assert!(t.fell_back());

    // An FD receiver whose ack of the FD header was lost: the classic
    // header that follows starts the message anew, classic bodies.
    let msg = msg_of(90, 5);
    let mut r = rx(Some(BodySize::MAX));
    let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(90), false, &t0, Some(BodySize::MAX));
    let f = t.start(&msg, 0);
    let (lost, _) = feed(&mut r, &f, 0);
    assert_eq!(lost.unwrap().len, 4);
    let FdStep::Send(c) = t.on_timer(&msg, 100) else {
        panic!()
    };
    let (ack, _) = feed(&mut r, &c, 100);
    let ack = ack.unwrap();
    assert_eq!(ack.payload(), &[0, 0]);
    // The late FD ack is ignored, the classic one moves on to 8-byte bodies.
    let aid = DsorId::from_can_id(ack.id).unwrap();
    assert_eq!(
        t.on_ack(&aid, lost.unwrap().payload(), &msg, 101),
        FdStep::Nothing
    );
    let FdStep::Send(b1) = t.on_ack(&aid, ack.payload(), &msg, 101) else {
        panic!()
    };
    assert_eq!((b1.len, b1.fdf), (8, false));
    assert!(feed(&mut r, &b1, 102).0.is_some());
}

/// What happens to a frame on a channel: delivered, lost or duplicated.
#[derive(Clone, Copy, Debug)]
enum Fate {
    Pass,
    Lose,
    Dup,
}

fn fate() -> impl Strategy<Value = Fate> {
    prop_oneof![8 => Just(Fate::Pass), 1 => Just(Fate::Lose), 1 => Just(Fate::Dup)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// One FD sender and one receiver (FD with any cap, or classic) over
    /// two FIFO channels that lose and duplicate frames (never reorder):
    /// success means the receiver delivered the message exactly once and
    /// intact; a message is never delivered twice or corrupted.
    #[test]
    fn fd_sim_lossy(len in 0u16..=3000, seed: u8, q: bool,
                    offer in body_size(), cap in prop::option::of(body_size()),
                    fates in prop::collection::vec(fate(), 1..400)) {
        let msg = msg_of(len as usize, seed);
        let t0 = Timers::default();
        let mut r = rx(cap);
        let mut t = FdTransfer::new_fd(5, 0, 0, 0x40, segm(len), q, &t0, Some(offer));
        let mut fates = fates.into_iter().cycle();
        let mut to_rx: std::collections::VecDeque<FdFrame> = [t.start(&msg, 0)].into();
        let mut to_tx: std::collections::VecDeque<Frame> = Default::default();
        let mut delivered = Vec::new();
        let mut now = 0u64;
        let result = loop {
            now += 10;
            if let Some(f) = to_rx.pop_front() {
                let n = match fates.next().unwrap() {
                    Fate::Pass => 1, Fate::Lose => 0, Fate::Dup => 2,
                };
                for _ in 0..n {
                    let (ack, got) = feed(&mut r, &f, now);
                    if let Some(g) = got { delivered.push(g); }
                    if let Some(a) = ack { to_tx.push_back(a); }
                }
                continue;
            }
            if let Some(a) = to_tx.pop_front() {
                if matches!(fates.next().unwrap(), Fate::Lose) { continue; }
                let aid = DsorId::from_can_id(a.id).unwrap();
                match t.on_ack(&aid, a.payload(), &msg, now) {
                    FdStep::Send(f) => to_rx.push_back(f),
                    FdStep::Done => break Ok(()),
                    FdStep::Failed(e) => break Err(e),
                    FdStep::Nothing => {}
                }
                continue;
            }
            // Both channels idle: time passes to the sender's deadline.
            now = t.deadline().unwrap().max(now);
            r.on_timer(now);
            match t.on_timer(&msg, now) {
                FdStep::Send(f) => to_rx.push_back(f),
                FdStep::Failed(e) => break Err(e),
                s => prop_assert!(false, "{:?}", s),
            }
        };
        prop_assert!(delivered.len() <= 1);
        for d in &delivered { prop_assert_eq!(d, &msg); }
        match result {
            Ok(()) => prop_assert_eq!(delivered.len(), 1),
            Err(_) => prop_assert!(delivered.is_empty() || t.last_frame_sent()),
        }
        if result.is_ok() && cap.is_none() { prop_assert!(!t.fd_acked()); }
    }
}
