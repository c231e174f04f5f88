// SPDX-License-Identifier: GPL-2.0
//! Local echo of CAN_RAW: who sees a frame for each combination of the
//! sender's CAN_RAW_LOOPBACK and CAN_RAW_RECV_OWN_MSGS, and the recvmsg
//! flags MSG_DONTROUTE (sent from this host) and MSG_CONFIRM (sent by this
//! very socket) on every copy.
//!
//! A third socket sends a marker after the frame under test; every socket
//! sees the marker, so a socket's next frame being the marker proves that
//! the frame under test did not reach it.

use socketcan::SocketOptions;

use super::{portable_table, raw1};
use crate::canraw::{self, expect_msg, expect_quiet, std};
use crate::check::{OrFail, TestResult};
use crate::ctx::Ctx;
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_loopback_on_own_off,
    raw_loopback_on_own_on,
    raw_loopback_off_own_off,
    raw_loopback_off_own_on,
    raw_loopback_is_per_sender,
    raw_loopback_own_filtered,
];

/// The sender has `loopback` and `own` set; another socket on can0 has the
/// defaults. The other socket sees the frame iff loopback is on, the sender
/// iff both are on, and only the sender's copy has MSG_CONFIRM.
fn loopback_case(ctx: &mut Ctx, loopback: bool, own: bool) -> TestResult {
    let idx = raw1(ctx)?;
    let sender = canraw::open(idx)?;
    let other = canraw::open(idx)?;
    let marker_tx = canraw::open(idx)?;
    sender
        .set_loopback(loopback)
        .or_fail("set CAN_RAW_LOOPBACK")?;
    sender
        .set_recv_own_msgs(own)
        .or_fail("set CAN_RAW_RECV_OWN_MSGS")?;
    let f = std(0x101, &[1, 2, 3]);
    let marker = std(0x7FE, &[0xEE]);
    canraw::send(&sender, &f)?;
    canraw::send(&marker_tx, &marker)?;
    let tag = format!("loopback {loopback}, recv_own_msgs {own}");
    if loopback {
        expect_msg(&other, &f, true, false, &format!("{tag}: other socket"))?;
    }
    expect_msg(
        &other,
        &marker,
        true,
        false,
        &format!("{tag}: other socket"),
    )?;
    if loopback && own {
        expect_msg(&sender, &f, true, true, &format!("{tag}: sender"))?;
    }
    expect_msg(&sender, &marker, true, false, &format!("{tag}: sender"))?;
    expect_quiet(&[("sender", &sender), ("other socket", &other)])
}

/// Default: others see the frame, the sender does not.
fn raw_loopback_on_own_off(ctx: &mut Ctx) -> TestResult {
    loopback_case(ctx, true, false)
}

/// RECV_OWN_MSGS: the sender sees its frame too, with MSG_CONFIRM.
fn raw_loopback_on_own_on(ctx: &mut Ctx) -> TestResult {
    loopback_case(ctx, true, true)
}

/// No loopback: no local socket sees the frame.
fn raw_loopback_off_own_off(ctx: &mut Ctx) -> TestResult {
    loopback_case(ctx, false, false)
}

/// RECV_OWN_MSGS without loopback: still nobody, the sender neither.
fn raw_loopback_off_own_on(ctx: &mut Ctx) -> TestResult {
    loopback_case(ctx, false, true)
}

/// The options act on what a socket sends, not on what it receives: a
/// socket with loopback off and RECV_OWN_MSGS on receives another socket's
/// frame normally (no MSG_CONFIRM), and its own frames reach nobody.
fn raw_loopback_is_per_sender(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let plain = canraw::open(idx)?;
    let odd = canraw::open(idx)?;
    let marker_tx = canraw::open(idx)?;
    odd.set_loopback(false).or_fail("set CAN_RAW_LOOPBACK 0")?;
    odd.set_recv_own_msgs(true)
        .or_fail("set CAN_RAW_RECV_OWN_MSGS 1")?;
    let from_plain = std(0x201, &[1]);
    let from_odd = std(0x202, &[2]);
    let marker = std(0x7FE, &[0xEE]);
    canraw::send(&plain, &from_plain)?;
    canraw::send(&odd, &from_odd)?;
    canraw::send(&marker_tx, &marker)?;
    expect_msg(&odd, &from_plain, true, false, "loopback-off socket")?;
    expect_msg(&odd, &marker, true, false, "loopback-off socket")?;
    expect_msg(&plain, &marker, true, false, "default socket")?;
    expect_quiet(&[("default socket", &plain), ("loopback-off socket", &odd)])
}

/// With RECV_OWN_MSGS, the sender's own frames pass its filters like any
/// other: only those that match come back.
fn raw_loopback_own_filtered(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let s = canraw::open(idx)?;
    s.set_recv_own_msgs(true)
        .or_fail("set CAN_RAW_RECV_OWN_MSGS 1")?;
    s.set_filters(&[(0x100, 0x7FF)]).or_fail("set filter")?;
    let other = std(0x200, &[1]);
    let mine = std(0x100, &[2]);
    canraw::send(&s, &other)?;
    canraw::send(&s, &mine)?;
    expect_msg(&s, &mine, true, true, "sender with a filter")?;
    expect_quiet(&[("sender with a filter", &s)])
}
