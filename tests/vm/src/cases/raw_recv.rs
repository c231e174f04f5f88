// SPDX-License-Identifier: GPL-2.0
//! Receiving on CAN_RAW: every frame kind arrives unchanged, non-blocking
//! and timed-out reads, truncation, receive timestamps (SO_TIMESTAMP,
//! SO_TIMESTAMPNS, SIOCGSTAMP), and that no byte the kernel hands to user
//! space is undefined: padding of the frame, the address, `msg_namelen`.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use socketcan::{Socket, SocketOptions};

use super::{portable_table, raw1};
use crate::canraw::{
    self, addr_ifindex, expect, expect_seq, ext, rtr_ext, rtr_std, show_wire, std, within, CAN_MTU,
    MIN_NAMELEN,
};
use crate::check::{ensure, expect_errno, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::sys::{self, FILL};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_recv_frame_kinds,
    raw_recv_nonblocking,
    raw_recv_truncated,
    raw_recv_so_timestamp,
    raw_recv_so_timestampns,
    raw_recv_siocgstamp,
    raw_recv_defined_bytes,
];

/// Standard, extended and remote frames of every length, extreme ids,
/// arrive unchanged and in order.
fn raw_recv_frame_kinds(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let data = [0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88];
    let mut frames = Vec::new();
    for n in 0..=8 {
        frames.push(std(0x7FF - n as u16, &data[..n]));
        frames.push(ext(0x1FFF_FFFF - n as u32, &data[..n]));
        frames.push(rtr_std(n as u16, n));
        frames.push(rtr_ext(0x1000_0000 + n as u32, n));
    }
    frames.extend([std(0, &[]), ext(0, &[0xFF]), std(0x7FF, &[0; 8])]);
    for f in &frames {
        canraw::send(&tx, f)?;
    }
    expect_seq(&rx, &frames, "receiver")?;
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// An empty queue gives EAGAIN at once with O_NONBLOCK or MSG_DONTWAIT, and
/// after SO_RCVTIMEO; so does the (empty) error queue, MSG_ERRQUEUE; a
/// queued frame is read without blocking and MSG_PEEK leaves it queued.
fn raw_recv_nonblocking(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    // Long timeout: if the non-blocking requests were ignored, the
    // watchdog would report a hang.
    rx.set_read_timeout(Duration::from_secs(600))
        .or_fail("SO_RCVTIMEO")?;
    rx.set_nonblocking(true).or_fail("O_NONBLOCK")?;
    expect_errno(rx.read_frame(), libc::EAGAIN, "read_frame with O_NONBLOCK")?;
    rx.set_nonblocking(false).or_fail("clear O_NONBLOCK")?;
    expect_errno(
        sys::recvmsg(&rx, CAN_MTU, libc::MSG_DONTWAIT),
        libc::EAGAIN,
        "recvmsg MSG_DONTWAIT",
    )?;
    expect_errno(
        sys::recvmsg(&rx, CAN_MTU, libc::MSG_ERRQUEUE),
        libc::EAGAIN,
        "recvmsg MSG_ERRQUEUE",
    )?;
    rx.set_read_timeout(Duration::from_millis(100))
        .or_fail("SO_RCVTIMEO 100 ms")?;
    expect_errno(
        rx.read_frame(),
        libc::EAGAIN,
        "read_frame after SO_RCVTIMEO",
    )?;
    rx.set_read_timeout(canraw::RAW_RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")?;
    let f = std(0x11, &[1]);
    canraw::send(&tx, &f)?;
    // Wait for it blocking, then check that a non-blocking read finds the
    // next one once it is there.
    expect(&rx, &f, "receiver")?;
    let g = std(0x12, &[2]);
    canraw::send(&tx, &g)?;
    let peek = sys::recvmsg(&rx, CAN_MTU, libc::MSG_PEEK).or_fail("recvmsg MSG_PEEK")?;
    ensure!(
        peek.data[..CAN_MTU] == canraw::wire(&g),
        "MSG_PEEK returned {}",
        show_wire(&peek.data[..peek.len.min(CAN_MTU)])
    );
    rx.set_nonblocking(true).or_fail("O_NONBLOCK")?;
    let got = rx
        .read_frame()
        .or_fail("read_frame with O_NONBLOCK, frame queued")?;
    ensure!(
        canraw::same(&got, &g),
        "non-blocking read returned {}",
        canraw::show(&got)
    );
    expect_errno(
        rx.read_frame(),
        libc::EAGAIN,
        "read_frame with O_NONBLOCK again",
    )
}

/// A buffer shorter than the frame gets its first bytes, MSG_TRUNC in
/// msg_flags and the return value is the bytes copied, also with the
/// MSG_TRUNC request flag; the rest of the frame is gone and the next read
/// gets the next frame.
fn raw_recv_truncated(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let f1 = ext(0x0123_4567, &[1, 2, 3, 4, 5, 6, 7, 8]);
    let f2 = std(0x89, &[9]);
    canraw::send(&tx, &f1)?;
    canraw::send(&tx, &f2)?;
    let r = sys::recvmsg(&rx, 8, 0).or_fail("recvmsg into 8 bytes")?;
    ensure!(
        r.len == 8 && r.data[..8] == canraw::wire(&f1)[..8] && r.data[8..] == [FILL; 64],
        "recvmsg of {} into 8 bytes: returned {}, buffer {:02X?}",
        canraw::show(&f1),
        r.len,
        &r.data[..16]
    );
    ensure!(
        r.flags & libc::MSG_TRUNC != 0,
        "recvmsg into 8 bytes: no MSG_TRUNC in msg_flags {:#x}",
        r.flags
    );
    expect(&rx, &f2, "next read after the truncated one")?;
    // The MSG_TRUNC request flag does not change the return value (unlike
    // on datagram sockets, which return the full length).
    canraw::send(&tx, &f1)?;
    let r = sys::recvmsg(&rx, 8, libc::MSG_TRUNC).or_fail("recvmsg MSG_TRUNC into 8 bytes")?;
    ensure!(
        r.len == 8 && r.flags & libc::MSG_TRUNC != 0,
        "recvmsg with the MSG_TRUNC flag into 8 bytes: returned {}, msg_flags {:#x}; expected 8 and MSG_TRUNC",
        r.len,
        r.flags
    );
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// Seconds and nanoseconds to a SystemTime (negative: the epoch, which
/// `within` rejects).
fn system_time(sec: i64, nsec: i64) -> SystemTime {
    match (u64::try_from(sec), u32::try_from(nsec)) {
        (Ok(s), Ok(n)) => UNIX_EPOCH + Duration::new(s, n),
        _ => UNIX_EPOCH,
    }
}

/// SO_TIMESTAMP: every frame comes with an SCM_TIMESTAMP control message
/// holding a time between sending and receiving it.
fn raw_recv_so_timestamp(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    rx.set_socket_option_int(libc::SOL_SOCKET, libc::SO_TIMESTAMP, 1)
        .or_fail("SO_TIMESTAMP")?;
    let on = rx
        .get_socket_option_int(libc::SOL_SOCKET, libc::SO_TIMESTAMP)
        .or_fail("getsockopt SO_TIMESTAMP")?;
    ensure!(on == 1, "SO_TIMESTAMP reads {on} after setting 1");
    for i in 0..3u8 {
        let f = std(0x300 + u16::from(i), &[i]);
        let before = SystemTime::now();
        canraw::send(&tx, &f)?;
        let r = sys::recvmsg(&rx, CAN_MTU, 0).or_fail("recvmsg")?;
        let after = SystemTime::now();
        ensure!(
            r.data[..CAN_MTU] == canraw::wire(&f),
            "frame {i}: expected {}, got {}",
            canraw::show(&f),
            show_wire(&r.data[..r.len.min(CAN_MTU)])
        );
        let tv = r.timeval.ok_or_else(|| {
            format!(
                "frame {i}: no SCM_TIMESTAMP control message (got {:?})",
                r.cmsgs
            )
        })?;
        within(
            system_time(tv.tv_sec, tv.tv_usec * 1000),
            before,
            after,
            &format!("frame {i}: SCM_TIMESTAMP"),
        )?;
    }
    Ok(())
}

/// SO_TIMESTAMPNS through the crate (`read_frame_with_timestamp`) and
/// through recvmsg: an SCM_TIMESTAMPNS between sending and receiving.
fn raw_recv_so_timestampns(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    rx.set_recv_timestamp(true).or_fail("SO_TIMESTAMPNS")?;
    let f = ext(0x4000, &[4]);
    let before = SystemTime::now();
    canraw::send(&tx, &f)?;
    let (got, ts) = rx
        .read_frame_with_timestamp()
        .or_fail("read_frame_with_timestamp")?;
    let after = SystemTime::now();
    ensure!(
        canraw::same(&got, &f),
        "expected {}, got {}",
        canraw::show(&f),
        canraw::show(&got)
    );
    within(ts, before, after, "read_frame_with_timestamp")?;

    let g = std(0x401, &[5]);
    let before = SystemTime::now();
    canraw::send(&tx, &g)?;
    let r = sys::recvmsg(&rx, CAN_MTU, 0).or_fail("recvmsg")?;
    let after = SystemTime::now();
    let ts = r
        .timespec
        .ok_or_else(|| format!("no SCM_TIMESTAMPNS control message (got {:?})", r.cmsgs))?;
    within(
        system_time(ts.tv_sec, ts.tv_nsec),
        before,
        after,
        "SCM_TIMESTAMPNS",
    )?;
    ensure!(
        r.timeval.is_none(),
        "SCM_TIMESTAMP came without SO_TIMESTAMP"
    );
    Ok(())
}

/// SIOCGSTAMP and SIOCGSTAMPNS: ENOENT before any frame was read, then the
/// time of the last frame read (between its sending and the ioctl), not
/// going backwards.
fn raw_recv_siocgstamp(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    expect_errno(
        sys::siocgstamp(&rx),
        libc::ENOENT,
        "SIOCGSTAMP before any frame was read",
    )?;
    expect_errno(
        sys::siocgstampns(&rx),
        libc::ENOENT,
        "SIOCGSTAMPNS before any frame was read",
    )?;
    let mut last = UNIX_EPOCH;
    for i in 0..2u8 {
        let f = std(0x500 + u16::from(i), &[i]);
        let before = SystemTime::now();
        canraw::send(&tx, &f)?;
        expect(&rx, &f, "receiver")?;
        let tv = sys::siocgstamp(&rx).or_fail(format_args!("SIOCGSTAMP after frame {i}"))?;
        let ts = sys::siocgstampns(&rx).or_fail(format_args!("SIOCGSTAMPNS after frame {i}"))?;
        let after = SystemTime::now();
        let t = system_time(tv.tv_sec, tv.tv_usec * 1000);
        within(t, before, after, &format!("SIOCGSTAMP after frame {i}"))?;
        ensure!(t >= last, "SIOCGSTAMP went backwards after frame {i}");
        let tns = system_time(ts.tv_sec, ts.tv_nsec);
        within(tns, before, after, &format!("SIOCGSTAMPNS after frame {i}"))?;
        last = t;
    }
    Ok(())
}

/// Into buffers filled with 0xAA: the 16 bytes of each received frame are
/// exactly those sent (padding, len8_dlc and unused data bytes zero), the
/// address is 8 defined bytes (family, zero padding, ifindex) with
/// msg_namelen 8 and nothing written beyond, through recvmsg and recvfrom.
fn raw_recv_defined_bytes(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let frames = [
        std(0x123, &[]),
        std(0x7FF, &[1, 2, 3]),
        ext(0x1FFF_FFFF, &[1, 2, 3, 4, 5, 6, 7, 8]),
        rtr_std(0x10, 8),
        rtr_ext(0x20, 0),
    ];
    for f in &frames {
        canraw::send(&tx, f)?;
        let r =
            sys::recvmsg(&rx, 72, 0).or_fail(format_args!("recvmsg for {}", canraw::show(f)))?;
        let what = canraw::show(f);
        ensure!(
            r.len == CAN_MTU,
            "{what}: recvmsg returned {} bytes, expected {CAN_MTU}",
            r.len
        );
        ensure!(
            r.data[..CAN_MTU] == canraw::wire(f),
            "{what}: received {} ({:02X?})",
            show_wire(&r.data[..CAN_MTU]),
            &r.data[..CAN_MTU]
        );
        ensure!(
            r.data[CAN_MTU..].iter().all(|&b| b == FILL),
            "{what}: recvmsg wrote past the 16 bytes it returned"
        );
        ensure!(
            r.namelen == MIN_NAMELEN,
            "{what}: msg_namelen {}, expected {MIN_NAMELEN}",
            r.namelen
        );
        let got_idx = addr_ifindex(&r.name).map_err(|e| format!("{what}: {e}"))?;
        ensure!(
            got_idx == idx,
            "{what}: address ifindex {got_idx}, expected {idx}"
        );
        ensure!(
            r.name[MIN_NAMELEN..].iter().all(|&b| b == FILL),
            "{what}: address bytes past msg_namelen were written: {:02X?}",
            &r.name[MIN_NAMELEN..]
        );
    }
    // recvfrom reports the same length.
    let f = std(0x55, &[5]);
    canraw::send(&tx, &f)?;
    let mut buf = [FILL; CAN_MTU];
    let mut name = [FILL; sys::SOCKADDR_CAN_LEN];
    let (n, namelen) =
        rcan_uapi::raw::recvfrom(&rx, &mut buf, 0, Some(&mut name)).or_fail("recvfrom")?;
    ensure!(
        n == CAN_MTU && buf == canraw::wire(&f),
        "recvfrom: {}",
        show_wire(&buf[..n.min(CAN_MTU)])
    );
    ensure!(
        namelen as usize == MIN_NAMELEN,
        "recvfrom: addrlen {namelen}, expected {MIN_NAMELEN}"
    );
    ensure!(
        addr_ifindex(&name)? == idx && name[MIN_NAMELEN..].iter().all(|&b| b == FILL),
        "recvfrom address {name:02X?}"
    );
    Ok(())
}
