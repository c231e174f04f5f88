// SPDX-License-Identifier: GPL-2.0
//! socket(), addresses, round trips with every send and receive call,
//! connect, loopback to the sender and fan-out to several sockets.

use std::io::{IoSlice, IoSliceMut};

use rcan_uapi::{
    arb_ext, arb_std, raw, ArbSocket, SockaddrCanArb, AF_CAN, CANPROTO_CAN, CAN_MASK_ANY,
    CAN_MASK_EXACT, PF_CAN,
};

use super::{stack1, test_table};
use crate::check::{
    ensure, expect_errno, expect_frame, expect_frames, expect_none, recv_frame, Frame, OrFail,
    TestResult,
};
use crate::ctx::{Ctx, Module};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    socket_create,
    ;
    stack:
    sockname_peername,
    roundtrip_std_sendto,
    roundtrip_ext_sendto,
    roundtrip_remote_sendto,
    roundtrip_sendmsg_recvmsg,
    recv_calls,
    loopback_own_frame,
    fanout_three_sockets,
    connect_write,
    connect_send,
    connect_required,
    connect_unspec_dissolves,
];

fn int_opt(s: &ArbSocket, name: libc::c_int) -> Result<i32, String> {
    let mut v = [0u8; 4];
    let len = raw::getsockopt(s, libc::SOL_SOCKET, name, &mut v).or_fail("getsockopt")?;
    ensure!(len == 4, "getsockopt({name}) length {len}");
    Ok(i32::from_ne_bytes(v))
}

/// socket(): type and protocol checks; a good socket reports its identity.
fn socket_create(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    expect_errno(
        raw::socket(PF_CAN, libc::SOCK_DGRAM, CANPROTO_CAN),
        libc::EPROTOTYPE,
        "socket(AF_CAN, SOCK_DGRAM, CANPROTO_CAN)",
    )?;
    expect_errno(
        raw::socket(PF_CAN, libc::SOCK_RAW, 99),
        libc::EPROTONOSUPPORT,
        "socket(AF_CAN, SOCK_RAW, 99)",
    )?;
    expect_errno(
        raw::socket(PF_CAN, libc::SOCK_RAW, 5),
        libc::EPROTONOSUPPORT,
        "socket(AF_CAN, SOCK_RAW, 5) (unregistered)",
    )?;
    let s = ArbSocket::new().or_fail("socket(AF_CAN, SOCK_RAW, CANPROTO_CAN)")?;
    ensure!(
        int_opt(&s, libc::SO_TYPE)? == libc::SOCK_RAW,
        "SO_TYPE is not SOCK_RAW"
    );
    ensure!(
        int_opt(&s, libc::SO_DOMAIN)? == PF_CAN,
        "SO_DOMAIN is not AF_CAN"
    );
    ensure!(
        int_opt(&s, libc::SO_PROTOCOL)? == CANPROTO_CAN,
        "SO_PROTOCOL is not CANPROTO_CAN"
    );
    let nb = ArbSocket::new_nonblocking().or_fail("socket(.. SOCK_NONBLOCK ..)")?;
    drop((s, nb));
    Ok(())
}

/// getsockname returns the filter given to bind; getpeername the connected
/// destination, ENOTCONN when there is none.
fn sockname_peername(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.socket()?;
    let mut raw_addr = [0xAAu8; 16];
    let len = raw::getsockname(&s, &mut raw_addr).or_fail("getsockname before bind")?;
    let a = SockaddrCanArb::from_bytes(&raw_addr);
    ensure!(len == 16, "getsockname before bind: addrlen {len}");
    ensure!(
        (a.family == AF_CAN || a.family == 0)
            && a.pad == 0
            && (a.arb, a.mask, a.ifindex) == (0, 0, 0),
        "getsockname before bind: {a:?}, expected zeros"
    );

    let filters = [
        (arb_std(0x123, false), CAN_MASK_EXACT, idx),
        (arb_ext(0x1ABC_DEF0, true), 0x0000_FFF9, 0),
        (0, CAN_MASK_ANY, idx),
    ];
    for (arb, mask, ifindex) in filters {
        s.bind(arb, mask, ifindex).or_fail("bind")?;
        let got = s.local_addr().or_fail("getsockname")?;
        ensure!(
            got == SockaddrCanArb::new(arb, mask, ifindex),
            "getsockname after bind({arb:#x}, {mask:#x}, {ifindex}): {got:?}"
        );
    }

    expect_errno(s.peer_addr(), libc::ENOTCONN, "getpeername before connect")?;
    let arb = arb_ext(0x1234, false);
    s.connect(arb, idx).or_fail("connect")?;
    let p = s.peer_addr().or_fail("getpeername after connect")?;
    ensure!(
        p == SockaddrCanArb::new(arb, 0, idx),
        "getpeername after connect: {p:?}"
    );
    s.disconnect().or_fail("connect(AF_UNSPEC)")?;
    expect_errno(
        s.peer_addr(),
        libc::ENOTCONN,
        "getpeername after disconnect",
    )
}

