// SPDX-License-Identifier: GPL-2.0
//! Info leaks (issue 15, item 2) where the fuzzer cannot see them: every
//! buffer is filled with [`FILL`] (0xAA) before the call, and every byte
//! the kernel reports written must be the defined value, padding zero;
//! nothing past the reported length may change. `raw_leak_*` also runs
//! against mainline SocketCAN (what mainline writes is the reference);
//! `leak_*` checks frames our kernel code builds itself, from hardware
//! registers (SJA1000, 82527) or from scratch (the time service), whose
//! padding no sender wrote: an uninitialised skb shows there.

use std::os::fd::AsFd;
use std::time::Duration;

use rcan_uapi::raw;
use socketcan::{Socket, SocketOptions};

use super::{portable_table, raw1, test_table};
use crate::canraw::{
    self, addr_ifindex, sff_with_tail, CAN_ERR_MASK, CAN_MTU, MIN_NAMELEN, SOL_CAN_RAW,
};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::{Ctx, Module};
use crate::sys::{self, FILL};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_leak_poisoned_buffers,
    bcm_leak_replies,
];

pub const OURS: &[Test] = test_table![
    leak_sja1000_frames,
    leak_i82527_frames,
    leak_time_frame,
    leak_rtime_frame,
    leak_dsor_bodies,
    leak_error_frames,
];

/// `SO_RCVMARK`: an `SO_MARK` control message (4 bytes) with every frame.
const SO_RCVMARK: libc::c_int = 75;
/// `sizeof(struct cmsghdr)` on x86_64.
const CMSG_HDR: usize = 16;

/// The control messages in `buf[..controllen]` as (level, type, payload
/// length), after checking the chain: each `cmsg_len` at least a header
/// and inside `controllen`, the alignment bytes after each zero or
/// [`FILL`] (never written, or zeroed), nothing past `controllen` written.
fn cmsg_chain(buf: &[u8], controllen: usize) -> Result<Vec<(i32, i32, usize)>, String> {
    ensure!(
        controllen <= buf.len(),
        "msg_controllen {controllen} > {}",
        buf.len()
    );
    ensure!(
        buf[controllen..].iter().all(|&b| b == FILL),
        "control buffer written past msg_controllen {controllen}"
    );
    let mut out = Vec::new();
    let mut off = 0;
    while off < controllen {
        ensure!(
            controllen - off >= CMSG_HDR,
            "a cut control message header at {off}"
        );
        let len = u64::from_ne_bytes(buf[off..off + 8].try_into().unwrap()) as usize;
        let level = i32::from_ne_bytes(buf[off + 8..off + 12].try_into().unwrap());
        let ty = i32::from_ne_bytes(buf[off + 12..off + 16].try_into().unwrap());
        ensure!(
            (CMSG_HDR..=controllen - off).contains(&len),
            "control message at {off}: cmsg_len {len} (level {level}, type {ty})"
        );
        let next = (off + len).next_multiple_of(8).min(controllen);
        if let Some(i) = (off + len..next).find(|&i| buf[i] != 0 && buf[i] != FILL) {
            return Err(format!(
                "alignment byte {i} after control message ({level}, {ty}) is {:#04x}: \
                 uninitialised kernel memory",
                buf[i]
            ));
        }
        out.push((level, ty, len - CMSG_HDR));
        off = next;
    }
    Ok(out)
}

