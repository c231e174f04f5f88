// SPDX-License-Identifier: GPL-2.0
//! The three workloads, each one measurement run; `main` warms up, repeats
//! and takes medians.
//!
//! Frames carry two little-endian 32-bit words: a sequence number and a run
//! tag, so a receiver can tell lost, late and stale frames apart. Senders
//! install an empty `CAN_RAW_FILTER` (they receive nothing) and keep
//! `CAN_RAW_LOOPBACK` on, so the echoing device hands every frame back to
//! the receive path, where the receiver sockets pick it up.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use crate::can::{pin_current_thread, send_retrying, Frame, RawSocket, Shape, EXACT_SFF_MASK};

/// Identifier used by the throughput workload.
pub const TP_ID: u32 = 0x123;
/// Identifier used by the latency workload.
pub const LAT_ID: u32 = 0x321;
/// First identifier of the fan-out receivers (`FANOUT_BASE_ID + i`).
pub const FANOUT_BASE_ID: u32 = 0x010;
/// Receive buffer asked of every receiver socket: far more than any
/// window or batch the workloads keep in flight.
pub const RCVBUF: usize = 4 << 20;
/// `SO_RCVTIMEO` of every receiver: a blocking receive that waits this
/// long counts as a stall.
const RECV_TIMEOUT: Duration = Duration::from_secs(1);
/// A frame is lost after this many stalls in a row.
const STALLS_PER_LOSS: u64 = 3;
/// Throughput is also timed chunk by chunk, over this many frames received
/// (a few sender/receiver cycles of the window; about 10 ms here).
pub const CHUNK: u64 = 512;
/// The "undisturbed" figures of (a) and (b) come from this percentile of
/// the chunk (batch) times: the fastest tenth, which the moments the host
/// does not run the VM rarely reach.
pub const FAST_PERCENTILE: f64 = 10.0;
/// A run gives up after this many lost frames.
const MAX_LOST: u64 = 10;

/// A fresh tag per run, so that frames of an earlier (aborted) run are
/// recognised as stale.
pub fn next_tag() -> u32 {
    static TAG: AtomicU64 = AtomicU64::new(1);
    TAG.fetch_add(1, Ordering::Relaxed) as u32
}

/// A pure sender on `ifindex`: empty filter, loopback on.
pub fn sender(ifindex: i32) -> io::Result<RawSocket> {
    let s = RawSocket::new()?;
    s.set_filters(&[])?;
    s.set_loopback(true)?;
    s.bind(ifindex)?;
    Ok(s)
}

/// A receiver of exactly the 11-bit data frame `id` on `ifindex`, with a
/// large receive buffer and a receive timeout.
pub fn receiver(ifindex: i32, id: u32) -> io::Result<RawSocket> {
    let s = RawSocket::new()?;
    s.set_filters(&[(id, EXACT_SFF_MASK)])?;
    s.set_rcvbuf(RCVBUF)?;
    s.set_rcvtimeo(RECV_TIMEOUT)?;
    s.bind(ifindex)?;
    Ok(s)
}

/// Frame accounting common to all workloads.
#[derive(Clone, Copy, Debug, Default)]
pub struct Counts {
    /// Frames handed to `send()`.
    pub sent: u64,
    /// Frames received by the socket they were meant for, in order.
    pub received: u64,
    /// Frames that never arrived (sequence gaps, receive timeouts).
    pub lost: u64,
    /// Frames that arrived out of order, at the wrong socket, or from an
    /// earlier run.
    pub odd: u64,
    /// `send()` calls retried because the device queue pushed back.
    pub send_retries: u64,
    /// Blocking receives that waited a whole `RECV_TIMEOUT` (1 s).
    pub stalls: u64,
}

/// Blocking receive on `rx` that tolerates `STALLS_PER_LOSS - 1` timeouts
/// (counted in `c.stalls`); `None` if nothing came at all.
pub fn recv_patient(rx: &RawSocket, c: &mut Counts) -> io::Result<Option<Frame>> {
    for _ in 0..STALLS_PER_LOSS {
        match rx.recv(false) {
            Ok(f) => return Ok(Some(f)),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => c.stalls += 1,
            Err(e) => return Err(e),
        }
    }
    Ok(None)
}

