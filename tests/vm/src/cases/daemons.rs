// SPDX-License-Identifier: GPL-2.0
//! The vehicle's daemons (tools/can-daemons, issue 17) as a user runs
//! them, over CAN_RAW only (so these tests also run against mainline):
//!
//! - `canzlogd` writes what `candump -l` writes, line for line, kernel
//!   timestamps included; keeps its flush promise under SIGKILL; rotates;
//!   reports SO_RXQ_OVFL drops so that logged + dropped = sent;
//! - `cantcpd` carries frames both ways for python-can's `socketcand`
//!   interface (a client nobody here wrote) and a second client at once.
//!
//! Log files are read back with `zcat`, as a user would.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant, SystemTime};

use socketcan::CanFrame;

use super::sja1000::kvaser2;
use super::{portable_table, raw1, test_table};
use crate::canraw::{self, err_frame, ext, rtr_ext, rtr_std, std, CAN_ERR_CRTL};
use crate::check::{ensure, wait_for, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::tools::{self, Bg, TempDir, TOOL_LIMIT};
use crate::Test;

pub const TESTS: &[Test] = portable_table![
    canzlogd_matches_candump_log,
    canzlogd_sigkill_loses_at_most_flush_interval,
    canzlogd_rotates_by_size_and_age,
    canzlogd_reports_rxq_overflow,
    cantcpd_python_can_and_second_client,
    cantcpd_slow_client_drops_alone,
];

/// canzlogd on the emulated SJA1000 cards (rcan_kvaser_pci): ours only.
pub const SJA1000_TESTS: &[Test] = test_table![sja1000_canzlogd_two_cards];

/// Starts canzlogd on can0 into `dir` with `extra` options; returns once
/// it waits for frames.
fn canzlogd(dir: &Path, extra: &[&str]) -> Result<Bg, String> {
    let d = dir.to_str().ok_or("non-UTF-8 dir")?;
    let mut args = vec!["-d", d];
    args.extend_from_slice(extra);
    args.push("can0");
    let mut z = tools::spawn_own("canzlogd", &args, None)?;
    z.wait_stderr("canzlogd: logging")?;
    z.wait_listening()?;
    Ok(z)
}

/// SIGTERM, then the daemon must exit with status 0 on its own.
fn stop(z: Bg, what: &str) -> TestResult {
    z.signal("TERM")?;
    let out = z.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "{what} after SIGTERM: {}: {}",
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// The log files of `dir`, in name (= creation) order.
fn log_files(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .or_fail(dir.display())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_str().is_some_and(|s| s.ends_with(".log.gz")))
        .collect();
    v.sort();
    Ok(v)
}

/// `zcat FILES...` (must exit 0): (frame lines, `# ` note lines).
fn zcat(files: &[PathBuf]) -> Result<(Vec<String>, Vec<String>), String> {
    ensure!(!files.is_empty(), "no log file");
    let names: Vec<&str> = files.iter().filter_map(|p| p.to_str()).collect();
    let out = tools::run_ok("zcat", &names)?;
    let (notes, frames) = out
        .stdout
        .lines()
        .map(str::to_string)
        .partition(|l| l.starts_with("# "));
    Ok((frames, notes))
}

/// A candump -l line without its timestamp: `can0 123#1122`.
fn body(line: &str) -> &str {
    line.split_once(") ").map_or(line, |x| x.1)
}

fn now_us() -> u64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or_default()
        .as_micros() as u64
}

/// A frame carrying counter `i` (0x100, 4 bytes little endian).
fn numbered(i: u32) -> CanFrame {
    std(0x100, &i.to_le_bytes())
}

/// The counter of a `can0 100#XXXXXXXX` line.
fn number_of(line: &str) -> Result<u32, String> {
    let d = body(line)
        .strip_prefix("can0 100#")
        .filter(|d| d.len() == 8)
        .ok_or_else(|| format!("unexpected line {line:?}"))?;
    let b = u32::from_str_radix(d, 16).map_err(|_| format!("bad data in {line:?}"))?;
    Ok(b.swap_bytes())
}

