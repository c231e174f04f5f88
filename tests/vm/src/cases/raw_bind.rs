// SPDX-License-Identifier: GPL-2.0
//! Binding CAN_RAW sockets: one interface or all of them (ifindex 0) with
//! two interfaces, rebinding, getsockname, the calls CAN_RAW does not
//! support, binding to an interface that is down or goes down, and the
//! errno of every bad bind address.

use socketcan::{CanAddr, CanSocket, Socket, SocketOptions};

use super::{portable_table, raw1, raw2};
use crate::canraw::{
    self, addr_bytes, addr_ifindex, expect, expect_quiet, ext, show_wire, std, CAN_MTU, CAN_RAW,
    MIN_NAMELEN,
};
use crate::check::{ensure, expect_errno, OrFail, TestResult};
use crate::ctx::{dev, Ctx, Module, Stack};
use crate::sys::{self, FILL, SOCKADDR_CAN_LEN};
use crate::Test;
use rcan_uapi::raw;

pub const TESTS: &[Test] = portable_table![
    raw_bind_interface_removed,
    raw_bind_after_interface_removed,
    raw_close_in_every_state,
    ;
    stack:
    raw_bind_all_interfaces,
    raw_bind_rebind,
    raw_bind_getsockname,
    raw_bind_errors,
    raw_bind_interface_down,
    raw_socket_calls,
];

const AF_CAN: u16 = libc::AF_CAN as u16;

/// Binds `s` to `ifindex` through the socket the crate wraps.
fn bind(s: &CanSocket, ifindex: u32) -> TestResult {
    s.as_raw_socket()
        .bind(&CanAddr::new(ifindex).into_sock_addr())
        .or_fail(format_args!("bind to ifindex {ifindex}"))
}

/// Receives one frame with its source address; returns (frame bytes,
/// ifindex).
fn recv_from(s: &CanSocket, who: &str) -> Result<([u8; CAN_MTU], u32), String> {
    let r = sys::recvmsg(s, CAN_MTU, 0).or_fail(format_args!("{who}: recvmsg"))?;
    ensure!(r.len == CAN_MTU, "{who}: recvmsg returned {} bytes", r.len);
    let idx = addr_ifindex(&r.name[..r.namelen.min(SOCKADDR_CAN_LEN)])
        .map_err(|e| format!("{who}: {e}"))?;
    Ok((r.data[..CAN_MTU].try_into().unwrap(), idx))
}

/// With can0 and can1: a socket bound to ifindex 0 receives from both and
/// the address tells which; one bound to can1 only from can1. A socket
/// bound to 0 has no interface to write to (ENXIO) but can sendto one.
fn raw_bind_all_interfaces(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = raw2(ctx)?;
    let all = canraw::open(0)?;
    let only1 = canraw::open(i1)?;
    let tx0 = canraw::open(i0)?;
    let tx1 = canraw::open(i1)?;
    let f0 = std(0x100, &[0]);
    let f1 = std(0x101, &[1]);
    let f2 = ext(0x102, &[2]);
    canraw::send(&tx0, &f0)?;
    canraw::send(&tx1, &f1)?;
    canraw::send(&tx0, &f2)?;
    // The interfaces are independent: compare without their interleaving.
    let mut got = Vec::new();
    for _ in 0..3 {
        got.push(recv_from(&all, "socket bound to all")?);
    }
    got.sort();
    let mut want = vec![
        (canraw::wire(&f0), i0),
        (canraw::wire(&f1), i1),
        (canraw::wire(&f2), i0),
    ];
    want.sort();
    ensure!(
        got == want,
        "socket bound to all received {:?}, expected {:?}",
        got.iter()
            .map(|(b, i)| format!("{} on {i}", show_wire(b)))
            .collect::<Vec<_>>(),
        want.iter()
            .map(|(b, i)| format!("{} on {i}", show_wire(b)))
            .collect::<Vec<_>>()
    );
    let (b, i) = recv_from(&only1, "socket bound to can1")?;
    ensure!(
        b == canraw::wire(&f1) && i == i1,
        "socket bound to can1 received {} on {i}, expected {} on {i1}",
        show_wire(&b),
        canraw::show(&f1)
    );

    expect_errno(
        canraw::write_bytes(&all, &canraw::wire(&f0)),
        libc::ENXIO,
        "write on a socket bound to all interfaces",
    )?;
    let f3 = std(0x103, &[3]);
    let n = raw::sendto(&all, &canraw::wire(&f3), 0, Some(&addr_bytes(AF_CAN, i1)))
        .or_fail("sendto can1 from the socket bound to all")?;
    ensure!(n == CAN_MTU, "sendto returned {n}");
    let (b, i) = recv_from(&only1, "socket bound to can1")?;
    ensure!(
        b == canraw::wire(&f3) && i == i1,
        "after sendto can1: socket bound to can1 received {} on {i}",
        show_wire(&b)
    );
    expect_quiet(&[("socket bound to can1", &only1)])
}