/// Error for a run with too many lost frames.
fn too_many_lost(c: &Counts, what: &str) -> io::Error {
    io::Error::other(format!(
        "{} frames not received within {} s each ({what}, {} frames sent so far); giving up",
        c.lost,
        STALLS_PER_LOSS * RECV_TIMEOUT.as_secs(),
        c.sent
    ))
}

/// One throughput run.
#[derive(Clone, Copy, Debug)]
pub struct ThroughputRun {
    pub counts: Counts,
    pub elapsed: Duration,
    /// Frames received per second over the whole run.
    pub fps: f64,
    /// Rate of a chunk of `CHUNK` received frames at the `FAST_PERCENTILE`
    /// of the chunk times: the undisturbed rate.
    pub fps_fast: f64,
}

/// Shared state between the throughput sender and receiver threads.
struct Window {
    /// Next sequence number the receiver expects (all below it are accounted
    /// for: received or lost).
    upto: AtomicU64,
    /// Receiver gave up or finished.
    finished: AtomicBool,
    /// Sender is (about to be) asleep on `cv`.
    waiting: AtomicBool,
    /// The sender wants to be woken once `upto` reaches this.
    wake_at: AtomicU64,
    lock: Mutex<()>,
    cv: Condvar,
}

impl Window {
    /// Wakes the sender if it sleeps and `upto` reached its mark (or
    /// unconditionally with `force`).
    fn wake_sender(&self, force: bool) {
        if self.waiting.load(Ordering::SeqCst)
            && (force || self.upto.load(Ordering::SeqCst) >= self.wake_at.load(Ordering::SeqCst))
        {
            let _g = self.lock.lock().unwrap_or_else(|e| e.into_inner());
            self.cv.notify_one();
        }
    }
}

/// Workload (a): `frames` frames from `tx` to `rx` (a receiver of
/// `TP_ID`), at most `window` in flight, the receiver in its own thread
/// (pinned to `rx_cpu` if given; else it inherits the caller's affinity).
/// Frames per second = frames received / time from the start to the last
/// receive; the undisturbed rate comes from the receiver's timestamps of
/// every `CHUNK`-th frame.
pub fn throughput(
    tx: &RawSocket,
    rx: &RawSocket,
    frames: u64,
    window: u64,
    rx_cpu: Option<usize>,
) -> io::Result<ThroughputRun> {
    throughput_shaped(tx, rx, frames, window, rx_cpu, Shape::CLASSIC8)
}

