// SPDX-License-Identifier: GPL-2.0
//! CAN FD as users meet it (Documentation/networking/rcan/can-fd.rst):
//! `ip link set can0 mtu 72` makes a loopback device carry CAN FD frames
//! (mainline: vcan, the same command); the `socketcan` crate's
//! `CanFdSocket`, can-utils (`cansend ...##...`, `candump`, `cangen -f`),
//! python-can (`is_fd=True`) and an `AF_PACKET` socket bound to
//! ETH_P_CANFD send and receive them; CAN_RAW's FD rules and errnos are
//! mainline's. Every test is portable: on the mainline stage it runs on
//! `vcan` with the same MTU.
//!
//! One interface setup per test (two interfaces: an FD one and a classic
//! one where the errno table needs it); loads are a handful of frames, so
//! the debug kernel runs the same tests.

use std::io::ErrorKind;
use std::os::fd::{AsFd, OwnedFd};
use std::time::Duration;

use rcan_uapi::raw;
use socketcan::id::FdFlags;
use socketcan::{CanAnyFrame, CanFdFrame, CanFdSocket, EmbeddedFrame, Frame, Socket, StandardId};

use super::portable_table;
use crate::canraw::{self, std as sff, CANFD_MTU, CAN_MTU, CAN_RAW_FD_FRAMES, SOL_CAN_RAW};
use crate::check::{ensure, errno_text, OrFail, TestResult, QUIET};
use crate::ctx::{dev, Ctx};
use crate::tools::{self, TOOL_LIMIT};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_fd_mtu_switch,
    raw_fd_socketcan_round_trip,
    raw_fd_classic_sockets,
    raw_fd_errnos,
    raw_fd_recv_trunc,
    raw_fd_packet_socket,
    canutils_fd_cansend_candump,
    canutils_fd_cangen,
    canutils_fd_python_can,
    bcm_fd_tx_send,
];

/// `CANFD_BRS`, `CANFD_ESI`, `CANFD_FDF` (`<linux/can.h>`).
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;
const CANFD_FDF: u8 = 0x04;
/// `CAN_RAW_XL_FRAMES` (`<linux/can/raw.h>`, Linux 6.2).
const CAN_RAW_XL_FRAMES: libc::c_int = 7;
/// `ETH_P_CANFD` (`<linux/if_ether.h>`).
const ETH_P_CANFD: u16 = 0x000D;

/// `ip ARGS` as a user types it; its exit status and stderr.
fn ip(args: &[&str]) -> Result<(bool, String), String> {
    let out = tools::spawn("ip", args, None)?.finish(TOOL_LIMIT)?;
    Ok((out.status.success(), out.stderr))
}

/// `ip link set NAME mtu MTU`, which must succeed.
fn set_mtu(name: &str, mtu: usize) -> TestResult {
    let m = mtu.to_string();
    let (ok, err) = ip(&["link", "set", name, "mtu", &m])?;
    ensure!(ok, "ip link set {name} mtu {mtu}: {}", err.trim());
    Ok(())
}

/// The MTU sysfs shows for `name`.
fn mtu_of(name: &str) -> Result<usize, String> {
    let p = format!("/sys/class/net/{name}/mtu");
    std::fs::read_to_string(&p)
        .or_fail(&p)?
        .trim()
        .parse()
        .map_err(|e| format!("{p}: {e}"))
}

/// The stack under test with `n` interfaces (can0.., up, echoing); the
/// first `fd` of them made CAN FD interfaces (down, `mtu 72`, up), the
/// rest stay classic (MTU 16). Returns their ifindexes.
fn fd_ifaces(ctx: &mut Ctx, n: usize, fd: usize) -> Result<Vec<u32>, String> {
    let idx = ctx.can_ifaces(n)?;
    for i in 0..fd {
        let name = dev(i);
        ctx.link_down(&name)?;
        set_mtu(&name, CANFD_MTU)?;
        ctx.link_up(&name)?;
    }
    Ok(idx)
}

