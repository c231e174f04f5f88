// SPDX-License-Identifier: GPL-2.0
//! `powerd` (thesis 3.3): listens on a CAN interface for the frame that
//! commands an orderly shutdown, then stops the programs that write the
//! log partition, syncs and unmounts it (Documentation/networking/rcan/
//! powerd.rst). One thread: poll(2) on the CAN_RAW socket and a signalfd.

use std::os::fd::AsFd;
use std::path::Path;
use std::process::ExitCode;
use std::thread;
use std::time::{Duration, Instant};

use clap::Parser;
use nix::errno::Errno;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::spawn::{posix_spawn, PosixSpawnAttr, PosixSpawnFileActions, PosixSpawnFlags};
use nix::sys::signal::{kill, SigSet, Signal};
use nix::sys::wait::{waitpid, WaitStatus};
use nix::unistd::Pid;
use rcan_daemons::canrx::CanPort;
use rcan_daemons::cli::PowerCli;
use rcan_daemons::powerd::Pattern;
use rcan_daemons::signals;

/// How often the waits look again.
const POLL: Duration = Duration::from_millis(50);

/// The pids named by `--pidfile` and `--name`; problems as messages.
fn targets(cli: &PowerCli, errors: &mut Vec<String>) -> Vec<(Pid, String)> {
    let mut v = Vec::new();
    for f in &cli.pidfile {
        match std::fs::read_to_string(f) {
            Ok(s) => match s.trim().parse::<i32>() {
                Ok(p) if p > 0 => {
                    v.push((Pid::from_raw(p), format!("pid {p} from {}", f.display())))
                }
                _ => errors.push(format!("{}: no pid in it", f.display())),
            },
            Err(e) => errors.push(format!("{}: {e}", f.display())),
        }
    }
    if !cli.name.is_empty() {
        let me = std::process::id();
        let procs = std::fs::read_dir("/proc").map(|d| {
            d.filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().to_str()?.parse::<i32>().ok())
                .collect::<Vec<_>>()
        });
        let procs = procs.unwrap_or_default();
        for n in &cli.name {
            let before = v.len();
            for &p in &procs {
                if p as u32 == me {
                    continue;
                }
                let comm = std::fs::read_to_string(format!("/proc/{p}/comm")).unwrap_or_default();
                if comm.trim_end_matches('\n') == n {
                    v.push((Pid::from_raw(p), format!("pid {p} ({n})")));
                }
            }
            if v.len() == before {
                eprintln!("powerd: no process named {n}");
            }
        }
    }
    v
}

/// The shutdown sequence; true if every step succeeded.
fn shutdown(cli: &PowerCli) -> bool {
    let dry = if cli.dry_run { "dry run: would " } else { "" };
    let mut errors = Vec::new();
    let pids = targets(cli, &mut errors);
    let t0 = Instant::now();
    let limit = Duration::from_millis(cli.wait_ms);
    for (pid, what) in &pids {
        eprintln!("powerd: {dry}send {} to {what}", cli.signal);
        if !cli.dry_run {
            if let Err(e) = kill(*pid, cli.signal) {
                errors.push(format!("kill {what}: {e}"));
            }
        }
    }
    if !cli.dry_run {
        // Wait for them to go (ESRCH), so that their last writes are in
        // before sync and unmount.
        let mut alive: Vec<&(Pid, String)> = pids.iter().collect();
        while !alive.is_empty() && t0.elapsed() < limit {
            alive.retain(|(p, _)| running(*p));
            if !alive.is_empty() {
                thread::sleep(POLL);
            }
        }
        for (_, what) in alive {
            errors.push(format!("{what} still running after {} ms", cli.wait_ms));
        }
    }
    if !cli.no_sync {
        eprintln!("powerd: {dry}sync");
        if !cli.dry_run {
            nix::unistd::sync();
        }
    }
    for d in &cli.umount {
        eprintln!("powerd: {dry}unmount {}", d.display());
        if cli.dry_run {
            continue;
        }
        if let Err(e) = umount(d, t0, limit) {
            errors.push(format!("unmount {}: {e}", d.display()));
        }
    }
    if let Some(c) = &cli.exec {
        eprintln!("powerd: {dry}run {c}");
        if !cli.dry_run {
            match shell(c) {
                Ok(WaitStatus::Exited(_, 0)) => {}
                Ok(s) => errors.push(format!("{c}: {s:?}")),
                Err(e) => errors.push(format!("{c}: {e}")),
            }
        }
    }
    for e in &errors {
        eprintln!("powerd: {e}");
    }
    eprintln!(
        "powerd: shutdown sequence {}",
        if errors.is_empty() {
            "done"
        } else {
            "done with errors"
        }
    );
    errors.is_empty()
}

