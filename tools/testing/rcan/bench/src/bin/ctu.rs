// SPDX-License-Identifier: GPL-2.0

//! rcan-bench-ctu: the CTU CAN FD section of `make bench --part fd`
//! (tools/testing/rcan/bench.sh), run inside one VM booted with QEMU's
//! `ctucan_pci` card (two cores on one `can-bus`, as RCAN_QEMU_CAN sets it
//! up for the VM tests) and QEMU's `memory_region_ops_read/write` trace
//! events on. For each stack -- mainline `ctucanfd` + `ctucanfd_pci` (with
//! can, can-raw, can-dev from the test kernel) and ours
//! (`rcan_ctucanfd_pci` with rcan_pf, rcan_can, rcan_raw, rcan_dev), the
//! order alternating between rounds -- it sets both cores up as users do
//! (`ip link set canX type can bitrate 500000 dbitrate 2000000 fd on`)
//! and per frame shape (64-byte FD frames with BRS, classic 8-byte
//! frames, both on the FD-enabled cores) sends `--frames` frames can0 ->
//! can1 over CAN_RAW as fast as the driver takes them and reads them on
//! can1, and prints one line per phase:
//!
//! ```text
//! CTU-PHASE <n> <stack> <round> <frames> <seconds> <shape> <kernel CPU ns/frame>
//! ```
//!
//! bracketed by trace markers as in `card.rs`; sja-count.awk (with `-v
//! tag=CTU -v region=ctucan`) counts each driver's register accesses per
//! frame. A phase in which a frame goes missing (10 s), comes out of
//! order or cannot be sent (the driver's queue stopped for a second)
//! prints `CTU-FAILED` and counts in the summary: a finding about that
//! driver, not an error of the benchmark; the others go on. The exit
//! status is non-zero only if a stack cannot be set up.
//!
//! Interrupts of the card and this process are on CPU 0, as in the
//! SJA1000 section: QEMU's bus has no bit timing, so the receiving core's
//! RX buffer is drained only as fast as its interrupt is served.

#[path = "../can.rs"]
#[allow(dead_code)]
mod can;
#[path = "../card.rs"]
mod card;

use can::Shape;
use card::{marker, phase, pin_irq, Stack, MARK_END, MARK_START};
use std::path::{Path, PathBuf};

const MAINLINE: [&str; 5] = ["ctucanfd_pci", "ctucanfd", "can_dev", "can_raw", "can"];
const OURS: [&str; 5] = [
    "rcan_ctucanfd_pci",
    "rcan_dev",
    "rcan_raw",
    "rcan_can",
    "rcan_pf",
];

/// The shapes measured in each phase pair, with their labels.
const SHAPES: [(Shape, &str); 2] = [(Shape::FD64_BRS, "fd64"), (Shape::CLASSIC8, "classic8")];

/// Frames sent after pinning the interrupt, before the phases.
const WARMUP: u32 = 16;

/// Extended identifier of every frame.
const ID: u32 = 0x1234_5678 | 1 << 31;

fn unload() -> Result<(), String> {
    let all: Vec<&str> = MAINLINE.iter().chain(&OURS).copied().collect();
    card::unload(&all)
}

fn load(s: Stack, root: &Path, kb: &Path) -> Result<(), String> {
    card::load(
        s,
        root,
        kb,
        &[
            "drivers/net/can/ctucanfd/ctucanfd.ko",
            "drivers/net/can/ctucanfd/ctucanfd_pci.ko",
        ],
        &["drivers/net/can/ctucanfd/rcan_ctucanfd_pci.ko"],
        &["bitrate", "500000", "dbitrate", "2000000", "fd", "on"],
    )
}

/// The command line (`bench.sh` passes `--frames 4000 --rounds 3`).
#[derive(clap::Parser, Debug)]
#[command(
    name = "rcan-bench-ctu",
    version,
    about = "CTU CAN FD driver, ours vs mainline ctucanfd, on QEMU's ctucan_pci card (run by bench.sh --part fd in the VM)",
    long_about = None
)]
struct Cli {
    /// Frames sent per phase (each round has an FD 64-byte and a classic 8-byte phase per stack).
    #[arg(long, default_value_t = 4000, value_parser = clap::value_parser!(u32).range(1..))]
    frames: u32,
    /// Rounds; mainline first in odd rounds, ours first in even ones.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    rounds: u64,
}

