// SPDX-License-Identifier: GPL-2.0
//! Error states, error frames, bus-off and restart as users meet them, on
//! the simulated SJA1000 cards (`rcan_sja1000_sim`: the real SJA1000
//! driver on the register-level model, faults injected through its
//! `fault` module parameter): CAN_RAW sockets with `CAN_RAW_ERR_FILTER`
//! and `candump -e` see mainline-format error frames, `ip -d -s link
//! show` the state, the error counters and the CAN device statistics;
//! bus-off ends with the automatic restart (`restart-ms`) or `ip link set
//! canX type can restart`; one-shot and listen-only behave as mainline's
//! sja1000 does.
//!
//! Not portable: QEMU's cards, which mainline's drivers run on, produce no
//! bus errors. The expected frames are mainline's (`sja1000_err`), worked
//! out in drivers/net/can/chips/tests/sja1000_faults.rs, which checks the same
//! sequences against the model on the host.

use socketcan::{CanFrame, CanSocket, SocketOptions};

use super::candev::{ip, ip_ok};
use super::test_table;
use crate::canraw::{self, CAN_ERR_MASK};
use crate::check::{ensure, wait_for, OrFail, TestResult, SETTLE};
use crate::ctx::{Ctx, Module};
use crate::tools;

pub const TESTS: &[crate::Test] = test_table![
    sja1000_sim_bus_off_auto_restart,
    sja1000_sim_bus_off_manual_restart,
    sja1000_sim_bus_errors_candump,
    sja1000_sim_arblost_overrun,
    sja1000_sim_one_shot,
    sja1000_sim_listen_only_presume_ack,
];

/// Error classes (`<linux/can/error.h>`), shared by the simulated cards'
/// tests.
pub(super) const LOSTARB: u32 = 0x02;
pub(super) const CRTL: u32 = 0x04;
pub(super) const PROT: u32 = 0x08;
pub(super) const BUSOFF: u32 = 0x40;
pub(super) const BUSERROR: u32 = 0x80;
pub(super) const RESTARTED: u32 = 0x100;
pub(super) const CNT: u32 = 0x200;
/// data[1]: TX warning, TX passive, RX overflow.
pub(super) const CRTL_TX_WARNING: u8 = 0x08;
pub(super) const CRTL_TX_PASSIVE: u8 = 0x20;
pub(super) const CRTL_RX_OVERFLOW: u8 = 0x01;
/// data[2]: bit error, on transmission; data[3]: data field, ACK slot.
const PROT_BIT: u8 = 0x01;
const PROT_TX: u8 = 0x80;
const LOC_DATA: u8 = 0x0A;
const LOC_ACK: u8 = 0x19;

const PARAMS: &str = "/sys/module/rcan_sja1000_sim/parameters";

/// Sets the simulated bus's fault (`none`, `noack`, `biterr`, `arblost`,
/// `overrun`).
pub(super) fn fault(name: &str) -> TestResult {
    let p = format!("{PARAMS}/fault");
    std::fs::write(&p, name).or_fail(format_args!("echo {name} > {p}"))
}

/// Loads rcan_pf, rcan_raw and rcan_sja1000_sim (two cards), gives can0
/// `bitrate 500000` and `can0_args`, can1 `bitrate 500000` and
/// `can1_args`, brings both up, and returns their ifindexes.
pub(super) fn sim2(
    ctx: &mut Ctx,
    can0_args: &[&str],
    can1_args: &[&str],
) -> Result<(u32, u32), String> {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::Sja1000Sim, &["cards=2"])?;
    ensure!(
        std::path::Path::new("/sys/class/net/can1").exists()
            && !std::path::Path::new("/sys/class/net/can2").exists(),
        "rcan_sja1000_sim cards=2 did not make exactly can0 and can1"
    );
    let mut lines = Vec::new();
    for (dev, extra) in [("can0", can0_args), ("can1", can1_args)] {
        let mut a = vec!["link", "set", dev, "type", "can", "bitrate", "500000"];
        a.extend_from_slice(extra);
        lines.push(a);
        lines.push(vec!["link", "set", dev, "up"]);
    }
    super::candev::ip_batch_ok(&lines)?;
    Ok((ctx.ifindex("can0")?, ctx.ifindex("can1")?))
}