/// Binding again moves the socket to the new interface.
fn raw_bind_rebind(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = raw2(ctx)?;
    let s = canraw::open(i0)?;
    let tx0 = canraw::open(i0)?;
    let tx1 = canraw::open(i1)?;
    let a = std(0x10, &[1]);
    canraw::send(&tx0, &a)?;
    expect(&s, &a, "socket bound to can0")?;
    bind(&s, i1)?;
    let b = std(0x11, &[2]);
    let c = std(0x12, &[3]);
    canraw::send(&tx0, &b)?;
    canraw::send(&tx1, &c)?;
    let (got, i) = recv_from(&s, "socket rebound to can1")?;
    ensure!(
        got == canraw::wire(&c) && i == i1,
        "socket rebound to can1 received {} on {i}, expected {} on {i1}",
        show_wire(&got),
        canraw::show(&c)
    );
    expect_quiet(&[("socket rebound to can1", &s)])
}

/// getsockname into 0xAA: length 8, AF_CAN, zero padding, the bound ifindex
/// (0 when unbound or bound to all), nothing written beyond.
fn raw_bind_getsockname(ctx: &mut Ctx) -> TestResult {
    let (_, i1) = raw2(ctx)?;
    let check = |s: &CanSocket, want: u32, what: &str| -> TestResult {
        let mut a = [FILL; SOCKADDR_CAN_LEN];
        let len = raw::getsockname(s, &mut a).or_fail(format_args!("getsockname ({what})"))?;
        ensure!(
            len as usize == MIN_NAMELEN,
            "getsockname ({what}): length {len}, expected {MIN_NAMELEN}"
        );
        let idx = addr_ifindex(&a).map_err(|e| format!("getsockname ({what}): {e}"))?;
        ensure!(
            idx == want,
            "getsockname ({what}): ifindex {idx}, expected {want}"
        );
        ensure!(
            a[MIN_NAMELEN..].iter().all(|&b| b == FILL),
            "getsockname ({what}) wrote past its length: {a:02X?}"
        );
        Ok(())
    };
    let s = canraw::unbound()?;
    check(&s, 0, "unbound")?;
    bind(&s, i1)?;
    check(&s, i1, "bound to can1")?;
    check(&canraw::open(0)?, 0, "bound to all")
}

/// Bad bind addresses: shorter than 8 bytes or not AF_CAN is EINVAL; an
/// unknown ifindex or a non-CAN interface (lo) is ENODEV. 8 bytes are
/// enough. A failed bind leaves the socket as it was.
fn raw_bind_errors(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let lo = ctx.ifindex("lo")?;
    let s = canraw::unbound()?;
    let tx = canraw::open(idx)?;
    let good = addr_bytes(AF_CAN, idx);
    for len in [0, 2, 4, 7] {
        expect_errno(
            raw::bind(&s, &good[..len]),
            libc::EINVAL,
            &format!("bind with addrlen {len}"),
        )?;
    }
    for family in [
        libc::AF_INET as u16,
        libc::AF_UNSPEC as u16,
        libc::AF_PACKET as u16,
    ] {
        expect_errno(
            raw::bind(&s, &addr_bytes(family, idx)),
            libc::EINVAL,
            &format!("bind with family {family}"),
        )?;
    }
    raw::bind(&s, &good[..MIN_NAMELEN]).or_fail("bind with addrlen 8")?;
    expect_errno(
        raw::bind(&s, &addr_bytes(AF_CAN, 999_999)),
        libc::ENODEV,
        "bind to unknown ifindex 999999",
    )?;
    expect_errno(
        raw::bind(&s, &addr_bytes(AF_CAN, lo)),
        libc::ENODEV,
        "bind to lo",
    )?;
    // Still bound to can0.
    let f = std(0x77, &[7]);
    canraw::send(&tx, &f)?;
    expect(&s, &f, "socket after the failed binds")
}

