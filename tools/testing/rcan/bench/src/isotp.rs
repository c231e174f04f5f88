// SPDX-License-Identifier: GPL-2.0
//! The ISO-TP part (`--part isotp`): rcan's `rcan_isotp` (over
//! `rcan_loop`) against mainline's `can-isotp.ko` (over `vcan echo=1`),
//! the same CAN_ISOTP program and socket options on both, issue 41's
//! targets.
//!
//! Each round loads one stack (both ISO-TP modules with the same
//! `max_pdu_size`, the device at MTU 72), measures everything, removes
//! it, then does the same with the other stack (the order alternates
//! between rounds):
//!
//! - goodput and CPU per KiB: for each link layer (classic 8-byte frames,
//!   CAN FD 64-byte frames through `CAN_ISOTP_LL_OPTS`) and PDU size, one
//!   PDU in flight between two sockets of one thread (`dsor::run`: send,
//!   receive on the other socket, compare byte for byte), block size 0,
//!   STmin 0 and `frame_txtime` 0 (no gap: each consecutive frame leaves
//!   from the echo of the previous one); goodput, kernel CPU per KiB from
//!   `/proc/stat`, CPU per KiB from the soaker run, frames and softirqs
//!   per KiB, as the DSOR part measures them;
//! - frame spacing: the receiver asks for BS 8 and STmin 1 ms
//!   (`CAN_ISOTP_RECV_FC`), a CAN_RAW socket on the bus takes every data
//!   frame with its receive time (`SO_TIMESTAMPNS`), and the gaps between
//!   consecutive frames of a block (the ones STmin governs) are compared
//!   with the 1 ms asked for.
//!
//! Never fails on a missed target; the exit status says only whether a
//! stack could be loaded and every transfer arrived intact.

use std::fmt::Write as _;
use std::io;
use std::time::{Duration, Instant};

use crate::can::{self, IsotpSocket, RawSocket, CAN_EFF_FLAG, CAN_RTR_FLAG};
use crate::dsor::{self, MsgRun, Pair, Soaker};
use crate::report::ratio_range;
use crate::stack::{self, Paths, Stack};
use crate::workload::median;

/// Identifiers (29-bit, as the DSOR part's ISO-TP rows): data frames
/// from the sender on `DATA_ID`, flow control from the receiver on
/// `FC_ID`.
const DATA_ID: u32 = 0x18da_10f1 | CAN_EFF_FLAG;
const FC_ID: u32 = 0x18da_f110 | CAN_EFF_FLAG;
/// Send and receive timeout of every socket: a run that waits this long
/// has failed.
const IO_TIMEOUT: Duration = Duration::from_secs(20);
/// The spacing run's flow control: block size 8, STmin 0x01 = 1 ms.
pub const SPACING_BS: u8 = 8;
pub const SPACING_STMIN: u8 = 1;
/// The gap STmin 0x01 asks for, ns.
pub const SPACING_ASKED_NS: f64 = 1e6;
/// Issue 41's targets: goodput at least, CPU per KiB at most this many
/// times mainline's; spacing within this fraction of the asked gap.
pub const TARGET_GOODPUT: f64 = 1.2;
pub const TARGET_CPU: f64 = 0.8;
pub const TARGET_SPACING: f64 = 0.10;

/// The link layer of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Link {
    /// Classic CAN, 8-byte frames (the default `CAN_ISOTP_LL_OPTS`).
    Classic,
    /// CAN FD, `CAN_ISOTP_LL_OPTS` mtu 72, tx_dl 64, no flags.
    Fd,
}

impl Link {
    pub fn name(self) -> &'static str {
        match self {
            Link::Classic => "classic",
            Link::Fd => "FD",
        }
    }

    /// PDU size of the spacing run: about 140 consecutive frames classic,
    /// 65 FD (each under a second at 1 ms).
    pub fn spacing_size(self) -> usize {
        match self {
            Link::Classic => 1000,
            Link::Fd => 4095,
        }
    }
}

