// SPDX-License-Identifier: GPL-2.0
//! Remote frames whose sender left bytes in the data field (issue 20 item
//! 3): a CAN_RAW socket writes a `struct can_frame` with `CAN_RTR_FLAG`,
//! DLC 1 and a non-zero data byte. CAN_RAW passes the frame through
//! unchanged, as mainline does (portable test); a CANPROTO_CAN socket reads
//! the remote frame's data field as zeros, as canproto-can.rst says (ours
//! only).

use rcan_uapi::{raw, CAN_MASK_ANY};

use super::{portable_table, raw1, test_table};
use crate::canraw::{self, CAN_MTU, CAN_RTR_FLAG};
use crate::check::{ensure, expect_frame, Frame, OrFail, TestResult};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    stack:
    raw_remote_data_passthrough,
];

pub const OURS: &[Test] = test_table![
    stack:
    canproto_remote_data_zero,
];

/// The identifier of the test frame.
const ID: u32 = 0x123;

/// The 16 bytes of `struct can_frame` for standard remote frame [`ID`]
/// with DLC 1 and data byte 0 = 0xA5 (the other data bytes 0x5A): what a
/// careless program leaves in a remote frame's buffer.
fn remote_with_bytes() -> [u8; CAN_MTU] {
    let mut b = [0u8; CAN_MTU];
    b[..4].copy_from_slice(&(ID | CAN_RTR_FLAG).to_ne_bytes());
    b[4] = 1;
    b[8] = 0xA5;
    b[9..].fill(0x5A);
    b
}

/// Writes the remote frame on a CAN_RAW socket bound to `idx`.
fn send_remote(idx: u32) -> Result<(), String> {
    let tx = canraw::open(idx)?;
    let b = remote_with_bytes();
    let n = canraw::write_bytes(&tx, &b).or_fail("write of a remote frame with data bytes")?;
    ensure!(n == CAN_MTU, "write returned {n}, expected {CAN_MTU}");
    Ok(())
}

/// Reads one frame's bytes from a CAN_RAW socket and checks them against
/// what was written: mainline's CAN_RAW hands the `struct can_frame` over
/// as the sender wrote it, data bytes of a remote frame included.
fn expect_passthrough(rx: &socketcan::CanSocket) -> TestResult {
    let mut got = [0u8; 32];
    let n = raw::read(rx, &mut got).or_fail("read on the CAN_RAW receiver")?;
    let want = remote_with_bytes();
    ensure!(
        got[..n] == want[..],
        "CAN_RAW receiver read {}, sender wrote {}",
        canraw::show_wire(&got[..n]),
        canraw::show_wire(&want)
    );
    Ok(())
}

/// A remote frame with DLC 1 and data bytes written on CAN_RAW reaches
/// another CAN_RAW socket on the interface unchanged (mainline: raw.c
/// copies the can_frame both ways, vcan echoes the skb as it is).
fn raw_remote_data_passthrough(ctx: &mut crate::ctx::Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    send_remote(idx)?;
    expect_passthrough(&rx)
}

/// The same frame read by a CANPROTO_CAN socket: a remote frame with DLC 1
/// whose one data byte reads as zero (recvfrom returns the DLC, 1 byte,
/// and `check::recv_frame` fails on any non-zero byte of a remote frame);
/// a CAN_RAW socket beside it still reads the bytes the sender wrote.
fn canproto_remote_data_zero(ctx: &mut crate::ctx::Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let thesis = ctx.bound(0, CAN_MASK_ANY, idx)?;
    let rx = canraw::open(idx)?;
    send_remote(idx)?;
    expect_frame(&thesis, &Frame::remote_std(ID, 1), idx)?;
    expect_passthrough(&rx)
}
