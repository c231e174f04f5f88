// SPDX-License-Identifier: GPL-2.0
//! CAN_J1939's transport protocols (issue 42) as a user sees them: a
//! message of more than 8 bytes sent with one `sendto` and received whole
//! with one `recvmsg`, carried by the connection-mode transport (TP
//! RTS/CTS, up to 1785 bytes), the broadcast one (BAM) and the extended
//! one (ETP, beyond 1785 bytes, through can-utils' `j1939cat`). A CAN_RAW
//! socket on the same interface is the bus: it records the frames the
//! kernel sends, checked against J1939-21's transport protocol as written
//! here, independently of rcan-core (TP.CM PGN 0xEC00 and TP.DT 0xEB00,
//! ETP.CM 0xC800; RTS `10 size(le16) packets max-per-CTS pgn(le24)`, CTS
//! `11 count next FF FF pgn`, EOMA `13 size(le16) packets FF pgn`, BAM
//! `20 size(le16) packets FF pgn`, abort `FF reason FF FF FF pgn`, DT
//! `seq(1-based) 7 bytes`, the last padded with 0xFF), and it plays the
//! other node where the kernel's side must be seen alone: a receiver that
//! answers an RTS with CTS and EOMA, or with an abort; a sender that goes
//! silent after the CTS; an address nobody answers. What a socket is told
//! when a session fails, and what a second session between the same two
//! addresses gets, are mainline's (the mainline stage runs these against
//! can-j1939.ko).
//!
//! No test sleeps to synchronise or measures time: T1-T3 (750 and 1250
//! ms) are waited out by reads with a 10 s deadline; "not sent" and "not
//! received" are checked by order (a frame or message that must come
//! after the one that must not, and the first read must be it).

use std::os::fd::{AsFd, OwnedFd};

use rcan_uapi::raw;

use crate::canraw;
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::{dev, Ctx, Stack};
use crate::sys;
use crate::tools::{self, TOOL_LIMIT};

use super::isotp::{hex, raw_open, raw_send, want_errno};
use super::j1939::{
    can_id, jaddr, jbound, raw_from, raw_next, set_broadcast, NAMELEN, NO_ADDR, NO_PGN,
    SCM_J1939_DEST_ADDR, SOL_CAN_J1939, T,
};
use super::portable_table;

pub static TESTS: &[crate::Test] = portable_table![
    ;
    stack:
    j1939_tp_unicast_sizes,
    j1939_bam_broadcast,
    j1939_canutils_j1939cat_etp,
    j1939_canutils_j1939cat_single_frame,
    j1939_tp_second_session_busy,
    j1939_tp_raw_peer_silent_after_cts,
    j1939_tp_raw_peer_receives,
    j1939_tp_abort_from_peer,
    j1939_tp_raw_peer_second_rts,
    j1939_tp_raw_peer_holds,
];

/// TP.CM, the connection management PGN (J1939-21 5.10).
const PGN_TP_CM: u32 = 0x0EC00;
/// TP.DT, the data transfer PGN.
const PGN_TP_DT: u32 = 0x0EB00;
/// ETP.CM, the extended transport's connection management PGN.
const PGN_ETP_CM: u32 = 0x0C800;
const RTS: u8 = 0x10;
const CTS: u8 = 0x11;
const EOMA: u8 = 0x13;
const BAM: u8 = 0x20;
const ABORT: u8 = 0xff;
const ETP_RTS: u8 = 0x14;
/// Connection abort reasons (J1939-21): "already in one or more
/// sessions", "timeout".
const ABORT_BUSY: u8 = 1;
const ABORT_TIMEOUT: u8 = 3;
/// "Duplicate sequence number" (mainline's `J1939_XTP_ABORT_DUP_SEQ`).
const ABORT_DUP_SEQ: u8 = 8;
/// The PGN the messages carry: PDU1 with a clean PS byte (data page 1).
pub(super) const PGN: u32 = 0x12300;

/// A J1939 frame as the bus shows it: priority, PGN (PS cleared for
/// PDU1), destination (0xFF for PDU2), source, data.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Frame {
    pgn: u32,
    da: u8,
    sa: u8,
    data: Vec<u8>,
}

/// Splits a 29-bit identifier as J1939-21 lays it out: PF (bits 23..16)
/// below 240 makes PS (15..8) the destination.
fn frame(id: u32, data: Vec<u8>) -> Frame {
    let pgn = (id >> 8) & 0x3ffff;
    let pf = (pgn >> 8) & 0xff;
    let (pgn, da) = if pf < 240 {
        (pgn & !0xff, (pgn & 0xff) as u8)
    } else {
        (pgn, NO_ADDR)
    };
    Frame {
        pgn,
        da,
        sa: id as u8,
        data,
    }
}

fn show(f: &Frame) -> String {
    format!(
        "PGN {:05X} {:02X}->{:02X} [{}]",
        f.pgn,
        f.sa,
        f.da,
        hex(&f.data)
    )
}

/// The next frame on the bus socket `bus` that concerns `addrs` (its
/// source or its destination is one of them); others are skipped.
fn next_of(bus: impl AsFd, addrs: &[u8], what: &str) -> Result<Frame, String> {
    loop {
        let (id, data) = raw_next(&bus, what)?;
        ensure!(
            id & libc::CAN_EFF_FLAG != 0,
            "{what}: a standard frame {id:03X}"
        );
        let f = frame(id, data);
        if addrs.contains(&f.sa) || addrs.contains(&f.da) {
            return Ok(f);
        }
    }
}