/// A CAN_RAW socket with CAN_RAW_FD_FRAMES, bound to `ifindex`, with the
/// suite's receive timeout.
fn fd_open(ifindex: u32) -> Result<CanFdSocket, String> {
    let s = CanFdSocket::open_iface(ifindex)
        .or_fail(format_args!("CanFdSocket bound to ifindex {ifindex}"))?;
    s.set_read_timeout(canraw::RAW_RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")?;
    Ok(s)
}

/// A standard-id CAN FD frame with `data` and `flags` (BRS/ESI).
fn fd_frame(id: u16, data: &[u8], flags: FdFlags) -> Result<CanFdFrame, String> {
    let id = StandardId::new(id).ok_or("bad id")?;
    CanFdFrame::with_flags(id, data, flags).ok_or_else(|| "bad FD frame".to_string())
}

/// The 72 bytes of an FD frame as written: id, len, flags, data.
fn fd_wire(id: u32, data: &[u8], flags: u8) -> [u8; CANFD_MTU] {
    let mut b = [0u8; CANFD_MTU];
    b[..4].copy_from_slice(&id.to_ne_bytes());
    b[4] = data.len() as u8;
    b[5] = flags;
    b[8..8 + data.len()].copy_from_slice(data);
    b
}

/// Reads one frame from `s` and checks that it is the FD frame `id`,
/// `data`, with exactly the flags `flags` plus CANFD_FDF (which the
/// sending stack sets on every FD frame, mainline `can_send`).
fn expect_fd(s: &CanFdSocket, id: u32, data: &[u8], flags: u8, who: &str) -> TestResult {
    let got = s
        .read_frame()
        .or_fail(format_args!("{who}: waiting for FD frame {id:03X}"))?;
    let CanAnyFrame::Fd(f) = got else {
        return Err(format!("{who}: expected FD frame {id:03X}, got {got:?}"));
    };
    let raw: &libc::canfd_frame = f.as_ref();
    ensure!(
        raw.can_id == id && f.data() == data && raw.flags == flags | CANFD_FDF,
        "{who}: expected FD {id:03X} [{}] flags {:#x}, got {:03X} [{}] flags {:#x} data {:02X?}",
        data.len(),
        flags | CANFD_FDF,
        raw.can_id,
        f.data().len(),
        raw.flags,
        f.data()
    );
    Ok(())
}

/// The payload `0, 1, ..., n-1`.
fn payload(n: usize) -> Vec<u8> {
    (0..n as u8).collect()
}

/// `ip link set can0 mtu 72` and back, with vcan's rules: refused while up
/// (EBUSY), values other than 16 and 72 refused (EINVAL; CAN XL MTUs
/// aside, which no rcan device takes and the test does not try), the MTU
/// the device then has as set.
fn raw_fd_mtu_switch(ctx: &mut Ctx) -> TestResult {
    ctx.can_ifaces(1)?;
    let c0 = dev(0);
    ensure!(
        mtu_of(&c0)? == CAN_MTU,
        "can0 starts with MTU {}",
        mtu_of(&c0)?
    );
    let (ok, err) = ip(&["link", "set", &c0, "mtu", "72"])?;
    ensure!(
        !ok && err.contains("Device or resource busy"),
        "mtu 72 while up: expected EBUSY, ip said ok={ok}: {}",
        err.trim()
    );
    // Setting the MTU it has is no change, up or not.
    set_mtu(&c0, CAN_MTU)?;
    ctx.link_down(&c0)?;
    // Each `ip` costs seconds on the debug kernel under TCG: two values
    // there, either side of 72.
    let bad: &[&str] = if crate::ctx::debug_kernel() {
        &["17", "73"]
    } else {
        &["15", "17", "64", "71", "73"]
    };
    for &bad in bad {
        let (ok, err) = ip(&["link", "set", &c0, "mtu", bad])?;
        ensure!(
            !ok && err.contains("Invalid argument"),
            "mtu {bad}: expected EINVAL, ip said ok={ok}: {}",
            err.trim()
        );
    }
    set_mtu(&c0, CANFD_MTU)?;
    ensure!(
        mtu_of(&c0)? == CANFD_MTU,
        "MTU {} after mtu 72",
        mtu_of(&c0)?
    );
    set_mtu(&c0, CAN_MTU)?;
    ensure!(mtu_of(&c0)? == CAN_MTU, "MTU {} after mtu 16", mtu_of(&c0)?);
    set_mtu(&c0, CANFD_MTU)?;
    ctx.link_up(&c0)?;
    // And it carries FD frames now.
    let idx = ctx.ifindex(&c0)?;
    let rx = fd_open(idx)?;
    let tx = fd_open(idx)?;
    let data = payload(64);
    tx.write_frame(&fd_frame(0x123, &data, FdFlags::empty())?)
        .or_fail("write FD frame")?;
    expect_fd(&rx, 0x123, &data, 0, "FD socket on can0 (mtu 72)")
}

/// `CanFdSocket` to `CanFdSocket`: 64-byte payloads, BRS and ESI as set,
/// every valid CAN FD length, an extended id; a classic frame sent by an
/// FD socket arrives as a 16-byte classic frame.
fn raw_fd_socketcan_round_trip(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let tx = fd_open(idx)?;
    let rx = fd_open(idx)?;
    let cases: [(u8, FdFlags); 4] = [
        (0, FdFlags::empty()),
        (CANFD_BRS, FdFlags::BRS),
        (CANFD_ESI, FdFlags::ESI),
        (CANFD_BRS | CANFD_ESI, FdFlags::BRS | FdFlags::ESI),
    ];
    for (bits, flags) in cases {
        let data: Vec<u8> = (0..64u8).map(|i| i ^ bits).collect();
        tx.write_frame(&fd_frame(0x7FF, &data, flags)?)
            .or_fail("write 64-byte FD frame")?;
        expect_fd(&rx, 0x7FF, &data, bits, "FD receiver")?;
    }
    // Every length a CAN FD frame can have on the bus.
    for n in [0usize, 1, 7, 8, 12, 16, 20, 24, 32, 48, 64] {
        let data = payload(n);
        tx.write_frame(&fd_frame(0x100 + n as u16, &data, FdFlags::BRS)?)
            .or_fail(format_args!("write FD frame of {n} bytes"))?;
        expect_fd(&rx, 0x100 + n as u32, &data, CANFD_BRS, "FD receiver")?;
    }
    // Extended identifier.
    let eid = socketcan::ExtendedId::new(0x1ABC_DEF0).ok_or("bad id")?;
    let data = payload(20);
    let f = CanFdFrame::with_flags(eid, &data, FdFlags::BRS).ok_or("bad frame")?;
    tx.write_frame(&f).or_fail("write extended FD frame")?;
    expect_fd(
        &rx,
        0x1ABC_DEF0 | libc::CAN_EFF_FLAG,
        &data,
        CANFD_BRS,
        "FD receiver",
    )?;
    // A classic frame through an FD socket stays classic (16 bytes).
    tx.write_frame(&sff(0x55, &[1, 2, 3]))
        .or_fail("write classic frame on FD socket")?;
    let got = rx.read_frame().or_fail("read classic frame")?;
    ensure!(
        matches!(got, CanAnyFrame::Normal(f) if f.raw_id() == 0x55 && f.data() == [1, 2, 3]),
        "expected classic 055 [3] 01 02 03, got {got:?}"
    );
    Ok(())
}

/// Sockets without CAN_RAW_FD_FRAMES on an FD interface: they get the
/// classic frames and never an FD one (mainline `raw_rcv`); the thesis
/// API's socket (ours only) likewise.
fn raw_fd_classic_sockets(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let tx = fd_open(idx)?;
    let classic = canraw::open(idx)?;
    let fd = fd_open(idx)?;
    let data = payload(64);
    tx.write_frame(&fd_frame(0x101, &data, FdFlags::BRS)?)
        .or_fail("write FD frame")?;
    let c = sff(0x102, &[9, 8]);
    tx.write_frame(&c).or_fail("write classic frame")?;
    expect_fd(&fd, 0x101, &data, CANFD_BRS, "FD socket")?;
    let got = fd.read_frame().or_fail("FD socket: classic frame")?;
    ensure!(
        matches!(got, CanAnyFrame::Normal(f) if f.raw_id() == 0x102),
        "FD socket: expected classic 102, got {got:?}"
    );
    // The classic socket's first frame is the classic one: the FD frame
    // sent before it was never queued.
    canraw::expect(&classic, &c, "classic CAN_RAW socket")?;
    canraw::expect_quiet(&[("classic CAN_RAW socket", &classic)])
}

/// The errno table of CAN_RAW with CAN FD, each as mainline:
/// CAN_RAW_FD_FRAMES' option sizes, a 72-byte write without it, to a
/// classic interface, with `len` > 64; CAN_RAW_XL_FRAMES implying FD.
fn raw_fd_errnos(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 2, 1)?;
    let (fd_if, classic_if) = (idx[0], idx[1]);
    let s = canraw::open(fd_if)?;
    let frame = fd_wire(0x123, &payload(64), CANFD_BRS);
    let write = |s: &socketcan::CanSocket, b: &[u8]| canraw::write_bytes(s, b);
    let einval = |r: std::io::Result<usize>, what: &str| -> TestResult {
        match r {
            Err(e) if e.raw_os_error() == Some(libc::EINVAL) => Ok(()),
            Err(e) => Err(format!("{what}: expected EINVAL, got {}", errno_text(&e))),
            Ok(n) => Err(format!("{what}: expected EINVAL, wrote {n} bytes")),
        }
    };
    // Off by default; a 72-byte write is refused.
    ensure!(
        canraw::int_opt(&s, CAN_RAW_FD_FRAMES)? == 0,
        "CAN_RAW_FD_FRAMES is on by default"
    );
    einval(write(&s, &frame), "72-byte write without CAN_RAW_FD_FRAMES")?;
    // Option size: exactly an int.
    for len in [0usize, 1, 2, 3, 5, 8] {
        let v = [1u8; 8];
        let r = setsockopt_raw(&s, CAN_RAW_FD_FRAMES, &v[..len]);
        ensure!(
            r.as_ref().err().and_then(|e| e.raw_os_error()) == Some(libc::EINVAL),
            "setsockopt(CAN_RAW_FD_FRAMES) with optlen {len}: expected EINVAL, got {:?}",
            r.map_err(|e| errno_text(&e))
        );
    }
    setsockopt_raw(&s, CAN_RAW_FD_FRAMES, &1i32.to_ne_bytes())
        .or_fail("setsockopt(CAN_RAW_FD_FRAMES, 1)")?;
    ensure!(
        canraw::int_opt(&s, CAN_RAW_FD_FRAMES)? == 1,
        "CAN_RAW_FD_FRAMES does not read back 1"
    );
    // getsockopt with a long buffer returns an int; a short one is cut.
    let (v, n) = getsockopt_raw(&s, CAN_RAW_FD_FRAMES, 8).or_fail("getsockopt len 8")?;
    ensure!(
        n == 4 && v[..4] == 1i32.to_ne_bytes(),
        "getsockopt(CAN_RAW_FD_FRAMES) len 8: {n} bytes {v:02X?}"
    );
    let (_, n) = getsockopt_raw(&s, CAN_RAW_FD_FRAMES, 2).or_fail("getsockopt len 2")?;
    ensure!(n == 2, "getsockopt(CAN_RAW_FD_FRAMES) len 2 gave {n} bytes");
    // Now the FD frame goes out on the FD interface...
    let n = write(&s, &frame).or_fail("72-byte write with CAN_RAW_FD_FRAMES")?;
    ensure!(n == CANFD_MTU, "72-byte write returned {n}");
    // ... but not with len > 64, nor to a classic interface.
    let mut bad = frame;
    bad[4] = 65;
    einval(write(&s, &bad), "72-byte write with len 65")?;
    let to_classic = sendto_raw(&s, &frame, classic_if);
    einval(to_classic, "72-byte write to a classic (MTU 16) interface")?;
    // A classic frame still goes to both.
    let c = canraw::wire(&sff(0x321, &[1]));
    let n = sendto_raw(&s, &c, classic_if).or_fail("16-byte write to the classic interface")?;
    ensure!(n == CAN_MTU, "16-byte write returned {n}");
    // Sizes that are no frame at all.
    for len in [15usize, 17, 71, 73] {
        let b = vec![0u8; len];
        einval(write(&s, &b), &format!("{len}-byte write"))?;
    }
    // CAN XL includes CAN FD: with XL on, FD cannot be turned off.
    if setsockopt_raw(&s, CAN_RAW_XL_FRAMES, &1i32.to_ne_bytes()).is_ok() {
        let r = setsockopt_raw(&s, CAN_RAW_FD_FRAMES, &0i32.to_ne_bytes());
        ensure!(
            r.as_ref().err().and_then(|e| e.raw_os_error()) == Some(libc::EINVAL),
            "CAN_RAW_FD_FRAMES 0 with CAN_RAW_XL_FRAMES on: expected EINVAL, got {:?}",
            r.map_err(|e| errno_text(&e))
        );
    }
    Ok(())
}