/// Settings of the ISO-TP part.
#[derive(Debug, PartialEq)]
pub struct Config {
    pub stacks: Vec<Stack>,
    pub links: Vec<Link>,
    pub sizes: Vec<usize>,
    pub rounds: usize,
    /// Minimum duration and messages of a measured run; warm-up messages.
    pub secs: f64,
    pub min_msgs: u64,
    pub warmup: u64,
    /// PDUs per spacing run (0: no spacing runs).
    pub spacing_pdus: usize,
    pub iface: String,
    pub cpu: Option<usize>,
    /// Load and unload the stacks (else measure what is set up on
    /// `iface`, as the one stack named: for profiling).
    pub load: bool,
}

impl Config {
    /// `max_pdu_size` both modules are loaded with: mainline's default
    /// (8300) or the largest PDU measured.
    pub fn max_pdu(&self) -> u32 {
        self.sizes.iter().copied().max().unwrap_or(0).max(8300) as u32
    }
}

/// The CF gaps of one spacing run, ns.
#[derive(Clone, Debug, Default)]
pub struct Spacing {
    /// Between consecutive frames of one block (STmin applies).
    pub inner: Vec<f64>,
    /// From the last frame of a block to the first of the next (the flow
    /// control round trip; STmin does not apply).
    pub across: Vec<f64>,
    /// Data frames the listener saw without a timestamp.
    pub unstamped: u64,
}

/// All runs so far.
#[derive(Default)]
pub struct Samples {
    pub runs: Vec<(Stack, Link, usize, usize, MsgRun)>,
    pub spacing: Vec<(Stack, Link, usize, Spacing)>,
    pub errors: Vec<String>,
}

/// A sender and a receiver on `iface` with the part's options:
/// `frame_txtime` 0 on both, `CAN_ISOTP_LL_OPTS` for FD, and the
/// receiver's flow control `fc` (block size, STmin byte) if given.
fn open_pair(link: Link, iface: &str, fc: Option<(u8, u8)>) -> io::Result<Pair> {
    let ifindex = can::ifindex(iface)?;
    let tx = IsotpSocket::new()?;
    let rx = IsotpSocket::new()?;
    // Options are set before bind().
    for s in [&tx, &rx] {
        s.set_no_frame_gap()?;
        if link == Link::Fd {
            s.set_ll_opts(72, 64, 0)?;
        }
    }
    if let Some((bs, stmin)) = fc {
        rx.set_recv_fc(bs, stmin)?;
    }
    tx.bind(ifindex, FC_ID, DATA_ID)?;
    tx.set_timeouts(IO_TIMEOUT)?;
    rx.bind(ifindex, DATA_ID, FC_ID)?;
    rx.set_timeouts(IO_TIMEOUT)?;
    Ok(Pair::Isotp { tx, rx })
}

/// The gaps in `frames` (N_PCI byte, receive time in ns, in bus order) of
/// the data identifier: each first frame starts a PDU; the gap before
/// consecutive frame *k* > 1 is inside a block unless *k* - 1 is a
/// multiple of `bs`.
pub fn gaps(frames: &[(u8, i64)], bs: u8) -> Spacing {
    let mut s = Spacing::default();
    let mut cf = 0usize;
    let mut last: Option<i64> = None;
    for &(pci, t) in frames {
        match pci >> 4 {
            1 => {
                cf = 0;
                last = None;
            }
            2 => {
                cf += 1;
                if let Some(p) = last {
                    let g = (t - p) as f64;
                    if bs != 0 && (cf - 1).is_multiple_of(usize::from(bs)) {
                        s.across.push(g);
                    } else {
                        s.inner.push(g);
                    }
                }
                last = Some(t);
            }
            _ => {}
        }
    }
    s
}

