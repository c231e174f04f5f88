// SPDX-License-Identifier: GPL-2.0
//! The codec and the protocol against the worked example and the rules of
//! the DSOR wire specification, frame by frame.

use dsor_peer::node::{Config, Delivery, Event, Fail, Node};
use dsor_peer::wire::*;

fn f(id: u32, b: &[u8]) -> Frame {
    Frame::new(id, b)
}

fn frames(n: &mut Node) -> Vec<Frame> {
    std::iter::from_fn(|| n.pop_frame()).collect()
}

fn events(n: &mut Node) -> Vec<Event> {
    std::iter::from_fn(|| n.pop_event()).collect()
}

#[test]
fn identifier_fields() {
    let id = Id {
        prio: 0x40,
        dst: 0,
        src: 5,
        typ: Type::Header,
        q: false,
        chan: 0,
    };
    assert_eq!(id.encode(), 0x0800_0280);
    assert_eq!(Id::decode(0x0800_0280), id);
    let ack = Id {
        prio: 0x40,
        dst: 5,
        src: 0,
        typ: Type::Ack,
        q: false,
        chan: 0,
    };
    assert_eq!(ack.encode(), 0x0801_4040);
    assert_eq!(
        Id::decode(0x1fff_ffff),
        Id {
            prio: 0xff,
            dst: 0x7f,
            src: 0x7f,
            typ: Type::Reserved,
            q: true,
            chan: 15
        }
    );
    for raw in [
        0u32,
        1,
        0x10,
        0x20,
        0x40,
        0x60,
        0x3f80,
        0x1fc000,
        0x1fe0_0000,
        0x1234_5678,
    ] {
        assert_eq!(Id::decode(raw).encode(), raw);
    }
}

#[test]
fn header_and_ack_payloads() {
    let h = Header {
        len: 10,
        kind: Kind::Segm { id: 0x1234_5678 },
    };
    let (b, n) = h.encode();
    assert_eq!(&b[..n as usize], &[0x00, 0x0A, 0x12, 0x34, 0x56, 0x78]);
    assert_eq!(Header::decode(&b[..6]), Some(h));
    let p = Header {
        len: 0x0102,
        kind: Kind::Port {
            dport: 0x21,
            sport: 0x43,
        },
    };
    let (b, n) = p.encode();
    assert_eq!(&b[..n as usize], &[1, 2, 0x21, 0x43]);
    assert_eq!(Header::decode(&b[..4]), Some(p));
    let u = Header {
        len: 65535,
        kind: Kind::Udp {
            dport: 5000,
            daddr: 0x0a00_0001,
        },
    };
    let (b, n) = u.encode();
    assert_eq!(&b[..n as usize], &[0xff, 0xff, 0x13, 0x88, 10, 0, 0, 1]);
    assert_eq!(Header::decode(&b[..8]), Some(u));
    for bad in [0usize, 1, 2, 3, 5, 7] {
        assert_eq!(Header::decode(&[0u8; 8][..bad]), None, "DLC {bad}");
    }
    assert_eq!(
        Ack::decode(&[0, 2]),
        Some(Ack {
            index: 2,
            status: Status::Ok
        })
    );
    assert_eq!(
        Ack::decode(&[1, 0, 3]),
        Some(Ack {
            index: 256,
            status: Status::TooLong
        })
    );
    assert_eq!(
        Ack::decode(&[0, 0, 0]),
        Some(Ack {
            index: 0,
            status: Status::Ok
        })
    );
    for bad in [0usize, 1, 4, 8] {
        assert_eq!(Ack::decode(&[0u8; 8][..bad]), None, "DLC {bad}");
    }
    // Undefined statuses make the ack malformed.
    assert_eq!(Ack::decode(&[0, 0, 4]), None);
    assert_eq!(Ack::decode(&[0, 0, 0xff]), None);
    let (b, n) = Ack {
        index: 0,
        status: Status::Refused,
    }
    .encode();
    assert_eq!(&b[..n as usize], &[0, 0, 1]);
    assert_eq!(bodies(0), 0);
    assert_eq!(bodies(8), 1);
    assert_eq!(bodies(9), 2);
    assert_eq!(bodies(65535), 8192);
    assert_eq!(body_dlc(10, 1), 8);
    assert_eq!(body_dlc(10, 2), 2);
    assert_eq!(body_dlc(16, 2), 8);
    assert_eq!(body_dlc(65535, 8192), 7);
}

