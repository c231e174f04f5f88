// SPDX-License-Identifier: GPL-2.0
//! rcan-bench: rcan's CAN_RAW receive path against mainline SocketCAN.
//!
//! Run as root inside the test VM (`make bench`, or
//! `tools/testing/rcan/bench.sh`). In each of `--rounds` rounds it loads
//! every selected stack in turn (the order alternates between rounds),
//! brings `can0` up, runs three workloads with the same code (mainline
//! CAN_RAW ABI only) and removes the stack again:
//!
//! - (a) throughput: frames/s from one sender socket to one receiver
//!   socket, at most `--window` frames in flight, losses counted;
//! - (b) fan-out: cost per frame with 1, 100 and 1,000 receivers, each
//!   bound to its own exact 11-bit id, frames sent round-robin over the ids;
//! - (c) latency: send-to-receive p50/p99/max, one frame in flight.
//!
//! Each workload is warmed up, then measured `--reps` times per round. The
//! summary shows medians over all runs, the ratios ours/mainline and their
//! range round by round, and the targets met or missed. A missed target is
//! never an error: the exit status is non-zero only if a stack could not be
//! set up or a workload could not run. See
//! `Documentation/networking/rcan/benchmarks.rst`.
//!
//! A second part (`--part table`, see `table.rs`) measures what many
//! sockets cost on both stacks: bind and close of 1,000 and 10,000
//! sockets, the cost of a frame nobody wants with that many filters, 1,000
//! against 1 receivers, two senders on two CPUs, memory per socket.
//!
//! A third part (`--part dsor`, see `dsor.rs`) measures messages instead
//! of frames: rcan's DSOR protocol against mainline ISO-TP, goodput and
//! kernel CPU time per KiB. `--part raw,table,dsor` (the default) runs all
//! three in that order.
//!
//! A fourth part, only on request (`--part bcm`, see `bcm.rs`), measures
//! kernel CPU time per cyclic frame of CAN_BCM (1,000 jobs at 10 ms):
//! rcan_bcm against mainline's can-bcm.ko.
//!
//! A fifth part, only on request (`--part fd`, see `fd.rs`), measures CAN
//! FD frames: workload (a) with 64-byte FD frames (BRS) and with classic
//! frames on rcan_loop and vcan at MTU 72, frames/s and kernel CPU per
//! frame.
//!
//! A sixth part, only on request (`--part isotp`, see `isotp.rs`),
//! measures CAN_ISOTP: rcan_isotp against mainline's can-isotp.ko,
//! goodput and CPU per KiB of 4 KiB and 64 KiB PDUs over classic CAN and
//! CAN FD, and the consecutive-frame spacing with STmin 1 ms (issue 41).

mod bcm;
mod can;
mod cli;
mod dsor;
mod fd;
mod isotp;
mod report;
mod stack;
mod table;
mod workload;

use std::process::ExitCode;
use std::time::Instant;

use cli::Config;
use report::{Fanout, Latency, StackResult, Throughput};
use stack::Stack;
use workload::median;

fn median_u64(v: Vec<u64>) -> u64 {
    median(v.into_iter().map(|x| x as f64).collect()).round() as u64
}

/// Percentiles of one latency run, in ns.
#[derive(Clone, Copy, Debug)]
struct LatencyStats {
    p50: u64,
    p99: u64,
    max: u64,
    lost: u64,
    odd: u64,
}

/// Raw runs of one stack over all rounds (each tagged with its round),
/// and what stopped working.
#[derive(Default)]
struct Samples {
    tp: Vec<(usize, workload::ThroughputRun)>,
    fan: Vec<(usize, usize, workload::FanoutRun)>,
    lat: Vec<(usize, LatencyStats)>,
    errors: Vec<String>,
    /// Setup failed: skip the stack in later rounds.
    broken: bool,
    /// Workloads that failed: skipped in later rounds.
    tp_off: bool,
    fan_off: Vec<usize>,
    lat_off: bool,
}