/// A CAN_RAW socket on `ifindex` that receives every error frame and no
/// data frame.
pub(super) fn err_socket(ifindex: u32) -> Result<CanSocket, String> {
    let s = canraw::open(ifindex)?;
    s.set_filter_drop_all().or_fail("CAN_RAW_FILTER: none")?;
    s.set_error_filter(CAN_ERR_MASK)
        .or_fail("CAN_RAW_ERR_FILTER CAN_ERR_MASK")?;
    Ok(s)
}

/// Reads error frames from `s` until one whose class has any of `class`
/// bits arrives (at most `limit` frames); returns it and those before.
pub(super) fn until(
    s: &CanSocket,
    class: u32,
    limit: usize,
) -> Result<(CanFrame, Vec<CanFrame>), String> {
    let mut before = Vec::new();
    for _ in 0..limit {
        let f = canraw::recv(s).map_err(|e| {
            format!(
                "waiting for error class {class:#x} after {}: {e}",
                shows(&before)
            )
        })?;
        let c: &libc::can_frame = f.as_ref();
        if c.can_id & class != 0 {
            return Ok((f, before));
        }
        before.push(f);
    }
    Err(format!(
        "no error class {class:#x} in {limit} frames: {}",
        shows(&before)
    ))
}

pub(super) fn shows(v: &[CanFrame]) -> String {
    v.iter().map(canraw::show).collect::<Vec<_>>().join(", ")
}

pub(super) fn check_same(got: &CanFrame, want: &CanFrame, what: &str) -> TestResult {
    ensure!(
        canraw::same(got, want),
        "{what}: expected {}, got {}",
        canraw::show(want),
        canraw::show(got)
    );
    Ok(())
}

/// `ip -s -d link show DEV` must contain every one of `want`.
pub(super) fn details_have(dev: &str, want: &[&str]) -> TestResult {
    let t = ip_ok(&["-s", "-d", "link", "show", dev])?;
    for w in want {
        ensure!(
            t.contains(w),
            "ip -s -d link show {dev}: {w:?} missing in {t}"
        );
    }
    Ok(())
}

/// `ip -d link show DEV` until it contains `want` (the chip retries
/// every 2 ms, so the state moves on its own); fails with the last output
/// after [`SETTLE`]. Not a timing assertion: the bound only ends a wait
/// for a state that never comes.
pub(super) fn details_become(dev: &str, want: &str) -> TestResult {
    let mut last = String::new();
    wait_for(SETTLE, &format!("{want:?} in ip -d link show {dev}"), || {
        last = ip_ok(&["-d", "link", "show", dev])?;
        Ok(last.contains(want).then_some(()))
    })
    .map_err(|e| format!("{e}: {last}"))
}

/// The CAN device statistics `ip -s -d link show DEV` prints: re-started,
/// bus-errors, arbit-lost, error-warn, error-pass, bus-off.
pub(super) fn can_stats(dev: &str) -> Result<[u64; 6], String> {
    let t = ip_ok(&["-s", "-d", "link", "show", dev])?;
    let line = t
        .lines()
        .skip_while(|l| !l.contains("re-started bus-errors arbit-lost"))
        .nth(1)
        .unwrap_or("");
    let v: Vec<u64> = line
        .split_whitespace()
        .take(6)
        .filter_map(|w| w.parse().ok())
        .collect();
    v.try_into()
        .map_err(|_| format!("ip -s -d link show {dev}: no CAN device statistics in {t}"))
}

/// Checks the CAN device statistics of `dev` (re-started, bus-errors,
/// arbit-lost, error-warn, error-pass, bus-off).
pub(super) fn stats_are(dev: &str, want: [u64; 6]) -> TestResult {
    let got = can_stats(dev)?;
    ensure!(
        got == want,
        "{dev}: CAN device statistics {got:?}, expected {want:?}"
    );
    Ok(())
}