/// Sends a frame, retrying while the device queue is full (ENOBUFS).
fn send_retry(s: &socketcan::CanSocket, f: &CanFrame) -> TestResult {
    use socketcan::Socket;
    for _ in 0..1000 {
        match s.write_frame(f) {
            Ok(()) => return Ok(()),
            Err(e) if e.raw_os_error() == Some(libc::ENOBUFS) => {
                thread::sleep(Duration::from_millis(1))
            }
            Err(e) => return Err(format!("write {}: {e}", canraw::show(f))),
        }
    }
    Err(format!("write {}: ENOBUFS for 1 s", canraw::show(f)))
}

/// canzlogd and `candump -l can0,0:0,#FFFFFFFF` log the same frames (data, extended,
/// remote, error) as the same lines, timestamps included: both read the
/// kernel's receive time. SIGTERM ends canzlogd with status 0, and its
/// notes say so.
fn canzlogd_matches_candump_log(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let zdir = TempDir::new("canzlogd")?;
    let ddir = TempDir::new("candump")?;
    let mut frames = vec![
        std(0x123, &[0x11, 0x22]),
        ext(0x1234567, &[]),
        rtr_std(0x7FF, 0),
        rtr_std(0x7FE, 4),
        rtr_ext(5, 0),
        std(0, &[1, 2, 3, 4, 5, 6, 7, 8]),
        err_frame(CAN_ERR_CRTL, &[0, 4]),
    ];
    frames.extend((0..50).map(numbered));
    let mut dump = tools::spawn("candump", &["-l", "can0,0:0,#FFFFFFFF"], Some(ddir.path()))?;
    dump.wait_listening()?;
    let z = canzlogd(zdir.path(), &["--flush-ms", "100"])?;
    for f in &frames {
        send_retry(&tx, f)?;
    }
    // Both read the frames as they come; give them a generous second.
    thread::sleep(Duration::from_secs(1));
    dump.signal("TERM")?;
    let out = dump.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "candump -l: {}: {}",
        out.status,
        out.stderr.trim()
    );
    stop(z, "canzlogd")?;
    let dlogs: Vec<PathBuf> = std::fs::read_dir(ddir.path())
        .or_fail(ddir.path().display())?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    let [dlog] = dlogs.as_slice() else {
        return Err(format!("expected one candump log, found {dlogs:?}"));
    };
    let want: Vec<String> = std::fs::read_to_string(dlog)
        .or_fail(dlog.display())?
        .lines()
        .map(str::to_string)
        .collect();
    let (got, notes) = zcat(&log_files(zdir.path())?)?;
    ensure!(
        got == want,
        "canzlogd logged\n{}\ncandump -l logged\n{}",
        got.join("\n"),
        want.join("\n")
    );
    ensure!(
        notes.first().is_some_and(|l| l.contains("started on can0"))
            && notes
                .last()
                .is_some_and(|l| l.contains("stopping on signal 15, 57 frames")),
        "notes {notes:?}"
    );
    Ok(())
}

