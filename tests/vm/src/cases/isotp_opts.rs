// SPDX-License-Identifier: GPL-2.0
//! CAN_ISOTP's options and flags, each driven through a kernel ISO-TP
//! socket against a CAN_RAW peer that plays the other end of the bus
//! (crafted flow control, wait frames, bad padding, consecutive frames),
//! and its effect checked on the bus (frame content and length, order and
//! counts) and in the errno the socket reports (issue 41, isotp.rst
//! "Coverage: every option and flag and its test").
//!
//! Frame spacing is checked only as a lower bound on the peer's kernel
//! receive timestamps (`SO_TIMESTAMPNS`), which a timer that never fires
//! early makes robust on a loaded, emulated VM; the one upper bound (a
//! gap that `CAN_ISOTP_FRAME_TXTIME_ZERO` must not leave at 4 s) is
//! generous. No sleep synchronises: frames and conditions are awaited;
//! the sleeps that remain pace a peer that must send a frame after a
//! given time (wait frames against N_Bs, a CF after the receiver's
//! forced STmin).
//!
//! The test thread is pinned to one CPU (its writer and poller threads
//! inherit that) so that the peer's frames, each received in the NET_RX
//! softirq of the CPU that sent it, reach the ISO-TP socket in the order
//! the peer wrote them, also if the softirq is deferred to ksoftirqd.
//!
//! Portable: the three `Uses::Stack` tests and `isotp_max_pdu_size` pass
//! against mainline's can-isotp.ko too (mainline stage), so they encode
//! mainline 6.12's behaviour.

use std::os::fd::{AsFd, OwnedFd};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use rcan_uapi::raw;

use crate::check::{ensure, errno_name, wait_blocked, OrFail, TestResult};
use crate::ctx::{dev, Ctx};

use super::isotp::{
    errno_of, hex, joined_within, opts, pattern, raw_open, raw_send, show, tp_addr, tp_socket,
    want_errno, write_bg, Fr, CAN_ISOTP_LL_OPTS, CAN_ISOTP_OPTS, CAN_ISOTP_WAIT_TX_DONE,
    SOL_CAN_ISOTP,
};
use super::portable_table;

pub static TESTS: &[crate::Test] = portable_table![
    isotp_max_pdu_size;
    stack:
    isotp_opts_sender,
    isotp_opts_receiver,
    isotp_opts_fd_tx_dl,
];

const CAN_ISOTP_RECV_FC: i32 = 2;
const CAN_ISOTP_TX_STMIN: i32 = 3;
const CAN_ISOTP_RX_STMIN: i32 = 4;
const CAN_ISOTP_RX_PADDING: u32 = 0x0008;
const CAN_ISOTP_CHK_PAD_LEN: u32 = 0x0010;
const CAN_ISOTP_CHK_PAD_DATA: u32 = 0x0020;
const CAN_ISOTP_HALF_DUPLEX: u32 = 0x0040;
const CAN_ISOTP_FORCE_TXSTMIN: u32 = 0x0080;
const CAN_ISOTP_FORCE_RXSTMIN: u32 = 0x0100;
const CAN_ISOTP_CF_BROADCAST: u32 = 0x1000;
const CAN_ISOTP_DYN_FC_PARMS: u32 = 0x2000;
const CAN_ISOTP_FRAME_TXTIME_ZERO: u32 = 0xFFFF_FFFF;
/// `SO_RXQ_OVFL` of `<asm-generic/socket.h>`.
const SO_RXQ_OVFL: i32 = 40;
const MS: u32 = 1_000_000;
const CANFD_BRS: u8 = 0x01;

/// Deadline of every awaited frame or call: it ends a wait for
/// something that never comes, it never paces the test.
const T: Duration = Duration::from_secs(10);

/// `struct can_isotp_options`: `flags`, `frame_txtime` ns (0: unchanged),
/// no address bytes, `txpad_content` 0xCC, `rxpad_content` `rxpad`.
fn opts_with(flags: u32, frame_txtime: u32, rxpad: u8) -> [u8; 12] {
    let mut o = opts(flags);
    o[4..8].copy_from_slice(&frame_txtime.to_ne_bytes());
    o[10] = rxpad;
    o
}

/// An unbound ISO-TP socket with CAN_ISOTP_OPTS `o`, then each option of
/// `more` (name, value) at SOL_CAN_ISOTP.
fn tp_with(o: [u8; 12], more: &[(i32, &[u8])]) -> Result<OwnedFd, String> {
    let s = tp_socket(0)?;
    raw::setsockopt(&s, SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &o).or_fail("CAN_ISOTP_OPTS")?;
    for (name, v) in more {
        raw::setsockopt(&s, SOL_CAN_ISOTP, *name, v)
            .or_fail(format!("SOL_CAN_ISOTP option {name} = {}", hex(v)))?;
    }
    Ok(s)
}

fn bind_tp(s: impl AsFd, ifindex: u32, rx: u32, tx: u32) -> TestResult {
    raw::bind(s, &tp_addr(ifindex, rx, tx)).or_fail(format!("bind rx {rx:03X} tx {tx:03X}"))
}

/// [`tp_with`] bound to `rx`/`tx` on `ifindex`, with SO_RCVTIMEO [`T`].
fn tp_on(
    o: [u8; 12],
    more: &[(i32, &[u8])],
    ifindex: u32,
    rx: u32,
    tx: u32,
) -> Result<OwnedFd, String> {
    let s = tp_with(o, more)?;
    bind_tp(&s, ifindex, rx, tx)?;
    raw::set_timeout(&s, libc::SO_RCVTIMEO, T).or_fail("SO_RCVTIMEO")?;
    Ok(s)
}

/// A frame the peer received, with its kernel receive time.
struct At {
    f: Fr,
    /// `SO_TIMESTAMPNS` (CLOCK_REALTIME), ns.
    ns: i128,
}

/// The peer: a CAN_RAW socket on `ifindex` taking CAN FD frames too, all
/// identifiers, with kernel receive timestamps. (It does not receive its
/// own frames.)
fn peer_open(ifindex: u32) -> Result<OwnedFd, String> {
    let s = raw_open(ifindex)?;
    raw::setsockopt(
        &s,
        libc::SOL_SOCKET,
        libc::SO_TIMESTAMPNS,
        &1i32.to_ne_bytes(),
    )
    .or_fail("SO_TIMESTAMPNS")?;
    Ok(s)
}

/// The next frame on the peer within `t`, or None.
fn peer_read(s: impl AsFd, t: Duration) -> Result<Option<At>, String> {
    raw::set_timeout(&s, libc::SO_RCVTIMEO, t).or_fail("SO_RCVTIMEO")?;
    match crate::sys::recvmsg(&s, 72, 0) {
        Ok(r) if r.len == 16 || r.len == 72 => {
            let b = &r.data;
            let len = usize::from(b[4]).min(r.len - 8);
            let ts = r
                .timespec
                .ok_or("a frame without SCM_TIMESTAMPNS on the peer")?;
            Ok(Some(At {
                f: Fr {
                    id: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
                    fd: r.len == 72,
                    flags: b[5],
                    data: b[8..8 + len].to_vec(),
                },
                ns: i128::from(ts.tv_sec) * 1_000_000_000 + i128::from(ts.tv_nsec),
            }))
        }
        Ok(r) => Err(format!("CAN_RAW read {} bytes", r.len)),
        Err(e) if e.raw_os_error() == Some(libc::EAGAIN) => Ok(None),
        Err(e) => Err(format!("CAN_RAW read: {e}")),
    }
}

