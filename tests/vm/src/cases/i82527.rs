// SPDX-License-Identifier: GPL-2.0
//! The Intel 82527 driver family (thesis 5.3.10-5.3.11) in the VM: the
//! unchanged driver on two simulated cards (`rcan_i82527_sim`, whose
//! registers are the register-level model and whose bus connects the
//! cards), under rcan_pf, CANPROTO_CAN and CAN_RAW. Frames both ways with
//! both APIs, remote frames answered by the other card's message objects
//! (published with the SIOCRCANI82527ANSWER ioctl), a burst with every
//! frame checked, rmmod under traffic; and the ISA front-end refusing to
//! load where there is no card.
//!
//! Chip-level behaviour (allocation, overrun, bus-off, masks) is covered
//! by the host tests (drivers/net/can/chips/tests/i82527_*.rs).

use std::thread;
use std::time::{Duration, Instant};

use socketcan::{CanFrame, Socket};

use super::test_table;
use crate::canraw::{self, ext, rtr_ext, rtr_std, std as sff};
use crate::check::{ensure, wait_until, OrFail, TestResult, SETTLE};
use crate::ctx::{dev, sized, Ctx, Module};
use crate::tools;
use rcan_uapi::{dev_ioctl, SIOCDEVPRIVATE};

pub const TESTS: &[crate::Test] = test_table![
    i82527_frames_both_ways,
    i82527_thesis_api,
    i82527_remote_answer,
    i82527_burst,
    i82527_rmmod_during_traffic,
    i82527_isa_no_card,
    i82527_config_tool,
];

/// Loads rcan_pf, rcan_can, rcan_raw and rcan_i82527_sim (two cards:
/// can0, can1), both up; returns their ifindexes.
pub(super) fn sim2(ctx: &mut Ctx) -> Result<(u32, u32), String> {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::I82527Sim, &["cards=2"])?;
    ensure!(
        std::path::Path::new("/sys/class/net/can1").exists()
            && !std::path::Path::new("/sys/class/net/can2").exists(),
        "rcan_i82527_sim cards=2 did not make exactly can0 and can1"
    );
    ctx.link_up(&dev(0))?;
    ctx.link_up(&dev(1))?;
    Ok((ctx.ifindex(&dev(0))?, ctx.ifindex(&dev(1))?))
}

const SIOCRCANI82527GET: libc::c_ulong = SIOCDEVPRIVATE;
const SIOCRCANI82527ANSWER: libc::c_ulong = SIOCDEVPRIVATE + 2;

/// Publishes (`Some`) or withdraws the answer of slot `slot` on `iface`
/// (`struct rcan_i82527_answer`).
fn answer(iface: &str, slot: u32, f: Option<&CanFrame>) -> std::io::Result<()> {
    let mut b = [0u8; 24];
    b[..4].copy_from_slice(&slot.to_ne_bytes());
    b[4..8].copy_from_slice(&u32::from(f.is_some()).to_ne_bytes());
    if let Some(f) = f {
        b[8..24].copy_from_slice(&canraw::wire(f));
    }
    dev_ioctl(iface, SIOCRCANI82527ANSWER, &mut b)
}

/// Every data frame kind: standard and extended, DLC 0..8.
fn data_kinds() -> Vec<CanFrame> {
    let mut v = Vec::new();
    for n in 0..=8usize {
        let data: Vec<u8> = (0..n as u8).map(|i| 0xA0 | i).collect();
        v.push(sff(0x100 + n as u16, &data));
        v.push(ext(0x1234_5600 + n as u32, &data));
    }
    v.push(sff(0x7FF, &[0xFF; 8]));
    v.push(ext(0x1FFF_FFFF, &[]));
    v
}