/// Binding to an interface that is down succeeds and reports ENETDOWN once
/// (SO_ERROR, or the next receive); sending there is ENETDOWN. A socket bound while
/// the interface goes down gets ENETDOWN too. After ip link set up, both
/// work again.
fn raw_bind_interface_down(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let early = canraw::open(idx)?;
    ctx.link_down(&dev(0))?;
    expect_errno(
        early.read_frame(),
        libc::ENETDOWN,
        "read on a socket bound to can0 after it went down",
    )?;
    let probe = canraw::open(idx).map_err(|e| format!("bind to can0 while down: {e}"))?;
    for (want, what) in [(libc::ENETDOWN, "first"), (0, "second")] {
        let e = probe
            .get_socket_option_int(libc::SOL_SOCKET, libc::SO_ERROR)
            .or_fail("SO_ERROR")?;
        ensure!(
            e == want,
            "{what} SO_ERROR after binding to can0 while down: {e}, expected {want}"
        );
    }
    let late = canraw::open(idx).map_err(|e| format!("bind to can0 while down: {e}"))?;
    expect_errno(
        late.read_frame(),
        libc::ENETDOWN,
        "first read on a socket bound to can0 while down",
    )?;
    expect_errno(
        late.write_frame(&std(0x1, &[1])),
        libc::ENETDOWN,
        "write on can0 while down",
    )?;
    ctx.link_up(&dev(0))?;
    let tx = canraw::open(idx)?;
    let f = std(0x2, &[2]);
    canraw::send(&tx, &f)?;
    expect(&early, &f, "socket bound before the interface went down")?;
    expect(&late, &f, "socket bound while the interface was down")
}

/// Unregistering the interface a socket is bound to unbinds it: the next
/// read is ENODEV, getsockname reports ifindex 0, its filters are gone
/// (zero filters) and a write without an address is ENXIO. A socket bound
/// to all interfaces gets no error.
fn raw_bind_interface_removed(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let all = canraw::open(0)?;
    s.set_filters(&[(0x10, 0x7F0), (0x20, 0x7F0)])
        .or_fail("set two filters")?;
    ctx.remove_can_ifaces()?;
    expect_errno(
        s.read_frame(),
        libc::ENODEV,
        "read after the interface was unregistered",
    )?;
    let mut a = [FILL; SOCKADDR_CAN_LEN];
    raw::getsockname(&s, &mut a).or_fail("getsockname")?;
    let i = addr_ifindex(&a)?;
    ensure!(
        i == 0,
        "getsockname after the interface was unregistered: ifindex {i}, expected 0"
    );
    let f = canraw::filters(&s)?;
    ensure!(
        f.is_empty(),
        "filters after the interface was unregistered: {f:08X?}, expected none"
    );
    expect_errno(
        canraw::write_bytes(&s, &canraw::wire(&std(0x10, &[1]))),
        libc::ENXIO,
        "write after the interface was unregistered",
    )?;
    expect_quiet(&[("socket bound to all interfaces", &all)])
}

/// Brings can0 back (up, classic MTU) after [`Ctx::remove_can_ifaces`],
/// the rest of the stack still loaded; returns its ifindex.
fn readd_iface(ctx: &mut Ctx) -> Result<u32, String> {
    match ctx.stack() {
        Stack::Ours => {
            ctx.insmod(Module::Loop, &["count=1"])?;
            ctx.links_up()?;
        }
        Stack::Mainline => {
            for args in [
                &["link", "add", "dev", "can0", "type", "vcan"][..],
                &["link", "set", "can0", "mtu", "16"],
                &["link", "set", "can0", "up"],
            ] {
                crate::tools::run_ok("ip", args)?;
            }
        }
    }
    ctx.ifindex(&dev(0))
}

/// A socket unbound by its interface going away binds again and receives
/// as a fresh one: bound to a new interface with a filter it gets each
/// matching frame once; its filters emptied, nothing; set again (two of
/// them, both matching one frame), that frame once. Then it closes and
/// the stack unloads.
fn raw_bind_after_interface_removed(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::unbound()?;
    s.set_filters(&[(0x10, 0x7FF)]).or_fail("set a filter")?;
    bind(&s, idx)?;
    ctx.remove_can_ifaces()?;
    expect_errno(
        s.read_frame(),
        libc::ENODEV,
        "read after the interface was unregistered",
    )?;
    let idx = readd_iface(ctx)?;
    let tx = canraw::open(idx)?;
    s.set_filters(&[(0x20, 0x7FF)])
        .or_fail("set a filter, unbound")?;
    bind(&s, idx)?;
    let f = std(0x20, &[1]);
    canraw::send(&tx, &std(0x10, &[0]))?;
    canraw::send(&tx, &f)?;
    expect(&s, &f, "rebound socket")?;
    expect_quiet(&[("rebound socket, after its frame", &s)])?;
    s.set_filter_drop_all().or_fail("set zero filters")?;
    canraw::send(&tx, &f)?;
    expect_quiet(&[("rebound socket without filters", &s)])?;
    s.set_filters(&[(0x20, 0x7FF), (0x20, 0x7F0)])
        .or_fail("set two filters")?;
    let g = std(0x20, &[2]);
    canraw::send(&tx, &g)?;
    expect(&s, &g, "rebound socket with two filters")?;
    expect_quiet(&[("rebound socket with two filters, after its frame", &s)])?;
    drop((s, tx));
    ctx.unload_all()
        .map_err(|e| format!("unloading after the socket was closed: {e}"))
}

