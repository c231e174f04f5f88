// SPDX-License-Identifier: GPL-2.0
//! The CAN FD part (`--part fd`): CAN_RAW throughput of 64-byte FD frames
//! with BRS on our `rcan_loop` against mainline `vcan`, both at MTU 72
//! (`ip link set can0 mtu 72`, set while down as users do), with the
//! raw part's throughput workload (a) ([`workload::throughput_shaped`]):
//! one sender and one receiver socket, both with `CAN_RAW_FD_FRAMES`, at
//! most `--window` frames in flight. Also classic 8-byte frames on the
//! same MTU-72 devices and sockets: what being an FD device costs.
//!
//! Each round loads each stack in turn (order alternating between rounds,
//! as the raw part does), and per frame shape runs a warm-up and `--reps`
//! measured runs. Besides frames/s (undisturbed and whole run) every run
//! reads the kernel CPU time of all CPUs (`/proc/stat` system + irq +
//! softirq) before and after: kernel CPU per frame received. The summary
//! gives medians per stack, the ratio ours/mainline of the medians and
//! the range of that ratio round by round. A missed expectation is never
//! an error.

use std::time::Instant;

use crate::can::kernel_cpu_s;
use crate::can::{self, Shape};
use crate::report::ratio_range;
use crate::stack::{self, Paths, Stack};
use crate::workload::{self, median};

/// Settings (from the raw part's options).
pub struct Config {
    pub stacks: Vec<Stack>,
    pub rounds: usize,
    pub reps: usize,
    pub warmup: u64,
    pub frames: u64,
    pub window: u64,
    pub rx_cpu: Option<usize>,
    pub iface: String,
    pub load: bool,
}

/// The MTU of an FD device (`CANFD_MTU`).
pub const FD_MTU: u32 = 72;

/// The frame shapes measured, in order, with their row labels.
pub const SHAPES: [(Shape, &str); 2] = [
    (Shape::FD64_BRS, "FD 64 B, BRS"),
    (Shape::CLASSIC8, "classic 8 B"),
];

/// One measured run.
#[derive(Clone, Copy, Debug)]
pub struct Run {
    pub stack: Stack,
    pub round: usize,
    pub shape: Shape,
    /// Undisturbed frames/s (fastest tenth of the chunks).
    pub fps: f64,
    /// Frames/s over the whole run.
    pub fps_run: f64,
    /// Kernel CPU time of all CPUs per frame received, in ns.
    pub cpu_ns: f64,
    pub lost: u64,
    pub odd: u64,
}

/// Every run and error so far.
#[derive(Default)]
pub struct Samples {
    pub runs: Vec<Run>,
    pub errors: Vec<String>,
}

/// `ip link set IFACE down; ... mtu 72; ... up`: the device switched to
/// CAN FD as users switch vcan (refused while up).
fn set_fd_mtu(iface: &str) -> Result<(), String> {
    stack::set_link(iface, &["down"])?;
    stack::set_link(iface, &["mtu", &FD_MTU.to_string()])?;
    stack::set_link(iface, &["up"])?;
    let mtu = std::fs::read_to_string(format!("/sys/class/net/{iface}/mtu"))
        .map_err(|e| format!("{iface} mtu: {e}"))?;
    if mtu.trim() != FD_MTU.to_string() {
        return Err(format!(
            "{iface}: mtu {} after setting {FD_MTU}",
            mtu.trim()
        ));
    }
    Ok(())
}

/// Warm-up and `reps` runs of one shape on `ifindex`.
fn shape_runs(
    c: &Config,
    tag: &str,
    stack: Stack,
    round: usize,
    ifindex: i32,
    (shape, label): (Shape, &str),
    s: &mut Samples,
) -> Result<(), String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let rx = workload::receiver(ifindex, workload::TP_ID)
        .map_err(|e| format!("receiver socket: {e}"))?;
    for (sock, what) in [(&tx, "sender"), (&rx, "receiver")] {
        sock.set_fd_frames(true)
            .map_err(|e| format!("CAN_RAW_FD_FRAMES on the {what}: {e}"))?;
    }
    let w = workload::throughput_shaped(&tx, &rx, c.warmup, c.window, c.rx_cpu, shape)
        .map_err(|e| format!("{label} warm-up: {e}"))?;
    println!(
        "{tag} {label} warm-up: {} frames, {:.0} frames/s",
        w.counts.received, w.fps
    );
    for i in 1..=c.reps {
        let k0 = kernel_cpu_s().map_err(|e| e.to_string())?;
        let r = workload::throughput_shaped(&tx, &rx, c.frames, c.window, c.rx_cpu, shape)
            .map_err(|e| format!("{label} run {i}: {e}"))?;
        let k1 = kernel_cpu_s().map_err(|e| e.to_string())?;
        let cpu_ns = if r.counts.received > 0 {
            (k1 - k0) * 1e9 / r.counts.received as f64
        } else {
            0.0
        };
        println!(
            "{tag} {label} run {i}/{}: {} sent, {} received in {:.3} s = {:.0} frames/s, undisturbed {:.0}; \
             kernel CPU {:.0} ns/frame; lost {}, odd {}, send retries {}, stalls {}",
            c.reps,
            r.counts.sent,
            r.counts.received,
            r.elapsed.as_secs_f64(),
            r.fps,
            r.fps_fast,
            cpu_ns,
            r.counts.lost,
            r.counts.odd,
            r.counts.send_retries,
            r.counts.stalls
        );
        s.runs.push(Run {
            stack,
            round,
            shape,
            fps: r.fps_fast,
            fps_run: r.fps,
            cpu_ns,
            lost: r.counts.lost,
            odd: r.counts.odd,
        });
    }
    Ok(())
}

