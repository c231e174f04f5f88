// SPDX-License-Identifier: GPL-2.0
//! `cantcpd`: the vehicle's CAN-over-TCP proxy (thesis 3.3), speaking
//! socketcand's raw mode (`socketcand.rs`) so existing clients connect
//! unchanged.
//!
//! Threads: the main thread accepts connections and watches a signalfd
//! (SIGTERM, SIGINT). Each client has three: the command reader (its
//! TCP input, owns the CAN socket's sending side), the CAN receiver
//! (started by `< rawmode >`; never blocks on the client: it puts frames
//! into the client's bounded queue or counts them dropped) and the
//! writer (drains the queue into TCP, as slowly as the client reads).
//! Replies and frames share the TCP stream under `Client::out`, a mutex
//! held for one whole message, so messages never interleave.

use std::io::{self, ErrorKind, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::os::fd::AsFd;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, RecvTimeoutError, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use clap::Parser;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::signal::{SigSet, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use rcan_daemons::canrx::CanPort;
use rcan_daemons::cli::TcpCli;
use rcan_daemons::socketcand::{frame_msg, parse, Command, Splitter};

/// How often blocked threads look at the stop flags.
const TICK: Duration = Duration::from_millis(200);

/// State shared by all threads.
struct Server {
    /// Set on SIGTERM/SIGINT: every client thread ends.
    stop: AtomicBool,
    /// Clients connected now.
    active: AtomicUsize,
    queue: usize,
    allow: Vec<String>,
    sndbuf: Option<usize>,
}

/// One connection.
struct Client {
    /// The TCP stream for output; locked for one whole message.
    out: Mutex<TcpStream>,
    /// Set when the connection ends (either side): its threads stop.
    closed: AtomicBool,
    /// Frames dropped because the queue was full.
    dropped: AtomicU64,
    peer: String,
}

impl Client {
    fn send(&self, msg: &str) -> io::Result<()> {
        let mut s = self.out.lock().unwrap_or_else(|e| e.into_inner());
        s.write_all(msg.as_bytes())
    }

    fn done(&self, srv: &Server) -> bool {
        self.closed.load(Ordering::Relaxed) || srv.stop.load(Ordering::Relaxed)
    }
}

/// CAN receiver: frames into the bounded queue, never waiting for it.
fn rx_loop(
    srv: Arc<Server>,
    cl: Arc<Client>,
    port: Arc<CanPort>,
    q: std::sync::mpsc::SyncSender<String>,
) {
    let mut last_ovfl = 0;
    while !cl.done(&srv) {
        match port.recv(false) {
            Ok(Some(r)) => {
                if r.dropped != last_ovfl {
                    eprintln!(
                        "cantcpd: {}: {}: {} frames dropped by the socket",
                        cl.peer,
                        port.iface,
                        r.dropped.wrapping_sub(last_ovfl)
                    );
                    last_ovfl = r.dropped;
                }
                let mut m = String::with_capacity(48);
                frame_msg(&mut m, &r.frame, r.sec, r.usec);
                match q.try_send(m) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_)) => {
                        cl.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(TrySendError::Disconnected(_)) => break,
                }
            }
            Ok(None) => {}
            Err(e) if e.kind() == ErrorKind::WouldBlock => {}
            Err(e) => {
                let _ = cl.send(&format!("< error receive: {e} >"));
                thread::sleep(TICK);
            }
        }
    }
}