impl Samples {
    /// Medians over the runs of `round`, or of all rounds.
    fn result(&self, stack: Stack, round: Option<usize>) -> StackResult {
        let want = |r: usize| round.is_none_or(|k| k == r);
        let tp: Vec<_> = self
            .tp
            .iter()
            .filter(|(r, _)| want(*r))
            .map(|(_, t)| t)
            .collect();
        let throughput = (!tp.is_empty()).then(|| Throughput {
            fps: median(tp.iter().map(|r| r.fps_fast).collect()),
            fps_run: median(tp.iter().map(|r| r.fps).collect()),
            lost: tp.iter().map(|r| r.counts.lost).sum(),
            odd: tp.iter().map(|r| r.counts.odd).sum(),
            runs: tp.len(),
        });
        let fan: Vec<_> = self.fan.iter().filter(|(r, _, _)| want(*r)).collect();
        let mut counts: Vec<usize> = fan.iter().map(|(_, n, _)| *n).collect();
        counts.sort_unstable();
        counts.dedup();
        let fanout = counts
            .into_iter()
            .map(|n| {
                let runs: Vec<_> = fan
                    .iter()
                    .filter(|(_, k, _)| *k == n)
                    .map(|(_, _, f)| f)
                    .collect();
                Fanout {
                    receivers: n,
                    ns_per_frame: median(runs.iter().map(|r| r.ns_fast).collect()),
                    ns_run: median(runs.iter().map(|r| r.ns_per_frame).collect()),
                    setup_ms: median(runs.iter().map(|r| r.setup.as_secs_f64() * 1e3).collect()),
                    lost: runs.iter().map(|r| r.counts.lost).sum(),
                    odd: runs.iter().map(|r| r.counts.odd).sum(),
                    runs: runs.len(),
                }
            })
            .collect();
        let lat: Vec<_> = self
            .lat
            .iter()
            .filter(|(r, _)| want(*r))
            .map(|(_, l)| l)
            .collect();
        let latency = (!lat.is_empty()).then(|| Latency {
            p50: median_u64(lat.iter().map(|l| l.p50).collect()),
            p99: median_u64(lat.iter().map(|l| l.p99).collect()),
            max: lat.iter().map(|l| l.max).max().unwrap_or(0),
            lost: lat.iter().map(|l| l.lost).sum(),
            odd: lat.iter().map(|l| l.odd).sum(),
            runs: lat.len(),
        });
        StackResult {
            stack,
            errors: if round.is_none() {
                self.errors.clone()
            } else {
                Vec::new()
            },
            throughput,
            fanout,
            latency,
        }
    }
}

/// Workload (a) on `ifindex`: warm-up, then `reps` runs.
fn bench_throughput(
    c: &Config,
    tag: &str,
    ifindex: i32,
    round: usize,
    s: &mut Samples,
) -> Result<(), String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let rx = workload::receiver(ifindex, workload::TP_ID)
        .map_err(|e| format!("receiver socket: {e}"))?;
    let w = workload::throughput(&tx, &rx, c.warmup, c.window, c.rx_cpu)
        .map_err(|e| format!("warm-up: {e}"))?;
    println!(
        "{tag} (a) warm-up: {} frames, {:.0} frames/s",
        w.counts.received, w.fps
    );
    for i in 1..=c.reps {
        let r = workload::throughput(&tx, &rx, c.tp_frames, c.window, c.rx_cpu)
            .map_err(|e| format!("run {i}: {e}"))?;
        println!(
            "{tag} (a) run {i}/{}: {} sent, {} received in {:.3} s = {:.0} frames/s, undisturbed {:.0}; \
             lost {}, odd {}, send retries {}, stalls {}",
            c.reps,
            r.counts.sent,
            r.counts.received,
            r.elapsed.as_secs_f64(),
            r.fps,
            r.fps_fast,
            r.counts.lost,
            r.counts.odd,
            r.counts.send_retries,
            r.counts.stalls
        );
        s.tp.push((round, r));
    }
    Ok(())
}