/// The 3 PGN bytes of a TP.CM message (little endian).
fn pgn_bytes(pgn: u32) -> [u8; 3] {
    [pgn as u8, (pgn >> 8) as u8, (pgn >> 16) as u8]
}

/// A TP.CM message's 8 bytes: `head` (5 bytes) and the PGN.
fn cm(head: [u8; 5], pgn: u32) -> Vec<u8> {
    let mut d = head.to_vec();
    d.extend_from_slice(&pgn_bytes(pgn));
    d
}

/// `n` bytes that differ from message to message (`seed`) and along
/// the message: a misplaced or repeated packet shows.
pub(super) fn payload(n: usize, seed: u32) -> Vec<u8> {
    let mut x = seed.wrapping_mul(2_654_435_761) | 1;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 8) as u8
        })
        .collect()
}

fn packets(size: usize) -> usize {
    size.div_ceil(7)
}

/// Checks that `f` is TP.CM `cmd` from `sa` to `da` with `data`.
fn want_cm(f: &Frame, sa: u8, da: u8, data: &[u8], what: &str) -> TestResult {
    ensure!(
        f.pgn == PGN_TP_CM && f.sa == sa && f.da == da && f.data == data,
        "{what}: {}, want PGN {PGN_TP_CM:05X} {sa:02X}->{da:02X} [{}]",
        show(f),
        hex(data)
    );
    Ok(())
}

/// Checks the RTS of a `size`-byte message: `10 size packets max pgn`,
/// the maximum packets per CTS no less than the packets (mainline
/// sends the packet count there; 0xFF, "no limit", would do).
fn want_rts(f: &Frame, sa: u8, da: u8, size: usize, pgn: u32) -> TestResult {
    let n = packets(size);
    let d = &f.data;
    ensure!(
        f.pgn == PGN_TP_CM
            && f.sa == sa
            && f.da == da
            && d.len() == 8
            && d[0] == RTS
            && d[1..3] == (size as u16).to_le_bytes()
            && usize::from(d[3]) == n
            && usize::from(d[4]) >= n
            && d[5..] == pgn_bytes(pgn),
        "the RTS: {}, want PGN {PGN_TP_CM:05X} {sa:02X}->{da:02X} [10 {} {n:02X} >={n:02X} {}]",
        show(f),
        hex(&(size as u16).to_le_bytes()),
        hex(&pgn_bytes(pgn))
    );
    Ok(())
}

/// Checks that `f` is TP.DT packet `seq` (1-based) of `msg`, from `sa`
/// to `da`: 7 bytes of the message, the last packet padded with 0xFF.
fn want_dt(f: &Frame, sa: u8, da: u8, seq: usize, msg: &[u8]) -> TestResult {
    let want = dt(seq, msg);
    ensure!(
        f.pgn == PGN_TP_DT && f.sa == sa && f.da == da && f.data == want,
        "DT {seq}: {}, want PGN {PGN_TP_DT:05X} {sa:02X}->{da:02X} [{}]",
        show(f),
        hex(&want)
    );
    Ok(())
}

/// One received J1939 message (up to 2048 bytes): data, source PGN and
/// address, SCM_J1939_DEST_ADDR.
#[derive(Debug)]
pub(super) struct Msg {
    data: Vec<u8>,
    pgn: u32,
    sa: u8,
    da: Option<u8>,
    flags: i32,
}

/// The next message on J1939 socket `s` within [`T`].
pub(super) fn recv_msg(s: impl AsFd, what: &str) -> Result<Msg, String> {
    raw::set_timeout(&s, libc::SO_RCVTIMEO, T).or_fail("SO_RCVTIMEO")?;
    let mut data = vec![0u8; 2048];
    let mut name = [0u8; NAMELEN];
    let mut control = [0u64; 32];
    let r = sys::recvmsg_into(&s, &mut data, &mut name, &mut control, 0)
        .or_fail(format!("recvmsg ({what})"))?;
    let bytes: Vec<u8> = control.iter().flat_map(|w| w.to_ne_bytes()).collect();
    let mut da = None;
    let mut at = 0;
    // struct cmsghdr: cmsg_len (size_t), cmsg_level, cmsg_type (int),
    // then the data; each header at an 8-byte boundary.
    while at + 16 <= r.controllen.min(bytes.len()) {
        let len = u64::from_ne_bytes(bytes[at..at + 8].try_into().unwrap_or_default()) as usize;
        let level = i32::from_ne_bytes(bytes[at + 8..at + 12].try_into().unwrap_or_default());
        let ty = i32::from_ne_bytes(bytes[at + 12..at + 16].try_into().unwrap_or_default());
        ensure!(len >= 16, "{what}: control message of {len} bytes");
        if level == SOL_CAN_J1939 && ty == SCM_J1939_DEST_ADDR && len > 16 {
            da = bytes.get(at + 16).copied();
        }
        at += (len + 7) & !7;
    }
    Ok(Msg {
        data: data[..r.len.min(data.len())].to_vec(),
        pgn: u32::from_ne_bytes([name[16], name[17], name[18], name[19]]),
        sa: name[20],
        da,
        flags: r.flags,
    })
}

