// SPDX-License-Identifier: GPL-2.0
//! The test cases, grouped by topic. Each file exports a `TESTS` table.

mod bcm;
mod candev;
mod candev_err;
mod canutils;
mod capture;
mod ctucanfd;
mod ctucanfd_sim;
mod ctucanfd_wire;
pub use ctucanfd_wire::park_spare_ctucan_cards;
mod daemons;
mod dsor;
mod errors;
mod fd;
mod filter;
mod gateway;
mod i82527;
mod i82527_dev;
mod install;
mod isotp;
mod isotp_opts;
mod j1939;
mod j1939_errqueue;
mod j1939_sja1000;
mod j1939_tp;
mod leak;
mod lifecycle;
mod loopdrv;
mod mixed;
mod modules;
mod netns;
mod raw_bind;
mod raw_efault;
mod raw_filter;
mod raw_loopback;
mod raw_recv;
mod raw_send;
mod raw_sockopt;
mod recv;
mod remote;
mod robust;
mod rxcontext;
mod sja1000;
mod sja1000_modes;
mod socket;
mod teardown;
mod timesvc;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::Duration;

use socketcan::Socket;

use crate::canraw::{self, std as sff};
use crate::check::{ensure, wait_until, OnDrop, OrFail, TestResult, SETTLE};
use crate::ctx::{dev, Ctx, Module};
use crate::Test;

/// `test_table![a, b]`: a table of [`Test`]s named after their functions,
/// run against our stack only, each with modules of its own
/// ([`crate::Uses::Own`]). `test_table![a; stack: b, c]` (or `test_table![stack:
/// b, c]`) declares `b` and `c` [`crate::Uses::Stack`]: they run on the loaded
/// stack the runner keeps from one such test to the next.
macro_rules! test_table {
    (stack: $($s:ident),* $(,)?) => {
        &[$(crate::Test { name: stringify!($s), run: $s, portable: false, uses: crate::Uses::Stack }),*]
    };
    ($($f:ident),* $(,)? $(; stack: $($s:ident),* $(,)?)?) => {
        &[
            $(crate::Test { name: stringify!($f), run: $f, portable: false, uses: crate::Uses::Own },)*
            $($(crate::Test { name: stringify!($s), run: $s, portable: false, uses: crate::Uses::Stack },)*)?
        ]
    };
}
pub(crate) use test_table;

/// `portable_table![a, b]`: like [`test_table`], for tests that also run
/// against mainline SocketCAN (`--stack mainline`); `stack:` likewise.
macro_rules! portable_table {
    (stack: $($s:ident),* $(,)?) => {
        &[$(crate::Test { name: stringify!($s), run: $s, portable: true, uses: crate::Uses::Stack }),*]
    };
    ($($f:ident),* $(,)? $(; stack: $($s:ident),* $(,)?)?) => {
        &[
            $(crate::Test { name: stringify!($f), run: $f, portable: true, uses: crate::Uses::Own },)*
            $($(crate::Test { name: stringify!($s), run: $s, portable: true, uses: crate::Uses::Stack },)*)?
        ]
    };
}
pub(crate) use portable_table;

