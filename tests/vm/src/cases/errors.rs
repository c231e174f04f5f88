// SPDX-License-Identifier: GPL-2.0
//! Every error of the API: bad addresses, bad frames, bad interfaces,
//! faulting pointers, unsupported flags, calls and option levels.

use std::io::IoSlice;

use rcan_uapi::{arb_std, raw, ArbSocket, SockaddrCanArb, CAN_MASK_ANY, CAN_MASK_EXACT};

use super::{stack1, test_table};
use crate::check::{ensure, expect_errno, expect_frame, expect_none, Frame, OrFail, TestResult};
use crate::ctx::{dev, Ctx};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    stack:
    err_addrlen_short,
    err_family,
    err_arb_unused_bit,
    err_std_arb_with_ext_bits,
    err_dlc_too_long,
    err_unknown_ifindex,
    err_non_can_ifindex,
    err_interface_down,
    err_efault,
    err_msg_oob,
    err_listen_accept,
    err_sockopt_level,
];

/// bind, connect and sendto with the raw address `addr`, all expecting
/// `errno`.
fn all_addr_calls(s: &ArbSocket, addr: &[u8], errno: i32, what: &str) -> TestResult {
    expect_errno(raw::bind(s, addr), errno, &format!("bind {what}"))?;
    expect_errno(raw::connect(s, addr), errno, &format!("connect {what}"))?;
    expect_errno(
        raw::sendto(s, &[1, 2], 0, Some(addr)),
        errno,
        &format!("sendto {what}"),
    )
}

/// addrlen 15 (one byte short) is EINVAL; so are 2 and 0 for bind.
fn err_addrlen_short(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.socket()?;
    let good = SockaddrCanArb::new(arb_std(0x10, false), CAN_MASK_EXACT, idx).to_bytes();
    all_addr_calls(&s, &good[..15], libc::EINVAL, "with addrlen 15")?;
    expect_errno(
        raw::bind(&s, &good[..2]),
        libc::EINVAL,
        "bind with addrlen 2",
    )?;
    expect_errno(raw::bind(&s, &[]), libc::EINVAL, "bind with addrlen 0")?;
    // The full 16 bytes work.
    raw::bind(&s, &good).or_fail("bind with addrlen 16")?;
    raw::connect(&s, &good).or_fail("connect with addrlen 16")?;
    raw::sendto(&s, &[1], 0, Some(&good)).or_fail("sendto with addrlen 16")?;
    Ok(())
}

/// family AF_INET is EINVAL for bind/connect/sendto; AF_UNSPEC too, except
/// for connect.
fn err_family(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.socket()?;
    let mut a = SockaddrCanArb::new(arb_std(0x10, false), CAN_MASK_EXACT, idx);
    a.family = libc::AF_INET as u16;
    all_addr_calls(&s, &a.to_bytes(), libc::EINVAL, "with family AF_INET")?;
    a.family = 0;
    let b = a.to_bytes();
    expect_errno(
        raw::bind(&s, &b),
        libc::EINVAL,
        "bind with family AF_UNSPEC",
    )?;
    expect_errno(
        raw::sendto(&s, &[1], 0, Some(&b)),
        libc::EINVAL,
        "sendto with family AF_UNSPEC",
    )?;
    raw::connect(&s, &b).or_fail("connect with family AF_UNSPEC")
}

/// Arbitration field bit 0 set is EINVAL.
fn err_arb_unused_bit(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.socket()?;
    for arb in [arb_std(0x10, false) | 1, Frame::ext(0x10, &[]).arb | 1, 1] {
        let a = SockaddrCanArb::new(arb, CAN_MASK_ANY, idx).to_bytes();
        all_addr_calls(&s, &a, libc::EINVAL, &format!("with arb {arb:#010x}"))?;
    }
    Ok(())
}