/// Checks that `m` is `data` from `sa` to `da` with [`PGN`], whole.
pub(super) fn want_msg(m: &Msg, data: &[u8], sa: u8, da: Option<u8>, what: &str) -> TestResult {
    ensure!(
        m.data.len() == data.len() && m.flags & libc::MSG_TRUNC == 0,
        "{what}: {} bytes (flags {:#x}), want {}",
        m.data.len(),
        m.flags,
        data.len()
    );
    ensure!(
        m.data == data,
        "{what}: the bytes differ from those sent, first at {}",
        m.data
            .iter()
            .zip(data)
            .position(|(a, b)| a != b)
            .unwrap_or(0)
    );
    ensure!(
        m.pgn == PGN && m.sa == sa && m.da == da,
        "{what}: PGN {:05X} from {:02X}, DEST_ADDR {:02X?}; want PGN {PGN:05X} from {sa:02X}, \
         DEST_ADDR {da:02X?}",
        m.pgn,
        m.sa,
        m.da
    );
    Ok(())
}

/// A CAN_RAW socket on `ifindex` with room for every frame of a 1785-byte
/// session (its default buffer holds some 250 frames), so that none is
/// dropped while the test waits elsewhere.
fn bus_socket(ifindex: u32) -> Result<OwnedFd, String> {
    let s = raw_open(ifindex)?;
    sys::set_rcvbufforce(&s, 8 << 20).or_fail("SO_RCVBUFFORCE")?;
    Ok(s)
}

/// A CAN_RAW socket on `ifindex` receiving only the frames of `pgns` from
/// `sa` to `da` (at any priority) through exact-identifier filters.
///
/// It is the socket to wait on when the J1939 stack's handling of such a
/// frame must be over once the frame has been read. Mainline's
/// `can_rcv_filter` hands a frame to the receivers of all frames first,
/// then to the masked ones (J1939's), then to those of its exact
/// identifier, in one softirq: a reader of [`bus_socket`] can run before
/// J1939 has seen the frame; a reader of this socket cannot. This matters
/// for mainline's own abort after a timeout. It reports the session's
/// error on the sending socket twice, at the timeout
/// (`__j1939_session_cancel`) and again when the abort comes back to it
/// (`j1939_xtp_rx_abort` as transmitter); a test that read the abort on
/// [`bus_socket`], then SO_ERROR twice, saw the second report
/// (`j1939_tp_abort_from_peer`, mainline stage, CI of 7b48b72,
/// 2026-11-30). Ours reports the error once, at the timeout.
fn exact_socket(ifindex: u32, sa: u8, da: u8, pgns: &[u32]) -> Result<OwnedFd, String> {
    let mask = libc::CAN_EFF_MASK | libc::CAN_EFF_FLAG | libc::CAN_RTR_FLAG;
    let f: Vec<(u32, u32)> = pgns
        .iter()
        .flat_map(|&pgn| (0..8).map(move |prio| (can_id(prio, pgn, da, sa), mask)))
        .collect();
    let s = canraw::open_fd(ifindex, &f, false)?;
    sys::set_rcvbufforce(&s, 8 << 20).or_fail("SO_RCVBUFFORCE")?;
    Ok(s)
}

/// `sendto` of `data` to `da` with [`PGN`], which must return its size at
/// once (a session runs after the call).
pub(super) fn send_to(s: impl AsFd, data: &[u8], da: u8, what: &str) -> TestResult {
    let n = raw::sendto(&s, data, 0, Some(&jaddr(0, 0, PGN, da))).or_fail(what)?;
    ensure!(n == data.len(), "{what}: returned {n}, want {}", data.len());
    Ok(())
}

/// Waits (within [`T`]) until `s` reports an error (POLLERR): a session
/// of it has failed.
pub(super) fn wait_pollerr(s: impl AsFd, what: &str) -> TestResult {
    let r = sys::poll_one(&s, libc::POLLERR, T.as_millis() as i32).or_fail("poll")?;
    ensure!(
        r & libc::POLLERR != 0,
        "{what}: poll gave {r:#x} within {T:?}, want POLLERR"
    );
    Ok(())
}

/// SO_ERROR of `s` (reading it clears it).
fn so_error(s: impl AsFd) -> Result<i32, String> {
    let mut e = [0u8; 4];
    raw::getsockopt(&s, libc::SOL_SOCKET, libc::SO_ERROR, &mut e).or_fail("SO_ERROR")?;
    Ok(i32::from_ne_bytes(e))
}