/// recvmsg of an FD frame: a 72-byte buffer gets 72 bytes, a 16-byte one
/// 16 bytes and MSG_TRUNC (mainline `raw_recvmsg`); classic frames are 16
/// bytes on an FD socket.
fn raw_fd_recv_trunc(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let tx = fd_open(idx)?;
    let rx = fd_open(idx)?;
    let data = payload(48);
    for _ in 0..2 {
        tx.write_frame(&fd_frame(0x42, &data, FdFlags::BRS)?)
            .or_fail("write FD frame")?;
    }
    tx.write_frame(&sff(0x43, &[7])).or_fail("write classic")?;
    let r = crate::sys::recvmsg(&rx, CANFD_MTU, 0).or_fail("recvmsg 72")?;
    let want = fd_wire(0x42, &data, CANFD_BRS | CANFD_FDF);
    ensure!(
        r.len == CANFD_MTU && r.data == want && r.flags & libc::MSG_TRUNC == 0,
        "recvmsg(72): {} bytes, flags {:#x}, {:02X?}",
        r.len,
        r.flags,
        &r.data[..8]
    );
    let r = crate::sys::recvmsg(&rx, CAN_MTU, 0).or_fail("recvmsg 16")?;
    ensure!(
        r.len == CAN_MTU && r.flags & libc::MSG_TRUNC != 0 && r.data[..CAN_MTU] == want[..CAN_MTU],
        "recvmsg(16) of an FD frame: {} bytes, flags {:#x} (expected 16 and MSG_TRUNC)",
        r.len,
        r.flags
    );
    let r = crate::sys::recvmsg(&rx, CANFD_MTU, 0).or_fail("recvmsg classic")?;
    ensure!(
        r.len == CAN_MTU && r.flags & libc::MSG_TRUNC == 0,
        "recvmsg(72) of a classic frame: {} bytes, flags {:#x}",
        r.len,
        r.flags
    );
    Ok(())
}