#[test]
fn pattern_and_hash() {
    assert_eq!(pattern(4, 0, 0), vec![0, 31, 62, 93]);
    assert_eq!(pattern(3, 2, 1), vec![15, 46, 77]);
    assert_eq!(pattern(10, 0, 0)[9], ((9 * 31) & 0xff) as u8);
    // FNV-1a 64 reference values.
    assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    assert_eq!(fnv1a64(b"foobar"), 0x8594_4171_f739_67e8);
    // The example in Documentation/networking/rcan/dsor-peer.rst (computed
    // there with an independent script).
    assert_eq!(fnv1a64(&pattern(10, 0, 0)), 0x938c_f491_198f_7900);
    assert_eq!(parse_ipv4("10.0.0.1"), Some(0x0a00_0001));
    assert_eq!(parse_ipv4("10.0.0.256"), None);
    assert_eq!(fmt_ipv4(0xc0a8_0102), "192.168.1.2");
}

/// The worked example of the spec, exactly: node 5 sends 10 bytes, segmented
/// id 0x12345678, priority 0x40, to node 0 on channel 0.
#[test]
fn worked_example() {
    let mut a = Node::new(Config::new(5));
    let mut b = Node::new(Config::new(0));
    let msg: Vec<u8> = (0..10).collect();
    a.send(0, 0, 0x40, Kind::Segm { id: 0x1234_5678 }, msg.clone())
        .unwrap();
    let expect = [
        (
            f(0x0800_0280, &[0x00, 0x0A, 0x12, 0x34, 0x56, 0x78]),
            f(0x0801_4040, &[0, 0]),
        ),
        (
            f(0x0800_02B0, &[0, 1, 2, 3, 4, 5, 6, 7]),
            f(0x0801_4050, &[0, 1]),
        ),
        (f(0x0800_02A0, &[8, 9]), f(0x0801_4040, &[0, 2])),
    ];
    for (data, ack) in expect {
        assert_eq!(frames(&mut a), vec![data]);
        b.on_frame(1, &data);
        assert_eq!(frames(&mut b), vec![ack]);
        a.on_frame(1, &ack);
    }
    assert!(frames(&mut a).is_empty());
    assert_eq!(
        events(&mut b),
        vec![Event::Delivered(Delivery {
            src: 5,
            prio: 0x40,
            chan: 0,
            kind: Kind::Segm { id: 0x1234_5678 },
            payload: msg
        })]
    );
    assert!(matches!(
        events(&mut a)[..],
        [Event::Sent {
            result: Ok(()),
            last_frame_sent: true,
            ..
        }]
    ));

    // The next message on the stream starts with Q = NOT(last Q) = 1 on
    // channel 0 again; zero length: the header is the whole message.
    a.send(2, 0, 0x40, Kind::Port { dport: 1, sport: 2 }, vec![])
        .unwrap();
    let h = frames(&mut a);
    assert_eq!(h, vec![f(0x0800_0290, &[0, 0, 1, 2])]);
    b.on_frame(3, &h[0]);
    assert_eq!(frames(&mut b), vec![f(0x0801_4050, &[0, 0])]);
    assert_eq!(events(&mut b).len(), 1);
    // A duplicate of the zero-length header: re-ack, no second delivery.
    b.on_frame(4, &h[0]);
    assert_eq!(frames(&mut b), vec![f(0x0801_4050, &[0, 0])]);
    assert!(events(&mut b).is_empty());
}

