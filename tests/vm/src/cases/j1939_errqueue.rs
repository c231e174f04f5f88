// SPDX-License-Identifier: GPL-2.0
//! CAN_J1939's error queue (issue 42) as senders read it: with
//! `SO_J1939_ERRQUEUE` on and `SO_TIMESTAMPING` flags, a socket is told
//! of its sends (TX SCHED, TX ACK, TX ABORT with the errno, each with the
//! send's timestamp key and `J1939_NLA_BYTES_ACKED`) and of the messages
//! it would receive (RX RTS with the size, PGN and addresses), as
//! `recvmsg(MSG_ERRQUEUE)` gives them: a `SCM_J1939_ERRQUEUE` control
//! message (`struct sock_extended_err`) and the statistics as the data.
//! For a transport session (more than 8 bytes) and for a single frame,
//! which mainline sends as a "simple" session waiting for its echo.
//! The portable tests (`j1939_`) run against mainline's can-j1939.ko in
//! the mainline stage too.
//!
//! No test sleeps to synchronise: notifications are waited for with
//! `poll(POLLERR)` and a deadline; "nothing more" is an `EAGAIN` at once
//! after what must come last.

use std::os::fd::AsFd;
use std::time::Duration;

use rcan_uapi::raw;

use crate::check::{ensure, OnDrop, OrFail, TestResult};
use crate::ctx::{dev, Ctx};
use crate::sys;

use super::isotp::want_errno;
use super::j1939::{jbound, NO_PGN, SOL_CAN_J1939, T};
use super::j1939_tp::{payload, recv_msg, send_to, wait_pollerr, want_msg, PGN};
use super::{portable_table, test_table};

pub static TESTS: &[crate::Test] = portable_table![
    ;
    stack:
    j1939_tp_errqueue_notifications,
    j1939_errqueue_single_frames,
];

/// Ours only: the loopback device's `droprate` loses frames.
pub static OURS: &[crate::Test] = test_table![
    ;
    stack:
    teardown_j1939_single_frame_lost_echo,
];

/// `SO_J1939_ERRQUEUE`, `SCM_J1939_ERRQUEUE` (`<linux/can/j1939.h>`).
const SO_J1939_ERRQUEUE: i32 = 4;
const SCM_J1939_ERRQUEUE: i32 = 4;
/// `SOF_TIMESTAMPING_*` (`<linux/net_tstamp.h>`).
const SOF_RX_SOFTWARE: u32 = 1 << 3;
const SOF_SOFTWARE: u32 = 1 << 4;
const SOF_OPT_ID: u32 = 1 << 7;
const SOF_TX_SCHED: u32 = 1 << 8;
const SOF_TX_ACK: u32 = 1 << 9;
const SOF_OPT_TSONLY: u32 = 1 << 11;
/// Needs [`SOF_OPT_TSONLY`] beside it (`sock_set_timestamping`: `EINVAL`).
const SOF_OPT_STATS: u32 = 1 << 12;
/// `SO_EE_ORIGIN_LOCAL`, `SO_EE_ORIGIN_TIMESTAMPING`, `SCM_TSTAMP_SCHED`,
/// `SCM_TSTAMP_ACK`, `J1939_EE_INFO_TX_ABORT`, `J1939_EE_INFO_RX_RTS`.
const ORIGIN_LOCAL: u8 = 1;
const ORIGIN_TIMESTAMPING: u8 = 4;
pub(super) const TSTAMP_SCHED: u32 = 1;
pub(super) const TSTAMP_ACK: u32 = 2;
const EE_INFO_TX_ABORT: u32 = 1;
const EE_INFO_RX_RTS: u32 = 2;
/// `J1939_NLA_*` statistics attributes.
pub(super) const NLA_BYTES_ACKED: u16 = 1;
const NLA_TOTAL_SIZE: u16 = 2;
const NLA_PGN: u16 = 3;
const NLA_SRC_ADDR: u16 = 6;
const NLA_DEST_ADDR: u16 = 7;