/// An `AF_PACKET` socket bound to ETH_P_CANFD on can0 (what tcpdump and
/// Wireshark see) receives the FD frame, as an ETH_P_CANFD packet of 72
/// bytes; one bound to ETH_P_CAN does not.
fn raw_fd_packet_socket(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let pfd = packet_socket(idx, ETH_P_CANFD)?;
    let pcan = packet_socket(idx, 0x000C)?;
    let tx = fd_open(idx)?;
    let data = payload(32);
    tx.write_frame(&fd_frame(0x2AB, &data, FdFlags::ESI)?)
        .or_fail("write FD frame")?;
    let (b, proto) = packet_recv(&pfd, 0).or_fail("ETH_P_CANFD packet socket")?;
    let want = fd_wire(0x2AB, &data, CANFD_ESI | CANFD_FDF);
    ensure!(
        proto == ETH_P_CANFD && b == want,
        "ETH_P_CANFD socket: protocol {proto:#06x}, {} bytes {:02X?}",
        b.len(),
        &b[..b.len().min(8)]
    );
    // A negative check's window (nothing reaches the ETH_P_CAN socket),
    // not synchronisation.
    std::thread::sleep(QUIET);
    match packet_recv(&pcan, libc::MSG_DONTWAIT) {
        Err(e) if e.kind() == ErrorKind::WouldBlock => Ok(()),
        Err(e) => Err(format!("ETH_P_CAN socket: {}", errno_text(&e))),
        Ok((b, p)) => Err(format!(
            "ETH_P_CAN packet socket got a packet of {} bytes, protocol {p:#06x}",
            b.len()
        )),
    }
}

