// SPDX-License-Identifier: GPL-2.0
//! The CAN FD extension of DSOR frame by frame (dsor-wire.rst, "Message
//! transfer with CAN FD bodies"): the worked example, the fallback to a
//! classic receiver, the receiver's choice of body size, malformed FD
//! headers and acks.

use dsor_peer::node::{Config, Event, Node};
use dsor_peer::wire::{FdAck, FdHeader, Frame, Header, Kind, Status};

const MSG_ID: u32 = 0x1234_5678;

fn fd_node(n: u8, b_max: u8) -> Node {
    Node::new(Config {
        fd: true,
        fd_b_max: b_max,
        ..Config::new(n)
    })
}

fn classic_node(n: u8) -> Node {
    Node::new(Config::new(n))
}

/// The FD header of a `len`-byte segmented message offering 64.
fn fd_header(len: u16) -> FdHeader {
    FdHeader {
        header: Header {
            len,
            kind: Kind::Segm { id: MSG_ID },
        },
        b_max: 64,
    }
}

/// Moves frames between `a` and `b` until neither sends any; returns
/// them in bus order with the sender's index.
fn pump(now: u64, a: &mut Node, b: &mut Node) -> Vec<(usize, Frame)> {
    let mut seen = Vec::new();
    loop {
        let mut moved = false;
        while let Some(f) = a.pop_frame() {
            b.on_frame(now, &f);
            seen.push((0, f));
            moved = true;
        }
        while let Some(f) = b.pop_frame() {
            a.on_frame(now, &f);
            seen.push((1, f));
            moved = true;
        }
        if !moved {
            return seen;
        }
    }
}

fn delivered(n: &mut Node) -> Vec<Vec<u8>> {
    let mut v = Vec::new();
    while let Some(e) = n.pop_event() {
        if let Event::Delivered(d) = e {
            v.push(d.payload);
        }
    }
    v
}

fn sent_ok(n: &mut Node) -> usize {
    let mut k = 0;
    while let Some(e) = n.pop_event() {
        if let Event::Sent { result, .. } = e {
            assert_eq!(result, Ok(()));
            k += 1;
        }
    }
    k
}

#[test]
fn worked_example() {
    let msg: Vec<u8> = (0..90u8).collect();
    let mut tx = fd_node(0x05, 64);
    let mut rx = fd_node(0x00, 64);
    tx.send(0, 0x00, 0x40, Kind::Segm { id: MSG_ID }, msg.clone())
        .unwrap();
    let got = pump(0, &mut tx, &mut rx);
    let mut body2 = (64..90u8).collect::<Vec<u8>>();
    body2.extend([0; 6]);
    let want: Vec<(usize, u32, bool, Vec<u8>)> = vec![
        (
            0,
            0x0800_0280,
            true,
            vec![0x00, 0x5a, 0x12, 0x34, 0x56, 0x78, 0, 0, 0x06, 0x40, 0, 0],
        ),
        (1, 0x0801_4040, false, vec![0, 0, 0, 0x40]),
        (0, 0x0800_02B0, true, (0..64u8).collect()),
        (1, 0x0801_4050, false, vec![0, 1]),
        (0, 0x0800_02A0, true, body2),
        (1, 0x0801_4040, false, vec![0, 2]),
    ];
    let got: Vec<(usize, u32, bool, Vec<u8>)> = got
        .into_iter()
        .map(|(s, f)| (s, f.id, f.fd, f.bytes().to_vec()))
        .collect();
    assert_eq!(got, want);
    assert_eq!(delivered(&mut rx), vec![msg]);
    assert_eq!(sent_ok(&mut tx), 1);
}

#[test]
fn classic_receiver_gets_the_fallback_once() {
    let msg: Vec<u8> = (0..90u8).collect();
    let mut tx = fd_node(0x05, 64);
    let mut rx = classic_node(0x00);
    tx.send(0, 0x00, 0x40, Kind::Segm { id: MSG_ID }, msg.clone())
        .unwrap();
    // The FD header goes unanswered.
    let first = pump(0, &mut tx, &mut rx);
    assert_eq!(first.len(), 1);
    assert!(first[0].1.fd && first[0].1.len == 12);
    // At T_ack: the classic header, Q = 0 still, then 12 classic bodies.
    tx.poll(100);
    let rest = pump(100, &mut tx, &mut rx);
    let (_, h) = &rest[0];
    assert_eq!(
        (h.id, h.fd, h.bytes()),
        (
            0x0800_0280,
            false,
            &[0x00, 0x5a, 0x12, 0x34, 0x56, 0x78][..]
        )
    );
    let bodies = rest.iter().filter(|(s, f)| *s == 0 && f.id & 0x60 == 0x20);
    assert_eq!(bodies.clone().count(), 12);
    assert!(bodies.clone().all(|(_, f)| !f.fd && f.len <= 8));
    assert_eq!(delivered(&mut rx), vec![msg.clone()]);
    assert_eq!(sent_ok(&mut tx), 1);
    // Remembered: the next message goes classic at once.
    tx.send(200, 0x00, 0x40, Kind::Segm { id: MSG_ID }, msg.clone())
        .unwrap();
    let next = pump(200, &mut tx, &mut rx);
    assert!(!next[0].1.fd && next[0].1.len == 6);
    assert_eq!(delivered(&mut rx), vec![msg]);
}

