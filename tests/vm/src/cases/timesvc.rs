// SPDX-License-Identifier: GPL-2.0
//! The DSOR time services, `rcan_time` and `rcan_rtime` (thesis 5.3.3;
//! Documentation/networking/rcan/time.rst): the time frame once per second
//! with the right identifier and payload, and how far after the second
//! boundary it arrives; parameters; the interface going down and up and
//! being re-registered; clock steps; unloading while sending; the
//! redundant service staying silent while a user-space "GPS node" sends,
//! taking over when it stops and handing back when it resumes.
//!
//! Frames are received on a CAN_RAW socket (the `socketcan` crate) with
//! `SO_TIMESTAMPNS`. The VM is software-emulated and shared, so timing
//! bounds are generous and the measured numbers are printed, not
//! asserted tightly.

use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use socketcan::{CanSocket, Socket, SocketOptions};

use super::{raw1, raw2, test_table};
use crate::canraw::{self, CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
use crate::check::{ensure, wait_until, OrFail, TestResult, SETTLE};
use crate::ctx::{dev, sized, tool, Ctx, Kmsg, Module};
use crate::Test;

pub const TESTS: &[Test] = test_table![
    time_frames_1hz,
    time_params,
    time_dev_down_up,
    time_clock_step,
    time_unload,
    rtime_takeover_handback,
    rtime_silent_with_local_time,
];

/// The default vehicle identifier, the time frame's CAN id.
const VEHICLE: u32 = 0xc0;
/// `rcan_rtime`'s default takeover timeout.
const TIMEOUT: Duration = Duration::from_millis(2500);
/// Source byte values of the time frame.
const SRC_GPS: u8 = 0;
const SRC_TIME: u8 = 1;
const SRC_RTIME: u8 = 2;

/// One received frame.
#[derive(Clone, Copy, Debug)]
struct Rx {
    /// When the capture thread got it (monotonic; for gaps across clock
    /// steps).
    mono: Instant,
    /// The kernel's receive timestamp (`SO_TIMESTAMPNS`, CLOCK_REALTIME).
    ts: SystemTime,
    /// The 16 bytes of `struct can_frame`.
    wire: [u8; 16],
}

impl Rx {
    fn can_id(&self) -> u32 {
        u32::from_ne_bytes([self.wire[0], self.wire[1], self.wire[2], self.wire[3]])
    }
    fn len(&self) -> u8 {
        self.wire[4]
    }
    fn data(&self) -> &[u8] {
        &self.wire[8..]
    }
    /// Bytes 0-3: the UNIX second, big-endian.
    fn second(&self) -> u64 {
        u64::from(u32::from_be_bytes([
            self.wire[8],
            self.wire[9],
            self.wire[10],
            self.wire[11],
        ]))
    }
    fn source(&self) -> u8 {
        self.wire[12]
    }
    fn ts_ns(&self) -> i128 {
        unix_ns(self.ts)
    }
    fn show(&self) -> String {
        format!(
            "{:03X}#{} at {}",
            self.can_id(),
            self.data()
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect::<String>(),
            show_time(self.ts)
        )
    }
}

fn unix_ns(t: SystemTime) -> i128 {
    match t.duration_since(UNIX_EPOCH) {
        Ok(d) => d.as_nanos() as i128,
        Err(e) => -(e.duration().as_nanos() as i128),
    }
}

fn show_time(t: SystemTime) -> String {
    let ns = unix_ns(t);
    format!(
        "{}.{:09}",
        ns.div_euclid(1_000_000_000),
        ns.rem_euclid(1_000_000_000)
    )
}

/// Checks the frame format of the DSOR wire specification: standard id
/// `vehicle`, DLC 8, source `source`, bytes 5-7 zero, and the named second
/// within one of the receive timestamp's.
fn check_format(f: &Rx, vehicle: u32, source: u8) -> TestResult {
    ensure!(
        f.can_id() == vehicle && f.len() == 8,
        "not a time frame for {vehicle:#x}: {}",
        f.show()
    );
    ensure!(
        f.source() == source,
        "source {} (want {source}): {}",
        f.source(),
        f.show()
    );
    ensure!(
        f.data()[5..] == [0, 0, 0],
        "reserved bytes not zero: {}",
        f.show()
    );
    let ts_sec = f.ts_ns().div_euclid(1_000_000_000) as i64;
    ensure!(
        (f.second() as i64 - ts_sec).abs() <= 1,
        "frame names second {} but arrived at {}",
        f.second(),
        show_time(f.ts)
    );
    Ok(())
}

const SEC: i128 = 1_000_000_000;
const MSEC: i128 = 1_000_000;

/// The seconds jumped over between consecutive frames of one service:
/// each frame must name a later second than the one before (never two
/// frames for one second, never one back); a frame naming k > 1 seconds
/// after its predecessor leaves k - 1 seconds without a frame, which the
/// caller must have explained by the service's own count of seconds missed
/// to a late timer ([`ensure_explained`]).
fn jumped<'a>(pairs: impl Iterator<Item = (&'a Rx, &'a Rx)>, who: &str) -> Result<u64, String> {
    let mut n = 0;
    for (a, b) in pairs {
        ensure!(
            b.second() > a.second(),
            "{who}: {} then {}: a second named twice or out of order",
            a.show(),
            b.show()
        );
        n += b.second() - a.second() - 1;
    }
    Ok(n)
}