/// Flush policy under SIGKILL: with `--flush-ms 200`, every frame
/// received more than 200 ms (plus 400 ms of slack for a slow emulated
/// VM) before the kill is in the files, which `zcat` reads without error,
/// and the logged frames are exactly the first ones sent, in order.
fn canzlogd_sigkill_loses_at_most_flush_interval(ctx: &mut Ctx) -> TestResult {
    const FLUSH_MS: u64 = 200;
    const SLACK_MS: u64 = 400;
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let dir = TempDir::new("canzlogd-kill")?;
    let z = canzlogd(dir.path(), &["--flush-ms", &FLUSH_MS.to_string()])?;
    // A sender thread keeps frames coming every 2 ms while the kill
    // happens, as on a running bus; it returns the send times.
    let stop = Arc::new(AtomicBool::new(false));
    let sender = {
        let stop = Arc::clone(&stop);
        thread::spawn(move || -> Result<Vec<u64>, String> {
            let mut sent_at = Vec::new();
            while !stop.load(Ordering::Relaxed) {
                sent_at.push(now_us());
                send_retry(&tx, &numbered(sent_at.len() as u32 - 1))?;
                thread::sleep(Duration::from_millis(2));
            }
            Ok(sent_at)
        })
    };
    thread::sleep(Duration::from_millis(1500));
    let kill_us = now_us();
    let killed = z.signal("KILL");
    thread::sleep(Duration::from_millis(100));
    stop.store(true, Ordering::Relaxed);
    let sent_at = sender.join().map_err(|_| "sender panicked")??;
    killed?;
    let i = sent_at.len();
    let out = z.finish(TOOL_LIMIT)?;
    ensure!(
        !out.status.success(),
        "canzlogd survived SIGKILL: {}",
        out.status
    );
    let (lines, _) = zcat(&log_files(dir.path())?)?;
    for (k, l) in lines.iter().enumerate() {
        let got = number_of(l)?;
        ensure!(got == k as u32, "line {k} is frame {got}: {l:?}");
    }
    let logged = lines.len();
    let must = sent_at
        .iter()
        .filter(|&&t| t + (FLUSH_MS + SLACK_MS) * 1000 <= kill_us)
        .count();
    ensure!(
        logged >= must,
        "{logged} of {i} frames logged; the {must} sent more than {} ms before SIGKILL must be",
        FLUSH_MS + SLACK_MS
    );
    eprintln!(
        "    canzlogd SIGKILL: {logged} of {i} frames logged, last logged sent {} ms before kill(1) started",
        logged
            .checked_sub(1)
            .map_or(0, |k| kill_us.saturating_sub(sent_at[k]) / 1000)
    );
    Ok(())
}

/// `--max-size`: several files, each a whole gzip stream on its own;
/// `--max-age 1`: a new file after a second even when small. Read back in
/// name order they hold every frame once, in order.
fn canzlogd_rotates_by_size_and_age(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    for (opts, n, gap_ms, what) in [
        (
            ["--max-size", "200", "--flush-ms", "50"],
            100u32,
            5u64,
            "size",
        ),
        (["--max-age", "1", "--flush-ms", "100"], 60, 40, "age"),
    ] {
        let dir = TempDir::new("canzlogd-rot")?;
        let z = canzlogd(dir.path(), &opts)?;
        for i in 0..n {
            send_retry(&tx, &numbered(i))?;
            thread::sleep(Duration::from_millis(gap_ms));
        }
        stop(z, "canzlogd")?;
        let files = log_files(dir.path())?;
        ensure!(
            files.len() >= 2,
            "rotation by {what}: {} file(s)",
            files.len()
        );
        for f in &files {
            zcat(std::slice::from_ref(f)).map_err(|e| format!("{what}: {e}"))?;
        }
        let (lines, _) = zcat(&files)?;
        let nums: Result<Vec<u32>, String> = lines.iter().map(|l| number_of(l)).collect();
        let nums = nums?;
        ensure!(
            nums == (0..n).collect::<Vec<_>>(),
            "rotation by {what}: frames {nums:?}"
        );
        drop(dir);
    }
    Ok(())
}

/// SO_RXQ_OVFL: canzlogd with a tiny receive buffer is stopped (SIGSTOP)
/// while 200 frames arrive; after SIGCONT and one more frame (the kernel
/// reports drops with the next frame it queues), its notes report the
/// drops, and logged + reported = sent.
fn canzlogd_reports_rxq_overflow(ctx: &mut Ctx) -> TestResult {
    const N: u32 = 200;
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let dir = TempDir::new("canzlogd-ovfl")?;
    let z = canzlogd(dir.path(), &["--rcvbuf", "1", "--flush-ms", "100"])?;
    z.signal("STOP")?;
    for i in 0..N {
        send_retry(&tx, &numbered(i))?;
    }
    // The loopback device echoes in softirq; give it time to finish.
    thread::sleep(Duration::from_millis(300));
    z.signal("CONT")?;
    thread::sleep(Duration::from_millis(500));
    // SO_RXQ_OVFL reports drops with the next frame queued after them:
    // one more frame, once canzlogd has drained its queue.
    send_retry(&tx, &numbered(N))?;
    thread::sleep(Duration::from_millis(500));
    stop(z, "canzlogd")?;
    let (lines, notes) = zcat(&log_files(dir.path())?)?;
    let mut dropped = 0u64;
    for n in &notes {
        if let Some((_, rest)) = n.split_once("can0: ") {
            if let Some((k, _)) = rest.split_once(" frames dropped") {
                dropped += k.parse::<u64>().map_err(|_| format!("bad note {n:?}"))?;
            }
        }
    }
    ensure!(
        dropped > 0,
        "no drop reported; {} frames logged; notes {notes:?}",
        lines.len()
    );
    ensure!(
        lines.len() as u64 + dropped == u64::from(N + 1),
        "{} logged + {dropped} reported dropped != {} sent; notes {notes:?}",
        lines.len(),
        N + 1
    );
    Ok(())
}