/// Workload (a) with frames of `shape` (the FD part: 64-byte FD frames;
/// both sockets need `CAN_RAW_FD_FRAMES` for those). A frame received in
/// another shape counts as odd.
pub fn throughput_shaped(
    tx: &RawSocket,
    rx: &RawSocket,
    frames: u64,
    window: u64,
    rx_cpu: Option<usize>,
    shape: Shape,
) -> io::Result<ThroughputRun> {
    let stale = rx.drain();
    let tag = next_tag();
    let w = Window {
        upto: AtomicU64::new(0),
        finished: AtomicBool::new(false),
        waiting: AtomicBool::new(false),
        wake_at: AtomicU64::new(0),
        lock: Mutex::new(()),
        cv: Condvar::new(),
    };
    let start = Instant::now();
    let (send_res, recv_res) = thread::scope(|s| {
        let receiver = s.spawn(|| -> io::Result<(Counts, Instant, Vec<f64>)> {
            if let Some(cpu) = rx_cpu {
                if let Err(e) = pin_current_thread(cpu) {
                    w.finished.store(true, Ordering::SeqCst);
                    return Err(io::Error::other(format!(
                        "pinning the receiver to CPU {cpu}: {e}"
                    )));
                }
            }
            let mut c = Counts {
                odd: stale,
                ..Counts::default()
            };
            let mut expected = 0u64;
            let mut last = Instant::now();
            let mut chunk_start = start;
            let mut chunk_ns = Vec::with_capacity((frames / CHUNK) as usize);
            let res = loop {
                if expected >= frames {
                    break Ok(());
                }
                match recv_patient(rx, &mut c) {
                    Ok(Some(f)) => {
                        let seq = u64::from(f.seq());
                        if f.tag() != tag || f.id != TP_ID || f.shape() != shape || seq < expected {
                            // Stale, foreign, or late (out of order).
                            c.odd += 1;
                        } else {
                            c.received += 1;
                            expected = seq + 1;
                            last = Instant::now();
                            if c.received.is_multiple_of(CHUNK) {
                                chunk_ns.push(last.duration_since(chunk_start).as_nanos() as f64);
                                chunk_start = last;
                            }
                            w.upto.store(expected, Ordering::SeqCst);
                            w.wake_sender(false);
                        }
                    }
                    // Nothing for a while: whatever is missing is lost.
                    Ok(None) => break Ok(()),
                    Err(e) => break Err(e),
                }
            };
            w.finished.store(true, Ordering::SeqCst);
            w.wake_sender(true);
            res.map(|()| (c, last, chunk_ns))
        });

        let sender = || -> io::Result<(u64, u64)> {
            let mut retries = 0;
            let mut known = 0u64;
            for seq in 0..frames {
                if seq - known >= window {
                    // Window full: sleep until it has drained to half, so
                    // that sender and receiver do not wake each other for
                    // every frame.
                    let wake_at = seq - window / 2;
                    let mut g = w.lock.lock().unwrap_or_else(|e| e.into_inner());
                    w.wake_at.store(wake_at, Ordering::SeqCst);
                    loop {
                        w.waiting.store(true, Ordering::SeqCst);
                        known = w.upto.load(Ordering::SeqCst);
                        if known >= wake_at || w.finished.load(Ordering::SeqCst) {
                            break;
                        }
                        g =
                            w.cv.wait_timeout(g, Duration::from_millis(100))
                                .unwrap_or_else(|e| e.into_inner())
                                .0;
                    }
                    w.waiting.store(false, Ordering::SeqCst);
                    if w.finished.load(Ordering::SeqCst) {
                        return Ok((seq, retries));
                    }
                }
                retries += send_retrying(tx, &Frame::shaped(TP_ID, seq as u32, tag, shape))?;
            }
            Ok((frames, retries))
        };
        let send_res = sender();
        (send_res, receiver.join().expect("receiver thread panicked"))
    });
    let (sent, send_retries) = send_res?;
    let (mut counts, last, chunk_ns) = recv_res?;
    counts.sent = sent;
    counts.send_retries = send_retries;
    counts.lost = sent.saturating_sub(counts.received);
    let elapsed = last.saturating_duration_since(start);
    let fps = if elapsed.is_zero() {
        0.0
    } else {
        counts.received as f64 / elapsed.as_secs_f64()
    };
    Ok(ThroughputRun {
        counts,
        elapsed,
        fps,
        fps_fast: match percentile_f64(chunk_ns, FAST_PERCENTILE) {
            ns if ns > 0.0 => CHUNK as f64 * 1e9 / ns,
            _ => 0.0,
        },
    })
}

/// One fan-out run.
#[derive(Clone, Copy, Debug)]
pub struct FanoutRun {
    pub counts: Counts,
    pub elapsed: Duration,
    /// Wall time per frame sent and received over the whole run, in ns.
    pub ns_per_frame: f64,
    /// Time per frame of a full batch at the `FAST_PERCENTILE` of the
    /// batch times, in ns: the undisturbed cost.
    pub ns_fast: f64,
    /// Time it took to open, filter and bind the receiver sockets (set by
    /// the caller, who opens them).
    pub setup: Duration,
}

/// Workload (b): `frames` frames from `tx`, round-robin over the
/// identifiers of `rxs` (receiver `i` takes exactly `FANOUT_BASE_ID + i`),
/// in batches of `batch`: send the batch, then read each frame from the
/// socket it was meant for. One thread; cost per frame = elapsed / frames,
/// and the undisturbed cost from the time of each full batch.
pub fn fanout(tx: &RawSocket, rxs: &[RawSocket], frames: u64, batch: u64) -> io::Result<FanoutRun> {
    let n = rxs.len() as u64;
    let mut c = Counts {
        odd: rxs.iter().map(RawSocket::drain).sum(),
        ..Counts::default()
    };
    let tag = next_tag();
    let start = Instant::now();
    let mut first = 0u64;
    let mut batch_ns = Vec::with_capacity((frames / batch) as usize);
    while first < frames {
        let end = (first + batch).min(frames);
        let t = Instant::now();
        for seq in first..end {
            let id = FANOUT_BASE_ID + (seq % n) as u32;
            c.send_retries += send_retrying(tx, &Frame::with_words(id, seq as u32, tag))?;
            c.sent += 1;
        }
        for seq in first..end {
            let i = (seq % n) as usize;
            match recv_patient(&rxs[i], &mut c)? {
                Some(f)
                    if f.tag() == tag
                        && f.seq() == seq as u32
                        && f.id == FANOUT_BASE_ID + i as u32 =>
                {
                    c.received += 1
                }
                Some(_) => c.odd += 1,
                None => {
                    c.lost += 1;
                    if c.lost >= MAX_LOST {
                        return Err(too_many_lost(&c, &format!("{n} receivers")));
                    }
                }
            }
        }
        if end - first == batch {
            batch_ns.push(t.elapsed().as_nanos() as f64 / batch as f64);
        }
        first = end;
    }
    let elapsed = start.elapsed();
    // Anything still queued went to a socket that should not have had it.
    c.odd += rxs.iter().map(RawSocket::drain).sum::<u64>();
    Ok(FanoutRun {
        counts: c,
        elapsed,
        ns_per_frame: elapsed.as_nanos() as f64 / frames.max(1) as f64,
        ns_fast: percentile_f64(batch_ns, FAST_PERCENTILE),
        setup: Duration::ZERO,
    })
}

