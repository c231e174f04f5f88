// SPDX-License-Identifier: GPL-2.0
//! Module load order and reference counting.

use std::time::Instant;

use rcan_uapi::{raw, PF_CAN};

use super::teardown::{module_listed, CANPROTO_EXITTEST};
use super::{stack1, test_table};
use crate::canraw::{self, std as sff};
use crate::check::{ensure, expect_errno, expect_frame, wait_until, Frame, TestResult, SETTLE};
use crate::ctx::{Ctx, Module, ABISKEW};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    module_can_needs_pf,
    module_pf_pinned_by_can,
    module_can_pinned_by_socket,
    module_abi_mismatch,
];

/// rcan_can cannot be loaded before rcan_pf.
fn module_can_needs_pf(ctx: &mut Ctx) -> TestResult {
    ensure!(
        ctx.insmod(Module::Can, &[]).is_err(),
        "insmod rcan_can without rcan_pf succeeded"
    );
    ensure!(
        !ctx.is_loaded(Module::Can),
        "rcan_can is listed in /proc/modules after a failed insmod"
    );
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ctx.rmmod(Module::Can)?;
    ctx.rmmod(Module::Pf)
}

/// rcan_pf cannot be unloaded while rcan_can is loaded.
fn module_pf_pinned_by_can(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ensure!(
        ctx.rmmod(Module::Pf).is_err(),
        "rmmod rcan_pf succeeded while rcan_can is loaded"
    );
    ensure!(ctx.is_loaded(Module::Pf), "rcan_pf vanished");
    ctx.rmmod(Module::Can)?;
    ctx.rmmod(Module::Pf)
}

/// rcan_can cannot be unloaded while one of its sockets is open; after the
/// last close it can, also when the socket had frames queued.
fn module_can_pinned_by_socket(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    let s = ctx.socket()?;
    ensure!(
        ctx.rmmod(Module::Can).is_err(),
        "rmmod rcan_can succeeded with a socket open"
    );
    drop(s);
    rmmod_after_close(ctx, "an unbound socket")?;
    ctx.rmmod(Module::Pf)?;

    // Again with the driver and a bound socket holding a queued frame.
    let idx = stack1(ctx)?;
    let s = ctx.bound(0, rcan_uapi::CAN_MASK_ANY, idx)?;
    let f = Frame::std(0x42, &[1, 2, 3]);
    f.send(&s, idx)?;
    f.send(&s, idx)?;
    expect_frame(&s, &f, idx)?; // the second copy stays queued
    ensure!(
        ctx.rmmod(Module::Can).is_err(),
        "rmmod rcan_can succeeded with a bound socket open"
    );
    drop(s);
    rmmod_after_close(ctx, "a bound socket with a queued frame")
}

/// rmmod rcan_can right after the last socket was closed. A socket whose
/// memory is freed after an RCU grace period may keep the module busy
/// briefly, so retry until it goes (up to [`SETTLE`]: the debug kernel
/// under load stretches a grace period), and say so if it was needed.
fn rmmod_after_close(ctx: &mut Ctx, what: &str) -> TestResult {
    let start = Instant::now();
    let mut tries = 0;
    let mut last = String::new();
    wait_until(SETTLE, "rmmod rcan_can to succeed", || {
        tries += 1;
        match ctx.rmmod(Module::Can) {
            Ok(()) => true,
            Err(e) => {
                last = e;
                false
            }
        }
    })
    .map_err(|e| format!("after closing {what}: {e}: {last}"))?;
    if tries > 1 {
        ctx.note(format!(
            "rmmod rcan_can after closing {what} succeeded only at try {tries} ({:?})",
            start.elapsed()
        ));
    }
    Ok(())
}

/// A protocol module built for another ABI than the loaded rcan_pf's
/// (issue 39, "a versioned module ABI"; `rcan_abiskew`, `rcan_exittest`'s
/// code built to claim the next ABI version, as a module from another
/// tree would) fails to load cleanly: ENOEXEC, a kernel log line from
/// that module naming both ABIs, nothing left registered (it is not
/// listed, its protocol number says EPROTONOSUPPORT, its devices do not
/// exist), and the stack keeps working (CAN_RAW frames on can0).
fn module_abi_mismatch(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&[])?;
    let can0 = ctx.ifindex("can0")?;
    let mut kmsg = ctx.kmsg()?;
    match ctx.insmod_abiskew()? {
        Ok(()) => return Err(format!("insmod {ABISKEW} succeeded against another ABI")),
        Err(e) => ensure!(
            e.raw_os_error() == Some(libc::ENOEXEC),
            "insmod {ABISKEW}: {e}, expected ENOEXEC (Exec format error)"
        ),
    }
    let log = kmsg.read_new()?;
    // The version numbers are the tree's (bumped when the ABI changes):
    // the skewed module claims the next one.
    let version = |l: &str, what: &str| -> Option<u32> {
        let rest = &l[l.find(what)? + what.len()..];
        rest.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok()
    };
    ensure!(
        log.iter().any(|l| l.contains(ABISKEW)
            && l.contains("rcan ABI mismatch")
            && matches!(
                (version(l, "this module has ABI "), version(l, "rcan_pf has ABI ")),
                (Some(skewed), Some(ours)) if skewed == ours + 1
            )),
        "no ABI-mismatch line from {ABISKEW} naming both ABIs (the next version and rcan_pf's) in the kernel log: {log:?}"
    );
    ensure!(!module_listed(ABISKEW), "{ABISKEW} listed in /proc/modules after the failed insmod");
    ensure!(
        !std::path::Path::new("/sys/class/net/rcanexit0").exists(),
        "{ABISKEW} registered a device before failing"
    );
    let s = raw::socket(PF_CAN, libc::SOCK_DGRAM, CANPROTO_EXITTEST);
    expect_errno(s, libc::EPROTONOSUPPORT, "socket(CANPROTO_EXITTEST) after the failed insmod")?;
    let rx = canraw::open(can0)?;
    let tx = canraw::open(can0)?;
    let f = sff(0x2a5, &[0xab, 0x1]);
    canraw::send(&tx, &f)?;
    canraw::expect(&rx, &f, "can0 after the failed insmod")
}
