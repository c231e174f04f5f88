// SPDX-License-Identifier: GPL-2.0
//! Error states, error frames, bus-off and restart of the CTU CAN FD
//! driver as users meet them, on the simulated CTU CAN FD cores
//! (`rcan_ctucanfd_sim`: the real `ctucanfd.rs` driver on the
//! register-level model with fault confinement, faults injected through
//! its `fault` module parameter): CAN_RAW sockets with
//! `CAN_RAW_ERR_FILTER` and `candump -e any,0:0,#FFFFFFFF` see the error
//! frames mainline's `ctucan_err_interrupt` makes, `ip -d -s link show`
//! the state, `berr-counter` and the CAN device statistics; bus-off ends
//! with the automatic restart (`restart-ms`) or `ip link set canX type can
//! restart`; arbitration lost and data overrun.
//!
//! Not portable: QEMU's ctucan_pci, which mainline's driver runs on, has
//! no fault confinement. The expected sequences (warning after 12 failed
//! attempts, passive after 16, bus-off after 32; mainline's error frames
//! with unspecified bus error type and location) are worked out in
//! drivers/net/can/chips/tests/ctucanfd_faults.rs against the model on
//! the host. One module load per test; the loads are small (one frame,
//! at most 32 failed attempts 2 ms apart, 64 copies for the overrun), so
//! the debug kernel runs them as they are.

use super::candev_err::{
    check_same, details_have, err_socket, restarted_by_hand, send_one, shows, stats_are, until,
    BUSERROR, BUSOFF, CNT, CRTL, CRTL_RX_OVERFLOW, CRTL_TX_PASSIVE, CRTL_TX_WARNING, LOSTARB, PROT,
    RESTARTED,
};
use super::test_table;
use crate::canraw;
use crate::check::{ensure, TestResult};
use crate::ctx::{Ctx, Module};
use crate::tools;

pub const TESTS: &[crate::Test] = test_table![
    ctucanfd_sim_bus_off_auto_restart,
    ctucanfd_sim_bus_off_manual_restart,
    ctucanfd_sim_candump_arblost_overrun,
];

const PARAMS: &str = "/sys/module/rcan_ctucanfd_sim/parameters";

/// Words of a simulated core's RX buffer (`RX_WORDS` in sim.rs): a
/// standard frame without data takes 4 of them.
const SIM_RX_WORDS: usize = 256;

/// Sets the simulated bus's fault (`none`, `noack`, `biterr`, `arblost`,
/// `overrun`).
fn fault(name: &str) -> TestResult {
    let p = format!("{PARAMS}/fault");
    std::fs::write(&p, name).map_err(|e| format!("echo {name} > {p}: {e}"))
}

/// Loads rcan_pf, rcan_raw and rcan_ctucanfd_sim (two cores), gives can0
/// `bitrate 500000` and `can0_args`, can1 `bitrate 500000`, brings both
/// up, and returns their ifindexes.
fn ctu2(ctx: &mut Ctx, can0_args: &[&str]) -> Result<(u32, u32), String> {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::CtuCanFdSim, &["cards=2"])?;
    ensure!(
        std::path::Path::new("/sys/class/net/can1").exists()
            && !std::path::Path::new("/sys/class/net/can2").exists(),
        "rcan_ctucanfd_sim cards=2 did not make exactly can0 and can1"
    );
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

/// Bit errors on every transmission (`fault=biterr`, berr-reporting off,
/// so only the state changes interrupt): the socket sees error warning
/// (TEC 96), error passive (128) and bus-off, and the kernel log the
/// state changes as mainline words them; `restart-ms 100` restarts the
/// core (`CAN_ERR_RESTARTED`, the log names the scheduled restart); the
/// frame the core gave up on at bus-off is dropped (`tx_dropped`, as
/// mainline's TX failed buffer); `ip -d -s` counts one restart, warning,
/// passive and bus-off and shows ERROR-ACTIVE with the counters at 0;
/// the bus works afterwards.
fn ctucanfd_sim_bus_off_auto_restart(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctu2(ctx, &["restart-ms", "100"])?;
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    let mut kmsg = ctx.kmsg()?;
    fault("biterr")?;
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
    check_same(
        &canraw::recv(&e)?,
        &canraw::err_frame(RESTARTED, &[]),
        "after restart-ms",
    )?;
    let log = kmsg.read_new()?;
    for want in [
        "can0: state changes from CAN_STATE_ERROR_ACTIVE to CAN_STATE_ERROR_WARNING",
        "can0: state changes from CAN_STATE_ERROR_WARNING to CAN_STATE_ERROR_PASSIVE",
        "can0: state changes from CAN_STATE_ERROR_PASSIVE to CAN_STATE_BUS_OFF",
        "can0: bus-off, scheduling restart in 100 ms",
    ] {
        ensure!(
            log.iter().any(|l| l.contains(want)),
            "no {want:?} in the kernel log: {log:?}"
        );
    }
    details_have(
        "can0",
        &[
            "state ERROR-ACTIVE",
            "berr-counter tx 0 rx 0",
            "restart-ms 100",
        ],
    )?;
    stats_are("can0", [1, 0, 0, 1, 1, 1])?;
    ensure!(
        ctx.stat("can0", "tx_dropped")? == 1,
        "can0 tx_dropped not 1 after the frame given up at bus-off"
    );
    let f = canraw::std(0x124, &[3]);
    send_one(i0, &f)?;
    canraw::expect(&rx1, &f, "can1 after the restart")
}

