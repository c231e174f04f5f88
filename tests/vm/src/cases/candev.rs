// SPDX-License-Identifier: GPL-2.0
//! The CAN device layer as users meet it: `ip link set canX type can ...`
//! and `ip -details link show canX` on QEMU's Kvaser cards (an SJA1000
//! with an 8 MHz CAN clock). Portable: with `--stack mainline` they run
//! against mainline's can-dev + sja1000 + kvaser_pci, which shows that the
//! expected values are mainline's; with ours against rcan_dev +
//! rcan_kvaser_pci. Every command is the plain `ip` command a user types.
//!
//! What differs on purpose is not checked here: our SJA1000's transmit
//! queue is longer (1000, not 10). Loopback and cc-len8-dlc, which QEMU's
//! card cannot carry out, are tested on the simulated card
//! (sja1000_modes.rs). `sja1000_ip_matches_mainline`
//! (sja1000.rs) compares the whole `ip -j -d` output of both in one boot.

use super::portable_table;
use crate::check::{ensure, wait_for, TestResult, SETTLE};
use crate::ctx::Ctx;
use crate::tools::{self, Output};

pub const TESTS: &[crate::Test] = portable_table![
    candev_bitrate_125k,
    candev_bitrate_sample_point,
    candev_direct_timing,
    candev_errors,
    candev_up_without_bitrate,
    candev_busy_when_up,
    candev_restart_ms,
];

/// Runs `ip ARGS...` to completion, whatever its exit status.
pub(super) fn ip(args: &[&str]) -> Result<Output, String> {
    tools::spawn("ip", args, None)?.finish(tools::TOOL_LIMIT)
}

/// Runs `ip ARGS...`, which must succeed; returns its stdout.
pub(super) fn ip_ok(args: &[&str]) -> Result<String, String> {
    Ok(tools::run_ok("ip", args)?.stdout)
}