/// Sends one data frame from a CAN_RAW socket on `ifindex`.
pub(super) fn send_one(ifindex: u32, f: &CanFrame) -> TestResult {
    let s = canraw::open(ifindex)?;
    canraw::send(&s, f)
}

/// Bit errors on every transmission (`fault=biterr`, berr-reporting off):
/// the socket sees error warning (TXERR 96), error passive (128) and
/// bus-off, then `restart-ms 100` restarts the controller
/// (`CAN_ERR_RESTARTED`); `ip -d -s` counts one of each and shows the
/// controller ERROR-ACTIVE again; the bus works afterwards.
fn sja1000_sim_bus_off_auto_restart(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &["restart-ms", "100"], &[])?;
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    fault("biterr")?;
    let mut kmsg = ctx.kmsg()?;
    send_one(i0, &canraw::std(0x123, &[1, 2]))?;
    let want = [
        canraw::err_frame(CRTL | CNT, &[0, CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0]),
        canraw::err_frame(CRTL | CNT, &[0, CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0]),
        canraw::err_frame(BUSOFF, &[]),
    ];
    for (i, w) in want.iter().enumerate() {
        check_same(&canraw::recv(&e)?, w, &format!("error frame {i}"))?;
    }
    fault("none")?;
    restarted_by_timer(ctx, &mut kmsg, &e, &rx1, [1, 0, 0, 1, 1, 1])
}

/// After a bus-off of can0 with `restart-ms 100` and the fault gone: the
/// error socket `e` reads `CAN_ERR_RESTARTED`, the kernel log names the
/// scheduled restart (read from `kmsg`, opened before the bus-off), `ip
/// -d` shows ERROR-ACTIVE and the CAN device statistics `stats`, the
/// frame lost with the bus-off is one TX error (mainline's
/// `can_flush_echo_skb` counts it so), and the restarted controller
/// sends: can1's `rx1` receives.
pub(super) fn restarted_by_timer(
    ctx: &Ctx,
    kmsg: &mut crate::ctx::Kmsg,
    e: &CanSocket,
    rx1: &CanSocket,
    stats: [u64; 6],
) -> TestResult {
    check_same(
        &canraw::recv(e)?,
        &canraw::err_frame(RESTARTED, &[]),
        "after restart-ms",
    )?;
    let log = kmsg.read_new()?;
    ensure!(
        log.iter()
            .any(|l| l.contains("can0: bus-off, scheduling restart in 100 ms")),
        "no 'can0: bus-off, scheduling restart in 100 ms' in the kernel log: {log:?}"
    );
    details_have("can0", &["state ERROR-ACTIVE"])?;
    stats_are("can0", stats)?;
    ensure!(
        ctx.stat("can0", "tx_errors")? == 1,
        "can0 tx_errors not 1 after the frame lost with the bus-off"
    );
    let f = canraw::std(0x124, &[3]);
    send_one(ctx.ifindex("can0")?, &f)?;
    canraw::expect(rx1, &f, "can1 after the restart")
}

/// Bus-off with `restart-ms 0`: the controller stays off (`ip -d` shows
/// BUS-OFF, the carrier is off) until `ip link set can0 type can
/// restart`, which brings `CAN_ERR_RESTARTED`; a second `restart` is
/// refused with EBUSY (not bus-off), as mainline.
fn sja1000_sim_bus_off_manual_restart(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &["berr-reporting", "on"], &[])?;
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    fault("biterr")?;
    send_one(i0, &canraw::std(0x7, &[]))?;
    let (off, before) = until(&e, BUSOFF, 40)?;
    fault("none")?;
    // 31 bus errors before, each with TXERR in data[6]; the bus-off frame
    // carries the 32nd bus error and no counters.
    ensure!(
        before.len() == 31,
        "{} error frames before bus-off, expected 31: {}",
        before.len(),
        shows(&before)
    );
    check_same(
        &before[0],
        &canraw::err_frame(
            PROT | BUSERROR | CNT,
            &[0, 0, PROT_BIT | PROT_TX, LOC_DATA, 0, 0, 8, 0],
        ),
        "first bus error",
    )?;
    check_same(
        &off,
        &canraw::err_frame(
            PROT | BUSERROR | BUSOFF,
            &[0, 0, PROT_BIT | PROT_TX, LOC_DATA, 0, 0, 0, 0],
        ),
        "bus-off frame",
    )?;
    restarted_by_hand(&e, i0, &rx1, "berr-counter tx 127 rx 0")
}

