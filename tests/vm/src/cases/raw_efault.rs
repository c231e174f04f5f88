// SPDX-License-Identifier: GPL-2.0
//! Bad user pointers on CAN_RAW: every call that copies from or to user
//! memory gets EFAULT for an inaccessible buffer, without side effects on
//! the socket's options, and the socket keeps working.

use socketcan::SocketOptions;

use super::{portable_table, raw1};
use crate::canraw::{
    self, addr_bytes, expect, filters, opt_name, std, CAN_MTU, CAN_RAW_ERR_FILTER,
    CAN_RAW_FD_FRAMES, CAN_RAW_FILTER, CAN_RAW_JOIN_FILTERS, CAN_RAW_LOOPBACK,
    CAN_RAW_RECV_OWN_MSGS, SOL_CAN_RAW,
};
use crate::check::{ensure, expect_errno, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::sys;
use crate::Test;
use rcan_uapi::raw;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_efault_send_recv,
    raw_efault_sockopt_bind,
];

const AF_CAN: u16 = libc::AF_CAN as u16;

/// write, sendto from and recv, recvfrom into inaccessible memory: EFAULT.
fn raw_efault_send_recv(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    expect_errno(
        sys::write_fault(&tx, CAN_MTU),
        libc::EFAULT,
        "write from an inaccessible buffer",
    )?;
    expect_errno(
        raw::sendto_fault(&tx, CAN_MTU, 0, &addr_bytes(AF_CAN, idx)),
        libc::EFAULT,
        "sendto from an inaccessible buffer",
    )?;
    // Nothing was sent: the first frame rx sees is the next one.
    let f = std(0x61, &[1]);
    canraw::send(&tx, &f)?;
    expect(&rx, &f, "receiver after the faulting sends")?;

    canraw::send(&tx, &std(0x62, &[2]))?;
    expect_errno(
        raw::recv_fault(&rx, CAN_MTU, 0),
        libc::EFAULT,
        "recv into an inaccessible buffer",
    )?;
    canraw::send(&tx, &std(0x63, &[3]))?;
    let mut buf = [0u8; CAN_MTU];
    expect_errno(
        raw::recvfrom_addr_fault(&rx, &mut buf, 0),
        libc::EFAULT,
        "recvfrom into an inaccessible address",
    )?;
    // Whether a frame that could not be copied out is dropped or stays
    // queued is not part of the ABI; the socket must go on working.
    let g = std(0x64, &[4]);
    canraw::send(&tx, &g)?;
    for _ in 0..3 {
        let got = canraw::recv(&rx).map_err(|e| format!("after the faulting receives: {e}"))?;
        if canraw::same(&got, &g) {
            return Ok(());
        }
        ensure!(
            [0x62, 0x63].contains(&(got.as_ref() as &libc::can_frame).can_id),
            "after the faulting receives: unexpected {}",
            canraw::show(&got)
        );
    }
    Err(format!(
        "after the faulting receives: {} did not arrive",
        canraw::show(&g)
    ))
}

/// setsockopt from, getsockopt into, getsockopt's optlen at and bind from
/// inaccessible memory: EFAULT, and the filters and the error mask keep
/// their values. (Not the int options: mainline copies them in place, and
/// a faulting copy leaves them zeroed.)
fn raw_efault_sockopt_bind(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    s.set_filters(&[(0x70, 0x7F0)]).or_fail("set filter")?;
    for (name, len) in [
        (CAN_RAW_FILTER, 8),
        (CAN_RAW_FILTER, 16),
        (CAN_RAW_ERR_FILTER, 4),
        (CAN_RAW_LOOPBACK, 4),
        (CAN_RAW_RECV_OWN_MSGS, 4),
        (CAN_RAW_FD_FRAMES, 4),
        (CAN_RAW_JOIN_FILTERS, 4),
    ] {
        expect_errno(
            sys::setsockopt_fault(&s, SOL_CAN_RAW, name, len),
            libc::EFAULT,
            &format!(
                "setsockopt {} optlen {len} from an inaccessible buffer",
                opt_name(name)
            ),
        )?;
    }
    for (name, len) in [
        (CAN_RAW_FILTER, 8),
        (CAN_RAW_LOOPBACK, 4),
        (CAN_RAW_ERR_FILTER, 4),
    ] {
        expect_errno(
            sys::getsockopt_val_fault(&s, SOL_CAN_RAW, name, len),
            libc::EFAULT,
            &format!("getsockopt {} into an inaccessible buffer", opt_name(name)),
        )?;
        expect_errno(
            sys::getsockopt_len_fault(&s, SOL_CAN_RAW, name),
            libc::EFAULT,
            &format!("getsockopt {} with an inaccessible optlen", opt_name(name)),
        )?;
    }
    let u = canraw::unbound()?;
    expect_errno(
        raw::bind_fault(&u, 24),
        libc::EFAULT,
        "bind from an inaccessible address",
    )?;

    let f = filters(&s)?;
    ensure!(f == [(0x70, 0x7F0)], "filters changed to {f:08X?}");
    ensure!(
        s.error_filter().or_fail("getsockopt CAN_RAW_ERR_FILTER")? == 0,
        "CAN_RAW_ERR_FILTER changed"
    );
    let f = std(0x71, &[1]);
    canraw::send(&tx, &f)?;
    expect(&s, &f, "socket after the faulting calls")
}
