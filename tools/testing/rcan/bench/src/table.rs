// SPDX-License-Identifier: GPL-2.0
//! The receive-table part (`--part table`): what many sockets cost, on
//! mainline SocketCAN and on ours, in alternating rounds like the raw part.
//!
//! Per round and stack (loaded with two devices: `rcan_loop count=2`, or
//! two `vcan` devices):
//!
//! - (d) bind + close: for each socket count N (1,000 and 10,000) and each
//!   filter kind ([`Kind`]): open N CAN_RAW sockets and set one filter on
//!   each (timed), bind them all to `can0` (timed; the last tenth of the
//!   binds also on its own: the cost of one bind at n ~ N), ... and at the
//!   end close them all (timed; the first tenth on its own);
//! - (h) memory: `/proc/meminfo` `Slab`, `MemFree` and `Percpu` before
//!   the sockets are opened and after they are all bound, per socket;
//! - (e) unwanted frame: while those N sockets are bound, the cost of a
//!   frame that none of them wants (id `UNWANTED_ID`), by the fan-out
//!   workload's method: one thread sends a batch of such frames, then one
//!   frame for a sentinel socket (`SENTINEL_ID`, wanted by nobody else),
//!   and reads it back; the wall time of a batch over the frames it put
//!   through the receive path, fastest tenth of the batches and whole run,
//!   the same with no socket bound (the baseline), and the difference.
//!   Kernel CPU (system + irq + softirq of all CPUs, `/proc/stat`) per
//!   frame is printed beside it (not summarised: too coarse in USER_HZ
//!   ticks for short runs). Afterwards every one of the N sockets must be
//!   empty (a frame there is reported);
//! - (f) 1,000 : 1 receivers: workload (b) of the raw part with 1 and with
//!   1,000 exact receivers (each on its own id), cost per frame;
//! - (g) two senders: one thread on CPU 0 sending to and receiving from
//!   `can0`, and one on CPU 1 doing the same on `can1`, at the same time
//!   for `--table-secs`: aggregate frames/s (whole run and undisturbed,
//!   see [`pair`]), against one thread alone.
//!
//! Medians over the rounds, ratios ours/mainline and their range round by
//! round, as in the raw part. Never fails on a missed target.

use std::fmt::Write as _;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Barrier;
use std::thread;
use std::time::{Duration, Instant};

use crate::can::{self, pin_current_thread, send_retrying, Frame, RawSocket, EXACT_SFF_MASK};
use crate::stack::{self, Paths, Stack};
use crate::workload::{self, median, percentile_f64, recv_patient, Counts, FAST_PERCENTILE};

/// The frame nobody wants, in workload (e).
pub const UNWANTED_ID: u32 = 0x555;
/// The sentinel's frame that ends every batch of (e): wanted by the
/// sentinel socket only.
pub const SENTINEL_ID: u32 = 0x55a;
/// The one identifier of every socket of kind `same`.
pub const SHARED_ID: u32 = 0x0a0;
/// Mask of kind `masked`: `candump can0,ID:7F0`.
pub const MASK: u32 = 0x7f0;
/// Identifier of workload (g) on both devices.
pub const PAIR_ID: u32 = 0x123;
/// Pause after closing sockets and before sampling memory: lets
/// RCU-deferred frees of the previous step finish.
const SETTLE: Duration = Duration::from_millis(500);

/// The filter each of the N sockets gets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One exact 11-bit id each (`{id, CAN_SFF_MASK | EFF | RTR}`), the
    /// ids 0..0x7ff round-robin, except `UNWANTED_ID` and `SENTINEL_ID`.
    Exact,
    /// All sockets on one exact id, `SHARED_ID`.
    Same,
    /// `{id, 0x7f0}`: 127 groups of 16 ids round-robin (every group but
    /// `UNWANTED_ID`'s).
    Masked,
    /// `--table-masks` distinct masks `0x700 | k`, ids whose top three
    /// bits differ from `UNWANTED_ID`'s.
    Masks,
}

impl Kind {
    pub const ALL: [Kind; 4] = [Kind::Exact, Kind::Same, Kind::Masked, Kind::Masks];