/// One frame through CAN_RAW into poisoned buffers, with SO_TIMESTAMP and
/// SO_RCVMARK on: the 16 frame bytes as sent and nothing after them, an
/// 8-byte address (family, zero padding, ifindex) and nothing after it in
/// a 128-byte buffer, a well-formed control chain whose alignment bytes
/// are clean, with a 16-byte timestamp and a 4-byte mark; then every
/// SOL_CAN_RAW option and getsockname into 64 and 128 poisoned bytes:
/// only the reported length changed.
fn raw_leak_poisoned_buffers(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let rx = canraw::open(idx)?;
    rx.set_socket_option_int(libc::SOL_SOCKET, libc::SO_TIMESTAMP, 1)
        .or_fail("SO_TIMESTAMP")?;
    rx.set_socket_option_int(libc::SOL_SOCKET, SO_RCVMARK, 1)
        .or_fail("SO_RCVMARK")?;
    let f = canraw::std(0x321, &[1, 2, 3]);
    canraw::send(&tx, &f)?;
    let mut data = [FILL; 72];
    let mut name = [FILL; 128];
    let mut control = [u64::from_ne_bytes([FILL; 8]); 32];
    let r = sys::recvmsg_into(&rx, &mut data, &mut name, &mut control, 0).or_fail("recvmsg")?;
    ensure!(
        r.len == CAN_MTU && data[..CAN_MTU] == canraw::wire(&f),
        "recvmsg returned {} bytes: {}",
        r.len,
        canraw::show_wire(&data[..r.len.min(CAN_MTU)])
    );
    ensure!(
        data[CAN_MTU..].iter().all(|&b| b == FILL),
        "data buffer written past the {CAN_MTU} bytes returned"
    );
    ensure!(
        r.namelen == MIN_NAMELEN,
        "msg_namelen {} for a 128-byte buffer, expected {MIN_NAMELEN}",
        r.namelen
    );
    ensure!(
        addr_ifindex(&name)? == idx,
        "address ifindex {:02X?}",
        &name[..8]
    );
    ensure!(
        name[MIN_NAMELEN..].iter().all(|&b| b == FILL),
        "address buffer written past msg_namelen: {:02X?}",
        &name[..32]
    );
    ensure!(
        r.flags & (libc::MSG_TRUNC | libc::MSG_CTRUNC) == 0,
        "msg_flags {:#x}: truncated with room to spare",
        r.flags
    );
    let bytes: Vec<u8> = control.iter().flat_map(|w| w.to_ne_bytes()).collect();
    let chain = cmsg_chain(&bytes, r.controllen)?;
    let has = |ty: i32, len: usize| chain.contains(&(libc::SOL_SOCKET, ty, len));
    ensure!(
        has(libc::SO_TIMESTAMP, 16) && has(libc::SO_MARK, 4),
        "control messages {chain:?}: expected SCM_TIMESTAMP (16 bytes) and SO_MARK (4 bytes)"
    );
    for (opt, want) in [
        (canraw::CAN_RAW_FILTER, 8),
        (canraw::CAN_RAW_ERR_FILTER, 4),
        (canraw::CAN_RAW_LOOPBACK, 4),
        (canraw::CAN_RAW_RECV_OWN_MSGS, 4),
        (canraw::CAN_RAW_FD_FRAMES, 4),
        (canraw::CAN_RAW_JOIN_FILTERS, 4),
    ] {
        let what = canraw::opt_name(opt);
        let mut v = [FILL; 64];
        let (res, len) = sys::getsockopt_len(&rx, SOL_CAN_RAW, opt, &mut v, 64);
        res.or_fail(format_args!("getsockopt {what}"))?;
        ensure!(
            len == want,
            "getsockopt {what} into 64 bytes: optlen {len}, expected {want}"
        );
        ensure!(
            v[want as usize..].iter().all(|&b| b == FILL),
            "getsockopt {what}: written past optlen {len}: {:02X?}",
            &v[..16]
        );
    }
    let mut a = [FILL; 128];
    let n = raw::getsockname(&rx, &mut a).or_fail("getsockname")? as usize;
    ensure!(n == MIN_NAMELEN, "getsockname length {n}");
    ensure!(addr_ifindex(&a)? == idx, "getsockname ifindex");
    ensure!(
        a[n..].iter().all(|&b| b == FILL),
        "getsockname wrote past its {n} bytes"
    );
    Ok(())
}

/// The frame rcan_rtime builds when it hears no other time source (it
/// takes over after `timeout_ms`, here its minimum of 1200 ms), read by a
/// CAN_RAW socket on can0 ([`kernel_built`]).
fn leak_rtime_frame(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    rx.set_read_timeout(Duration::from_secs(10))
        .or_fail("SO_RCVTIMEO")?;
    ctx.insmod(Module::Rtime, &["timeout_ms=1200"])?;
    let w = kernel_built(&rx, "rcan_rtime frame")?;
    ctx.note(format!("rtime frame {}", canraw::show_wire(&w)));
    Ok(())
}

/// `sizeof(struct bcm_msg_head)` on x86_64 (bcm.rst); encoded here
/// independently of bcm.rs and rcan-core.
const BCM_HEAD: usize = 56;

