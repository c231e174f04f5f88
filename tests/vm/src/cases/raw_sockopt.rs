// SPDX-License-Identifier: GPL-2.0
//! CAN_RAW socket options at `SOL_CAN_RAW`: defaults, set and get back,
//! the filter limit, and the errno of every malformed `setsockopt` and
//! `getsockopt` (level, name, optlen), as mainline has them.

use socketcan::{CanAddr, CanSocket, Socket, SocketOptions};

use super::{portable_table, raw1};
use crate::canraw::{
    self, filter_bytes, filters, int_opt, opt_name, std, CAN_EFF_FLAG, CAN_EFF_MASK,
    CAN_ERR_BUSOFF, CAN_ERR_CRTL, CAN_ERR_MASK, CAN_INV_FILTER, CAN_MTU, CAN_RAW_ERR_FILTER,
    CAN_RAW_FD_FRAMES, CAN_RAW_FILTER, CAN_RAW_JOIN_FILTERS, CAN_RAW_LOOPBACK,
    CAN_RAW_RECV_OWN_MSGS, CAN_RTR_FLAG, CAN_SFF_MASK, FILTER_LEN, FILTER_MAX, SOL_CAN_RAW,
};
use crate::check::{ensure, expect_errno, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::sys;
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_sockopt_defaults,
    raw_sockopt_roundtrip,
    raw_sockopt_fd_frames,
    raw_sockopt_filter_max,
    raw_sockopt_filter_get_short_buffer,
    raw_sockopt_bad_optlen,
    raw_sockopt_bad_level_and_name,
    raw_sockopt_get_optlen,
];

/// The int options and their defaults (`CAN_RAW_LOOPBACK` on, the rest off).
const INT_OPTS: [(libc::c_int, i32); 4] = [
    (CAN_RAW_LOOPBACK, 1),
    (CAN_RAW_RECV_OWN_MSGS, 0),
    (CAN_RAW_FD_FRAMES, 0),
    (CAN_RAW_JOIN_FILTERS, 0),
];

/// Checks every option of `s` against the defaults of a new socket: one
/// filter receiving everything, no error frames, loopback on, the rest off.
fn check_defaults(s: &CanSocket, who: &str) -> TestResult {
    let f = filters(s)?;
    ensure!(
        f == [(0, 0)],
        "{who}: CAN_RAW_FILTER is {f:08X?}, expected the default [(0, 0)]"
    );
    let e = s.error_filter().or_fail("getsockopt CAN_RAW_ERR_FILTER")?;
    ensure!(e == 0, "{who}: CAN_RAW_ERR_FILTER is {e:#x}, expected 0");
    for (name, want) in INT_OPTS {
        let v = int_opt(s, name)?;
        ensure!(
            v == want,
            "{who}: {} is {v}, expected {want}",
            opt_name(name)
        );
    }
    Ok(())
}

/// A new socket, unbound and bound, reports the default options.
fn raw_sockopt_defaults(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    check_defaults(&canraw::unbound()?, "unbound socket")?;
    check_defaults(&canraw::open(idx)?, "socket bound to can0")?;
    check_defaults(&canraw::open(0)?, "socket bound to all interfaces")
}

