// SPDX-License-Identifier: GPL-2.0
//! Thesis API and CAN_RAW on the same interface (our stack only): a
//! CANPROTO_CAN socket and a CAN_RAW socket each see the other's frames with
//! the same identifier, flags and data, and CAN_RAW_LOOPBACK off hides a
//! CAN_RAW frame from thesis sockets too.

use rcan_uapi::CAN_MASK_ANY;
use socketcan::{CanFrame, SocketOptions};

use super::{raw1, test_table};
use crate::canraw::{self, expect_msg, ext, rtr_ext, rtr_std, std};
use crate::check::{expect_frame, expect_none, Frame, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::Test;

pub const TESTS: &[Test] = test_table![
    stack:
    mixed_thesis_to_raw,
    mixed_raw_to_thesis,
    mixed_raw_loopback_off,
];

/// The same frames in both APIs: standard, extended, remote (standard and
/// extended), empty and full.
fn pairs() -> Vec<(Frame, CanFrame)> {
    vec![
        (Frame::std(0x123, &[1, 2, 3]), std(0x123, &[1, 2, 3])),
        (Frame::std(0x7FF, &[]), std(0x7FF, &[])),
        (
            Frame::ext(0x1234_5678, &[1, 2, 3, 4, 5, 6, 7, 8]),
            ext(0x1234_5678, &[1, 2, 3, 4, 5, 6, 7, 8]),
        ),
        (Frame::ext(0x7FF, &[9]), ext(0x7FF, &[9])),
        (Frame::remote_std(0x456, 3), rtr_std(0x456, 3)),
        (Frame::remote_ext(0x1ABC_DEF0, 8), rtr_ext(0x1ABC_DEF0, 8)),
        (Frame::remote_std(0, 0), rtr_std(0, 0)),
    ]
}

/// Frames a thesis socket sends reach a CAN_RAW socket unchanged: same
/// can_id flags and len, the data bytes, zeros past len and in remote
/// frames (the thesis socket passes 0x5A filler there), and
/// MSG_DONTROUTE (sent from this host) without MSG_CONFIRM.
fn mixed_thesis_to_raw(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let thesis = ctx.socket()?;
    let rx = canraw::open(idx)?;
    for (t, r) in pairs() {
        t.send(&thesis, idx)?;
        expect_msg(
            &rx,
            &r,
            true,
            false,
            &format!("CAN_RAW socket, thesis frame {t}"),
        )?;
    }
    canraw::expect_quiet(&[("CAN_RAW socket", &rx)])
}

/// Frames a CAN_RAW socket sends reach a thesis socket with the same
/// arbitration field and data.
fn mixed_raw_to_thesis(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let thesis = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let tx = canraw::open(idx)?;
    for (t, r) in pairs() {
        canraw::send(&tx, &r)?;
        expect_frame(&thesis, &t, idx)
            .map_err(|e| format!("thesis socket, CAN_RAW frame {}: {e}", canraw::show(&r)))?;
    }
    expect_none(&[&thesis])
}

/// A CAN_RAW frame sent with CAN_RAW_LOOPBACK off reaches no local socket,
/// thesis sockets included; the next looped frame does.
fn mixed_raw_loopback_off(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let thesis = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let quiet = canraw::open(idx)?;
    let tx = canraw::open(idx)?;
    quiet
        .set_loopback(false)
        .or_fail("set CAN_RAW_LOOPBACK 0")?;
    canraw::send(&quiet, &std(0x111, &[1]))?;
    let marker = std(0x222, &[2]);
    canraw::send(&tx, &marker)?;
    expect_frame(&thesis, &Frame::std(0x222, &[2]), idx)
        .map_err(|e| format!("thesis socket: {e}"))?;
    expect_none(&[&thesis])
}