/// Runs `/bin/sh -c COMMAND` and waits for it. posix_spawn with an empty
/// signal mask: powerd blocks SIGTERM and SIGINT (its signalfd), and a
/// child started with std's Command would inherit that mask and could
/// not be stopped with them.
fn shell(command: &str) -> Result<WaitStatus, String> {
    use std::ffi::CString;
    use std::os::unix::ffi::OsStringExt;
    let e = |e: Errno| e.to_string();
    let mut attr = PosixSpawnAttr::init().map_err(e)?;
    attr.set_sigmask(&SigSet::empty()).map_err(e)?;
    attr.set_flags(PosixSpawnFlags::POSIX_SPAWN_SETSIGMASK)
        .map_err(e)?;
    let actions = PosixSpawnFileActions::init().map_err(e)?;
    let args = [
        CString::new("sh").map_err(|x| x.to_string())?,
        CString::new("-c").map_err(|x| x.to_string())?,
        CString::new(command).map_err(|x| x.to_string())?,
    ];
    let env: Vec<CString> = std::env::vars_os()
        .filter_map(|(k, v)| {
            let mut b = k.into_vec();
            b.push(b'=');
            b.extend(v.into_vec());
            CString::new(b).ok()
        })
        .collect();
    let pid = posix_spawn(Path::new("/bin/sh"), &actions, &attr, &args, &env).map_err(e)?;
    waitpid(pid, None).map_err(e)
}

/// True while `pid` exists and is not a zombie (a zombie has closed its
/// files and left its working directory: it holds no mount busy, only its
/// parent has yet to reap it).
fn running(pid: Pid) -> bool {
    if kill(pid, None::<Signal>) == Err(Errno::ESRCH) {
        return false;
    }
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // `PID (COMM) STATE ...`; COMM may contain spaces and parentheses.
    let state = stat
        .rsplit_once(')')
        .and_then(|(_, r)| r.split_whitespace().next());
    !matches!(state, Some("Z") | Some("X") | None)
}

/// umount(2), retried while EBUSY until `limit` after `t0`.
fn umount(d: &Path, t0: Instant, limit: Duration) -> Result<(), Errno> {
    loop {
        match nix::mount::umount(d) {
            Err(Errno::EBUSY) if t0.elapsed() < limit => thread::sleep(POLL),
            r => return r,
        }
    }
}

fn run(cli: &PowerCli) -> Result<bool, String> {
    let pat = Pattern::new(
        cli.id,
        cli.data.0.clone(),
        cli.mask.as_ref().map(|m| m.0.clone()),
    )?;
    let sfd = signals::stop_signals()?;
    let port = CanPort::open(&cli.iface, false).map_err(|e| format!("{}: {e}", cli.iface))?;
    let (fid, fmask) = pat.raw_filter();
    port.set_filter(fid, fmask)
        .map_err(|e| format!("{}: CAN_RAW_FILTER: {e}", cli.iface))?;
    eprintln!(
        "powerd: waiting on {} for the shutdown frame{}",
        cli.iface,
        if cli.dry_run { " (dry run)" } else { "" }
    );
    loop {
        let mut fds = [
            PollFd::new(sfd.as_fd(), PollFlags::POLLIN),
            PollFd::new(port.as_fd(), PollFlags::POLLIN),
        ];
        match poll(&mut fds, PollTimeout::NONE) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(e) => return Err(format!("poll: {e}")),
        }
        if fds[0].any().unwrap_or(false) {
            let sig = signals::signo(&sfd);
            eprintln!("powerd: signal {sig}: stopped, no shutdown frame seen");
            return Ok(true);
        }
        loop {
            match port.recv(true) {
                Ok(Some(r)) if pat.matches(&r.frame) => {
                    let mut s = String::new();
                    r.frame.write_candump(&mut s);
                    eprintln!(
                        "powerd: {}: shutdown frame {s} at {}.{:06}",
                        cli.iface, r.sec, r.usec
                    );
                    return Ok(shutdown(cli));
                }
                Ok(Some(_)) => {}
                Ok(None) => break,
                Err(e) => {
                    // ENETDOWN while the interface is down, for instance:
                    // keep listening.
                    eprintln!("powerd: {}: receive error: {e}", cli.iface);
                    thread::sleep(Duration::from_millis(500));
                    break;
                }
            }
        }
    }
}

fn main() -> ExitCode {
    let cli = PowerCli::parse();
    match run(&cli) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("powerd: {e}");
            ExitCode::FAILURE
        }
    }
}