/// Checks the spacing of consecutive frames of one service, `frames` in
/// the order received, by their receive timestamps, and returns the
/// seconds jumped over ([`jumped`]). `lo..=hi` is the test's bound for
/// the gap between two frames naming consecutive seconds, which assumes
/// both came near the start of their seconds. Timer callbacks that run
/// late (a stalled guest) move a frame later in its second, or past it:
///
/// * A frame naming k > 1 seconds after its predecessor comes from a
///   callback at least k - 1 s late: k - 1 whole seconds later than an
///   on-time one, and anywhere in the second it names (the callback names
///   the second it runs in): its gap must be at least `lo + (k - 1) s`,
///   and at most what the next point allows.
/// * A callback late by less than a second sends a frame late in its own
///   second. Such a frame may come up to the end of the second it names,
///   so the gap before it may reach `(k + 1) s` minus the predecessor's
///   offset in its second, if that is more than the usual bound. A frame
///   received `1 s - lo` or more into its second (but before its end) may
///   be followed by an on-time frame less than `lo` later: then that one
///   must not have been received before the start of the second it names
///   (its gap is at least `k s` minus the predecessor's offset).
///
/// Otherwise never under `lo` after the previous frame, whatever k. Two
/// frames for one second, a drifting service (each frame later in its
/// second), or a catch-up burst (frames received after the second they
/// name has ended) still fail.
fn check_spacing(frames: &[Rx], lo: i128, hi: i128, who: &str) -> Result<u64, String> {
    let n = jumped(frames.windows(2).map(|w| (&w[0], &w[1])), who)?;
    for w in frames.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        let k = (b.second() - a.second()) as i128;
        let g = b.ts_ns() - a.ts_ns();
        // Where in the second it names the earlier frame was received.
        let off_a = a.ts_ns() - a.second() as i128 * SEC;
        let min = if (SEC - lo..SEC).contains(&off_a) {
            k * SEC - off_a
        } else {
            lo + (k - 1) * SEC
        };
        let max = (hi + (k - 1) * SEC).max((k + 1) * SEC - off_a);
        ensure!(
            (min..=max).contains(&g),
            "{who}: frames {} ms apart, naming seconds {k} apart (want {} to {} ms): {} then {}",
            g / MSEC,
            min / MSEC,
            max / MSEC,
            a.show(),
            b.show()
        );
    }
    Ok(n)
}

/// Seconds jumped over between frames (`what`: which) are accepted only
/// as far as the service counted seconds missed to a late timer callback.
fn ensure_explained(jumped: u64, missed: u64, who: &str, what: &str) -> TestResult {
    ensure!(
        jumped <= missed,
        "{who}: {jumped} second(s) to explain ({what}), but the service counted {missed} \
         second(s) missed (late timer)"
    );
    Ok(())
}

/// The counters of a time service's exit log line (`rcan_time: stopped:
/// 30 frames sent, 0 seconds skipped, 1 seconds missed (late timer), ...`).
#[derive(Debug, Default, PartialEq)]
struct Stopped {
    sent: u64,
    skipped: u64,
    missed: u64,
}

/// Parses the exit log line of `module` among `lines`.
fn parse_stopped(lines: &[String], module: &str) -> Result<Stopped, String> {
    let head = format!("{module}: stopped: ");
    let line = lines
        .iter()
        .rev()
        .find_map(|l| l.split_once(&head).map(|(_, rest)| rest))
        .ok_or_else(|| format!("no '{head}' line in the kernel log: {lines:?}"))?;
    let counter = |label: &str| -> Result<u64, String> {
        line.split(", ")
            .find_map(|part| part.strip_suffix(label)?.trim().parse().ok())
            .ok_or_else(|| format!("no '{label}' in '{head}{line}'"))
    };
    Ok(Stopped {
        sent: counter("frames sent")?,
        skipped: counter("seconds skipped")?,
        missed: counter("seconds missed (late timer)")?,
    })
}

/// Unloads `m` (a time service) and reads its counters from the exit log
/// line, which module exit prints before rmmod returns.
fn rmmod_stopped(
    ctx: &mut Ctx,
    m: Module,
    k: &mut Kmsg,
    seen: &mut Vec<String>,
) -> Result<Stopped, String> {
    ctx.rmmod(m)?;
    seen.extend(k.read_new()?);
    parse_stopped(seen, m.name())
}