    pub fn parse(s: &str) -> Option<Kind> {
        Some(match s {
            "exact" => Kind::Exact,
            "same" => Kind::Same,
            "masked" => Kind::Masked,
            "masks" => Kind::Masks,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Kind::Exact => "exact",
            Kind::Same => "same",
            Kind::Masked => "masked",
            Kind::Masks => "masks",
        }
    }

    fn describe(self, masks: usize) -> String {
        match self {
            Kind::Exact => format!(
                "exact = one exact 11-bit id each, ids 0x000-0x7ff round-robin without {UNWANTED_ID:#x} and {SENTINEL_ID:#x}"
            ),
            Kind::Same => format!("same = all on exact id {SHARED_ID:#05x}"),
            Kind::Masked => format!(
                "masked = id:{MASK:03x}, 127 groups round-robin (not {:#05x})",
                UNWANTED_ID & MASK
            ),
            Kind::Masks => format!(
                "masks = {masks} distinct masks 0x700|k, ids with top bits != {:#05x}",
                UNWANTED_ID & 0x700
            ),
        }
    }

    /// `(can_id, can_mask)` of socket `i`; `masks` distinct masks for
    /// `Masks` (1..=255).
    pub fn filter(self, i: usize, masks: usize) -> (u32, u32) {
        match self {
            Kind::Exact => {
                let mut id = (i % 2046) as u32;
                if id >= UNWANTED_ID {
                    id += 1;
                }
                if id >= SENTINEL_ID {
                    id += 1;
                }
                (id, EXACT_SFF_MASK)
            }
            Kind::Same => (SHARED_ID, EXACT_SFF_MASK),
            Kind::Masked => {
                let skip = UNWANTED_ID >> 4;
                let mut g = (i % 127) as u32;
                if g >= skip {
                    g += 1;
                }
                ((g << 4) | ((i / 127) % 16) as u32, MASK)
            }
            Kind::Masks => {
                const TOP: [u32; 7] = [0, 1, 2, 3, 4, 6, 7];
                let m = masks.clamp(1, 255);
                let top = TOP[(i / m) % TOP.len()];
                ((top << 8) | (i % 256) as u32, 0x700 | (i % m) as u32)
            }
        }
    }
}

/// Settings of the table part.
#[derive(Debug, PartialEq)]
pub struct Config {
    pub counts: Vec<usize>,
    pub kinds: Vec<Kind>,
    pub masks: usize,
    pub rounds: usize,
    /// Unwanted frames per measured run of (e) (plus one sentinel frame
    /// per batch).
    pub frames: u64,
    /// Unwanted frames per warm-up run.
    pub warmup: u64,
    pub batch: u64,
    /// Frames per run of (f).
    pub fan_frames: u64,
    /// Run (d), (e) and (h).
    pub sockets: bool,
    /// Run (f).
    pub fan: bool,
    /// Seconds per run of (g).
    pub secs: f64,
    pub pair: bool,
    pub iface: String,
    pub iface2: String,
    pub load: bool,
    /// `can_id` of (e)'s frames; the kinds are built so that nobody wants
    /// `UNWANTED_ID`, the default. Another id (`--table-unwanted-id`)
    /// probes a particular hash bucket; the run reports any socket that
    /// wants it.
    pub unwanted_id: u32,
}

/// All samples: `(stack, round, figure, value)`, and the figures in the
/// order they were first recorded, with their printing precision.
#[derive(Default)]
pub struct Samples {
    vals: Vec<(Stack, usize, String, f64)>,
    keys: Vec<(String, usize)>,
    pub errors: Vec<String>,
    /// Misdelivered frames seen, per stack (should stay 0).
    odd: Vec<(Stack, u64)>,
    lost: Vec<(Stack, u64)>,
}

impl Samples {
    fn put(&mut self, stack: Stack, round: usize, key: String, prec: usize, v: f64) {
        if !self.keys.iter().any(|(k, _)| *k == key) {
            self.keys.push((key.clone(), prec));
        }
        self.vals.push((stack, round, key, v));
    }

    fn get(&self, stack: Stack, round: Option<usize>, key: &str) -> Option<f64> {
        let v: Vec<f64> = self
            .vals
            .iter()
            .filter(|(s, r, k, _)| *s == stack && k == key && round.is_none_or(|x| x == *r))
            .map(|x| x.3)
            .collect();
        (!v.is_empty()).then(|| median(v))
    }

    fn count(list: &mut Vec<(Stack, u64)>, stack: Stack, n: u64) {
        match list.iter_mut().find(|(s, _)| *s == stack) {
            Some(e) => e.1 += n,
            None => list.push((stack, n)),
        }
    }
}

/// `/proc/meminfo` fields in KiB.
#[derive(Clone, Copy, Debug, Default)]
struct Mem {
    slab: u64,
    free: u64,
    percpu: u64,
}

fn meminfo() -> io::Result<Mem> {
    let text = std::fs::read_to_string("/proc/meminfo")?;
    let field = |name: &str| -> u64 {
        text.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':'))
            .and_then(|v| v.split_whitespace().next()?.parse().ok())
            .unwrap_or(0)
    };
    Ok(Mem {
        slab: field("Slab"),
        free: field("MemFree"),
        percpu: field("Percpu"),
    })
}

/// Kernel CPU time of all CPUs so far (in can.rs: the card sections use
/// it too).
use crate::can::kernel_cpu_s;

/// One run of workload (e).
#[derive(Clone, Copy, Debug)]
pub struct UnwantedRun {
    /// Frames through the receive path: unwanted plus sentinel frames.
    pub frames: u64,
    /// Wall time per frame of a full batch at the `FAST_PERCENTILE` of
    /// the batch times, ns.
    pub ns_fast: f64,
    /// Wall time per frame over the whole run, ns.
    pub ns_run: f64,
    /// Kernel CPU (all CPUs, `/proc/stat`, in USER_HZ ticks: too coarse
    /// for short runs; printed, not summarised) per frame over the run, ns.
    pub kernel_ns: f64,
    pub counts: Counts,
}