/// The next frame with identifier `id` on the peer within [`T`] (others
/// are skipped).
fn peer_expect(s: impl AsFd, id: u32, what: &str) -> Result<At, String> {
    let end = Instant::now() + T;
    loop {
        let left = end.saturating_duration_since(Instant::now());
        ensure!(!left.is_zero(), "no {what} (id {id:03X}) within {T:?}");
        if let Some(a) = peer_read(&s, left)? {
            if a.f.id == id {
                return Ok(a);
            }
        }
    }
}

/// The next `n` frames with identifier `id` on the peer.
fn peer_frames(s: impl AsFd, id: u32, n: usize, what: &str) -> Result<Vec<At>, String> {
    (0..n)
        .map(|i| peer_expect(&s, id, &format!("{what} (frame {} of {n})", i + 1)))
        .collect()
}

/// Frames with identifier `id` already queued on the peer (none awaited).
fn peer_queued(s: impl AsFd, id: u32) -> Result<Vec<Fr>, String> {
    let mut v = Vec::new();
    while let Some(a) = peer_read(&s, Duration::from_millis(1))? {
        if a.f.id == id {
            v.push(a.f);
        }
    }
    Ok(v)
}

/// Sends a CAN FD frame `id##data` (no BRS) on `s`.
fn raw_send_fd(s: impl AsFd, id: u32, data: &[u8]) -> TestResult {
    let mut b = [0u8; 72];
    b[..4].copy_from_slice(&id.to_ne_bytes());
    b[4] = data.len() as u8;
    b[8..8 + data.len()].copy_from_slice(data);
    raw::write(s, &b).or_fail(format!("send {id:03X}##{}", hex(data)))?;
    Ok(())
}

/// The frames of `pdu` (longer than 7 bytes) as a classic sender without
/// padding and with normal addressing sends them, written here from ISO
/// 15765-2 (12-bit FF_DL): `1L LL` and 6 bytes, then `2N` and 7 bytes
/// each, N = 1, 2, ... mod 16, the last CF as long as its content.
fn classic_frames(pdu: &[u8]) -> Vec<Vec<u8>> {
    let n = pdu.len();
    let mut v = vec![[&[0x10 | (n >> 8) as u8, n as u8][..], &pdu[..6]].concat()];
    for (i, c) in pdu[6..].chunks(7).enumerate() {
        v.push([&[0x20 | ((i + 1) & 0xF) as u8][..], c].concat());
    }
    v
}

/// Checks that `got` (the sender's frames in bus order) are exactly
/// `want`.
fn same_frames(got: &[&Fr], want: &[Vec<u8>], what: &str) -> TestResult {
    let g: Vec<&[u8]> = got.iter().map(|f| &f.data[..]).collect();
    let w: Vec<&[u8]> = want.iter().map(|d| &d[..]).collect();
    ensure!(
        g == w,
        "{what}: frames {:?}, want {:?}",
        got.iter().map(|f| show(f)).collect::<Vec<_>>(),
        want.iter().map(|d| hex(d)).collect::<Vec<_>>()
    );
    Ok(())
}

/// Each frame of `fr` came at least `min` after the one before (kernel
/// receive timestamps; 1 % slack for CLOCK_REALTIME against the
/// monotonic clock of the kernel's timers).
fn gaps_at_least(fr: &[&At], min: Duration, what: &str) -> TestResult {
    let min_ns = min.as_nanos() as i128 * 99 / 100;
    for w in fr.windows(2) {
        let g = w[1].ns - w[0].ns;
        ensure!(
            g >= min_ns,
            "{what}: {} came {:.3} ms after {}, want at least {min:?}",
            show(&w[1].f),
            g as f64 / 1e6,
            show(&w[0].f)
        );
    }
    Ok(())
}

/// Reads one PDU from `s` (blocking, SO_RCVTIMEO): its bytes, or the
/// errno.
fn read_pdu(s: impl AsFd) -> Result<Result<Vec<u8>, i32>, String> {
    let mut buf = vec![0u8; 9000];
    match raw::read(&s, &mut buf) {
        Ok(n) => Ok(Ok(buf[..n].to_vec())),
        Err(e) => match e.raw_os_error() {
            Some(libc::EAGAIN) => Err("read: nothing within SO_RCVTIMEO (10 s)".into()),
            Some(n) => Ok(Err(n)),
            None => Err(format!("read: {e}")),
        },
    }
}

fn want_pdu(s: impl AsFd, pdu: &[u8], what: &str) -> TestResult {
    match read_pdu(s)? {
        Ok(p) => {
            ensure!(p == pdu, "{what}: read {}, want {}", hex(&p), hex(pdu));
            Ok(())
        }
        Err(e) => Err(format!("{what}: read {}, want {}", errno_name(e), hex(pdu))),
    }
}

fn want_read_errno(s: impl AsFd, want: i32, what: &str) -> TestResult {
    match read_pdu(s)? {
        Ok(p) => Err(format!(
            "{what}: read the PDU {}, want {} as mainline",
            hex(&p),
            errno_name(want)
        )),
        Err(e) => {
            ensure!(
                e == want,
                "{what}: read {}, want {} as mainline",
                errno_name(e),
                errno_name(want)
            );
            Ok(())
        }
    }
}

/// The result of a background writer, which must return within [`T`].
fn writer_result(
    w: thread::JoinHandle<std::io::Result<usize>>,
    what: &str,
) -> Result<std::io::Result<usize>, String> {
    joined_within(w, T, &format!("{what}: the writer to return"))
}

fn want_written(w: thread::JoinHandle<std::io::Result<usize>>, n: usize, what: &str) -> TestResult {
    let r = writer_result(w, what)?;
    ensure!(
        matches!(r, Ok(m) if m == n),
        "{what}: write returned {r:?}, want {n}"
    );
    Ok(())
}

fn want_write_errno(
    w: thread::JoinHandle<std::io::Result<usize>>,
    want: i32,
    what: &str,
) -> TestResult {
    want_errno(writer_result(w, what)?, want, what)
}

// ---------------------------------------------------------------------
// The sender's options.
// ---------------------------------------------------------------------

/// The sender's options and flags, each against a CAN_RAW peer (pinned
/// to one CPU, see the module documentation):
/// 1. `CAN_ISOTP_FORCE_TXSTMIN` with `CAN_ISOTP_TX_STMIN` 40 ms: the FC's
///    STmin 0 is overridden, each CF at least 40 ms after the one before.
/// 2. `CAN_ISOTP_CF_BROADCAST` (with the forced STmin): the FF and its
///    CFs go out without any flow control, 40 ms apart.
/// 3. `frame_txtime` 40 ms, then CAN_ISOTP_OPTS again with 0 (which
///    leaves it, and reads back as 0): with the FC's STmin of 20 ms the
///    CFs are at least 60 ms apart (N_As plus STmin).
/// 4. `CAN_ISOTP_FRAME_TXTIME_ZERO` after a `frame_txtime` of 4 s: N_As
///    is 0 again, the two CFs less than 4 s apart (a generous upper
///    bound; no lower one exists).
/// 5. `CAN_ISOTP_DYN_FC_PARMS`: the block size comes from every FC. A
///    wait frame with BS 1 is the sender's first FC, a CTS with BS 0
///    follows: with the flag all three CFs go out; without it (mainline:
///    parameters from the first FC only) one CF, then the sender waits
///    for an FC, and the peer's overflow FC ends it with EMSGSIZE.
/// 6. Received wait frames, with `wftmax` 1 set (mainline stores it, and
///    enforces no limit): three wait frames, then an overflow FC: the
///    sender still waited, EMSGSIZE. Then wait frames every 0.6 s keep
///    the sender past its 1-s N_Bs until a CTS, and the PDU goes out.
/// 7. `EBADMSG` of the sender: with `CAN_ISOTP_RX_PADDING`,
///    `CHK_PAD_LEN`, `CHK_PAD_DATA` and `rxpad_content` 0xAA an FC padded
///    with 0xCC, and an FC of 3 bytes; without checks an FC of 2 bytes and
///    one with the reserved flow status 3. A correctly padded FC then
///    lets the PDU out.
/// 8. `CAN_ISOTP_HALF_DUPLEX`: an SF that comes while the socket sends is
///    dropped (the next SF is read, not it); while it receives and sends
///    at once, an overflow FC and the CFs are dropped: the write ends in
///    ECOMM after N_Bs (not EMSGSIZE), no PDU is read.
/// 9. `O_NONBLOCK`: a write while a transfer waits for its FC is EAGAIN;
///    `connect` and `getpeername` are EOPNOTSUPP.
fn isotp_opts_sender(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.isotp_ifaces(1)?[0];
    let _pin = crate::sys::pin_to_cpu0_for().or_fail("pin to CPU 0")?;
    let peer = peer_open(i0)?;
    forced_tx_stmin(i0, &peer)?;
    cf_broadcast(i0, &peer)?;
    frame_txtime(i0, &peer)?;
    frame_txtime_zero(i0, &peer)?;
    dyn_fc_parms(ctx, i0, &peer)?;
    // The half-duplex socket's timeouts (1 s) run out while the wait
    // frames are paced (1.2 s).
    let hd = half_duplex(i0, &peer)?;
    wait_frames(ctx, i0, &peer)?;
    half_duplex_end(hd, &peer)?;
    sender_ebadmsg(i0, &peer)?;
    nonblocking_send(i0, &peer)
}