/// Runs `ip -batch` on `lines` (each one `ip` command's arguments, as
/// typed after `ip`), all of which must succeed: one `ip` start for a
/// set-up of several commands. `ip` sends each line's netlink request
/// as it would for the command alone, stops at the first that fails and
/// names it ("Command failed FILE:LINE"), as a chain of [`ip_ok`] calls
/// stops at the first error. For set-ups, not for the commands a test is
/// about: on the debug kernel each `ip` start costs 1-7 s of KASAN-checked
/// exec and page faults under TCG.
pub(super) fn ip_batch_ok(lines: &[Vec<&str>]) -> TestResult {
    let dir = tools::TempDir::new("ip-batch")?;
    let file = dir.path().join("lines");
    let text: String = lines.iter().map(|l| l.join(" ") + "\n").collect();
    std::fs::write(&file, &text).map_err(|e| format!("{}: {e}", file.display()))?;
    let file = file.to_string_lossy().into_owned();
    let out = ip(&["-batch", &file])?;
    ensure!(
        out.status.success(),
        "ip -batch of {:?}: {}: {}",
        text.lines().collect::<Vec<_>>(),
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// Runs `ip ARGS...`, which must fail with an error output containing
/// `want`.
fn ip_fails(args: &[&str], want: &str) -> TestResult {
    let out = ip(args)?;
    ensure!(
        !out.status.success() && out.stderr.contains(want),
        "ip {}: expected failure with {want:?}, got {} {:?}",
        args.join(" "),
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// `ip link set DEV type can ARGS...`, which must succeed.
fn set_can(dev: &str, args: &[&str]) -> TestResult {
    let mut a = vec!["link", "set", dev, "type", "can"];
    a.extend_from_slice(args);
    ip_ok(&a).map(|_| ())
}

/// The output of `ip -j -d link show DEV` (one JSON line).
pub(super) fn details_json(dev: &str) -> Result<String, String> {
    ip_ok(&["-j", "-d", "link", "show", dev])
}

/// Waits until `/sys/class/net/DEV/operstate` reads `want` (the kernel's
/// link watch updates it shortly after the carrier changes); fails with
/// the last value after [`SETTLE`]. Not a timing assertion: the bound
/// only ends a wait for a state that never comes.
fn operstate_becomes(dev: &str, want: &str) -> TestResult {
    let p = format!("/sys/class/net/{dev}/operstate");
    let mut last = String::new();
    wait_for(SETTLE, &format!("{p} reading {want:?}"), || {
        last = std::fs::read_to_string(&p).map_err(|e| format!("{p}: {e}"))?;
        Ok((last.trim() == want).then_some(()))
    })
    .map_err(|e| format!("{e}: last {:?}", last.trim()))
}

/// Checks that `text` contains every one of `want`.
fn contains_all(what: &str, text: &str, want: &[&str]) -> TestResult {
    for w in want {
        ensure!(text.contains(w), "{what}: {w:?} missing in {text}");
    }
    Ok(())
}

/// `bitrate 125000` on can0: mainline's timing (87.5 % sample point,
/// tq 500 ns, brp 4), the SJA1000's limits and clock, state STOPPED while
/// down, in both `ip -d` and `ip -j -d`.
fn candev_bitrate_125k(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can("can0", &["bitrate", "125000"])?;
    contains_all(
        "ip -d link show can0",
        &ip_ok(&["-d", "link", "show", "can0"])?,
        &[
            "can state STOPPED (berr-counter tx 0 rx 0) restart-ms 0",
            "bitrate 125000 sample-point 0.875",
            "tq 500 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1 brp 4",
            "sja1000: tseg1 1..16 tseg2 1..8 sjw 1..4 brp 1..64 brp_inc 1",
            "clock 8000000",
        ],
    )?;
    contains_all(
        "ip -j -d link show can0",
        &details_json("can0")?,
        &[
            r#""info_kind":"can""#,
            r#""state":"STOPPED""#,
            r#""berr_counter":{"tx":0,"rx":0}"#,
            r#""restart_ms":0"#,
            r#""bittiming":{"bitrate":125000,"sample_point":"0.875","tq":500,"prop_seg":6,"phase_seg1":7,"phase_seg2":2,"sjw":1,"brp":4}"#,
            r#""bittiming_const":{"name":"sja1000","tseg1":{"min":1,"max":16},"tseg2":{"min":1,"max":8},"sjw":{"min":1,"max":4},"brp":{"min":1,"max":64},"brp_inc":1}"#,
            r#""clock":8000000"#,
        ],
    )
}

/// `bitrate 500000 sample-point 0.875`, then up (systemd's order: bit
/// timing first): the timing mainline computes, state ERROR-ACTIVE once
/// up, the operational state UP (the carrier is on; the issue found
/// UNKNOWN), and the device statistics of `ip -s -d` all zero.
fn candev_bitrate_sample_point(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can("can0", &["bitrate", "500000", "sample-point", "0.875"])?;
    ip_ok(&["link", "set", "can0", "up"])?;
    operstate_becomes("can0", "up")?;
    contains_all(
        "ip -j -d link show can0",
        &details_json("can0")?,
        &[
            r#""state":"ERROR-ACTIVE""#,
            r#""bittiming":{"bitrate":500000,"sample_point":"0.875","tq":125,"prop_seg":6,"phase_seg1":7,"phase_seg2":2,"sjw":1,"brp":1}"#,
        ],
    )?;
    let s = ip_ok(&["-s", "-d", "link", "show", "can0"])?;
    contains_all(
        "ip -s -d link show can0",
        &s,
        &[
            "can state ERROR-ACTIVE",
            "re-started bus-errors arbit-lost error-warn error-pass bus-off",
        ],
    )?;
    // The six counters follow their header line.
    let counters = s
        .lines()
        .skip_while(|l| !l.contains("re-started"))
        .nth(1)
        .unwrap_or("");
    let zeros: Vec<&str> = counters.split_whitespace().take(6).collect();
    ensure!(
        zeros == ["0"; 6],
        "device statistics not all zero: {counters:?}"
    );
    ip_ok(&["link", "set", "can0", "down"])?;
    ensure!(
        details_json("can0")?.contains(r#""state":"STOPPED""#),
        "state not STOPPED after down"
    );
    Ok(())
}

/// A timing given directly (`tq prop-seg phase-seg1 phase-seg2 sjw`): the
/// bit rate and sample point follow; `tq 130` becomes the prescaler's
/// 125 ns.
fn candev_direct_timing(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can(
        "can0",
        &[
            "tq",
            "130",
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
    contains_all(
        "ip -j -d link show can0",
        &details_json("can0")?,
        &[
            r#""bittiming":{"bitrate":500000,"sample_point":"0.875","tq":125,"prop_seg":6,"phase_seg1":7,"phase_seg2":2,"sjw":1,"brp":1}"#,
        ],
    )
}

/// Impossible settings are refused with mainline's errno and message, and
/// leave the timing set before unchanged. A control mode the SJA1000
/// lacks (`fd on`: it is a classic controller) is refused with
/// EOPNOTSUPP and leaves the modes as they were.
fn candev_errors(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can("can0", &["bitrate", "250000"])?;
    let base = ["link", "set", "can0", "type", "can"];
    let with = |extra: &[&'static str]| -> Vec<&str> {
        let mut v = base.to_vec();
        v.extend_from_slice(extra);
        v
    };
    ip_fails(
        &with(&["bitrate", "500000", "sample-point", "1.0"]),
        "Error: sample point must be between 0 and 100%",
    )?;
    ip_fails(
        &with(&["bitrate", "1000"]),
        "Error: bitrate error: 429496729.5% too high",
    )?;
    ip_fails(
        &with(&[
            "tq",
            "125",
            "prop-seg",
            "10",
            "phase-seg1",
            "7",
            "phase-seg2",
            "2",
        ]),
        "Error: prop-seg + phase-seg1: 17 greater than tseg1-max: 16",
    )?;
    ip_fails(
        &with(&[
            "tq",
            "125",
            "prop-seg",
            "6",
            "phase-seg1",
            "7",
            "phase-seg2",
            "2",
            "sjw",
            "5",
        ]),
        "Error: sjw: 5 greater than max sjw: 4",
    )?;
    // Both a bit rate and a timing: EINVAL without a message.
    ip_fails(
        &with(&[
            "bitrate",
            "500000",
            "tq",
            "125",
            "prop-seg",
            "6",
            "phase-seg1",
            "7",
            "phase-seg2",
            "2",
        ]),
        "Invalid argument",
    )?;
    ip_fails(&with(&["fd", "on"]), "Operation not supported")?;
    let j = details_json("can0")?;
    ensure!(
        j.contains(r#""bitrate":250000"#),
        "a refused setting changed the bit timing"
    );
    ensure!(
        !j.contains(r#""FD""#),
        "a refused fd on shows in the control modes: {j}"
    );
    Ok(())
}

/// `ip link set can0 up` without a bit timing: EINVAL, and the kernel log
/// says why, as mainline's "bit-timing not yet defined".
fn candev_up_without_bitrate(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    let mut kmsg = ctx.kmsg()?;
    ip_fails(&["link", "set", "can0", "up"], "Invalid argument")?;
    let log = kmsg.read_new()?;
    ensure!(
        log.iter()
            .any(|l| l.contains("can0") && l.contains("bit-timing not yet defined")),
        "no 'bit-timing not yet defined' line for can0 in the kernel log: {log:?}"
    );
    ensure!(
        details_json("can0")?.contains(r#""operstate":"DOWN""#),
        "can0 not down after the refused up"
    );
    Ok(())
}

/// While up, bit timing and restart-ms are refused with EBUSY; down
/// again, they are taken. The MTU (mainline `can_change_mtu`): `mtu 72`
/// (CAN FD) is EINVAL while down on this classic controller and EBUSY
/// while up; `mtu 16`, the current one, is taken either way.
fn candev_busy_when_up(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can("can0", &["bitrate", "250000"])?;
    let inval = "RTNETLINK answers: Invalid argument";
    ip_fails(&["link", "set", "can0", "mtu", "72"], inval)?;
    ip_fails(&["link", "set", "can0", "mtu", "20"], inval)?;
    ip_ok(&["link", "set", "can0", "mtu", "16"])?;
    ip_ok(&["link", "set", "can0", "up"])?;
    let busy = "RTNETLINK answers: Device or resource busy";
    ip_fails(&["link", "set", "can0", "mtu", "72"], busy)?;
    ip_ok(&["link", "set", "can0", "mtu", "16"])?;
    ensure!(
        details_json("can0")?.contains(r#""mtu":16"#),
        "can0's MTU changed"
    );
    ip_fails(
        &["link", "set", "can0", "type", "can", "bitrate", "125000"],
        busy,
    )?;
    ip_fails(
        &["link", "set", "can0", "type", "can", "restart-ms", "100"],
        busy,
    )?;
    ip_fails(
        &[
            "link",
            "set",
            "can0",
            "type",
            "can",
            "triple-sampling",
            "on",
        ],
        busy,
    )?;
    ip_ok(&["link", "set", "can0", "down"])?;
    set_can("can0", &["bitrate", "125000", "triple-sampling", "on"])?;
    contains_all(
        "ip -j -d link show can0",
        &details_json("can0")?,
        &[r#""bitrate":125000"#, r#""ctrlmode":["TRIPLE-SAMPLING"]"#],
    )
}

/// `restart-ms` is accepted and reported; a manual `restart` is refused
/// while down (EINVAL) and, once up with automatic restart off, while the
/// controller is not bus-off (EBUSY), as mainline.
fn candev_restart_ms(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    set_can("can0", &["bitrate", "500000", "restart-ms", "100"])?;
    contains_all(
        "ip -d link show can0",
        &ip_ok(&["-d", "link", "show", "can0"])?,
        &["restart-ms 100"],
    )?;
    ip_fails(
        &["link", "set", "can0", "type", "can", "restart"],
        "Invalid argument",
    )?;
    set_can("can0", &["restart-ms", "0"])?;
    ip_ok(&["link", "set", "can0", "up"])?;
    ip_fails(
        &["link", "set", "can0", "type", "can", "restart"],
        "Device or resource busy",
    )?;
    ensure!(
        details_json("can0")?.contains(r#""restart_ms":0"#),
        "restart-ms 0 not reported"
    );
    Ok(())
}