/// The frames of one RTS/CTS session from `sa` to `da` of `msg` as the
/// bus shows them: the RTS, then each CTS from `da` (the packets it asks
/// for starting at the next one not yet sent) followed by those DTs,
/// then the EOMA from `da` (size and packet count).
fn check_session_on_bus(bus: impl AsFd, sa: u8, da: u8, msg: &[u8]) -> TestResult {
    let addrs = [sa, da];
    let n = packets(msg.len());
    let f = next_of(&bus, &addrs, "the RTS")?;
    want_rts(&f, sa, da, msg.len(), PGN)?;
    let mut next = 1;
    let mut ctss = 0;
    while next <= n {
        let f = next_of(&bus, &addrs, "a CTS")?;
        ensure!(
            f.pgn == PGN_TP_CM
                && f.sa == da
                && f.da == sa
                && f.data.len() == 8
                && f.data[0] == CTS
                && f.data[3..5] == [0xff, 0xff]
                && f.data[5..] == pgn_bytes(PGN),
            "after packet {}: {}, want a CTS {da:02X}->{sa:02X} [11 count next FF FF {}]",
            next - 1,
            show(&f),
            hex(&pgn_bytes(PGN))
        );
        let (count, from) = (usize::from(f.data[1]), usize::from(f.data[2]));
        ensure!(
            from == next && count >= 1 && next + count - 1 <= n,
            "CTS {}: {count} packets from {from}, want 1..={} from {next}",
            ctss + 1,
            n - next + 1
        );
        ctss += 1;
        for seq in next..next + count {
            let f = next_of(&bus, &addrs, "a DT")?;
            want_dt(&f, sa, da, seq, msg)?;
        }
        next += count;
    }
    let f = next_of(&bus, &addrs, "the EOMA")?;
    let size = (msg.len() as u16).to_le_bytes();
    want_cm(
        &f,
        da,
        sa,
        &cm([EOMA, size[0], size[1], n as u8, 0xff], PGN),
        "the EOMA",
    )
}

/// Messages of 9 (the least TP carries), 100 and 1785 bytes (the most)
/// from a socket at 0x20 to one at 0x30 on the same interface: each
/// `sendto` returns the size, the receiver reads each whole (source,
/// PGN, SCM_J1939_DEST_ADDR), and the bus shows an RTS/CTS session per
/// message (the receiving kernel's CTS and EOMA from 0x30) carrying
/// exactly the bytes sent.
fn j1939_tp_unicast_sizes(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let bus = bus_socket(i0)?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    for (k, size) in [9usize, 100, 1785].into_iter().enumerate() {
        let msg = payload(size, k as u32 + 1);
        send_to(&a, &msg, 0x30, &format!("sendto {size} bytes"))?;
        let m = recv_msg(&b, &format!("{size} bytes at 0x30"))?;
        want_msg(&m, &msg, 0x20, Some(0x30), &format!("{size} bytes at 0x30"))?;
        check_session_on_bus(&bus, 0x20, 0x30, &msg)
            .map_err(|e| format!("{size} bytes on the bus: {e}"))?;
    }
    Ok(())
}

/// A broadcast of 100 bytes (SO_BROADCAST, to address 0xFF): two
/// receivers at 0x30 and 0x40 (with SO_BROADCAST) read it whole; the bus
/// shows a BAM (size, packets, PGN) and the 15 DTs, and nothing from the
/// receivers: the frame after the last DT is the sender's next message.
fn j1939_bam_broadcast(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let bus = bus_socket(i0)?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    set_broadcast(&a)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    set_broadcast(&b)?;
    let c = jbound(i0, 0x40, NO_PGN)?;
    set_broadcast(&c)?;
    let msg = payload(100, 7);
    send_to(&a, &msg, NO_ADDR, "sendto broadcast 100 bytes")?;
    for (s, who) in [(&b, "0x30"), (&c, "0x40")] {
        let m = recv_msg(s, &format!("the broadcast at {who}"))?;
        want_msg(&m, &msg, 0x20, None, &format!("the broadcast at {who}"))?;
    }
    // A marker from 0x20 after both have the message.
    send_to(&a, &[0x4d], NO_ADDR, "sendto broadcast 1 byte")?;

    let addrs = [0x20, 0x30, 0x40];
    let f = next_of(&bus, &addrs, "the BAM")?;
    want_cm(
        &f,
        0x20,
        NO_ADDR,
        &cm([BAM, 100, 0, 15, 0xff], PGN),
        "the BAM",
    )?;
    for seq in 1..=15 {
        let f = next_of(&bus, &addrs, "a DT")?;
        want_dt(&f, 0x20, NO_ADDR, seq, &msg)?;
    }
    let f = next_of(&bus, &addrs, "the marker")?;
    ensure!(
        f == Frame {
            pgn: PGN,
            da: NO_ADDR,
            sa: 0x20,
            data: vec![0x4d]
        },
        "after the last DT: {}, want the marker (no CTS or EOMA for a BAM)",
        show(&f)
    );
    Ok(())
}