fn main() -> std::process::ExitCode {
    // Usage errors exit 2 (clap) before anything is loaded or pinned.
    let cli = <Cli as clap::Parser>::parse();
    match real_main(cli.frames, cli.rounds as usize) {
        Ok(failed) => {
            if failed > 0 {
                println!(
                    "rcan-bench-ctu: {failed} phase(s) lost frames or stalled (CTU-FAILED lines)"
                );
            }
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("rcan-bench-ctu: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// The interface counters that tell where a missing frame went: sent
/// by can0 or not, received by can1 or dropped or overrun there.
fn link_stats() -> String {
    let stat = |d: &str, f: &str| {
        std::fs::read_to_string(format!("/sys/class/net/{d}/statistics/{f}"))
            .map_or_else(|_| "?".into(), |v| v.trim().to_string())
    };
    format!(
        "can0 tx_packets {} tx_dropped {} tx_errors {}, can1 rx_packets {} rx_dropped {} rx_over_errors {}",
        stat("can0", "tx_packets"),
        stat("can0", "tx_dropped"),
        stat("can0", "tx_errors"),
        stat("can1", "rx_packets"),
        stat("can1", "rx_dropped"),
        stat("can1", "rx_over_errors")
    )
}

/// Kernel CPU time over `f`, in seconds, with `f`'s result.
fn kernel_cpu<T>(f: impl FnOnce() -> T) -> Result<(T, f64), String> {
    let k0 = can::kernel_cpu_s().map_err(|e| e.to_string())?;
    let r = f();
    let k1 = can::kernel_cpu_s().map_err(|e| e.to_string())?;
    Ok((r, k1 - k0))
}

/// Runs every phase; returns how many failed.
fn real_main(frames: u32, rounds: usize) -> Result<usize, String> {
    let env = |k: &str| std::env::var_os(k).map(PathBuf::from);
    let root = env("RCAN_ROOT").unwrap_or_else(|| PathBuf::from("."));
    let kb = env("RCAN_KBUILD").ok_or("RCAN_KBUILD not set")?;
    can::pin_current_thread(0).map_err(|e| e.to_string())?;
    // The CTU CAN FD PCI card (both cores are in its BAR).
    let (config, cf8) = card::pci_config(0x1760, 0xff00)?;
    println!("CTU-MARKERS {:#x} {:#x}", cf8 | MARK_START, cf8 | MARK_END);
    unload()?;
    let (mut n, mut failed) = (0, 0);
    for round in 0..rounds {
        let mut order = [Stack::Mainline, Stack::Ours];
        if round % 2 == 1 {
            order.reverse();
        }
        for s in order {
            let name = if s == Stack::Ours { "ours" } else { "mainline" };
            load(s, &root, &kb)?;
            pin_irq("can0")?;
            pin_irq("can1")?;
            // The new affinity takes effect at the line's next interrupt:
            // a few frames first, so that the phases start on CPU 0 (a
            // driver that hands frames to netif_rx in its hard interrupt
            // can otherwise deliver the first frames out of order, as the
            // backlogs of the old and the new CPU drain independently).
            if let Err(e) = phase(WARMUP, Shape::CLASSIC8, ID) {
                println!("CTU-WARMUP {name} {round}: {e}");
            }
            for (shape, label) in SHAPES {
                marker(&config, MARK_START)?;
                let (secs, cpu_s) = kernel_cpu(|| phase(frames, shape, ID))?;
                marker(&config, MARK_END)?;
                match secs {
                    Ok(secs) => println!(
                        "CTU-PHASE {n} {name} {round} {frames} {secs:.3} {label} {:.0}",
                        cpu_s * 1e9 / f64::from(frames)
                    ),
                    Err(e) => {
                        println!(
                            "CTU-FAILED {n} {name} {round} {label}: {e}; since loading: {}",
                            link_stats()
                        );
                        failed += 1;
                    }
                }
                n += 1;
            }
            unload()?;
        }
    }
    Ok(failed)
}