/// A standard arbitration field (IDE clear) with extension bits set is
/// EINVAL for sendto and connect.
fn err_std_arb_with_ext_bits(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.socket()?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    for bits in [0x8, 0x0010_0000, 0x001F_FFF8] {
        let arb = arb_std(0x123, false) | bits;
        expect_errno(
            s.send_to(&[1], arb, idx),
            libc::EINVAL,
            &format!("sendto arb {arb:#010x}"),
        )?;
        expect_errno(
            s.connect(arb, idx),
            libc::EINVAL,
            &format!("connect arb {arb:#010x}"),
        )?;
    }
    expect_none(&[&rx])
}

/// More than 8 data bytes is EINVAL for sendto, send, write and sendmsg,
/// also for remote frames.
fn err_dlc_too_long(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let s = ctx.socket()?;
    let nine = [0x99u8; 9];
    let arb = arb_std(0x99, false);
    expect_errno(s.send_to(&nine, arb, idx), libc::EINVAL, "sendto 9 bytes")?;
    expect_errno(
        s.send_to(&[0; 64], arb, idx),
        libc::EINVAL,
        "sendto 64 bytes",
    )?;
    expect_errno(
        s.send_to(&nine, arb_std(0x99, true), idx),
        libc::EINVAL,
        "sendto remote frame with length 9",
    )?;
    expect_errno(
        s.send_msg(
            &[IoSlice::new(&nine[..5]), IoSlice::new(&nine[5..])],
            Some((arb, idx)),
            0,
        ),
        libc::EINVAL,
        "sendmsg 5+4 bytes",
    )?;
    s.connect(arb, idx).or_fail("connect")?;
    expect_errno(s.send(&nine), libc::EINVAL, "send 9 bytes")?;
    expect_errno(s.write(&nine), libc::EINVAL, "write 9 bytes")?;
    expect_none(&[&rx])
}

/// An ifindex that does not exist is ENODEV.
fn err_unknown_ifindex(ctx: &mut Ctx) -> TestResult {
    stack1(ctx)?;
    let bad = (9999..)
        .find(|&i| rcan_uapi::ifname(i).is_err())
        .unwrap_or(9999);
    let s = ctx.socket()?;
    expect_errno(
        s.send_to(&[1], arb_std(1, false), bad),
        libc::ENODEV,
        "sendto ifindex 9999",
    )?;
    expect_errno(
        s.bind(0, CAN_MASK_ANY, bad),
        libc::ENODEV,
        "bind ifindex 9999",
    )?;
    expect_errno(
        s.connect(arb_std(1, false), bad),
        libc::ENODEV,
        "connect ifindex 9999",
    )
}

/// The ifindex of a non-CAN interface (lo) is ENODEV.
fn err_non_can_ifindex(ctx: &mut Ctx) -> TestResult {
    stack1(ctx)?;
    let lo = ctx.ifindex("lo")?;
    let s = ctx.socket()?;
    expect_errno(
        s.send_to(&[1], arb_std(1, false), lo),
        libc::ENODEV,
        "sendto ifindex of lo",
    )?;
    expect_errno(
        s.bind(0, CAN_MASK_ANY, lo),
        libc::ENODEV,
        "bind ifindex of lo",
    )?;
    expect_errno(
        s.connect(arb_std(1, false), lo),
        libc::ENODEV,
        "connect ifindex of lo",
    )
}

/// Sending on an interface that is down is ENETDOWN (ifindex 0 too, when
/// every CAN interface is down); binding to it is allowed and works once
/// it is up.
fn err_interface_down(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let tx = ctx.socket()?;
    tx.connect(arb_std(0x44, false), idx).or_fail("connect")?;
    ctx.link_down(&dev(0))?;
    let rx = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let f = Frame::std(0x44, &[4]);
    expect_errno(
        tx.send_to(&f.data, f.arb, idx),
        libc::ENETDOWN,
        "sendto can0 (down)",
    )?;
    expect_errno(
        tx.send_to(&f.data, f.arb, 0),
        libc::ENETDOWN,
        "sendto ifindex 0 (all down)",
    )?;
    expect_errno(
        tx.write(&f.data),
        libc::ENETDOWN,
        "write connected to can0 (down)",
    )?;
    ctx.link_up(&dev(0))?;
    tx.write(&f.data).or_fail("write after link up")?;
    expect_frame(&rx, &f, idx)?;
    expect_none(&[&rx])
}