const STMIN_40MS: u32 = 40 * MS;

fn forced_tx_stmin(i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "FORCE_TXSTMIN 40 ms";
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_FORCE_TXSTMIN | CAN_ISOTP_WAIT_TX_DONE),
        &[(CAN_ISOTP_TX_STMIN, &STMIN_40MS.to_ne_bytes())],
        i0,
        0x708,
        0x700,
    )?);
    let pdu = pattern(27);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x700, "FF")?;
    raw_send(peer, 0x708, &[0x30, 0, 0])?;
    let cfs = peer_frames(peer, 0x700, 3, "CFs after an FC with STmin 0")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), what)?;
    gaps_at_least(
        &cfs.iter().collect::<Vec<_>>(),
        Duration::from_millis(40),
        what,
    )?;
    want_written(w, 27, what)
}

fn cf_broadcast(i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "CF_BROADCAST with FORCE_TXSTMIN 40 ms";
    // rx_id is neither used nor checked with a broadcast flag.
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_CF_BROADCAST | CAN_ISOTP_FORCE_TXSTMIN | CAN_ISOTP_WAIT_TX_DONE),
        &[(CAN_ISOTP_TX_STMIN, &STMIN_40MS.to_ne_bytes())],
        i0,
        0x800,
        0x701,
    )?);
    let pdu = pattern(20);
    let w = write_bg(&s, pdu.clone());
    // No FC from the peer: FF and both CFs come on their own.
    let fr = peer_frames(peer, 0x701, 3, "FF and CFs without flow control")?;
    let all: Vec<&Fr> = fr.iter().map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), what)?;
    gaps_at_least(
        &fr.iter().collect::<Vec<_>>(),
        Duration::from_millis(40),
        what,
    )?;
    want_written(w, 20, what)
}

fn frame_txtime(i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "frame_txtime 40 ms with STmin 20 ms";
    let s = tp_with(opts_with(CAN_ISOTP_WAIT_TX_DONE, 40 * MS, 0xCC), &[])?;
    // frame_txtime 0: N_As stays as set; the option reads back as given.
    let o = opts_with(CAN_ISOTP_WAIT_TX_DONE, 0, 0xCC);
    raw::setsockopt(&s, SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &o).or_fail("CAN_ISOTP_OPTS again")?;
    let mut back = [0u8; 12];
    let n = raw::getsockopt(&s, SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &mut back).or_fail("getsockopt")?;
    ensure!(
        n == 12 && back == o,
        "CAN_ISOTP_OPTS read back {}, want {} as set",
        hex(&back[..n as usize]),
        hex(&o)
    );
    bind_tp(&s, i0, 0x70A, 0x702)?;
    let s = Arc::new(s);
    let pdu = pattern(27);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x702, "FF")?;
    raw_send(peer, 0x70A, &[0x30, 0, 20])?;
    let cfs = peer_frames(peer, 0x702, 3, "CFs after an FC with STmin 20 ms")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), what)?;
    gaps_at_least(
        &cfs.iter().collect::<Vec<_>>(),
        Duration::from_millis(60),
        what,
    )?;
    want_written(w, 27, what)
}

fn frame_txtime_zero(i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "FRAME_TXTIME_ZERO after frame_txtime 4 s";
    let s = tp_with(opts_with(CAN_ISOTP_WAIT_TX_DONE, 4000 * MS, 0xCC), &[])?;
    let o = opts_with(CAN_ISOTP_WAIT_TX_DONE, CAN_ISOTP_FRAME_TXTIME_ZERO, 0xCC);
    raw::setsockopt(&s, SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &o).or_fail("CAN_ISOTP_OPTS ZERO")?;
    bind_tp(&s, i0, 0x70B, 0x703)?;
    let s = Arc::new(s);
    let pdu = pattern(20);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x703, "FF")?;
    raw_send(peer, 0x70B, &[0x30, 0, 0])?;
    let cfs = peer_frames(peer, 0x703, 2, "CFs after an FC with STmin 0")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), what)?;
    let gap = cfs[1].ns - cfs[0].ns;
    ensure!(
        gap < 4_000_000_000,
        "{what}: the CFs {:.3} s apart: the 4 s of the former frame_txtime are still in force",
        gap as f64 / 1e9
    );
    want_written(w, 20, what)
}

fn dyn_fc_parms(ctx: &Ctx, i0: u32, peer: &OwnedFd) -> TestResult {
    let pdu = pattern(27);
    // With the flag: BS 1 of the wait frame, then BS 0 of the CTS.
    let what = "DYN_FC_PARMS";
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_DYN_FC_PARMS | CAN_ISOTP_WAIT_TX_DONE),
        &[],
        i0,
        0x70C,
        0x704,
    )?);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x704, "FF")?;
    raw_send(peer, 0x70C, &[0x31, 1, 0])?;
    raw_send(peer, 0x70C, &[0x30, 0, 0])?;
    let cfs = peer_frames(
        peer,
        0x704,
        3,
        "CFs after a wait frame with BS 1 and a CTS with BS 0",
    )?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), what)?;
    want_written(w, 27, what)?;

    // Without: BS 1 of the first FC (the wait frame) stays.
    let what = "BS of the first FC only (no DYN_FC_PARMS)";
    let s = Arc::new(tp_on(opts(CAN_ISOTP_WAIT_TX_DONE), &[], i0, 0x70D, 0x705)?);
    let w = write_bg(&s, pdu.clone());
    peer_expect(peer, 0x705, "FF")?;
    raw_send(peer, 0x70D, &[0x31, 1, 0])?;
    raw_send(peer, 0x70D, &[0x30, 0, 0])?;
    let cf = peer_expect(peer, 0x705, "CF 1")?;
    ensure!(
        cf.f.data[0] == 0x21,
        "{what}: {} after the CTS",
        show(&cf.f)
    );
    // The sender now waits for the FC of its next block.
    raw_send(peer, 0x70D, &[0x32, 0, 0])?;
    let e = errno_of(writer_result(w, what)?, what)?;
    // ECOMM only if the overflow FC overtook CF 1's echo in the sender
    // (a peer on another CPU can be that quick): it was then ignored and
    // N_Bs ran out; still no second CF.
    ensure!(
        e == libc::EMSGSIZE || e == libc::ECOMM,
        "{what}: write {}, want EMSGSIZE (the sender waited for an FC after CF 1)",
        errno_name(e)
    );
    if e == libc::ECOMM {
        ctx.note(format!(
            "{what}: ECOMM, the overflow FC came before CF 1's echo"
        ));
    }
    let more = peer_queued(peer, 0x705)?;
    ensure!(
        more.is_empty(),
        "{what}: {:?} after CF 1 with BS 1",
        more.iter().map(show).collect::<Vec<_>>()
    );
    Ok(())
}