/// Sends every frame of `frames` with sendto and receives it back.
fn roundtrip(ctx: &mut Ctx, frames: &[Frame]) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    for f in frames {
        f.send(&tx, idx)?;
        expect_frame(&rx, f, idx)?;
    }
    expect_none(&[&rx, &tx])
}

fn all_dlcs(mk: impl Fn(&[u8]) -> Frame) -> Vec<Frame> {
    (0..=8)
        .map(|dlc| mk(&[0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88][..dlc]))
        .collect()
}

/// Standard data frames, DLC 0..=8, lowest, middle and highest identifier.
fn roundtrip_std_sendto(ctx: &mut Ctx) -> TestResult {
    let mut frames = Vec::new();
    for id in [0x000, 0x123, 0x7FF] {
        frames.extend(all_dlcs(|d| Frame::std(id, d)));
    }
    roundtrip(ctx, &frames)
}

/// Extended data frames, DLC 0..=8.
fn roundtrip_ext_sendto(ctx: &mut Ctx) -> TestResult {
    let mut frames = Vec::new();
    for id in [0, 0x1ABC_DEF0, 0x1FFF_FFFF] {
        frames.extend(all_dlcs(|d| Frame::ext(id, d)));
    }
    roundtrip(ctx, &frames)
}

/// Remote frames: the data bytes given to sendto are ignored, the frame's
/// DLC is the length, recv returns DLC zero bytes.
fn roundtrip_remote_sendto(ctx: &mut Ctx) -> TestResult {
    let mut frames = Vec::new();
    for dlc in 0..=8 {
        frames.push(Frame::remote_std(0x456, dlc));
        frames.push(Frame::remote_ext(0x1ABC_DEF0, dlc));
    }
    roundtrip(ctx, &frames)
}

/// sendmsg with the data split over two iovecs, recvmsg scattering into
/// two buffers; every kind of frame and DLC.
fn roundtrip_sendmsg_recvmsg(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let mut frames = all_dlcs(|d| Frame::std(0x321, d));
    frames.extend(all_dlcs(|d| Frame::ext(0x0765_4321, d)));
    frames.extend((0..=8).map(|dlc| Frame::remote_std(0x321, dlc)));
    for f in &frames {
        let bytes = f.tx_bytes();
        let (a, b) = bytes.split_at(bytes.len() / 2);
        let n = tx
            .send_msg(&[IoSlice::new(a), IoSlice::new(b)], Some((f.arb, idx)), 0)
            .or_fail(format_args!("sendmsg {f}"))?;
        ensure!(n == f.data.len(), "sendmsg {f}: returned {n}");

        let (mut x, mut y) = ([0xAAu8; 3], [0xAAu8; 13]);
        let m = rx
            .recv_msg(&mut [IoSliceMut::new(&mut x), IoSliceMut::new(&mut y)], 0)
            .or_fail(format_args!("recvmsg (waiting for {f})"))?;
        let got: Vec<u8> = x.iter().chain(&y).take(m.len).copied().collect();
        let rxf = Frame::with_arb(m.addr.arb, &got);
        ensure!(
            rxf == *f && m.addr == SockaddrCanArb::new(f.arb, 0, idx),
            "recvmsg: expected {f} from {idx}, got {rxf} from {:?}",
            m.addr
        );
        ensure!(m.addrlen == 16, "recvmsg: msg_namelen {}", m.addrlen);
        ensure!(
            m.flags & libc::MSG_TRUNC == 0,
            "recvmsg {f}: MSG_TRUNC set with room to spare"
        );
    }
    expect_none(&[&rx])
}

/// recv, read, recvfrom and recvmsg all deliver one whole frame each.
fn recv_calls(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let frames: Vec<Frame> = (1..=4u8)
        .map(|i| Frame::std(0x100 + u32::from(i), &[i; 5]))
        .collect();
    for f in &frames {
        f.send(&tx, idx)?;
    }
    let mut buf = [0u8; 8];
    let n = rx.recv(&mut buf, 0).or_fail("recv")?;
    ensure!(buf[..n] == frames[0].data, "recv: {:02X?}", &buf[..n]);
    let n = rx.read(&mut buf).or_fail("read")?;
    ensure!(buf[..n] == frames[1].data, "read: {:02X?}", &buf[..n]);
    expect_frame(&rx, &frames[2], idx)?;
    let m = rx.recv_msg_buf(&mut buf, 0).or_fail("recvmsg")?;
    ensure!(
        buf[..m.len] == frames[3].data && m.addr.arb == frames[3].arb,
        "recvmsg: {:02X?} arb {:#x}",
        &buf[..m.len],
        m.addr.arb
    );
    expect_none(&[&rx])
}