/// can-utils' `j1939cat` as its usage text shows it: a receiver
/// `j1939cat -r can0:0x90 > FILE` and a sender `j1939cat -i INPUT
/// can0:0x80 :0x90,0x12300` of a 64 KiB file (8 KiB on the debug
/// kernel), which goes by ETP (more
/// than 1785 bytes: the first frame from 0x80 is an ETP.CM RTS with the
/// size). The received file equals the input.
///
/// The sender may exit 1 saying "recvmsg error notification: truncated"
/// (can-utils 2020.11 on mainline 6.12.117, 2026-11-30): it reads its
/// error queue into a 100-byte control buffer, too small for what 6.12
/// puts there (timestamps, statistics and the J1939 notification), after
/// its `send` has queued the whole file; its `close` then waits for the
/// session's end (mainline's `j1939_sk_release`), so the file still
/// arrives. (`-P 0`, plain blocking sends, fails too: it sends 0 bytes
/// after the last and calls that an error.) Any other failure fails.
fn j1939_canutils_j1939cat_etp(ctx: &mut Ctx) -> TestResult {
    // The file's size (KiB): 64 on the release kernel; 8 (1171 packets,
    // still ETP) on the debug kernel, where the 64 KiB session (9363
    // packets, 2.5 s on release) outlasted the sender's 60 s bound: its
    // `close` waits for the session's end (make check of dfe3356,
    // 2026-11-30).
    let size = crate::ctx::sized("RCAN_J1939CAT_KIB", 64, 8) as usize;
    let size = size << 10;
    let mut want = vec![ETP_RTS];
    want.extend_from_slice(&(size as u32).to_le_bytes());
    want.extend_from_slice(&pgn_bytes(PGN));
    j1939cat_transfer(ctx, size, |f| {
        ensure!(
            f.pgn == PGN_ETP_CM && f.da == 0x90 && f.data == want,
            "first frame from 0x80: {}, want the ETP RTS PGN {PGN_ETP_CM:05X} 80->90 [{}]",
            show(f),
            hex(&want)
        );
        Ok(())
    })
}

/// can-utils' `j1939cat` sending a file of 5 bytes, one single frame, as
/// [`j1939_canutils_j1939cat_etp`] sends its file: the frame from 0x80 to
/// 0x90 carries the file, `j1939cat -r` writes it, and the sender ends
/// within its bound. The sender waits for its error queue's TX ACK of the
/// last message (or, as there, exits 1 on the truncated notification);
/// before single frames were told on the error queue (2026-12-01) it
/// waited out its 100 s poll on ours and the test's 60 s bound failed it.
fn j1939_canutils_j1939cat_single_frame(ctx: &mut Ctx) -> TestResult {
    j1939cat_transfer(ctx, 5, |f| {
        ensure!(
            f.pgn == PGN && f.da == 0x90 && f.data == payload(5, 64),
            "first frame from 0x80: {}, want the file, PGN {PGN:05X} 80->90",
            show(f)
        );
        Ok(())
    })
}

/// `j1939cat -r can0:0x90 > FILE` receiving what `j1939cat -i INPUT
/// can0:0x80 :0x90,0x12300` sends, a file of `size` bytes: the sender
/// ends within [`TOOL_LIMIT`] (exit 0, or 1 with can-utils' truncated
/// notification, see [`j1939_canutils_j1939cat_etp`]), the first frame
/// from 0x80 passes `first`, and the received file equals the input.
fn j1939cat_transfer(
    ctx: &mut Ctx,
    size: usize,
    first: impl Fn(&Frame) -> TestResult,
) -> TestResult {
    const CTRUNC: &str = "recvmsg error notification: truncated";
    let i0 = ctx.j1939_ifaces(1)?[0];
    let c0 = dev(0);
    let from80 = raw_from(i0, 0x80)?;
    let dir = tools::TempDir::new("j1939cat")?;
    let input = dir.path().join("in");
    let output = dir.path().join("out");
    let msg = payload(size, 64);
    std::fs::write(&input, &msg).or_fail("write the input file")?;
    let (inp, outp) = (
        input.to_str().ok_or("non-UTF-8 path")?,
        output.to_str().ok_or("non-UTF-8 path")?,
    );
    let recv_cmd = format!("exec j1939cat -r {c0}:0x90 > {outp}");
    let mut r = tools::spawn("sh", &["-c", &recv_cmd], None)?;
    r.wait_listening()?;
    let s = tools::spawn(
        "j1939cat",
        &["-i", inp, &format!("{c0}:0x80"), &format!(":0x90,{PGN:#x}")],
        None,
    )?
    .finish(TOOL_LIMIT)?;
    ensure!(
        s.status.success() || s.stderr.contains(CTRUNC),
        "j1939cat -i: {}: {}",
        s.status,
        s.stderr.trim()
    );
    if !s.status.success() {
        ctx.note(format!("j1939cat -i: {}: {CTRUNC}", s.status));
    }
    let (id, data) = raw_next(&from80, "the first frame from 0x80")?;
    first(&frame(id, data))?;
    // The receiver writes the message after its recv: wait for the file
    // to be whole.
    crate::check::wait_until(TOOL_LIMIT, "j1939cat -r to write the file", || {
        std::fs::metadata(&output).is_ok_and(|m| m.len() as usize >= size)
    })
    .map_err(|e| format!("{e}; j1939cat -r: {}", r.stderr_now().trim()))?;
    let got = std::fs::read(&output).or_fail("read the output file")?;
    let _ = r.signal("TERM");
    let _ = r.finish(TOOL_LIMIT)?;
    ensure!(
        got == msg,
        "j1939cat -r wrote {} bytes, not the {size} sent (first difference at {})",
        got.len(),
        got.iter()
            .zip(&msg)
            .position(|(a, b)| a != b)
            .unwrap_or(got.len().min(size))
    );
    Ok(())
}