/// Workload (e): `frames` frames of `id` (`UNWANTED_ID` unless
/// `--table-unwanted-id`) from `tx`, in batches of
/// `batch`, each batch followed by one `SENTINEL_ID` frame that is read
/// back from `sentinel` (so the batch has been through the receive path
/// when its time is taken).
pub fn unwanted(
    tx: &RawSocket,
    sentinel: &RawSocket,
    id: u32,
    frames: u64,
    batch: u64,
) -> io::Result<UnwantedRun> {
    let batch = batch.max(1);
    let mut c = Counts {
        odd: sentinel.drain(),
        ..Counts::default()
    };
    let tag = workload::next_tag();
    let mut batch_ns = Vec::with_capacity((frames / batch + 1) as usize);
    let k0 = kernel_cpu_s()?;
    let start = Instant::now();
    let mut sent = 0u64;
    let mut through = 0u64;
    let mut seq = 0u32;
    while sent < frames {
        let n = batch.min(frames - sent);
        let t = Instant::now();
        for _ in 0..n {
            c.send_retries += send_retrying(tx, &Frame::with_words(id, seq, tag))?;
            seq = seq.wrapping_add(1);
        }
        let mark = Frame::with_words(SENTINEL_ID, seq, tag);
        seq = seq.wrapping_add(1);
        c.send_retries += send_retrying(tx, &mark)?;
        c.sent += n + 1;
        loop {
            match recv_patient(sentinel, &mut c)? {
                Some(f) if f == mark => {
                    c.received += 1;
                    break;
                }
                Some(_) => c.odd += 1,
                None => {
                    return Err(io::Error::other(format!(
                        "sentinel frame {seq} not received within 3 s"
                    )));
                }
            }
        }
        if n == batch {
            batch_ns.push(t.elapsed().as_nanos() as f64 / (n + 1) as f64);
        }
        sent += n;
        through += n + 1;
    }
    let elapsed = start.elapsed();
    let k1 = kernel_cpu_s()?;
    Ok(UnwantedRun {
        frames: through,
        ns_fast: percentile_f64(batch_ns, FAST_PERCENTILE),
        ns_run: elapsed.as_nanos() as f64 / through.max(1) as f64,
        kernel_ns: (k1 - k0).max(0.0) * 1e9 / through.max(1) as f64,
        counts: c,
    })
}

/// Window of workload (g)'s undisturbed rate.
const PAIR_WINDOW: Duration = Duration::from_millis(20);

/// One run of workload (g).
#[derive(Clone, Copy, Debug, Default)]
pub struct PairRun {
    /// Frames received by all lanes together per second.
    pub fps: f64,
    /// Frames received by all lanes together in a `PAIR_WINDOW` at the
    /// fastest tenth of the windows in which every lane ran, per second.
    pub fps_fast: f64,
    /// Per lane: frames received.
    pub per_lane: [u64; 2],
    pub counts: Counts,
}