/// One spacing run on `link`: `pdus` PDUs with the receiver's BS 8 and
/// STmin 1 ms, the data frames timestamped by a CAN_RAW listener.
fn spacing(link: Link, iface: &str, pdus: usize) -> io::Result<Spacing> {
    let ifindex = can::ifindex(iface)?;
    let bus = RawSocket::new()?;
    bus.set_filters(&[(DATA_ID, 0x1fff_ffff | CAN_EFF_FLAG | CAN_RTR_FLAG)])?;
    if link == Link::Fd {
        bus.set_fd_frames(true)?;
    }
    bus.set_rcvbuf(4 << 20)?;
    bus.set_timestampns(true)?;
    bus.bind(ifindex)?;
    let p = open_pair(link, iface, Some((SPACING_BS, SPACING_STMIN)))?;
    let size = link.spacing_size();
    let msg: Vec<u8> = (0..size).map(|i| (i * 13 + 1) as u8).collect();
    let mut buf = vec![0u8; size + 64];
    for n in 0..pdus {
        let sent = p.send(&msg)?;
        let got = p.recv(&mut buf)?;
        if sent != size || got != size || buf[..got] != msg[..] {
            return Err(io::Error::other(format!(
                "spacing PDU {n}: sent {sent}, received {got} of {size} bytes, or content differs"
            )));
        }
    }
    let mut frames = Vec::new();
    let mut unstamped = 0;
    loop {
        match bus.recv_stamped(true) {
            Ok((f, Some(t))) => frames.push((f.data[0], t)),
            Ok((_, None)) => unstamped += 1,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
            Err(e) => return Err(e),
        }
    }
    let mut s = gaps(&frames, SPACING_BS);
    s.unstamped = unstamped;
    Ok(s)
}

