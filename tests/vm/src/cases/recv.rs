// SPDX-License-Identifier: GPL-2.0
//! Receive semantics: truncation, MSG_TRUNC, MSG_PEEK, non-blocking and
//! timed-out receives, and the exact bytes of the source address.

use std::time::Duration;

use rcan_uapi::{raw, AF_CAN, CAN_MASK_ANY};

use super::{stack1, test_table};
use crate::check::{ensure, expect_errno, expect_frame, expect_none, Frame, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::Test;

pub const TESTS: &[Test] = test_table![
    stack:
    recv_short_buffer,
    recv_peek,
    recv_dontwait_eagain,
    recv_rcvtimeo_eagain,
    recvfrom_address,
];

const EIGHT: [u8; 8] = [0x10, 0x21, 0x32, 0x43, 0x54, 0x65, 0x76, 0x87];

/// A 3-byte buffer gets the first 3 bytes of an 8-byte frame and the rest
/// is lost; recvmsg flags MSG_TRUNC; the MSG_TRUNC request flag makes recv
/// return the full DLC; the next recv gets the next frame.
fn recv_short_buffer(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let frames = [
        Frame::std(0x101, &EIGHT),
        Frame::ext(0x102, &EIGHT),
        Frame::std(0x103, &EIGHT),
        Frame::std(0x104, &EIGHT[..6]),
        Frame::std(0x105, &EIGHT),
    ];
    for f in &frames {
        f.send(&tx, idx)?;
    }

    let mut buf = [0xAAu8; 8];
    let (n, a) = rx.recv_from(&mut buf[..3]).or_fail("recvfrom len 3")?;
    ensure!(n == 3, "recvfrom len 3 of an 8-byte frame returned {n}");
    ensure!(a.arb == frames[0].arb, "recvfrom len 3: arb {:#x}", a.arb);
    ensure!(
        buf[..3] == EIGHT[..3] && buf[3..].iter().all(|&b| b == 0xAA),
        "recvfrom len 3: buffer {buf:02X?}"
    );

    let mut buf = [0xAAu8; 8];
    let m = rx.recv_msg_buf(&mut buf[..3], 0).or_fail("recvmsg len 3")?;
    ensure!(m.len == 3, "recvmsg len 3 returned {}", m.len);
    ensure!(
        m.addr.arb == frames[1].arb,
        "recvmsg len 3: arb {:#x}",
        m.addr.arb
    );
    ensure!(
        m.flags & libc::MSG_TRUNC != 0,
        "recvmsg len 3 of an 8-byte frame: MSG_TRUNC not in msg_flags ({:#x})",
        m.flags
    );

    let mut buf = [0xAAu8; 8];
    let n = rx
        .recv(&mut buf[..3], libc::MSG_TRUNC)
        .or_fail("recv len 3 with MSG_TRUNC")?;
    ensure!(
        n == 8,
        "recv len 3 with MSG_TRUNC returned {n}, expected the DLC 8"
    );
    ensure!(
        buf[..3] == EIGHT[..3] && buf[3..].iter().all(|&b| b == 0xAA),
        "recv len 3 with MSG_TRUNC: buffer {buf:02X?}"
    );

    let mut buf = [0u8; 8];
    let m = rx.recv_msg_buf(&mut buf, 0).or_fail("recvmsg len 8")?;
    ensure!(
        m.len == 6 && buf[..6] == EIGHT[..6] && m.addr.arb == frames[3].arb,
        "next recvmsg: {} bytes {:02X?} arb {:#x}, expected {}",
        m.len,
        &buf[..m.len.min(8)],
        m.addr.arb,
        frames[3]
    );
    ensure!(
        m.flags & libc::MSG_TRUNC == 0,
        "recvmsg of a 6-byte frame into 8 bytes: MSG_TRUNC set"
    );
    expect_frame(&rx, &frames[4], idx)?;
    expect_none(&[&rx])
}

/// MSG_PEEK returns the head frame without consuming it.
fn recv_peek(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    expect_errno(
        rx.recv_from_flags(&mut [0; 8], libc::MSG_PEEK | libc::MSG_DONTWAIT),
        libc::EAGAIN,
        "MSG_PEEK|MSG_DONTWAIT on an empty queue",
    )?;
    let f1 = Frame::ext(0x1234_5678, &[1, 2, 3, 4, 5]);
    let f2 = Frame::std(0x321, &[6]);
    f1.send(&tx, idx)?;
    f2.send(&tx, idx)?;
    for (i, len) in [(1, 8), (2, 2), (3, 8)] {
        let mut buf = [0u8; 8];
        let (n, a) = rx
            .recv_from_flags(&mut buf[..len], libc::MSG_PEEK)
            .or_fail(format_args!("MSG_PEEK #{i}"))?;
        let want = &f1.data[..len.min(f1.data.len())];
        ensure!(
            a.arb == f1.arb && &buf[..n] == want && a.ifindex == idx,
            "MSG_PEEK #{i} (len {len}): {n} bytes {:02X?} arb {:#x}, expected {f1}",
            &buf[..n],
            a.arb
        );
    }
    expect_frame(&rx, &f1, idx)?;
    expect_frame(&rx, &f2, idx)?;
    expect_none(&[&rx])
}

/// An empty queue: MSG_DONTWAIT and O_NONBLOCK give EAGAIN at once.
fn recv_dontwait_eagain(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    // Long timeout: if MSG_DONTWAIT were ignored, the watchdog would see it.
    rx.set_rcvtimeo(Duration::from_secs(30))
        .or_fail("SO_RCVTIMEO")?;
    let mut buf = [0u8; 8];
    expect_errno(
        rx.recv(&mut buf, libc::MSG_DONTWAIT),
        libc::EAGAIN,
        "recv MSG_DONTWAIT",
    )?;
    expect_errno(
        rx.recv_msg_buf(&mut buf, libc::MSG_DONTWAIT),
        libc::EAGAIN,
        "recvmsg MSG_DONTWAIT",
    )?;
    rx.set_nonblocking(true).or_fail("O_NONBLOCK")?;
    expect_errno(rx.read(&mut buf), libc::EAGAIN, "read with O_NONBLOCK")?;
    expect_errno(
        rx.recv_from(&mut buf),
        libc::EAGAIN,
        "recvfrom with O_NONBLOCK",
    )?;
    // Still a working socket afterwards.
    let f = Frame::std(0x7, &[7]);
    f.send(&rx, idx)?;
    rx.set_nonblocking(false).or_fail("clear O_NONBLOCK")?;
    rx.set_rcvtimeo(crate::check::RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")?;
    expect_frame(&rx, &f, idx)
}

/// SO_RCVTIMEO expiry gives EAGAIN (== EWOULDBLOCK).
fn recv_rcvtimeo_eagain(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let t = Duration::from_millis(300);
    rx.set_rcvtimeo(t).or_fail("SO_RCVTIMEO")?;
    let got = rx.rcvtimeo().or_fail("getsockopt SO_RCVTIMEO")?;
    ensure!(got == t, "SO_RCVTIMEO reads back as {got:?}");
    let mut buf = [0u8; 8];
    expect_errno(
        rx.recv_from(&mut buf),
        libc::EAGAIN,
        "recvfrom after SO_RCVTIMEO",
    )?;
    expect_errno(rx.read(&mut buf), libc::EAGAIN, "read after SO_RCVTIMEO")?;
    expect_errno(
        rx.recv_msg_buf(&mut buf, 0),
        libc::EAGAIN,
        "recvmsg after SO_RCVTIMEO",
    )
}

/// The source address byte by byte: family, zero padding, arb, mask 0,
/// ifindex, addrlen 16; nothing written past 16 bytes; a short address
/// buffer gets a prefix and the full length.
fn recvfrom_address(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let frames = [
        Frame::std(0x7FF, &[1]),
        Frame::remote_ext(0x1FFF_FFFF, 8),
        Frame::ext(0, &[]),
    ];
    for f in &frames {
        f.send(&tx, idx)?;
    }
    let mut want = [0u8; 16];
    for (i, f) in frames.iter().enumerate() {
        want[0..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        want[4..8].copy_from_slice(&f.arb.to_ne_bytes());
        want[12..16].copy_from_slice(&idx.to_ne_bytes());
        let mut addr = [0xAAu8; 20];
        let mut buf = [0u8; 8];
        let (addr_used, n, alen) = if i < 2 {
            let (n, alen) = raw::recvfrom(&rx, &mut buf, 0, Some(&mut addr))
                .or_fail(format_args!("recvfrom (waiting for {f})"))?;
            (20, n, alen)
        } else {
            // Room for only 8 address bytes: truncated copy, full length.
            let (n, alen) = raw::recvfrom(&rx, &mut buf, 0, Some(&mut addr[..8]))
                .or_fail(format_args!("recvfrom (waiting for {f})"))?;
            (8, n, alen)
        };
        ensure!(n == f.data.len(), "{f}: recvfrom returned {n}");
        ensure!(alen == 16, "{f}: addrlen {alen}, expected 16");
        ensure!(
            addr[..addr_used.min(16)] == want[..addr_used.min(16)],
            "{f}: address bytes {:02X?}, expected {:02X?} (bytes 2-3 are padding and must be 0)",
            &addr[..16],
            want
        );
        ensure!(
            addr[addr_used.min(16)..].iter().all(|&b| b == 0xAA),
            "{f}: recvfrom wrote past the address it may use: {addr:02X?}"
        );
    }
    expect_none(&[&rx])
}