/// Data frames, standard and extended, DLC 0..8, can0 -> can1 and back,
/// through CAN_RAW sockets; remote frames (standard and extended, DLC
/// 0..8) both ways: each goes on the bus (its sender's echo shows it to a
/// second local socket) and is answered by the other card's message
/// object. A receive object never stores a remote frame (datasheet), so
/// the receiving host sees the answer it sent, not the request.
fn i82527_frames_both_ways(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx)?;
    let (s0, s1) = (canraw::open(i0)?, canraw::open(i1)?);
    let frames = data_kinds();
    for f in &frames {
        canraw::send(&s0, f)?;
        canraw::expect(&s1, f, "can1")?;
    }
    for f in &frames {
        canraw::send(&s1, f)?;
        canraw::expect(&s0, f, "can0")?;
    }
    // Remote frames. One standard and one extended answer per card (the
    // open filters make the global standard mask "don't care", so a
    // standard answer object answers every standard remote frame: one is
    // all that can be told apart).
    let (e0, e1) = (canraw::open(i0)?, canraw::open(i1)?);
    let mut n = 0;
    for (tx, echo, rx, from, to) in [
        (&s0, &e0, &s0, "can0", "can1"),
        (&s1, &e1, &s1, "can1", "can0"),
    ] {
        for dlc in 0..=8usize {
            let data: Vec<u8> = (0..dlc as u8).collect();
            let sa = sff(0x300 + dlc as u16, &data);
            let ea = ext(0x0030_0000 + dlc as u32, &data);
            answer(to, 0, Some(&sa)).or_fail(format_args!("publish on {to}"))?;
            answer(to, 1, Some(&ea)).or_fail(format_args!("publish on {to}"))?;
            for (req, ans) in [
                (rtr_std(0x300 + dlc as u16, dlc), sa),
                (rtr_ext(0x0030_0000 + dlc as u32, dlc), ea),
            ] {
                canraw::send(tx, &req)?;
                // The second socket sees the request (echoed once it was on
                // the bus), then the answer; the sender only the answer.
                canraw::expect_seq(echo, &[req, ans], &format!("{from} echo"))?;
                canraw::expect(rx, &ans, &format!("{from} answer from {to}"))?;
                n += 1;
            }
        }
        answer(to, 0, None).or_fail("withdraw")?;
        answer(to, 1, None).or_fail("withdraw")?;
    }
    canraw::expect_quiet(&[
        ("can0", &s0),
        ("can1", &s1),
        ("can0 2nd", &e0),
        ("can1 2nd", &e1),
    ])?;
    ctx.note(format!(
        "{} data frames each way, {n} remote frames answered",
        frames.len()
    ));
    Ok(())
}

/// The thesis API on the simulated cards: a CANPROTO_CAN socket on can1
/// receives what a CAN_RAW socket sends on can0, and the other way round.
fn i82527_thesis_api(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx)?;
    let arb = ctx.bound(0, rcan_uapi::CAN_MASK_ANY, i1)?;
    let raw0 = canraw::open(i0)?;
    canraw::send(&raw0, &sff(0x321, &[1, 2, 3]))?;
    let mut buf = [0u8; 8];
    let (n, from) = arb.recv_from(&mut buf).or_fail("thesis recv on can1")?;
    ensure!(
        from.arb == rcan_uapi::arb_std(0x321, false) && buf[..n] == [1, 2, 3],
        "thesis socket got arb {:#x} data {:02x?}",
        from.arb,
        &buf[..n]
    );
    let tx = ctx.socket()?;
    tx.send_to(&[9, 8], rcan_uapi::arb_ext(0x0ABC_DEF0, false), i1)
        .or_fail("thesis sendto can1")?;
    canraw::expect(&raw0, &ext(0x0ABC_DEF0, &[9, 8]), "can0")?;
    Ok(())
}

