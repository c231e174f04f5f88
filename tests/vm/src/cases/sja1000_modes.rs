// SPDX-License-Identifier: GPL-2.0
//! The SJA1000 control modes that need the chip's self reception and its
//! DLC field, as users meet them: `loopback on` (mainline `sja1000`:
//! MOD.STM and the self reception request CMR.SRR) and `cc-len8-dlc on`
//! (DLC 9..15 in `can_frame.len8_dlc`), on the
//! simulated SJA1000 cards (`rcan_sja1000_sim`: the real driver on the
//! register-level model).
//!
//! Not portable: QEMU's SJA1000 model (hw/net/can/can_sja1000.c) acts
//! on CMR.TR only, so mainline's driver in loopback mode, which asks for
//! SRR, sends nothing there; and it clamps a DLC above 8 to 8 on the way
//! to the bus, so no DLC 9..15 ever reaches a receiver.
//!
//! The DLC 9..15 frames go through CAN_RAW sockets: the test VM's
//! can-utils (Debian's 2020.11) predate the `_X` DLC suffix of
//! `cansend`/`candump -8`.

use super::candev::ip_ok;
use super::candev_err::{details_have, sim2};
use super::test_table;
use crate::canraw::{self, show_wire};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::tools::{self, TOOL_LIMIT};

pub const TESTS: &[crate::Test] = test_table![sja1000_sim_loopback_cc_len8_dlc];

/// `struct can_frame` of a standard (`id` < 0x800) or extended data frame
/// with 8 data bytes `data` and `len8_dlc` `l8`.
fn wire8(id: u32, data: [u8; 8], l8: u8) -> [u8; 16] {
    let can_id = if id > 0x7FF {
        id | libc::CAN_EFF_FLAG
    } else {
        id
    };
    let mut b = [0u8; 16];
    b[..4].copy_from_slice(&can_id.to_ne_bytes());
    b[4] = 8;
    b[7] = l8;
    b[8..].copy_from_slice(&data);
    b
}

/// Receives one frame on `s` (recvmsg: its 16 bytes and whether it is a
/// local echo, `MSG_DONTROUTE`), which must be `want`.
fn expect_wire(s: &socketcan::CanSocket, want: &[u8; 16], echo: bool, who: &str) -> TestResult {
    let r = crate::sys::recvmsg(s, 16, 0).or_fail(format_args!(
        "{who}: recvmsg waiting for {}",
        show_wire(want)
    ))?;
    let got = &r.data[..r.len.min(16)];
    let dontroute = r.flags & libc::MSG_DONTROUTE != 0;
    ensure!(
        got == want && dontroute == echo,
        "{who}: expected {} ({}), got {} (MSG_DONTROUTE {dontroute})",
        show_wire(want),
        if echo { "the echo" } else { "from the chip" },
        show_wire(got)
    );
    Ok(())
}