/// Two sockets at 0x20 send to 0x50, an address nobody answers: the
/// first `sendto` returns its size at once and its RTS goes out; the
/// second, an identical session (same source and destination) while
/// the first waits for a CTS, is refused with EBUSY (mainline) and sends
/// nothing. After T3 the first session ends with an abort "timeout"
/// (reason 3) from 0x20 to 0x50, and its socket reports the error
/// (POLLERR): its next `sendto` fails with EHOSTUNREACH (mainline's
/// errno for a timeout), the one after goes out. The bus is read on an
/// [`exact_socket`]: mainline reports the timeout twice.
fn j1939_tp_second_session_busy(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let bus = exact_socket(i0, 0x20, 0x50, &[PGN_TP_CM, PGN])?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let a2 = jbound(i0, 0x20, NO_PGN)?;
    let msg = payload(20, 4);
    send_to(&a, &msg, 0x50, "sendto 20 bytes to 0x50")?;
    want_errno(
        raw::sendto(&a2, &msg, 0, Some(&jaddr(0, 0, PGN, 0x50))),
        libc::EBUSY,
        "a second socket's sendto 20 bytes to 0x50 while the first session runs",
    )?;
    let addrs = [0x20, 0x50];
    let f = next_of(&bus, &addrs, "the RTS")?;
    want_rts(&f, 0x20, 0x50, 20, PGN)?;
    let f = next_of(&bus, &addrs, "the abort")?;
    want_cm(
        &f,
        0x20,
        0x50,
        &cm([ABORT, ABORT_TIMEOUT, 0xff, 0xff, 0xff], PGN),
        "after the RTS (no second RTS)",
    )?;
    wait_pollerr(&a, "the first socket after the abort")?;
    want_errno(
        raw::sendto(&a, &[1], 0, Some(&jaddr(0, 0, PGN, 0x50))),
        libc::EHOSTUNREACH,
        "the first socket's next sendto after its session timed out",
    )?;
    send_to(&a, &[2], 0x50, "the first socket's sendto after that")?;
    let f = next_of(&bus, &addrs, "the single frame")?;
    ensure!(
        f.pgn == PGN && f.sa == 0x20 && f.da == 0x50 && f.data == [2],
        "after the abort: {}, want the single frame [02] 20->50",
        show(&f)
    );
    ensure!(
        so_error(&a2)? == 0,
        "the refused socket has a pending error"
    );
    Ok(())
}

/// A node at 0x60 (CAN_RAW) sends an RTS for 20 bytes (3 packets) to a
/// socket at 0x30; the kernel answers with a CTS for the 3 packets from
/// the first; the peer stays silent; after T2 the kernel aborts
/// (reason 3, timeout) from 0x30 to 0x60, and the socket receives no
/// message: the first it reads is a single frame the peer sends after.
fn j1939_tp_raw_peer_silent_after_cts(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let peer = bus_socket(i0)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    let addrs = [0x30, 0x60];
    raw_send(
        &peer,
        can_id(7, PGN_TP_CM, 0x30, 0x60),
        &cm([RTS, 20, 0, 3, 0xff], PGN),
    )?;
    let f = next_of(&peer, &addrs, "the CTS")?;
    want_cm(&f, 0x30, 0x60, &cm([CTS, 3, 1, 0xff, 0xff], PGN), "the CTS")?;
    let f = next_of(&peer, &addrs, "the abort")?;
    want_cm(
        &f,
        0x30,
        0x60,
        &cm([ABORT, ABORT_TIMEOUT, 0xff, 0xff, 0xff], PGN),
        "after the CTS and silence",
    )?;
    raw_send(&peer, can_id(6, PGN, 0x30, 0x60), &[0x61, 0x62, 0x63])?;
    let m = recv_msg(&b, "the single frame at 0x30")?;
    want_msg(
        &m,
        &[0x61, 0x62, 0x63],
        0x60,
        Some(0x30),
        "the first message at 0x30",
    )
}

/// The kernel sends 100 bytes from 0x20 to 0x61, a node played by a
/// CAN_RAW socket: its RTS, the peer's CTS for all 15 packets, the 15 DTs
/// (the message's bytes, the last padded with 0xFF), the peer's EOMA.
/// The session ends cleanly (no error on the socket) and a second
/// message goes the same way.
fn j1939_tp_raw_peer_receives(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let peer = bus_socket(i0)?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let addrs = [0x20, 0x61];
    for k in 0..2 {
        let msg = payload(100, 10 + k);
        send_to(&a, &msg, 0x61, &format!("sendto 100 bytes #{k}"))?;
        let f = next_of(&peer, &addrs, "the RTS")?;
        want_rts(&f, 0x20, 0x61, 100, PGN).map_err(|e| format!("message {k}: {e}"))?;
        raw_send(
            &peer,
            can_id(7, PGN_TP_CM, 0x20, 0x61),
            &cm([CTS, 15, 1, 0xff, 0xff], PGN),
        )?;
        for seq in 1..=15 {
            let f = next_of(&peer, &addrs, "a DT")?;
            want_dt(&f, 0x20, 0x61, seq, &msg).map_err(|e| format!("message {k}: {e}"))?;
        }
        raw_send(
            &peer,
            can_id(7, PGN_TP_CM, 0x20, 0x61),
            &cm([EOMA, 100, 0, 15, 0xff], PGN),
        )?;
    }
    ensure!(
        so_error(&a)? == 0,
        "an error on the sender after two good sessions"
    );
    Ok(())
}