/// One latency run: the sorted per-frame latencies.
#[derive(Clone, Debug)]
pub struct LatencyRun {
    pub counts: Counts,
    /// Send-to-receive latencies of the received frames, sorted, in ns.
    pub sorted_ns: Vec<u64>,
}

impl LatencyRun {
    /// The `p`-th percentile (nearest rank), in ns.
    pub fn percentile(&self, p: f64) -> u64 {
        percentile(&self.sorted_ns, p)
    }
}

/// Median of `v` (0 if empty).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => 0.0,
        _ if n % 2 == 1 => v[n / 2],
        _ => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// Nearest-rank percentile of `v`, unsorted (0 if empty).
pub fn percentile_f64(mut v: Vec<f64>, p: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * v.len() as f64).ceil() as usize;
    v[rank.clamp(1, v.len()) - 1]
}

/// Nearest-rank percentile of sorted `v` (0 if empty).
pub fn percentile(v: &[u64], p: f64) -> u64 {
    if v.is_empty() {
        return 0;
    }
    let rank = ((p / 100.0) * v.len() as f64).ceil() as usize;
    v[rank.clamp(1, v.len()) - 1]
}

/// Workload (c): `frames` times: read CLOCK_MONOTONIC (`Instant`), send one
/// frame on `tx`, block in `recv()` on `rx` (a receiver of `LAT_ID`) until
/// it is there, read the clock again. One frame in flight, one thread.
pub fn latency(tx: &RawSocket, rx: &RawSocket, frames: u64) -> io::Result<LatencyRun> {
    let mut c = Counts {
        odd: rx.drain(),
        ..Counts::default()
    };
    let tag = next_tag();
    let mut lat = Vec::with_capacity(frames as usize);
    for seq in 0..frames {
        let f = Frame::with_words(LAT_ID, seq as u32, tag);
        let t0 = Instant::now();
        c.send_retries += send_retrying(tx, &f)?;
        c.sent += 1;
        loop {
            match recv_patient(rx, &mut c)? {
                Some(g) if g == f => {
                    lat.push(t0.elapsed().as_nanos() as u64);
                    c.received += 1;
                    break;
                }
                // A stale or late frame: keep waiting for this one.
                Some(_) => c.odd += 1,
                None => {
                    c.lost += 1;
                    if c.lost >= MAX_LOST {
                        return Err(too_many_lost(&c, "latency"));
                    }
                    break;
                }
            }
        }
    }
    lat.sort_unstable();
    Ok(LatencyRun {
        counts: c,
        sorted_ns: lat,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank() {
        let v: Vec<u64> = (1..=100).collect();
        assert_eq!(percentile(&v, 50.0), 50);
        assert_eq!(percentile(&v, 99.0), 99);
        assert_eq!(percentile(&v, 100.0), 100);
        assert_eq!(percentile(&[7], 99.0), 7);
        assert_eq!(percentile(&[], 50.0), 0);
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
        assert_eq!(median(Vec::new()), 0.0);
        let w: Vec<f64> = (1..=100).rev().map(f64::from).collect();
        assert_eq!(percentile_f64(w, 10.0), 10.0);
        assert_eq!(percentile_f64(Vec::new(), 10.0), 0.0);
    }
}
