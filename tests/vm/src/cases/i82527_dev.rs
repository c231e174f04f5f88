// SPDX-License-Identifier: GPL-2.0
//! The CAN device layer on the Intel 82527 (`ip link set canX type can
//! ...`), its error frames, bus-off and restarts, on the simulated cards
//! (`rcan_i82527_sim`: the real 82527 driver on the register-level model,
//! faults injected through its `fault` module parameter): bit timing over
//! netlink with the 82527's limits and system clock, refused while up,
//! control modes the chip lacks refused, `i82527config` agreeing with
//! `ip`; bus errors seen by `candump -e` with berr-reporting on; bus-off
//! ended by `restart-ms` and by `ip link set canX type can restart`.
//!
//! Not portable: mainline has no 82527 driver for a card QEMU emulates
//! (its cc770 drives the successor chip on ISA/platform boards), and no
//! emulated card produces bus errors. The expected frames are worked out
//! in drivers/net/can/chips/tests/i82527_chip.rs, which checks the same sequences
//! against the model on the host.

use super::candev::{details_json, ip, ip_ok};
use super::candev_err::{
    check_same, details_become, details_have, err_socket, restarted_by_timer, send_one, shows,
    stats_are, until, BUSOFF, CRTL, RESTARTED,
};
use super::test_table;
use crate::canraw;
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::{Ctx, Module};
use crate::tools;

pub const TESTS: &[crate::Test] = test_table![
    i82527_sim_ip_bittiming,
    i82527_sim_bus_errors_candump,
    i82527_sim_overrun_candump,
    i82527_sim_bus_off_restarts,
];

/// data[1]: RX and TX warning (the 82527 does not say which counter).
const CRTL_WARNING: u8 = 0x04 | 0x08;

const PARAMS: &str = "/sys/module/rcan_i82527_sim/parameters";

/// Sets the simulated bus's fault (`none`, `noack`, `biterr`).
fn fault(name: &str) -> TestResult {
    let p = format!("{PARAMS}/fault");
    std::fs::write(&p, name).or_fail(format_args!("echo {name} > {p}"))
}

/// `ip link set DEV type can ARGS...`, which must succeed.
fn set_can(dev: &str, args: &[&str]) -> TestResult {
    let mut a = vec!["link", "set", dev, "type", "can"];
    a.extend_from_slice(args);
    ip_ok(&a).map(|_| ())
}

