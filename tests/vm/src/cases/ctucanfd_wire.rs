// SPDX-License-Identifier: GPL-2.0
//! The wire-peer test of the CTU CAN FD driver (issue 14, item 5): our
//! `rcan_ctucanfd_pci` on one QEMU `ctucan_pci` card and mainline's
//! `ctucanfd` + `ctucanfd_pci` on the second, both cards on QEMU's bus1
//! (`RCAN_QEMU_CAN`), in one boot. What one driver writes into its
//! card's TX buffers the other must read from its RX buffer, byte for
//! byte: classic and CAN FD frames, BRS, 64-byte payloads, both ways.
//!
//! Two stacks in one kernel, and what each may own:
//!
//! * The "can" link kind: mainline's `ctucanfd` needs mainline's
//!   `can-dev`, which registers it, so `rcan_dev` is loaded with
//!   `rtnl_link=0` and our cores get their bit timing from
//!   `rcan_ctucanfd_pci bitrate= dbitrate=` (FD on with `ip link set
//!   canX mtu 72`); `ip link set canX type can ...` on ours is refused
//!   with `EOPNOTSUPP` (rtnetlink compares mainline's kind with our
//!   device's ops and never calls mainline's `can_changelink` on it).
//! * PF_CAN (family 29): only one `can.ko` / `rcan_pf` can hold it. The
//!   mainline side therefore loads no PF_CAN at all (`can-dev` and the
//!   driver do not need it), and the wire peer is driven by *our* CAN_RAW
//!   sockets on mainline's interface: our pf_can serves every ARPHRD_CAN
//!   device, and mainline's can-dev devices take our skbs (mainline's
//!   canonical layout with `struct can_skb_priv`) and hand theirs up the
//!   same way. An AF_PACKET socket on mainline's interface would also
//!   work, but would test less: this way mainline's driver meets our
//!   stack on its send and receive paths too (its echo included), which
//!   is itself an interoperability statement. What crosses the wire is
//!   still produced and decoded by mainline's driver alone.
//!
//! The cards are split with sysfs `driver_override` (both drivers match
//! 1760:ff00): the first card in PCI order to `rcan_ctucanfd_pci`, the
//! second to `ctucanfd_pci`, set before either module loads and put back
//! when the test ends (also on failure). Every other test sees the first
//! card only: [`park_spare_ctucan_cards`], called once when rcan-vmtest
//! starts, overrides the second card to [`PARKED`], a driver name no
//! module has, and this test parks it again when it ends. (Each load of
//! a CTU CAN FD driver probing four cores instead of two cost every CTU
//! test 3-5 s on the debug kernel, and `modules_load_unload_cycles` 9 s
//! on the release kernel.) Interface names are taken from what each load
//! adds.
//!
//! Pacing: every frame is sent and awaited before the next (one frame in
//! flight), a rate mainline's driver sustains on QEMU's card; the test
//! asserts no loss there. Mainline's `ctucanfd` loses frames on QEMU's
//! card under load (ctucanfd.rst, "Wire peer"): a short unpaced burst
//! each way counts the loss and reports it (in the test's note), without
//! asserting on it.
//!
//! Ours only (not portable): it is the two stacks side by side. It runs on
//! both kernels (release-only until 2026-12-01, see `RELEASE_ONLY`).

use socketcan::id::FdFlags;
use socketcan::{CanAnyFrame, CanFdFrame, CanFdSocket, EmbeddedFrame, ExtendedId, Socket};

use super::candev::ip_ok;
use super::ctucanfd::{classic_kinds, fd_cross, fd_open, ip_fails, json_has};
use super::test_table;
use crate::canraw;
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::{sized, Ctx, Mainline, Module};
use crate::Test;

pub const TESTS: &[Test] = test_table![ctucanfd_bitrate_params, ctucanfd_wire_peer_mainline];

/// `CANFD_BRS`, `CANFD_ESI`, `CANFD_FDF` (`<linux/can.h>`).
const CANFD_BRS: u8 = 0x01;
const CANFD_ESI: u8 = 0x02;
const CANFD_FDF: u8 = 0x04;

/// The bit rates both sides use (QEMU's bus ignores them; they are what
/// a user would set on a real bus: the same on every node).
const BITRATE: &str = "1000000";
const DBITRATE: &str = "4000000";