/// `cansend can0 123##1...` (a CAN FD frame with BRS, 64 bytes) is shown
/// by `candump -L` with its flags and read by an FD socket.
fn canutils_fd_cansend_candump(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let rx = fd_open(idx)?;
    let data: Vec<u8> = (0..64u8).map(|i| i.wrapping_mul(3)).collect();
    let hex: String = data.iter().map(|b| format!("{b:02X}")).collect();
    let arg = format!("123##1{hex}");
    let mut dump = tools::spawn("candump", &["-L", "-n", "1", "can0"], None)?;
    dump.wait_listening()?;
    tools::run_ok("cansend", &["can0", &arg])?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(out.status.success(), "candump: {}", out.stderr.trim());
    // "(1700000000.123456) can0 123##5<hex>": the flags nibble after
    // "##" (BRS, plus FDF on newer can-utils), then the data.
    let line = out.stdout.trim();
    let rest = line
        .split_whitespace()
        .nth(2)
        .ok_or_else(|| format!("candump -L printed {line:?}"))?;
    let (id, fd) = rest
        .split_once("##")
        .ok_or_else(|| format!("candump -L shows no FD frame: {line:?}"))?;
    let flags = u8::from_str_radix(&fd[..1], 16).map_err(|_| format!("flags in {line:?}"))?;
    ensure!(
        id == "123" && flags & (CANFD_BRS | CANFD_ESI) == CANFD_BRS && fd[1..] == hex,
        "candump -L printed {line:?}, expected 123##1{hex}"
    );
    expect_fd(&rx, 0x123, &data, CANFD_BRS, "FD socket after cansend")
}