/// One error queue notification: `struct sock_extended_err`'s errno,
/// origin, info and data, and the statistics (netlink attributes, the
/// message's data) as (type, payload).
#[derive(Debug)]
pub(super) struct Note {
    errno: u32,
    origin: u8,
    pub(super) info: u32,
    pub(super) data: u32,
    stats: Vec<(u16, Vec<u8>)>,
}

impl Note {
    /// The payload of statistics attribute `ty`, as a little number.
    pub(super) fn stat(&self, ty: u16) -> Option<u64> {
        let (_, p) = self.stats.iter().find(|(t, _)| *t == ty)?;
        let mut b = [0u8; 8];
        b[..p.len().min(8)].copy_from_slice(&p[..p.len().min(8)]);
        Some(u64::from_ne_bytes(b))
    }
}

fn set_int(s: impl AsFd, level: i32, name: i32, v: u32, what: &str) -> TestResult {
    raw::setsockopt(&s, level, name, &v.to_ne_bytes()).or_fail(what)
}

/// The next notification on `s`'s error queue, waited for (POLLERR)
/// within [`T`].
pub(super) fn next_note(s: impl AsFd, what: &str) -> Result<Note, String> {
    next_note_within(s, T, what)
}

/// The next notification on `s`'s error queue, waited for (POLLERR)
/// within `limit`.
fn next_note_within(s: impl AsFd, limit: Duration, what: &str) -> Result<Note, String> {
    let r = sys::poll_one(&s, libc::POLLERR, limit.as_millis() as i32).or_fail("poll")?;
    ensure!(
        r & libc::POLLERR != 0,
        "{what}: poll gave {r:#x} within {limit:?}, want POLLERR"
    );
    let r = sys::recvmsg(&s, 72, libc::MSG_ERRQUEUE)
        .or_fail(format!("recvmsg MSG_ERRQUEUE ({what})"))?;
    let ee = r
        .cmsgs
        .iter()
        .zip(&r.cdata)
        .find(|((l, t), d)| *l == SOL_CAN_J1939 && *t == SCM_J1939_ERRQUEUE && d.len() >= 16)
        .map(|(_, d)| d)
        .ok_or(format!(
            "{what}: no SCM_J1939_ERRQUEUE of 16 bytes among {:?}",
            r.cmsgs
        ))?;
    let u = |i: usize| u32::from_ne_bytes([ee[i], ee[i + 1], ee[i + 2], ee[i + 3]]);
    let b = &r.data[..r.len.min(r.data.len())];
    let mut stats = vec![];
    let mut i = 0;
    while i + 4 <= b.len() {
        let len = usize::from(u16::from_ne_bytes([b[i], b[i + 1]]));
        let ty = u16::from_ne_bytes([b[i + 2], b[i + 3]]);
        ensure!(
            len >= 4 && i + len <= b.len(),
            "{what}: statistics attribute of {len} bytes at {i} of {}",
            b.len()
        );
        stats.push((ty, b[i + 4..i + len].to_vec()));
        i += len.div_ceil(4) * 4;
    }
    Ok(Note {
        errno: u(0),
        origin: ee[4],
        info: u(8),
        data: u(12),
        stats,
    })
}

/// Checks that `s`'s error queue is empty now (EAGAIN at once).
pub(super) fn no_note(s: impl AsFd, what: &str) -> TestResult {
    want_errno(
        sys::recvmsg(&s, 72, libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT),
        libc::EAGAIN,
        what,
    )
}