/// A `struct bcm_msg_head` as written: opcode, flags, count, ival1 and
/// ival2 (µs), can_id, nframes; the 4-byte hole at 12..16 stays zero.
fn bcm_head(
    op: u32,
    flags: u32,
    count: u32,
    ival1_us: i64,
    ival2_us: i64,
    id: u32,
    n: u32,
) -> Vec<u8> {
    let mut b = vec![0u8; BCM_HEAD];
    b[0..4].copy_from_slice(&op.to_ne_bytes());
    b[4..8].copy_from_slice(&flags.to_ne_bytes());
    b[8..12].copy_from_slice(&count.to_ne_bytes());
    for (i, us) in [ival1_us, ival2_us].into_iter().enumerate() {
        b[16 + 16 * i..24 + 16 * i].copy_from_slice(&(us / 1_000_000).to_ne_bytes());
        b[24 + 16 * i..32 + 16 * i].copy_from_slice(&(us % 1_000_000).to_ne_bytes());
    }
    b[48..52].copy_from_slice(&id.to_ne_bytes());
    b[52..56].copy_from_slice(&n.to_ne_bytes());
    b
}

/// Reads one BCM reply into a 4096-byte data buffer and a 128-byte name
/// buffer, both [`FILL`]ed, and checks: its length is the head plus
/// `nframes` 16-byte frames, the head's hole (bytes 12..16, the
/// CVE-2021-34693 bytes) is zero, nothing past the returned length and
/// `msg_namelen` changed, the address is `AF_CAN`, zero padding, `ifindex`,
/// the rest of what was reported zero. Returns the reply. (Replies of a
/// transmission carry ifindex 0: mainline fills in the operation's
/// receive interface, which a TX operation has not.)
fn bcm_reply(fd: impl AsFd, ifindex: u32, what: &str) -> Result<Vec<u8>, String> {
    let mut data = [FILL; 4096];
    let mut name = [FILL; 128];
    let mut control = [0u64; 0];
    let r = sys::recvmsg_into(&fd, &mut data, &mut name, &mut control, 0)
        .or_fail(format_args!("{what}: recvmsg"))?;
    ensure!(r.len >= BCM_HEAD, "{what}: {} bytes", r.len);
    let nframes = u32::from_ne_bytes(data[52..56].try_into().unwrap()) as usize;
    ensure!(
        r.len == BCM_HEAD + 16 * nframes,
        "{what}: {} bytes for nframes {nframes}",
        r.len
    );
    ensure!(
        data[12..16] == [0; 4],
        "{what}: the hole of bcm_msg_head (bytes 12..16) is {:02X?}: uninitialised kernel memory",
        &data[12..16]
    );
    ensure!(
        data[r.len..].iter().all(|&b| b == FILL),
        "{what}: data buffer written past the {} bytes returned",
        r.len
    );
    ensure!(
        (8..=24).contains(&r.namelen),
        "{what}: msg_namelen {}",
        r.namelen
    );
    ensure!(
        name[r.namelen..].iter().all(|&b| b == FILL),
        "{what}: address buffer written past msg_namelen {}",
        r.namelen
    );
    ensure!(
        u16::from_ne_bytes([name[0], name[1]]) == libc::AF_CAN as u16
            && name[2..4] == [0, 0]
            && addr_ifindex(&name)? == ifindex
            && name[8..r.namelen].iter().all(|&b| b == 0),
        "{what}: address [{:02X?}] (AF_CAN, zero padding, ifindex {ifindex})",
        &name[..r.namelen]
    );
    Ok(data[..r.len].to_vec())
}