#[test]
fn receiver_chooses_the_smaller_body_size() {
    for (tx_max, rx_max, want) in [(64, 16, 16), (20, 64, 20), (48, 32, 32), (12, 12, 12)] {
        let msg: Vec<u8> = (0..200u8).collect();
        let mut tx = fd_node(0x05, tx_max);
        let mut rx = fd_node(0x00, rx_max);
        tx.send(
            0,
            0x00,
            0x40,
            Kind::Port { dport: 1, sport: 2 },
            msg.clone(),
        )
        .unwrap();
        let got = pump(0, &mut tx, &mut rx);
        assert_eq!(got[1].1.bytes(), &[0, 0, 0, want]);
        let n = 200usize.div_ceil(usize::from(want));
        let bodies: Vec<&Frame> = got
            .iter()
            .filter(|(s, f)| *s == 0 && f.id & 0x60 == 0x20)
            .map(|(_, f)| f)
            .collect();
        assert_eq!(bodies.len(), n, "B {want}");
        assert!(bodies[..n - 1].iter().all(|f| f.fd && f.len == want));
        assert_eq!(delivered(&mut rx), vec![msg], "B {want}");
    }
}

#[test]
fn short_messages_use_the_classic_header() {
    // L <= 8: one body at most, FD does not shorten it.
    let mut tx = fd_node(0x05, 64);
    let mut rx = fd_node(0x00, 64);
    tx.send(0, 0x00, 0x40, Kind::Segm { id: 1 }, vec![7; 8])
        .unwrap();
    let got = pump(0, &mut tx, &mut rx);
    assert!(got.iter().all(|(_, f)| !f.fd));
    assert_eq!(delivered(&mut rx), vec![vec![7; 8]]);
}

#[test]
fn malformed_fd_headers_are_ignored() {
    let h = fd_header(90);
    let good = h.encode();
    let mut bad_type = good;
    bad_type[8] = 5;
    let mut bad_b = good;
    bad_b[9] = 40;
    let short = fd_header(8).encode();
    for bytes in [bad_type, bad_b, short] {
        assert_eq!(FdHeader::decode(&bytes), None);
        let mut rx = fd_node(0x00, 64);
        rx.on_frame(0, &Frame::new_fd(0x0800_0280, &bytes));
        assert!(rx.pop_frame().is_none(), "{bytes:02x?} answered");
    }
    // Reserved bytes do not matter; a classic node ignores even a good one.
    let mut reserved = good;
    reserved[10] = 0xff;
    assert_eq!(FdHeader::decode(&reserved), Some(h));
    let mut classic = classic_node(0x00);
    classic.on_frame(0, &Frame::new_fd(0x0800_0280, &good));
    assert!(classic.pop_frame().is_none());
}

#[test]
fn duplicate_fd_header_gets_the_same_4_byte_ack() {
    let mut rx = fd_node(0x00, 32);
    let h = fd_header(90).encode();
    rx.on_frame(0, &Frame::new_fd(0x0800_0280, &h));
    let a1 = rx.pop_frame().unwrap();
    let mut h2 = h;
    h2[11] = 0x55; // reserved: still a duplicate
    rx.on_frame(10, &Frame::new_fd(0x0800_0280, &h2));
    let a2 = rx.pop_frame().unwrap();
    assert_eq!(a1, a2);
    assert_eq!(
        FdAck::decode(a1.bytes()),
        Some(FdAck {
            status: Status::Ok,
            b: 32
        })
    );
}

#[test]
fn refused_fd_header_is_acked_with_4_bytes() {
    let mut rx = Node::new(Config {
        fd: true,
        refuse: true,
        ..Config::new(0)
    });
    let h = fd_header(90).encode();
    rx.on_frame(0, &Frame::new_fd(0x0800_0280, &h));
    let a = rx.pop_frame().unwrap();
    assert_eq!(a.bytes(), &[0, 0, 1, 8]);
    // The sender ends the transfer with REFUSED.
    let mut tx = fd_node(0x05, 64);
    tx.send(0, 0x00, 0x40, Kind::Segm { id: MSG_ID }, vec![0; 90])
        .unwrap();
    let _ = tx.pop_frame();
    tx.on_frame(1, &a);
    match tx.pop_event() {
        Some(Event::Sent { result, .. }) => {
            assert_eq!(result, Err(dsor_peer::node::Fail::Refused))
        }
        e => panic!("{e:?}"),
    }
}