/// The error queue as `j1939cat` and other senders read it, between two
/// sockets on one interface, 0x20 sending 100 bytes (TP, one CTS) to
/// 0x30, both with SO_J1939_ERRQUEUE on:
/// 1. the sender, with SOF_TIMESTAMPING_TX_ACK | TX_SCHED | OPT_ID, is
///    told once per message, when the receiver's EOMA acknowledged it:
///    ENOMSG, origin TIMESTAMPING, `SCM_TSTAMP_ACK`, the send's key (0,
///    then 1 for the next message), statistics J1939_NLA_BYTES_ACKED 100;
///    nothing else (one CTS for all packets: no TX_SCHED, which mainline
///    gives only for a CTS after the first);
/// 2. the receiver, with SOF_TIMESTAMPING_RX_SOFTWARE, is told of the
///    RTS: ENOMSG, origin LOCAL, J1939_EE_INFO_RX_RTS, statistics
///    TOTAL_SIZE 100, PGN, SRC_ADDR 0x20, DEST_ADDR 0x30;
/// 3. turning SO_J1939_ERRQUEUE off empties the queue: a third message's
///    notification, queued, is gone (mainline's `skb_queue_purge`).
fn j1939_tp_errqueue_notifications(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let a = jbound(i0, 0x20, NO_PGN)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    set_int(
        &a,
        SOL_CAN_J1939,
        SO_J1939_ERRQUEUE,
        1,
        "SO_J1939_ERRQUEUE at 0x20",
    )?;
    set_int(
        &b,
        SOL_CAN_J1939,
        SO_J1939_ERRQUEUE,
        1,
        "SO_J1939_ERRQUEUE at 0x30",
    )?;
    set_int(
        &a,
        libc::SOL_SOCKET,
        libc::SO_TIMESTAMPING,
        SOF_TX_ACK | SOF_TX_SCHED | SOF_SOFTWARE | SOF_OPT_ID | SOF_OPT_STATS | SOF_OPT_TSONLY,
        "SO_TIMESTAMPING at 0x20",
    )?;
    set_int(
        &b,
        libc::SOL_SOCKET,
        libc::SO_TIMESTAMPING,
        SOF_RX_SOFTWARE | SOF_SOFTWARE | SOF_OPT_STATS | SOF_OPT_TSONLY,
        "SO_TIMESTAMPING at 0x30",
    )?;
    for key in 0..2u32 {
        let msg = payload(100, key + 40);
        send_to(&a, &msg, 0x30, &format!("sendto 100 bytes, key {key}"))?;
        let m = recv_msg(&b, "100 bytes at 0x30")?;
        want_msg(&m, &msg, 0x20, Some(0x30), "100 bytes at 0x30")?;
        let what = format!("the sender's notification of message {key}");
        let n = next_note(&a, &what)?;
        ensure!(
            n.errno == libc::ENOMSG as u32
                && n.origin == ORIGIN_TIMESTAMPING
                && n.info == TSTAMP_ACK
                && n.data == key
                && n.stat(NLA_BYTES_ACKED) == Some(100),
            "{what}: {n:?}, want errno ENOMSG, origin {ORIGIN_TIMESTAMPING}, info \
             SCM_TSTAMP_ACK ({TSTAMP_ACK}), data {key}, BYTES_ACKED 100"
        );
        no_note(&a, &format!("the sender's queue after message {key}'s ACK"))?;
        let what = format!("the receiver's notification of message {key}");
        let n = next_note(&b, &what)?;
        ensure!(
            n.errno == libc::ENOMSG as u32
                && n.origin == ORIGIN_LOCAL
                && n.info == EE_INFO_RX_RTS
                && n.stat(NLA_TOTAL_SIZE) == Some(100)
                && n.stat(NLA_PGN) == Some(u64::from(PGN))
                && n.stat(NLA_SRC_ADDR) == Some(0x20)
                && n.stat(NLA_DEST_ADDR) == Some(0x30),
            "{what}: {n:?}, want errno ENOMSG, origin {ORIGIN_LOCAL}, info RX_RTS \
             ({EE_INFO_RX_RTS}), TOTAL_SIZE 100, PGN {PGN:05X}, SRC_ADDR 20, DEST_ADDR 30"
        );
        no_note(
            &b,
            &format!("the receiver's queue after message {key}'s RTS"),
        )?;
    }
    let msg = payload(100, 42);
    send_to(&a, &msg, 0x30, "sendto 100 bytes, the third")?;
    let m = recv_msg(&b, "the third 100 bytes at 0x30")?;
    want_msg(&m, &msg, 0x20, Some(0x30), "the third 100 bytes at 0x30")?;
    wait_pollerr(&a, "the sender's notification of the third message")?;
    set_int(
        &a,
        SOL_CAN_J1939,
        SO_J1939_ERRQUEUE,
        0,
        "SO_J1939_ERRQUEUE 0 at 0x20",
    )?;
    no_note(&a, "the sender's queue after SO_J1939_ERRQUEUE 0")
}