/// Tests the runner leaves out on the debug kernel, where they run past
/// the per-test watchdog (360 s) under TCG: `install_autoload` runs the
/// kernel's Makefile (`make install`) and some twenty programs. The code
/// it reaches in the kernel, `rcan_pf`'s request_module on `socket()`,
/// also runs on the debug kernel in `socket_create` (an unregistered
/// protocol).
///
/// Four of the simulated-SJA1000 tests too: under TCG on a shared host
/// each took 40-190 s on the debug kernel (the `ip` and `insmod` starts
/// dominate); the debug kernel keeps `sja1000_sim_bus_off_auto_restart`
/// (bus-off, the restart timer, error frames) and
/// `sja1000_sim_arblost_overrun`, which reach the same driver paths
/// under lockdep and KASAN.
///
/// And the daemons added with powerd and logd (40-130 s each on the
/// loaded debug kernel): they test user-space tools; the kernel paths
/// they use (CAN_BCM jobs, CANPROTO_DSOR receive, CAN_RAW filters) run
/// on the debug kernel in the bcm, dsor and raw tests.
///
/// The info-leak checks of DSOR bodies and the rtime frame, and the DSOR
/// loss accounting at 30 and 50 % drop rate (1-5 min each on the loaded
/// debug kernel): what they check does not depend on the kernel variant;
/// the DSOR engine's paths run on the debug kernel in the dsor tests.
///
/// Two of the simulated-82527 device-layer tests (98 and 27 s on the
/// loaded debug kernel, mostly `ip` starts): the debug kernel keeps
/// `i82527_sim_bus_off_restarts` (43 s), which reaches the changelink
/// hooks, the error frames, the restart timer and the manual restart
/// under lockdep and KASAN.
///
/// `canutils_fd_python_can` starts python3 (some 100 s under TCG on the
/// debug kernel); the FD paths of CAN_RAW it reaches run there in the
/// other `fd.rs` tests.
///
/// Three of the CTU CAN FD tests (13-22 s each on the debug kernel, mostly
/// the interface setup and the tools' starts): `candev_ctucanfd_fd_both_ways` and
/// `ctucanfd_rmmod_during_traffic` reach the same driver paths (transmit,
/// the TX ring wrapping round, echo, receive, the shared interrupt,
/// teardown) under lockdep and KASAN. Likewise `candev_ctucanfd_ip_fd_on_off`
/// (some 15 `ip` starts, 90 s on the loaded debug kernel) and
/// `ctucanfd_fd_esi_both_ways`: `candev_ctucanfd_ip_fd_refusals` reaches the
/// same changelink, MTU and open paths of the device layer there.
pub const RELEASE_ONLY: &[&str] = &[
    "install_autoload",
    "sja1000_sim_bus_off_manual_restart",
    "sja1000_sim_bus_errors_candump",
    "sja1000_sim_one_shot",
    "sja1000_sim_listen_only_presume_ack",
    "cantcpd_bcm_mode_jobs_and_subscriptions",
    "powerd_shuts_down_on_its_frame_only",
    "powerd_dry_run_and_sigterm_change_nothing",
    "logd_logs_dsor_messages_from_peer",
    "canutils_fd_python_can",
    "leak_dsor_bodies",
    "leak_rtime_frame",
    "dsor_loss_accounting",
    "i82527_sim_ip_bittiming",
    "i82527_sim_bus_errors_candump",
    "i82527_sim_overrun_candump",
    "candev_ctucanfd_classic_both_ways",
    "ctucanfd_burst",
    "candev_ctucanfd_cansend_candump",
    "candev_ctucanfd_ip_fd_on_off",
    "ctucanfd_fd_esi_both_ways",
    // The state and counters `ip -d` shows; candev_ctucanfd_ctrlmodes
    // reaches the same state/berr-counter/restart paths on the debug kernel.
    "ctucanfd_error_active_when_up",
    // ctucanfd_sim_bus_off_auto_restart reaches bus-off and the restart
    // on the debug kernel, ctucanfd_sim_candump_arblost_overrun the bus
    // error, arbitration-lost and overrun interrupts.
    "ctucanfd_sim_bus_off_manual_restart",
    // Both stacks' CTU CAN FD drivers on two cards (some 10 `ip` and
    // module loads): the debug kernel reaches our driver's paths in the
    // ctucanfd tests; mainline's is not ours to check under KASAN.
    "ctucanfd_wire_peer_mainline",
];

/// Tests whose hang bound (the per-test watchdog, `--timeout`) is longer
/// than the suite's, in seconds: it detects a hang, and these take most
/// of the suite's bound on a quiet host. `install_autoload` runs the
/// kernel's Makefile (`make install`: `modules_install` with some forty
/// program starts) and `make uninstall` in the guest: 68-153 s of guest
/// time on a quiet host (build.rst), and on 2026-11-29 it passed the 180 s
/// bound beside other VMs and builds, which ended its shard's run there.
///
/// The tests that start python3 on the debug kernel wait for it up to
/// `tools::python_limit()` (900 s there): importing python-can on a
/// loaded host's debug kernel took more than 300 s on 2026-11-30.
pub const LONG_RUNNING: &[(&str, u64)] = &[
    ("install_autoload", 900),
    ("bcm_python_can_send_periodic", 1200),
    ("cantcpd_python_can_and_second_client", 1200),
    ("cantcpd_slow_client_drops_alone", 1200),
    ("isotp_python_uds", 1200),
];

/// Every test, in running order.
pub fn all() -> impl Iterator<Item = &'static Test> {
    [
        modules::TESTS,
        socket::TESTS,
        recv::TESTS,
        filter::TESTS,
        errors::TESTS,
        loopdrv::TESTS,
        lifecycle::TESTS,
        teardown::TESTS,
        teardown::OURS,
        raw_sockopt::TESTS,
        raw_filter::TESTS,
        raw_loopback::TESTS,
        raw_recv::TESTS,
        raw_bind::TESTS,
        raw_send::TESTS,
        raw_efault::TESTS,
        leak::TESTS,
        canutils::TESTS,
        daemons::TESTS,
        capture::TESTS,
        gateway::TESTS,
        mixed::TESTS,
        remote::TESTS,
        remote::OURS,
        timesvc::TESTS,
        dsor::TESTS,
        sja1000::TESTS,
        ctucanfd::TESTS,
        ctucanfd::PORTABLE_TESTS,
        candev::TESTS,
        capture::SJA1000_TESTS,
        daemons::SJA1000_TESTS,
        daemons::DSOR_TESTS,
        i82527::TESTS,
        candev_err::TESTS,
        sja1000_modes::TESTS,
        i82527_dev::TESTS,
        leak::OURS,
        rxcontext::TESTS,
        install::TESTS,
        bcm::TESTS,
        bcm::OURS,
        isotp::TESTS,
        isotp::OURS,
        isotp_opts::TESTS,
        j1939::TESTS,
        j1939_tp::TESTS,
        j1939_errqueue::TESTS,
        j1939_errqueue::OURS,
        j1939_sja1000::TESTS,
        netns::TESTS,
        netns::OURS,
        fd::TESTS,
        robust::OURS,
        ctucanfd_sim::TESTS,
        ctucanfd_wire::TESTS,
    ]
    .into_iter()
    .flatten()
}