/// Workload (b), one run with `n` receivers on `ifindex`: open the sockets,
/// warm up, measure, close them.
fn bench_fanout(
    c: &Config,
    tag: &str,
    ifindex: i32,
    n: usize,
    run: &str,
) -> Result<workload::FanoutRun, String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let t0 = Instant::now();
    let rxs = (0..n)
        .map(|i| workload::receiver(ifindex, workload::FANOUT_BASE_ID + i as u32))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("receiver sockets: {e}"))?;
    let setup = t0.elapsed();
    let w = workload::fanout(&tx, &rxs, c.warmup, c.batch).map_err(|e| format!("warm-up: {e}"))?;
    let mut r = workload::fanout(&tx, &rxs, c.fan_frames, c.batch)
        .map_err(|e| format!("run {run}: {e}"))?;
    println!(
        "{tag} (b) {n} receiver(s), run {run}: {} sent, {} received in {:.3} s = {:.0} ns/frame, undisturbed {:.0}; \
         lost {}, odd {}, send retries {}, stalls {} (sockets set up in {:.3} s, warm-up {:.0} ns/frame)",
        r.counts.sent,
        r.counts.received,
        r.elapsed.as_secs_f64(),
        r.ns_per_frame,
        r.ns_fast,
        r.counts.lost,
        r.counts.odd,
        r.counts.send_retries,
        r.counts.stalls,
        setup.as_secs_f64(),
        w.ns_per_frame
    );
    r.setup = setup;
    Ok(r)
}

/// Workload (c) on `ifindex`: warm-up, then `reps` runs of `lat_frames`.
fn bench_latency(
    c: &Config,
    tag: &str,
    ifindex: i32,
    round: usize,
    s: &mut Samples,
) -> Result<(), String> {
    let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
    let rx = workload::receiver(ifindex, workload::LAT_ID)
        .map_err(|e| format!("receiver socket: {e}"))?;
    let w = workload::latency(&tx, &rx, c.warmup).map_err(|e| format!("warm-up: {e}"))?;
    println!(
        "{tag} (c) warm-up: p50 {:.1} us",
        w.percentile(50.0) as f64 / 1e3
    );
    for i in 1..=c.reps {
        let r = workload::latency(&tx, &rx, c.lat_frames).map_err(|e| format!("run {i}: {e}"))?;
        let us = |p: f64| r.percentile(p) as f64 / 1e3;
        println!(
            "{tag} (c) run {i}/{}: {} frames: p50 {:.1} us, p90 {:.1} us, p99 {:.1} us, \
             p99.9 {:.1} us, max {:.1} us; lost {}, odd {}, stalls {}",
            c.reps,
            r.counts.received,
            us(50.0),
            us(90.0),
            us(99.0),
            us(99.9),
            us(100.0),
            r.counts.lost,
            r.counts.odd,
            r.counts.stalls
        );
        s.lat.push((
            round,
            LatencyStats {
                p50: r.percentile(50.0),
                p99: r.percentile(99.0),
                max: r.percentile(100.0),
                lost: r.counts.lost,
                odd: r.counts.odd,
            },
        ));
    }
    Ok(())
}