fn wait_frames(ctx: &Ctx, i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "three wait frames";
    // wftmax 1: stored (our FC never waits); received wait frames are
    // not counted against it (mainline).
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_WAIT_TX_DONE),
        &[(CAN_ISOTP_RECV_FC, &[0, 0, 1])],
        i0,
        0x70E,
        0x706,
    )?);
    let w = write_bg(&s, pattern(20));
    peer_expect(peer, 0x706, "FF")?;
    for _ in 0..3 {
        raw_send(peer, 0x70E, &[0x31, 0, 0])?;
    }
    raw_send(peer, 0x70E, &[0x32, 0, 0])?;
    want_write_errno(w, libc::EMSGSIZE, &format!("{what}, then an overflow FC"))?;
    let early = peer_queued(peer, 0x706)?;
    ensure!(
        early.is_empty(),
        "{what}: {:?} sent before any CTS",
        early.iter().map(show).collect::<Vec<_>>()
    );

    // Each wait frame restarts N_Bs (1 s): wait frames 0.6 s apart keep
    // the sender waiting 1.2 s in all. The sleeps pace the peer (the
    // condition is the time passed). Under host stalls a gap can pass
    // 1 s anyway: then ECOMM is inconclusive and the step runs again.
    let what = "wait frames 0.6 s apart, then a CTS";
    let pace = Duration::from_millis(600);
    for attempt in 1..=3 {
        let pdu = pattern(20);
        let start = Instant::now();
        let w = write_bg(&s, pdu.clone());
        let ff = peer_expect(peer, 0x706, "FF")?;
        // (before, after) each frame's send: a gap is measured from before
        // one send (or the write) to after the next, an upper bound of
        // the time the sender's timer saw.
        let mut sent: Vec<(Instant, Instant)> = Vec::new();
        for fc in [[0x31u8, 0, 0], [0x31, 0, 0], [0x30, 0, 0]] {
            let base = sent.last().map_or(start, |p| p.0);
            thread::sleep(pace.saturating_sub(base.elapsed()));
            let before = Instant::now();
            raw_send(peer, 0x70E, &fc)?;
            sent.push((before, Instant::now()));
        }
        let r = writer_result(w, what)?;
        if let Err(e) = &r {
            let mut gaps = vec![sent[0].1 - start];
            gaps.extend(sent.windows(2).map(|p| p[1].1 - p[0].0));
            let stalled = gaps.iter().any(|g| *g >= Duration::from_millis(950));
            if e.raw_os_error() == Some(libc::ECOMM) && stalled && attempt < 3 {
                ctx.note(format!(
                    "{what}: ECOMM with gaps {gaps:?} (host stall): again"
                ));
                continue;
            }
            return Err(format!(
                "{what}: write {e} after the frames {gaps:?} apart, want 20 \
                 (each wait frame restarts N_Bs)"
            ));
        }
        ensure!(matches!(r, Ok(20)), "{what}: write {r:?}, want 20");
        let cfs = peer_frames(peer, 0x706, 2, "CFs after the CTS")?;
        let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
        return same_frames(&all, &classic_frames(&pdu), what);
    }
    Ok(())
}

fn sender_ebadmsg(i0: u32, peer: &OwnedFd) -> TestResult {
    let checks = CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN | CAN_ISOTP_CHK_PAD_DATA;
    let s = Arc::new(tp_on(
        opts_with(CAN_ISOTP_WAIT_TX_DONE | checks, 0, 0xAA),
        &[],
        i0,
        0x718,
        0x710,
    )?);
    for (fc, what) in [
        (
            &[0x30, 0, 0, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC][..],
            "FC padded with CC, rxpad_content AA (CHK_PAD_DATA)",
        ),
        (&[0x30, 0, 0][..], "FC of 3 bytes (RX_PADDING, CHK_PAD_LEN)"),
    ] {
        let w = write_bg(&s, pattern(20));
        peer_expect(peer, 0x710, "FF")?;
        raw_send(peer, 0x718, fc)?;
        want_write_errno(w, libc::EBADMSG, what)?;
    }
    let pdu = pattern(20);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x710, "FF")?;
    raw_send(peer, 0x718, &[0x30, 0, 0, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA])?;
    let cfs = peer_frames(peer, 0x710, 2, "CFs after an FC padded with AA")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), "an FC padded as checked")?;
    want_written(w, 20, "an FC padded as checked")?;

    let s = Arc::new(tp_on(opts(CAN_ISOTP_WAIT_TX_DONE), &[], i0, 0x719, 0x711)?);
    for (fc, what) in [
        (&[0x30, 0][..], "FC of 2 bytes"),
        (&[0x33, 0, 0][..], "FC with the reserved flow status 3"),
    ] {
        let w = write_bg(&s, pattern(20));
        peer_expect(peer, 0x711, "FF")?;
        raw_send(peer, 0x719, fc)?;
        want_write_errno(w, libc::EBADMSG, what)?;
    }
    Ok(())
}

/// The half-duplex socket of [`half_duplex`] whose two transfers block
/// each other, and its writer.
struct HalfDuplex {
    s: Arc<OwnedFd>,
    w: thread::JoinHandle<std::io::Result<usize>>,
}

const HALF_DUPLEX_BOTH: &str = "HALF_DUPLEX, an overflow FC and CFs while receiving and sending";

/// Checks the first half-duplex rule, and starts the second (checked by
/// [`half_duplex_end`] once the timeouts have run out).
fn half_duplex(i0: u32, peer: &OwnedFd) -> Result<HalfDuplex, String> {
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_HALF_DUPLEX | CAN_ISOTP_WAIT_TX_DONE),
        &[],
        i0,
        0x71A,
        0x712,
    )?);
    // Sending: an SF for the socket is dropped.
    let what = "HALF_DUPLEX, an SF while sending";
    let pdu = pattern(20);
    let w = write_bg(&s, pdu.clone());
    peer_expect(peer, 0x712, "FF")?;
    raw_send(peer, 0x71A, &[0x02, 0xEE, 0xEE])?;
    raw_send(peer, 0x71A, &[0x30, 0, 0])?;
    peer_frames(peer, 0x712, 2, "CFs")?;
    want_written(w, 20, what)?;
    raw_send(peer, 0x71A, &[0x02, 0xBB, 0xBB])?;
    want_pdu(&*s, &[0xBB, 0xBB], what)?;

    // Sending and receiving at once: an FC that comes while the socket
    // receives is dropped, and so are the CFs that come while it sends:
    // neither transfer can go on, both run into their timeouts (N_Cr,
    // then N_Bs, 1 s each; mainline's rule, checked at this cost).
    let what = HALF_DUPLEX_BOTH;
    raw_send(peer, 0x71A, &[0x10, 20, 1, 2, 3, 4, 5, 6])?;
    let fc = peer_expect(peer, 0x712, "the socket's FC")?;
    ensure!(fc.f.data == [0x30, 0, 0], "{what}: FC {}", show(&fc.f));
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, 0x712, "the socket's FF")?;
    ensure!(ff.f.data[0] == 0x10, "{what}: {} for the FF", show(&ff.f));
    raw_send(peer, 0x71A, &[0x32, 0, 0])?;
    raw_send(peer, 0x71A, &[0x21, 7, 8, 9, 10, 11, 12, 13])?;
    raw_send(peer, 0x71A, &[0x22, 14, 15, 16, 17, 18, 19, 20])?;
    Ok(HalfDuplex { s, w })
}