/// CAN_BCM replies and notifications into poisoned buffers
/// ([`bcm_reply`]): the kernel builds each head itself, the timer ones
/// (`TX_EXPIRED`, `RX_TIMEOUT`) from a head on the stack in mainline,
/// where CVE-2021-34693 leaked its 4-byte hole. `TX_STATUS` (`TX_READ`:
/// the frames as written, with their padding bytes set by us, come
/// back as written), `TX_EXPIRED`, `RX_CHANGED` (the received frame),
/// `RX_TIMEOUT` and `RX_STATUS`: every defined field as expected.
fn bcm_leak_replies(ctx: &mut Ctx) -> TestResult {
    const TX_SETUP: u32 = 1;
    const TX_READ: u32 = 3;
    const RX_SETUP: u32 = 5;
    const RX_READ: u32 = 7;
    const SETTIMER: u32 = 0x1;
    const STARTTIMER: u32 = 0x2;
    const TX_COUNTEVT: u32 = 0x4;
    const RX_FILTER_ID: u32 = 0x20;
    let idx = ctx.bcm_ifaces(1)?[0];
    let bcm = raw::socket(libc::AF_CAN, libc::SOCK_DGRAM, 2).or_fail("socket(CAN_BCM)")?;
    raw::connect(&bcm, &canraw::addr_bytes(libc::AF_CAN as u16, idx)).or_fail("connect")?;
    raw::set_timeout(&bcm, libc::SO_RCVTIMEO, Duration::from_secs(5)).or_fail("SO_RCVTIMEO")?;
    let tx = canraw::open(idx)?;
    let head = |b: &[u8]| -> (u32, u32, u32, u32, u32) {
        let u = |o: usize| u32::from_ne_bytes(b[o..o + 4].try_into().unwrap());
        (u(0), u(4), u(8), u(48), u(52))
    };
    // TX_STATUS: two frames with 0x5C in __pad/__res0/len8_dlc and the
    // data past len (user bytes: they come back as written).
    let frames = [sff_with_tail(0x101, 2, 0x5C), sff_with_tail(0x101, 5, 0x5C)];
    let mut m = bcm_head(TX_SETUP, 0, 0, 0, 0, 0x101, 2);
    frames.iter().for_each(|f| m.extend_from_slice(f));
    raw::write(&bcm, &m).or_fail("TX_SETUP")?;
    raw::write(&bcm, &bcm_head(TX_READ, 0, 0, 0, 0, 0x101, 0)).or_fail("TX_READ")?;
    let r = bcm_reply(&bcm, 0, "TX_STATUS")?;
    ensure!(
        head(&r) == (8, 0, 0, 0x101, 2) && r[56..72] == frames[0] && r[72..88] == frames[1],
        "TX_STATUS: head {:?}, frames {:02X?}",
        head(&r),
        &r[56..]
    );
    // TX_EXPIRED: two frames at 10 ms, counted.
    let mut m = bcm_head(
        TX_SETUP,
        SETTIMER | STARTTIMER | TX_COUNTEVT,
        2,
        10_000,
        0,
        0x102,
        1,
    );
    m.extend_from_slice(&canraw::wire(&canraw::std(0x102, &[7])));
    raw::write(&bcm, &m).or_fail("TX_SETUP with a count")?;
    let r = bcm_reply(&bcm, 0, "TX_EXPIRED")?;
    ensure!(
        head(&r).0 == 9 && head(&r).3 == 0x102,
        "TX_EXPIRED: head {:?}",
        head(&r)
    );
    // RX_CHANGED: any frame 0x123 (RX_FILTER_ID), sent through CAN_RAW.
    raw::write(&bcm, &bcm_head(RX_SETUP, RX_FILTER_ID, 0, 0, 0, 0x123, 0)).or_fail("RX_SETUP")?;
    let f = canraw::std(0x123, &[1, 2, 3]);
    canraw::send(&tx, &f)?;
    let r = bcm_reply(&bcm, idx, "RX_CHANGED")?;
    // The frame as sent, but for byte 5 (`flags`/`__pad`), where mainline
    // marks RX_LOCAL (0x40) and RX_OWN (0x80) traffic.
    let mut want = canraw::wire(&f);
    want[5] = r[56 + 5] & 0xC0;
    ensure!(
        head(&r) == (12, RX_FILTER_ID, 0, 0x123, 1) && r[56..72] == want,
        "RX_CHANGED: head {:?}, frame {}",
        head(&r),
        canraw::show_wire(&r[56..r.len().min(72)])
    );
    // RX_TIMEOUT: nothing with 0x124 within 20 ms.
    raw::write(
        &bcm,
        &bcm_head(
            RX_SETUP,
            SETTIMER | STARTTIMER | RX_FILTER_ID,
            0,
            20_000,
            0,
            0x124,
            0,
        ),
    )
    .or_fail("RX_SETUP with a timeout")?;
    let r = bcm_reply(&bcm, idx, "RX_TIMEOUT")?;
    ensure!(
        head(&r).0 == 11 && head(&r).3 == 0x124,
        "RX_TIMEOUT: head {:?}",
        head(&r)
    );
    // RX_STATUS of the first receive operation.
    raw::write(&bcm, &bcm_head(RX_READ, 0, 0, 0, 0, 0x123, 0)).or_fail("RX_READ")?;
    let r = bcm_reply(&bcm, idx, "RX_STATUS")?;
    ensure!(
        head(&r).0 == 10 && head(&r).3 == 0x123,
        "RX_STATUS: head {:?}",
        head(&r)
    );
    ctx.note("TX_STATUS, TX_EXPIRED, RX_CHANGED, RX_TIMEOUT, RX_STATUS checked");
    Ok(())
}

