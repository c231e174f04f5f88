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
//! With `RCAN_BENCH_SJA_BEFORE_KO` set to another build of
//! `rcan_kvaser_pci.ko` (say, of the commit before a change to the driver
//! or the glue), the rounds compare that module with ours instead of
//! mainline with ours, on the same core modules (ours): phases named
//! `before` and `ours`. Under `RCAN_KVM=icount` the seconds are guest
//! instructions (one nanosecond each), so the two figures give the
//! change's instructions per frame.
//!
//! Interrupts of both cards and this process are on CPU 0, as in the VM
//! burst test: QEMU's bus has no bit timing, so without that the
//! receiver's FIFO overruns and the figures would measure losses.

#[path = "../can.rs"]
#[allow(dead_code)]
mod can;
#[path = "../card.rs"]
mod card;

use card::{marker, phase, pin_irq, Stack, MARK_END, MARK_START};
use std::path::{Path, PathBuf};

const MAINLINE: [&str; 5] = ["kvaser_pci", "sja1000", "can_dev", "can_raw", "can"];
const OURS: [&str; 5] = [
    "rcan_kvaser_pci",
    "rcan_dev",
    "rcan_raw",
    "rcan_can",
    "rcan_pf",
];

fn unload() -> Result<(), String> {
    let all: Vec<&str> = MAINLINE.iter().chain(&OURS).copied().collect();
    card::unload(&all)
}

/// Our driver module, relative to the tree.
const OUR_KO: &str = "drivers/net/can/sja1000/rcan_kvaser_pci.ko";

/// Loads stack `s`; `ko` (absolute, or relative to `root`) is our driver
/// module.
fn load(s: Stack, root: &Path, kb: &Path, ko: &Path) -> Result<(), String> {
    let ko = ko.to_str().ok_or("driver module path not UTF-8")?;
    card::load(
        s,
        root,
        kb,
        &[
            "drivers/net/can/sja1000/sja1000.ko",
            "drivers/net/can/sja1000/kvaser_pci.ko",
        ],
        &[ko],
        &["bitrate", "500000"],
    )
}

/// 8-byte frames, extended id, as the SJA1000 VM tests send them.
const ID: u32 = 0x1234_5678 | 1 << 31;

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
    // The first Kvaser PCIcan card.
    let (config, cf8) = card::pci_config(0x10e8, 0x8406)?;
    println!("SJA-MARKERS {:#x} {:#x}", cf8 | MARK_START, cf8 | MARK_END);
    unload()?;
    // (stack, our driver module, phase name): mainline then ours, or the
    // other build of our driver then ours.
    let before = env("RCAN_BENCH_SJA_BEFORE_KO");
    let ours = (Stack::Ours, PathBuf::from(OUR_KO), "ours");
    let sides = match before {
        Some(ko) => [(Stack::Ours, ko, "before"), ours],
        None => [(Stack::Mainline, PathBuf::from(OUR_KO), "mainline"), ours],
    };
    let mut n = 0;
    for round in 0..rounds {
        for (s, ko, name) in &sides {
            load(*s, &root, &kb, ko)?;
            pin_irq("can0")?;
            pin_irq("can1")?;
            marker(&config, MARK_START)?;
            let secs = phase(frames, can::Shape::CLASSIC8, ID);
            marker(&config, MARK_END)?;
            unload()?;
            let secs = secs?;
            println!("SJA-PHASE {n} {name} {round} {frames} {secs:.3}");
            n += 1;
        }
    }
    Ok(())
}