/// Two messages at once to one node use channels 0 and 1.
#[test]
fn parallel_channels() {
    let mut a = Node::new(Config::new(5));
    a.send(0, 9, 1, Kind::Segm { id: 1 }, vec![1]).unwrap();
    a.send(0, 9, 1, Kind::Segm { id: 2 }, vec![2]).unwrap();
    let fr = frames(&mut a);
    assert_eq!(
        fr.iter().map(|f| Id::decode(f.id).chan).collect::<Vec<_>>(),
        vec![0, 1]
    );
    for c in 2..16 {
        a.send(0, 9, 1, Kind::Segm { id: c }, vec![]).unwrap();
    }
    assert_eq!(
        a.send(0, 9, 1, Kind::Segm { id: 99 }, vec![]),
        Err(dsor_peer::node::SendError::Busy)
    );
    // Another destination still has all channels.
    assert!(a.send(0, 10, 1, Kind::Segm { id: 99 }, vec![]).is_ok());
}

#[test]
fn retransmission_and_timeout() {
    let mut cfg = Config::new(1);
    cfg.t_ack = 100;
    cfg.n_retx = 3;
    let mut a = Node::new(cfg);
    a.send(0, 2, 7, Kind::Segm { id: 0 }, vec![1, 2, 3])
        .unwrap();
    let first = frames(&mut a);
    assert_eq!(first.len(), 1);
    a.poll(99);
    assert!(frames(&mut a).is_empty());
    for t in [100, 200, 300] {
        a.poll(t);
        assert_eq!(frames(&mut a), first, "retransmission at {t}");
    }
    a.poll(399);
    assert!(events(&mut a).is_empty());
    a.poll(400);
    assert!(frames(&mut a).is_empty());
    assert_eq!(
        events(&mut a),
        vec![Event::Sent {
            handle: 0,
            result: Err(Fail::Timeout),
            last_frame_sent: false
        }]
    );
    // The failed header had Q 0, so the next message's header has Q 1.
    a.send(500, 2, 7, Kind::Segm { id: 0 }, vec![]).unwrap();
    assert!(Id::decode(frames(&mut a)[0].id).q);
}

#[test]
fn stale_acks_ignored_and_status_fails() {
    let mut a = Node::new(Config::new(1));
    a.send(0, 2, 7, Kind::Segm { id: 0 }, vec![0; 9]).unwrap();
    frames(&mut a);
    // Wrong Q, wrong index, wrong channel, wrong source, malformed DLC.
    for ack in [
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: true,
                chan: 0,
            }
            .encode(),
            &[0, 0],
        ),
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 1],
        ),
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 1,
            }
            .encode(),
            &[0, 0],
        ),
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 3,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 0],
        ),
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0],
        ),
        f(
            Id {
                prio: 7,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 0, 0, 0],
        ),
        f(
            Id {
                prio: 7,
                dst: 4,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 0],
        ),
    ] {
        a.on_frame(1, &ack);
        assert!(
            frames(&mut a).is_empty() && events(&mut a).is_empty(),
            "{ack:?}"
        );
    }
    // Priority is not matched: an ack with another P counts.
    a.on_frame(
        1,
        &f(
            Id {
                prio: 9,
                dst: 1,
                src: 2,
                typ: Type::Ack,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 0],
        ),
    );
    assert_eq!(frames(&mut a).len(), 1);
    for (st, fail) in [
        (1u8, Fail::Refused),
        (2, Fail::NoMemory),
        (3, Fail::TooLong),
    ] {
        let mut a = Node::new(Config::new(1));
        a.send(0, 2, 7, Kind::Segm { id: 0 }, vec![0; 9]).unwrap();
        frames(&mut a);
        a.on_frame(
            1,
            &f(
                Id {
                    prio: 7,
                    dst: 1,
                    src: 2,
                    typ: Type::Ack,
                    q: false,
                    chan: 0,
                }
                .encode(),
                &[0, 0, st],
            ),
        );
        assert!(frames(&mut a).is_empty());
        assert_eq!(
            events(&mut a),
            vec![Event::Sent {
                handle: 0,
                result: Err(fail),
                last_frame_sent: false
            }]
        );
    }
}