/// Closing sockets in every state leaves nothing behind: never bound; a
/// filter set but never bound; bound; bound, then its filters changed
/// twice; bound to an interface that is then unregistered. Each state is
/// checked first (the bound ones receive what they should), then all are
/// closed and the whole stack must unload (a socket, or a receiver that
/// holds one, left behind keeps CAN_RAW's module in use), and a stack
/// loaded afresh delivers a frame.
fn raw_close_in_every_state(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let mut socks = Vec::new();
    for i in 0..40u16 {
        let s = canraw::unbound()?;
        let id = 0x100 + u32::from(i);
        match i % 4 {
            0 => {}
            1 => s.set_filters(&[(id, 0x7FF)]).or_fail("set a filter")?,
            2 => bind(&s, idx)?,
            _ => {
                bind(&s, idx)?;
                s.set_filters(&[(id, 0x7FF)]).or_fail("set a filter")?;
                s.set_filters(&[(id, 0x7FF), (0x300 + id, 0x7FF)])
                    .or_fail("set two filters")?;
            }
        }
        socks.push((i, s));
    }
    for (i, s) in &socks {
        if i % 4 == 3 {
            let f = std(0x100 + i, &[*i as u8]);
            canraw::send(&tx, &f)?;
            expect(s, &f, "socket whose filters changed twice")?;
        }
    }
    let gone = canraw::open(idx)?;
    ctx.remove_can_ifaces()?;
    drop((tx, gone, socks));
    ctx.unload_all()
        .map_err(|e| format!("unloading after every socket was closed: {e}"))?;
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    let f = std(0x42, &[4, 2]);
    canraw::send(&tx, &f)?;
    expect(&s, &f, "socket of the reloaded stack")
}

/// socket() with SOCK_DGRAM is EPROTOTYPE; the socket reports its type
/// and domain (not SO_PROTOCOL: mainline leaves it 0); connect,
/// getpeername, listen, accept and shutdown are EOPNOTSUPP.
fn raw_socket_calls(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    expect_errno(
        raw::socket(libc::PF_CAN, libc::SOCK_DGRAM, CAN_RAW),
        libc::EPROTOTYPE,
        "socket(PF_CAN, SOCK_DGRAM, CAN_RAW)",
    )?;
    let s = canraw::open(idx)?;
    for (name, opt, want) in [
        ("SO_TYPE", libc::SO_TYPE, libc::SOCK_RAW),
        ("SO_DOMAIN", libc::SO_DOMAIN, libc::AF_CAN),
    ] {
        let v = s
            .get_socket_option_int(libc::SOL_SOCKET, opt)
            .or_fail(name)?;
        ensure!(v == want, "{name} is {v}, expected {want}");
    }
    let addr = addr_bytes(AF_CAN, idx);
    expect_errno(raw::connect(&s, &addr), libc::EOPNOTSUPP, "connect")?;
    let mut peer = [0u8; SOCKADDR_CAN_LEN];
    expect_errno(
        raw::getpeername(&s, &mut peer),
        libc::EOPNOTSUPP,
        "getpeername",
    )?;
    expect_errno(raw::listen(&s, 1), libc::EOPNOTSUPP, "listen")?;
    expect_errno(raw::accept(&s), libc::EOPNOTSUPP, "accept")?;
    expect_errno(
        s.as_raw_socket().shutdown(std::net::Shutdown::Both),
        libc::EOPNOTSUPP,
        "shutdown",
    )?;
    // Still a working socket.
    let tx = canraw::open(idx)?;
    let f = std(0x3, &[3]);
    canraw::send(&tx, &f)?;
    expect(&s, &f, "socket after the refused calls")
}