/// A thread receiving every time frame on one interface.
struct Capture {
    frames: Arc<Mutex<Vec<Rx>>>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Capture {
    /// Starts capturing standard data frames with id `vehicle` on
    /// `ifindex`.
    fn start(ifindex: u32, vehicle: u32) -> Result<Capture, String> {
        let s = canraw::open(ifindex)?;
        s.set_filters(&[(vehicle, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG)])
            .or_fail("CAN_RAW_FILTER")?;
        s.set_recv_timestamp(true).or_fail("SO_TIMESTAMPNS")?;
        s.set_read_timeout(Duration::from_millis(200))
            .or_fail("SO_RCVTIMEO")?;
        let frames = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (f, st) = (Arc::clone(&frames), Arc::clone(&stop));
        let handle = thread::spawn(move || capture_loop(&s, &f, &st));
        Ok(Capture {
            frames,
            stop,
            handle: Some(handle),
        })
    }

    /// The frames so far.
    fn frames(&self) -> Vec<Rx> {
        self.frames
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Waits up to `limit` for a frame (received from now on, or already
    /// there) satisfying `pred`.
    fn wait_for(&self, limit: Duration, pred: impl Fn(&Rx) -> bool) -> Option<Rx> {
        let end = Instant::now() + limit;
        loop {
            if let Some(f) = self.frames().into_iter().find(&pred) {
                return Some(f);
            }
            if Instant::now() > end {
                return None;
            }
            // The poll interval of this wait, not synchronisation.
            thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits until `n` frames satisfying `pred` have been captured (from
    /// the start), failing after [`SETTLE`]: progress counted in the
    /// service's own ticks, not in the guest's seconds.
    fn wait_count(&self, n: usize, what: &str, pred: impl Fn(&Rx) -> bool) -> TestResult {
        wait_until(SETTLE, what, || {
            self.frames().iter().filter(|f| pred(f)).count() >= n
        })
    }

    /// Stops and returns everything captured.
    fn finish(mut self) -> Vec<Rx> {
        self.halt();
        self.frames()
    }

    fn halt(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        self.halt();
    }
}

fn capture_loop(s: &CanSocket, frames: &Mutex<Vec<Rx>>, stop: &AtomicBool) {
    while !stop.load(Ordering::Relaxed) {
        match s.read_frame_with_timestamp() {
            Ok((f, ts)) => {
                let rx = Rx {
                    mono: Instant::now(),
                    ts,
                    wire: canraw::wire(&f),
                };
                frames.lock().unwrap_or_else(|e| e.into_inner()).push(rx);
            }
            // Timeouts, and ENETDOWN/ENODEV reported once when the
            // interface goes down or away: keep listening (the 5 ms only
            // keep a gone interface from spinning the loop).
            Err(_) => thread::sleep(Duration::from_millis(5)),
        }
    }
}

/// p50, p99 and max of `v` (sorted in place).
fn percentiles(v: &mut [i128]) -> (i128, i128, i128) {
    v.sort_unstable();
    let at = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    (at(0.50), at(0.99), v[v.len() - 1])
}

/// Gaps between consecutive frames, by the time the capture thread got
/// them (monotonic).
fn gaps(frames: &[Rx]) -> Vec<Duration> {
    frames
        .windows(2)
        .map(|w| w[1].mono.duration_since(w[0].mono))
        .collect()
}

/// Waits until the kernel log (from `k` on) holds at least `want[i].1`
/// lines containing `want[i].0` each; the kernel logs asynchronously. The
/// caller checks the exact counts.
fn wait_log(k: &mut Kmsg, seen: &mut Vec<String>, want: &[(&str, usize)]) -> TestResult {
    let mut err = None;
    let r = wait_until(SETTLE, &format!("kernel log lines {want:?}"), || {
        match k.read_new() {
            Ok(l) => seen.extend(l),
            Err(e) => err = Some(e),
        }
        err.is_some()
            || want
                .iter()
                .all(|(pat, n)| seen.iter().filter(|l| l.contains(pat)).count() >= *n)
    });
    match err {
        Some(e) => Err(e),
        None => r.map_err(|e| format!("{e}: {seen:?}")),
    }
}

/// Kernel log lines from now on that contain `pat`.
fn count_log(k: &mut Kmsg, seen: &mut Vec<String>, pat: &str) -> Result<usize, String> {
    seen.extend(k.read_new()?);
    Ok(seen.iter().filter(|l| l.contains(pat)).count())
}

/// Every frame once per second with the right id and payload; the
/// receive timestamp's offset from the second boundary over 31 s (11 s on
/// the debug kernel, `RCAN_TIME_SECS`: the rest of the debug stage checks
/// the same path).
///
/// Bounds: every frame has the format of the wire specification and names
/// a second within one of its receive timestamp's; seconds increase; gaps
/// between receive timestamps lie in 0.25..1.75 s. The nominal 0.5..1.5 s
/// is reported, not asserted: on a shared host the emulated CPUs are
/// sometimes not scheduled for half a second (a 1.54 s gap was seen, with
/// the frame still naming the right second). A stall of more than a
/// second makes the timer callback run after the next boundary; it names
/// the second it runs in, so seconds in between get no frame: accepted
/// only as far as the service's own count of seconds missed to a late
/// timer (its exit log line) accounts for them ([`check_spacing`]).
fn time_frames_1hz(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let mut k = ctx.kmsg()?;
    let mut log = Vec::new();
    let cap = Capture::start(idx, VEHICLE)?;
    ctx.insmod(Module::Time, &[])?;
    let secs = sized("RCAN_TIME_SECS", 31, 11) as usize;
    // The measurement window of a 1 Hz service, not synchronisation.
    thread::sleep(Duration::from_secs(secs as u64));
    let frames = cap.finish();
    let stopped = rmmod_stopped(ctx, Module::Time, &mut k, &mut log)?;
    ensure!(
        frames.len() >= 2,
        "{} time frames in {secs} s",
        frames.len()
    );
    // Seconds named from the first frame to the last: frames, plus the
    // seconds jumped over (explained below).
    let span = (frames[frames.len() - 1].second() - frames[0].second() + 1) as usize;
    ensure!(
        (secs - 5..=secs + 2).contains(&span),
        "{} time frames naming {span} seconds in {secs} s",
        frames.len()
    );
    let dts: Vec<i128> = frames
        .windows(2)
        .map(|w| w[1].ts_ns() - w[0].ts_ns())
        .collect();
    let skipped = frames
        .windows(2)
        .filter(|w| w[1].second() != w[0].second() + 1)
        .count();
    let off_nominal = dts
        .iter()
        .filter(|d| !(500_000_000..=1_500_000_000).contains(*d))
        .count();
    // Offset of each frame from the start of the second it names.
    let mut offs: Vec<i128> = frames
        .iter()
        .map(|f| f.ts_ns() - f.second() as i128 * 1_000_000_000)
        .collect();
    let (p50, p99, max) = percentiles(&mut offs);
    ctx.note(format!(
        "rcan_time: {} frames in {secs} s, {} jumps over seconds, {} gaps outside 0.5..1.5 s; \
         {} seconds missed (late timer) by its count; receive timestamp after the second \
         boundary: p50 {} us, p99 {} us, max {} us",
        frames.len(),
        skipped,
        off_nominal,
        stopped.missed,
        p50 / 1000,
        p99 / 1000,
        max / 1000
    ));
    for f in &frames {
        check_format(f, VEHICLE, SRC_TIME)?;
    }
    let jumped = check_spacing(&frames, 250 * MSEC, 1750 * MSEC, "rcan_time")?;
    ensure_explained(
        jumped,
        stopped.missed,
        "rcan_time",
        "jumped over between frames",
    )?;
    ensure!(
        offs[0] >= 0,
        "a frame was received {} ns before the second it names",
        -offs[0]
    );
    Ok(())
}

/// Writes a module parameter through sysfs.
fn write_param(module: &str, name: &str, val: &str) -> std::io::Result<()> {
    std::fs::write(format!("/sys/module/{module}/parameters/{name}"), val)
}

fn read_param(module: &str, name: &str) -> Result<String, String> {
    let p = format!("/sys/module/{module}/parameters/{name}");
    Ok(std::fs::read_to_string(&p).or_fail(&p)?.trim().to_string())
}

/// Bad parameters fail the load with EINVAL; `vehicle` and `dev` choose
/// the identifier and the interface; `timeout_ms` can be changed at run
/// time within its range.
fn time_params(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = raw2(ctx)?;
    for m in [Module::Time, Module::Rtime] {
        for bad in [
            "vehicle=0xc1",
            "vehicle=0x100",
            "vehicle=0x1c0",
            "vehicle=-1",
            "dev=",
            "dev=a/b",
            "dev=abcdefghijklmnop",
        ] {
            let r = ctx.insmod(m, &[bad]);
            ensure!(
                r.is_err() && !ctx.is_loaded(m),
                "insmod {} {bad}: loaded",
                m.name()
            );
            let e = r.unwrap_err();
            ensure!(
                e.contains("Invalid") || e.contains("EINVAL") || e.contains("nvalid"),
                "insmod {} {bad}: {e}",
                m.name()
            );
        }
    }
    for bad in ["timeout_ms=1000", "timeout_ms=60001"] {
        ensure!(
            ctx.insmod(Module::Rtime, &[bad]).is_err() && !ctx.is_loaded(Module::Rtime),
            "insmod rcan_rtime {bad}: loaded"
        );
    }

    let c0 = Capture::start(i0, 0x50)?;
    let c1 = Capture::start(i1, 0x50)?;
    ctx.insmod(Module::Time, &["vehicle=0x50", "dev=can1"])?;
    let v = read_param("rcan_time", "vehicle")?;
    ensure!(v == "0x50", "vehicle reads {v:?}");
    let d = read_param("rcan_time", "dev")?;
    ensure!(d == "can1", "dev reads {d:?}");
    ensure!(
        write_param("rcan_time", "vehicle", "0x60").is_err(),
        "vehicle is writable at run time"
    );
    // Two ticks on can1 (was 3.5 s); a frame on can0 would have come with
    // either.
    c1.wait_count(2, "two time frames on can1", |_| true)?;
    ctx.rmmod(Module::Time)?;
    let f1 = c1.finish();
    let f0 = c0.finish();
    ensure!(f0.is_empty(), "time frame on can0: {}", f0[0].show());
    ensure!(f1.len() >= 2, "{} time frames on can1", f1.len());
    for f in &f1 {
        check_format(f, 0x50, SRC_TIME)?;
    }

    ctx.insmod(Module::Rtime, &["timeout_ms=5000"])?;
    let t = read_param("rcan_rtime", "timeout_ms")?;
    ensure!(t == "5000", "timeout_ms reads {t:?}");
    ensure!(
        write_param("rcan_rtime", "timeout_ms", "100").is_err(),
        "timeout_ms=100 accepted at run time"
    );
    write_param("rcan_rtime", "timeout_ms", "1200").or_fail("timeout_ms=1200")?;
    let t = read_param("rcan_rtime", "timeout_ms")?;
    ensure!(t == "1200", "timeout_ms reads {t:?} after writing 1200");
    Ok(())
}

/// The service survives its interface going down and up, and being
/// unregistered and registered again (rcan_loop reloaded), with one log
/// line per change.
fn time_dev_down_up(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let mut k = ctx.kmsg()?;
    let mut log = Vec::new();
    let cap = Capture::start(idx, VEHICLE)?;
    ctx.insmod(Module::Time, &[])?;
    cap.wait_for(Duration::from_secs(4), |_| true)
        .ok_or("no time frame within 4 s of loading")?;

    ctx.link_down(&dev(0))?;
    // Once `ip link set down` has returned, no transmission is running
    // (dev_close waits for it), so nothing can be timestamped later.
    let down_at = unix_ns(SystemTime::now());
    // A negative check over three of the service's ticks, not
    // synchronisation: nothing marks a tick that sends nothing.
    thread::sleep(Duration::from_millis(3500));
    let n = cap.frames().iter().filter(|f| f.ts_ns() > down_at).count();
    ensure!(n == 0, "{n} time frames while can0 was down");
    ctx.link_up(&dev(0))?;
    let up_at = Instant::now();
    let f = cap
        .wait_for(Duration::from_secs(4), |f| f.mono > up_at)
        .ok_or("no time frame within 4 s of can0 coming up")?;
    check_format(&f, VEHICLE, SRC_TIME)?;
    // The kernel logs asynchronously: wait for the lines.
    wait_log(
        &mut k,
        &mut log,
        &[
            ("rcan_time: can0: device down", 1),
            ("rcan_time: can0: sending time frames again", 1),
        ],
    )?;
    let downs = count_log(&mut k, &mut log, "rcan_time: can0: device down")?;
    let agains = count_log(
        &mut k,
        &mut log,
        "rcan_time: can0: sending time frames again",
    )?;
    ensure!(
        downs == 1 && agains == 1,
        "log lines: {downs} 'device down', {agains} 'sending again' (want 1 each): {log:?}"
    );
    drop(cap);

    // The device goes away (until the service has noticed: its log line,
    // was 3.5 s) and comes back with a new ifindex.
    ctx.rmmod(Module::Loop)?;
    wait_log(&mut k, &mut log, &[("rcan_time: can0: no such device", 1)])?;
    ctx.insmod(Module::Loop, &[])?;
    ctx.link_up(&dev(0))?;
    let idx2 = ctx.ifindex(&dev(0))?;
    let cap = Capture::start(idx2, VEHICLE)?;
    let f = cap
        .wait_for(Duration::from_secs(4), |_| true)
        .ok_or("no time frame within 4 s of can0 coming back")?;
    check_format(&f, VEHICLE, SRC_TIME)?;
    wait_log(
        &mut k,
        &mut log,
        &[("rcan_time: can0: sending time frames again", 2)],
    )?;
    let missing = count_log(&mut k, &mut log, "rcan_time: can0: no such device")?;
    let agains = count_log(
        &mut k,
        &mut log,
        "rcan_time: can0: sending time frames again",
    )?;
    ensure!(
        missing == 1 && agains == 2,
        "log lines: {missing} 'no such device' (want 1), {agains} 'sending again' (want 2): {log:?}"
    );
    Ok(())
}

/// Sets CLOCK_REALTIME with date(1), as an administrator would.
fn set_clock(unix_ns: i128) -> TestResult {
    let arg = format!(
        "@{}.{:09}",
        unix_ns.div_euclid(1_000_000_000),
        unix_ns.rem_euclid(1_000_000_000)
    );
    let out = Command::new(tool("date"))
        .args(["-s", &arg])
        .output()
        .or_fail("date -s")?;
    ensure!(
        out.status.success(),
        "date -s {arg}: {}",
        String::from_utf8_lossy(&out.stderr).trim()
    );
    Ok(())
}

/// Puts the clock back where it would be without the test's steps.
struct ClockGuard {
    real0: i128,
    mono0: Instant,
}

impl ClockGuard {
    fn new() -> Self {
        ClockGuard {
            real0: unix_ns(SystemTime::now()),
            mono0: Instant::now(),
        }
    }
}

impl Drop for ClockGuard {
    fn drop(&mut self) {
        let now = self.real0 + self.mono0.elapsed().as_nanos() as i128;
        if let Err(e) = set_clock(now) {
            println!("# could not restore the clock: {e}");
        }
    }
}

/// Sleeps until `phase` ns into a second of CLOCK_REALTIME: a position in
/// the service's second, which the tests choose on purpose; not
/// synchronisation.
fn sleep_to_phase(phase: u32) {
    let sub = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    let wait = (1_000_000_000 + phase - sub) % 1_000_000_000;
    thread::sleep(Duration::from_nanos(u64::from(wait)));
}

/// Clock steps forward by 100 s and back by 200 s, both in the middle of
/// a second. Forward: the timer fires at once, sending one frame for the
/// new current second (not waiting for the next boundary, not catching up
/// on the 100 skipped seconds), then every following second. Backward:
/// the monotonic watchdog re-arms the timer for the new clock's next
/// second (it does not wait 200 s for the old one to come round again):
/// no gap beyond 2.2 s, plus emulation slack.
///
/// The clock is set with date(1); the new clock reads the requested time
/// when date sets it, so a frame's receive timestamp minus that time is
/// how long after the step it came, whatever date's own latency.
fn time_clock_step(ctx: &mut Ctx) -> TestResult {
    const NS: i128 = 1_000_000_000;
    let idx = raw1(ctx)?;
    let mut k = ctx.kmsg()?;
    let mut log = Vec::new();
    let restore = ClockGuard::new();
    let cap = Capture::start(idx, VEHICLE)?;
    let loaded = Instant::now();
    ctx.insmod(Module::Time, &[])?;
    cap.wait_for(Duration::from_secs(4), |_| true)
        .ok_or("no time frame within 4 s of loading")?;
    // The windows below are the test's subject (seconds before and after
    // each clock step), not synchronisation.
    thread::sleep(Duration::from_secs(3));

    sleep_to_phase(300_000_000);
    let before = unix_ns(SystemTime::now());
    let fwd_to = before + 100 * NS;
    set_clock(fwd_to)?;
    let fwd = Instant::now();
    thread::sleep(Duration::from_secs(5));

    sleep_to_phase(500_000_000);
    let before_back = unix_ns(SystemTime::now());
    let back_to = before_back - 200 * NS;
    // Taken before the step, not after: a frame of the stepped-back clock
    // may come before set_clock (date(1)) returns, and an instant taken
    // after it then counted that frame among those after the forward step
    // (2026-11-29, a loaded debug guest: date returned about a second
    // after the step, past the new clock's first frame).
    let back = Instant::now();
    set_clock(back_to)?;
    thread::sleep(Duration::from_secs(6));
    let frames = cap.finish();
    drop(restore);

    for f in &frames {
        check_format(f, VEHICLE, SRC_TIME)?;
    }
    let g = gaps(&frames);
    let show_gaps = |from: Instant| -> String {
        frames
            .windows(2)
            .zip(&g)
            .filter(|(w, _)| {
                w[1].mono + Duration::from_secs(2) > from
                    && w[1].mono < from + Duration::from_secs(4)
            })
            .map(|(w, g)| {
                let frac = w[1].ts_ns().rem_euclid(NS) / 1_000_000;
                format!("{}@.{frac:03} +{} ms", w[1].second(), g.as_millis())
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    ctx.note(format!(
        "forward step +100 s at {}: {}",
        show_time(UNIX_EPOCH + Duration::from_nanos(fwd_to as u64)),
        show_gaps(fwd)
    ));
    ctx.note(format!(
        "backward step -200 s at {}: {}",
        show_time(UNIX_EPOCH + Duration::from_nanos(back_to as u64)),
        show_gaps(back)
    ));

    // Forward. The step frame: the first naming a second of the new clock.
    let fwd_s = (fwd_to / NS) as u64;
    let i = frames
        .iter()
        .position(|f| f.second() + 50 > fwd_s && f.second() < fwd_s + 50)
        .ok_or("no frame after the forward step")?;
    let step = &frames[i];
    let late = step.ts_ns() - fwd_to;
    ensure!(
        step.second() == fwd_s && (0..500_000_000).contains(&late),
        "first frame after stepping to {}: {} ({} ms after the step; the next second \
         began 700 ms after it)",
        show_time(UNIX_EPOCH + Duration::from_nanos(fwd_to as u64)),
        step.show(),
        late / 1_000_000
    );
    let after_fwd: Vec<&Rx> = frames[i..]
        .iter()
        .filter(|f| f.mono < back && f.ts_ns() < fwd_to + 3 * NS)
        .collect();
    ensure!(
        after_fwd.len() <= 4,
        "{} frames in the 3 s after the forward step",
        after_fwd.len()
    );
    // Consecutive seconds, but for seconds missed to a late timer
    // (explained at the end).
    let jumped_fwd = jumped(
        after_fwd.windows(2).map(|w| (w[0], w[1])),
        "after the forward step",
    )?;

    // Backward: the first frame naming a second of the stepped-back clock
    // comes within 2.2 s of the last one before it (plus slack); frames
    // keep at least half a second apart.
    let back_s = (back_to / NS) as u64;
    let j = frames
        .iter()
        .position(|f| f.second() + 50 > back_s && f.second() < back_s + 50)
        .ok_or("no frame after the backward step")?;
    ensure!(
        j > 0 && frames.len() - j >= 3,
        "{} frames in the 6 s after the backward step",
        frames.len() - j
    );
    let first = &frames[j];
    let since = first.ts_ns() - back_to;
    ensure!(
        first.second() >= back_s && (0..2_700_000_000).contains(&since),
        "first frame after stepping back to {}: {} ({} ms after the step)",
        show_time(UNIX_EPOCH + Duration::from_nanos(back_to as u64)),
        first.show(),
        since / 1_000_000
    );
    ensure!(
        g[j - 1] <= Duration::from_millis(3200) && g[j - 1] >= Duration::from_millis(500),
        "gap of {} ms before {} after the backward step",
        g[j - 1].as_millis(),
        first.show()
    );
    // From there on, frames name the new clock's seconds, one by one but
    // for seconds missed to a late timer (explained below).
    let jumped_back = check_spacing(
        &frames[j..],
        500 * MSEC,
        3200 * MSEC,
        "after the backward step",
    )?;
    let n = count_log(&mut k, &mut log, "rcan_time: clock stepped back")?;
    ensure!(
        n == 1,
        "{n} 'clock stepped back' log lines (want 1): {log:?}"
    );
    let stopped = rmmod_stopped(ctx, Module::Time, &mut k, &mut log)?;
    let ran = loaded.elapsed().as_secs() + 1;
    ctx.note(format!(
        "rcan_time: {} seconds missed (late timer) by its count in {ran} s, {} jumped over \
         between frames after the steps",
        stopped.missed,
        jumped_fwd + jumped_back
    ));
    ensure_explained(
        jumped_fwd + jumped_back,
        stopped.missed,
        "rcan_time",
        "jumped over between frames after the steps",
    )?;
    // The seconds a forward step jumps over (100 here, and the clock's
    // restoration) are not missed: a late timer cannot miss more seconds
    // than the service ran.
    ensure!(
        stopped.missed <= ran,
        "rcan_time counted {} seconds missed (late timer) in {ran} s: clock steps counted",
        stopped.missed
    );
    Ok(())
}

/// rmmod while sending, at several phases of the second (just before a
/// boundary, when the timer is about to fire): nothing arrives afterwards.
/// (1.6 s of watching after each rmmod, the next boundary and 0.6 s; it
/// was 1.2 s of waiting before it and 2.5 s after, 27.7 s on the release
/// kernel: the waits that remain are the ones a lingering timer needs to
/// show itself, and a frame it sends is timestamped when received.)
/// A frame handed to the device before rmmod returned may be timestamped
/// a few ms later by the receive path; 100 ms are allowed for that, and it
/// must name a second no later than the one rmmod returned in.
fn time_unload(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let cap = Capture::start(idx, VEHICLE)?;
    let phases = [
        (Module::Time, 990_000_000u32),
        (Module::Time, 997_000_000),
        (Module::Time, 500_000_000),
        (Module::Rtime, 990_000_000),
        (Module::Rtime, 997_000_000),
    ];
    for (m, phase) in phases {
        let params: &[&str] = if m == Module::Rtime {
            &["timeout_ms=1200"]
        } else {
            &[]
        };
        let src = if m == Module::Rtime {
            SRC_RTIME
        } else {
            SRC_TIME
        };
        let loaded = Instant::now();
        ctx.insmod(m, params)?;
        cap.wait_for(Duration::from_secs(5), |f| {
            f.mono > loaded && f.source() == src
        })
        .ok_or_else(|| format!("{}: no frame within 5 s of loading", m.name()))?;
        // The timer is running (it sent a frame): unload at `phase` of
        // this second or the next.
        sleep_to_phase(phase);
        ctx.rmmod(m)?;
        let gone = SystemTime::now();
        // A timer left armed fires at the next boundary, at most 1 s
        // away (0.5 s at phase 500 ms, 10 and 3 ms at phases 990 and
        // 997 ms, where 1.6 s also covers the boundary after it). A
        // negative check's window, not synchronisation.
        thread::sleep(Duration::from_millis(1600));
        let gone_ns = unix_ns(gone);
        let gone_s = (gone_ns / 1_000_000_000) as u64;
        for f in cap.frames() {
            ensure!(
                f.ts_ns() <= gone_ns + 100_000_000 && f.second() <= gone_s,
                "{} unloaded at {}: frame {} afterwards",
                m.name(),
                show_time(gone),
                f.show()
            );
        }
    }
    Ok(())
}

/// A user-space program playing the GPS node: sends the time frame
/// (source 0) at every second boundary while running.
struct Gps {
    /// 0 sending, 1 paused, 2 exit.
    state: Arc<AtomicU8>,
    handle: Option<JoinHandle<()>>,
}

const GPS_SEND: u8 = 0;
const GPS_PAUSE: u8 = 1;
const GPS_EXIT: u8 = 2;

impl Gps {
    fn start(ifindex: u32) -> Result<Gps, String> {
        let s = canraw::open(ifindex)?;
        let state = Arc::new(AtomicU8::new(GPS_SEND));
        let st = Arc::clone(&state);
        let handle = thread::spawn(move || loop {
            sleep_to_phase(0);
            match st.load(Ordering::Relaxed) {
                GPS_EXIT => break,
                GPS_PAUSE => continue,
                _ => {}
            }
            let secs = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0);
            let mut data = [0u8; 8];
            data[..4].copy_from_slice(&(secs as u32).to_be_bytes());
            data[4] = SRC_GPS;
            let _ = canraw::send(&s, &canraw::std(VEHICLE as u16, &data));
        });
        Ok(Gps {
            state,
            handle: Some(handle),
        })
    }

    fn set(&self, state: u8) {
        self.state.store(state, Ordering::Relaxed);
    }
}

impl Drop for Gps {
    fn drop(&mut self) {
        self.set(GPS_EXIT);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Waits for the first rcan_rtime frame after `after`; checks that it came
/// the takeover timeout after the last GPS frame, plus at most a second
/// (to the next boundary) and emulation slack. Returns that delay; beyond
/// that bound, [`takeover_excess`] says how many seconds of a late timer
/// callback it needs.
fn expect_takeover(cap: &Capture, after: Instant, what: &str) -> Result<Duration, String> {
    let first = cap
        .wait_for(TIMEOUT + Duration::from_secs(5), |f| {
            f.mono > after && f.source() == SRC_RTIME
        })
        .ok_or_else(|| format!("{what}: rcan_rtime did not take over within 7.5 s"))?;
    let last_gps = cap
        .frames()
        .into_iter()
        .rev()
        .find(|f| f.source() == SRC_GPS && f.mono < first.mono)
        .ok_or_else(|| format!("{what}: no GPS frame before the takeover"))?;
    let delay = first.mono.duration_since(last_gps.mono);
    ensure!(
        delay >= TIMEOUT - Duration::from_millis(100),
        "{what}: first rcan_rtime frame {} ms after the last GPS frame (want 2500 to 3500 \
         plus slack)",
        delay.as_millis()
    );
    check_format(&first, VEHICLE, SRC_RTIME)?;
    Ok(delay)
}

/// Whole seconds (rounded up) by which a takeover `delay` exceeds the
/// timeout, the second to the next boundary and a second of slack. A
/// timer callback that runs x >= 1 s late decides the takeover x later
/// and counts floor(x) seconds missed, so each second beyond the bound
/// must be one the service counted.
fn takeover_excess(delay: Duration) -> u64 {
    let bound = TIMEOUT + Duration::from_millis(2000);
    let over = delay.saturating_sub(bound).as_nanos();
    over.div_ceil(1_000_000_000) as u64
}

/// The redundant service is silent while the GPS node sends, takes over
/// within the documented time when it stops (sending at 1 Hz, ignoring
/// its own echoes), hands back when it resumes with at most one second
/// carrying both, and needs the full timeout again for the next takeover.
fn rtime_takeover_handback(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let mut k = ctx.kmsg()?;
    let mut log = Vec::new();
    let cap = Capture::start(idx, VEHICLE)?;
    let gps = Gps::start(idx)?;
    // The GPS node is on the bus before rcan_rtime comes (was 1.5 s).
    cap.wait_count(1, "the first GPS frame", |f| f.source() == SRC_GPS)?;
    ctx.insmod(Module::Rtime, &[])?;

    // A: the GPS node sends; we stay silent, for six of its frames (was
    // 6 s, which a stalled guest could fill with fewer).
    let gps_before = cap.frames().iter().filter(|f| f.source() == SRC_GPS).count();
    cap.wait_count(gps_before + 6, "six GPS frames after loading rcan_rtime", |f| {
        f.source() == SRC_GPS
    })?;
    let fs = cap.frames();
    let gps_n = fs.iter().filter(|f| f.source() == SRC_GPS).count();
    ensure!(gps_n >= 5, "only {gps_n} GPS frames");
    if let Some(f) = fs.iter().find(|f| f.source() != SRC_GPS) {
        return Err(format!(
            "frame from rcan_rtime while the GPS node sends: {}",
            f.show()
        ));
    }

    // B: the GPS node fails.
    gps.set(GPS_PAUSE);
    let paused = Instant::now();
    let d1 = expect_takeover(&cap, paused, "first takeover")?;
    // Four of its frames (was 4.5 s).
    cap.wait_count(4, "four rcan_rtime frames", |f| f.source() == SRC_RTIME)?;
    let ours: Vec<Rx> = cap
        .frames()
        .into_iter()
        .filter(|f| f.source() == SRC_RTIME)
        .collect();
    ensure!(ours.len() >= 4, "only {} rcan_rtime frames", ours.len());
    for f in &ours {
        check_format(f, VEHICLE, SRC_RTIME)?;
    }
    // Explained by its count of missed seconds at the end.
    let jumped_b = check_spacing(&ours, 500 * MSEC, 1500 * MSEC, "rcan_rtime")?;

    // C: the GPS node is back.
    gps.set(GPS_SEND);
    let resumed = Instant::now();
    let g1 = cap
        .wait_for(Duration::from_secs(3), |f| {
            f.mono > resumed && f.source() == SRC_GPS
        })
        .ok_or("GPS frame did not come back")?;
    // Silent again, for five more GPS frames (was 5 s).
    cap.wait_count(5, "five GPS frames after it came back", |f| {
        f.mono > g1.mono && f.source() == SRC_GPS
    })?;
    let late: Vec<Rx> = cap
        .frames()
        .into_iter()
        .filter(|f| f.mono > g1.mono && f.source() == SRC_RTIME)
        .collect();
    ensure!(
        late.len() <= 1 && late.iter().all(|f| f.second() == g1.second()),
        "rcan_rtime frames after the GPS node came back ({}): {}",
        g1.show(),
        late.iter().map(Rx::show).collect::<Vec<_>>().join(", ")
    );
    let flap = cap
        .frames()
        .iter()
        .filter(|f| f.source() == SRC_RTIME && f.second() == g1.second())
        .count();

    // D: it fails again: takeover after the full timeout again.
    gps.set(GPS_PAUSE);
    let paused = Instant::now();
    let d2 = expect_takeover(&cap, paused, "second takeover")?;
    drop(gps);
    wait_log(
        &mut k,
        &mut log,
        &[
            ("rcan_rtime: can0: no time frame from another", 2),
            ("rcan_rtime: can0: time frame from another source: handing back", 1),
        ],
    )?;
    ctx.note(format!(
        "rcan_rtime: first frame {} ms and {} ms after the last GPS frame (timeout 2500 ms); \
         {} rcan_rtime frame(s) in the second the GPS node came back",
        d1.as_millis(),
        d2.as_millis(),
        flap
    ));
    let takeovers = count_log(
        &mut k,
        &mut log,
        "rcan_rtime: can0: no time frame from another",
    )?;
    let handbacks = count_log(
        &mut k,
        &mut log,
        "rcan_rtime: can0: time frame from another source: handing back",
    )?;
    ensure!(
        takeovers == 2 && handbacks == 1,
        "log: {takeovers} takeovers (want 2), {handbacks} handbacks (want 1): {log:?}"
    );
    let stopped = rmmod_stopped(ctx, Module::Rtime, &mut k, &mut log)?;
    let (x1, x2) = (takeover_excess(d1), takeover_excess(d2));
    ctx.note(format!(
        "rcan_rtime: {} seconds missed (late timer) by its count; {jumped_b} seconds jumped over \
         between its frames, takeovers {x1} and {x2} s over the bound",
        stopped.missed
    ));
    ensure_explained(
        jumped_b + x1 + x2,
        stopped.missed,
        "rcan_rtime",
        &format!(
            "{jumped_b} jumped over between its frames, {x1} and {x2} by which the takeovers \
             exceeded their bound"
        ),
    )?;
    Ok(())
}

/// rcan_time on the same host counts as another source: rcan_rtime stays
/// silent while it runs and takes over when it is unloaded.
fn rtime_silent_with_local_time(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let cap = Capture::start(idx, VEHICLE)?;
    ctx.insmod(Module::Time, &[])?;
    ctx.insmod(Module::Rtime, &["timeout_ms=1200"])?;
    // Five of rcan_time's frames (was 5 s), more than rcan_rtime's timeout.
    cap.wait_count(5, "five rcan_time frames", |f| f.source() == SRC_TIME)?;
    let fs = cap.frames();
    ensure!(
        fs.iter().filter(|f| f.source() == SRC_TIME).count() >= 4,
        "rcan_time sent {} frames",
        fs.len()
    );
    if let Some(f) = fs.iter().find(|f| f.source() == SRC_RTIME) {
        return Err(format!(
            "rcan_rtime sent while rcan_time runs: {}",
            f.show()
        ));
    }
    ctx.rmmod(Module::Time)?;
    let gone = Instant::now();
    let f = cap
        .wait_for(Duration::from_secs(5), |f| {
            f.mono > gone && f.source() == SRC_RTIME
        })
        .ok_or("rcan_rtime did not take over within 5 s of rcan_time's unload")?;
    check_format(&f, VEHICLE, SRC_RTIME)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames (second, receive time in ns) as the capture thread would
    /// have them, received on the monotonic clock as on the realtime one.
    fn frames(list: &[(u32, i128)]) -> Vec<Rx> {
        let base = Instant::now();
        list.iter()
            .map(|&(sec, at)| {
                let mut wire = [0u8; 16];
                wire[..4].copy_from_slice(&VEHICLE.to_ne_bytes());
                wire[4] = 8;
                wire[8..12].copy_from_slice(&sec.to_be_bytes());
                wire[12] = SRC_RTIME;
                let rel = (at - list[0].1) as u64;
                Rx {
                    mono: base + Duration::from_nanos(rel),
                    ts: UNIX_EPOCH + Duration::from_nanos(at as u64),
                    wire,
                }
            })
            .collect()
    }

    /// rtime_takeover_handback's check of the frames of phase B.
    fn rtime_b(list: &[(u32, i128)], missed: u64) -> TestResult {
        let f = frames(list);
        for x in &f {
            check_format(x, VEHICLE, SRC_RTIME)?;
        }
        let j = check_spacing(&f, 500 * MSEC, 1500 * MSEC, "rcan_rtime")?;
        ensure_explained(j, missed, "rcan_rtime", "test")
    }

    const T0: u32 = 0x6B0B_7FCF;

    fn at(sec: u32, frac_ms: i128) -> (u32, i128) {
        (sec, i128::from(sec) * SEC + frac_ms * MSEC)
    }

    /// The failure of issue 40: 0C0#6B0B7FD1 at ...729.002161751, then
    /// 0C0#6B0B7FD3 at ...731.440013282 (a TICK callback 1.44 s late).
    #[test]
    fn late_callback_needs_the_count() {
        let seen = [
            at(T0, 2),
            at(T0 + 1, 1),
            (T0 + 2, 1_795_915_729_002_161_751),
            (T0 + 4, 1_795_915_731_440_013_282),
            at(T0 + 5, 3),
        ];
        assert_eq!(T0 + 2, 1_795_915_729);
        // Without the service's count (a module without the counter, or
        // one that counted nothing) it fails, as before the counter ...
        let e = rtime_b(&seen, 0).unwrap_err();
        assert!(e.contains("1 second(s) to explain"), "{e}");
        // ... with it, it passes.
        rtime_b(&seen, 1).unwrap();
        rtime_b(&seen, 2).unwrap();
    }

    #[test]
    fn late_anywhere_in_its_second() {
        // Late by 1.98 s: second T0+2 named at .98 (gap 2.97 s).
        rtime_b(&[at(T0, 10), at(T0 + 2, 980)], 1).unwrap();
        // Late by several seconds.
        rtime_b(&[at(T0, 10), at(T0 + 4, 500)], 3).unwrap();
        assert!(rtime_b(&[at(T0, 10), at(T0 + 4, 500)], 2).is_err());
        // A frame naming T0+2 but received 3.6 s after T0's: not in the
        // second it names, whatever the count.
        assert!(rtime_b(
            &[at(T0, 10), (T0 + 2, i128::from(T0 + 3) * SEC + 610 * MSEC)],
            5
        )
        .is_err());
    }

    #[test]
    fn bad_services_still_fail() {
        // 0.5 Hz: every other second, 2 s apart, nothing missed.
        let half: Vec<_> = (0..6).map(|i| at(T0 + 2 * i, 5)).collect();
        let e = rtime_b(&half, 0).unwrap_err();
        assert!(e.contains("5 second(s) to explain"), "{e}");
        // A second named twice, or out of order.
        assert!(rtime_b(&[at(T0, 5), at(T0 + 1, 5), at(T0 + 1, 900)], 9).is_err());
        assert!(rtime_b(&[at(T0, 5), at(T0 - 1, 995)], 9).is_err());
        // Two frames under 500 ms apart, the first not late in its second.
        let early = (T0 + 1, i128::from(T0 + 1) * SEC - 250 * MSEC);
        assert!(rtime_b(&[at(T0, 300), early], 9).is_err());
        // Received after the end of the second it names (2.1 s after an
        // on-time frame), whatever the count.
        assert!(rtime_b(&[at(T0, 5), at(T0 + 2, 1105)], 9).is_err());
        // Drifting: 1.9 s apart, naming consecutive seconds.
        let drift = [at(T0, 5), at(T0 + 1, 905), at(T0 + 2, 1805)];
        assert!(rtime_b(&drift, 9).is_err());
        // On time passes with nothing missed.
        rtime_b(&[at(T0, 5), at(T0 + 1, 2), at(T0 + 2, 400)], 0).unwrap();
    }

    /// Run 2 on a loaded host: a frame 944 ms late in its own second, the
    /// next on time 56 ms later.
    #[test]
    fn late_in_its_second() {
        rtime_b(&[at(T0, 5), at(T0 + 1, 944), at(T0 + 2, 0)], 0).unwrap();
        // But the next one not before its second begins.
        let early = (T0 + 2, i128::from(T0 + 1) * SEC + 990 * MSEC);
        assert!(rtime_b(&[at(T0 + 1, 944), early], 9).is_err());
        // Only a frame late within its second excuses a short gap: after
        // one received when its second had ended (a catch-up burst), the
        // usual bound holds.
        let burst = [
            (T0 + 1, i128::from(T0 + 2) * SEC + 300 * MSEC),
            (T0 + 2, i128::from(T0 + 2) * SEC + 301 * MSEC),
        ];
        assert!(rtime_b(&burst, 9).is_err());
        // A frame early in its second gets no such excuse.
        let early = (T0 + 1, i128::from(T0 + 1) * SEC - 150 * MSEC);
        assert!(rtime_b(&[at(T0, 400), early], 9).is_err());
    }

    #[test]
    fn exit_line() {
        let lines = [
            "rcan_time: can0: sending time frame 0c0 at every second".to_string(),
            "rcan_rtime: stopped: 12 frames sent, 3 seconds skipped, 2 seconds missed (late \
             timer), 2 takeovers, 0 backward clock steps caught"
                .to_string(),
        ];
        assert_eq!(
            parse_stopped(&lines, "rcan_rtime").unwrap(),
            Stopped {
                sent: 12,
                skipped: 3,
                missed: 2
            }
        );
        assert!(parse_stopped(&lines, "rcan_time").is_err());
        // The line of a module without the counter.
        let old = [
            "rcan_time: stopped: 30 frames sent, 0 seconds skipped, 0 backward clock \
                    steps caught"
                .to_string(),
        ];
        let e = parse_stopped(&old, "rcan_time").unwrap_err();
        assert!(e.contains("seconds missed (late timer)"), "{e}");
    }
}