/// The remote-answer interface: a data frame published on can1 answers a
/// remote frame from can0 without waking can1's host (its rx_packets does
/// not move); republishing changes the answer; withdrawing stops it; bad
/// slots and remote frames are refused; GET reports the setup.
fn i82527_remote_answer(ctx: &mut Ctx) -> TestResult {
    let (i0, _i1) = sim2(ctx)?;
    let s0 = canraw::open(i0)?;
    let ans = ext(0x01AB_CDEF, &[1, 2, 3, 4]);
    answer("can1", 3, Some(&ans)).or_fail("publish")?;
    let before = ctx.stat("can1", "rx_packets")?;
    canraw::send(&s0, &rtr_ext(0x01AB_CDEF, 4))?;
    canraw::expect(&s0, &ans, "can0")?;
    let ans2 = ext(0x01AB_CDEF, &[5, 6]);
    answer("can1", 3, Some(&ans2)).or_fail("republish")?;
    canraw::send(&s0, &rtr_ext(0x01AB_CDEF, 2))?;
    canraw::expect(&s0, &ans2, "can0 after republish")?;
    let after = ctx.stat("can1", "rx_packets")?;
    ensure!(
        after == before,
        "can1's host received {} frames while its chip answered",
        after - before
    );
    answer("can1", 3, None).or_fail("withdraw")?;
    canraw::send(&s0, &rtr_ext(0x01AB_CDEF, 2))?;
    canraw::expect_quiet(&[("can0", &s0)])?;
    let e = answer("can1", 12, Some(&ans)).expect_err("slot 12 accepted");
    ensure!(
        e.raw_os_error() == Some(libc::ERANGE),
        "slot 12: {e}, expected ERANGE"
    );
    let e = answer("can1", 0, Some(&rtr_std(0x5, 0))).expect_err("remote answer accepted");
    ensure!(
        e.raw_os_error() == Some(libc::EINVAL),
        "remote frame as answer: {e}, expected EINVAL"
    );
    let mut setup = [0u8; 12];
    dev_ioctl("can1", SIOCRCANI82527GET, &mut setup).or_fail("GET")?;
    ensure!(
        setup[..6] == [0x40, 0x00, 0x40, 0x00, 0x2B, 0],
        "GET: {setup:02x?}"
    );
    Ok(())
}

/// Frames per direction in [`i82527_burst`] (`RCAN_I82527_BURST`; default
/// 100,000, 2,000 on the debug kernel, as for the SJA1000 burst).
fn burst_len() -> u32 {
    sized("RCAN_I82527_BURST", 100_000, 2_000)
}

/// Longest wait for the next frame of a burst: a generous deadline, not a
/// rate (a loaded host stalls the emulated guest for seconds at times).
const BURST_GAP: Duration = Duration::from_secs(60);

/// Frames between two watchdog heartbeats in a burst.
const BURST_HEARTBEAT: u32 = 1_000;

