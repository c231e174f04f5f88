// SPDX-License-Identifier: GPL-2.0
//! `logd` (thesis 3.3): logs the DSOR segmented messages of the given
//! node/id pairs, one line each with a timestamp, in the format of
//! `logd.rs` (Documentation/networking/rcan/logd.rst). One thread:
//! poll(2) on one CANPROTO_DSOR socket per source and a signalfd.

use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Write};
use std::os::fd::AsFd;
use std::process::ExitCode;
use std::time::{SystemTime, UNIX_EPOCH};

use clap::Parser;
use nix::errno::Errno;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use rcan_daemons::cli::LogdCli;
use rcan_daemons::logd::{line, ID_ANY, NODE_ANY};
use rcan_daemons::signals;
use rcan_uapi::dsor::{DsorAddr, DsorSocket};

/// `MSG_TRUNC`: recvfrom returns the message's full length.
const MSG_TRUNC: i32 = 0x20;

fn now() -> (u64, u32) {
    let t = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    (t.as_secs(), t.subsec_micros())
}

/// Appends `text` (whole lines) with one write(2); fdatasync with `sync`.
fn append(f: &mut File, text: &str, sync: bool) -> std::io::Result<()> {
    f.write_all(text.as_bytes())?;
    if sync {
        f.sync_data()?;
    }
    Ok(())
}

fn note(f: &mut File, text: &str, sync: bool) -> std::io::Result<()> {
    let (s, us) = now();
    append(f, &format!("# logd ({s:010}.{us:06}): {text}\n"), sync)
}

fn show(node: u8, id: u32) -> String {
    let n = if node == NODE_ANY {
        "any".to_string()
    } else {
        format!("0x{node:02x}")
    };
    let i = if id == ID_ANY {
        "any".to_string()
    } else {
        format!("0x{id:x}")
    };
    format!("{n}:{i}")
}

fn run(cli: LogdCli) -> Result<(), String> {
    let sfd = signals::stop_signals()?;
    let mut socks = Vec::new();
    for &(node, id) in &cli.sources {
        let what = show(node, id);
        let s = DsorSocket::new().map_err(|e| {
            format!("socket(PF_CAN, SOCK_DGRAM, CANPROTO_DSOR): {e} (is rcan_dsor loaded?)")
        })?;
        s.bind(&DsorAddr::Segm { prio: 0, node, id })
            .map_err(|e| format!("bind {what}: {e}"))?;
        s.set_nonblocking(true)
            .map_err(|e| format!("{what}: O_NONBLOCK: {e}"))?;
        socks.push((s, what));
    }
    if let Some(d) = cli.log.parent() {
        if !d.as_os_str().is_empty() {
            std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
        }
    }
    let mut f = OpenOptions::new()
        .create(true)
        .append(true)
        .open(&cli.log)
        .map_err(|e| format!("{}: {e}", cli.log.display()))?;
    let fail = |e: std::io::Error| format!("{}: {e}", cli.log.display());
    let names: Vec<&str> = socks.iter().map(|(_, w)| w.as_str()).collect();
    note(
        &mut f,
        &format!(
            "{} started, sources {}",
            env!("CARGO_PKG_VERSION"),
            names.join(" ")
        ),
        cli.fsync,
    )
    .map_err(fail)?;
    eprintln!(
        "logd: logging {} into {}",
        names.join(" "),
        cli.log.display()
    );

    let max = usize::try_from(cli.max_len).unwrap_or(65535);
    let mut buf = vec![0u8; max];
    let mut text = String::with_capacity(2 * max + 64);
    let mut count: u64 = 0;
    let mut fds = Vec::with_capacity(socks.len() + 1);
    let mut ready = vec![false; socks.len()];
    loop {
        fds.clear();
        fds.push(PollFd::new(sfd.as_fd(), PollFlags::POLLIN));
        fds.extend(
            socks
                .iter()
                .map(|(s, _)| PollFd::new(s.as_fd(), PollFlags::POLLIN)),
        );
        match poll(&mut fds, PollTimeout::NONE) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(e) => return Err(format!("poll: {e}")),
        }
        if fds[0].any().unwrap_or(false) {
            let sig = signals::signo(&sfd);
            note(
                &mut f,
                &format!("stopping on signal {sig}, {count} messages logged"),
                cli.fsync,
            )
            .map_err(fail)?;
            f.sync_data().map_err(fail)?;
            eprintln!("logd: signal {sig}: {count} messages logged");
            return Ok(());
        }
        for (r, p) in ready.iter_mut().zip(&fds[1..]) {
            *r = p.any().unwrap_or(false);
        }
        for (i, (s, what)) in socks.iter().enumerate() {
            if !ready[i] {
                continue;
            }
            loop {
                match s.recv_from_flags(&mut buf, MSG_TRUNC) {
                    Ok((n, addr)) => {
                        let (sec, usec) = now();
                        let (node, id) = match addr {
                            Some(DsorAddr::Segm { node, id, .. }) => (node, id),
                            _ => (NODE_ANY, ID_ANY),
                        };
                        text.clear();
                        line(&mut text, sec, usec, node, id, &buf[..n.min(max)]);
                        if n > max {
                            text.push_str(&format!(
                                "# logd: the message above had {n} bytes, logged {max}\n"
                            ));
                        }
                        append(&mut f, &text, cli.fsync).map_err(fail)?;
                        count += 1;
                    }
                    Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                    Err(e) => {
                        note(&mut f, &format!("{what}: receive error: {e}"), cli.fsync)
                            .map_err(fail)?;
                        break;
                    }
                }
            }
        }
    }
}

fn main() -> ExitCode {
    let cli = LogdCli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("logd: {e}");
            ExitCode::FAILURE
        }
    }
}