/// `cangen can0 -f -b -I 1A5 -n 5`: five FD frames with BRS, each of a
/// valid CAN FD length, reach an FD socket.
fn canutils_fd_cangen(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let rx = fd_open(idx)?;
    tools::run_ok(
        "cangen",
        &["can0", "-f", "-b", "-I", "1A5", "-n", "5", "-g", "1"],
    )?;
    for i in 0..5 {
        let got = rx
            .read_frame()
            .or_fail(format_args!("FD frame {i} from cangen"))?;
        let CanAnyFrame::Fd(f) = got else {
            return Err(format!("cangen frame {i}: not FD: {got:?}"));
        };
        let raw: &libc::canfd_frame = f.as_ref();
        let valid_len = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64].contains(&raw.len);
        ensure!(
            raw.can_id == 0x1A5 && valid_len && raw.flags & CANFD_BRS != 0,
            "cangen frame {i}: id {:X} len {} flags {:#x}",
            raw.can_id,
            raw.len,
            raw.flags
        );
    }
    Ok(())
}

/// python-can, as a user writes it: `can.Bus(..., fd=True)` sends a
/// `can.Message(is_fd=True, bitrate_switch=True)` of 48 bytes (an FD socket
/// reads it with BRS) and receives one we send with ESI (`is_fd`,
/// `error_state_indicator`, the data).
fn canutils_fd_python_can(ctx: &mut Ctx) -> TestResult {
    let idx = fd_ifaces(ctx, 1, 1)?[0];
    let rx = fd_open(idx)?;
    let script = r#"
import can
bus = can.Bus(interface="socketcan", channel="can0", fd=True)
bus.send(can.Message(arbitration_id=0x1AB, is_extended_id=False, is_fd=True,
                     bitrate_switch=True, data=bytes(range(48))))
m = bus.recv(timeout=120)
print("got", m is not None and m.is_fd, m is not None and m.error_state_indicator,
      m is not None and m.bitrate_switch, hex(m.arbitration_id) if m else None,
      m.data.hex() if m else None, flush=True)
bus.shutdown()
"#;
    let limit = tools::python_limit();
    let py = tools::spawn("/usr/bin/python3", &["-c", script], None)?;
    // Python's start-up under emulation takes long. Once its frame is
    // here its socket exists, so the frame we send back is queued for it
    // whether or not it is in recv() yet.
    rx.set_read_timeout(limit).or_fail("SO_RCVTIMEO")?;
    let sent = expect_fd(
        &rx,
        0x1AB,
        &payload(48),
        CANFD_BRS,
        "FD socket (python-can sent)",
    );
    if let Err(e) = sent {
        let out = py
            .finish(Duration::from_secs(1))
            .map(|o| format!("{}: {} {}", o.status, o.stdout.trim(), o.stderr.trim()));
        return Err(format!("{e}; python3: {}", out.unwrap_or_else(|e| e)));
    }
    let back = payload(24);
    let tx = fd_open(idx)?;
    tx.write_frame(&fd_frame(0x77, &back, FdFlags::ESI)?)
        .or_fail("write FD frame for python-can")?;
    let out = py.finish(limit)?;
    let hex: String = back.iter().map(|b| format!("{b:02x}")).collect();
    let want = format!("got True True False 0x77 {hex}");
    ensure!(
        out.status.success() && out.stdout.trim() == want,
        "python-can: {}: printed {:?}, expected {want:?}; stderr {}",
        out.status,
        out.stdout.trim(),
        out.stderr.trim()
    );
    Ok(())
}