/// The sender receives its own frame if (and only if) its filter matches.
fn loopback_own_frame(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let me = ctx.bound(arb_std(0x10, false), CAN_MASK_EXACT, idx)?;
    let hit = Frame::std(0x10, &[1, 2]);
    let miss = Frame::std(0x11, &[3]);
    miss.send(&me, idx)?;
    hit.send(&me, idx)?;
    expect_frame(&me, &hit, idx)?;
    expect_none(&[&me])
}

/// Three sockets with different filters that all match each get a copy;
/// a fourth whose filter does not match gets none.
fn fanout_three_sockets(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let f = Frame::std(0x2A5, &[9, 8, 7, 6]);
    let socks = [
        ctx.bound(f.arb, CAN_MASK_EXACT, idx)?,
        ctx.bound(arb_std(0x2A0, false), arb_std(0xF, false) | 1, idx)?,
        ctx.bound(0, CAN_MASK_ANY, 0)?,
    ];
    let other = ctx.bound(arb_std(0x2A6, false), CAN_MASK_EXACT, idx)?;
    let tx = ctx.socket()?;
    f.send(&tx, idx)?;
    for (i, s) in socks.iter().enumerate() {
        expect_frame(s, &f, idx).map_err(|e| format!("socket #{i}: {e}"))?;
    }
    let [a, b, c] = &socks;
    expect_none(&[a, b, c, &other, &tx])
}

/// connect + write: every DLC, then a remote frame.
fn connect_write(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let tx = ctx.socket()?;
    let frames = all_dlcs(|d| Frame::ext(0x0ABC_0123, d));
    tx.connect(frames[0].arb, idx).or_fail("connect")?;
    for f in &frames {
        let n = tx.write(&f.data).or_fail("write")?;
        ensure!(n == f.data.len(), "write returned {n}");
    }
    expect_frames(&rx, &frames, idx)?;
    let r = Frame::remote_std(0x77, 6);
    tx.connect(r.arb, idx).or_fail("connect (remote)")?;
    tx.write(&r.tx_bytes()).or_fail("write (remote)")?;
    expect_frame(&rx, &r, idx)?;
    expect_none(&[&rx, &tx])
}

/// connect + send and sendmsg without address; connecting again replaces
/// the destination.
fn connect_send(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let tx = ctx.socket()?;
    let a = Frame::std(0x0AA, &[0xAA; 3]);
    let b = Frame::std(0x0BB, &[0xBB; 8]);
    tx.connect(a.arb, idx).or_fail("connect")?;
    tx.send(&a.data).or_fail("send")?;
    tx.send_msg(&[IoSlice::new(&a.data)], None, 0)
        .or_fail("sendmsg without address")?;
    tx.connect(b.arb, 0).or_fail("connect again (ifindex 0)")?;
    tx.send(&b.data).or_fail("send after reconnect")?;
    expect_frames(&rx, &[a.clone(), a, b], idx)?;
    expect_none(&[&rx])
}

/// send/write/sendmsg without destination fail with EDESTADDRREQ.
fn connect_required(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let tx = ctx.socket()?;
    expect_errno(tx.write(&[1]), libc::EDESTADDRREQ, "write before connect")?;
    expect_errno(tx.send(&[1]), libc::EDESTADDRREQ, "send before connect")?;
    expect_errno(
        tx.send_msg(&[IoSlice::new(&[1])], None, 0),
        libc::EDESTADDRREQ,
        "sendmsg without address before connect",
    )?;
    expect_none(&[&rx])
}

/// connect(AF_UNSPEC) dissolves the association.
fn connect_unspec_dissolves(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let tx = ctx.socket()?;
    let f = Frame::std(0x5, &[5]);
    tx.connect(f.arb, idx).or_fail("connect")?;
    tx.write(&f.data).or_fail("write while connected")?;
    expect_frame(&rx, &f, idx)?;
    tx.disconnect().or_fail("connect(AF_UNSPEC)")?;
    expect_errno(tx.write(&[1]), libc::EDESTADDRREQ, "write after AF_UNSPEC")?;
    expect_errno(
        tx.peer_addr(),
        libc::ENOTCONN,
        "getpeername after AF_UNSPEC",
    )?;
    // sendto still works on the dissolved socket.
    f.send(&tx, idx)?;
    let rxd = recv_frame(&rx)?;
    ensure!(rxd.frame == f, "after AF_UNSPEC sendto: got {}", rxd.frame);
    expect_none(&[&rx])
}