/// Reads one frame from `rx` into a poisoned buffer and checks what a
/// frame built by the kernel must look like: 16 bytes, `__pad`, `__res0`
/// and `len8_dlc` zero, data bytes past `len` zero (not the sender's
/// bytes, not stale memory), nothing past the 16 bytes. Returns them.
fn kernel_built(rx: impl AsFd, what: &str) -> Result<[u8; CAN_MTU], String> {
    let r = sys::recvmsg(rx, 72, 0).or_fail(format_args!("{what}: recvmsg"))?;
    ensure!(r.len == CAN_MTU, "{what}: {} bytes", r.len);
    let w: [u8; CAN_MTU] = r.data[..CAN_MTU].try_into().unwrap();
    let len = usize::from(w[4]).min(8);
    ensure!(
        w[5..8] == [0, 0, 0] && w[8 + len..].iter().all(|&b| b == 0),
        "{what}: {} [{:02X?}]: padding or data past len not zero",
        canraw::show_wire(&w),
        w
    );
    ensure!(
        r.data[CAN_MTU..].iter().all(|&b| b == FILL),
        "{what}: written past the 16 bytes"
    );
    Ok(w)
}

/// Frames of every length sent on card 0 with 0x5C in the data bytes
/// past `len` (CAN_RAW passes a writer's bytes through, so they reach the
/// driver), received on card 1 from the controller's registers: the
/// driver's receive path must hand up zeros there.
fn driver_frames(ctx: &Ctx, i0: u32, i1: u32, card: &str) -> TestResult {
    let tx = canraw::open(i0)?;
    let rx = canraw::open(i1)?;
    rx.set_read_timeout(Duration::from_secs(5))
        .or_fail("SO_RCVTIMEO")?;
    for len in 0..=8u8 {
        let sent = sff_with_tail(0x240 + u16::from(len), len, 0x5C);
        raw::write(&tx, &sent).or_fail(format_args!("{card}: write len {len}"))?;
        let w = kernel_built(
            &rx,
            &format!("{card}: frame of len {len} from the other card"),
        )?;
        ensure!(
            w[..5] == sent[..5] && w[8..8 + usize::from(len)] == sent[8..8 + usize::from(len)],
            "{card}: sent {}, received {}",
            canraw::show_wire(&sent),
            canraw::show_wire(&w)
        );
    }
    ctx.note(format!("{card}: 9 frames checked"));
    Ok(())
}

/// [`driver_frames`] through two emulated Kvaser PCIcan cards (SJA1000).
fn leak_sja1000_frames(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = super::sja1000::kvaser2(ctx)?;
    driver_frames(ctx, i0, i1, "rcan_kvaser_pci")
}

/// [`driver_frames`] through two simulated 82527 cards.
fn leak_i82527_frames(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = super::i82527::sim2(ctx)?;
    driver_frames(ctx, i0, i1, "rcan_i82527_sim")
}

/// The bytes of an error frame's data that its class (`can_id`) defines
/// (`<linux/can/error.h>`): data[0] lost arbitration, data[1] controller,
/// data[2..4] protocol, data[4] transceiver, data[6..8] the error
/// counters (CAN_ERR_CNT); data[5], controller-specific, is never set by
/// the SJA1000 drivers (mainline's or ours).
fn err_defined(can_id: u32) -> [bool; 8] {
    let mut d = [false; 8];
    for (class, bytes) in [
        (0x02u32, 0..1),
        (0x04, 1..2),
        (0x08, 2..4),
        (0x10, 4..5),
        (0x200, 6..8),
    ] {
        if can_id & class != 0 {
            d[bytes].fill(true);
        }
    }
    d
}