/// One direction of the burst: `n` numbered frames, standard and extended
/// alternately (object 1 and object 15), every one must arrive once, in
/// order, intact. The receiver restarts the runner's watchdog every
/// [`BURST_HEARTBEAT`] frames: the watchdog bounds the wait for progress,
/// not the time the whole burst takes, which follows the host's load (on
/// a loaded host 100,000 frames each way took longer than the 180 s
/// watchdog at some 1,000 frames/s).
fn burst_one(
    ctx: &Ctx,
    n: u32,
    tx: &socketcan::CanSocket,
    rx: socketcan::CanSocket,
    what: &str,
) -> TestResult {
    let start = Instant::now();
    let frame = |seq: u32| {
        let mut d = [0x5Au8; 8];
        d[..4].copy_from_slice(&seq.to_le_bytes());
        if seq.is_multiple_of(2) {
            ext(0x0100_0000 | (seq & 0xFFFF), &d)
        } else {
            sff((seq & 0x7FF) as u16, &d)
        }
    };
    // The receiver hands its socket back even on failure: closing it would
    // change the masks (nobody wants anything) and blur where a frame went
    // missing (the simulated cards report "not taken" frames at unload).
    let recv = thread::spawn(move || -> (Result<u32, String>, socketcan::CanSocket) {
        if let Err(e) = rx.set_read_timeout(BURST_GAP) {
            return (Err(format!("SO_RCVTIMEO: {e}")), rx);
        }
        let mut next = 0u32;
        while next < n {
            let f = match canraw::recv(&rx) {
                Ok(f) => f,
                Err(e) => return (Err(e), rx),
            };
            if !canraw::same(&f, &frame(next)) {
                return (Err(format!("frame {next}: got {}", canraw::show(&f))), rx);
            }
            next += 1;
            if next.is_multiple_of(BURST_HEARTBEAT) {
                crate::heartbeat();
            }
        }
        (Ok(next), rx)
    });
    // What both ends have sent so far (tx_packets + tx_dropped +
    // tx_errors of can0 and can1), to tell when the burst has left.
    let tx_done = || -> u64 {
        ["can0", "can1"]
            .iter()
            .flat_map(|d| ["tx_packets", "tx_dropped", "tx_errors"].map(|n| (*d, n)))
            .map(|(d, n)| ctx.stat(d, n).unwrap_or(0))
            .sum()
    };
    let tx_before = tx_done();
    for seq in 0..n {
        canraw::send(tx, &frame(seq))?;
    }
    let (got, _rx) = recv.join().map_err(|_| "receiver panicked".to_string())?;
    let got = got.map_err(|e| {
        // Let the queued frames go out while the receiver still listens:
        // until every frame sent has left a card, or SETTLE (the counts
        // below then say where they stuck).
        let left = wait_until(SETTLE, "the burst to leave", || {
            tx_done() >= tx_before + u64::from(n)
        });
        // Where a frame went missing: the counters of both ends and the
        // softnet backlog drops.
        let c = |d: &str, n: &str| ctx.stat(d, n).map_or(-1, |v| v as i64);
        let softnet = std::fs::read_to_string("/proc/net/softnet_stat").unwrap_or_default();
        format!(
            "{e}; can0 tx {} tx_dropped {} rx {} rx_dropped {} rx_over {}; can1 tx {} tx_dropped {} rx {} rx_dropped {} rx_over {}; softnet {:?}{}",
            c("can0", "tx_packets"), c("can0", "tx_dropped"), c("can0", "rx_packets"), c("can0", "rx_dropped"), c("can0", "rx_over_errors"),
            c("can1", "tx_packets"), c("can1", "tx_dropped"), c("can1", "rx_packets"), c("can1", "rx_dropped"), c("can1", "rx_over_errors"),
            softnet.lines().collect::<Vec<_>>(),
            left.err().map(|w| format!(" ({w})")).unwrap_or_default()
        )
    })?;
    let secs = start.elapsed().as_secs_f64();
    ctx.note(format!(
        "burst {what}: {got}/{n} frames in {secs:.1} s ({:.0} frames/s)",
        f64::from(got) / secs
    ));
    Ok(())
}

/// Bursts both ways at 1 Mbit/s (`ip link set canX type can bitrate
/// 1000000`, the simulated bus paces frames by their bits at that rate):
/// every frame arrives, once, in order, intact; nothing dropped, no
/// overrun; the statistics (`ip -s link`) count them. Nothing here
/// depends on the guest's speed: the simulated bus holds a frame while
/// the receiving driver has not read what is in its way (the driver
/// leaves frames in the chip while its queue is full, see i82527.rst),
/// so a receiver whose CPU the host does not schedule for a while loses
/// nothing (before, the bus ran on at the bit rate and the driver's
/// 1,024-frame queue could overflow: `rx_dropped`); the receiver waits up
/// to [`BURST_GAP`] for each frame, and the watchdog bounds the wait for
/// the next [`BURST_HEARTBEAT`] frames, not the whole burst.
fn i82527_burst(ctx: &mut Ctx) -> TestResult {
    let n = burst_len();
    let (i0, i1) = sim2(ctx)?;
    let mut lines = Vec::new();
    for d in ["can0", "can1"] {
        lines.push(vec!["link", "set", d, "down"]);
        lines.push(vec!["link", "set", d, "type", "can", "bitrate", "1000000"]);
        lines.push(vec!["link", "set", d, "up"]);
    }
    super::candev::ip_batch_ok(&lines)?;
    let big = |s: &socketcan::CanSocket| -> TestResult {
        crate::sys::set_rcvbufforce(s, 64 << 20).or_fail("SO_RCVBUFFORCE")
    };
    let tx_before = ctx.stat("can0", "tx_packets")?;
    let rx_before = ctx.stat("can1", "rx_packets")?;
    let (rx1, tx0) = (canraw::open(i1)?, canraw::open(i0)?);
    big(&rx1)?;
    burst_one(ctx, n, &tx0, rx1, "can0->can1")?;
    let sent = ctx.stat("can0", "tx_packets")? - tx_before;
    let got = ctx.stat("can1", "rx_packets")? - rx_before;
    ensure!(
        sent == u64::from(n) && got == u64::from(n),
        "statistics: can0 tx_packets +{sent}, can1 rx_packets +{got}, sent {n}"
    );
    let (rx0, tx1) = (canraw::open(i0)?, canraw::open(i1)?);
    big(&rx0)?;
    burst_one(ctx, n, &tx1, rx0, "can1->can0")?;
    for d in ["can0", "can1"] {
        let over = ctx.stat(d, "rx_over_errors")?;
        ensure!(over == 0, "{d}: {over} message object overruns");
        let dropped = ctx.stat(d, "rx_dropped")?;
        ensure!(dropped == 0, "{d}: {dropped} frames dropped (rx_dropped)");
    }
    Ok(())
}