/// Turns `s` into a sender that is told of everything: SO_J1939_ERRQUEUE
/// on, SO_TIMESTAMPING with TX ACK, TX SCHED, the send's key and the
/// statistics (what `j1939cat` sets).
pub(super) fn errqueue_sender(s: impl AsFd, what: &str) -> TestResult {
    set_int(&s, SOL_CAN_J1939, SO_J1939_ERRQUEUE, 1, &format!("SO_J1939_ERRQUEUE at {what}"))?;
    set_int(
        &s,
        libc::SOL_SOCKET,
        libc::SO_TIMESTAMPING,
        SOF_TX_ACK | SOF_TX_SCHED | SOF_SOFTWARE | SOF_OPT_ID | SOF_OPT_STATS | SOF_OPT_TSONLY,
        &format!("SO_TIMESTAMPING at {what}"),
    )
}

/// Checks that `n` is a timestamping notification `info` (SCHED or ACK)
/// of the send with key `key` of `size` bytes.
pub(super) fn want_tstamp(n: &Note, info: u32, key: u32, size: u64, what: &str) -> TestResult {
    ensure!(
        n.errno == libc::ENOMSG as u32
            && n.origin == ORIGIN_TIMESTAMPING
            && n.info == info
            && n.data == key
            && n.stat(NLA_BYTES_ACKED) == Some(size),
        "{what}: {n:?}, want errno ENOMSG, origin {ORIGIN_TIMESTAMPING}, info {info} \
         (1 SCM_TSTAMP_SCHED, 2 SCM_TSTAMP_ACK), data {key}, BYTES_ACKED {size}"
    );
    Ok(())
}

/// Checks that `n` is the abort of the send with key `key` of `size`
/// bytes with `errno`.
fn want_abort(n: &Note, errno: i32, key: u32, size: u64, what: &str) -> TestResult {
    ensure!(
        n.errno == errno as u32
            && n.origin == ORIGIN_LOCAL
            && n.info == EE_INFO_TX_ABORT
            && n.data == key
            && n.stat(NLA_BYTES_ACKED) == Some(size),
        "{what}: {n:?}, want errno {}, origin {ORIGIN_LOCAL}, info J1939_EE_INFO_TX_ABORT \
         ({EE_INFO_TX_ABORT}), data {key}, BYTES_ACKED {size}",
        crate::check::errno_name(errno)
    );
    Ok(())
}

/// Messages of at most 8 bytes (a single frame each) from 0x20 to 0x30,
/// the sender with SO_J1939_ERRQUEUE and SOF_TIMESTAMPING_TX_SCHED |
/// TX_ACK | OPT_ID | OPT_STATS on: for each, once the receiver has it,
/// the sender has been told TX SCHED and then TX ACK, both with the
/// send's key (0, 1, 2) and J1939_NLA_BYTES_ACKED the message's size,
/// and nothing else (mainline sends each as a "simple" session: SCHED
/// when the frame went to the device, ACK when its echo came back). A
/// transport message after them takes the next key (3): single frames
/// and sessions count on one key.
fn j1939_errqueue_single_frames(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let a = jbound(i0, 0x20, NO_PGN)?;
    let b = jbound(i0, 0x30, NO_PGN)?;
    errqueue_sender(&a, "0x20")?;
    for (key, size) in [(0u32, 1usize), (1, 5), (2, 8)] {
        let msg = payload(size, key + 7);
        send_to(&a, &msg, 0x30, &format!("sendto {size} bytes, key {key}"))?;
        let m = recv_msg(&b, &format!("{size} bytes at 0x30"))?;
        want_msg(&m, &msg, 0x20, Some(0x30), &format!("{size} bytes at 0x30"))?;
        let what = format!("the sender's first notification of message {key} ({size} bytes)");
        want_tstamp(&next_note(&a, &what)?, TSTAMP_SCHED, key, size as u64, &what)?;
        let what = format!("the sender's second notification of message {key} ({size} bytes)");
        want_tstamp(&next_note(&a, &what)?, TSTAMP_ACK, key, size as u64, &what)?;
        no_note(&a, &format!("the sender's queue after message {key}'s ACK"))?;
    }
    let msg = payload(100, 3);
    send_to(&a, &msg, 0x30, "sendto 100 bytes after the single frames")?;
    let m = recv_msg(&b, "100 bytes at 0x30")?;
    want_msg(&m, &msg, 0x20, Some(0x30), "100 bytes at 0x30")?;
    let what = "the sender's notification of the 100-byte message";
    want_tstamp(&next_note(&a, what)?, TSTAMP_ACK, 3, 100, what)?;
    no_note(&a, "the sender's queue after the 100-byte message's ACK")
}