/// Error frames, which the driver builds from scratch in its interrupt
/// path (mainline's `alloc_can_err_skb` zeroes them), read into poisoned
/// buffers ([`kernel_built`]): every data byte the frame's class does not
/// define must be zero, len 8 (CAN_ERR_DLC). The simulated SJA1000 card
/// with berr-reporting: bit errors on transmission up to bus-off and the
/// restart, then lost arbitration, then a data overrun.
fn leak_error_frames(ctx: &mut Ctx) -> TestResult {
    use super::candev_err::{err_socket, fault, sim2};
    let (i0, i1) = sim2(ctx, &["berr-reporting", "on", "restart-ms", "100"], &[])?;
    let e0 = err_socket(i0)?;
    let mut seen = 0u32;
    let mut check = |e0: &socketcan::CanSocket, what: &str| -> Result<u32, String> {
        let w = kernel_built(e0, what)?;
        let id = u32::from_ne_bytes(w[..4].try_into().unwrap());
        let def = err_defined(id);
        ensure!(
            id & libc::CAN_ERR_FLAG != 0 && w[4] == 8,
            "{what}: {} is not an error frame of len 8",
            canraw::show_wire(&w)
        );
        if let Some(i) = (0..8).find(|&i| !def[i] && w[8 + i] != 0) {
            return Err(format!(
                "{what}: {}: data[{i}] is {:#04x}, not defined for class {:#x}",
                canraw::show_wire(&w),
                w[8 + i],
                id & CAN_ERR_MASK
            ));
        }
        seen |= id & CAN_ERR_MASK;
        Ok(id)
    };
    fault("biterr")?;
    raw::write(&canraw::open(i0)?, &sff_with_tail(0x55, 1, 0)).or_fail("write")?;
    // Bus errors, warning, passive, bus-off: then the restart.
    let mut n = 0;
    loop {
        n += 1;
        ensure!(n < 200, "no bus-off in 200 error frames");
        if check(&e0, &format!("bit-error frame {n}"))? & 0x40 != 0 {
            break;
        }
    }
    fault("none")?;
    while check(&e0, "after bus-off")? & 0x100 == 0 {
        n += 1;
        ensure!(n < 250, "no CAN_ERR_RESTARTED after bus-off");
    }
    fault("arblost")?;
    raw::write(&canraw::open(i0)?, &sff_with_tail(0x300, 1, 0)).or_fail("write")?;
    while check(&e0, "lost arbitration")? & 0x02 == 0 {}
    // The card's acceptance filter lets data frames in only while a
    // socket wants them.
    let _rx0 = canraw::open(i0)?;
    fault("overrun")?;
    raw::write(&canraw::open(i1)?, &sff_with_tail(0x42, 0, 0)).or_fail("write")?;
    while check(&e0, "overrun")? & 0x04 == 0 {}
    fault("none")?;
    ensure!(
        seen & 0x3ce == 0x3ce,
        "error classes seen {seen:#x}: want lost arbitration, controller, protocol, bus-off, bus error, restarted and counters"
    );
    ctx.note(format!("{n} error frames checked, classes {seen:#x}"));
    Ok(())
}

/// The time frame rcan_time builds every second, read by a CAN_RAW socket
/// on can0 ([`kernel_built`]).
fn leak_time_frame(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    rx.set_read_timeout(Duration::from_secs(5))
        .or_fail("SO_RCVTIMEO")?;
    ctx.insmod(Module::Time, &[])?;
    let w = kernel_built(&rx, "rcan_time frame")?;
    ctx.note(format!("time frame {}", canraw::show_wire(&w)));
    Ok(())
}

