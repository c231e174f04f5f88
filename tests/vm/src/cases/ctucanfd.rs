// SPDX-License-Identifier: GPL-2.0
//! The CTU CAN FD driver (`rcan_ctucanfd_pci`) on QEMU's `ctucan_pci`
//! card: two cores on their own virtual bus (bus1 of RCAN_QEMU_CAN, so the
//! SJA1000 cards on bus0 see none of it), can0 and can1 when only this
//! driver is loaded. Bit timing with `ip link set canX type can bitrate`,
//! classic and CAN FD frames (64 bytes, BRS, ESI) both ways through
//! CAN_RAW sockets, and an rmmod under traffic.
//!
//! QEMU ignores bit timing and has no error frames or fault confinement:
//! those are covered by the host tests of the chip logic
//! (net/can/core/tests/ctucanfd_chip.rs).

use socketcan::id::FdFlags;
use socketcan::{CanAnyFrame, CanFdFrame, CanFdSocket, EmbeddedFrame, ExtendedId, Socket};

use super::candev::ip_ok;
use super::test_table;
use crate::canraw::{self, ext, rtr_ext, rtr_std, std as sff};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::{dev, sized, Ctx, Module};
use crate::tools::{self, TOOL_LIMIT};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    ctucanfd_classic_both_ways,
    ctucanfd_fd_both_ways,
    ctucanfd_burst,
    ctucanfd_cansend_candump,
    ctucanfd_rmmod_during_traffic,
];

/// `CANFD_BRS`, `CANFD_ESI`, `CANFD_FDF` (`<linux/can.h>`).
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;
const CANFD_FDF: u8 = 0x04;

/// Loads the stack and rcan_ctucanfd_pci, sets 500 kbit/s on both cores
/// and brings them up; returns their ifindexes.
fn ctucan2(ctx: &mut Ctx) -> Result<(u32, u32), String> {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Can, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::CtuCanFdPci, &[])?;
    ensure!(
        std::path::Path::new("/sys/class/net/can1").exists(),
        "rcan_ctucanfd_pci found fewer than two cores (is the VM booted with QEMU's ctucan_pci, RCAN_QEMU_CAN?)"
    );
    for i in 0..2 {
        ip_ok(&["link", "set", &dev(i), "type", "can", "bitrate", "500000"])?;
        ctx.link_up(&dev(i))?;
    }
    Ok((ctx.ifindex(&dev(0))?, ctx.ifindex(&dev(1))?))
}

/// Standard, extended and remote frames, DLC 0..8.
fn classic_kinds() -> Vec<socketcan::CanFrame> {
    let mut v = Vec::new();
    for n in 0..=8usize {
        let data: Vec<u8> = (0..n as u8).map(|i| 0xC0 | i).collect();
        v.push(sff(0x100 + n as u16, &data));
        v.push(ext(0x1234_5600 + n as u32, &data));
        v.push(rtr_std(0x7F0 + n as u16, n));
        v.push(rtr_ext(0x1FFF_FF00 + n as u32, n));
    }
    v
}

/// Classic frames of every kind, can0 -> can1 and back, through CAN_RAW
/// sockets.
fn ctucanfd_classic_both_ways(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctucan2(ctx)?;
    let (s0, s1) = (canraw::open(i0)?, canraw::open(i1)?);
    let frames = classic_kinds();
    for f in &frames {
        canraw::send(&s0, f)?;
        canraw::expect(&s1, f, "can1")?;
    }
    for f in &frames {
        canraw::send(&s1, f)?;
        canraw::expect(&s0, f, "can0")?;
    }
    let tx = ctx.stat("can0", "tx_packets")?;
    ensure!(
        tx >= frames.len() as u64,
        "can0 counted {tx} frames sent, {} went",
        frames.len()
    );
    ctx.note(format!("{} frames each way", frames.len()));
    Ok(())
}