/// Loopback and cc-len8-dlc on one card setup (can0 `loopback on
/// cc-len8-dlc on`, can1 `cc-len8-dlc on`):
///
/// * `ip -d` shows the modes;
/// * can0 alone on the bus (can1 down): `cansend can0 123#11223344` and
///   `candump -L can0` sees the frame twice: the echo and the frame the
///   chip received itself; no acknowledgement was needed (TX error
///   counter 0, ERROR-ACTIVE); a socket sees a DLC 9 frame's echo
///   (`MSG_DONTROUTE`) first, then the chip's frame, `len8_dlc` kept;
/// * can1 up: DLC 9..15 cross the bus both ways (`len8_dlc` kept), the
///   loopback frame reaches can1 too;
/// * can1 with `cc-len8-dlc off` (release kernel only): it receives such
///   a frame as DLC 8 (`len8_dlc` 0) and sends one with `len8_dlc` as
///   DLC 8.
fn sja1000_sim_loopback_cc_len8_dlc(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(
        ctx,
        &["loopback", "on", "cc-len8-dlc", "on"],
        &["cc-len8-dlc", "on"],
    )?;
    details_have("can0", &["<LOOPBACK,CC-LEN8-DLC>"])?;
    details_have("can1", &["<CC-LEN8-DLC>"])?;

    // can0 alone: self test.
    ip_ok(&["link", "set", "can1", "down"])?;
    let mut dump = tools::spawn("candump", &["-L", "-n", "2", "can0"], None)?;
    dump.wait_listening()?;
    tools::run_ok("cansend", &["can0", "123#11223344"])?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(out.status.success(), "candump: {}", out.stderr.trim());
    let frames: Vec<&str> = out
        .stdout
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .collect();
    ensure!(
        frames == ["123#11223344"; 2],
        "candump -L can0 printed {:?}, expected the echo and the self-received frame, 123#11223344 twice",
        out.stdout
    );
    details_have("can0", &["ERROR-ACTIVE (berr-counter tx 0 rx 0)"])?;
    let d = [0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88];
    let (tx0, rx0) = (canraw::open(i0)?, canraw::open(i0)?);
    let f = wire8(0x1ABC_DEF0, d, 9);
    canraw::write_bytes(&tx0, &f).or_fail("write to can0")?;
    expect_wire(&rx0, &f, true, "can0 (loopback)")?;
    expect_wire(&rx0, &f, false, "can0 (loopback)")?;
    expect_wire(&tx0, &f, false, "can0's sender (loopback)")?;

    // can1 up: across the bus, both ways. can0's sockets see each of its
    // frames twice (echo, then from the chip), can1's see their echo.
    ip_ok(&["link", "set", "can1", "up"])?;
    {
        let (tx1, rx1) = (canraw::open(i1)?, canraw::open(i1)?);
        let from0 = |f: &[u8; 16], at1: &[u8; 16], who: &str| -> TestResult {
            canraw::write_bytes(&tx0, f).or_fail("write to can0")?;
            expect_wire(&rx0, f, true, who)?;
            expect_wire(&rx0, f, false, who)?;
            expect_wire(&rx1, at1, false, who)
        };
        let from1 = |f: &[u8; 16], at0: &[u8; 16], who: &str| -> TestResult {
            canraw::write_bytes(&tx1, f).or_fail("write to can1")?;
            expect_wire(&rx1, f, true, who)?;
            expect_wire(&rx0, at0, false, who)
        };
        for l8 in [9u8, 15] {
            let f = wire8(0x123, d, l8);
            from0(&f, &f, "can0 -> can1")?;
            let g = wire8(0x1FFF_FFFF, d, l8);
            from1(&g, &g, "can1 -> can0")?;
        }
    }

    if crate::ctx::debug_kernel() {
        // The rest is the receive-side rule with the mode off (pure
        // logic, host-tested) and three more `ip` starts: release only.
        return Ok(());
    }
    // can1 without cc-len8-dlc: DLC 8 both ways (the echo keeps what the
    // sender wrote).
    ip_ok(&["link", "set", "can1", "down"])?;
    ip_ok(&["link", "set", "can1", "type", "can", "cc-len8-dlc", "off"])?;
    ip_ok(&["link", "set", "can1", "up"])?;
    let (tx1, rx1) = (canraw::open(i1)?, canraw::open(i1)?);
    let f = wire8(0x124, d, 12);
    canraw::write_bytes(&tx0, &f).or_fail("write to can0")?;
    expect_wire(&rx0, &f, true, "can0 -> can1 (mode off)")?;
    expect_wire(&rx0, &f, false, "can0 -> can1 (mode off)")?;
    expect_wire(&rx1, &wire8(0x124, d, 0), false, "can0 -> can1 (mode off)")?;
    let g = wire8(0x125, d, 12);
    canraw::write_bytes(&tx1, &g).or_fail("write to can1")?;
    expect_wire(&rx1, &g, true, "can1 -> can0 (mode off)")?;
    expect_wire(&rx0, &wire8(0x125, d, 0), false, "can1 -> can0 (mode off)")?;
    ensure!(
        ctx.stat("can0", "rx_errors")? == 0 && ctx.stat("can1", "tx_errors")? == 0,
        "errors counted"
    );
    Ok(())
}