/// The end of [`half_duplex`]: the write ends in ECOMM (N_Bs), not
/// EMSGSIZE (the overflow FC was dropped), and no PDU came (the CFs were
/// dropped); nothing else went out.
fn half_duplex_end(hd: HalfDuplex, peer: &OwnedFd) -> TestResult {
    let what = HALF_DUPLEX_BOTH;
    let HalfDuplex { s, w } = hd;
    want_write_errno(w, libc::ECOMM, what)?;
    let mut e = [0u8; 4];
    raw::getsockopt(&*s, libc::SOL_SOCKET, libc::SO_ERROR, &mut e).or_fail("SO_ERROR")?;
    let mut buf = [0u8; 64];
    want_errno(
        raw::recvfrom(&*s, &mut buf, libc::MSG_DONTWAIT, None),
        libc::EAGAIN,
        &format!("{what}: a read (the CFs were dropped, no PDU)"),
    )?;
    let more = peer_queued(peer, 0x712)?;
    ensure!(
        more.is_empty(),
        "{what}: {:?} sent after the overflow FC",
        more.iter().map(show).collect::<Vec<_>>()
    );
    Ok(())
}

fn nonblocking_send(i0: u32, peer: &OwnedFd) -> TestResult {
    let s = tp_on(opts(0), &[], i0, 0x71B, 0x713)?;
    raw::set_nonblocking(&s, true).or_fail("O_NONBLOCK")?;
    let pdu = pattern(20);
    let n = raw::write(&s, &pdu).or_fail("O_NONBLOCK write of 20 bytes")?;
    ensure!(n == 20, "O_NONBLOCK write returned {n}");
    let ff = peer_expect(peer, 0x713, "FF")?;
    want_errno(
        raw::write(&s, &[1, 2, 3]),
        libc::EAGAIN,
        "O_NONBLOCK write while a transfer waits for its FC",
    )?;
    raw_send(peer, 0x71B, &[0x30, 0, 0])?;
    let cfs = peer_frames(peer, 0x713, 2, "CFs")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(&cfs).map(|a| &a.f).collect();
    same_frames(&all, &classic_frames(&pdu), "O_NONBLOCK transfer")?;
    want_errno(
        raw::connect(&s, &tp_addr(i0, 0x71B, 0x713)),
        libc::EOPNOTSUPP,
        "connect",
    )?;
    let mut name = [0u8; 24];
    want_errno(
        raw::getpeername(&s, &mut name),
        libc::EOPNOTSUPP,
        "getpeername",
    )
}

// ---------------------------------------------------------------------
// The receiver's options.
// ---------------------------------------------------------------------

/// The receiver's options and call modes, against a CAN_RAW peer:
/// 1. Non-blocking receive on an empty socket: `MSG_DONTWAIT` and
///    `O_NONBLOCK` reads are EAGAIN, no POLLIN.
/// 2. POLLIN: a poller blocked in `poll` is woken when a PDU is complete,
///    not by its FF or first CF (the socket's BS 1 makes it answer each
///    CF with an FC, so the test knows the CF was taken); our FCs carry
///    BS 1 and flow status CTS although `wftmax` is 5 (mainline never
///    sends wait frames).
/// 3. `CAN_ISOTP_FORCE_RXSTMIN` with `CAN_ISOTP_RX_STMIN` 100 ms: a CF
///    right after the one before is dropped, the same CF again after
///    0.25 s is taken: the PDU holds the second one's bytes. (A host
///    stall can space the first two 100 ms apart: the step then runs
///    again, up to three times.)
/// 4. The padding checks and `EBADMSG` of the receiver: with
///    `CAN_ISOTP_RX_PADDING` `CHK_PAD_LEN` rejects an SF of 4 bytes and
///    takes one of 8 whatever its pad bytes; `CHK_PAD_DATA` with
///    `rxpad_content` AA rejects an SF and a last CF with a CC pad byte
///    and takes them padded with AA; without `RX_PADDING` `CHK_PAD_LEN`
///    rejects an SF padded to 8 bytes and takes one of 4, and
///    `CHK_PAD_DATA` rejects even that (mainline).
/// 5. `SO_RXQ_OVFL`: 100 SFs into a receive buffer of the minimum size
///    overflow it; the SF read after the queue was drained carries the
///    number dropped, which is what was sent and not read.
fn isotp_opts_receiver(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.isotp_ifaces(1)?[0];
    let _pin = crate::sys::pin_to_cpu0_for().or_fail("pin to CPU 0")?;
    let peer = peer_open(i0)?;
    nonblocking_receive_and_pollin(i0, &peer)?;
    forced_rx_stmin(ctx, i0, &peer)?;
    receiver_padding_checks(i0, &peer)?;
    rxq_ovfl(ctx, i0, &peer)
}

fn nonblocking_receive_and_pollin(i0: u32, peer: &OwnedFd) -> TestResult {
    let s = Arc::new(tp_on(
        opts(0),
        &[(CAN_ISOTP_RECV_FC, &[1, 0, 5])],
        i0,
        0x728,
        0x720,
    )?);
    let mut buf = [0u8; 64];
    // SO_RCVTIMEO beyond the deadline below: a read that blocked would
    // neither return EAGAIN in time nor hang the test (an SF frees it).
    raw::set_timeout(&*s, libc::SO_RCVTIMEO, 6 * T).or_fail("SO_RCVTIMEO")?;
    nonblocking_read(
        &s,
        peer,
        0x728,
        false,
        "MSG_DONTWAIT read on an empty socket",
    )?;
    raw::set_nonblocking(&*s, true).or_fail("O_NONBLOCK")?;
    nonblocking_read(&s, peer, 0x728, true, "O_NONBLOCK read on an empty socket")?;
    let rev = crate::sys::poll_one(&*s, libc::POLLIN, 0).or_fail("poll")?;
    ensure!(rev == 0, "poll on an empty socket: revents {rev:#x}");

    let tid = Arc::new(AtomicI32::new(0));
    let poller = {
        let (s, tid) = (Arc::clone(&s), Arc::clone(&tid));
        thread::spawn(move || {
            tid.store(crate::sys::gettid(), Ordering::SeqCst);
            crate::sys::poll_one(&*s, libc::POLLIN, 20_000)
        })
    };
    wait_blocked(
        &tid,
        &[libc::SYS_poll, libc::SYS_ppoll],
        "the poller blocked in poll",
    )?;
    raw_send(peer, 0x728, &[0x10, 20, 1, 2, 3, 4, 5, 6])?;
    let fc = peer_expect(peer, 0x720, "FC to the FF")?;
    ensure!(
        fc.f.data == [0x30, 1, 0],
        "FC {} with RECV_FC bs 1, wftmax 5: want 30 01 00",
        show(&fc.f)
    );
    raw_send(peer, 0x728, &[0x21, 7, 8, 9, 10, 11, 12, 13])?;
    let fc = peer_expect(peer, 0x720, "FC after CF 1 (BS 1)")?;
    ensure!(fc.f.data == [0x30, 1, 0], "FC after CF 1: {}", show(&fc.f));
    let rev = crate::sys::poll_one(&*s, libc::POLLIN, 0).or_fail("poll")?;
    ensure!(
        rev == 0 && !poller.is_finished(),
        "POLLIN (revents {rev:#x}) before the PDU is complete"
    );
    raw_send(peer, 0x728, &[0x22, 14, 15, 16, 17, 18, 19, 20])?;
    joined_poll(poller)?;
    let n = raw::read(&*s, &mut buf).or_fail("O_NONBLOCK read after POLLIN")?;
    ensure!(
        buf[..n] == (1..=20).collect::<Vec<u8>>()[..],
        "PDU after POLLIN: {}",
        hex(&buf[..n])
    );
    Ok(())
}