/// `setsockopt(SOL_CAN_RAW, name, bytes)` with any option length.
fn setsockopt_raw(s: impl AsFd, name: libc::c_int, v: &[u8]) -> std::io::Result<()> {
    raw::setsockopt(s, SOL_CAN_RAW, name, v)
}

/// `getsockopt(SOL_CAN_RAW, name)` with a buffer of `len` (<= 16) bytes:
/// the bytes and the length the kernel returned.
fn getsockopt_raw(
    s: impl AsFd,
    name: libc::c_int,
    len: usize,
) -> std::io::Result<([u8; 16], usize)> {
    let mut buf = [0u8; 16];
    let n = raw::getsockopt(s, SOL_CAN_RAW, name, &mut buf[..len.min(16)])?;
    Ok((buf, n as usize))
}

/// `sendto` of raw bytes to interface `ifindex`.
fn sendto_raw(s: impl AsFd, b: &[u8], ifindex: u32) -> std::io::Result<usize> {
    let a = canraw::addr_bytes(libc::AF_CAN as u16, ifindex);
    raw::sendto(s, b, 0, Some(&a))
}

/// `sizeof(struct sockaddr_ll)`.
const SOCKADDR_LL_LEN: usize = 20;

/// An `AF_PACKET` `SOCK_RAW` socket for protocol `proto`, bound to
/// `ifindex`, with the suite's receive timeout.
fn packet_socket(ifindex: u32, proto: u16) -> Result<OwnedFd, String> {
    let fd = raw::socket(libc::AF_PACKET, libc::SOCK_RAW, i32::from(proto.to_be()))
        .or_fail(format_args!("socket(AF_PACKET, SOCK_RAW, {proto:#06x})"))?;
    // struct sockaddr_ll: family, protocol (network order), ifindex, ...
    let mut a = [0u8; SOCKADDR_LL_LEN];
    a[..2].copy_from_slice(&(libc::AF_PACKET as u16).to_ne_bytes());
    a[2..4].copy_from_slice(&proto.to_be_bytes());
    a[4..8].copy_from_slice(&(ifindex as i32).to_ne_bytes());
    raw::bind(&fd, &a).or_fail(format_args!("bind AF_PACKET {proto:#06x}"))?;
    raw::set_timeout(&fd, libc::SO_RCVTIMEO, canraw::RAW_RX_TIMEOUT).or_fail("SO_RCVTIMEO")?;
    Ok(fd)
}