/// Every option reads back what was set (integers as given), before and
/// after bind; the error mask keeps only the `CAN_ERR_MASK` bits.
fn raw_sockopt_roundtrip(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::unbound()?;
    let three = [
        (0x123, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG),
        (0x1234_5678 | CAN_EFF_FLAG, CAN_EFF_MASK | CAN_EFF_FLAG),
        (0x7 | CAN_INV_FILTER, 0x7),
    ];
    let set_and_check = |what: &str| -> TestResult {
        s.set_filters(&three).or_fail("set three filters")?;
        let f = filters(&s)?;
        ensure!(f == three, "{what}: three filters read back as {f:08X?}");
        s.set_filters(&[(0x100, 0x700)]).or_fail("set one filter")?;
        let f = filters(&s)?;
        ensure!(
            f == [(0x100, 0x700)],
            "{what}: one filter read back as {f:08X?}"
        );
        for mask in [CAN_ERR_BUSOFF | CAN_ERR_CRTL, CAN_ERR_MASK, 0] {
            s.set_error_filter(mask)
                .or_fail(format_args!("set CAN_RAW_ERR_FILTER {mask:#x}"))?;
            let e = s.error_filter().or_fail("getsockopt CAN_RAW_ERR_FILTER")?;
            ensure!(
                e == mask,
                "{what}: CAN_RAW_ERR_FILTER set to {mask:#x} reads {e:#x}"
            );
        }
        // Bits outside CAN_ERR_MASK (the flag bits) are dropped.
        s.set_error_filter(u32::MAX)
            .or_fail("set CAN_RAW_ERR_FILTER 0xFFFFFFFF")?;
        let e = s.error_filter().or_fail("getsockopt CAN_RAW_ERR_FILTER")?;
        ensure!(
            e == CAN_ERR_MASK,
            "{what}: CAN_RAW_ERR_FILTER set to 0xFFFFFFFF reads {e:#x}, expected {CAN_ERR_MASK:#x}"
        );
        for on in [false, true] {
            s.set_loopback(on).or_fail("set CAN_RAW_LOOPBACK")?;
            s.set_recv_own_msgs(!on)
                .or_fail("set CAN_RAW_RECV_OWN_MSGS")?;
            s.set_join_filters(!on)
                .or_fail("set CAN_RAW_JOIN_FILTERS")?;
            let got = [
                int_opt(&s, CAN_RAW_LOOPBACK)?,
                int_opt(&s, CAN_RAW_RECV_OWN_MSGS)?,
                int_opt(&s, CAN_RAW_JOIN_FILTERS)?,
            ];
            let want = [i32::from(on), i32::from(!on), i32::from(!on)];
            ensure!(
                got == want,
                "{what}: LOOPBACK, RECV_OWN_MSGS, JOIN_FILTERS read {got:?} after setting {want:?}"
            );
        }
        // Integers are kept as given, not squashed to 0/1.
        for (name, v) in [
            (CAN_RAW_LOOPBACK, 5),
            (CAN_RAW_RECV_OWN_MSGS, 7),
            (CAN_RAW_JOIN_FILTERS, 3),
            (CAN_RAW_LOOPBACK, 1),
            (CAN_RAW_RECV_OWN_MSGS, 0),
            (CAN_RAW_JOIN_FILTERS, 0),
        ] {
            s.set_socket_option_int(SOL_CAN_RAW, name, v)
                .or_fail(format_args!("set {} {v}", opt_name(name)))?;
            let got = int_opt(&s, name)?;
            ensure!(
                got == v,
                "{what}: {} set to {v} reads {got}",
                opt_name(name)
            );
        }
        s.set_socket_option_int(SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 0)
            .or_fail("set CAN_RAW_FD_FRAMES 0")?;
        ensure!(
            int_opt(&s, CAN_RAW_FD_FRAMES)? == 0,
            "{what}: CAN_RAW_FD_FRAMES set to 0 does not read 0"
        );
        Ok(())
    };
    set_and_check("unbound")?;
    // Options set before bind stay as they were.
    s.set_filters(&three).or_fail("set three filters")?;
    s.set_loopback(false).or_fail("set CAN_RAW_LOOPBACK 0")?;
    s.as_raw_socket()
        .bind(&CanAddr::new(idx).into_sock_addr())
        .or_fail("bind to can0")?;
    let f = filters(&s)?;
    ensure!(f == three, "filters set before bind read {f:08X?} after it");
    ensure!(
        int_opt(&s, CAN_RAW_LOOPBACK)? == 0,
        "CAN_RAW_LOOPBACK set to 0 before bind reads 1 after it"
    );
    set_and_check("bound")
}