/// Reads one `< ... >` message from a raw socketcand client connection.
fn read_msg(s: &mut TcpStream, pending: &mut String) -> Result<String, String> {
    let deadline = Instant::now() + TOOL_LIMIT;
    loop {
        if let Some(start) = pending.find('<') {
            if let Some(end) = pending[start..].find('>') {
                let m = pending[start..start + end + 1].to_string();
                pending.drain(..start + end + 1);
                return Ok(m);
            }
        }
        ensure!(
            Instant::now() < deadline,
            "no message from cantcpd; have {pending:?}"
        );
        let mut b = [0u8; 512];
        let n = s.read(&mut b).or_fail("read from cantcpd")?;
        ensure!(n > 0, "cantcpd closed the connection; have {pending:?}");
        pending.push_str(&String::from_utf8_lossy(&b[..n]));
    }
}

/// How long a python3 client may take to start and finish (under the
/// per-test watchdog of 180 s, so a slow start fails with this message).
const PY_LIMIT: Duration = Duration::from_secs(150);

/// The python-can side of the cantcpd test: sends two frames, then
/// prints the two it receives.
const PY_CLIENT: &str = r#"
import can, sys
bus = can.Bus(interface="socketcand", channel="can0", host="127.0.0.1", port=29536)
bus.send(can.Message(arbitration_id=0x123, data=[1, 2, 3], is_extended_id=False))
bus.send(can.Message(arbitration_id=0x1234567, data=[0xAA], is_extended_id=True))
print("SENT", flush=True)
for _ in range(2):
    m = bus.recv(timeout=60)
    if m is None:
        print("TIMEOUT", flush=True)
        sys.exit(1)
    print("RX %X %s" % (m.arbitration_id, m.data.hex()), flush=True)
bus.shutdown()
"#;