fn hdr(src: u8, dst: u8, q: bool, chan: u8, len: u16) -> Frame {
    let (b, n) = Header {
        len,
        kind: Kind::Segm { id: 7 },
    }
    .encode();
    f(
        Id {
            prio: 3,
            dst,
            src,
            typ: Type::Header,
            q,
            chan,
        }
        .encode(),
        &b[..n as usize],
    )
}

fn body(src: u8, dst: u8, q: bool, chan: u8, b: &[u8]) -> Frame {
    f(
        Id {
            prio: 3,
            dst,
            src,
            typ: Type::Body,
            q,
            chan,
        }
        .encode(),
        b,
    )
}

fn ack(src: u8, dst: u8, q: bool, chan: u8, index: u16, st: u8) -> Frame {
    let (b, n) = Ack {
        index,
        status: Status::from_code(st).unwrap(),
    }
    .encode();
    f(
        Id {
            prio: 3,
            dst,
            src,
            typ: Type::Ack,
            q,
            chan,
        }
        .encode(),
        &b[..n as usize],
    )
}

#[test]
fn receiver_duplicates_and_malformed() {
    let mut b = Node::new(Config::new(0));
    // Body with no transfer: ignored.
    b.on_frame(0, &body(5, 0, true, 0, &[1]));
    assert!(frames(&mut b).is_empty());
    // Header for another node: ignored. Malformed DLC: ignored.
    b.on_frame(0, &hdr(5, 1, false, 0, 9));
    b.on_frame(
        0,
        &f(
            Id {
                prio: 3,
                dst: 0,
                src: 5,
                typ: Type::Header,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 9, 0],
        ),
    );
    b.on_frame(
        0,
        &f(
            Id {
                prio: 3,
                dst: 0,
                src: 5,
                typ: Type::Reserved,
                q: false,
                chan: 0,
            }
            .encode(),
            &[0, 9, 0, 0],
        ),
    );
    assert!(frames(&mut b).is_empty());
    let h = hdr(5, 0, false, 0, 9);
    b.on_frame(0, &h);
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 0, 0)]);
    // Duplicate header before body 1: re-ack, state kept.
    b.on_frame(1, &h);
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 0, 0)]);
    // Body 1 with the wrong DLC: ignored.
    b.on_frame(2, &body(5, 0, true, 0, &[1; 7]));
    assert!(frames(&mut b).is_empty());
    let b1 = body(5, 0, true, 0, &[1; 8]);
    b.on_frame(2, &b1);
    assert_eq!(frames(&mut b), vec![ack(0, 5, true, 0, 1, 0)]);
    // Body 1 again (ack lost): re-ack index 1, nothing stored.
    b.on_frame(3, &b1);
    assert_eq!(frames(&mut b), vec![ack(0, 5, true, 0, 1, 0)]);
    // Body 2 completes the message.
    let b2 = body(5, 0, false, 0, &[2]);
    b.on_frame(4, &b2);
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 2, 0)]);
    let ev = events(&mut b);
    assert_eq!(ev.len(), 1);
    match &ev[0] {
        Event::Delivered(d) => assert_eq!(d.payload, [1, 1, 1, 1, 1, 1, 1, 1, 2]),
        e => panic!("{e:?}"),
    }
    // Done: a duplicate of the last body is re-acked, never delivered again.
    b.on_frame(5, &b2);
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 2, 0)]);
    // A body with the other Q in Done: ignored.
    b.on_frame(5, &body(5, 0, true, 0, &[2]));
    assert!(frames(&mut b).is_empty());
    assert!(events(&mut b).is_empty());
    assert_eq!(b.rx_bytes(), 0);
    // After T_reasm the Done record is gone: the duplicate is ignored.
    b.poll(5 + 2000);
    b.on_frame(2005, &b2);
    assert!(frames(&mut b).is_empty());
}