/// One round on one stack: load it (unless `--no-load`), run the selected
/// workloads, remove it again. Failures are recorded in `s` and switch the
/// failing part off for later rounds.
fn bench_round(c: &Config, stack: Stack, round: usize, s: &mut Samples) {
    let tag = if c.rounds > 1 {
        format!("[{stack} {round}/{}]", c.rounds)
    } else {
        format!("[{stack}]")
    };
    let fail = |s: &mut Samples, what: String| {
        println!("{tag} FAILED: {what}");
        s.errors.push(format!("round {round}: {what}"));
    };
    println!("=== {stack} stack, round {round}/{}", c.rounds);
    if c.load {
        if let Some(f) = stack::missing_module(stack, &c.paths) {
            fail(s, format!("module not available: {}", f.display()));
            s.broken = true;
            return;
        }
        if let Err(e) =
            stack::unload_all(&c.iface).and_then(|()| stack::load(stack, &c.paths, &c.iface))
        {
            fail(s, format!("setup: {e}"));
            s.broken = true;
            let _ = stack::unload_all(&c.iface);
            return;
        }
    }
    let started = Instant::now();
    match can::ifindex(&c.iface) {
        Err(e) => {
            fail(s, format!("{}: {e}", c.iface));
            s.broken = true;
        }
        Ok(ifindex) => {
            if c.run_a && !s.tp_off {
                if let Err(e) = bench_throughput(c, &tag, ifindex, round, s) {
                    fail(s, format!("(a) throughput: {e}"));
                    s.tp_off = true;
                }
            }
            if c.run_b {
                // Receiver counts interleaved run by run, so that slow
                // drifts of the host's load hit all of them alike.
                for i in 1..=c.reps {
                    for &n in &c.fan_counts {
                        if s.fan_off.contains(&n) {
                            continue;
                        }
                        match bench_fanout(c, &tag, ifindex, n, &format!("{i}/{}", c.reps)) {
                            Ok(r) => s.fan.push((round, n, r)),
                            Err(e) => {
                                fail(s, format!("(b) {n} receivers: {e}"));
                                s.fan_off.push(n);
                            }
                        }
                    }
                }
            }
            if c.run_c && !s.lat_off {
                if let Err(e) = bench_latency(c, &tag, ifindex, round, s) {
                    fail(s, format!("(c) latency: {e}"));
                    s.lat_off = true;
                }
            }
        }
    }
    println!(
        "{tag} workloads took {:.1} s",
        started.elapsed().as_secs_f64()
    );
    if c.load {
        if let Err(e) = stack::unload_all(&c.iface) {
            fail(s, format!("unload: {e}"));
            s.broken = true;
        }
    }
}

/// Prints the medians of one stack so far.
fn print_medians(r: &StackResult) {
    let tag = format!("[{}]", r.stack);
    if let Some(t) = r.throughput {
        println!(
            "{tag} (a) throughput: median {:.0} frames/s undisturbed, {:.0} whole runs, over {} runs; lost {}",
            t.fps, t.fps_run, t.runs, t.lost
        );
    }
    for f in &r.fanout {
        println!(
            "{tag} (b) {} receiver(s): median {:.0} ns/frame undisturbed, {:.0} whole runs, over {} runs; lost {}",
            f.receivers, f.ns_per_frame, f.ns_run, f.runs, f.lost
        );
    }
    if let Some((n, x)) = r.fanout_ratio() {
        println!("{tag} (b) cost per frame, {n} receivers : 1 receiver = {x:.2}");
    }
    if let Some(l) = r.latency {
        println!(
            "{tag} (c) latency: median p50 {:.1} us, median p99 {:.1} us, max {:.1} us over {} runs; lost {}",
            l.p50 as f64 / 1e3,
            l.p99 as f64 / 1e3,
            l.max as f64 / 1e3,
            l.runs,
            l.lost
        );
    }
}

fn cpu_name(cpu: Option<usize>) -> String {
    cpu.map_or_else(|| "any CPU".to_string(), |n| format!("CPU {n}"))
}

/// Kernel, CPUs and settings, for the summary's header.
fn header(c: &Config) -> String {
    let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
    let cpuinfo = read("/proc/cpuinfo");
    let model = cpuinfo
        .lines()
        .find_map(|l| {
            l.strip_prefix("model name")
                .and_then(|r| r.split_once(':'))
                .map(|x| x.1.trim())
        })
        .unwrap_or("?");
    let cpus = std::thread::available_parallelism().map_or(0, |n| n.get());
    let hv = if cpuinfo.contains(" hypervisor") {
        ", virtualised"
    } else {
        ""
    };
    format!(
        "kernel {} on {cpus} CPU(s) ({model}{hv})\n\
         workloads on {}; {} round(s) x {} run(s) per figure and stack; medians over all runs\n\
         (a) {} frames/run, window {}, receiver thread on {}\n\
         (b) {} frames/run round-robin over the receivers' ids, batch {}\n\
         (c) {} frames/run, one in flight\n\
         undisturbed: from the fastest tenth of the {}-frame chunks (a) or {}-frame batches (b) of a run; \
         whole runs: all frames / all time",
        read("/proc/sys/kernel/osrelease").trim(),
        cpu_name(c.cpu),
        c.rounds,
        c.reps,
        c.tp_frames,
        c.window,
        cpu_name(c.rx_cpu.or(c.cpu)),
        c.fan_frames,
        c.batch,
        c.lat_frames,
        workload::CHUNK,
        c.batch
    )
}