/// cantcpd on its default address (127.0.0.1:29536): python-can's
/// `socketcand` interface sends two frames, which a CAN_RAW socket and a
/// second (raw TCP) client receive; frames sent on can0 reach both
/// clients. SIGTERM ends cantcpd with status 0.
fn cantcpd_python_can_and_second_client(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let rx = canraw::open(idx)?;
    let mut srv = tools::spawn_own("cantcpd", &[], None)?;
    srv.wait_stderr("listening on 127.0.0.1:29536")?;

    let mut c2 = TcpStream::connect("127.0.0.1:29536").or_fail("connect")?;
    c2.set_read_timeout(Some(Duration::from_secs(5)))
        .or_fail("SO_RCVTIMEO")?;
    let mut pend = String::new();
    let expect = |c2: &mut TcpStream, pend: &mut String, want: &str| -> TestResult {
        let m = read_msg(c2, pend)?;
        ensure!(m == want, "second client: expected {want:?}, got {m:?}");
        Ok(())
    };
    expect(&mut c2, &mut pend, "< hi >")?;
    c2.write_all(b"< open can0 >").or_fail("write")?;
    expect(&mut c2, &mut pend, "< ok >")?;
    c2.write_all(b"< rawmode >").or_fail("write")?;
    expect(&mut c2, &mut pend, "< ok >")?;

    let py = tools::spawn("python3", &["-c", PY_CLIENT], None)?;
    // Importing python-can over 9p takes over a minute on the debug
    // kernel under TCG.
    wait_for(PY_LIMIT, "python-can client to send", || {
        if py.stdout_now().contains("SENT") {
            return Ok(Some(()));
        }
        if !py.stderr_now().is_empty() && py.stderr_now().contains("Error") {
            return Err(format!("python3: {}", py.stderr_now()));
        }
        Ok(None)
    })?;
    let from_py = [std(0x123, &[1, 2, 3]), ext(0x1234567, &[0xAA])];
    canraw::expect_seq(&rx, &from_py, "CAN_RAW socket, frames from python-can")?;
    let from_bus = [std(0x321, &[9, 8]), ext(0x1ABCDEF, &[])];
    for f in &from_bus {
        canraw::send(&rx, f)?;
        // python-can 4.1's socketcand reader loses a message split across
        // two reads: one frame at a time.
        thread::sleep(Duration::from_millis(200));
    }
    let out = py.finish(PY_LIMIT)?;
    ensure!(
        out.status.success()
            && out.stdout.contains("RX 321 0908")
            && out.stdout.contains("RX 1ABCDEF \n"),
        "python-can client: {}: stdout {:?}, stderr {:?}",
        out.status,
        out.stdout,
        out.stderr
    );
    let want2 = [
        ("< frame 123 ", " 010203 >"),
        ("< frame 01234567 ", " AA >"),
        ("< frame 321 ", " 0908 >"),
        ("< frame 01ABCDEF ", "  >"),
    ];
    for (pre, post) in want2 {
        let m = read_msg(&mut c2, &mut pend)?;
        ensure!(
            m.starts_with(pre) && m.ends_with(post),
            "second client: expected {pre}SEC.USEC{post}, got {m:?}"
        );
    }
    drop(c2);
    srv.signal("TERM")?;
    let out = srv.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "cantcpd after SIGTERM: {}: {}",
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// A socketcand client that reads nothing after `rawmode` (a small
/// SO_RCVBUF set before connecting); it prints READY and sleeps.
const PY_SLOW_CLIENT: &str = r#"
import socket, time
s = socket.socket()
s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
s.connect(("127.0.0.1", 29536))
for cmd in (None, b"< open can0 >", b"< rawmode >"):
    if cmd:
        s.sendall(cmd)
    reply = s.recv(64)
    assert reply in (b"< hi >", b"< ok >"), reply
print("READY", flush=True)
time.sleep(600)
"#;

/// A client that stops reading never stalls another: with `--queue 256
/// --sndbuf 4096`, 2,000 frames sent on can0 (one a millisecond, a busy
/// bus) all reach a reading client in order while a python client that reads nothing is connected; when the
/// latter goes, cantcpd reports the frames it dropped for it (and none for
/// the reading client).
fn cantcpd_slow_client_drops_alone(ctx: &mut Ctx) -> TestResult {
    const N: u32 = 2000;
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let mut srv = tools::spawn_own("cantcpd", &["--queue", "256", "--sndbuf", "4096"], None)?;
    srv.wait_stderr("listening on 127.0.0.1:29536")?;
    let mut fast = TcpStream::connect("127.0.0.1:29536").or_fail("connect")?;
    fast.set_read_timeout(Some(Duration::from_secs(10)))
        .or_fail("SO_RCVTIMEO")?;
    let mut pend = String::new();
    for (cmd, want) in [
        (None, "< hi >"),
        (Some("< open can0 >"), "< ok >"),
        (Some("< rawmode >"), "< ok >"),
    ] {
        if let Some(c) = cmd {
            fast.write_all(c.as_bytes()).or_fail("write")?;
        }
        let m = read_msg(&mut fast, &mut pend)?;
        ensure!(m == want, "reading client: expected {want:?}, got {m:?}");
    }
    let slow = tools::spawn("python3", &["-c", PY_SLOW_CLIENT], None)?;
    wait_for(PY_LIMIT, "the slow client to be in raw mode", || {
        if slow.stdout_now().contains("READY") {
            return Ok(Some(()));
        }
        if slow.stderr_now().contains("Error") {
            return Err(format!("python3: {}", slow.stderr_now()));
        }
        Ok(None)
    })?;
    // The reading client reads while the frames are sent, as a client on
    // a busy bus does.
    let reader = thread::spawn(move || -> TestResult {
        for i in 0..N {
            let m = read_msg(&mut fast, &mut pend)?;
            let want = format!("{:08X}", i.swap_bytes());
            ensure!(
                m.starts_with("< frame 100 ") && m.ends_with(&format!(" {want} >")),
                "reading client, frame {i}: got {m:?}"
            );
        }
        Ok(())
    });
    for i in 0..N {
        send_retry(&tx, &numbered(i))?;
        thread::sleep(Duration::from_millis(1));
    }
    reader.join().map_err(|_| "reader panicked")??;
    drop(slow);
    // Both connections are closed now (the reading one when its thread
    // ended): one "closed" line each, with its drop count.
    let counts = |err: &str| -> Vec<u32> {
        err.lines()
            .filter(|l| l.ends_with("frames dropped in all"))
            .filter_map(|l| l.split(", ").nth(1)?.split(' ').next()?.parse().ok())
            .collect()
    };
    let mut c = wait_for(TOOL_LIMIT, "cantcpd to close both clients", || {
        let c = counts(&srv.stderr_now());
        Ok((c.len() == 2).then_some(c))
    })?;
    c.sort();
    ensure!(
        c[0] == 0 && c[1] > 0 && c[1] < N,
        "drops reported for the two clients {c:?}, expected 0 for the reading one and some for the other: {}",
        srv.stderr_now()
    );
    srv.signal("TERM")?;
    let out = srv.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "cantcpd after SIGTERM: {}: {}",
        out.status,
        out.stderr.trim()
    );
    Ok(())
}