/// Loads the stack with one loopback device (up); returns can0's ifindex.
fn stack1(ctx: &mut Ctx) -> Result<u32, String> {
    ctx.load_stack(&[])?;
    ctx.ifindex(&dev(0))
}

/// Loads the stack with two loopback devices (up); returns their ifindexes.
fn stack2(ctx: &mut Ctx) -> Result<(u32, u32), String> {
    ctx.load_stack(&["count=2"])?;
    Ok((ctx.ifindex(&dev(0))?, ctx.ifindex(&dev(1))?))
}

/// Loads the stack under test with CAN_RAW and one interface (up);
/// returns can0's ifindex.
fn raw1(ctx: &mut Ctx) -> Result<u32, String> {
    Ok(ctx.can_ifaces(1)?[0])
}

/// Loads the stack under test with CAN_RAW and two interfaces (up);
/// returns their ifindexes.
fn raw2(ctx: &mut Ctx) -> Result<(u32, u32), String> {
    let i = ctx.can_ifaces(2)?;
    Ok((i[0], i[1]))
}

/// rmmod of card driver `m` while a sender on `i0` and a receiver on `i1`
/// (two of its interfaces, can0 and can1) are busy: the module goes,
/// their calls fail cleanly, the kernel log stays clean (checked by the VM
/// runner).
fn rmmod_card_during_traffic(ctx: &mut Ctx, m: Module, i0: u32, i1: u32) -> TestResult {
    let tx = canraw::open(i0)?;
    let rx = canraw::open(i1)?;
    rx.set_read_timeout(Duration::from_millis(200))
        .or_fail("SO_RCVTIMEO")?;
    let stop = Arc::new(AtomicBool::new(false));
    let (sent, got) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    // Stops both threads on every way out, the early returns included.
    let _stop = OnDrop({
        let stop = stop.clone();
        move || stop.store(true, Ordering::Relaxed)
    });
    let send = {
        let (stop, sent) = (stop.clone(), sent.clone());
        thread::spawn(move || {
            let mut n = 0u64;
            while !stop.load(Ordering::Relaxed) && tx.write_frame(&sff(0x55, &[n as u8])).is_ok() {
                n += 1;
                sent.store(n, Ordering::Relaxed);
            }
        })
    };
    let recv = {
        let (stop, got) = (stop.clone(), got.clone());
        thread::spawn(move || {
            while !stop.load(Ordering::Relaxed) {
                if rx.read_frame().is_ok() {
                    got.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
    };
    // Frames moving both ways before the card goes, not a fixed time.
    wait_until(SETTLE, "frames sent on can0 and received on can1", || {
        sent.load(Ordering::Relaxed) >= 16 && got.load(Ordering::Relaxed) >= 16
    })?;
    ctx.rmmod(m)?;
    // The sender ends at its first failed write: the card is gone.
    wait_until(SETTLE, "a write failing after the rmmod", || send.is_finished())?;
    stop.store(true, Ordering::Relaxed);
    send.join().map_err(|_| "sender panicked".to_string())?;
    recv.join().map_err(|_| "receiver panicked".to_string())?;
    let (sent, got) = (sent.load(Ordering::Relaxed), got.load(Ordering::Relaxed));
    ctx.note(format!(
        "{sent} frames sent, {got} received before and during rmmod"
    ));
    ensure!(
        sent > 0 && got > 0,
        "no traffic before rmmod (sent {sent}, received {got})"
    );
    ensure!(
        !std::path::Path::new("/sys/class/net/can0").exists(),
        "can0 still there after rmmod"
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn portable_names() {
        // The prefixes say what a test needs: raw_/canutils_/candev_/bcm_/
        // isotp_, j1939_ and the daemons' canzlogd_/cantcpd_/powerd_ run on both stacks,
        // everything else (mixed_, sja1000_ included) on ours only.
        for t in super::all() {
            let portable = [
                "raw_",
                "canutils_",
                "candev_",
                "bcm_",
                "isotp_",
                "j1939_",
                "canzlogd_",
                "cantcpd_",
                "powerd_",
            ]
            .iter()
            .any(|p| t.name.starts_with(p));
            assert_eq!(t.portable, portable, "{}", t.name);
        }
    }

    #[test]
    fn names_are_unique() {
        let mut names: Vec<_> = super::all().map(|t| t.name).collect();
        let n = names.len();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), n);
    }
}