/// The PCI addresses of QEMU's `ctucan_pci` cards (1760:ff00), in PCI
/// order.
fn ctucan_pci_cards() -> Result<Vec<String>, String> {
    crate::ctx::pci_devices(&[(0x1760, 0xff00)])
}

/// The `driver_override` of the spare `ctucan_pci` cards between tests:
/// a name no driver has, so neither `rcan_ctucanfd_pci` nor mainline's
/// `ctucanfd_pci` binds them (sysfs `driver_override`, "only a driver of
/// that name may bind").
pub const PARKED: &str = "rcan_vmtest_parked";

/// Parks every `ctucan_pci` card but the first ([`PARKED`]), so the CTU
/// CAN FD tests (ours and mainline's) probe the two cores can0/can1 of
/// the first card only. Called once when rcan-vmtest starts, before any
/// module is loaded; a VM without the cards is left alone.
pub fn park_spare_ctucan_cards() -> TestResult {
    for addr in ctucan_pci_cards()?.iter().skip(1) {
        let p = format!("/sys/bus/pci/devices/{addr}/driver_override");
        std::fs::write(&p, PARKED).map_err(|e| format!("echo {PARKED} > {p}: {e}"))?;
    }
    Ok(())
}

/// `echo DRIVER > /sys/bus/pci/devices/ADDR/driver_override` for each
/// card; dropping it puts back what each had (an empty write for none),
/// whatever the test's outcome.
pub(super) struct Overrides(Vec<(String, String)>);

impl Overrides {
    pub(super) fn set(pairs: &[(&str, &str)]) -> Result<Overrides, String> {
        let mut o = Overrides(Vec::new());
        for (addr, drv) in pairs {
            let p = format!("/sys/bus/pci/devices/{addr}/driver_override");
            // Reads "(null)" when no override is set.
            let was = std::fs::read_to_string(&p).or_fail(&p)?;
            let was = match was.trim() {
                "(null)" | "" => "\n".to_string(),
                w => w.to_string(),
            };
            std::fs::write(&p, drv).map_err(|e| format!("echo {drv} > {p}: {e}"))?;
            o.0.push((p, was));
        }
        Ok(o)
    }
}

impl Drop for Overrides {
    fn drop(&mut self) {
        for (p, was) in &self.0 {
            let _ = std::fs::write(p, was);
        }
    }
}

/// The canN interfaces there are now, sorted.
fn can_names() -> Result<Vec<String>, String> {
    let dir = "/sys/class/net";
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .or_fail(dir)?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("can"))
        .collect();
    v.sort();
    Ok(v)
}

/// Runs `load` and returns the canN interfaces it added (at least one).
fn added(who: &str, load: impl FnOnce() -> TestResult) -> Result<Vec<String>, String> {
    let before = can_names()?;
    load()?;
    let new: Vec<String> = can_names()?
        .into_iter()
        .filter(|n| !before.contains(n))
        .collect();
    ensure!(!new.is_empty(), "{who} made no CAN interface");
    Ok(new)
}

/// Reads one classic frame and compares it with `want`, all 16 bytes
/// (shown in hex on a difference); of a remote frame, whose data is not
/// on the wire, only the id and the length. Mainline's `ctucanfd` copies
/// the data words the RX buffer has for a remote frame (RWCNT counts the
/// DLC's words), and QEMU's model fills them with whatever the sender's
/// TX buffer held from an earlier frame (neither driver writes data words
/// for a remote frame): a remote frame from either driver can reach
/// mainline's sockets with stale bytes in `data`. Ours zeroes them.
fn classic_expect(s: &socketcan::CanSocket, want: &socketcan::CanFrame, who: &str) -> TestResult {
    let got =
        canraw::recv(s).map_err(|e| format!("{who}: waiting for {}: {e}", canraw::show(want)))?;
    let (g, w) = (canraw::wire(&got), canraw::wire(want));
    let rtr = u32::from_ne_bytes([w[0], w[1], w[2], w[3]]) & libc::CAN_RTR_FLAG != 0;
    let n = if rtr { 8 } else { g.len() };
    ensure!(g[..n] == w[..n], "{who}: expected {w:02X?}, got {g:02X?}");
    Ok(())
}

