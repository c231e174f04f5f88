// SPDX-License-Identifier: GPL-2.0
//! `canzlogd`: the vehicle's black box (thesis 3.3). Logs every frame of
//! the given interfaces, error frames included, with kernel timestamps,
//! in `candump -l` format into rotating gzip files; the flush policy is in
//! `zlog.rs` and Documentation/networking/rcan/canzlogd.rst.
//!
//! One thread: poll(2) on the CAN_RAW sockets and a signalfd (SIGTERM,
//! SIGINT), with a timeout that ends at the next flush.

use std::os::fd::AsFd;
use std::process::ExitCode;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use clap::Parser;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use rcan_daemons::canrx::CanPort;
use rcan_daemons::cli::ZlogCli;
use rcan_daemons::frame::candump_line;
use rcan_daemons::signals;
use rcan_daemons::zlog::{Config, ZLog};

/// Frames read from one socket before the others get their turn.
const BATCH: usize = 256;
/// Frames read from one socket when a signal stops the daemon: far more
/// than a receive buffer holds, a bound on a bus that never goes quiet.
const DRAIN_MAX: usize = 65_536;

/// A `# ` note line, which candump -l readers skip.
fn note(z: &mut ZLog, text: &str) {
    let t = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    let line = format!(
        "# canzlogd ({:010}.{:06}): {text}\n",
        t.as_secs(),
        t.subsec_micros()
    );
    z.buf().push_str(&line);
    z.line_added();
}

fn run(cli: ZlogCli) -> Result<(), String> {
    let sfd = signals::stop_signals()?;

    let mut ports = Vec::new();
    for i in &cli.ifaces {
        let p = CanPort::open(i, !cli.no_errors).map_err(|e| format!("{i}: {e}"))?;
        if let Some(b) = cli.rcvbuf {
            p.set_rcvbuf(b)
                .map_err(|e| format!("{i}: SO_RCVBUF: {e}"))?;
        }
        ports.push(p);
    }
    let mut last_drop = vec![0u32; ports.len()];
    let mut z = ZLog::new(Config {
        dir: cli.dir.clone(),
        prefix: cli.prefix.clone(),
        max_size: cli.max_size,
        max_age: Duration::from_secs(cli.max_age),
        fsync: !cli.no_fsync,
        level: cli.level,
    })
    .map_err(|e| format!("{}: {e}", cli.dir.display()))?;
    note(
        &mut z,
        &format!(
            "{} started on {}, flush every {} ms",
            env!("CARGO_PKG_VERSION"),
            cli.ifaces.join(" "),
            cli.flush_ms
        ),
    );
    let fail =
        |e: std::io::Error, z: &ZLog| format!("{}: {e}", z.current().unwrap_or(&cli.dir).display());
    z.flush().map_err(|e| fail(e, &z))?;
    eprintln!(
        "canzlogd: logging {} into {}",
        cli.ifaces.join(" "),
        cli.dir.display()
    );

    let interval = Duration::from_millis(cli.flush_ms);
    let mut next_flush = Instant::now() + interval;
    let mut frames: u64 = 0;
    let mut errors = vec![0u64; ports.len()];
    // Reused every round: no allocation per wakeup.
    let mut fds = Vec::with_capacity(ports.len() + 1);
    let mut ready = vec![false; ports.len()];
    loop {
        let now = Instant::now();
        let wait = next_flush.saturating_duration_since(now);
        // Round up: waking a little early would spin until the deadline.
        let ms = wait.as_millis().saturating_add(1).min(60_000) as u32;
        fds.clear();
        fds.push(PollFd::new(sfd.as_fd(), PollFlags::POLLIN));
        fds.extend(
            ports
                .iter()
                .map(|p| PollFd::new(p.as_fd(), PollFlags::POLLIN)),
        );
        match poll(
            &mut fds,
            PollTimeout::try_from(ms).unwrap_or(PollTimeout::MAX),
        ) {
            Ok(_) | Err(nix::errno::Errno::EINTR) => {}
            Err(e) => return Err(format!("poll: {e}")),
        }
        let stop = fds[0].any().unwrap_or(false);
        for (r, f) in ready.iter_mut().zip(&fds[1..]) {
            *r = f.any().unwrap_or(false);
        }
        // On a signal every socket is drained first: a frame the kernel
        // queued before the signal is logged, not lost with the socket.
        if stop {
            ready.iter_mut().for_each(|r| *r = true);
        }
        let batch = if stop { DRAIN_MAX } else { BATCH };
        for (i, p) in ports.iter().enumerate() {
            if !ready[i] {
                continue;
            }
            for _ in 0..batch {
                match p.recv(true) {
                    Ok(Some(r)) => {
                        if r.dropped != last_drop[i] {
                            let n = r.dropped.wrapping_sub(last_drop[i]);
                            last_drop[i] = r.dropped;
                            note(
                                &mut z,
                                &format!(
                                    "{}: {n} frames dropped (SO_RXQ_OVFL total {})",
                                    p.iface, r.dropped
                                ),
                            );
                        }
                        candump_line(z.buf(), r.sec, r.usec, &p.iface, &r.frame);
                        frames += 1;
                        if z.line_added() {
                            z.flush().map_err(|e| fail(e, &z))?;
                        }
                    }
                    Ok(None) => break,
                    Err(e) => {
                        // ENETDOWN when the interface goes down, for
                        // instance: noted (the first 100 per interface),
                        // and logging goes on.
                        errors[i] += 1;
                        if errors[i] <= 100 {
                            note(&mut z, &format!("{}: receive error: {e}", p.iface));
                        }
                        break;
                    }
                }
            }
        }
        if stop {
            let sig = signals::signo(&sfd);
            note(
                &mut z,
                &format!("stopping on signal {sig}, {frames} frames logged"),
            );
            z.close().map_err(|e| fail(e, &z))?;
            eprintln!(
                "canzlogd: signal {sig}: {frames} frames logged, {} bytes written",
                z.bytes_written
            );
            return Ok(());
        }
        if Instant::now() >= next_flush {
            z.flush().map_err(|e| fail(e, &z))?;
            next_flush += interval;
            if next_flush < Instant::now() {
                next_flush = Instant::now() + interval;
            }
        }
    }
}

fn main() -> ExitCode {
    let cli = ZlogCli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("canzlogd: {e}");
            ExitCode::FAILURE
        }
    }
}