/// One round of one stack: load it with one device at MTU 72, measure
/// every shape, unload. Returns false if the stack could not be set up.
fn round(c: &Config, paths: &Paths, stack: Stack, r: usize, s: &mut Samples) -> bool {
    let tag = format!("[fd {stack} {r}/{}]", c.rounds);
    println!("=== CAN FD part: {stack} stack, round {r}/{}", c.rounds);
    let fail = |s: &mut Samples, what: String| {
        println!("{tag} FAILED: {what}");
        s.errors.push(format!("fd {stack} round {r}: {what}"));
    };
    if c.load {
        if let Some(f) = stack::missing_module(stack, paths) {
            fail(s, format!("module not available: {}", f.display()));
            return false;
        }
        if let Err(e) =
            stack::unload_all(&c.iface).and_then(|()| stack::load(stack, paths, &c.iface))
        {
            fail(s, format!("setup: {e}"));
            let _ = stack::unload_all(&c.iface);
            return false;
        }
    }
    let started = Instant::now();
    let mut ok = true;
    match set_fd_mtu(&c.iface).and_then(|()| can::ifindex(&c.iface).map_err(|e| e.to_string())) {
        Err(e) => {
            fail(s, format!("{}: {e}", c.iface));
            ok = false;
        }
        Ok(ix) => {
            for sh in SHAPES {
                if let Err(e) = shape_runs(c, &tag, stack, r, ix, sh, s) {
                    fail(s, e);
                }
            }
        }
    }
    println!("{tag} took {:.1} s", started.elapsed().as_secs_f64());
    if c.load {
        if let Err(e) = stack::unload_all(&c.iface) {
            fail(s, format!("unload: {e}"));
            ok = false;
        }
    }
    ok
}

/// All rounds; `write_summary` is called after each round.
pub fn bench(c: &Config, paths: &Paths, write_summary: &dyn Fn(&Samples)) -> Samples {
    let mut s = Samples::default();
    let mut broken = vec![false; c.stacks.len()];
    for r in 1..=c.rounds {
        let mut order: Vec<usize> = (0..c.stacks.len()).collect();
        if r % 2 == 0 {
            order.reverse();
        }
        for i in order {
            if !broken[i] {
                broken[i] = !round(c, paths, c.stacks[i], r, &mut s);
            }
        }
        write_summary(&s);
    }
    s
}

/// Median of `f` over the runs of `stack` and `shape` (in `round`, or
/// all), if any.
fn med(
    runs: &[Run],
    stack: Stack,
    shape: Shape,
    round: Option<usize>,
    f: fn(&Run) -> f64,
) -> Option<f64> {
    let v: Vec<f64> = runs
        .iter()
        .filter(|r| r.stack == stack && r.shape == shape && round.is_none_or(|k| k == r.round))
        .map(f)
        .collect();
    (!v.is_empty()).then(|| median(v))
}