/// The payload lengths of the 16 FD length codes (DLC 0..15).
const FD_LENS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// Every FD length code with flags none, BRS, ESI and BRS|ESI, from `tx`
/// to `rx`; `esi_arrives`: whether ESI crosses (our driver writes it into
/// the TX buffer and QEMU's model carries it; mainline's does not
/// transmit it, though it reports a received one). Returns the count.
fn fd_all(
    tx: &CanFdSocket,
    rx: &CanFdSocket,
    base: u32,
    esi_arrives: bool,
    who: &str,
) -> Result<usize, String> {
    let mut n = 0;
    for (dlc, &len) in FD_LENS.iter().enumerate() {
        for flags in [0, CANFD_BRS, CANFD_ESI, CANFD_BRS | CANFD_ESI] {
            let data: Vec<u8> = (0..len)
                .map(|i| (i as u8).wrapping_mul(31) ^ (dlc as u8) << 4 ^ flags)
                .collect();
            let want = if esi_arrives {
                flags
            } else {
                flags & !CANFD_ESI
            };
            let id = base | (dlc as u32) << 4 | u32::from(flags);
            fd_cross(tx, rx, id, &data, flags, want, who)?;
            n += 1;
        }
    }
    Ok(n)
}

/// How long the burst's writer waits for its transmit queue to take a
/// frame before it calls the queue stalled: a hang bound, not a speed
/// limit (a run of 2026-12-01 blocked in `sendto` until the runner's
/// watchdog ended the test, build.rst).
const TX_STALL: std::time::Duration = std::time::Duration::from_secs(20);