/// A read on the empty socket `s` with `MSG_DONTWAIT` (or, `o_nonblock`,
/// a plain read on its `O_NONBLOCK` descriptor), in a thread: EAGAIN, and
/// at once: not after an SF the peer sends to `rx` once [`T`] has passed.
fn nonblocking_read(
    s: &Arc<OwnedFd>,
    peer: &OwnedFd,
    rx: u32,
    o_nonblock: bool,
    what: &str,
) -> TestResult {
    let h = {
        let s = Arc::clone(s);
        thread::spawn(move || {
            let mut buf = [0u8; 64];
            if o_nonblock {
                raw::read(&*s, &mut buf)
            } else {
                raw::recvfrom(&*s, &mut buf, libc::MSG_DONTWAIT, None).map(|(n, _)| n)
            }
        })
    };
    if crate::check::wait_until(T, what, || h.is_finished()).is_err() {
        raw_send(peer, rx, &[0x01, 0x99])?;
        let r = joined_within(h, T, what)?;
        return Err(format!(
            "{what}: blocked until a PDU came ({r:?}), want EAGAIN at once"
        ));
    }
    want_errno(joined_within(h, T, what)?, libc::EAGAIN, what)
}

fn joined_poll(h: thread::JoinHandle<std::io::Result<libc::c_short>>) -> TestResult {
    crate::check::wait_until(T, "the poller to return", || h.is_finished())?;
    let rev = h
        .join()
        .map_err(|_| "poller panicked".to_string())?
        .or_fail("poll")?;
    ensure!(
        rev & libc::POLLIN != 0,
        "poll after the last CF: revents {rev:#x}, want POLLIN"
    );
    Ok(())
}

fn forced_rx_stmin(ctx: &Ctx, i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "FORCE_RXSTMIN 100 ms";
    let s = tp_on(
        opts(CAN_ISOTP_FORCE_RXSTMIN),
        &[(CAN_ISOTP_RX_STMIN, &(100 * MS).to_ne_bytes())],
        i0,
        0x729,
        0x721,
    )?;
    let want: Vec<u8> = (1..=13).chain([0xB1; 7]).collect();
    for attempt in 1..=3 {
        raw_send(peer, 0x729, &[0x10, 20, 1, 2, 3, 4, 5, 6])?;
        peer_expect(peer, 0x721, "FC")?;
        raw_send(peer, 0x729, &[0x21, 7, 8, 9, 10, 11, 12, 13])?;
        let cf1 = Instant::now();
        raw_send(
            peer,
            0x729,
            &[0x22, 0xA1, 0xA1, 0xA1, 0xA1, 0xA1, 0xA1, 0xA1],
        )?;
        // The same CF once RX_STMIN has passed (the sleep is that
        // condition, with room for a slow softirq).
        thread::sleep(Duration::from_millis(250).saturating_sub(cf1.elapsed()));
        raw_send(
            peer,
            0x729,
            &[0x22, 0xB1, 0xB1, 0xB1, 0xB1, 0xB1, 0xB1, 0xB1],
        )?;
        let got = read_pdu(&s)?;
        let took = cf1.elapsed();
        match got {
            Ok(p) if p == want => return Ok(()),
            // The early CF taken: spaced 100 ms under a host stall?
            Ok(p) if p.len() == 20 && p[13..] == [0xA1; 7] && attempt < 3 => ctx.note(format!(
                "{what}: the close CF was taken (host stall?): again"
            )),
            // Both dropped: the late one processed early?
            Err(libc::ETIMEDOUT) if attempt < 3 => {
                ctx.note(format!("{what}: ETIMEDOUT after {took:?}: again"))
            }
            Ok(p) => {
                return Err(format!(
                    "{what}: PDU {}, want the CF sent 0.25 s after CF 1 ({}), not the one \
                     right after it",
                    hex(&p),
                    hex(&want)
                ))
            }
            Err(e) => return Err(format!("{what}: read {}", errno_name(e))),
        }
    }
    Ok(())
}

fn receiver_padding_checks(i0: u32, peer: &OwnedFd) -> TestResult {
    type Case<'a> = (&'a [u8], Option<&'a [u8]>);
    let sf = |s: &OwnedFd, rx: u32, cases: &[Case<'_>], what: &str| -> TestResult {
        for (frame, want) in cases {
            raw_send(peer, rx, frame)?;
            let w = format!("{what}, SF {}", hex(frame));
            match want {
                Some(p) => want_pdu(s, p, &w)?,
                None => want_read_errno(s, libc::EBADMSG, &w)?,
            }
        }
        Ok(())
    };
    // RX_PADDING with CHK_PAD_LEN: 8 bytes, any pad content.
    let s = tp_on(
        opts(CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN),
        &[],
        i0,
        0x72A,
        0x722,
    )?;
    sf(
        &s,
        0x72A,
        &[
            (&[0x03, 1, 2, 3], None),
            (&[0x03, 1, 2, 3, 0x55, 0x55, 0x55, 0x55], Some(&[1, 2, 3])),
        ],
        "RX_PADDING, CHK_PAD_LEN",
    )?;
    // RX_PADDING with CHK_PAD_DATA, rxpad_content AA: SFs and a last CF.
    let what = "RX_PADDING, CHK_PAD_DATA, rxpad_content AA";
    let s = tp_on(
        opts_with(CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_DATA, 0, 0xAA),
        &[],
        i0,
        0x72B,
        0x723,
    )?;
    sf(
        &s,
        0x72B,
        &[
            (&[0x03, 1, 2, 3, 0xAA, 0xAA, 0xAA, 0xCC], None),
            (&[0x03, 4, 5, 6, 0xAA, 0xAA, 0xAA, 0xAA], Some(&[4, 5, 6])),
            (&[0x03, 7, 8, 9], Some(&[7, 8, 9])),
        ],
        what,
    )?;
    for (pad, ok) in [(0xCC, false), (0xAA, true)] {
        raw_send(peer, 0x72B, &[0x10, 17, 1, 2, 3, 4, 5, 6])?;
        peer_expect(peer, 0x723, "FC")?;
        raw_send(peer, 0x72B, &[0x21, 7, 8, 9, 10, 11, 12, 13])?;
        raw_send(peer, 0x72B, &[0x22, 14, 15, 16, 17, 0xAA, 0xAA, pad])?;
        let w = format!("{what}, last CF padded with AA AA {pad:02X}");
        if ok {
            want_pdu(&s, &(1..=17).collect::<Vec<u8>>(), &w)?;
        } else {
            want_read_errno(&s, libc::EBADMSG, &w)?;
        }
    }
    // CHK_PAD_LEN without RX_PADDING: the optimised length only.
    let s = tp_on(opts(CAN_ISOTP_CHK_PAD_LEN), &[], i0, 0x72C, 0x724)?;
    sf(
        &s,
        0x72C,
        &[
            (&[0x03, 1, 2, 3, 0, 0, 0, 0], None),
            (&[0x03, 1, 2, 3], Some(&[1, 2, 3])),
        ],
        "CHK_PAD_LEN without RX_PADDING",
    )?;
    // CHK_PAD_DATA without RX_PADDING: every frame fails (mainline: "no
    // valid test against empty value").
    let s = tp_on(opts(CAN_ISOTP_CHK_PAD_DATA), &[], i0, 0x72D, 0x725)?;
    sf(
        &s,
        0x72D,
        &[(&[0x03, 1, 2, 3], None)],
        "CHK_PAD_DATA without RX_PADDING",
    )
}