/// Sets rcan_loop's `droprate` (percent of frames the loopback device
/// loses instead of echoing).
fn set_droprate(rate: u32) -> TestResult {
    std::fs::write("/sys/module/rcan_loop/parameters/droprate", format!("{rate}\n"))
        .or_fail("write droprate")
}

/// A single frame whose echo never comes (the loopback device loses
/// every frame: `droprate` 100), sent by a socket with SO_J1939_ERRQUEUE
/// and TX SCHED | TX ACK on: it is told TX SCHED at once, then, after the
/// 10 s mainline waits for the echo, TX ABORT with ETIME (key 0,
/// BYTES_ACKED 3), and nothing else; the kernel log names the device. A second lost frame (key 1) ends
/// with ESHUTDOWN when the interface goes down before its 10 s are out
/// (mainline's cancel of every session at NETDEV_DOWN). Ours only:
/// mainline's vcan has no way to lose a frame.
fn teardown_j1939_single_frame_lost_echo(ctx: &mut Ctx) -> TestResult {
    let i0 = ctx.j1939_ifaces(1)?[0];
    let c0 = dev(0);
    let a = jbound(i0, 0x20, NO_PGN)?;
    errqueue_sender(&a, "0x20")?;
    let _restore = OnDrop(|| {
        let _ = set_droprate(0);
        let _ = sys::set_link_up(&c0, true);
    });
    set_droprate(100)?;
    let mut kmsg = ctx.kmsg()?;
    send_to(&a, &[1, 2, 3], 0x30, "sendto 3 bytes, lost")?;
    let what = "the lost frame's first notification";
    want_tstamp(&next_note(&a, what)?, TSTAMP_SCHED, 0, 3, what)?;
    // Mainline's 10 s (J1939_SIMPLE_ECHO_TIMEOUT_MS), waited out with
    // room for a loaded emulated machine.
    let what = "the lost frame's end";
    want_abort(
        &next_note_within(&a, Duration::from_secs(60), what)?,
        libc::ETIME,
        0,
        3,
        what,
    )?;
    no_note(&a, "the sender's queue after the lost frame's abort")?;
    let log = kmsg.read_new()?;
    ensure!(
        log.iter()
            .any(|l| l.contains(&format!("{c0}: ")) && l.contains("ETIME")),
        "no kernel log line naming {c0} and ETIME: {log:?}"
    );
    send_to(&a, &[4, 5, 6], 0x30, "sendto 3 bytes, lost, then ifdown")?;
    let what = "the second lost frame's first notification";
    want_tstamp(&next_note(&a, what)?, TSTAMP_SCHED, 1, 3, what)?;
    sys::set_link_up(&c0, false).or_fail("ip link set can0 down")?;
    let what = "the second lost frame's end at ifdown";
    want_abort(&next_note(&a, what)?, libc::ESHUTDOWN, 1, 3, what)?;
    no_note(&a, "the sender's queue after the ifdown's abort")
}