#[test]
fn receiver_new_header_discards_partial_and_expires() {
    let mut b = Node::new(Config::new(0));
    b.on_frame(0, &hdr(5, 0, false, 3, 20));
    b.on_frame(0, &body(5, 0, true, 3, &[9; 8]));
    assert_eq!(b.rx_bytes(), 20);
    // A header with the other Q: a new message; partial one freed.
    b.on_frame(1, &hdr(5, 0, true, 3, 4));
    assert_eq!(b.rx_bytes(), 4);
    frames(&mut b);
    b.on_frame(2, &body(5, 0, false, 3, &[1, 2, 3, 4]));
    assert!(
        matches!(&events(&mut b)[..], [Event::Delivered(d)] if d.payload == [1, 2, 3, 4] && d.chan == 3)
    );
    // Partial message without progress is dropped after T_reasm.
    b.on_frame(10, &hdr(6, 0, false, 0, 20));
    b.poll(2009);
    assert_eq!(b.rx_bytes(), 20);
    b.poll(2010);
    assert_eq!(b.rx_bytes(), 0);
    frames(&mut b);
    b.on_frame(2011, &body(6, 0, true, 0, &[0; 8]));
    assert!(frames(&mut b).is_empty());
}

#[test]
fn receiver_limits() {
    let mut cfg = Config::new(0);
    cfg.max_len = 100;
    cfg.max_per_peer = 2;
    cfg.max_bytes_total = 150;
    let mut b = Node::new(cfg.clone());
    b.on_frame(0, &hdr(5, 0, false, 0, 101));
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 0, 3)]);
    b.on_frame(0, &hdr(5, 0, false, 1, 60));
    b.on_frame(0, &hdr(5, 0, false, 2, 60));
    b.on_frame(0, &hdr(5, 0, false, 3, 10)); // third from node 5
    b.on_frame(0, &hdr(6, 0, false, 0, 40)); // 160 bytes total
    b.on_frame(0, &hdr(6, 0, false, 1, 30));
    b.on_frame(0, &hdr(6, 0, false, 2, 0)); // zero length needs no memory
    assert_eq!(
        frames(&mut b),
        vec![
            ack(0, 5, false, 1, 0, 0),
            ack(0, 5, false, 2, 0, 0),
            ack(0, 5, false, 3, 0, 2),
            ack(0, 6, false, 0, 0, 2),
            ack(0, 6, false, 1, 0, 0),
            ack(0, 6, false, 2, 0, 0),
        ]
    );
    assert_eq!(b.rx_bytes(), 150);
    cfg.refuse = true;
    let mut b = Node::new(cfg);
    b.on_frame(0, &hdr(5, 0, false, 0, 10));
    assert_eq!(frames(&mut b), vec![ack(0, 5, false, 0, 0, 1)]);
    assert_eq!(b.rx_bytes(), 0);
    assert!(events(&mut b).is_empty());
}

/// A node may talk to itself (S == D).
#[test]
fn self_talk() {
    let mut a = Node::new(Config::new(7));
    a.send(
        0,
        7,
        0,
        Kind::Udp {
            dport: 53,
            daddr: 0x7f00_0001,
        },
        vec![5; 17],
    )
    .unwrap();
    for _ in 0..20 {
        while let Some(fr) = a.pop_frame() {
            a.on_frame(0, &fr);
        }
    }
    let ev = events(&mut a);
    assert_eq!(ev.len(), 2, "{ev:?}");
    assert!(ev
        .iter()
        .any(|e| matches!(e, Event::Delivered(d) if d.payload == [5; 17] && d.src == 7)));
    assert!(ev
        .iter()
        .any(|e| matches!(e, Event::Sent { result: Ok(()), .. })));
}

/// An ack with an undefined status is ignored by the sender.
#[test]
fn undefined_status_ignored() {
    let mut a = Node::new(Config::new(1));
    a.send(0, 2, 7, Kind::Segm { id: 0 }, vec![]).unwrap();
    frames(&mut a);
    let id = Id {
        prio: 7,
        dst: 1,
        src: 2,
        typ: Type::Ack,
        q: false,
        chan: 0,
    }
    .encode();
    a.on_frame(1, &f(id, &[0, 0, 4]));
    assert!(frames(&mut a).is_empty() && events(&mut a).is_empty());
    a.on_frame(1, &f(id, &[0, 0]));
    assert_eq!(events(&mut a).len(), 1);
}