/// A CAN_RAW socket with CAN_RAW_FD_FRAMES bound to `ifindex`.
fn fd_open(ifindex: u32) -> Result<CanFdSocket, String> {
    let s = CanFdSocket::open_iface(ifindex)
        .or_fail(format_args!("CanFdSocket bound to ifindex {ifindex}"))?;
    s.set_read_timeout(canraw::RAW_RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")?;
    Ok(s)
}

/// Sends the FD frame `id`, `data`, `flags` on `tx` and expects it,
/// flags included (plus CANFD_FDF), on `rx`.
fn fd_pass(
    tx: &CanFdSocket,
    rx: &CanFdSocket,
    id: u32,
    data: &[u8],
    flags: u8,
    who: &str,
) -> TestResult {
    let eid = ExtendedId::new(id).ok_or("bad id")?;
    let f = CanFdFrame::with_flags(eid, data, FdFlags::from_bits_truncate(flags))
        .ok_or("bad FD frame")?;
    tx.write_frame(&f)
        .or_fail(format_args!("{who}: write FD frame"))?;
    let got = rx
        .read_frame()
        .or_fail(format_args!("{who}: waiting for FD frame {id:08X}"))?;
    let CanAnyFrame::Fd(g) = got else {
        return Err(format!("{who}: expected FD frame {id:08X}, got {got:?}"));
    };
    let raw: &libc::canfd_frame = g.as_ref();
    ensure!(
        raw.can_id == id | libc::CAN_EFF_FLAG && g.data() == data && raw.flags == flags | CANFD_FDF,
        "{who}: expected FD {id:08X} [{}] flags {:#x}, got {:08X} [{}] flags {:#x}",
        data.len(),
        flags | CANFD_FDF,
        raw.can_id,
        g.data().len(),
        raw.flags
    );
    Ok(())
}

/// CAN FD frames of every FD length (0..64 bytes) with each BRS/ESI
/// combination, can0 -> can1 and back.
fn ctucanfd_fd_both_ways(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctucan2(ctx)?;
    let (s0, s1) = (fd_open(i0)?, fd_open(i1)?);
    let lens = [0usize, 1, 7, 8, 12, 16, 20, 24, 32, 48, 64];
    let mut n = 0;
    for (k, &len) in lens.iter().enumerate() {
        let data: Vec<u8> = (0..len).map(|i| (i * 5 + k) as u8).collect();
        for flags in [0, CANFD_BRS, CANFD_ESI, CANFD_BRS | CANFD_ESI] {
            let id = 0x0ABC_0000 | (k as u32) << 4 | u32::from(flags);
            fd_pass(&s0, &s1, id, &data, flags, "can0 -> can1")?;
            fd_pass(&s1, &s0, id | 0x100, &data, flags, "can1 -> can0")?;
            n += 1;
        }
    }
    ctx.note(format!("{n} FD frames each way"));
    Ok(())
}

/// One direction of the burst: `n` numbered 64-byte FD frames with BRS
/// from `tx` to `rx`; every one must arrive once, in order, intact.
fn burst_one(ctx: &Ctx, n: u32, tx: &CanFdSocket, rx: CanFdSocket, what: &str) -> TestResult {
    let start = std::time::Instant::now();
    let recv = std::thread::spawn(move || -> Result<u32, String> {
        for next in 0..n {
            let got = rx
                .read_frame()
                .or_fail(format_args!("waiting for frame {next}"))?;
            let CanAnyFrame::Fd(f) = got else {
                return Err(format!("frame {next}: not an FD frame: {got:?}"));
            };
            let raw: &libc::canfd_frame = f.as_ref();
            let d = f.data();
            let seq = u32::from_le_bytes(d[..4].try_into().unwrap_or([0xFF; 4]));
            ensure!(
                seq == next
                    && raw.can_id == (0x0200_0000 | (next & 0xFFFF)) | libc::CAN_EFF_FLAG
                    && d.len() == 64
                    && d[4..].iter().all(|&b| b == 0xA5)
                    && raw.flags == CANFD_BRS | CANFD_FDF,
                "frame {next}: got id {:#x} seq {seq} len {} flags {:#x}",
                raw.can_id,
                d.len(),
                raw.flags
            );
        }
        Ok(n)
    });
    for seq in 0..n {
        let mut d = [0xA5u8; 64];
        d[..4].copy_from_slice(&seq.to_le_bytes());
        let id = ExtendedId::new(0x0200_0000 | (seq & 0xFFFF)).ok_or("bad id")?;
        let f = CanFdFrame::with_flags(id, &d, FdFlags::BRS).ok_or("bad FD frame")?;
        tx.write_frame(&f)
            .or_fail(format_args!("write frame {seq}"))?;
    }
    let got = recv.join().map_err(|_| "receiver panicked".to_string())??;
    let secs = start.elapsed().as_secs_f64();
    ctx.note(format!(
        "burst {what}: {got}/{n} FD frames in {secs:.1} s ({:.0} frames/s)",
        f64::from(got) / secs
    ));
    Ok(())
}

/// Bursts of numbered 64-byte FD frames both ways (20,000 each on the
/// release kernel, 500 on the debug kernel): every one arrives, once, in
/// order, intact; no overrun. Both cores share the card's interrupt line,
/// so a lost interrupt of one (QEMU's model lets one core's register
/// access drop the other's request) stalls the burst and fails it.
fn ctucanfd_burst(ctx: &mut Ctx) -> TestResult {
    let n = sized("RCAN_CTU_BURST", 20_000, 500);
    let (i0, i1) = ctucan2(ctx)?;
    let big = |s: &CanFdSocket| -> TestResult {
        // Room for the whole burst: the reader is not paced by anything.
        crate::sys::set_rcvbufforce(s, 64 << 20).or_fail("SO_RCVBUFFORCE")
    };
    let (rx1, tx0) = (fd_open(i1)?, fd_open(i0)?);
    big(&rx1)?;
    burst_one(ctx, n, &tx0, rx1, "can0->can1")?;
    let (rx0, tx1) = (fd_open(i0)?, fd_open(i1)?);
    big(&rx0)?;
    burst_one(ctx, n, &tx1, rx0, "can1->can0")?;
    for d in ["can0", "can1"] {
        let over = ctx.stat(d, "rx_over_errors")?;
        ensure!(over == 0, "{d}: {over} RX buffer overruns");
    }
    Ok(())
}

/// can-utils across the bus: `candump -L can1` sees what `cansend can0`
/// sends, a 64-byte FD frame with BRS (`123##1...`) and a classic
/// extended frame (`1ABCDEF0#1122`), as `candump -L` prints them.
fn ctucanfd_cansend_candump(ctx: &mut Ctx) -> TestResult {
    ctucan2(ctx)?;
    let hex: String = (0..64u8)
        .map(|i| format!("{:02X}", i.wrapping_mul(7)))
        .collect();
    let fd_arg = format!("123##1{hex}");
    let mut dump = tools::spawn("candump", &["-L", "-n", "2", "can1"], None)?;
    dump.wait_listening()?;
    tools::run_ok("cansend", &["can0", &fd_arg])?;
    tools::run_ok("cansend", &["can0", "1ABCDEF0#1122"])?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(out.status.success(), "candump: {}", out.stderr.trim());
    let frames: Vec<&str> = out
        .stdout
        .lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .collect();
    ensure!(frames.len() == 2, "candump -L printed {:?}", out.stdout);
    // "123##<flags><hex>": the flags nibble is BRS, plus FDF on newer
    // can-utils.
    let (id, fd) = frames[0]
        .split_once("##")
        .ok_or_else(|| format!("candump -L shows no FD frame: {:?}", frames[0]))?;
    let flags = u8::from_str_radix(&fd[..1], 16).map_err(|_| format!("flags in {fd:?}"))?;
    ensure!(
        id == "123" && flags & (CANFD_BRS | CANFD_ESI) == CANFD_BRS && fd[1..] == hex,
        "candump -L printed {:?}, expected 123##1{hex}",
        frames[0]
    );
    ensure!(
        frames[1] == "1ABCDEF0#1122",
        "candump -L printed {:?}, expected 1ABCDEF0#1122",
        frames[1]
    );
    Ok(())
}

/// rmmod of the driver while a sender and a receiver are busy on its
/// interfaces: the module goes, their calls fail cleanly, the kernel log
/// stays clean (checked by the VM runner).
fn ctucanfd_rmmod_during_traffic(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = ctucan2(ctx)?;
    super::rmmod_card_during_traffic(ctx, Module::CtuCanFdPci, i0, i1)
}