/// can0 is bus-off after 32 bit errors (`ip -d` shows `state BUS-OFF`,
/// `busoff_counters` and NO-CARRIER; `ip -s -d` one bus-off and 32 bus
/// errors) and `restart-ms` is 0: `ip link set can0 type can restart`
/// brings `CAN_ERR_RESTARTED` on `e` and error active with counters 0;
/// a second `restart` is refused with EBUSY, as mainline; a frame then
/// reaches can1 (`rx1`). Shared by the simulated cards' manual-restart
/// tests.
pub(super) fn restarted_by_hand(
    e: &CanSocket,
    i0: u32,
    rx1: &CanSocket,
    busoff_counters: &str,
) -> TestResult {
    details_have("can0", &["state BUS-OFF", busoff_counters, "NO-CARRIER"])?;
    stats_are("can0", [0, 32, 0, 1, 1, 1])?;
    ip_ok(&["link", "set", "can0", "type", "can", "restart"])?;
    check_same(
        &canraw::recv(e)?,
        &canraw::err_frame(RESTARTED, &[]),
        "after ip ... restart",
    )?;
    details_have("can0", &["state ERROR-ACTIVE", "berr-counter tx 0 rx 0"])?;
    stats_are("can0", [1, 32, 0, 1, 1, 1])?;
    let out = ip(&["link", "set", "can0", "type", "can", "restart"])?;
    ensure!(
        !out.status.success() && out.stderr.contains("Device or resource busy"),
        "restart while error active: expected EBUSY, got {} {:?}",
        out.status,
        out.stderr.trim()
    );
    let f = canraw::std(0x8, &[8]);
    send_one(i0, &f)?;
    canraw::expect(rx1, &f, "can1 after the manual restart")
}

/// Missing acknowledgement with berr-reporting on, seen by `candump -e`
/// (the can-utils way: `candump -e can0,0:0,#FFFFFFFF`): one bus error
/// per attempt, ACK slot, on transmission, TXERR rising by 8; the
/// counter stops at error passive (ACK errors of an error-passive
/// transmitter do not count), which `ip -d` shows as `state
/// ERROR-PASSIVE (berr-counter tx 128 rx 0)`. Then the acknowledgement
/// comes back and the frame reaches can1.
fn sja1000_sim_bus_errors_candump(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &["berr-reporting", "on", "restart-ms", "100"], &[])?;
    let rx1 = canraw::open(i1)?;
    let mut dump = tools::spawn("candump", &["-e", "-n", "3", "can0,0:0,#FFFFFFFF"], None)?;
    dump.wait_listening()?;
    fault("noack")?;
    send_one(i0, &canraw::std(0x55, &[0x55]))?;
    let out = dump.finish(tools::TOOL_LIMIT)?;
    details_become("can0", "state ERROR-PASSIVE (berr-counter tx 128 rx 0)")?;
    fault("none")?;
    // candump -e prints each error frame with "ERRORFRAME" (and, in
    // Debian's can-utils, the frame again on a line of its own).
    let lines: Vec<&str> = out
        .stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("can0") && l.contains("20000288"))
        .collect();
    ensure!(
        lines.len() == 3,
        "candump -e: expected 3 bus-error frames (20000288) on can0, got {:?}",
        out.stdout
    );
    for (l, txerr) in lines.iter().zip([8, 16, 24]) {
        let data = format!("00 00 {PROT_TX:02X} {LOC_ACK:02X} 00 00 {txerr:02X} 00");
        ensure!(
            l.contains(&data) && l.contains("ERRORFRAME"),
            "candump -e line {l:?}: expected data {data} and ERRORFRAME"
        );
    }
    let f = canraw::std(0x55, &[0x55]);
    canraw::expect(&rx1, &f, "can1 once acknowledged")
}