/// Workload (g): one thread per `(ifindex, cpu)` lane, pinned to that
/// CPU, each with its own sender and receiver (`PAIR_ID`) on its device,
/// sending batches of `batch` frames and reading them back, all lanes at
/// the same time for `secs` seconds. Aggregate frames/s = frames received
/// by all lanes / the longest lane's time; undisturbed: the time is cut
/// into `PAIR_WINDOW`s, the frames of every batch that ended in a window
/// are counted to it, and the window at the 90th percentile of those
/// counts (the fastest tenth), among the windows in which all lanes ran,
/// gives the rate.
pub fn pair(lanes: &[(i32, usize)], secs: f64, batch: u64) -> io::Result<PairRun> {
    type Lane = (Counts, Duration, u64, Vec<u64>);
    let stop = AtomicBool::new(false);
    let go = Barrier::new(lanes.len() + 1);
    let t0 = Instant::now();
    let res: Vec<io::Result<Lane>> = thread::scope(|s| {
        let hs: Vec<_> = lanes
            .iter()
            .map(|&(ifindex, cpu)| {
                let (stop, go) = (&stop, &go);
                s.spawn(move || -> io::Result<Lane> {
                    let setup = (|| -> io::Result<(RawSocket, RawSocket)> {
                        pin_current_thread(cpu).map_err(|e| {
                            io::Error::other(format!("pinning a sender to CPU {cpu}: {e}"))
                        })?;
                        Ok((
                            workload::sender(ifindex)?,
                            workload::receiver(ifindex, PAIR_ID)?,
                        ))
                    })();
                    go.wait();
                    let (tx, rx) = setup?;
                    let mut c = Counts {
                        odd: rx.drain(),
                        ..Counts::default()
                    };
                    let tag = workload::next_tag();
                    let start = Instant::now();
                    let mut ends = Vec::new();
                    let mut seq = 0u32;
                    while !stop.load(Ordering::Relaxed) {
                        let first = seq;
                        for _ in 0..batch {
                            c.send_retries +=
                                send_retrying(&tx, &Frame::with_words(PAIR_ID, seq, tag))?;
                            seq = seq.wrapping_add(1);
                            c.sent += 1;
                        }
                        let mut want = first;
                        while want != seq {
                            match recv_patient(&rx, &mut c)? {
                                Some(f) if f.tag() == tag && f.seq() == want => {
                                    c.received += 1;
                                    want = want.wrapping_add(1);
                                }
                                Some(_) => c.odd += 1,
                                None => {
                                    return Err(io::Error::other(format!(
                                        "frame {want} on CPU {cpu} not received within 3 s"
                                    )));
                                }
                            }
                        }
                        ends.push(t0.elapsed().as_nanos() as u64);
                    }
                    let from = start.duration_since(t0).as_nanos() as u64;
                    Ok((c, start.elapsed(), from, ends))
                })
            })
            .collect();
        go.wait();
        thread::sleep(Duration::from_secs_f64(secs));
        stop.store(true, Ordering::Relaxed);
        hs.into_iter()
            .map(|h| h.join().expect("sender thread panicked"))
            .collect()
    });
    let mut r = PairRun::default();
    let mut longest = Duration::ZERO;
    // The span in which every lane ran: from the last start to the first
    // lane's last batch.
    let (mut from, mut to) = (0u64, u64::MAX);
    let mut all_ends = Vec::new();
    for (i, x) in res.into_iter().enumerate() {
        let (c, t, start, ends) = x?;
        from = from.max(start);
        to = to.min(ends.last().copied().unwrap_or(0));
        all_ends.extend(ends);
        if i < r.per_lane.len() {
            r.per_lane[i] = c.received;
        }
        r.counts.sent += c.sent;
        r.counts.received += c.received;
        r.counts.odd += c.odd;
        r.counts.lost += c.lost;
        r.counts.send_retries += c.send_retries;
        r.counts.stalls += c.stalls;
        longest = longest.max(t);
    }
    r.fps = if longest.is_zero() {
        0.0
    } else {
        r.counts.received as f64 / longest.as_secs_f64()
    };
    let w = PAIR_WINDOW.as_nanos() as u64;
    if to > from + w {
        let mut per = vec![0.0f64; ((to - from) / w) as usize];
        for e in all_ends {
            if let Some(k) = e.checked_sub(from).map(|d| (d / w) as usize) {
                if k < per.len() {
                    per[k] += batch as f64;
                }
            }
        }
        r.fps_fast = percentile_f64(per, 90.0) * 1e9 / w as f64;
    }
    Ok(r)
}

/// CPUs the kernel has online (`/proc/stat` `cpuN` lines).
fn online_cpus() -> usize {
    std::fs::read_to_string("/proc/stat")
        .unwrap_or_default()
        .lines()
        .filter(|l| l.starts_with("cpu") && l.as_bytes().get(3).is_some_and(u8::is_ascii_digit))
        .count()
        .max(1)
}