/// rmmod of the simulated cards while a sender and a receiver are busy:
/// the module goes, their calls fail cleanly, the kernel log stays clean
/// (checked by the VM runner).
fn i82527_rmmod_during_traffic(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = sim2(ctx)?;
    super::rmmod_card_during_traffic(ctx, Module::I82527Sim, i0, i1)
}

/// rcan_i82527_isa where there is no card (QEMU emulates none): loading
/// fails with ENODEV, with or without parameters, leaving no device and
/// no kernel report (checked by the VM runner); the memory region is
/// released (a second attempt fails the same way, not with EBUSY).
fn i82527_isa_no_card(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    for params in [
        &["iomem=0xd0000", "irq=5"][..],
        &["iomem=0xd0000", "irq=5"],
        &[],
    ] {
        let e = ctx
            .insmod(Module::I82527Isa, params)
            .err()
            .ok_or_else(|| format!("rcan_i82527_isa {params:?} loaded without a card"))?;
        ensure!(
            e.contains("No such device"),
            "rcan_i82527_isa {params:?}: {e}, expected ENODEV"
        );
        ensure!(
            !ctx.is_loaded(Module::I82527Isa),
            "rcan_i82527_isa listed after a failed load"
        );
    }
    ensure!(
        !std::path::Path::new("/sys/class/net/can0").exists(),
        "a device appeared"
    );
    Ok(())
}

/// i82527config: shows the setup; publishes an answer that the other card
/// then receives for its remote frame; withdraws it; refuses a bad slot.
fn i82527_config_tool(ctx: &mut Ctx) -> TestResult {
    let (i0, _i1) = sim2(ctx)?;
    let tool = ctx.root().join("target/release/i82527config");
    let tool = tool.to_string_lossy().into_owned();
    let out = tools::run_ok(&tool, &["can1"])?;
    ensure!(
        out.stdout
            .contains("bt0 0x00 bt1 0x2b cpu_if 0x40 (500000 bit/s"),
        "setup not shown: {}",
        out.stdout
    );
    tools::run_ok(&tool, &["can1", "answer", "0", "1ABCDEF0#CAFE"])?;
    let s0 = canraw::open(i0)?;
    canraw::send(&s0, &rtr_ext(0x1ABC_DEF0, 2))?;
    canraw::expect(&s0, &ext(0x1ABC_DEF0, &[0xCA, 0xFE]), "can0")?;
    tools::run_ok(&tool, &["can1", "withdraw", "0"])?;
    canraw::send(&s0, &rtr_ext(0x1ABC_DEF0, 2))?;
    canraw::expect_quiet(&[("can0", &s0)])?;
    let bad = tools::spawn(&tool, &["can1", "answer", "12", "123#00"], None)?
        .finish(tools::TOOL_LIMIT)?;
    ensure!(
        !bad.status.success() && bad.stderr.contains("slot 12"),
        "slot 12: {} {}",
        bad.status,
        bad.stderr
    );
    Ok(())
}