/// One packet from a packet socket: its bytes and `sll_protocol`.
fn packet_recv(fd: &OwnedFd, flags: libc::c_int) -> std::io::Result<(Vec<u8>, u16)> {
    let mut buf = [0u8; 128];
    let mut a = [0u8; SOCKADDR_LL_LEN];
    let (n, _) = raw::recvfrom(fd, &mut buf, flags, Some(&mut a))?;
    Ok((buf[..n].to_vec(), u16::from_be_bytes([a[2], a[3]])))
}

/// `CAN_BCM` `TX_SEND` with `CAN_FD_FRAME` on a CAN FD interface: the FD
/// frame goes out (an FD socket reads it, `CANFD_FDF` set by the stack).
fn bcm_fd_tx_send(ctx: &mut Ctx) -> TestResult {
    let idx = ctx.bcm_ifaces(1)?[0];
    let c0 = dev(0);
    ctx.link_down(&c0)?;
    set_mtu(&c0, CANFD_MTU)?;
    ctx.link_up(&c0)?;
    let rx = fd_open(idx)?;
    const CAN_BCM: libc::c_int = 2;
    const TX_SEND: u32 = 4;
    const CAN_FD_FRAME: u32 = 0x800;
    const MHSIZ: usize = 56;
    let bcm = raw::socket(libc::PF_CAN, libc::SOCK_DGRAM, CAN_BCM)
        .or_fail("socket(PF_CAN, SOCK_DGRAM, CAN_BCM)")?;
    let a = canraw::addr_bytes(libc::AF_CAN as u16, idx);
    raw::connect(&bcm, &a).or_fail("connect CAN_BCM")?;
    // struct bcm_msg_head (56 bytes on 64-bit) + one struct canfd_frame.
    let data = payload(64);
    let mut m = vec![0u8; MHSIZ];
    m[..4].copy_from_slice(&TX_SEND.to_ne_bytes());
    m[4..8].copy_from_slice(&CAN_FD_FRAME.to_ne_bytes());
    m[48..52].copy_from_slice(&0x3C1u32.to_ne_bytes());
    m[52..56].copy_from_slice(&1u32.to_ne_bytes());
    m.extend_from_slice(&fd_wire(0x3C1, &data, CANFD_BRS));
    let n = canraw::write_bytes(bcm.as_fd(), &m).or_fail("TX_SEND CAN_FD_FRAME")?;
    ensure!(n == MHSIZ + CANFD_MTU, "TX_SEND returned {n}");
    expect_fd(&rx, 0x3C1, &data, CANFD_BRS, "FD socket (BCM TX_SEND)")
}