/// CAN_RAW_FD_FRAMES, as mainline has it on a classic-only interface:
/// both 0 and 1 are accepted and read back, but with 1 a 72-byte CAN FD
/// frame is still refused (the interface's MTU is 16) and classic frames
/// are still read as 16 bytes.
fn raw_sockopt_fd_frames(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    s.set_socket_option_int(SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 0)
        .or_fail("set CAN_RAW_FD_FRAMES 0")?;
    ensure!(
        int_opt(&s, CAN_RAW_FD_FRAMES)? == 0,
        "CAN_RAW_FD_FRAMES 0 does not read back"
    );
    s.set_socket_option_int(SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 1)
        .or_fail("set CAN_RAW_FD_FRAMES 1")?;
    let v = int_opt(&s, CAN_RAW_FD_FRAMES)?;
    ensure!(v == 1, "CAN_RAW_FD_FRAMES set to 1 reads {v}");
    let fd_frame = canraw::frame_of_len(&std(0x123, &[1, 2, 3, 4, 5, 6, 7, 8]), canraw::CANFD_MTU);
    expect_errno(
        canraw::write_bytes(&s, &fd_frame),
        libc::EINVAL,
        "72-byte write with CAN_RAW_FD_FRAMES on a classic interface",
    )?;
    let f = std(0x321, &[9, 8, 7]);
    canraw::send(&tx, &f)?;
    let r = sys::recvmsg(&s, canraw::CANFD_MTU, 0).or_fail("recvmsg into 72 bytes")?;
    ensure!(
        r.len == CAN_MTU && r.data[..CAN_MTU] == canraw::wire(&f),
        "with CAN_RAW_FD_FRAMES, a classic frame read {} bytes: {}",
        r.len,
        canraw::show_wire(&r.data[..r.len.min(72)])
    );
    canraw::send(&s, &f).map_err(|e| format!("with CAN_RAW_FD_FRAMES on: {e}"))?;
    s.set_socket_option_int(SOL_CAN_RAW, CAN_RAW_FD_FRAMES, 0)
        .or_fail("set CAN_RAW_FD_FRAMES back to 0")?;
    ensure!(
        int_opt(&s, CAN_RAW_FD_FRAMES)? == 0,
        "CAN_RAW_FD_FRAMES back to 0 does not read 0"
    );
    Ok(())
}

/// 512 filters (CAN_RAW_FILTER_MAX) are accepted, read back and work; 513
/// are refused with EINVAL and leave the 512 in place.
fn raw_sockopt_filter_max(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    // Exact standard ids 0..511: 0x1FF passes, 0x200 does not.
    let max: Vec<(u32, u32)> = (0..FILTER_MAX as u32)
        .map(|i| (i, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG))
        .collect();
    rx.set_filters(&max).or_fail("set 512 filters")?;
    let got = filters(&rx)?;
    ensure!(
        got == max,
        "512 filters read back as {} filters (first differing: {:?})",
        got.len(),
        got.iter().zip(&max).position(|(a, b)| a != b)
    );
    let mut over = max.clone();
    over.push((0x200, CAN_SFF_MASK));
    expect_errno(
        rx.set_socket_option_bytes(SOL_CAN_RAW, CAN_RAW_FILTER, &filter_bytes(&over)),
        libc::EINVAL,
        "setsockopt CAN_RAW_FILTER with 513 filters",
    )?;
    let got = filters(&rx)?;
    ensure!(
        got == max,
        "after the refused 513 filters, {} filters read back, expected the 512",
        got.len()
    );
    let cases = [
        (std(0x200, &[1]), false),
        (std(0x000, &[2]), true),
        (std(0x600, &[3]), false),
        (std(0x1FF, &[4]), true),
    ];
    canraw::check_delivery(&tx, &rx, &cases, &std(0x0AB, &[5]), "512 filters")
}

