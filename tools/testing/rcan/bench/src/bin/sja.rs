// SPDX-License-Identifier: GPL-2.0

//! rcan-bench-sja: the SJA1000 section of `make bench`, run inside one VM
//! booted with two QEMU `kvaser_pci` cards on one `can-bus` and QEMU's
//! `memory_region_ops_read/write` trace events on (tools/testing/rcan/
//! bench.sh). For each stack -- mainline `sja1000` + `kvaser_pci` (with
//! can, can-raw, can-dev) and ours (`rcan_kvaser_pci` with rcan_pf,
//! rcan_can, rcan_raw), alternating rounds -- it sends `--frames` 8-byte
//! frames can0 -> can1 over CAN_RAW as fast as the driver takes them and
//! reads them on can1, and prints one line per phase:
//!
//! ```text
//! SJA-PHASE <n> <stack> <round> <frames> <seconds>
//! ```
//!
//! Each phase is bracketed by two reads of PCI configuration registers of
//! the first card that nothing else reads (0x80 opens, 0x84 closes;
//! `SJA-MARKERS` gives the values the kernel writes to QEMU's
//! `pci-conf-idx` port for them). The host counts the trace lines of the
//! cards' regions between the n-th pair of markers: register accesses of
//! both drivers counted by the same emulator code.
//!
//! Interrupts of both cards and this process are on CPU 0, as in the VM
//! burst test: QEMU's bus has no bit timing, so without that the
//! receiver's FIFO overruns and the figures would measure losses.

#[path = "../can.rs"]
#[allow(dead_code)]
mod can;