/// One round of `stack`: load, goodput runs of every link and size,
/// spacing runs, unload. Returns false if the stack is broken.
fn round(
    c: &Config,
    paths: &Paths,
    stack: Stack,
    r: usize,
    s: &mut Samples,
    soak: Option<&Soaker>,
) -> bool {
    let tag = format!("[isotp {stack} {r}/{}]", c.rounds);
    let fail = |s: &mut Samples, what: String| {
        println!("{tag} FAILED: {what}");
        s.errors.push(format!("{stack} round {r}: {what}"));
    };
    println!("=== ISO-TP, {stack}, round {r}/{}", c.rounds);
    if c.load {
        if let Some(f) = stack::missing_isotp_module(stack, paths) {
            fail(s, format!("module not available: {}", f.display()));
            return false;
        }
        if let Err(e) = stack::unload_all(&c.iface)
            .and_then(|()| stack::load_isotp(stack, paths, &c.iface, c.max_pdu()))
        {
            fail(s, format!("setup: {e}"));
            let _ = stack::unload_all(&c.iface);
            return false;
        }
    }
    let t0 = Instant::now();
    let mut ok = true;
    'links: for &link in &c.links {
        let p = match open_pair(link, &c.iface, None) {
            Ok(p) => p,
            Err(e) => {
                fail(s, format!("{} sockets: {e}", link.name()));
                ok = false;
                break;
            }
        };
        for &size in &c.sizes {
            let what = format!("{} {size} B", link.name());
            let res = dsor::run(&p, &c.iface, size, c.warmup, 0.0, None)
                .map_err(|e| format!("{what} warm-up: {e}"))
                .and_then(|_| {
                    dsor::run(&p, &c.iface, size, c.min_msgs, c.secs, None)
                        .map_err(|e| format!("{what}: {e}"))
                })
                .and_then(|mut m| {
                    let Some(k) = soak else { return Ok(m) };
                    let ms = dsor::run(&p, &c.iface, size, c.min_msgs, c.secs, Some(k))
                        .map_err(|e| format!("{what} with soaker: {e}"))?;
                    m.cpu_soak_s = ms.cpu_soak_s.map(|t| t * m.bytes as f64 / ms.bytes as f64);
                    Ok(m)
                });
            match res {
                Ok(m) => {
                    println!(
                        "{tag} {what}: {} PDUs in {:.3} s = {:.1} KiB/s; CPU {} us/KiB (soaker); \
                         kernel CPU {:.0} us/KiB (softirq {:.0}); {:.1} frames/KiB; \
                         per KiB {:.1} HRTIMER, {:.1} NET_RX softirqs",
                        m.msgs,
                        m.elapsed.as_secs_f64(),
                        m.kib_per_s(),
                        m.soak_us_per_kib()
                            .map_or_else(|| "-".into(), |v| format!("{v:.0}")),
                        m.kernel_us_per_kib(),
                        m.softirq_us_per_kib(),
                        m.frames_per_kib(),
                        m.hrtimer_per_kib(),
                        m.net_rx_per_kib()
                    );
                    s.runs.push((stack, link, size, r, m));
                }
                Err(e) => {
                    fail(s, e);
                    ok = false;
                    break 'links;
                }
            }
        }
    }
    if ok && c.spacing_pdus > 0 {
        for &link in &c.links {
            match spacing(link, &c.iface, c.spacing_pdus) {
                Ok(g) => {
                    let q = Quantiles::of(&g.inner);
                    println!(
                        "{tag} {} spacing, BS {SPACING_BS} STmin 1 ms: {} gaps in blocks, median {:.1} us, \
                         min {:.1}, max {:.1}; {} gaps across flow control, median {:.1} us; {} frames unstamped",
                        link.name(),
                        g.inner.len(),
                        q.median / 1e3,
                        q.min / 1e3,
                        q.max / 1e3,
                        g.across.len(),
                        Quantiles::of(&g.across).median / 1e3,
                        g.unstamped
                    );
                    s.spacing.push((stack, link, r, g));
                }
                Err(e) => {
                    fail(s, format!("{} spacing: {e}", link.name()));
                    ok = false;
                    break;
                }
            }
        }
    }
    println!("{tag} measured in {:.1} s", t0.elapsed().as_secs_f64());
    if c.load {
        if let Err(e) = stack::unload_all(&c.iface) {
            fail(s, format!("unload: {e}"));
            ok = false;
        }
    }
    ok
}

/// Runs the ISO-TP part; returns its samples (`summary` formats them).
pub fn bench(c: &Config, paths: &Paths, write_summary: &dyn Fn(&Samples)) -> Samples {
    let mut s = Samples::default();
    let mut broken = vec![false; c.stacks.len()];
    let soaker = Soaker::for_cpu(c.cpu);
    let t0 = Instant::now();
    for r in 1..=c.rounds {
        let mut order: Vec<usize> = (0..c.stacks.len()).collect();
        if r % 2 == 0 {
            order.reverse();
        }
        for i in order {
            if !broken[i] {
                broken[i] = !round(c, paths, c.stacks[i], r, &mut s, soaker.as_ref());
            }
        }
        write_summary(&s);
    }
    println!(
        "rcan-bench: ISO-TP part took {:.0} s",
        t0.elapsed().as_secs_f64()
    );
    s
}

/// Median, 99th percentile, minimum and maximum of a sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantiles {
    pub median: f64,
    pub p99: f64,
    pub min: f64,
    pub max: f64,
    pub n: usize,
}

impl Quantiles {
    pub fn of(v: &[f64]) -> Quantiles {
        if v.is_empty() {
            return Quantiles {
                median: f64::NAN,
                p99: f64::NAN,
                min: f64::NAN,
                max: f64::NAN,
                n: 0,
            };
        }
        let mut w = v.to_vec();
        w.sort_by(f64::total_cmp);
        let idx = |q: f64| ((w.len() - 1) as f64 * q).round() as usize;
        Quantiles {
            median: median(w.clone()),
            p99: w[idx(0.99)],
            min: w[0],
            max: w[w.len() - 1],
            n: w.len(),
        }
    }
}