/// A refused header is remembered: its retransmission gets the same
/// status even if the receiver could now accept it, and bodies are ignored.
#[test]
fn refusal_remembered() {
    let mut cfg = Config::new(0);
    cfg.max_bytes_total = 10;
    let mut b = Node::new(cfg);
    b.on_frame(0, &hdr(5, 0, false, 0, 8)); // takes 8 of 10 bytes
    b.on_frame(0, &hdr(6, 0, false, 0, 8)); // NO_MEMORY
    assert_eq!(
        frames(&mut b),
        vec![ack(0, 5, false, 0, 0, 0), ack(0, 6, false, 0, 0, 2)]
    );
    // Node 5's message is replaced by a zero-length one: memory free again.
    b.on_frame(1, &hdr(5, 0, true, 0, 0));
    assert_eq!(b.rx_bytes(), 0);
    frames(&mut b);
    events(&mut b);
    // Node 6 retransmits its header: still NO_MEMORY, nothing allocated.
    b.on_frame(2, &hdr(6, 0, false, 0, 8));
    assert_eq!(frames(&mut b), vec![ack(0, 6, false, 0, 0, 2)]);
    assert_eq!(b.rx_bytes(), 0);
    // A body (either Q) after a refusal or a zero-length message: ignored.
    for src in [5, 6] {
        for q in [false, true] {
            b.on_frame(3, &body(src, 0, q, 0, &[0; 8]));
        }
    }
    assert!(frames(&mut b).is_empty() && events(&mut b).is_empty());
    // A new header (other Q) is decided anew.
    b.on_frame(4, &hdr(6, 0, true, 0, 8));
    assert_eq!(frames(&mut b), vec![ack(0, 6, true, 0, 0, 0)]);
}

/// A body with the header's Q while body 1 is expected is ignored (no body
/// was received yet, so there is nothing to re-ack); acks carry the P of
/// the frame they acknowledge.
#[test]
fn body_with_header_q_ignored() {
    let mut b = Node::new(Config::new(0));
    b.on_frame(0, &hdr(5, 0, false, 0, 9));
    frames(&mut b);
    b.on_frame(1, &body(5, 0, false, 0, &[0; 8]));
    assert!(frames(&mut b).is_empty());
    let b1 = f(
        Id {
            prio: 0x77,
            dst: 0,
            src: 5,
            typ: Type::Body,
            q: true,
            chan: 0,
        }
        .encode(),
        &[0; 8],
    );
    b.on_frame(2, &b1);
    let got = frames(&mut b);
    assert_eq!(got.len(), 1);
    assert_eq!(Id::decode(got[0].id).prio, 0x77);
}

/// Plays one message from `a` to `b` on channel `chan` and checks every
/// frame on that channel against `expect` (identifier, data); frame number
/// `lose` is not delivered. Frames of other channels (messages kept in
/// flight only to occupy lower channels) are dropped.
fn exchange(a: &mut Node, b: &mut Node, chan: u8, expect: &[(u32, &[u8])], lose: Option<usize>) {
    let mut now = 1000;
    let pop = |n: &mut Node| loop {
        let fr = n.pop_frame()?;
        if Id::decode(fr.id).chan == chan {
            return Some(fr);
        }
    };
    for (i, (id, data)) in expect.iter().enumerate() {
        let mut got = None;
        for _ in 0..3 {
            if let Some(fr) = pop(a) {
                got = Some((fr, true));
            } else if let Some(fr) = pop(b) {
                got = Some((fr, false));
            }
            if got.is_some() {
                break;
            }
            now += 100;
            a.poll(now);
            b.poll(now);
        }
        let (fr, from_a) = got.unwrap_or_else(|| panic!("frame {i} missing"));
        assert_eq!(fr, Frame::new(*id, data), "frame {i}");
        if lose != Some(i) {
            if from_a {
                b.on_frame(now, &fr);
            } else {
                a.on_frame(now, &fr);
            }
        }
    }
    assert!(pop(a).is_none() && pop(b).is_none());
}