/// Pointers the kernel cannot access are EFAULT.
fn err_efault(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let dest = SockaddrCanArb::new(arb_std(0x77, false), 0, idx).to_bytes();
    expect_errno(
        raw::sendto_fault(&s, 8, 0, &dest),
        libc::EFAULT,
        "sendto with bad data pointer",
    )?;
    expect_errno(
        raw::bind_fault(&s, 16),
        libc::EFAULT,
        "bind with bad address pointer",
    )?;
    let f = Frame::std(0x77, &[7; 8]);
    f.send(&s, idx)?;
    f.send(&s, idx)?;
    expect_errno(
        raw::recv_fault(&s, 8, 0),
        libc::EFAULT,
        "recv into bad buffer",
    )?;
    let mut buf = [0u8; 8];
    expect_errno(
        raw::recvfrom_addr_fault(&s, &mut buf, 0),
        libc::EFAULT,
        "recvfrom with bad address pointer",
    )?;
    // The socket still works (whether the faulted frames were consumed is
    // not specified, so drain whatever is left).
    while s.recv(&mut buf, libc::MSG_DONTWAIT).is_ok() {}
    f.send(&s, idx)?;
    expect_frame(&s, &f, idx)
}

/// MSG_OOB is EOPNOTSUPP for sending and receiving; the queued frame stays.
fn err_msg_oob(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let f = Frame::std(0x1, &[1]);
    expect_errno(
        s.send_to_flags(&f.data, f.arb, idx, libc::MSG_OOB),
        libc::EOPNOTSUPP,
        "sendto MSG_OOB",
    )?;
    s.connect(f.arb, idx).or_fail("connect")?;
    expect_errno(
        s.send_flags(&f.data, libc::MSG_OOB),
        libc::EOPNOTSUPP,
        "send MSG_OOB",
    )?;
    f.send(&s, idx)?;
    let mut buf = [0u8; 8];
    expect_errno(
        s.recv(&mut buf, libc::MSG_OOB),
        libc::EOPNOTSUPP,
        "recv MSG_OOB",
    )?;
    expect_errno(
        s.recv_msg_buf(&mut buf, libc::MSG_OOB),
        libc::EOPNOTSUPP,
        "recvmsg MSG_OOB",
    )?;
    expect_frame(&s, &f, idx)?;
    expect_none(&[&s])
}

/// listen and accept are EOPNOTSUPP.
fn err_listen_accept(ctx: &mut Ctx) -> TestResult {
    let idx = stack1(ctx)?;
    let s = ctx.bound(0, CAN_MASK_ANY, idx)?;
    expect_errno(s.listen(1), libc::EOPNOTSUPP, "listen")?;
    expect_errno(s.accept(), libc::EOPNOTSUPP, "accept")
}

/// Options at a level other than SOL_SOCKET are ENOPROTOOPT; SOL_SOCKET
/// options work.
fn err_sockopt_level(ctx: &mut Ctx) -> TestResult {
    stack1(ctx)?;
    let s = ctx.socket()?;
    expect_errno(
        raw::setsockopt(&s, 1000, 1, &1i32.to_ne_bytes()),
        libc::ENOPROTOOPT,
        "setsockopt level 1000",
    )?;
    let mut v = [0u8; 4];
    expect_errno(
        raw::getsockopt(&s, 1000, 1, &mut v),
        libc::ENOPROTOOPT,
        "getsockopt level 1000",
    )?;
    raw::setsockopt(
        &s,
        libc::SOL_SOCKET,
        libc::SO_RCVBUF,
        &65536i32.to_ne_bytes(),
    )
    .or_fail("setsockopt SO_RCVBUF")?;
    let len = raw::getsockopt(&s, libc::SOL_SOCKET, libc::SO_RCVBUF, &mut v)
        .or_fail("getsockopt SO_RCVBUF")?;
    ensure!(
        len == 4 && i32::from_ne_bytes(v) > 0,
        "SO_RCVBUF reads {v:?}"
    );
    Ok(())
}
