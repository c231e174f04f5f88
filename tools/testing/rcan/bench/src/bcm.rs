// SPDX-License-Identifier: GPL-2.0
//! The `bcm` part: CPU time per cyclic frame of the broadcast manager,
//! rcan_bcm against mainline's can-bcm.ko, in the same boot.
//!
//! Per round and stack: load the stack (CAN_RAW stack plus its BCM module)
//! with one interface, open one CAN_BCM socket connected to it and set up
//! `--bcm-jobs` cyclic transmissions (`TX_SETUP` with `SETTIMER |
//! STARTTIMER`, `ival2` = `--bcm-ival-ms`, one 8-byte frame each,
//! distinct ids). After a second of warm-up, measure for `--bcm-secs`:
//! kernel CPU time (system + irq + softirq, all CPUs, `/proc/stat`) and
//! the frames the interface sent (`tx_packets`). No socket reads the
//! frames: the cost is the timer, the transmit path and the driver's echo
//! into the receive path with nobody subscribed. The figure is kernel CPU
//! µs per frame sent; the frame rate shows whether the stack kept up with
//! the schedule (`jobs / ival` frames/s). Under TCG the absolute figures
//! are emulation figures; the ratio of the two stacks in one boot is what
//! counts.

use std::io;
use std::os::fd::OwnedFd;
use std::time::{Duration, Instant};

use rcan_uapi::raw;

use crate::stack::{self, Paths, Stack};

pub struct Config {
    pub rounds: usize,
    pub jobs: u32,
    pub ival_ms: u64,
    pub secs: f64,
    pub iface: String,
    pub stacks: Vec<Stack>,
}

/// One measured run.
pub struct Run {
    pub stack: Stack,
    pub frames: u64,
    pub secs: f64,
    pub kernel_s: f64,
}

impl Run {
    pub fn us_per_frame(&self) -> f64 {
        self.kernel_s * 1e6 / self.frames.max(1) as f64
    }
    pub fn frames_per_s(&self) -> f64 {
        self.frames as f64 / self.secs
    }
}

const CAN_BCM: i32 = 2;
const TX_SETUP: u32 = 1;
const SETTIMER: u32 = 1;
const STARTTIMER: u32 = 2;
const MHSIZ: usize = 56;

fn cpu_ticks() -> io::Result<u64> {
    let stat = std::fs::read_to_string("/proc/stat")?;
    let line = stat
        .lines()
        .next()
        .ok_or_else(|| io::Error::other("/proc/stat: empty"))?;
    let f: Vec<u64> = line
        .split_whitespace()
        .skip(1)
        .map(|x| x.parse().unwrap_or(0))
        .collect();
    // user nice system idle iowait irq softirq
    Ok(f.get(2).copied().unwrap_or(0)
        + f.get(5).copied().unwrap_or(0)
        + f.get(6).copied().unwrap_or(0))
}

fn tx_packets(iface: &str) -> io::Result<u64> {
    let p = format!("/sys/class/net/{iface}/statistics/tx_packets");
    std::fs::read_to_string(&p)?
        .trim()
        .parse()
        .map_err(|e| io::Error::other(format!("{p}: {e}")))
}

fn bcm_socket(ifindex: i32) -> io::Result<OwnedFd> {
    let fd = raw::socket(libc::AF_CAN, libc::SOCK_DGRAM, CAN_BCM)?;
    // struct sockaddr_can: family, padding, ifindex, address union.
    let mut addr = [0u8; 24];
    addr[..2].copy_from_slice(&(libc::AF_CAN as u16).to_ne_bytes());
    addr[4..8].copy_from_slice(&ifindex.to_ne_bytes());
    raw::connect(&fd, &addr)?;
    Ok(fd)
}

fn tx_setup(fd: &OwnedFd, id: u32, ival_us: i64) -> io::Result<()> {
    let mut b = vec![0u8; MHSIZ + 16];
    b[0..4].copy_from_slice(&TX_SETUP.to_ne_bytes());
    b[4..8].copy_from_slice(&(SETTIMER | STARTTIMER).to_ne_bytes());
    b[32..40].copy_from_slice(&(ival_us / 1_000_000).to_ne_bytes());
    b[40..48].copy_from_slice(&(ival_us % 1_000_000).to_ne_bytes());
    b[48..52].copy_from_slice(&id.to_ne_bytes());
    b[52..56].copy_from_slice(&1u32.to_ne_bytes());
    b[MHSIZ..MHSIZ + 4].copy_from_slice(&id.to_ne_bytes());
    b[MHSIZ + 4] = 8;
    b[MHSIZ + 8..MHSIZ + 16].copy_from_slice(&id.to_le_bytes().repeat(2));
    raw::write(fd, &b).map(|_| ())
}