/// canzlogd on two interfaces, the two QEMU kvaser_pci cards on one bus:
/// frames sent on can0 with `cansend` (and a CAN_RAW socket) are logged
/// twice, as can0's local echo and as can1's reception from the bus, each
/// interface's lines in sending order.
fn sja1000_canzlogd_two_cards(ctx: &mut Ctx) -> TestResult {
    let (i0, _) = kvaser2(ctx)?;
    let tx = canraw::open(i0)?;
    let dir = TempDir::new("canzlogd-sja")?;
    let d = dir.path().to_str().ok_or("non-UTF-8 dir")?;
    let mut z = tools::spawn_own(
        "canzlogd",
        &["-d", d, "--flush-ms", "100", "can0", "can1"],
        None,
    )?;
    z.wait_stderr("canzlogd: logging")?;
    z.wait_listening()?;
    let mut want = Vec::new();
    // Remote frames with DLC 0 only (QEMU's SJA1000, see sja1000.rs).
    for (arg, line) in [
        ("123#1122", "123#1122"),
        ("12345678#", "12345678#"),
        ("7FF#R", "7FF#R"),
        ("000#0102030405060708", "000#0102030405060708"),
    ] {
        tools::run_ok("cansend", &["can0", arg])?;
        want.push(line.to_string());
    }
    // Paced: a burst overruns the receiving card's 64-byte FIFO, and
    // canzlogd then logs the controller's error frame
    // (20000004#0001..., CAN_ERR_CRTL_RX_OVERFLOW) instead of the frames
    // lost, as a black box should; this test wants every frame.
    for i in 0..50 {
        send_retry(&tx, &numbered(i))?;
        want.push(format!("100#{:08X}", i.swap_bytes()));
        thread::sleep(Duration::from_millis(5));
    }
    thread::sleep(Duration::from_millis(500));
    stop(z, "canzlogd")?;
    let (lines, _) = zcat(&log_files(dir.path())?)?;
    for iface in ["can0", "can1"] {
        let got: Vec<&str> = lines
            .iter()
            .filter_map(|l| body(l).strip_prefix(iface)?.strip_prefix(' '))
            .collect();
        ensure!(got == want, "{iface}: logged {got:?}, expected {want:?}");
    }
    ensure!(
        lines.len() == 2 * want.len(),
        "{} lines for {} frames on two interfaces: {lines:?}",
        lines.len(),
        want.len()
    );
    Ok(())
}