/// The summary: per link and size a row per figure, a column per stack,
/// the ratio ours/mainline of the medians and its range round by round;
/// the spacing rows; the target verdicts; errors.
pub fn summary(c: &Config, s: &Samples, header: &str) -> String {
    let med = |st: Stack,
               link: Link,
               size: usize,
               r: Option<usize>,
               f: &dyn Fn(&MsgRun) -> Option<f64>| {
        let v: Vec<f64> = s
            .runs
            .iter()
            .filter(|(a, l, z, k, _)| {
                *a == st && *l == link && *z == size && r.is_none_or(|r| r == *k)
            })
            .filter_map(|(_, _, _, _, m)| f(m))
            .collect();
        (!v.is_empty()).then(|| median(v))
    };
    let mut o = String::new();
    let _ = writeln!(
        o,
        "=== rcan-bench ISO-TP: rcan_isotp vs mainline can-isotp ==="
    );
    let _ = writeln!(o, "{header}");
    let _ = writeln!(
        o,
        "mainline: can-isotp over vcan echo=1; ours: rcan_isotp over rcan_loop; both max_pdu_size {}, \
         device at MTU 72, can-raw/rcan_raw loaded",
        c.max_pdu()
    );
    let _ = writeln!(
        o,
        "two sockets on {}, 29-bit ids, same options on both stacks: frame_txtime 0 \
         (CAN_ISOTP_FRAME_TXTIME_ZERO), receiver BS 0 STmin 0, no padding; FD: CAN_ISOTP_LL_OPTS \
         mtu 72 tx_dl 64; one PDU in flight, one thread on {}; {} round(s), runs of >= {} s and >= {} PDUs \
         after {} warm-up PDUs; medians over rounds",
        c.iface,
        c.cpu
            .map_or_else(|| "any CPU".to_string(), |n| format!("CPU {n}")),
        c.rounds,
        c.secs,
        c.min_msgs,
        c.warmup
    );
    let _ = writeln!(
        o,
        "CPU (soaker) = time of the benchmark's CPU a SCHED_IDLE spinner did not get (user and kernel); \
         kernel CPU = system + irq + softirq of all CPUs from /proc/stat; ratio = ours/mainline (range over rounds)"
    );
    let _ = writeln!(
        o,
        "{:<40} {:>10} {:>10} {:>8} {:>14}",
        "figure (medians)", "mainline", "ours", "ratio", "per round"
    );
    type Fig<'a> = (&'a str, usize, &'a dyn Fn(&MsgRun) -> Option<f64>);
    let figs: [Fig; 8] = [
        ("goodput, KiB/s", 1, &|m| Some(m.kib_per_s())),
        ("CPU (soaker), us/KiB", 0, &|m| m.soak_us_per_kib()),
        ("kernel CPU, us/KiB", 0, &|m| Some(m.kernel_us_per_kib())),
        ("  of which softirq, us/KiB", 0, &|m| {
            Some(m.softirq_us_per_kib())
        }),
        ("CAN frames/KiB", 1, &|m| Some(m.frames_per_kib())),
        ("kernel CPU, ns/frame", 0, &|m| m.kernel_ns_per_frame()),
        ("HRTIMER softirqs/KiB", 1, &|m| Some(m.hrtimer_per_kib())),
        ("NET_RX softirqs/KiB", 1, &|m| Some(m.net_rx_per_kib())),
    ];
    let ratio = |link: Link, size: usize, f: &dyn Fn(&MsgRun) -> Option<f64>| {
        let all = match (
            med(Stack::Ours, link, size, None, f),
            med(Stack::Mainline, link, size, None, f),
        ) {
            (Some(o), Some(m)) if m > 0.0 => Some(o / m),
            _ => None,
        };
        let per: Vec<f64> = (1..=c.rounds)
            .filter_map(|r| {
                let m = med(Stack::Mainline, link, size, Some(r), f)?;
                let o = med(Stack::Ours, link, size, Some(r), f)?;
                (m > 0.0).then(|| o / m)
            })
            .collect();
        (all, ratio_range(&per))
    };
    for &link in &c.links {
        for &size in &c.sizes {
            for (name, prec, f) in &figs {
                let cell = |st| {
                    med(st, link, size, None, f)
                        .map_or_else(|| "-".to_string(), |v| format!("{v:.prec$}"))
                };
                let (all, per) = ratio(link, size, f);
                let _ = writeln!(
                    o,
                    "{:<40} {:>10} {:>10} {:>8} {:>14}",
                    format!("{} {size} B: {name}", link.name()),
                    cell(Stack::Mainline),
                    cell(Stack::Ours),
                    all.map_or_else(|| "-".to_string(), |x| format!("{x:.2}x")),
                    per
                );
            }
        }
    }
    // Spacing: all gaps of all rounds together.
    let pooled = |st: Stack, link: Link, inner: bool| -> Vec<f64> {
        s.spacing
            .iter()
            .filter(|(a, l, _, _)| *a == st && *l == link)
            .flat_map(|(_, _, _, g)| {
                if inner {
                    g.inner.clone()
                } else {
                    g.across.clone()
                }
            })
            .collect()
    };
    let us = |v: f64| {
        if v.is_nan() {
            "-".to_string()
        } else {
            format!("{:.1}", v / 1e3)
        }
    };
    for &link in &c.links {
        let qm = Quantiles::of(&pooled(Stack::Mainline, link, true));
        let qo = Quantiles::of(&pooled(Stack::Ours, link, true));
        let am = Quantiles::of(&pooled(Stack::Mainline, link, false));
        let ao = Quantiles::of(&pooled(Stack::Ours, link, false));
        let rows: [(&str, f64, f64); 6] = [
            ("CF gap in a block, median, us", qm.median, qo.median),
            ("CF gap in a block, p99, us", qm.p99, qo.p99),
            ("CF gap in a block, max, us", qm.max, qo.max),
            ("CF gap in a block, min, us", qm.min, qo.min),
            (
                "gaps in blocks measured",
                qm.n as f64 * 1e3,
                qo.n as f64 * 1e3,
            ),
            ("CF gap across an FC, median, us", am.median, ao.median),
        ];
        for (name, m, ours) in rows {
            let ratio = if m > 0.0 && ours.is_finite() {
                format!("{:.2}x", ours / m)
            } else {
                "-".to_string()
            };
            let cell = |v: f64| {
                if name.starts_with("gaps") {
                    format!("{:.0}", v / 1e3)
                } else {
                    us(v)
                }
            };
            let _ = writeln!(
                o,
                "{:<40} {:>10} {:>10} {:>8}",
                format!("{} BS 8 STmin 1 ms: {name}", link.name()),
                cell(m),
                cell(ours),
                ratio
            );
        }
    }
    let _ = writeln!(o);
    let verdict = |met: bool| if met { "target met" } else { "target missed" };
    for &link in &c.links {
        for &size in &c.sizes {
            let gp = |m: &MsgRun| Some(m.kib_per_s());
            if let (Some(o_), Some(m)) = (
                med(Stack::Ours, link, size, None, &gp),
                med(Stack::Mainline, link, size, None, &gp),
            ) {
                let _ = writeln!(
                    o,
                    "goodput, {} {size} B: ours {o_:.1} vs mainline {m:.1} KiB/s = {:.2}x, want >= {TARGET_GOODPUT:.2}x: {}",
                    link.name(),
                    o_ / m,
                    verdict(o_ >= TARGET_GOODPUT * m)
                );
            }
            type Measure<'a> = (&'a str, &'a dyn Fn(&MsgRun) -> Option<f64>);
            let measures: [Measure; 2] = [
                ("soaker", &|m| m.soak_us_per_kib()),
                ("/proc/stat", &|m| Some(m.kernel_us_per_kib())),
            ];
            for (how, f) in measures {
                if let (Some(o_), Some(m)) = (
                    med(Stack::Ours, link, size, None, f),
                    med(Stack::Mainline, link, size, None, f),
                ) {
                    if m > 0.0 {
                        let _ = writeln!(
                            o,
                            "CPU per KiB ({how}), {} {size} B: ours {o_:.0} vs mainline {m:.0} us/KiB = {:.2}x, \
                             want <= {TARGET_CPU:.2}x: {}",
                            link.name(),
                            o_ / m,
                            verdict(o_ <= TARGET_CPU * m)
                        );
                    }
                }
            }
        }
    }
    for &link in &c.links {
        for st in [Stack::Mainline, Stack::Ours] {
            let q = Quantiles::of(&pooled(st, link, true));
            if q.n == 0 {
                continue;
            }
            let off = |v: f64| (v - SPACING_ASKED_NS).abs() / SPACING_ASKED_NS;
            let _ = writeln!(
                o,
                "CF spacing, {} BS 8 STmin 1 ms, {st}: median {:.1} us ({:+.1} %), worst {:.1} us ({:+.1} %), \
                 {} gaps; want within {:.0} % of 1000 us: median {}, worst {}",
                link.name(),
                q.median / 1e3,
                (q.median / SPACING_ASKED_NS - 1.0) * 100.0,
                q.max / 1e3,
                (q.max / SPACING_ASKED_NS - 1.0) * 100.0,
                q.n,
                TARGET_SPACING * 100.0,
                verdict(off(q.median) <= TARGET_SPACING),
                verdict(off(q.max) <= TARGET_SPACING && off(q.min) <= TARGET_SPACING)
            );
        }
    }
    for e in &s.errors {
        let _ = writeln!(o, "ERROR {e}");
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_split_at_blocks_and_pdus() {
        // FF, 10 CFs 1 us apart, except 5 us before CF 9 (the FC round
        // trip after block 1..8); then a second PDU.
        let mut f = vec![(0x10, 0)];
        let mut t = 100;
        for k in 1..=10 {
            t += if k == 9 { 5_000 } else { 1_000 };
            f.push((0x20 | (k % 16) as u8, t));
        }
        f.push((0x10, t + 50_000));
        f.push((0x21, t + 60_000));
        f.push((0x22, t + 61_000));
        let g = gaps(&f, 8);
        // Gaps before CFs 2..8 and 10 (8), and before CF 2 of the second PDU.
        assert_eq!(g.inner, vec![1000.0; 9]);
        assert_eq!(g.across, vec![5000.0]);
        // Block size 0: no block ends.
        let g0 = gaps(&f, 0);
        assert_eq!(g0.inner.len(), 10);
        assert!(g0.across.is_empty());
    }

    #[test]
    fn quantiles() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let q = Quantiles::of(&v);
        assert_eq!((q.min, q.max, q.n), (1.0, 100.0, 100));
        assert_eq!(q.median, 50.5);
        assert_eq!(q.p99, 99.0);
        assert!(Quantiles::of(&[]).median.is_nan());
    }

    #[test]
    fn max_pdu_covers_the_largest_size() {
        let mut c = Config {
            stacks: vec![Stack::Mainline, Stack::Ours],
            links: vec![Link::Classic],
            sizes: vec![4096],
            rounds: 1,
            secs: 1.0,
            min_msgs: 1,
            warmup: 1,
            spacing_pdus: 1,
            iface: "can0".into(),
            cpu: Some(0),
            load: true,
        };
        assert_eq!(c.max_pdu(), 8300);
        c.sizes = vec![65536, 4096];
        assert_eq!(c.max_pdu(), 65536);
    }
}