/// `ip link set DEV type can ARGS...`, which must fail with `want` in
/// its error output.
/// `ip link set DEV mtu 72` must fail with `want` in its error output.
fn mtu_fails(dev: &str, want: &str) -> TestResult {
    let out = ip(&["link", "set", dev, "mtu", "72"])?;
    ensure!(
        !out.status.success() && out.stderr.contains(want),
        "ip link set {dev} mtu 72: expected {want:?}, got {} {:?}",
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

fn set_can_fails(dev: &str, args: &[&str], want: &str) -> TestResult {
    let mut a = vec!["link", "set", dev, "type", "can"];
    a.extend_from_slice(args);
    let out = ip(&a)?;
    ensure!(
        !out.status.success() && out.stderr.contains(want),
        "ip {}: expected failure with {want:?}, got {} {:?}",
        a.join(" "),
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// Loads rcan_pf, rcan_raw and rcan_i82527_sim (two cards, down).
fn load(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::I82527Sim, &["cards=2"])?;
    ensure!(
        std::path::Path::new("/sys/class/net/can1").exists()
            && !std::path::Path::new("/sys/class/net/can2").exists(),
        "rcan_i82527_sim cards=2 did not make exactly can0 and can1"
    );
    Ok(())
}

/// Gives can0 `bitrate 500000` and `can0_args`, can1 `bitrate 500000`,
/// brings both up, and returns their ifindexes.
fn up2(ctx: &mut Ctx, can0_args: &[&str]) -> Result<(u32, u32), String> {
    let mut lines = Vec::new();
    for (dev, extra) in [("can0", can0_args), ("can1", &[][..])] {
        let mut a = vec!["link", "set", dev, "type", "can", "bitrate", "500000"];
        a.extend_from_slice(extra);
        lines.push(a);
        lines.push(vec!["link", "set", dev, "up"]);
    }
    super::candev::ip_batch_ok(&lines)?;
    Ok((ctx.ifindex("can0")?, ctx.ifindex("can1")?))
}

/// Bit timing over netlink: the preset of the card (500 kbit/s) shown
/// with the 82527's limits and its 8 MHz system clock; `bitrate 125000`
/// and a direct timing (tq/prop-seg/phase-seg1/phase-seg2/sjw) taken and
/// shown by `i82527config` as by `ip`; modes the chip lacks refused with
/// EOPNOTSUPP, changes while up with EBUSY; `mtu 72` refused with EINVAL
/// while down and EBUSY while up (mainline `can_change_mtu`); frames go
/// both ways at the new rate.
fn i82527_sim_ip_bittiming(ctx: &mut Ctx) -> TestResult {
    load(ctx)?;
    let j = details_json("can0")?;
    for w in [
        r#""bitrate":500000"#,
        r#""bittiming_const":{"name":"i82527","tseg1":{"min":3,"max":16},"tseg2":{"min":2,"max":8},"sjw":{"min":1,"max":4},"brp":{"min":1,"max":64},"brp_inc":1}"#,
        r#""clock":8000000"#,
        r#""state":"STOPPED""#,
    ] {
        ensure!(j.contains(w), "ip -j -d link show can0: {w} missing in {j}");
    }
    set_can("can0", &["bitrate", "125000"])?;
    let j = details_json("can0")?;
    ensure!(
        j.contains(r#""bitrate":125000"#),
        "ip does not show bitrate 125000: {j}"
    );
    let tool = ctx.root().join("target/release/i82527config");
    let tool = tool.to_string_lossy().into_owned();
    let out = tools::run_ok(&tool, &["can0"])?;
    ensure!(
        out.stdout.contains("(125000 bit/s"),
        "i82527config does not show the bit rate set with ip: {}",
        out.stdout
    );
    // tq 125 ns = one system clock period: (1 + 6 + 7 + 2) * 125 ns.
    set_can(
        "can0",
        &[
            "tq",
            "125",
            "prop-seg",
            "6",
            "phase-seg1",
            "7",
            "phase-seg2",
            "2",
            "sjw",
            "1",
        ],
    )?;
    let j = details_json("can0")?;
    ensure!(
        j.contains(r#""bitrate":500000"#) && j.contains(r#""sample_point":"0.875""#),
        "direct timing not shown as 500000 bit/s, sample point 0.875: {j}"
    );
    let out = tools::run_ok(&tool, &["can0"])?;
    ensure!(
        out.stdout.contains("(500000 bit/s"),
        "i82527config after a direct timing: {}",
        out.stdout
    );
    let unsupported = "Operation not supported";
    for mode in [
        "loopback",
        "listen-only",
        "one-shot",
        "presume-ack",
        "cc-len8-dlc",
        "fd",
    ] {
        set_can_fails("can0", &[mode, "on"], unsupported)?;
    }
    set_can("can0", &["triple-sampling", "on"])?;
    set_can("can0", &["triple-sampling", "off", "berr-reporting", "on"])?;
    mtu_fails("can0", "Invalid argument")?;
    let (i0, i1) = up2(ctx, &[])?;
    details_have("can0", &["state ERROR-ACTIVE", "bitrate 500000"])?;
    set_can_fails("can0", &["bitrate", "250000"], "Device or resource busy")?;
    mtu_fails("can0", "Device or resource busy")?;
    let (s0, s1) = (canraw::open(i0)?, canraw::open(i1)?);
    let a = canraw::std(0x321, &[1, 2, 3]);
    canraw::send(&s0, &a)?;
    canraw::expect(&s1, &a, "can1")?;
    let b = canraw::ext(0x1234_5678, &[4; 8]);
    canraw::send(&s1, &b)?;
    canraw::expect(&s0, &b, "can0")
}

/// Missing acknowledgement with berr-reporting on, seen by `candump -e`
/// (`candump -e can0,0:0,#FFFFFFFF`): one bus error per attempt, class
/// ACK | BUSERROR (0x200000A0), no counters (the 82527 has none); `ip -d`
/// shows `state ERROR-WARNING` once the chip's WARN bit is set. Then
/// the acknowledgement comes back and the frame reaches can1; the bus
/// errors are counted in `ip -s -d`.
fn i82527_sim_bus_errors_candump(ctx: &mut Ctx) -> TestResult {
    load(ctx)?;
    let (i0, i1) = up2(ctx, &["berr-reporting", "on"])?;
    let rx1 = canraw::open(i1)?;
    let mut dump = tools::spawn("candump", &["-e", "-n", "3", "can0,0:0,#FFFFFFFF"], None)?;
    dump.wait_listening()?;
    fault("noack")?;
    send_one(i0, &canraw::std(0x55, &[0x55]))?;
    let out = dump.finish(tools::TOOL_LIMIT)?;
    // The attempts go on: 12 ACK errors take the chip to warning, which
    // `ip -d` shows (the 82527 has no readable counters: 0/0).
    details_become("can0", "state ERROR-WARNING (berr-counter tx 0 rx 0)")?;
    fault("none")?;
    let lines: Vec<&str> = out
        .stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("can0") && l.contains("200000A0"))
        .collect();
    ensure!(
        lines.len() == 3,
        "candump -e: expected 3 bus-error frames (200000A0) on can0, got {:?}",
        out.stdout
    );
    for l in &lines {
        ensure!(
            l.contains("00 00 00 00 00 00 00 00") && l.contains("ERRORFRAME"),
            "candump -e line {l:?}: expected zero data and ERRORFRAME"
        );
    }
    let f = canraw::std(0x55, &[0x55]);
    canraw::expect(&rx1, &f, "can1 once acknowledged")?;
    let t = ip_ok(&["-s", "-d", "link", "show", "can0"])?;
    let errs = super::candev_err::can_stats("can0")?[1];
    ensure!(
        errs >= 3,
        "ip -s -d: {errs} bus errors after 3 seen by candump: {t}"
    );
    Ok(())
}

/// A receive overrun (`fault=overrun`: each frame reaches can1 twice
/// before its driver reads the first), seen by `candump -e`
/// (`candump -e can1,0:0,#FFFFFFFF`) as mainline reports it: an error
/// frame of class CRTL (0x20000004) with `CAN_ERR_CRTL_RX_OVERFLOW` in
/// byte 1, then the frame itself (the second copy); `ip -s -d` counts an
/// RX overrun. With `fault=none` the next frame comes alone.
fn i82527_sim_overrun_candump(ctx: &mut Ctx) -> TestResult {
    load(ctx)?;
    let (i0, i1) = up2(ctx, &[])?;
    let rx1 = canraw::open(i1)?;
    let mut dump = tools::spawn("candump", &["-e", "-n", "2", "can1,0:0,#FFFFFFFF"], None)?;
    dump.wait_listening()?;
    fault("overrun")?;
    send_one(i0, &canraw::std(0x66, &[6, 6]))?;
    let out = dump.finish(tools::TOOL_LIMIT)?;
    fault("none")?;
    // candump -e decodes an error frame on the next line
    // ("controller-problem{rx-overflow}").
    let lines: Vec<&str> = out
        .stdout
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("can1"))
        .collect();
    ensure!(
        out.stdout.contains("rx-overflow")
            && lines.len() == 2
            && lines[0].starts_with("can1  20000004")
            && lines[0].contains("[8]  00 01 00 00 00 00 00 00")
            && lines[0].contains("ERRORFRAME")
            && lines[1].starts_with("can1  066")
            && lines[1].contains("[2]  06 06"),
        "candump -e: expected the overflow error frame (20000004, byte 1 = 01) \
         and then 066#0606 on can1, got {:?}",
        out.stdout
    );
    canraw::expect(&rx1, &canraw::std(0x66, &[6, 6]), "can1 after the overrun")?;
    let over = ctx.stat("can1", "rx_over_errors")?;
    ensure!(over == 1, "can1: rx_over_errors {over}, expected 1");
    send_one(i0, &canraw::std(0x67, &[7]))?;
    canraw::expect(&rx1, &canraw::std(0x67, &[7]), "can1 with fault=none")?;
    let over = ctx.stat("can1", "rx_over_errors")?;
    ensure!(
        over == 1,
        "can1: rx_over_errors {over} after a frame without overrun"
    );
    Ok(())
}

/// Bit errors on every transmission (`fault=biterr`, berr-reporting
/// off): the socket sees error warning, then bus-off; `restart-ms 100`
/// restarts the controller (`CAN_ERR_RESTARTED`) and the bus works. Then
/// with `restart-ms 0`: bus-off stays (`ip -d` BUS-OFF, NO-CARRIER) until
/// `ip link set can0 type can restart`; a second `restart` is refused
/// with EBUSY, as mainline. `ip -s -d` counts it all.
fn i82527_sim_bus_off_restarts(ctx: &mut Ctx) -> TestResult {
    load(ctx)?;
    let (i0, i1) = up2(ctx, &["restart-ms", "100"])?;
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    let mut kmsg = ctx.kmsg()?;
    fault("biterr")?;
    send_one(i0, &canraw::std(0x123, &[1, 2]))?;
    check_same(
        &canraw::recv(&e)?,
        &canraw::err_frame(CRTL, &[0, CRTL_WARNING, 0, 0, 0, 0, 0, 0]),
        "error warning",
    )?;
    check_same(
        &canraw::recv(&e)?,
        &canraw::err_frame(BUSOFF, &[]),
        "bus-off",
    )?;
    fault("none")?;
    restarted_by_timer(ctx, &mut kmsg, &e, &rx1, [1, 0, 0, 1, 0, 1])?;

    // restart-ms cannot change while up (EBUSY, as mainline).
    set_can_fails("can0", &["restart-ms", "0"], "Device or resource busy")?;
    ip_ok(&["link", "set", "can0", "down"])?;
    set_can("can0", &["restart-ms", "0"])?;
    ip_ok(&["link", "set", "can0", "up"])?;
    // The down reported ENETDOWN to the bound sockets: fresh ones.
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    fault("biterr")?;
    send_one(i0, &canraw::std(0x7, &[]))?;
    let (_, before) = until(&e, BUSOFF, 10)?;
    fault("none")?;
    ensure!(
        before.len() == 1,
        "expected only the warning before bus-off: {}",
        shows(&before)
    );
    details_have("can0", &["state BUS-OFF", "NO-CARRIER"])?;
    stats_are("can0", [1, 0, 0, 2, 0, 2])?;
    ip_ok(&["link", "set", "can0", "type", "can", "restart"])?;
    check_same(
        &canraw::recv(&e)?,
        &canraw::err_frame(RESTARTED, &[]),
        "after ip ... restart",
    )?;
    details_have("can0", &["state ERROR-ACTIVE"])?;
    stats_are("can0", [2, 0, 0, 2, 0, 2])?;
    set_can_fails("can0", &["restart"], "Device or resource busy")?;
    let f = canraw::std(0x8, &[8]);
    send_one(i0, &f)?;
    canraw::expect(&rx1, &f, "can1 after the manual restart")
}