/// A PDU read and the drop count its `SO_RXQ_OVFL` control message gave.
type PduOvfl = (Vec<u8>, Option<u32>);

/// The next PDU on `s` (blocking, SO_RCVTIMEO; None when it expires) and
/// the count of its `SOL_SOCKET`/`SO_RXQ_OVFL` control message, if any.
fn recv_ovfl(s: impl AsFd) -> Result<Option<PduOvfl>, String> {
    let mut data = [0u8; 64];
    let mut name = [0u8; 24];
    let mut control = [0u64; 32];
    let r = match crate::sys::recvmsg_into(&s, &mut data, &mut name, &mut control, 0) {
        Ok(r) => r,
        Err(e) if e.raw_os_error() == Some(libc::EAGAIN) => return Ok(None),
        Err(e) => return Err(format!("recvmsg: {e}")),
    };
    let bytes: Vec<u8> = control.iter().flat_map(|w| w.to_ne_bytes()).collect();
    let mut at = 0;
    let mut ovfl = None;
    // struct cmsghdr: cmsg_len (size_t), cmsg_level, cmsg_type (int),
    // then the data; each header at an 8-byte boundary.
    while at + 16 <= r.controllen.min(bytes.len()) {
        let len = u64::from_ne_bytes(bytes[at..at + 8].try_into().unwrap_or_default()) as usize;
        let level = i32::from_ne_bytes(bytes[at + 8..at + 12].try_into().unwrap_or_default());
        let ty = i32::from_ne_bytes(bytes[at + 12..at + 16].try_into().unwrap_or_default());
        ensure!(len >= 16, "control message of {len} bytes");
        if level == libc::SOL_SOCKET && ty == SO_RXQ_OVFL && len >= 20 {
            ovfl = Some(u32::from_ne_bytes(
                bytes[at + 16..at + 20].try_into().unwrap_or_default(),
            ));
        }
        at += (len + 7) & !7;
    }
    Ok(Some((data[..r.len].to_vec(), ovfl)))
}

fn rxq_ovfl(ctx: &Ctx, i0: u32, peer: &OwnedFd) -> TestResult {
    let what = "SO_RXQ_OVFL";
    let s = tp_on(opts(0), &[], i0, 0x72E, 0x726)?;
    raw::setsockopt(&s, libc::SOL_SOCKET, SO_RXQ_OVFL, &1i32.to_ne_bytes())
        .or_fail("SO_RXQ_OVFL")?;
    // The minimum buffer (SOCK_MIN_RCVBUF) holds a few PDUs.
    raw::setsockopt(&s, libc::SOL_SOCKET, libc::SO_RCVBUF, &0i32.to_ne_bytes())
        .or_fail("SO_RCVBUF 0")?;
    const N: u8 = 100;
    for i in 0..N {
        raw_send(peer, 0x72E, &[0x02, 0x5F, i])?;
    }
    // Drain, then a marker SF (0x5E); if the queue had refilled meanwhile
    // (softirq deferred), the marker may be dropped too: drain again and
    // send another.
    let (mut read, mut markers) = (0usize, 0u8);
    let dropped = loop {
        loop {
            match raw::recvfrom(&s, &mut [0u8; 8], libc::MSG_DONTWAIT, None) {
                Ok(_) => read += 1,
                Err(e) if e.raw_os_error() == Some(libc::EAGAIN) => break,
                Err(e) => return Err(format!("{what}: drain: {e}")),
            }
        }
        ensure!(markers < 5, "{what}: five markers dropped");
        raw_send(peer, 0x72E, &[0x02, 0x5E, markers])?;
        markers += 1;
        raw::set_timeout(&s, libc::SO_RCVTIMEO, Duration::from_millis(500))
            .or_fail("SO_RCVTIMEO")?;
        // The marker, or older SFs before it; a marker dropped leaves the
        // read to time out (0.5 s, then another marker).
        let mut got = None;
        loop {
            match recv_ovfl(&s).map_err(|e| format!("{what}: {e}"))? {
                Some((p, o)) if p == [0x5E, markers - 1] => {
                    got = Some(o);
                    break;
                }
                Some(_) => read += 1,
                None => break,
            }
        }
        if let Some(o) = got {
            break o;
        }
    };
    let sent = usize::from(N) + usize::from(markers);
    let lost = sent - read - 1;
    ensure!(
        lost > 0,
        "{what}: all {sent} PDUs queued with SO_RCVBUF 0: no overflow to report"
    );
    ensure!(
        dropped == Some(lost as u32),
        "{what}: the PDU read after the overflow says {dropped:?} dropped; {sent} sent, \
         {} read: want {lost}",
        read + 1
    );
    ctx.note(format!(
        "{what}: {read} of {N} SFs read, {lost} dropped and reported"
    ));
    Ok(())
}

// ---------------------------------------------------------------------
// TX_DL on CAN FD.
// ---------------------------------------------------------------------

/// `tx_dl` 12, 16, 20, 24, 32 and 48 (`CAN_ISOTP_LL_OPTS` with MTU 72;
/// 8 and 64 are in isotp.rs) on an FD interface, each against a CAN_RAW
/// peer:
/// - a PDU of TX_DL - 2 bytes is one FD single frame of TX_DL bytes with
///   the SF_DL escape `00 LL`;
/// - a PDU of 3 TX_DL - 6 bytes: an FD FF of TX_DL bytes (`1L LL` and
///   TX_DL - 2 bytes), CF 1 of TX_DL bytes, the last CF with TX_DL - 3
///   bytes padded to TX_DL with CC (a CAN FD frame over 8 bytes has a
///   valid length; CC without TX_PADDING), every frame FD without BRS;
///   the peer's FC is an FD frame too;
/// - and received: the peer sends such a PDU with TX_DL 12 and 48 (the
///   receiver learns RX_DL from the FF); our FC is an FD frame `30 00 00`.
///
/// The interface's MTU is 16 again afterwards.
fn isotp_opts_fd_tx_dl(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.isotp_ifaces(1)?[0];
    let c0 = dev(0);
    let mtu = |m: i32| -> TestResult {
        ctx.link_down(&c0)?;
        crate::sys::set_mtu(&c0, m).or_fail(format!("{c0} mtu {m}"))?;
        ctx.link_up(&c0)
    };
    mtu(72)?;
    let r = (|| {
        let _pin = crate::sys::pin_to_cpu0_for().or_fail("pin to CPU 0")?;
        let peer = peer_open(i0)?;
        for (k, dl) in [12usize, 16, 20, 24, 32, 48].into_iter().enumerate() {
            fd_send(i0, &peer, dl, 0x740 + k as u32, 0x750 + k as u32)?;
        }
        for (k, dl) in [12usize, 48].into_iter().enumerate() {
            fd_receive(i0, &peer, dl, 0x760 + k as u32, 0x768 + k as u32)?;
        }
        Ok(())
    })();
    let restore = mtu(16);
    r.and(restore)
}

/// The frames of `pdu` (3 dl - 6 bytes) from a CAN FD sender with TX_DL
/// `dl` > 8 and no padding option, from ISO 15765-2 and isotp.rst: the FF,
/// one full CF, the last CF padded with CC to `dl`.
fn fd_frames(pdu: &[u8], dl: usize) -> Vec<Vec<u8>> {
    let n = pdu.len();
    let ff = [&[0x10 | (n >> 8) as u8, n as u8][..], &pdu[..dl - 2]].concat();
    let cf1 = [&[0x21][..], &pdu[dl - 2..2 * dl - 3]].concat();
    let mut cf2 = [&[0x22][..], &pdu[2 * dl - 3..]].concat();
    cf2.resize(dl, 0xCC);
    vec![ff, cf1, cf2]
}