fn load_bcm(st: Stack, paths: &Paths, iface: &str) -> Result<(), String> {
    stack::unload_all(iface)?;
    stack::load(st, paths, iface)?;
    let ko = match st {
        Stack::Mainline => paths
            .kbuild
            .as_ref()
            .ok_or("RCAN_KBUILD is not set")?
            .join("net/can/can-bcm.ko"),
        Stack::Ours => paths.root.join("net/can/rcan_bcm.ko"),
    };
    let out = std::process::Command::new("insmod")
        .arg(&ko)
        .output()
        .map_err(|e| format!("insmod: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "insmod {}: {}",
            ko.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    Ok(())
}

fn one(c: &Config, st: Stack, paths: &Paths) -> Result<Run, String> {
    load_bcm(st, paths, &c.iface)?;
    let ifindex = crate::can::ifindex(&c.iface).map_err(|e| format!("{}: {e}", c.iface))?;
    let fd = bcm_socket(ifindex).map_err(|e| format!("BCM socket: {e}"))?;
    for i in 0..c.jobs {
        tx_setup(&fd, 0x100 + i, c.ival_ms as i64 * 1000)
            .map_err(|e| format!("TX_SETUP {i}: {e}"))?;
    }
    std::thread::sleep(Duration::from_secs(1));
    let tck = 100.0; // USER_HZ
    let (f0, c0, t0) = (
        tx_packets(&c.iface).map_err(|e| e.to_string())?,
        cpu_ticks().map_err(|e| e.to_string())?,
        Instant::now(),
    );
    std::thread::sleep(Duration::from_secs_f64(c.secs));
    let (f1, c1, secs) = (
        tx_packets(&c.iface).map_err(|e| e.to_string())?,
        cpu_ticks().map_err(|e| e.to_string())?,
        t0.elapsed().as_secs_f64(),
    );
    drop(fd);
    let run = Run {
        stack: st,
        frames: f1.saturating_sub(f0),
        secs,
        kernel_s: c1.saturating_sub(c0) as f64 / tck,
    };
    stack::unload_all(&c.iface)?;
    Ok(run)
}

/// Runs the part; returns the runs and the errors.
pub fn bench(c: &Config, paths: &Paths) -> (Vec<Run>, Vec<String>) {
    let mut runs = Vec::new();
    let mut errors = Vec::new();
    for round in 1..=c.rounds {
        let mut order = c.stacks.clone();
        if round % 2 == 0 {
            order.reverse();
        }
        for st in order {
            match one(c, st, paths) {
                Ok(r) => {
                    println!(
                        "[bcm {st} {round}/{}] {} jobs at {} ms: {} frames in {:.2} s = {:.0} frames/s \
                         (schedule {:.0}); kernel CPU {:.2} s = {:.2} us/frame",
                        c.rounds,
                        c.jobs,
                        c.ival_ms,
                        r.frames,
                        r.secs,
                        r.frames_per_s(),
                        c.jobs as f64 * 1000.0 / c.ival_ms as f64,
                        r.kernel_s,
                        r.us_per_frame()
                    );
                    runs.push(r);
                }
                Err(e) => {
                    println!("[bcm {st} {round}/{}] FAILED: {e}", c.rounds);
                    errors.push(format!("bcm {st} round {round}: {e}"));
                    let _ = stack::unload_all(&c.iface);
                }
            }
        }
    }
    (runs, errors)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    Some(v[v.len() / 2])
}

/// The summary lines.
pub fn summary(c: &Config, runs: &[Run]) -> String {
    let med = |st: Stack, f: &dyn Fn(&Run) -> f64| {
        median(runs.iter().filter(|r| r.stack == st).map(f).collect())
    };
    let mut s = format!(
        "\nCAN_BCM cyclic transmission: {} jobs at {} ms ({:.0} frames/s scheduled), \
         medians of {} round(s); kernel CPU = system + irq + softirq from /proc/stat\n",
        c.jobs,
        c.ival_ms,
        c.jobs as f64 * 1000.0 / c.ival_ms as f64,
        c.rounds
    );
    for st in [Stack::Mainline, Stack::Ours] {
        if let (Some(us), Some(fps)) = (
            med(st, &|r| r.us_per_frame()),
            med(st, &|r| r.frames_per_s()),
        ) {
            s += &format!(
                "  {:<9} {us:8.2} us CPU/frame  {fps:9.0} frames/s\n",
                st.to_string()
            );
        }
    }
    if let (Some(o), Some(m)) = (
        med(Stack::Ours, &|r| r.us_per_frame()),
        med(Stack::Mainline, &|r| r.us_per_frame()),
    ) {
        s += &format!(
            "  ratio ours/mainline, CPU per frame: {:.2} (target <= 1.00: {})\n",
            o / m,
            if o <= m { "met" } else { "missed" }
        );
    }
    s
}