/// Occupies channels 0..chan from `a` to `dst` with messages that stay in flight.
fn occupy(a: &mut Node, dst: u8, chan: u8) {
    for _ in 0..chan {
        a.send(0, dst, 0xff, Kind::Segm { id: 0 }, vec![0; 8])
            .unwrap();
    }
}

/// The further worked examples of Documentation/networking/rcan/dsor-wire.rst
/// (written by another helper from the same brief): the two readings agree.
#[test]
fn doc_port_example() {
    let mut a = Node::new(Config::new(0x10));
    let mut b = Node::new(Config::new(0x21));
    occupy(&mut a, 0x21, 2);
    a.send(
        0,
        0x21,
        0x80,
        Kind::Port { dport: 3, sport: 7 },
        vec![0x41, 0x42, 0x43],
    )
    .unwrap();
    exchange(
        &mut a,
        &mut b,
        2,
        &[
            (0x1008_4802, &[0, 3, 3, 7]),
            (0x1004_10C2, &[0, 0]),
            (0x1008_4832, &[0x41, 0x42, 0x43]),
            (0x1004_10D2, &[0, 1]),
        ],
        None,
    );
    assert!(events(&mut b)
        .iter()
        .any(|e| matches!(e, Event::Delivered(d) if d.kind == Kind::Port { dport: 3, sport: 7 })));
}

#[test]
fn doc_udp_example() {
    let mut a = Node::new(Config::new(0x01));
    let mut b = Node::new(Config::new(0x7f));
    let udp = Kind::Udp {
        dport: 5000,
        daddr: 0xc0a8_0114,
    };
    // A zero-length message first, so the stream's last Q is 0.
    a.send(0, 0x7f, 0xc0, udp, vec![]).unwrap();
    exchange(
        &mut a,
        &mut b,
        0,
        &[
            (0x181F_C080, &[0, 0, 0x13, 0x88, 0xc0, 0xa8, 1, 0x14]),
            (0x1800_7FC0, &[0, 0]),
        ],
        None,
    );
    a.send(0, 0x7f, 0xc0, udp, (0..12).collect()).unwrap();
    exchange(
        &mut a,
        &mut b,
        0,
        &[
            (
                0x181F_C090,
                &[0x00, 0x0c, 0x13, 0x88, 0xc0, 0xa8, 0x01, 0x14],
            ),
            (0x1800_7FD0, &[0, 0]),
            (0x181F_C0A0, &[0, 1, 2, 3, 4, 5, 6, 7]),
            (0x1800_7FC0, &[0, 1]),
            (0x181F_C0B0, &[8, 9, 10, 11]),
            (0x1800_7FD0, &[0, 2]),
        ],
        None,
    );
    assert_eq!(events(&mut b).len(), 2);
}

#[test]
fn doc_lost_ack_example() {
    let mut a = Node::new(Config::new(0x05));
    let mut b = Node::new(Config::new(0x03));
    occupy(&mut a, 0x03, 5);
    a.send(0, 0x03, 0x20, Kind::Segm { id: 1 }, vec![]).unwrap();
    exchange(
        &mut a,
        &mut b,
        5,
        &[(0x0400_C285, &[0, 0, 0, 0, 0, 1]), (0x0401_41C5, &[0, 0])],
        None,
    );
    events(&mut b);
    a.send(0, 0x03, 0x20, Kind::Segm { id: 1 }, (0xa0..=0xa8).collect())
        .unwrap();
    let body1: &[u8] = &[0xa0, 0xa1, 0xa2, 0xa3, 0xa4, 0xa5, 0xa6, 0xa7];
    exchange(
        &mut a,
        &mut b,
        5,
        &[
            (0x0400_C295, &[0, 9, 0, 0, 0, 1]),
            (0x0401_41D5, &[0, 0]),
            (0x0400_C2A5, body1),
            (0x0401_41C5, &[0, 1]), // lost
            (0x0400_C2A5, body1),
            (0x0401_41C5, &[0, 1]),
            (0x0400_C2B5, &[0xa8]),
            (0x0401_41D5, &[0, 2]),
        ],
        Some(3),
    );
    let ev = events(&mut b);
    assert!(
        matches!(&ev[..], [Event::Delivered(d)] if d.payload == (0xa0..=0xa8).collect::<Vec<u8>>())
    );
}