/// DSOR message bodies, reassembled in the kernel from frames: messages
/// of 0, 1, 6, 7, 8, 13, 14 and 100 bytes (and 1000 and 4000 on the
/// release kernel), largest first so that later, shorter ones reuse what the
/// earlier ones left, each received into a buffer 64 bytes longer than
/// the message and filled with [`FILL`]: the message's bytes as sent and
/// nothing after them; then one received into a buffer half its length:
/// the first half, `MSG_TRUNC` in `recvmsg`'s flags, an 8-byte address
/// and nothing after it.
fn leak_dsor_bodies(ctx: &mut Ctx) -> TestResult {
    use rcan_uapi::dsor::{DsorAddr, DsorSocket, DSOR_ID_ANY};
    ctx.load_stack(&[])?;
    ctx.insmod(Module::Dsor, &["ifname=can0"])?;
    let rx = DsorSocket::new().or_fail("DSOR socket")?;
    rx.bind(&DsorAddr::Segm {
        prio: 0,
        node: 0,
        id: DSOR_ID_ANY,
    })
    .or_fail("bind")?;
    rx.set_rcvtimeo(Duration::from_secs(20))
        .or_fail("SO_RCVTIMEO")?;
    let tx = DsorSocket::new().or_fail("DSOR socket")?;
    // The debug kernel under TCG takes minutes for the long ones.
    let mut lens = vec![100, 14, 13, 8, 7, 6, 1, 0];
    if !crate::ctx::debug_kernel() {
        lens.splice(0..0, [4000, 1000]);
    }
    let body = |id: u32, len: usize| -> Vec<u8> {
        (0..len)
            .map(|i| (i as u32 * 7 + id * 13 + 1) as u8 | 1)
            .collect()
    };
    for (j, &len) in lens.iter().enumerate() {
        let id = 0x1eaf_0000 | j as u32;
        let a = DsorAddr::Segm {
            prio: 0x20,
            node: 0,
            id,
        };
        tx.send_to(&body(id, len), &a)
            .or_fail(format_args!("send {len} bytes"))?;
        let mut buf = vec![FILL; len + 64];
        let (n, from) = rx
            .recv_from(&mut buf)
            .or_fail(format_args!("recv {len} bytes"))?;
        ensure!(
            matches!(from, Some(DsorAddr::Segm { id: i, .. }) if i == id),
            "message of {len} bytes from {from:?}"
        );
        ensure!(
            n == len && buf[..n] == body(id, len)[..],
            "message of {len} bytes: {n} bytes received, content {}",
            if buf[..n.min(len)] == body(id, len)[..n.min(len)] {
                "as sent"
            } else {
                "differs"
            }
        );
        ensure!(
            buf[n..].iter().all(|&b| b == FILL),
            "message of {len} bytes: buffer written past it: {:02X?}",
            &buf[n..(n + 16).min(buf.len())]
        );
    }
    // Into a buffer half the message's length.
    let id = 0x1eaf_1000;
    let len = 100;
    tx.send_to(
        &body(id, len),
        &DsorAddr::Segm {
            prio: 0x20,
            node: 0,
            id,
        },
    )
    .or_fail("send 100 bytes")?;
    let mut data = [FILL; 50];
    let mut name = [FILL; 128];
    let mut control = [0u64; 0];
    let r = sys::recvmsg_into(&rx, &mut data, &mut name, &mut control, 0)
        .or_fail("recvmsg into 50 bytes")?;
    ensure!(
        r.len == 50 && r.flags & libc::MSG_TRUNC != 0 && data[..50] == body(id, len)[..50],
        "100-byte message into 50 bytes: returned {}, msg_flags {:#x}",
        r.len,
        r.flags
    );
    ensure!(
        name[r.namelen.min(128)..].iter().all(|&b| b == FILL) && r.namelen == 8,
        "100-byte message: msg_namelen {} (sockaddr_cansegm: 8), address bytes {:02X?}",
        r.namelen,
        &name[..16]
    );
    ctx.note(format!(
        "{} messages of {lens:?} bytes and a truncated one checked",
        lens.len()
    ));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmsg(level: i32, ty: i32, data: &[u8]) -> Vec<u8> {
        let mut b = ((CMSG_HDR + data.len()) as u64).to_ne_bytes().to_vec();
        b.extend_from_slice(&level.to_ne_bytes());
        b.extend_from_slice(&ty.to_ne_bytes());
        b.extend_from_slice(data);
        b
    }

    #[test]
    fn control_chain() {
        let mut buf = vec![FILL; 256];
        let a = cmsg(1, 36, &[7, 0, 0, 0]);
        let b = cmsg(1, 29, &[1; 16]);
        buf[..20].copy_from_slice(&a);
        buf[24..56].copy_from_slice(&b);
        assert_eq!(cmsg_chain(&buf, 56).unwrap(), [(1, 36, 4), (1, 29, 16)]);
        buf[22] = 0x11;
        assert!(cmsg_chain(&buf, 56)
            .unwrap_err()
            .contains("alignment byte 22"));
        buf[22] = 0;
        assert!(cmsg_chain(&buf, 56).is_ok());
        assert!(cmsg_chain(&buf, 40).is_err());
        buf[60] = 0;
        assert!(cmsg_chain(&buf, 56).is_err());
    }
}