/// getsockopt CAN_RAW_FILTER into a buffer smaller than the filters fails
/// with ERANGE, reports the length needed and writes nothing; a larger
/// buffer gets the filters and nothing past them; zero filters read as
/// length 0 and write nothing.
fn raw_sockopt_filter_get_short_buffer(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let three = [(1, 0x7FF), (2, 0x7FF), (3, 0x7FF)];
    s.set_filters(&three).or_fail("set three filters")?;
    let mut buf = [0xAAu8; 64];
    for len in [0, 8, 16, 23] {
        let (r, got) = sys::getsockopt_len(&s, SOL_CAN_RAW, CAN_RAW_FILTER, &mut buf, len);
        expect_errno(
            r,
            libc::ERANGE,
            &format!("getsockopt CAN_RAW_FILTER (3 filters) with optlen {len}"),
        )?;
        ensure!(
            got == 24,
            "getsockopt CAN_RAW_FILTER with optlen {len}: ERANGE reports optlen {got}, expected 24"
        );
        ensure!(
            buf == [0xAA; 64],
            "getsockopt CAN_RAW_FILTER with optlen {len} (ERANGE) wrote the buffer: {:02X?}",
            &buf[..24]
        );
    }
    let (r, got) = sys::getsockopt_len(&s, SOL_CAN_RAW, CAN_RAW_FILTER, &mut buf, 64);
    r.or_fail("getsockopt CAN_RAW_FILTER with optlen 64")?;
    ensure!(
        got == 24,
        "getsockopt of 3 filters with optlen 64 reports {got}"
    );
    ensure!(
        buf[..24] == filter_bytes(&three)[..],
        "getsockopt of 3 filters returned {:02X?}",
        &buf[..24]
    );
    ensure!(
        buf[24..] == [0xAA; 40],
        "getsockopt of 3 filters with optlen 64 wrote past the filters: {:02X?}",
        &buf[24..32]
    );
    s.set_filter_drop_all().or_fail("set zero filters")?;
    buf = [0xAA; 64];
    let (r, got) = sys::getsockopt_len(&s, SOL_CAN_RAW, CAN_RAW_FILTER, &mut buf, 64);
    r.or_fail("getsockopt CAN_RAW_FILTER with zero filters")?;
    ensure!(got == 0, "zero filters read back with optlen {got}");
    ensure!(
        buf == [0xAA; 64],
        "zero filters read back wrote the buffer: {:02X?}",
        &buf[..8]
    );
    Ok(())
}

/// setsockopt with an optlen the option cannot have: EINVAL, and the option
/// keeps its value.
fn raw_sockopt_bad_optlen(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let buf = [0u8; 32];
    for len in [1, 4, 7, 9, 12, 15, 17] {
        expect_errno(
            s.set_socket_option_bytes(SOL_CAN_RAW, CAN_RAW_FILTER, &buf[..len]),
            libc::EINVAL,
            &format!("setsockopt CAN_RAW_FILTER optlen {len} (not a multiple of {FILTER_LEN})"),
        )?;
    }
    for name in [
        CAN_RAW_ERR_FILTER,
        CAN_RAW_LOOPBACK,
        CAN_RAW_RECV_OWN_MSGS,
        CAN_RAW_FD_FRAMES,
        CAN_RAW_JOIN_FILTERS,
    ] {
        for len in [0, 1, 2, 3, 5, 8] {
            expect_errno(
                s.set_socket_option_bytes(SOL_CAN_RAW, name, &buf[..len]),
                libc::EINVAL,
                &format!("setsockopt {} optlen {len}", opt_name(name)),
            )?;
        }
    }
    check_defaults(&s, "after the refused setsockopt calls")
}