/// Bus-off with berr-reporting on and `restart-ms 0`: one error frame per
/// failed attempt, 31 before the bus-off (bus error, type and location
/// unspecified as in mainline; the 12th and 16th with the warning and
/// passive state and the counters), the 32nd with the bus-off; the core
/// stays off (`ip -d` shows BUS-OFF, `berr-counter tx 256`, no carrier)
/// until `ip link set can0 type can restart`, which brings
/// `CAN_ERR_RESTARTED` and the counters back to 0; a second `restart` is
/// refused with EBUSY (not bus-off), as mainline.
fn ctucanfd_sim_bus_off_manual_restart(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctu2(ctx, &["berr-reporting", "on"])?;
    let e = err_socket(i0)?;
    let rx1 = canraw::open(i1)?;
    fault("biterr")?;
    send_one(i0, &canraw::std(0x7, &[]))?;
    let (off, before) = until(&e, BUSOFF, 40)?;
    fault("none")?;
    ensure!(
        before.len() == 31,
        "{} error frames before bus-off, expected 31: {}",
        before.len(),
        shows(&before)
    );
    let berr = canraw::err_frame(PROT | BUSERROR, &[]);
    for (i, f) in before.iter().enumerate() {
        let want = match i + 1 {
            12 => canraw::err_frame(
                PROT | BUSERROR | CRTL | CNT,
                &[0, CRTL_TX_WARNING, 0, 0, 0, 0, 96, 0],
            ),
            16 => canraw::err_frame(
                PROT | BUSERROR | CRTL | CNT,
                &[0, CRTL_TX_PASSIVE, 0, 0, 0, 0, 128, 0],
            ),
            _ => berr,
        };
        check_same(f, &want, &format!("error frame of attempt {}", i + 1))?;
    }
    check_same(
        &off,
        &canraw::err_frame(PROT | BUSERROR | BUSOFF, &[]),
        "bus-off frame",
    )?;
    restarted_by_hand(&e, i0, &rx1, "berr-counter tx 256 rx 0")
}

/// `candump -e any,0:0,#FFFFFFFF` (every error class, no data frame) with
/// berr-reporting on while nobody acknowledges (`fault=noack`): bus
/// errors on can0 (`20000088`, type and location unspecified); once the
/// acknowledgement is back the frame reaches can1. Then lost arbitration
/// (`fault=arblost`): `CAN_ERR_LOSTARB` (bit unspecified, as mainline),
/// counted as arbit-lost, and the frame goes out on the retry. Then data
/// overrun (`fault=overrun`, a frame repeated past can0's RX buffer): the
/// frames that fit, `CAN_ERR_CRTL_RX_OVERFLOW`, one rx overrun.
fn ctucanfd_sim_candump_arblost_overrun(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctu2(ctx, &["berr-reporting", "on"])?;
    let rx1 = canraw::open(i1)?;
    let mut dump = tools::spawn("candump", &["-e", "-n", "3", "any,0:0,#FFFFFFFF"], None)?;
    dump.wait_listening()?;
    fault("noack")?;
    let f = canraw::std(0x55, &[0x55]);
    send_one(i0, &f)?;
    let out = dump.finish(tools::TOOL_LIMIT)?;
    fault("none")?;
    let lines: Vec<&str> = out
        .stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("can0") && l.contains("20000088"))
        .collect();
    ensure!(
        lines.len() == 3,
        "candump -e: expected 3 bus-error frames (20000088) on can0, got {:?}",
        out.stdout
    );
    for l in &lines {
        ensure!(
            l.contains("00 00 00 00 00 00 00 00") && l.contains("ERRORFRAME"),
            "candump -e line {l:?}: expected data 00 .. 00 and ERRORFRAME"
        );
    }
    canraw::expect(&rx1, &f, "can1 once acknowledged")?;

    // The bus is quiet now: a fresh error socket sees only what follows.
    let e0 = err_socket(i0)?;
    let before = super::candev_err::can_stats("can0")?;
    fault("arblost")?;
    let g = canraw::std(0x300, &[5]);
    send_one(i0, &g)?;
    // A state change back to error active may come first (the noack
    // attempts before `fault none` took effect are not counted here).
    let (lost, _) = until(&e0, LOSTARB, 3)?;
    check_same(&lost, &canraw::err_frame(LOSTARB, &[]), "lost arbitration")?;
    canraw::expect(&rx1, &g, "can1 after the retry")?;
    fault("none")?;
    let after = super::candev_err::can_stats("can0")?;
    ensure!(
        after[2] == before[2] + 1 && after[0] == before[0] && after[5] == before[5],
        "can0 CAN device statistics {before:?} -> {after:?}: expected one more arbit-lost, \
         nothing else but bus errors and states"
    );

    fault("overrun")?;
    let rx0 = canraw::open(i0)?;
    let h = canraw::std(0x42, &[]);
    send_one(i1, &h)?;
    check_same(
        &canraw::recv(&e0)?,
        &canraw::err_frame(CRTL, &[0, CRTL_RX_OVERFLOW]),
        "overrun",
    )?;
    fault("none")?;
    let fit = SIM_RX_WORDS / 4;
    for i in 0..fit {
        canraw::expect(&rx0, &h, &format!("can0 copy {i}"))?;
    }
    canraw::expect_quiet(&[("can0", &rx0)])?;
    ensure!(
        ctx.stat("can0", "rx_over_errors")? == 1,
        "can0 rx_over_errors not 1"
    );
    Ok(())
}