/// Lost arbitration (`fault=arblost`, at bit 5): `CAN_ERR_LOSTARB` with
/// the bit in data[0], counted as arbit-lost, and the frame goes out on
/// the retry. Data overrun (`fault=overrun`): the frames that fit, then
/// `CAN_ERR_CRTL_RX_OVERFLOW`, counted as an rx overrun.
fn sja1000_sim_arblost_overrun(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &[], &[])?;
    let e0 = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    fault("arblost")?;
    let f = canraw::std(0x300, &[5]);
    send_one(i0, &f)?;
    check_same(
        &canraw::recv(&e0)?,
        &canraw::err_frame(LOSTARB | CNT, &[5]),
        "lost arbitration",
    )?;
    canraw::expect(&rx1, &f, "can1 after the retry")?;
    stats_are("can0", [0, 0, 1, 0, 0, 0])?;
    fault("overrun")?;
    let rx0 = canraw::open(i0)?;
    // A standard frame without data takes 3 of the FIFO's 64 bytes: 21 fit.
    let g = canraw::std(0x42, &[]);
    send_one(i1, &g)?;
    // The bus reads the fault when it moves the frame: keep it until the
    // overrun is reported.
    check_same(
        &canraw::recv(&e0)?,
        &canraw::err_frame(CRTL | CNT, &[0, CRTL_RX_OVERFLOW]),
        "overrun",
    )?;
    fault("none")?;
    for i in 0..21 {
        canraw::expect(&rx0, &g, &format!("can0 copy {i}"))?;
    }
    canraw::expect_quiet(&[("can0", &rx0)])?;
    ensure!(
        ctx.stat("can0", "rx_over_errors")? == 1,
        "can0 rx_over_errors not 1"
    );
    Ok(())
}

/// `one-shot on`: a transmission nobody acknowledges is tried once and
/// dropped, counted as a TX error (mainline sja1000); the sender's echo
/// never comes; the next frame goes out.
fn sja1000_sim_one_shot(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &["one-shot", "on"], &[])?;
    let rx1 = canraw::open(i1)?;
    let tx = canraw::open(i0)?;
    tx.set_recv_own_msgs(true)
        .or_fail("CAN_RAW_RECV_OWN_MSGS")?;
    fault("noack")?;
    canraw::send(&tx, &canraw::std(0x10, &[1]))?;
    // The failed attempt frees the TX buffer: the next frame is sent
    // after it, and the first one's echo never comes.
    wait_for(SETTLE, "a tx error after the failed one-shot frame", || {
        Ok((ctx.stat("can0", "tx_errors")? != 0).then_some(()))
    })?;
    fault("none")?;
    let f = canraw::std(0x11, &[2]);
    canraw::send(&tx, &f)?;
    canraw::expect(&tx, &f, "can0's own second frame (echo)")?;
    canraw::expect(&rx1, &f, "can1")?;
    details_have("can0", &["<ONE-SHOT>"])?;
    ensure!(ctx.stat("can0", "tx_errors")? == 1, "tx_errors not 1");
    Ok(())
}

/// `listen-only on` can0 sends nothing (its frames are dropped, as
/// mainline's `can_dev_dropped_skb`) and acknowledges nothing; can1 with
/// `presume-ack on` needs no acknowledgement, so can0 still receives.
fn sja1000_sim_listen_only_presume_ack(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx, &["listen-only", "on"], &["presume-ack", "on"])?;
    let rx0 = canraw::open(i0)?;
    let rx1 = canraw::open(i1)?;
    send_one(i0, &canraw::std(0x1, &[1]))?;
    let f = canraw::std(0x2, &[2]);
    send_one(i1, &f)?;
    canraw::expect(&rx0, &f, "listen-only can0")?;
    // can1's sockets see its own frame (the echo), and nothing from can0.
    canraw::expect(&rx1, &f, "can1's echo")?;
    canraw::expect_quiet(&[("can1", &rx1)])?;
    ensure!(
        ctx.stat("can0", "tx_dropped")? == 1,
        "listen-only can0: tx_dropped not 1"
    );
    details_have("can0", &["<LISTEN-ONLY>"])?;
    details_have("can1", &["<PRESUME-ACK>"])
}
