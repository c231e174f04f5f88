// SPDX-License-Identifier: GPL-2.0
//! Sending on CAN_RAW with bad input, byte by byte: writes that are not
//! exactly one classic frame, frames with more than 8 data bytes, sending
//! on an unbound socket, and sendto with bad addresses. Each gets mainline's
//! errno and nothing malformed reaches a receiver.

use std::io::{IoSlice, IoSliceMut};

use socketcan::Socket;

use super::{portable_table, raw1};
use crate::canraw::{
    self, addr_bytes, expect_seq, ext, frame_of_len, std, wire, write_bytes, CAN_MTU, MIN_NAMELEN,
};
use crate::check::{ensure, expect_errno, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::Test;
use rcan_uapi::raw;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_send_bad_size,
    raw_send_len_over_8,
    raw_send_unbound,
    raw_sendto_addresses,
    raw_send_iovecs,
];

const AF_CAN: u16 = libc::AF_CAN as u16;

/// Writes of any size but 16 bytes (CAN FD frames are off) are EINVAL,
/// through write and send; a 16-byte write then goes through alone.
fn raw_send_bad_size(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let f = std(0x123, &[1, 2, 3, 4]);
    for len in [0, 1, 8, 12, 13, 15, 17, 24, 64, 72, 73, 2061, 4096] {
        let b = frame_of_len(&f, len);
        expect_errno(
            write_bytes(&tx, &b),
            libc::EINVAL,
            &format!("write of {len} bytes"),
        )?;
        expect_errno(
            raw::sendto(&tx, &b, 0, None),
            libc::EINVAL,
            &format!("send of {len} bytes"),
        )?;
    }
    let n = write_bytes(&tx, &wire(&f)).or_fail("write of 16 bytes")?;
    ensure!(n == CAN_MTU, "write of 16 bytes returned {n}");
    let marker = std(0x7FF, &[0xEE]);
    canraw::send(&tx, &marker)?;
    expect_seq(&rx, &[f, marker], "receiver")?;
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// A 16-byte frame whose len field is above 8 is EINVAL.
fn raw_send_len_over_8(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    for base in [std(0x10, &[0; 8]), ext(0x10, &[0; 8])] {
        for len in [9u8, 15, 16, 255] {
            let mut b = wire(&base);
            b[4] = len;
            expect_errno(
                write_bytes(&tx, &b),
                libc::EINVAL,
                &format!("write of {} with len {len}", canraw::show(&base)),
            )?;
        }
    }
    let ok = ext(0x10, &[8; 8]);
    canraw::send(&tx, &ok)?;
    expect_seq(&rx, &[ok], "receiver")?;
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// An unbound socket has no interface: write is ENXIO (also for a frame
/// that is malformed besides), but sendto with an address works.
fn raw_send_unbound(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let u = canraw::unbound()?;
    let rx = canraw::open(idx)?;
    let f = std(0x20, &[2]);
    expect_errno(
        write_bytes(&u, &wire(&f)),
        libc::ENXIO,
        "write on an unbound socket",
    )?;
    expect_errno(
        u.write_frame(&f),
        libc::ENXIO,
        "write_frame on an unbound socket",
    )?;
    expect_errno(
        write_bytes(&u, &frame_of_len(&f, 15)),
        libc::ENXIO,
        "write of 15 bytes on an unbound socket",
    )?;
    let n = raw::sendto(&u, &wire(&f), 0, Some(&addr_bytes(AF_CAN, idx)))
        .or_fail("sendto can0 from an unbound socket")?;
    ensure!(n == CAN_MTU, "sendto returned {n}");
    expect_seq(&rx, &[f], "receiver")?;
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// sendto: an address shorter than 8 bytes or not AF_CAN is EINVAL; ifindex
/// 0 or unknown is ENXIO; a non-CAN interface (lo) is EPERM. 8 bytes of
/// address are enough; a socket bound to all interfaces sends where the
/// address says.
fn raw_sendto_addresses(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let lo = ctx.ifindex("lo")?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let f = std(0x30, &[3]);
    let b = wire(&f);
    let good = addr_bytes(AF_CAN, idx);
    for len in [1, 2, 4, 7] {
        expect_errno(
            raw::sendto(&tx, &b, 0, Some(&good[..len])),
            libc::EINVAL,
            &format!("sendto with addrlen {len}"),
        )?;
    }
    for family in [libc::AF_INET as u16, libc::AF_UNSPEC as u16] {
        expect_errno(
            raw::sendto(&tx, &b, 0, Some(&addr_bytes(family, idx))),
            libc::EINVAL,
            &format!("sendto with family {family}"),
        )?;
    }
    expect_errno(
        raw::sendto(&tx, &b, 0, Some(&addr_bytes(AF_CAN, 0))),
        libc::ENXIO,
        "sendto ifindex 0",
    )?;
    expect_errno(
        raw::sendto(&tx, &b, 0, Some(&addr_bytes(AF_CAN, 999_999))),
        libc::ENXIO,
        "sendto unknown ifindex 999999",
    )?;
    expect_errno(
        raw::sendto(&tx, &b, 0, Some(&addr_bytes(AF_CAN, lo))),
        libc::EPERM,
        "sendto lo",
    )?;
    let n = raw::sendto(&tx, &b, 0, Some(&good[..MIN_NAMELEN])).or_fail("sendto addrlen 8")?;
    ensure!(n == CAN_MTU, "sendto addrlen 8 returned {n}");
    let g = std(0x31, &[4]);
    raw::sendto(&tx, &wire(&g), 0, Some(&good)).or_fail("sendto addrlen 24")?;
    expect_seq(&rx, &[f, g], "receiver")?;
    let all = canraw::open(0)?;
    let h = std(0x32, &[5]);
    raw::sendto(&all, &wire(&h), 0, Some(&good))
        .or_fail("sendto can0 from a socket bound to all")?;
    expect_seq(&rx, &[h], "receiver")?;
    canraw::expect_quiet(&[("receiver", &rx)])
}

/// sendmsg gathering a frame from two pieces (with and without an address)
/// and recvmsg scattering one into two pieces move the same 16 bytes.
fn raw_send_iovecs(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    let f = ext(0x0ABC_DEF0, &[1, 2, 3, 4, 5, 6, 7, 8]);
    let w = wire(&f);
    for (split, addr) in [(4, None), (11, Some(addr_bytes(AF_CAN, idx)))] {
        let iov = [IoSlice::new(&w[..split]), IoSlice::new(&w[split..])];
        let n = raw::sendmsg(&tx, &iov, addr.as_ref().map(|a| &a[..]), 0).or_fail(format_args!(
            "sendmsg in pieces of {split} and {}",
            CAN_MTU - split
        ))?;
        ensure!(n == CAN_MTU, "sendmsg returned {n}");
        let (mut a, mut b) = ([0xAAu8; 10], [0xAAu8; 10]);
        let mut into = [IoSliceMut::new(&mut a), IoSliceMut::new(&mut b[..6])];
        let mut name = [0u8; 24];
        let (n, _, _) =
            raw::recvmsg(&rx, &mut into, &mut name, 0).or_fail("recvmsg into 10 + 6 bytes")?;
        let got: Vec<u8> = a.iter().chain(&b[..6]).copied().collect();
        ensure!(
            n == CAN_MTU && got == w && b[6..] == [0xAA; 4],
            "sent in pieces of {split} and {}, received {n} bytes into 10 + 6: {}",
            CAN_MTU - split,
            canraw::show_wire(&got)
        );
    }
    canraw::expect_quiet(&[("receiver", &rx)])
}