/// Writer: the queue into TCP; reports drops at most once a second.
fn tx_loop(srv: Arc<Server>, cl: Arc<Client>, q: std::sync::mpsc::Receiver<String>) {
    let mut reported = 0;
    let mut last_report = Instant::now();
    while !cl.done(&srv) {
        match q.recv_timeout(TICK) {
            Ok(m) => {
                if cl.send(&m).is_err() {
                    break;
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        let d = cl.dropped.load(Ordering::Relaxed);
        if d != reported && last_report.elapsed() >= Duration::from_secs(1) {
            eprintln!(
                "cantcpd: {}: {} frames dropped (queue full)",
                cl.peer,
                d - reported
            );
            if cl
                .send(&format!("< error dropped {} >", d - reported))
                .is_err()
            {
                break;
            }
            reported = d;
            last_report = Instant::now();
        }
    }
    cl.closed.store(true, Ordering::Relaxed);
}

/// One command; the reply, if any.
fn handle(
    srv: &Arc<Server>,
    cl: &Arc<Client>,
    port: &mut Option<Arc<CanPort>>,
    threads: &mut Vec<thread::JoinHandle<()>>,
    msg: Result<String, String>,
) -> Option<String> {
    let cmd = match msg.and_then(|m| parse(&m)) {
        Ok(c) => c,
        Err(e) => return Some(format!("< error {e} >")),
    };
    match cmd {
        Command::Open(iface) => {
            if port.is_some() {
                return Some("< error already open >".into());
            }
            if !srv.allow.is_empty() && !srv.allow.contains(&iface) {
                return Some(format!("< error {iface} not allowed >"));
            }
            match CanPort::open(&iface, false)
                .and_then(|p| p.set_read_timeout(Some(TICK)).map(|()| p))
            {
                Ok(p) => {
                    *port = Some(Arc::new(p));
                    Some("< ok >".into())
                }
                Err(e) => Some(format!("< error open {iface}: {e} >")),
            }
        }
        Command::RawMode => {
            let Some(p) = port else {
                return Some("< error no interface open >".into());
            };
            if !threads.is_empty() {
                return Some("< ok >".into());
            }
            // The reply goes out before the first frame can.
            if cl.send("< ok >").is_err() {
                cl.closed.store(true, Ordering::Relaxed);
                return None;
            }
            let (tx, rx) = sync_channel(srv.queue);
            let (s1, c1, p1) = (Arc::clone(srv), Arc::clone(cl), Arc::clone(p));
            threads.push(thread::spawn(move || rx_loop(s1, c1, p1, tx)));
            let (s2, c2) = (Arc::clone(srv), Arc::clone(cl));
            threads.push(thread::spawn(move || tx_loop(s2, c2, rx)));
            None
        }
        Command::Send(f) => match port {
            None => Some("< error no interface open >".into()),
            Some(p) => match p.send(&f) {
                Ok(()) => None,
                Err(e) => Some(format!("< error send: {e} >")),
            },
        },
        Command::Echo => Some("< echo >".into()),
        Command::Unsupported(w) => Some(format!("< error unsupported command {w} >")),
    }
}

/// The command reader of one connection, until it ends.
fn client(srv: Arc<Server>, stream: TcpStream) {
    let peer = stream
        .peer_addr()
        .map(|a| a.to_string())
        .unwrap_or_else(|_| "?".into());
    let _ = stream.set_nodelay(true);
    if let Some(b) = srv.sndbuf {
        if let Err(e) = nix::sys::socket::setsockopt(&stream, nix::sys::socket::sockopt::SndBuf, &b)
        {
            eprintln!("cantcpd: {peer}: SO_SNDBUF: {e}");
        }
    }
    let _ = stream.set_read_timeout(Some(TICK));
    let mut input = match stream.try_clone() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("cantcpd: {peer}: {e}");
            return;
        }
    };
    let cl = Arc::new(Client {
        out: Mutex::new(stream),
        closed: AtomicBool::new(false),
        dropped: AtomicU64::new(0),
        peer,
    });
    let mut port = None;
    let mut threads = Vec::new();
    let mut split = Splitter::default();
    let mut buf = [0u8; 1024];
    if cl.send("< hi >").is_ok() {
        while !cl.done(&srv) {
            match input.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => split.feed(&buf[..n]),
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) =>
                {
                    continue
                }
                Err(_) => break,
            }
            while let Some(m) = split.next_msg() {
                if let Some(reply) = handle(&srv, &cl, &mut port, &mut threads, m) {
                    if cl.send(&reply).is_err() {
                        cl.closed.store(true, Ordering::Relaxed);
                    }
                }
            }
        }
    }
    cl.closed.store(true, Ordering::Relaxed);
    let _ = input.shutdown(Shutdown::Both);
    for t in threads {
        let _ = t.join();
    }
    let d = cl.dropped.load(Ordering::Relaxed);
    eprintln!("cantcpd: {}: closed, {d} frames dropped in all", cl.peer);
    srv.active.fetch_sub(1, Ordering::SeqCst);
}

fn run(cli: TcpCli) -> Result<(), String> {
    let mut mask = SigSet::empty();
    mask.add(Signal::SIGTERM);
    mask.add(Signal::SIGINT);
    // Blocked before any thread starts, so every thread inherits the mask
    // and only the signalfd sees the signals.
    mask.thread_block()
        .map_err(|e| format!("sigprocmask: {e}"))?;
    let sfd = SignalFd::with_flags(&mask, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)
        .map_err(|e| format!("signalfd: {e}"))?;
    let listener = TcpListener::bind(cli.listen).map_err(|e| format!("{}: {e}", cli.listen))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("{}: {e}", cli.listen))?;
    let srv = Arc::new(Server {
        stop: AtomicBool::new(false),
        active: AtomicUsize::new(0),
        queue: usize::try_from(cli.queue).unwrap_or(usize::MAX),
        allow: cli.allow.clone(),
        sndbuf: cli.sndbuf,
    });
    eprintln!(
        "cantcpd: listening on {}",
        listener.local_addr().map_err(|e| e.to_string())?
    );
    loop {
        let mut fds = [
            PollFd::new(sfd.as_fd(), PollFlags::POLLIN),
            PollFd::new(listener.as_fd(), PollFlags::POLLIN),
        ];
        match poll(&mut fds, PollTimeout::NONE) {
            Ok(_) | Err(nix::errno::Errno::EINTR) => {}
            Err(e) => return Err(format!("poll: {e}")),
        }
        if fds[0].any().unwrap_or(false) {
            let sig = sfd
                .read_signal()
                .ok()
                .flatten()
                .map(|s| s.ssi_signo)
                .unwrap_or(0);
            srv.stop.store(true, Ordering::SeqCst);
            let t0 = Instant::now();
            while srv.active.load(Ordering::SeqCst) > 0 && t0.elapsed() < Duration::from_secs(3) {
                thread::sleep(Duration::from_millis(20));
            }
            eprintln!("cantcpd: signal {sig}: stopped");
            return Ok(());
        }
        loop {
            match listener.accept() {
                Ok((s, addr)) => {
                    let _ = s.set_nonblocking(false);
                    if srv.active.load(Ordering::SeqCst) >= cli.max_clients {
                        let mut s = s;
                        let _ = s.write_all(b"< error too many clients >");
                        eprintln!("cantcpd: {addr}: refused, {} clients", cli.max_clients);
                        continue;
                    }
                    srv.active.fetch_add(1, Ordering::SeqCst);
                    eprintln!("cantcpd: {addr}: connected");
                    let s2 = Arc::clone(&srv);
                    thread::spawn(move || client(s2, s));
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) => {
                    eprintln!("cantcpd: accept: {e}");
                    break;
                }
            }
        }
    }
}

fn main() -> ExitCode {
    let cli = TcpCli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("cantcpd: {e}");
            ExitCode::FAILURE
        }
    }
}