/// The peer at 0x61 answers the RTS with an abort "busy" (reason 1):
/// the sending socket reports an error (POLLERR, SO_ERROR once), and the
/// next frame from 0x20 after that is a later single frame.
///
/// The error differs. Mainline 6.12 does not see the abort: an abort
/// addressed to a local address is looked up among its receive sessions
/// only (`j1939_tp_cmd_recv` passes `transmitter` false to
/// `j1939_xtp_rx_abort`), so the sender waits out T3, sends its own abort
/// (reason 3, timeout) and reports EHOSTUNREACH (seen on 6.12.117,
/// 2026-11-30: "rx timeout, send abort" in its log). Ours (the core's
/// `TxSession`) ends the session at the peer's abort with the reason's
/// errno, EALREADY for "busy", and sends nothing more. The frames from
/// 0x20 are read on an [`exact_socket`]: mainline reports its timeout
/// twice, and the second report must be in before SO_ERROR is read.
fn j1939_tp_abort_from_peer(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let peer = bus_socket(i0)?;
    let from_a = exact_socket(i0, 0x20, 0x61, &[PGN_TP_CM, PGN])?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let addrs = [0x20, 0x61];
    let msg = payload(30, 5);
    send_to(&a, &msg, 0x61, "sendto 30 bytes")?;
    let f = next_of(&from_a, &addrs, "the RTS")?;
    want_rts(&f, 0x20, 0x61, 30, PGN)?;
    raw_send(
        &peer,
        can_id(7, PGN_TP_CM, 0x20, 0x61),
        &cm([ABORT, ABORT_BUSY, 0xff, 0xff, 0xff], PGN),
    )?;
    let want = match ctx.stack() {
        Stack::Mainline => {
            let f = next_of(&from_a, &addrs, "mainline's abort after T3")?;
            want_cm(
                &f,
                0x20,
                0x61,
                &cm([ABORT, ABORT_TIMEOUT, 0xff, 0xff, 0xff], PGN),
                "mainline after the peer's abort",
            )?;
            libc::EHOSTUNREACH
        }
        Stack::Ours => libc::EALREADY,
    };
    wait_pollerr(&a, "the sender after the peer's abort")?;
    let e = so_error(&a)?;
    ensure!(
        e == want,
        "SO_ERROR after the peer's abort (busy): {}, want {}",
        crate::check::errno_name(e),
        crate::check::errno_name(want)
    );
    ensure!(so_error(&a)? == 0, "SO_ERROR read twice: the error stays");
    send_to(&a, &[3], 0x61, "sendto 1 byte after the abort")?;
    let f = next_of(&from_a, &addrs, "the single frame")?;
    ensure!(
        f.pgn == PGN && f.sa == 0x20 && f.da == 0x61 && f.data == [3],
        "after the peer's abort: {}, want the single frame [03] 20->61",
        show(&f)
    );
    Ok(())
}

/// TP.DT packet `seq` (1-based) of `msg`: the sequence number and 7
/// bytes of it, the last packet padded with 0xFF.
fn dt(seq: usize, msg: &[u8]) -> Vec<u8> {
    let lo = (seq - 1) * 7;
    let mut d = vec![seq as u8];
    d.extend_from_slice(&msg[lo..(lo + 7).min(msg.len())]);
    d.resize(8, 0xff);
    d
}

/// A node at 0x60 (CAN_RAW) sends 20 bytes (3 packets) to a socket at
/// 0x30 and, after the kernel's CTS and one data packet, the same RTS
/// again (mainline's bug class "second RTS": `j1939_xtp_rx_rts_session_active`
/// has had use-after-free and double-deactivation fixes). The kernel
/// aborts the running session with reason 1 ("already in a session")
/// and starts none for the second RTS; a third RTS then starts a fresh
/// session that runs to its EOMA, and the first message the socket
/// reads is that one, whole: nothing of the aborted session.
fn j1939_tp_raw_peer_second_rts(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let peer = bus_socket(i0)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    let addrs = [0x30, 0x60];
    let to_b = can_id(7, PGN_TP_CM, 0x30, 0x60);
    let rts = cm([RTS, 20, 0, 3, 0xff], PGN);
    let msg = payload(20, 31);
    raw_send(&peer, to_b, &rts)?;
    let f = next_of(&peer, &addrs, "the CTS")?;
    want_cm(&f, 0x30, 0x60, &cm([CTS, 3, 1, 0xff, 0xff], PGN), "the CTS")?;
    raw_send(&peer, can_id(7, PGN_TP_DT, 0x30, 0x60), &dt(1, &msg))?;
    raw_send(&peer, to_b, &rts)?;
    let f = next_of(&peer, &addrs, "the answer to the second RTS")?;
    want_cm(
        &f,
        0x30,
        0x60,
        &cm([ABORT, ABORT_BUSY, 0xff, 0xff, 0xff], PGN),
        "the answer to a second RTS during the session",
    )?;
    raw_send(&peer, to_b, &rts)?;
    let f = next_of(&peer, &addrs, "the CTS of the third RTS")?;
    want_cm(
        &f,
        0x30,
        0x60,
        &cm([CTS, 3, 1, 0xff, 0xff], PGN),
        "the answer to a third RTS after the abort",
    )?;
    for seq in 1..=3 {
        raw_send(&peer, can_id(7, PGN_TP_DT, 0x30, 0x60), &dt(seq, &msg))?;
    }
    let f = next_of(&peer, &addrs, "the EOMA")?;
    want_cm(&f, 0x30, 0x60, &cm([EOMA, 20, 0, 3, 0xff], PGN), "the EOMA")?;
    let m = recv_msg(&b, "the 20 bytes at 0x30")?;
    want_msg(&m, &msg, 0x60, Some(0x30), "the first message at 0x30")
}