/// One step of (d), (h) and (e): N sockets of `kind` on `ifindex`.
#[allow(clippy::too_many_arguments)]
fn sockets_step(
    c: &Config,
    tag: &str,
    stack: Stack,
    round: usize,
    ifindex: i32,
    n: usize,
    kind: Kind,
    base: Option<f64>,
    s: &mut Samples,
) -> Result<(), String> {
    let name = format!("{n} {}", kind.name());
    thread::sleep(SETTLE);
    let m0 = meminfo().map_err(|e| format!("/proc/meminfo: {e}"))?;
    let t0 = Instant::now();
    let mut socks = Vec::with_capacity(n);
    for i in 0..n {
        let sk = RawSocket::new().map_err(|e| format!("socket {i}: {e}"))?;
        sk.set_filters(&[kind.filter(i, c.masks)])
            .map_err(|e| format!("CAN_RAW_FILTER on socket {i}: {e}"))?;
        socks.push(sk);
    }
    let t1 = Instant::now();
    let tenth = (n / 10).max(1);
    let mut t_last = t1;
    // Every call is also timed on its own: the medians are what a busy
    // host moves least (the totals carry its descheduling).
    let mut bind_each = Vec::with_capacity(n);
    let mut t_prev = t1;
    for (i, sk) in socks.iter().enumerate() {
        if i == n - tenth {
            t_last = t_prev;
        }
        sk.bind(ifindex)
            .map_err(|e| format!("bind of socket {i}: {e}"))?;
        let t = Instant::now();
        bind_each.push((t - t_prev).as_secs_f64() * 1e6);
        t_prev = t;
    }
    let t2 = t_prev;
    let m1 = meminfo().map_err(|e| format!("/proc/meminfo: {e}"))?;
    let (open_s, bind_s) = ((t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
    let bind_last_us = (t2 - t_last).as_secs_f64() * 1e6 / tenth as f64;
    let per = |a: u64, b: u64| (b as f64 - a as f64) * 1024.0 / n as f64;
    let (slab, free, percpu) = (
        per(m0.slab, m1.slab),
        per(m1.free, m0.free),
        per(m0.percpu, m1.percpu),
    );
    println!(
        "{tag} (d) {name}: socket + filter {open_s:.3} s, bind {bind_s:.3} s ({:.1} us/socket; last tenth {bind_last_us:.1} us each)",
        bind_s * 1e6 / n as f64
    );
    println!(
        "{tag} (h) {name}: per socket Slab {slab:.0} B, MemFree drop {free:.0} B, Percpu {percpu:.0} B \
         (Slab {} -> {} KiB, MemFree {} -> {} KiB)",
        m0.slab, m1.slab, m0.free, m1.free
    );
    s.put(stack, round, format!("(d) {name}: bind, s"), 3, bind_s);
    s.put(
        stack,
        round,
        format!("(d) {name}: one bind at n~{n}, us"),
        1,
        bind_last_us,
    );
    s.put(stack, round, format!("(h) {name}: Slab, B/socket"), 0, slab);
    s.put(
        stack,
        round,
        format!("(h) {name}: MemFree drop, B/socket"),
        0,
        free,
    );

    // (e) with these sockets bound.
    let res = (|| -> Result<UnwantedRun, String> {
        let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
        let sentinel = workload::receiver(ifindex, SENTINEL_ID)
            .map_err(|e| format!("sentinel socket: {e}"))?;
        unwanted(&tx, &sentinel, c.unwanted_id, c.warmup, c.batch)
            .map_err(|e| format!("warm-up: {e}"))?;
        unwanted(&tx, &sentinel, c.unwanted_id, c.frames, c.batch).map_err(|e| e.to_string())
    })();
    match res {
        Ok(r) => {
            let stray: u64 = socks.iter().map(RawSocket::drain).sum();
            println!(
                "{tag} (e) {name}: {} frames: {:.0} ns/frame undisturbed, {:.0} whole run, kernel CPU {:.0} ns/frame; \
                 {} frame(s) reached the {n} sockets (want 0); odd {}, send retries {}, stalls {}",
                r.frames, r.ns_fast, r.ns_run, r.kernel_ns, stray, r.counts.odd, r.counts.send_retries, r.counts.stalls
            );
            Samples::count(&mut s.odd, stack, stray + r.counts.odd);
            s.put(
                stack,
                round,
                format!("(e) {name}: ns/frame, undisturbed"),
                0,
                r.ns_fast,
            );
            s.put(
                stack,
                round,
                format!("(e) {name}: ns/frame, whole run"),
                0,
                r.ns_run,
            );
            if let Some(b) = base {
                s.put(
                    stack,
                    round,
                    format!("(e) {name}: ns/frame over 0 rcv"),
                    0,
                    r.ns_fast - b,
                );
            }
        }
        Err(e) => {
            println!("{tag} FAILED: (e) {name}: {e}");
            s.errors
                .push(format!("{stack} round {round}: (e) {name}: {e}"));
        }
    }

    let t3 = Instant::now();
    let mut t_first = t3;
    let mut close_each = Vec::with_capacity(n);
    let mut t_prev = t3;
    for (i, sk) in socks.into_iter().enumerate() {
        drop(sk);
        let t = Instant::now();
        close_each.push((t - t_prev).as_secs_f64() * 1e6);
        t_prev = t;
        if i + 1 == tenth {
            t_first = t;
        }
    }
    let t4 = t_prev;
    let close_s = (t4 - t3).as_secs_f64();
    let close_first_us = (t_first - t3).as_secs_f64() * 1e6 / tenth as f64;
    println!(
        "{tag} (d) {name}: close {close_s:.3} s ({:.1} us/socket; first tenth {close_first_us:.1} us each); \
         bind + close {:.1} us/socket",
        close_s * 1e6 / n as f64,
        (bind_s + close_s) * 1e6 / n as f64
    );
    s.put(stack, round, format!("(d) {name}: close, s"), 3, close_s);
    s.put(
        stack,
        round,
        format!("(d) {name}: bind + close, s"),
        3,
        bind_s + close_s,
    );
    s.put(
        stack,
        round,
        format!("(d) {name}: one close at n~{n}, us"),
        1,
        close_first_us,
    );
    // The 10th percentiles too: a busy host lengthens some calls (the
    // guest's CPU descheduled) but rarely the fastest tenth, so on a
    // loaded host they compare builds more steadily than the medians.
    let (bind_p10, close_p10) = (
        percentile_f64(bind_each.clone(), FAST_PERCENTILE),
        percentile_f64(close_each.clone(), FAST_PERCENTILE),
    );
    let (bind_med, close_med) = (median(bind_each), median(close_each));
    println!("{tag} (d) {name}: per call, medians: bind {bind_med:.2} us, close {close_med:.2} us");
    println!(
        "{tag} (d) {name}: per call, 10th percentiles: bind {bind_p10:.2} us, close {close_p10:.2} us"
    );
    s.put(
        stack,
        round,
        format!("(d) {name}: bind, median us"),
        2,
        bind_med,
    );
    s.put(
        stack,
        round,
        format!("(d) {name}: close, median us"),
        2,
        close_med,
    );
    s.put(
        stack,
        round,
        format!("(d) {name}: bind + close, median us"),
        2,
        bind_med + close_med,
    );
    Ok(())
}

/// One round of one stack.
fn round(c: &Config, paths: &Paths, stack: Stack, r: usize, s: &mut Samples, broken: &mut bool) {
    let tag = format!("[{stack} {r}/{}]", c.rounds);
    let fail = |s: &mut Samples, what: String| {
        println!("{tag} FAILED: {what}");
        s.errors.push(format!("{stack} round {r}: {what}"));
    };
    println!("=== table part: {stack} stack, round {r}/{}", c.rounds);
    if c.load {
        if let Some(f) = stack::missing_module(stack, paths) {
            fail(s, format!("module not available: {}", f.display()));
            *broken = true;
            return;
        }
        let ifaces = [c.iface.as_str(), c.iface2.as_str()];
        if let Err(e) =
            stack::unload_all(&c.iface).and_then(|()| stack::load_devices(stack, paths, &ifaces))
        {
            fail(s, format!("setup: {e}"));
            *broken = true;
            let _ = stack::unload_all(&c.iface);
            return;
        }
    }
    let started = Instant::now();
    let body = |s: &mut Samples| -> Result<(), String> {
        let ifindex = can::ifindex(&c.iface).map_err(|e| format!("{}: {e}", c.iface))?;
        let counts: &[usize] = if c.sockets { &c.counts } else { &[] };
        // (e) baseline: no socket bound but the sender and the sentinel.
        let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
        let sentinel = workload::receiver(ifindex, SENTINEL_ID)
            .map_err(|e| format!("sentinel socket: {e}"))?;
        unwanted(&tx, &sentinel, c.unwanted_id, c.warmup, c.batch)
            .map_err(|e| format!("(e) warm-up: {e}"))?;
        let b = unwanted(&tx, &sentinel, c.unwanted_id, c.frames, c.batch)
            .map_err(|e| format!("(e) 0 rcv: {e}"))?;
        drop((tx, sentinel));
        println!(
            "{tag} (e) 0 rcv: {} frames: {:.0} ns/frame undisturbed, {:.0} whole run, kernel CPU {:.0} ns/frame; odd {}",
            b.frames, b.ns_fast, b.ns_run, b.kernel_ns, b.counts.odd
        );
        Samples::count(&mut s.odd, stack, b.counts.odd);
        s.put(
            stack,
            r,
            "(e) 0 rcv: ns/frame, undisturbed".into(),
            0,
            b.ns_fast,
        );
        s.put(
            stack,
            r,
            "(e) 0 rcv: ns/frame, whole run".into(),
            0,
            b.ns_run,
        );
        for &n in counts {
            for &k in &c.kinds {
                if let Err(e) = sockets_step(c, &tag, stack, r, ifindex, n, k, Some(b.ns_fast), s) {
                    fail(s, format!("(d) {n} {}: {e}", k.name()));
                }
            }
        }
        if c.fan {
            let mut cost = [0.0f64; 2];
            for (j, &n) in [1usize, 1000].iter().enumerate() {
                let tx = workload::sender(ifindex).map_err(|e| format!("sender socket: {e}"))?;
                let rxs = (0..n)
                    .map(|i| workload::receiver(ifindex, workload::FANOUT_BASE_ID + i as u32))
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|e| format!("(f) receiver sockets: {e}"))?;
                workload::fanout(&tx, &rxs, c.warmup, c.batch)
                    .map_err(|e| format!("(f) {n} rcv warm-up: {e}"))?;
                let f = workload::fanout(&tx, &rxs, c.fan_frames, c.batch)
                    .map_err(|e| format!("(f) {n} rcv: {e}"))?;
                println!(
                    "{tag} (f) {n} exact receiver(s), each frame for one: {:.0} ns/frame undisturbed, {:.0} whole run; lost {}, odd {}",
                    f.ns_fast, f.ns_per_frame, f.counts.lost, f.counts.odd
                );
                Samples::count(&mut s.odd, stack, f.counts.odd);
                Samples::count(&mut s.lost, stack, f.counts.lost);
                cost[j] = f.ns_fast;
                s.put(
                    stack,
                    r,
                    format!("(f) {n} rcv: ns/frame, undisturbed"),
                    0,
                    f.ns_fast,
                );
            }
            if cost[0] > 0.0 {
                s.put(
                    stack,
                    r,
                    "(f) cost 1000 : 1 rcv".into(),
                    2,
                    cost[1] / cost[0],
                );
            }
        }
        if c.pair {
            let cpus = online_cpus();
            let ifindex2 = can::ifindex(&c.iface2).map_err(|e| format!("{}: {e}", c.iface2));
            match (cpus, ifindex2) {
                (1, _) => println!("{tag} (g) only one CPU online: two senders not measured"),
                (_, Err(e)) => fail(s, format!("(g) {e}")),
                (_, Ok(ifindex2)) => {
                    let one = [(ifindex, 0)];
                    let two = [(ifindex, 0), (ifindex2, 1)];
                    let warm = (c.secs / 4.0).min(0.5);
                    pair(&two, warm, c.batch).map_err(|e| format!("(g) warm-up: {e}"))?;
                    let a =
                        pair(&one, c.secs, c.batch).map_err(|e| format!("(g) one sender: {e}"))?;
                    let d =
                        pair(&two, c.secs, c.batch).map_err(|e| format!("(g) two senders: {e}"))?;
                    for (what, x) in [("1 sender, CPU 0", &a), ("2 senders, CPUs 0+1", &d)] {
                        println!(
                            "{tag} (g) {what}: {:.0} frames/s, undisturbed {:.0} ({} + {} frames in {:.1} s); lost {}, odd {}, send retries {}, stalls {}",
                            x.fps,
                            x.fps_fast, x.per_lane[0], x.per_lane[1], c.secs, x.counts.lost, x.counts.odd,
                            x.counts.send_retries, x.counts.stalls
                        );
                        Samples::count(&mut s.odd, stack, x.counts.odd);
                        Samples::count(&mut s.lost, stack, x.counts.lost);
                    }
                    let figs = [
                        ("(g) 1 sender, frames/s, undisturbed", 0, a.fps_fast),
                        ("(g) 2 senders, frames/s, undisturbed", 0, d.fps_fast),
                        ("(g) 1 sender, frames/s, whole run", 0, a.fps),
                        ("(g) 2 senders, frames/s, whole run", 0, d.fps),
                    ];
                    for (key, prec, v) in figs {
                        s.put(stack, r, key.into(), prec, v);
                    }
                    if a.fps_fast > 0.0 {
                        s.put(
                            stack,
                            r,
                            "(g) 2 : 1 senders, undisturbed".into(),
                            2,
                            d.fps_fast / a.fps_fast,
                        );
                    }
                }
            }
        }
        Ok(())
    };
    if let Err(e) = body(s) {
        fail(s, e);
    }
    println!(
        "{tag} table workloads took {:.1} s",
        started.elapsed().as_secs_f64()
    );
    if c.load {
        stack::del_link(&c.iface2);
        if let Err(e) = stack::unload_all(&c.iface) {
            fail(s, format!("unload: {e}"));
            *broken = true;
        }
    }
}

/// Runs the table part on `stacks`; returns its samples (`summary`
/// formats them). `write_summary` is called after every round.
pub fn bench(
    c: &Config,
    stacks: &[Stack],
    paths: &Paths,
    write_summary: &dyn Fn(&Samples),
) -> Samples {
    let mut s = Samples::default();
    let mut broken = vec![false; stacks.len()];
    for r in 1..=c.rounds {
        let mut order: Vec<usize> = (0..stacks.len()).collect();
        if r % 2 == 0 {
            order.reverse();
        }
        for i in order {
            if !broken[i] {
                round(c, paths, stacks[i], r, &mut s, &mut broken[i]);
            }
        }
        write_summary(&s);
    }
    s
}

/// The summary: one row per figure, mainline, ours, ours/mainline of the
/// medians and its range round by round; then the targets.
pub fn summary(c: &Config, s: &Samples, header: &str) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "=== rcan-bench receive table ===");
    let _ = writeln!(o, "{header}");
    let _ = writeln!(
        o,
        "{} round(s), one run per figure and round; medians over rounds; sockets bound to {} (CAN_RAW, one filter each): {}",
        c.rounds,
        c.iface,
        c.kinds
            .iter()
            .map(|k| k.describe(c.masks))
            .collect::<Vec<_>>()
            .join("; ")
    );
    let _ = writeln!(
        o,
        "(e) {} frames of id {:#x} per run in batches of {}, each batch closed by one sentinel frame read back; \
         ns/frame = wall time of a batch / its {} frames (fastest tenth: undisturbed)",
        c.frames,
        c.unwanted_id,
        c.batch,
        c.batch + 1
    );
    let _ = writeln!(
        o,
        "(g) {} s per run, each sender thread (CPU 0: {}, CPU 1: {}) sends {} frames to its own device and reads them back; \
         undisturbed: the {} ms window with the fastest tenth of frame counts while all threads ran",
        c.secs,
        c.iface,
        c.iface2,
        c.batch,
        PAIR_WINDOW.as_millis()
    );
    let _ = writeln!(
        o,
        "{:<46} {:>10} {:>10} {:>14} {:>12}",
        "figure (medians)", "mainline", "ours", "ours/mainline", "per round"
    );
    let ratios = |key: &str| -> Vec<f64> {
        (1..=c.rounds)
            .filter_map(|r| {
                let m = s.get(Stack::Mainline, Some(r), key)?;
                let o = s.get(Stack::Ours, Some(r), key)?;
                (m > 0.0).then(|| o / m)
            })
            .collect()
    };
    let range = |v: &[f64]| -> String {
        match (
            v.iter().copied().reduce(f64::min),
            v.iter().copied().reduce(f64::max),
        ) {
            (Some(lo), Some(hi)) if v.len() > 1 => format!("{lo:.2}-{hi:.2}x"),
            _ => String::new(),
        }
    };
    for (key, prec) in &s.keys {
        let m = s.get(Stack::Mainline, None, key);
        let ov = s.get(Stack::Ours, None, key);
        let cell = |v: Option<f64>| v.map_or_else(|| "-".to_string(), |v| format!("{v:.prec$}"));
        // A difference can be negative or near 0: no ratio.
        let ratio = match (ov, m) {
            (Some(a), Some(b)) if b > 0.0 && !key.contains("over 0 rcv") => {
                format!("{:.2}x", a / b)
            }
            _ => "-".to_string(),
        };
        let rr = if key.contains("over 0 rcv") {
            String::new()
        } else {
            range(&ratios(key))
        };
        let line = format!(
            "{key:<46} {:>10} {:>10} {ratio:>14} {rr:>12}",
            cell(m),
            cell(ov)
        );
        let _ = writeln!(o, "{}", line.trim_end());
    }
    let _ = writeln!(o);
    let verdict = |key: &str, want: &str, ok: &dyn Fn(f64, f64) -> bool| -> String {
        match (
            s.get(Stack::Ours, None, key),
            s.get(Stack::Mainline, None, key),
        ) {
            (Some(a), Some(b)) => format!(
                "ours {a:.4} vs mainline {b:.4}{}, want {want}: target {}",
                match range(&ratios(key)).as_str() {
                    "" => String::new(),
                    x => format!(" (ratio per round {x})"),
                },
                if ok(a, b) { "met" } else { "missed" }
            ),
            _ => "needs both stacks: target not measured".to_string(),
        }
    };
    if let Some(&n) = c.counts.iter().max() {
        for k in &c.kinds {
            let key = format!("(d) {n} {}: bind + close, s", k.name());
            let _ = writeln!(
                o,
                "(d) {n} sockets, {}: bind + close: {}",
                k.name(),
                verdict(&key, "ours <= mainline", &|a, b| a <= b)
            );
        }
        for k in [Kind::Masked, Kind::Masks] {
            if c.kinds.contains(&k) {
                let key = format!("(e) {n} {}: ns/frame, undisturbed", k.name());
                let _ = writeln!(
                    o,
                    "(e) unwanted frame, {n} {} filters: {}",
                    k.name(),
                    verdict(&key, "ours <= mainline", &|a, b| a <= b)
                );
            }
        }
    }
    if let Some(x) = s.get(Stack::Ours, None, "(f) cost 1000 : 1 rcv") {
        let _ = writeln!(
            o,
            "(f) ours: cost 1000 : 1 exact receivers = {x:.2}x, want <= 1.5x: target {} (mainline {})",
            if x <= 1.5 { "met" } else { "missed" },
            s.get(Stack::Mainline, None, "(f) cost 1000 : 1 rcv")
                .map_or_else(|| "-".to_string(), |m| format!("{m:.2}x"))
        );
    }
    for (st, n) in &s.odd {
        if *n > 0 {
            let _ = writeln!(
                o,
                "NOTE {st}: {n} frame(s) reached a socket that did not want them, or came late or stale"
            );
        }
    }
    for (st, n) in &s.lost {
        if *n > 0 {
            let _ = writeln!(o, "NOTE {st}: {n} frame(s) lost");
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

    fn matches(frame_id: u32, (id, mask): (u32, u32)) -> bool {
        (frame_id & mask) == (id & mask)
    }

    /// No socket of any kind wants the unwanted or the sentinel frame,
    /// for every socket number the benchmark uses.
    #[test]
    fn nobody_wants_the_probe_frames() {
        for k in Kind::ALL {
            for i in 0..20_000 {
                let f = k.filter(i, 64);
                assert!(!matches(UNWANTED_ID, f), "{k:?} socket {i}: {f:x?}");
                assert!(!matches(SENTINEL_ID, f), "{k:?} socket {i}: {f:x?}");
                assert!(f.0 <= 0x7ff && f.1 != 0, "{k:?} socket {i}: {f:x?}");
            }
        }
    }

    #[test]
    fn kinds_spread_as_documented() {
        use std::collections::BTreeSet;
        let set = |k: Kind, n: usize, m: usize| -> BTreeSet<(u32, u32)> {
            (0..n).map(|i| k.filter(i, m)).collect()
        };
        // Exact: every 11-bit id but the two probes, once per 2046 sockets.
        let e = set(Kind::Exact, 2046, 64);
        assert_eq!(e.len(), 2046);
        assert!(e.iter().all(|&(_, m)| m == EXACT_SFF_MASK));
        assert_eq!(set(Kind::Same, 1000, 64).len(), 1);
        // Masked: one mask, 127 groups.
        let g: BTreeSet<u32> = (0..10_000)
            .map(|i| Kind::Masked.filter(i, 64))
            .map(|(id, m)| id & m)
            .collect();
        assert_eq!(g.len(), 127);
        // Masks: exactly `m` distinct masks, none exact.
        for m in [1, 64, 255] {
            let masks: BTreeSet<u32> = (0..10_000).map(|i| Kind::Masks.filter(i, m).1).collect();
            assert_eq!(masks.len(), m);
            assert!(!masks.contains(&0x7ff));
        }
    }
}