use can::{Frame, RawSocket};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn run(cmd: &str, args: &[&str]) -> Result<(), String> {
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

fn insmod(p: PathBuf) -> Result<(), String> {
    run("insmod", &[&p.to_string_lossy()])
}

fn loaded(name: &str) -> bool {
    std::fs::read_to_string("/proc/modules")
        .unwrap_or_default()
        .lines()
        .any(|l| l.split_whitespace().next() == Some(name))
}

#[derive(Clone, Copy, PartialEq)]
enum Stack {
    Mainline,
    Ours,
}

const MAINLINE: [&str; 5] = ["kvaser_pci", "sja1000", "can_dev", "can_raw", "can"];
const OURS: [&str; 5] = [
    "rcan_kvaser_pci",
    "rcan_dev",
    "rcan_raw",
    "rcan_can",
    "rcan_pf",
];

fn unload() -> Result<(), String> {
    for m in MAINLINE.iter().chain(&OURS) {
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

fn load(s: Stack, root: &Path, kb: &Path) -> Result<(), String> {
    match s {
        Stack::Mainline => {
            insmod(kb.join("net/can/can.ko"))?;
            insmod(kb.join("net/can/can-raw.ko"))?;
            insmod(kb.join("drivers/net/can/dev/can-dev.ko"))?;
            insmod(kb.join("drivers/net/can/sja1000/sja1000.ko"))?;
            insmod(kb.join("drivers/net/can/sja1000/kvaser_pci.ko"))?;
        }
        Stack::Ours => {
            insmod(root.join("net/can/rcan_pf.ko"))?;
            insmod(root.join("net/can/rcan_can.ko"))?;
            insmod(root.join("net/can/rcan_raw.ko"))?;
            insmod(root.join("drivers/net/can/dev/rcan_dev.ko"))?;
            insmod(root.join("drivers/net/can/sja1000/rcan_kvaser_pci.ko"))?;
        }
    }
    // The same bit timing for both, set as users set it.
    for d in ["can0", "can1"] {
        run(
            "ip",
            &["link", "set", d, "type", "can", "bitrate", "500000"],
        )?;
    }
    for d in ["can0", "can1"] {
        run("ip", &["link", "set", d, "up"])?;
    }
    Ok(())
}

/// Pins every interrupt line serving `dev` to CPU 0.
fn pin_irq(dev: &str) -> Result<(), String> {
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

/// The PCI configuration file of the first Kvaser card and the value the
/// kernel writes to QEMU's `pci-conf-idx` port (0xCF8) to read register
/// `reg` of it.
fn kvaser_config() -> Result<(PathBuf, u32), String> {
    let mut devs: Vec<_> = std::fs::read_dir("/sys/bus/pci/devices")
        .map_err(|e| e.to_string())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    devs.sort();
    for d in devs {
        let rd = |f: &str| std::fs::read_to_string(d.join(f)).unwrap_or_default();
        if rd("vendor").trim() == "0x10e8" && rd("device").trim() == "0x8406" {
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
    Err("no Kvaser PCIcan (10e8:8406) in the VM".into())
}

/// Start and end markers: device-specific configuration registers that
/// neither the drivers nor the PCI core read (the card has no capability
/// list), so the markers are unambiguous.
const MARK_START: u32 = 0x80;
const MARK_END: u32 = 0x84;

/// Reads configuration dword `reg` of the card: one `pci-conf-idx` write
/// in QEMU's trace, a phase marker.
fn marker(config: &PathBuf, reg: u32) -> Result<(), String> {
    use std::os::unix::fs::FileExt;
    let f = std::fs::File::open(config).map_err(|e| format!("{}: {e}", config.display()))?;
    let mut b = [0u8; 4];
    f.read_exact_at(&mut b, reg.into())
        .map_err(|e| format!("{}: {e}", config.display()))?;
    Ok(())
}

fn phase(frames: u32) -> Result<f64, String> {
    let ix0 = can::ifindex("can0").map_err(|e| e.to_string())?;
    let ix1 = can::ifindex("can1").map_err(|e| e.to_string())?;
    let rx = RawSocket::new().map_err(|e| e.to_string())?;
    rx.bind(ix1).map_err(|e| e.to_string())?;
    rx.set_rcvbuf(16 << 20).map_err(|e| e.to_string())?;
    rx.set_rcvtimeo(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    let tx = RawSocket::new().map_err(|e| e.to_string())?;
    tx.bind(ix0).map_err(|e| e.to_string())?;
    let recv = std::thread::spawn(move || -> Result<u32, String> {
        let _ = can::pin_current_thread(0);
        let mut got = 0;
        while got < frames {
            let f = rx.recv(false).map_err(|e| format!("after {got}: {e}"))?;
            if f.seq() != got {
                return Err(format!("frame {got}: seq {}", f.seq()));
            }
            got += 1;
        }
        Ok(got)
    });
    let t = Instant::now();
    for seq in 0..frames {
        can::send_retrying(&tx, &Frame::with_words(0x1234_5678 | 1 << 31, seq, 0x5a5a))
            .map_err(|e| format!("send {seq}: {e}"))?;
    }
    recv.join().map_err(|_| "receiver panicked")??;
    Ok(t.elapsed().as_secs_f64())
}

/// The command line (`bench.sh` passes `--frames 4000 --rounds 3`).
#[derive(clap::Parser, Debug)]
#[command(
    name = "rcan-bench-sja",
    version,
    about = "SJA1000 receive path, ours vs mainline, on two emulated Kvaser cards (run by bench.sh in the VM)",
    long_about = None
)]
struct Cli {
    /// 8-byte frames sent per phase.
    #[arg(long, default_value_t = 5000, value_parser = clap::value_parser!(u32).range(1..))]
    frames: u32,
    /// Rounds; each measures mainline, then ours.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    rounds: u64,
}

fn main() -> std::process::ExitCode {
    // Usage errors exit 2 (clap) before anything is loaded or pinned.
    let cli = <Cli as clap::Parser>::parse();
    match real_main(cli.frames, cli.rounds as usize) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("rcan-bench-sja: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn real_main(frames: u32, rounds: usize) -> Result<(), String> {
    let env = |k: &str| std::env::var_os(k).map(PathBuf::from);
    let root = env("RCAN_ROOT").unwrap_or_else(|| PathBuf::from("."));
    let kb = env("RCAN_KBUILD").ok_or("RCAN_KBUILD not set")?;
    can::pin_current_thread(0).map_err(|e| e.to_string())?;
    let (config, cf8) = kvaser_config()?;
    println!("SJA-MARKERS {:#x} {:#x}", cf8 | MARK_START, cf8 | MARK_END);
    unload()?;
    let mut n = 0;
    for round in 0..rounds {
        for s in [Stack::Mainline, Stack::Ours] {
            load(s, &root, &kb)?;
            pin_irq("can0")?;
            pin_irq("can1")?;
            marker(&config, MARK_START)?;
            let secs = phase(frames);
            marker(&config, MARK_END)?;
            unload()?;
            let secs = secs?;
            let name = if s == Stack::Ours { "ours" } else { "mainline" };
            println!("SJA-PHASE {n} {name} {round} {frames} {secs:.3}");
            n += 1;
        }
    }
    Ok(())
}