/// The kernel sends 100 bytes from 0x20 to a node played by a CAN_RAW
/// socket that answers the RTS with a hold, CTS(0) (mainline's bug class
/// "CTS hold timeout"):
/// 1. to 0x61, the hold and then silence: after T4 the kernel aborts
///    with reason 3 (timeout) and the socket's error is EHOSTUNREACH,
///    reported once when read (both stacks: mainline's T4 is 550 ms,
///    the core's too);
/// 2. to 0x62, the hold and then CTS(15) from packet 1: the stacks
///    differ. Ours follows the standard: the hold ends, the 15 packets
///    go out, the peer's EOMA ends the session without an error, and the
///    socket's next message goes out (its RTS). Mainline aborts a CTS that
///    follows a CTS with reason 8 ("duplicate sequence number",
///    `j1939_xtp_rx_cts_one`: the last command equals this one) and
///    reports EPROTO (j1939.rst, "Mainline or the standard").
///
/// The frames from 0x20 are read on an [`exact_socket`]: mainline reports
/// a session's error twice (at the abort and at its echo).
fn j1939_tp_raw_peer_holds(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let peer = bus_socket(i0)?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let hold = cm([CTS, 0, 0xff, 0xff, 0xff], PGN);
    let msg = payload(100, 21);

    let to61 = exact_socket(i0, 0x20, 0x61, &[PGN_TP_CM, PGN_TP_DT, PGN])?;
    let addrs = [0x20, 0x61];
    send_to(&a, &msg, 0x61, "sendto 100 bytes to 0x61")?;
    let f = next_of(&to61, &addrs, "the RTS to 0x61")?;
    want_rts(&f, 0x20, 0x61, 100, PGN)?;
    raw_send(&peer, can_id(7, PGN_TP_CM, 0x20, 0x61), &hold)?;
    let f = next_of(&to61, &addrs, "the frame after the hold and silence")?;
    want_cm(
        &f,
        0x20,
        0x61,
        &cm([ABORT, ABORT_TIMEOUT, 0xff, 0xff, 0xff], PGN),
        "after a hold and silence (T4)",
    )?;
    wait_pollerr(&a, "the sender after the hold's timeout")?;
    let e = so_error(&a)?;
    ensure!(
        e == libc::EHOSTUNREACH,
        "SO_ERROR after the hold's timeout: {}, want EHOSTUNREACH",
        crate::check::errno_name(e)
    );
    ensure!(so_error(&a)? == 0, "SO_ERROR read twice: the error stays");

    let to62 = exact_socket(i0, 0x20, 0x62, &[PGN_TP_CM, PGN_TP_DT, PGN])?;
    let addrs = [0x20, 0x62];
    let from62 = can_id(7, PGN_TP_CM, 0x20, 0x62);
    send_to(&a, &msg, 0x62, "sendto 100 bytes to 0x62")?;
    let f = next_of(&to62, &addrs, "the RTS to 0x62")?;
    want_rts(&f, 0x20, 0x62, 100, PGN)?;
    raw_send(&peer, from62, &hold)?;
    raw_send(&peer, from62, &cm([CTS, 15, 1, 0xff, 0xff], PGN))?;
    match ctx.stack() {
        Stack::Ours => {
            for seq in 1..=15 {
                let f = next_of(&to62, &addrs, "a DT after the hold")?;
                want_dt(&f, 0x20, 0x62, seq, &msg)?;
            }
            raw_send(&peer, from62, &cm([EOMA, 100, 0, 15, 0xff], PGN))?;
            // The socket's next message starts only once this session
            // has ended: its RTS, not an abort, is the next frame.
            let next = payload(9, 22);
            send_to(&a, &next, 0x62, "sendto 9 bytes to 0x62 after the EOMA")?;
            let f = next_of(&to62, &addrs, "the next message's RTS")?;
            want_rts(&f, 0x20, 0x62, 9, PGN)?;
            ensure!(so_error(&a)? == 0, "an error on the sender after the resumed session");
        }
        Stack::Mainline => {
            let f = next_of(&to62, &addrs, "mainline's answer to the CTS after the hold")?;
            want_cm(
                &f,
                0x20,
                0x62,
                &cm([ABORT, ABORT_DUP_SEQ, 0xff, 0xff, 0xff], PGN),
                "mainline after a CTS following a hold",
            )?;
            wait_pollerr(&a, "the sender after mainline's abort")?;
            let e = so_error(&a)?;
            ensure!(
                e == libc::EPROTO,
                "SO_ERROR after mainline's abort (reason 8): {}, want EPROTO",
                crate::check::errno_name(e)
            );
        }
    }
    Ok(())
}