fn fd_send(i0: u32, peer: &OwnedFd, dl: usize, tx: u32, rx: u32) -> TestResult {
    let what = format!("TX_DL {dl}");
    let s = Arc::new(tp_on(
        opts(CAN_ISOTP_WAIT_TX_DONE),
        &[(CAN_ISOTP_LL_OPTS, &[72, dl as u8, 0])],
        i0,
        rx,
        tx,
    )?);
    let sf = pattern(dl - 2);
    let w = write_bg(&s, sf.clone());
    let f = peer_expect(peer, tx, "SF")?.f;
    ensure!(
        f.fd && f.flags & CANFD_BRS == 0 && f.data == [&[0, (dl - 2) as u8][..], &sf].concat(),
        "{what}: {} bytes as {}, want one FD frame 00 {:02X} and the bytes",
        dl - 2,
        show(&f),
        dl - 2
    );
    want_written(w, dl - 2, &format!("{what}, SF"))?;

    let pdu = pattern(3 * dl - 6);
    let w = write_bg(&s, pdu.clone());
    let ff = peer_expect(peer, tx, "FF")?.f;
    raw_send_fd(peer, rx, &[0x30, 0, 0])?;
    let cfs = peer_frames(peer, tx, 2, "CFs")?;
    let all: Vec<&Fr> = [&ff].into_iter().chain(cfs.iter().map(|a| &a.f)).collect();
    ensure!(
        all.iter().all(|f| f.fd && f.flags & CANFD_BRS == 0),
        "{what}: a frame not FD, or with BRS: {:?}",
        all.iter().map(|f| show(f)).collect::<Vec<_>>()
    );
    same_frames(&all, &fd_frames(&pdu, dl), &what)?;
    want_written(w, pdu.len(), &what)
}

fn fd_receive(i0: u32, peer: &OwnedFd, dl: usize, rx: u32, tx: u32) -> TestResult {
    let what = format!("receiving with RX_DL {dl}");
    let s = tp_on(opts(0), &[(CAN_ISOTP_LL_OPTS, &[72, 64, 0])], i0, rx, tx)?;
    let pdu: Vec<u8> = (0..3 * dl - 6).map(|i| (i * 3 + 1) as u8).collect();
    let fr = fd_frames(&pdu, dl);
    raw_send_fd(peer, rx, &fr[0])?;
    let fc = peer_expect(peer, tx, "FC")?.f;
    ensure!(
        fc.fd && fc.data == [0x30, 0, 0],
        "{what}: FC {}, want an FD frame 30 00 00",
        show(&fc)
    );
    raw_send_fd(peer, rx, &fr[1])?;
    raw_send_fd(peer, rx, &fr[2])?;
    want_pdu(&s, &pdu, &what)
}

// ---------------------------------------------------------------------
// max_pdu_size.
// ---------------------------------------------------------------------

/// The module parameter `max_pdu_size` at 10000 (the ISO-TP module
/// loaded with it; above mainline's 8300-byte buffers, which mainline
/// uses whatever the parameter says):
/// 1. A write of 10001 bytes is EINVAL; one of 10000 bytes is taken: its
///    FF announces 10000 with the 32-bit FF_DL (`10 00 00 00 27 10`).
/// 2. An FF announcing 10001 bytes is answered with FC overflow
///    `32 00 00`, one announcing 10000 with `30 00 00`.
/// 3. Reloaded with 5000 (below 8300): the limit stays 8300 (8301 bytes
///    EINVAL, 8300 taken; an FF of 8301 overflow, of 8300 CTS), as on
///    mainline, whose buffers never shrink under 8300 bytes.
fn isotp_max_pdu_size(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.isotp_ifaces_with(1, &["max_pdu_size=10000"])?[0];
    let _pin = crate::sys::pin_to_cpu0_for().or_fail("pin to CPU 0")?;
    let peer = peer_open(i0)?;
    let s = tp_on(opts(0), &[], i0, 0x7F8, 0x7F0)?;
    want_errno(
        raw::write(&s, &vec![0u8; 10001]),
        libc::EINVAL,
        "write of 10001 bytes with max_pdu_size 10000",
    )?;
    let pdu = pattern(10000);
    let n = raw::write(&s, &pdu).or_fail("write of 10000 bytes with max_pdu_size 10000")?;
    ensure!(n == 10000, "write of 10000 bytes returned {n}");
    let ff = peer_expect(&peer, 0x7F0, "FF of 10000 bytes")?.f;
    ensure!(
        ff.data == [&[0x10, 0, 0, 0, 0x27, 0x10][..], &pdu[..2]].concat(),
        "FF of 10000 bytes: {}",
        show(&ff)
    );
    // End it: the receiver has no room.
    raw_send(&peer, 0x7F8, &[0x32, 0, 0])?;
    want_read_errno(&s, libc::EMSGSIZE, "the transfer answered FC overflow")?;

    for (len, fc) in [(10001u32, [0x32, 0, 0]), (10000, [0x30, 0, 0])] {
        let l = len.to_be_bytes();
        raw_send(&peer, 0x7F8, &[0x10, 0, l[0], l[1], l[2], l[3], 1, 2])?;
        let got = peer_expect(&peer, 0x7F0, "FC to an FF")?.f;
        ensure!(
            got.data == fc,
            "FC to an FF of {len} bytes with max_pdu_size 10000: {}, want {}",
            show(&got),
            hex(&fc)
        );
    }
    // An SF ends the running reception and is read.
    raw_send(&peer, 0x7F8, &[0x01, 0x77])?;
    want_pdu(&s, &[0x77], "an SF after the FF")?;
    drop((s, peer));

    // Below 8300 the parameter does not lower the limit: mainline's
    // buffers start at 8300 bytes and only grow.
    ctx.reload_isotp_with(&["max_pdu_size=5000"])?;
    let peer = peer_open(i0)?;
    let s = tp_on(opts(0), &[], i0, 0x7F8, 0x7F0)?;
    want_errno(
        raw::write(&s, &vec![0u8; 8301]),
        libc::EINVAL,
        "write of 8301 bytes with max_pdu_size 5000",
    )?;
    let n = raw::write(&s, &pattern(8300)).or_fail("write of 8300 bytes with max_pdu_size 5000")?;
    ensure!(n == 8300, "write of 8300 bytes returned {n}");
    let ff = peer_expect(&peer, 0x7F0, "FF of 8300 bytes")?.f;
    ensure!(
        ff.data.get(..6) == Some(&[0x10, 0, 0, 0, 0x20, 0x6C][..]),
        "FF of 8300 bytes with max_pdu_size 5000: {}",
        show(&ff)
    );
    raw_send(&peer, 0x7F8, &[0x32, 0, 0])?;
    want_read_errno(&s, libc::EMSGSIZE, "the 8300-byte transfer answered FC overflow")?;
    for (len, fc) in [(8301u32, [0x32, 0, 0]), (8300, [0x30, 0, 0])] {
        let l = len.to_be_bytes();
        raw_send(&peer, 0x7F8, &[0x10, 0, l[0], l[1], l[2], l[3], 1, 2])?;
        let got = peer_expect(&peer, 0x7F0, "FC to an FF")?.f;
        ensure!(
            got.data == fc,
            "FC to an FF of {len} bytes with max_pdu_size 5000: {}, want {}",
            show(&got),
            hex(&fc)
        );
    }
    raw_send(&peer, 0x7F8, &[0x01, 0x77])?;
    want_pdu(&s, &[0x77], "an SF after the FF")
}