/// dsor-wire.rst, "Full receiver": the application holds one message (the
/// zero-length one before), so the last body is answered NO_MEMORY.
#[test]
fn doc_full_receiver_example() {
    let mut a = Node::new(Config::new(0x05));
    let mut b = Node::new(Config {
        app_queue: Some(1),
        ..Config::new(0x03)
    });
    occupy(&mut a, 0x03, 5);
    a.send(0, 0x03, 0x20, Kind::Segm { id: 1 }, vec![]).unwrap();
    exchange(
        &mut a,
        &mut b,
        5,
        &[(0x0400_C285, &[0, 0, 0, 0, 0, 1]), (0x0401_41C5, &[0, 0])],
        None,
    );
    events(&mut b);
    events(&mut a);
    a.send(0, 0x03, 0x20, Kind::Segm { id: 1 }, (0xa0..=0xa8).collect())
        .unwrap();
    exchange(
        &mut a,
        &mut b,
        5,
        &[
            (0x0400_C295, &[0, 9, 0, 0, 0, 1]),
            (0x0401_41D5, &[0, 0]),
            (
                0x0400_C2A5,
                &[0xa0, 0xa1, 0xa2, 0xa3, 0xa4, 0xa5, 0xa6, 0xa7],
            ),
            (0x0401_41C5, &[0, 1]),
            (0x0400_C2B5, &[0xa8]),
            (0x0401_41D5, &[0, 2, 2]),
        ],
        None,
    );
    assert!(matches!(
        &events(&mut b)[..],
        [Event::NotDelivered { status: Status::NoMemory, msg }] if msg.payload.len() == 9
    ));
    assert!(events(&mut a).iter().any(|e| matches!(
        e,
        Event::Sent {
            result: Err(Fail::NoMemory),
            last_frame_sent: true,
            ..
        }
    )));
    // The retransmitted last body gets the same answer, nothing new.
    b.on_frame(5000, &f(0x0400_C2B5, &[0xa8]));
    assert_eq!(frames(&mut b), vec![f(0x0401_41D5, &[0, 2, 2])]);
    assert!(events(&mut b).is_empty());
}

#[test]
fn doc_refused_example() {
    let mut a = Node::new(Config::new(0x05));
    let mut cfg = Config::new(0x0a);
    cfg.refuse = true;
    let mut b = Node::new(cfg);
    occupy(&mut a, 0x0a, 3);
    a.send(
        0,
        0x0a,
        0x40,
        Kind::Port { dport: 1, sport: 2 },
        vec![0; 16],
    )
    .unwrap();
    exchange(
        &mut a,
        &mut b,
        3,
        &[(0x0802_8283, &[0, 0x10, 1, 2]), (0x0801_4543, &[0, 0, 1])],
        None,
    );
    assert!(events(&mut a).contains(&Event::Sent {
        handle: 3,
        result: Err(Fail::Refused),
        last_frame_sent: false
    }));
    // The next header on the stream has Q = 1.
    a.send(0, 0x0a, 0x40, Kind::Port { dport: 1, sport: 2 }, vec![])
        .unwrap();
    let fr = std::iter::from_fn(|| a.pop_frame())
        .find(|f| Id::decode(f.id).chan == 3)
        .unwrap();
    assert!(Id::decode(fr.id).q);
}