/// The summary: per shape, frames/s (undisturbed and whole runs) and
/// kernel CPU per frame; a column per stack, the ratio ours/mainline of
/// the medians and its range round by round.
pub fn summary(c: &Config, runs: &[Run], errors: &[String], header: &str) -> String {
    use std::fmt::Write;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "CAN FD part: CAN_RAW with CAN_RAW_FD_FRAMES, one sender and one receiver socket, \
         rcan_loop (ours) and vcan echo=1 (mainline) at MTU 72; {} rounds x {} runs of {} frames, window {}",
        c.rounds, c.reps, c.frames, c.window
    );
    let _ = writeln!(t, "{header}");
    let _ = writeln!(
        t,
        "{:<34} {:>12} {:>12} {:>8} {:>14}",
        "figure (median)", "mainline", "ours", "ratio", "per round"
    );
    type Fig = (&'static str, fn(&Run) -> f64, usize);
    let figs: [Fig; 3] = [
        ("frames/s, undisturbed", |r| r.fps, 0),
        ("frames/s, whole runs", |r| r.fps_run, 0),
        ("kernel CPU ns/frame", |r| r.cpu_ns, 0),
    ];
    for (shape, label) in SHAPES {
        for (name, f, prec) in figs {
            let m = med(runs, Stack::Mainline, shape, None, f);
            let o = med(runs, Stack::Ours, shape, None, f);
            let per: Vec<f64> = (1..=c.rounds)
                .filter_map(|k| {
                    match (
                        med(runs, Stack::Ours, shape, Some(k), f),
                        med(runs, Stack::Mainline, shape, Some(k), f),
                    ) {
                        (Some(o), Some(m)) if m > 0.0 => Some(o / m),
                        _ => None,
                    }
                })
                .collect();
            let cell = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.prec$}"));
            let ratio = match (o, m) {
                (Some(o), Some(m)) if m > 0.0 => format!("{:.2}x", o / m),
                _ => "-".to_string(),
            };
            let _ = writeln!(
                t,
                "{:<34} {:>12} {:>12} {:>8} {:>14}",
                format!("{label}: {name}"),
                cell(m),
                cell(o),
                ratio,
                ratio_range(&per)
            );
        }
    }
    // What FD costs against classic frames on the same device.
    for st in [Stack::Mainline, Stack::Ours] {
        let fd = med(runs, st, Shape::FD64_BRS, None, |r| r.cpu_ns);
        let cl = med(runs, st, Shape::CLASSIC8, None, |r| r.cpu_ns);
        if let (Some(fd), Some(cl)) = (fd, cl) {
            if cl > 0.0 {
                let _ = writeln!(
                    t,
                    "{st}: kernel CPU per FD 64-byte frame / per classic 8-byte frame = {:.2}",
                    fd / cl
                );
            }
        }
    }
    let lost: u64 = runs.iter().map(|r| r.lost).sum();
    let odd: u64 = runs.iter().map(|r| r.odd).sum();
    let _ = writeln!(t, "frames lost {lost}, odd {odd} over {} runs", runs.len());
    for e in errors {
        let _ = writeln!(t, "error: {e}");
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(stack: Stack, round: usize, shape: Shape, fps: f64, cpu_ns: f64) -> Run {
        Run {
            stack,
            round,
            shape,
            fps,
            fps_run: fps / 2.0,
            cpu_ns,
            lost: 0,
            odd: 0,
        }
    }

    #[test]
    fn summary_medians_and_ratio_ranges() {
        let c = Config {
            stacks: vec![Stack::Mainline, Stack::Ours],
            rounds: 2,
            reps: 1,
            warmup: 1,
            frames: 10,
            window: 4,
            rx_cpu: None,
            iface: "can0".into(),
            load: true,
        };
        let fd = Shape::FD64_BRS;
        let runs = [
            run(Stack::Mainline, 1, fd, 1000.0, 4000.0),
            run(Stack::Ours, 1, fd, 800.0, 5000.0),
            run(Stack::Mainline, 2, fd, 2000.0, 4000.0),
            run(Stack::Ours, 2, fd, 2000.0, 6000.0),
            run(Stack::Mainline, 1, Shape::CLASSIC8, 3000.0, 2000.0),
        ];
        let t = summary(&c, &runs, &["x".into()], "hdr");
        let line = |p: &str| {
            t.lines()
                .find(|l| l.starts_with(p))
                .unwrap_or_else(|| panic!("no {p:?} in\n{t}"))
                .split_whitespace()
                .rev()
                .take(4)
                .collect::<Vec<_>>()
        };
        // Medians 1500 and 1400, ratio 0.93; per round 0.80 and 1.00.
        assert_eq!(
            line("FD 64 B, BRS: frames/s, undisturbed"),
            ["0.80-1.00x", "0.93x", "1400", "1500"]
        );
        assert_eq!(
            line("FD 64 B, BRS: kernel CPU ns/frame"),
            ["1.25-1.50x", "1.38x", "5500", "4000"]
        );
        // Ours has no classic runs: no ratio.
        assert_eq!(
            line("classic 8 B: frames/s, undisturbed"),
            ["-", "-", "-", "3000"]
        );
        assert!(t.contains(
            "mainline: kernel CPU per FD 64-byte frame / per classic 8-byte frame = 2.00"
        ));
        assert!(!t.contains("ours: kernel CPU per FD"));
        assert!(t.contains("error: x"));
    }
}