/// A level other than SOL_CAN_RAW (and SOL_SOCKET) is EINVAL; an unknown
/// option at SOL_CAN_RAW is ENOPROTOOPT; both for set and get.
fn raw_sockopt_bad_level_and_name(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let one = 1i32.to_ne_bytes();
    let mut buf = [0u8; 4];
    // 0 is SOL_IP, 102 is SOL_CAN_BASE + CAN_BCM.
    for level in [0, 102] {
        expect_errno(
            s.set_socket_option_bytes(level, CAN_RAW_LOOPBACK, &one),
            libc::EINVAL,
            &format!("setsockopt level {level} CAN_RAW_LOOPBACK"),
        )?;
        let (r, _) = sys::getsockopt_len(&s, level, CAN_RAW_LOOPBACK, &mut buf, 4);
        expect_errno(
            r,
            libc::EINVAL,
            &format!("getsockopt level {level} CAN_RAW_LOOPBACK"),
        )?;
    }
    for name in [0, 99] {
        expect_errno(
            s.set_socket_option_bytes(SOL_CAN_RAW, name, &one),
            libc::ENOPROTOOPT,
            &format!("setsockopt SOL_CAN_RAW option {name}"),
        )?;
        let (r, _) = sys::getsockopt_len(&s, SOL_CAN_RAW, name, &mut buf, 4);
        expect_errno(
            r,
            libc::ENOPROTOOPT,
            &format!("getsockopt SOL_CAN_RAW option {name}"),
        )?;
    }
    check_defaults(&s, "after the refused calls")
}

/// getsockopt of an int option: a longer optlen is cut to 4, a shorter one
/// (down to 0) gets that many bytes of the value and nothing past them, a
/// negative one is EINVAL.
fn raw_sockopt_get_optlen(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    s.set_error_filter(0x0102_0304)
        .or_fail("set CAN_RAW_ERR_FILTER")?;
    let mut buf = [0xAAu8; 16];
    for (name, value) in [(CAN_RAW_LOOPBACK, 1u32), (CAN_RAW_ERR_FILTER, 0x0102_0304)] {
        let what = opt_name(name);
        let (r, len) = sys::getsockopt_len(&s, SOL_CAN_RAW, name, &mut buf, 16);
        r.or_fail(format_args!("getsockopt {what} optlen 16"))?;
        ensure!(
            len == 4 && buf[..4] == value.to_ne_bytes(),
            "getsockopt {what} optlen 16: optlen {len}, value {:02X?}",
            &buf[..4]
        );
        buf = [0xAA; 16];
        let (r, len) = sys::getsockopt_len(&s, SOL_CAN_RAW, name, &mut buf, 2);
        r.or_fail(format_args!("getsockopt {what} optlen 2"))?;
        ensure!(
            len == 2 && buf[..2] == value.to_ne_bytes()[..2] && buf[2..] == [0xAA; 14],
            "getsockopt {what} optlen 2: optlen {len}, buffer {:02X?}",
            &buf[..4]
        );
        for short in [0, 1, 3] {
            buf = [0xAA; 16];
            let (r, len) = sys::getsockopt_len(&s, SOL_CAN_RAW, name, &mut buf, short);
            r.or_fail(format_args!("getsockopt {what} optlen {short}"))?;
            let n = short as usize;
            ensure!(
                len == short && buf[..n] == value.to_ne_bytes()[..n] && buf[n..] == [0xAA; 16][n..],
                "getsockopt {what} optlen {short}: optlen {len}, buffer {:02X?}",
                &buf[..4]
            );
        }
        let (r, _) = sys::getsockopt_len(&s, SOL_CAN_RAW, name, &mut buf, -1);
        expect_errno(r, libc::EINVAL, &format!("getsockopt {what} optlen -1"))?;
    }
    let (r, _) = sys::getsockopt_len(&s, SOL_CAN_RAW, CAN_RAW_FILTER, &mut buf, -1);
    expect_errno(r, libc::EINVAL, "getsockopt CAN_RAW_FILTER optlen -1")
}