/// How long [`echo_count`] waits for the next echo.
const ECHO_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Reads the echoes of an unpaced burst (identifiers `base | seq`, see
/// [`burst_count`]) from `mon`, a socket on the sending device opened
/// before the burst, until `n` came or none for [`ECHO_WAIT`]; returns
/// how many came. Anything else on `mon` is an error.
fn echo_count(mon: &CanFdSocket, base: u32, n: u32) -> Result<u32, String> {
    mon.set_read_timeout(ECHO_WAIT).or_fail("SO_RCVTIMEO")?;
    let mut got = 0;
    while got < n {
        let Ok(f) = mon.read_frame() else { break };
        let CanAnyFrame::Fd(f) = f else {
            return Err(format!("echoes: not an FD frame: {f:?}"));
        };
        let raw: &libc::canfd_frame = f.as_ref();
        ensure!(
            raw.can_id & 0x1FFF_0000 == base,
            "echoes: frame {:#x} on the sending device",
            raw.can_id
        );
        got += 1;
    }
    Ok(got)
}

/// An unpaced burst of `n` numbered 64-byte BRS frames from `tx` to
/// `rx` (the writer does not wait for the reader, only for room in the
/// TX queue): how many arrived, whether those that did came in order and
/// intact (an `Err` if not), and the frame the writer stopped at if the
/// transmit queue took none for [`TX_STALL`] (`None`: all were written).
/// The reader stops at the last number or after a second of silence.
fn burst_count(
    tx: &CanFdSocket,
    rx: CanFdSocket,
    n: u32,
    base: u32,
) -> Result<(u32, Option<u32>), String> {
    tx.set_write_timeout(TX_STALL).or_fail("SO_SNDTIMEO")?;
    rx.set_read_timeout(std::time::Duration::from_secs(1))
        .or_fail("SO_RCVTIMEO")?;
    let recv = std::thread::spawn(move || -> Result<u32, String> {
        let (mut got, mut last) = (0u32, None::<u32>);
        while let Ok(f) = rx.read_frame() {
            let CanAnyFrame::Fd(f) = f else {
                return Err(format!("burst: not an FD frame: {f:?}"));
            };
            let d = f.data();
            let seq = u32::from_le_bytes(d[..4].try_into().unwrap_or([0xFF; 4]));
            let raw: &libc::canfd_frame = f.as_ref();
            ensure!(
                last.map_or(true, |l| seq > l)
                    && raw.can_id == (base | (seq & 0xFFFF)) | libc::CAN_EFF_FLAG
                    && d.len() == 64
                    && d[4..].iter().all(|&b| b == 0x5A)
                    && raw.flags == CANFD_BRS | CANFD_FDF,
                "burst: frame {seq} after {last:?}: id {:#x} len {} flags {:#x} data {}",
                raw.can_id,
                d.len(),
                raw.flags,
                d.iter().map(|b| format!("{b:02x}")).collect::<String>()
            );
            got += 1;
            last = Some(seq);
            if seq + 1 == n {
                break;
            }
        }
        Ok(got)
    });
    let mut stalled = None;
    let mut progress = std::time::Instant::now();
    'send: for seq in 0..n {
        let mut d = [0x5Au8; 64];
        d[..4].copy_from_slice(&seq.to_le_bytes());
        let id = ExtendedId::new(base | (seq & 0xFFFF)).ok_or("bad id")?;
        let f = CanFdFrame::with_flags(id, &d, FdFlags::BRS).ok_or("bad FD frame")?;
        // A full TX queue (mainline's can-dev devices: txqueuelen 10)
        // answers ENOBUFS: wait a little and write again, as `cangen -p`
        // (a back-off, not synchronisation: no event says the queue has
        // room).
        loop {
            match tx.write_frame(&f) {
                Ok(()) => {
                    progress = std::time::Instant::now();
                    break;
                }
                Err(e) if e.raw_os_error() == Some(libc::ENOBUFS) => {
                    if progress.elapsed() > TX_STALL {
                        stalled = Some(seq);
                        break 'send;
                    }
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
                // SO_SNDTIMEO ran out: the socket's buffer stayed full.
                Err(e) if e.raw_os_error() == Some(libc::EAGAIN) => {
                    stalled = Some(seq);
                    break 'send;
                }
                Err(e) => return Err(format!("burst: write frame {seq}: {e}")),
            }
        }
    }
    let got = recv
        .join()
        .map_err(|_| "burst receiver panicked".to_string())??;
    Ok((got, stalled))
}

/// Ours and mainline's CTU CAN FD drivers on two cards of one bus, see
/// the module's doc: `rcan_dev rtnl_link=0` and mainline's can-dev both
/// loaded; `ip link set canX type can` refused on ours with EOPNOTSUPP,
/// its module-parameter bit timing shown by `ip -d`; then, one frame in
/// flight, ours -> mainline and mainline -> ours: classic frames (std and
/// ext ids, data 0..8 bytes, RTR), every FD length code with and without
/// BRS and ESI (ESI as the chips carry it), checked byte for byte; then
/// an unpaced burst each way, whose loss is counted and reported.
fn ctucanfd_wire_peer_mainline(ctx: &mut Ctx) -> TestResult {
    let cards = ctucan_pci_cards()?;
    ensure!(
        cards.len() >= 2,
        "fewer than two ctucan_pci cards ({cards:?}): is the VM booted with RCAN_QEMU_CAN?"
    );
    let ko = |m: Mainline| {
        ctx.mainline_ko(m)
            .ok_or("no kernel build directory (RCAN_KBUILD): mainline's ctucanfd is needed")
    };
    let mainline_kos = [
        ko(Mainline::Dev)?,
        ko(Mainline::CtuCanFd)?,
        ko(Mainline::CtuCanFdPci)?,
    ];
    let _ovr = Overrides::set(&[
        (&cards[0], "rcan_ctucanfd_pci"),
        (&cards[1], "ctucanfd_pci"),
    ])?;

    // Ours: PF_CAN, CAN_RAW, the device layer without the link kind, and
    // the driver with its bit timing from module parameters.
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::Dev, &["rtnl_link=0"])?;
    let bitrate = format!("bitrate={BITRATE}");
    let dbitrate = format!("dbitrate={DBITRATE}");
    let ours = added("rcan_ctucanfd_pci", || {
        ctx.insmod(Module::CtuCanFdPci, &[&bitrate, &dbitrate])
    })?;
    // Mainline: can-dev (the "can" link kind), ctucanfd, ctucanfd_pci.
    let theirs = added("mainline ctucanfd_pci", || {
        for k in &mainline_kos {
            crate::sys::finit_module(k, &[]).map_err(|e| format!("insmod {}: {e}", k.display()))?;
        }
        Ok(())
    })?;
    let (a, b) = (ours[0].as_str(), theirs[0].as_str());
    ctx.note(format!(
        "ours {ours:?} on {}, mainline {theirs:?} on {}",
        cards[0], cards[1]
    ));

    // The kind is mainline's now: on our device it is refused, and our
    // own view of the settings (the preset) still shows.
    ip_fails(
        &["link", "set", a, "type", "can", "bitrate", "500000"],
        "Operation not supported",
    )?;
    json_has(a, &[r#""bitrate":1000000"#, r#""bitrate":4000000"#], &[])?;
    ip_ok(&["link", "set", a, "mtu", "72"])?;
    ctx.link_up(a)?;
    ip_ok(&[
        "link", "set", b, "type", "can", "bitrate", BITRATE, "dbitrate", DBITRATE, "fd", "on",
    ])?;
    ctx.link_up(b)?;
    let (ia, ib) = (ctx.ifindex(a)?, ctx.ifindex(b)?);

    // Classic frames, through classic CAN_RAW sockets. A CAN_RAW socket
    // also gets the frames other sockets of its interface sent, once the
    // driver reports them sent (the echo): the FD sockets opened below
    // would see a classic frame whose echo a loaded guest delivers after
    // the frame itself reached the other end (seen: mainline's echo of
    // the last one, 2026-11-28). So a monitor on each end counts what
    // the end saw, both ways, before the FD sockets open.
    {
        let (sa, sb) = (canraw::open(ia)?, canraw::open(ib)?);
        let (ma, mb) = (canraw::open(ia)?, canraw::open(ib)?);
        let frames = classic_kinds();
        for f in &frames {
            canraw::send(&sa, f)?;
            classic_expect(&sb, f, &format!("ours {a} -> mainline {b}"))?;
        }
        for f in &frames {
            canraw::send(&sb, f)?;
            classic_expect(&sa, f, &format!("mainline {b} -> ours {a}"))?;
        }
        for (m, d) in [(&ma, a), (&mb, b)] {
            for i in 0..2 * frames.len() {
                canraw::recv(m).map_err(|e| {
                    format!("{d}: {i} of the classic frames and their echoes, then: {e}")
                })?;
            }
        }
        ctx.note(format!("{} classic frames each way", frames.len()));
    }

    // FD frames, every length code, BRS and ESI; monitors as above, for
    // the burst's sockets.
    let (fa, fb) = (fd_open(ia)?, fd_open(ib)?);
    let (ma, mb) = (fd_open(ia)?, fd_open(ib)?);
    let n1 = fd_all(
        &fa,
        &fb,
        0x0A00_0000,
        true,
        &format!("ours {a} -> mainline {b}"),
    )?;
    let n2 = fd_all(
        &fb,
        &fa,
        0x0B00_0000,
        false,
        &format!("mainline {b} -> ours {a}"),
    )?;
    ctx.note(format!(
        "{n1} FD frames ours -> mainline, {n2} mainline -> ours (ESI arrives only from ours)"
    ));
    for (m, d) in [(&ma, a), (&mb, b)] {
        for i in 0..n1 + n2 {
            m.read_frame()
                .map_err(|e| format!("{d}: {i} of the FD frames and their echoes, then: {e}"))?;
        }
    }
    drop((ma, mb));

    // Unpaced: count, report, do not assert on loss.
    let n = sized("RCAN_CTU_WIRE_BURST", 2000, 100);
    let big = |s: CanFdSocket| -> Result<CanFdSocket, String> {
        // Room for the whole burst: only the drivers may lose frames.
        crate::sys::set_rcvbufforce(&s, 64 << 20).or_fail("SO_RCVBUFFORCE")?;
        Ok(s)
    };
    let over = |d: &str| ctx.stat(d, "rx_over_errors");
    let (ob, oa) = (over(b)?, over(a)?);
    // Our echoes of the burst, on a socket of our own device opened
    // before it: each frame sent comes back there (its echo, in our NAPI
    // poll) or is counted in rx_dropped (the poll's queue was full).
    let echo_mon = big(fd_open(ia)?)?;
    let dropped_a = ctx.stat(a, "rx_dropped")?;
    let (got_ab, stall_ab) = burst_count(&fa, big(fd_open(ib)?)?, n, 0x0C00_0000)?;
    // Our driver's transmit queue must keep draining; mainline's stall
    // is reported, as its losses are.
    if let Some(k) = stall_ab {
        return Err(format!(
            "unpaced burst ours -> mainline: our {a}'s transmit queue took no frame for {TX_STALL:?} \
             after {k} of {n} ({got_ab} arrived)"
        ));
    }
    // Every echo delivered or counted before the next burst's socket
    // opens on the same device (it would get the late ones).
    let echoed = echo_count(&echo_mon, 0x0C00_0000, n)?;
    let dropped = ctx.stat(a, "rx_dropped")? - dropped_a;
    ensure!(
        u64::from(echoed) + dropped >= u64::from(n),
        "unpaced burst ours -> mainline: our {a} delivered {echoed} of the {n} echoes and dropped \
         {dropped}: the rest did not come within {ECHO_WAIT:?} of the last"
    );
    drop(echo_mon);
    let ob2 = over(b)?;
    let (got_ba, stall_ba) = burst_count(&fb, big(fd_open(ia)?)?, n, 0x0D00_0000)?;
    if let Some(k) = stall_ba {
        ctx.note(format!(
            "unpaced burst mainline -> ours: mainline's {b} took no frame for {TX_STALL:?} after \
             {k} of {n}: written {k}"
        ));
    }
    let oa2 = over(a)?;
    let dropped_ba = ctx.stat(a, "rx_dropped")? - dropped_a - dropped;
    ctx.note(format!(
        "unpaced burst of {n} 64-byte BRS frames: ours -> mainline {got_ab} arrived ({} lost, \
         {} RX overruns on mainline's {b}; {echoed} echoes on our {a}, {dropped} dropped); \
         mainline -> ours {got_ba} arrived ({} lost, {} RX overruns and {dropped_ba} dropped \
         on our {a})",
        n - got_ab,
        ob2 - ob,
        n - got_ba,
        oa2 - oa
    ));
    Ok(())
}

/// `rcan_ctucanfd_pci bitrate= dbitrate=`: values no bit timing meets
/// (`bitrate=7`), `dbitrate` without `bitrate` or below it refuse the
/// load with EINVAL and a kernel log line naming the parameter; good ones
/// (with the link kind registered as usual) give every core that timing,
/// as `ip -d` shows it (the same as `ip ... bitrate 500000 dbitrate
/// 2000000` computes), a log line per core, and `up` needs no `ip ...
/// type can`; `mtu 72` turns CAN FD on with the preset data timing.
fn ctucanfd_bitrate_params(ctx: &mut Ctx) -> TestResult {
    ctx.insmod(Module::Pf, &[])?;
    ctx.insmod(Module::Raw, &[])?;
    ctx.insmod(Module::Dev, &[])?;
    for (params, why) in [
        (&["bitrate=7"][..], "bitrate:"),
        (&["dbitrate=2000000"][..], "dbitrate:"),
        (&["bitrate=1000000", "dbitrate=500000"][..], "dbitrate:"),
    ] {
        let mut kmsg = ctx.kmsg()?;
        let err = match ctx.insmod(Module::CtuCanFdPci, params) {
            Ok(()) => return Err(format!("rcan_ctucanfd_pci {params:?} loaded")),
            Err(e) => e,
        };
        ensure!(
            err.contains("Invalid argument"),
            "{params:?}: not EINVAL: {err}"
        );
        let log = kmsg.read_new()?;
        ensure!(
            log.iter().any(|l| l.contains("rcan_ctucanfd_pci")
                && l.contains("refused")
                && l.contains(why)),
            "{params:?}: no kernel log line naming {why:?}: {log:?}"
        );
    }
    let mut kmsg = ctx.kmsg()?;
    ctx.insmod(Module::CtuCanFdPci, &["bitrate=500000", "dbitrate=2000000"])?;
    let log = kmsg.read_new()?;
    ensure!(
        log.iter().any(|l| l
            .contains("can0: bit timing from module parameters: bitrate 500000, dbitrate 2000000")),
        "no log line for can0's preset: {log:?}"
    );
    json_has(
        "can0",
        &[
            r#""bittiming":{"bitrate":500000,"#,
            r#""data_bittiming":{"bitrate":2000000,"sample_point":"0.740""#,
        ],
        &[r#""ctrlmode":["FD"#],
    )?;
    ctx.link_up("can0")?;
    ctx.link_down("can0")?;
    ip_ok(&["link", "set", "can0", "mtu", "72"])?;
    ctx.link_up("can0")?;
    json_has("can0", &[r#""mtu":72"#, r#""ctrlmode":["FD"]"#], &[])?;
    Ok(())
}