fn main() -> ExitCode {
    let c = cli::parse();
    let hdr = header(&c);
    // The kernel and CPU line, for the other parts' summaries.
    let hdr1 = hdr.lines().next().unwrap_or_default().to_string();
    println!("rcan-bench: {hdr}");
    let mut want = 0u64;
    if c.run_raw && c.run_b {
        want = *c.fan_counts.iter().max().unwrap_or(&1) as u64 + 64;
    }
    if c.run_table {
        let most = c.table.counts.iter().copied().max().unwrap_or(0).max(1000);
        want = want.max(most as u64 + 64);
    }
    if want > 0 {
        match can::raise_nofile(want) {
            Ok(n) => println!("rcan-bench: RLIMIT_NOFILE {n}"),
            Err(e) => println!("rcan-bench: cannot raise RLIMIT_NOFILE to {want}: {e}"),
        }
    }
    if let Some(cpu) = c.cpu {
        // Threads inherit this, so every workload runs on that CPU.
        if let Err(e) = can::pin_current_thread(cpu) {
            eprintln!("rcan-bench: cannot pin to CPU {cpu}: {e}");
            return ExitCode::from(2);
        }
    }
    let t0 = Instant::now();
    let mut samples: Vec<(Stack, Samples)> = c
        .stacks
        .iter()
        .map(|&st| (st, Samples::default()))
        .collect();
    let results = |samples: &[(Stack, Samples)], round: Option<usize>| -> Vec<StackResult> {
        samples.iter().map(|(st, s)| s.result(*st, round)).collect()
    };
    let summary = |samples: &[(Stack, Samples)]| {
        let per_round: Vec<_> = (1..=c.rounds).map(|k| results(samples, Some(k))).collect();
        report::summary(&results(samples, None), &per_round, &hdr)
    };
    let raw_rounds = if c.run_raw { c.rounds } else { 0 };
    for round in 1..=raw_rounds {
        // Odd rounds in the given order, even rounds reversed (mainline,
        // ours, ours, mainline, ...): neither stack always goes first.
        let mut order: Vec<usize> = (0..samples.len()).collect();
        if round % 2 == 0 {
            order.reverse();
        }
        for i in order {
            let (stack, s) = &mut samples[i];
            if !s.broken {
                bench_round(&c, *stack, round, s);
            }
        }
        // Written after each round: a later crash keeps the earlier figures.
        if let Some(p) = &c.summary {
            if let Err(e) = std::fs::write(p, summary(&samples)) {
                eprintln!("rcan-bench: {}: {e}", p.display());
            }
        }
    }
    let all = results(&samples, None);
    let mut failed = all.iter().any(|r| !r.errors.is_empty());
    let raw_text = if c.run_raw {
        println!();
        all.iter().for_each(print_medians);
        println!();
        let t = summary(&samples);
        print!("{t}");
        t + "\n"
    } else {
        String::new()
    };
    let table_text = if c.run_table {
        let write = |s: &table::Samples| {
            if let Some(p) = &c.summary {
                let text = raw_text.clone() + &table::summary(&c.table, s, &hdr1);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let ts = table::bench(&c.table, &c.stacks, &c.paths, &write);
        println!();
        let t = table::summary(&c.table, &ts, &hdr1);
        print!("{t}");
        failed |= !ts.errors.is_empty();
        raw_text.clone() + &t + "\n"
    } else {
        raw_text.clone()
    };
    if c.run_dsor {
        let dc = dsor::Config {
            protos: c.protos.clone(),
            sizes: c.msg_sizes.clone(),
            rounds: c.rounds,
            secs: c.msg_secs,
            min_msgs: c.msg_min,
            warmup: c.msg_warmup,
            iface: c.iface.clone(),
            load: c.load,
            cpu: c.cpu,
        };
        let dhdr = hdr1.clone();
        let write = |s: &dsor::Samples| {
            if let Some(p) = &c.summary {
                let text = table_text.clone() + &dsor::summary(&dc, s, &dhdr);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let ds = dsor::bench(&dc, &c.paths, &write);
        println!();
        print!("{}", dsor::summary(&dc, &ds, &dhdr));
        failed |= !ds.errors.is_empty();
    }
    if c.run_bcm {
        let bc = bcm::Config {
            rounds: c.rounds,
            jobs: c.bcm_jobs,
            ival_ms: c.bcm_ival_ms,
            secs: c.bcm_secs,
            iface: c.iface.clone(),
            stacks: c.stacks.clone(),
        };
        let (runs, errors) = bcm::bench(&bc, &c.paths);
        let text = bcm::summary(&bc, &runs);
        print!("{text}");
        if let Some(p) = &c.summary {
            let old = std::fs::read_to_string(p).unwrap_or_default();
            if let Err(e) = std::fs::write(p, old + &text) {
                eprintln!("rcan-bench: {}: {e}", p.display());
            }
        }
        failed |= !errors.is_empty();
    }
    if c.run_fd {
        let fc = fd::Config {
            stacks: c.stacks.clone(),
            rounds: c.rounds,
            reps: c.reps,
            warmup: c.warmup,
            frames: c.tp_frames,
            window: c.window,
            rx_cpu: c.rx_cpu,
            iface: c.iface.clone(),
            load: c.load,
        };
        // Appended to what the other parts wrote.
        let before = c
            .summary
            .as_ref()
            .map(|p| std::fs::read_to_string(p).unwrap_or_default())
            .unwrap_or_default();
        let write = |s: &fd::Samples| {
            if let Some(p) = &c.summary {
                let text = before.clone() + &fd::summary(&fc, &s.runs, &s.errors, &hdr1);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let fs = fd::bench(&fc, &c.paths, &write);
        println!();
        print!("{}", fd::summary(&fc, &fs.runs, &fs.errors, &hdr1));
        failed |= !fs.errors.is_empty();
    }
    if c.run_isotp {
        let ic = isotp::Config {
            stacks: c.stacks.clone(),
            links: c.isotp_links.clone(),
            sizes: c.isotp_sizes.clone(),
            rounds: c.rounds,
            secs: c.msg_secs,
            min_msgs: c.msg_min,
            warmup: c.msg_warmup,
            spacing_pdus: c.isotp_spacing_pdus,
            iface: c.iface.clone(),
            cpu: c.cpu,
            load: c.load,
        };
        // Appended to what the other parts wrote.
        let before = c
            .summary
            .as_ref()
            .map(|p| std::fs::read_to_string(p).unwrap_or_default())
            .unwrap_or_default();
        let write = |s: &isotp::Samples| {
            if let Some(p) = &c.summary {
                let text = before.clone() + &isotp::summary(&ic, s, &hdr1);
                if let Err(e) = std::fs::write(p, text) {
                    eprintln!("rcan-bench: {}: {e}", p.display());
                }
            }
        };
        let is = isotp::bench(&ic, &c.paths, &write);
        println!();
        print!("{}", isotp::summary(&ic, &is, &hdr1));
        failed |= !is.errors.is_empty();
    }
    println!("rcan-bench: done in {:.0} s", t0.elapsed().as_secs_f64());
    if let Some(p) = &c.summary {
        println!("rcan-bench: summary saved in {}", p.display());
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
