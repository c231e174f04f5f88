// SPDX-License-Identifier: GPL-2.0
//! What the emulated-card sections of `make bench` share (`rcan-bench-sja`
//! on two Kvaser PCIcan cards, `rcan-bench-ctu` on the two cores of a CTU
//! CAN FD card): loading and unloading module sets, pinning a device's
//! interrupt, the phase markers in QEMU's trace, and one phase: frames
//! sent can0 -> can1 over CAN_RAW as fast as the driver takes them.
//!
//! Each phase is bracketed by two reads of PCI configuration registers of
//! the card that nothing else reads (0x80 opens, 0x84 closes; the
//! `*-MARKERS` line gives the values the kernel writes to QEMU's
//! `pci-conf-idx` port for them). The host counts the trace lines of the
//! card's regions between the n-th pair of markers (sja-count.awk):
//! register accesses of both drivers counted by the same emulator code.

use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use crate::can::{self, Frame, RawSocket, Shape};

/// Runs a command; fails on a non-zero exit status.
pub fn run(cmd: &str, args: &[&str]) -> Result<(), String> {
    let out = Command::new(cmd)
        .args(args)
        .output()
        .map_err(|e| format!("{cmd}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "{cmd} {}: {}: {}",
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

pub fn insmod(p: PathBuf) -> Result<(), String> {
    run("insmod", &[&p.to_string_lossy()])
}

/// The stack a card section measures.
#[derive(Clone, Copy, PartialEq)]
pub enum Stack {
    /// Mainline's CAN core, CAN_RAW, can-dev and the card's driver.
    Mainline,
    /// Ours.
    Ours,
}

/// Loads a stack for a card: the CAN core, CAN_RAW and the device layer
/// (mainline's from the kernel build `kb`, ours from our tree `root`),
/// then the card's driver modules (`mainline` or `ours`, paths relative to
/// the same place); sets `ip link set canX type can <timing>` on can0 and
/// can1, the same for both stacks, as users set it, and brings them up.
pub fn load(
    s: Stack,
    root: &Path,
    kb: &Path,
    mainline: &[&str],
    ours: &[&str],
    timing: &[&str],
) -> Result<(), String> {
    let (base, core, drivers): (&Path, [&str; 4], &[&str]) = match s {
        Stack::Mainline => (
            kb,
            [
                "net/can/can.ko",
                "net/can/can-raw.ko",
                "drivers/net/can/dev/can-dev.ko",
                "",
            ],
            mainline,
        ),
        Stack::Ours => (
            root,
            [
                "net/can/rcan_pf.ko",
                "net/can/rcan_can.ko",
                "net/can/rcan_raw.ko",
                "drivers/net/can/dev/rcan_dev.ko",
            ],
            ours,
        ),
    };
    for m in core.iter().filter(|m| !m.is_empty()).chain(drivers) {
        insmod(base.join(m))?;
    }
    for d in ["can0", "can1"] {
        let mut args = vec!["link", "set", d, "type", "can"];
        args.extend_from_slice(timing);
        run("ip", &args)?;
    }
    for d in ["can0", "can1"] {
        run("ip", &["link", "set", d, "up"])?;
    }
    Ok(())
}

fn loaded(name: &str) -> bool {
    std::fs::read_to_string("/proc/modules")
        .unwrap_or_default()
        .lines()
        .any(|l| l.split_whitespace().next() == Some(name))
}

/// Removes every loaded module of `names` (users first), retrying for a
/// few seconds each.
pub fn unload(names: &[&str]) -> Result<(), String> {
    for m in names {
        for _ in 0..30 {
            if !loaded(m) || run("rmmod", &[m]).is_ok() {
                break;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        if loaded(m) {
            return Err(format!("{m} does not unload"));
        }
    }
    Ok(())
}

/// Pins every interrupt line serving `dev` to CPU 0.
pub fn pin_irq(dev: &str) -> Result<(), String> {
    let text = std::fs::read_to_string("/proc/interrupts").map_err(|e| e.to_string())?;
    let mut found = false;
    for l in text.lines() {
        let Some((irq, rest)) = l.split_once(':') else {
            continue;
        };
        if rest
            .split(|c: char| c.is_whitespace() || c == ',')
            .any(|t| t == dev)
        {
            std::fs::write(format!("/proc/irq/{}/smp_affinity", irq.trim()), "1")
                .map_err(|e| format!("pin irq {irq}: {e}"))?;
            found = true;
        }
    }
    if found {
        Ok(())
    } else {
        Err(format!("no interrupt line for {dev}"))
    }
}

/// The PCI configuration file of the first card `vendor:device` and the
/// value the kernel writes to QEMU's `pci-conf-idx` port (0xCF8) to read
/// register 0 of it.
pub fn pci_config(vendor: u16, device: u16) -> Result<(PathBuf, u32), String> {
    let mut devs: Vec<_> = std::fs::read_dir("/sys/bus/pci/devices")
        .map_err(|e| e.to_string())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    devs.sort();
    let hex = |v: u16| format!("{v:#06x}");
    for d in devs {
        let rd = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
        if rd("vendor").trim() == hex(vendor) && rd("device").trim() == hex(device) {
            // "0000:00:03.0"
            let name = d
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let p: Vec<&str> = name.split([':', '.']).collect();
            let num = |s: &str| u32::from_str_radix(s, 16).map_err(|e| format!("{name}: {e}"));
            let (bus, dev, func) = (num(p[1])?, num(p[2])?, num(p[3])?);
            return Ok((
                d.join("config"),
                0x8000_0000 | bus << 16 | dev << 11 | func << 8,
            ));
        }
    }
    Err(format!("no PCI device {vendor:04x}:{device:04x} in the VM"))
}

/// Start and end markers: device-specific configuration registers that
/// neither the drivers nor the PCI core read (the cards have no
/// capability list), so the markers are unambiguous.
pub const MARK_START: u32 = 0x80;
pub const MARK_END: u32 = 0x84;

/// Reads configuration dword `reg` of the card: one `pci-conf-idx` write
/// in QEMU's trace, a phase marker.
pub fn marker(config: &Path, reg: u32) -> Result<(), String> {
    let f = std::fs::File::open(config).map_err(|e| format!("{}: {e}", config.display()))?;
    let mut b = [0u8; 4];
    f.read_exact_at(&mut b, reg.into())
        .map_err(|e| format!("{}: {e}", config.display()))?;
    Ok(())
}

/// One phase: `frames` frames of `shape` with `id`, numbered, sent on can0
/// as fast as the driver takes them (retrying while its queue pushes
/// back) and read in order on can1 by a thread on CPU 0. Both sockets have
/// `CAN_RAW_FD_FRAMES` for an FD shape. Returns the seconds it took.
pub fn phase(frames: u32, shape: Shape, id: u32) -> Result<f64, String> {
    let ix0 = can::ifindex("can0").map_err(|e| e.to_string())?;
    let ix1 = can::ifindex("can1").map_err(|e| e.to_string())?;
    let rx = RawSocket::new().map_err(|e| e.to_string())?;
    rx.bind(ix1).map_err(|e| e.to_string())?;
    rx.set_rcvbuf(16 << 20).map_err(|e| e.to_string())?;
    rx.set_rcvtimeo(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    let tx = RawSocket::new().map_err(|e| e.to_string())?;
    tx.bind(ix0).map_err(|e| e.to_string())?;
    if shape.fd.is_some() {
        rx.set_fd_frames(true).map_err(|e| e.to_string())?;
        tx.set_fd_frames(true).map_err(|e| e.to_string())?;
    }
    let recv = std::thread::spawn(move || -> Result<u32, String> {
        let _ = can::pin_current_thread(0);
        let mut got = 0;
        while got < frames {
            let f = rx.recv(false).map_err(|e| format!("after {got}: {e}"))?;
            if f.seq() != got || f.shape() != shape {
                // Evidence: the sequence numbers of what comes next.
                let mut next = vec![f.seq()];
                rx.set_rcvtimeo(Duration::from_secs(1))
                    .map_err(|e| e.to_string())?;
                while next.len() < 16 {
                    match rx.recv(false) {
                        Ok(g) => next.push(g.seq()),
                        Err(_) => break,
                    }
                }
                return Err(format!(
                    "frame {got}: seq {}, shape {:?}; seqs received from there: {next:?}",
                    f.seq(),
                    f.shape()
                ));
            }
            got += 1;
        }
        Ok(got)
    });
    let t = Instant::now();
    for seq in 0..frames {
        can::send_retrying(&tx, &Frame::shaped(id, seq, 0x5a5a, shape))
            .map_err(|e| format!("send {seq}: {e}"))?;
    }
    recv.join().map_err(|_| "receiver panicked")??;
    Ok(t.elapsed().as_secs_f64())
}
