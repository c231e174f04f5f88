// SPDX-License-Identifier: GPL-2.0
//! `cantcpd`: the vehicle's CAN-over-TCP proxy (thesis 3.3), speaking
//! socketcand's BCM mode (CAN_BCM, `bcm.rs`) and raw mode
//! (`socketcand.rs`) so existing clients connect unchanged.
//!
//! Threads: the main thread accepts connections and watches a signalfd
//! (SIGTERM, SIGINT). Each client has three: the command reader (its
//! TCP input, owns the mode's socket and sends BCM requests and frames),
//! the receiver of the current mode (started by `< open >`, replaced on a
//! mode switch; never blocks on the client: it puts messages into the
//! client's bounded queue or counts them dropped) and the writer (drains
//! the queue into TCP, as slowly as the client reads; started by `open`).
//! Replies and frames share the TCP stream under `Client::out`, a mutex
//! held for one whole message, so messages never interleave.

use std::io::{self, ErrorKind, Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::os::fd::AsFd;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use clap::Parser;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use rcan_daemons::bcm::{self, BcmSocket};
use rcan_daemons::canrx::CanPort;
use rcan_daemons::cli::TcpCli;
use rcan_daemons::frame::Frame;
use rcan_daemons::signals;
use rcan_daemons::socketcand::{bcm_frame_msg, frame_msg, parse, Command, Splitter};

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

/// Raw-mode receiver: every frame of the interface into the bounded
/// queue, never waiting for it. Ends when `stop` is set (mode switch) or
/// the client ends.
fn rx_loop(
    srv: Arc<Server>,
    cl: Arc<Client>,
    port: Arc<CanPort>,
    q: SyncSender<String>,
    stop: Arc<AtomicBool>,
) {
    let mut last_ovfl = 0;
    while !cl.done(&srv) && !stop.load(Ordering::Relaxed) {
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
                if !queue(&cl, &q, m) {
                    break;
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

/// Puts one message into the client's queue, or counts it dropped when
/// the queue is full; false once the writer is gone.
fn queue(cl: &Client, q: &SyncSender<String>, m: String) -> bool {
    match q.try_send(m) {
        Ok(()) => true,
        Err(TrySendError::Full(_)) => {
            cl.dropped.fetch_add(1, Ordering::Relaxed);
            true
        }
        Err(TrySendError::Disconnected(_)) => false,
    }
}

/// BCM-mode receiver: what the broadcast manager reports for the
/// client's filters and subscriptions (`RX_CHANGED`), into the queue.
fn bcm_rx_loop(
    srv: Arc<Server>,
    cl: Arc<Client>,
    sock: Arc<BcmSocket>,
    q: SyncSender<String>,
    stop: Arc<AtomicBool>,
) {
    while !cl.done(&srv) && !stop.load(Ordering::Relaxed) {
        match sock.recv() {
            Ok(Some((bcm::RX_CHANGED, _, Some(f), sec, usec))) => {
                let mut m = String::with_capacity(64);
                bcm_frame_msg(&mut m, &f, sec, usec);
                if !queue(&cl, &q, m) {
                    break;
                }
            }
            // RX_TIMEOUT, TX_EXPIRED and the like: cantcpd sets up
            // nothing that produces them; ignored.
            Ok(_) => {}
            Err(e) => {
                let _ = cl.send(&format!("< error receive: {e} >"));
                thread::sleep(TICK);
            }
        }
    }
}

/// Writer: the queue into TCP; reports drops at most once a second.
fn tx_loop(srv: Arc<Server>, cl: Arc<Client>, q: Receiver<String>) {
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

/// The socket of the current mode.
enum Mode {
    /// BCM mode (socketcand's default after `open`): a CAN_BCM socket, or
    /// why there is none (CAN_BCM not available: the BCM commands are
    /// answered with this error, raw mode works).
    Bcm(Result<Arc<BcmSocket>, String>),
    /// Raw mode: a CAN_RAW socket.
    Raw(Arc<CanPort>),
}

/// One connection's state, owned by its command reader.
struct Session {
    /// The opened interface and the current mode; `None` before `open`.
    mode: Option<(String, Mode)>,
    /// The queue's sending side (receivers get clones); the writer thread.
    q: Option<(SyncSender<String>, thread::JoinHandle<()>)>,
    /// The current receiver thread and its stop flag.
    rx: Option<(Arc<AtomicBool>, thread::JoinHandle<()>)>,
}

impl Session {
    /// Stops the current receiver and waits for it (at most one TICK).
    fn stop_rx(&mut self) {
        if let Some((stop, t)) = self.rx.take() {
            stop.store(true, Ordering::Relaxed);
            let _ = t.join();
        }
    }

    /// Starts the receiver of the current mode.
    fn start_rx(&mut self, srv: &Arc<Server>, cl: &Arc<Client>) {
        let (Some((_, mode)), Some((q, _))) = (&self.mode, &self.q) else {
            return;
        };
        let stop = Arc::new(AtomicBool::new(false));
        let (s, c, q, st) = (
            Arc::clone(srv),
            Arc::clone(cl),
            q.clone(),
            Arc::clone(&stop),
        );
        let t = match mode {
            Mode::Bcm(Ok(b)) => {
                let b = Arc::clone(b);
                thread::spawn(move || bcm_rx_loop(s, c, b, q, st))
            }
            Mode::Bcm(Err(_)) => return,
            Mode::Raw(p) => {
                let p = Arc::clone(p);
                thread::spawn(move || rx_loop(s, c, p, q, st))
            }
        };
        self.rx = Some((stop, t));
    }

    /// Ends the receiver and the writer.
    fn end(mut self) {
        self.stop_rx();
        if let Some((q, t)) = self.q.take() {
            drop(q);
            let _ = t.join();
        }
    }
}

/// A CAN_BCM socket on `addr`; `Ok(Err(why))` when the kernel has no
/// CAN_BCM (`EPROTONOSUPPORT`: rcan_bcm or can-bcm not loaded), other
/// failures as errors.
fn bcm_socket(addr: socketcan::CanAddr, peer: &str) -> io::Result<Result<Arc<BcmSocket>, String>> {
    match BcmSocket::open_addr(addr) {
        Ok(mut b) => {
            b.set_read_timeout(TICK)?;
            Ok(Ok(Arc::new(b)))
        }
        Err(e) if e.raw_os_error() == Some(nix::libc::EPROTONOSUPPORT) => {
            eprintln!("cantcpd: {peer}: no CAN_BCM ({e}): BCM commands will fail, raw mode works");
            Ok(Err(format!("no CAN_BCM: {e}")))
        }
        Err(e) => Err(e),
    }
}

/// A BCM request, or the error reply for it.
fn bcm_req(mode: &Mode, what: &str, m: bcm::Msg) -> Option<String> {
    let b = match mode {
        Mode::Raw(_) => return Some(format!("< error {what} needs bcmmode >")),
        Mode::Bcm(Err(e)) => return Some(format!("< error {what}: {e} >")),
        Mode::Bcm(Ok(b)) => b,
    };
    match b.send(&m) {
        Ok(()) => None,
        Err(e) => Some(format!("< error {what}: {e} >")),
    }
}

fn bcm_msg(
    opcode: u32,
    flags: u32,
    ival2: (u64, u64),
    can_id: u32,
    frame: Option<Frame>,
) -> bcm::Msg {
    bcm::Msg {
        opcode,
        flags,
        ival2,
        can_id,
        frame,
    }
}

/// One command; the reply, if any.
fn handle(
    srv: &Arc<Server>,
    cl: &Arc<Client>,
    ses: &mut Session,
    msg: Result<String, String>,
) -> Option<String> {
    let cmd = match msg.and_then(|m| parse(&m)) {
        Ok(c) => c,
        Err(e) => return Some(format!("< error {e} >")),
    };
    if let Command::Open(iface) = &cmd {
        if ses.mode.is_some() {
            return Some("< error already open >".into());
        }
        if !srv.allow.is_empty() && !srv.allow.contains(iface) {
            return Some(format!("< error {iface} not allowed >"));
        }
        let addr = match socketcan::CanAddr::from_iface(iface) {
            Ok(a) => a,
            Err(e) => return Some(format!("< error open {iface}: {e} >")),
        };
        return match bcm_socket(addr, &cl.peer) {
            Ok(b) => {
                ses.mode = Some((iface.clone(), Mode::Bcm(b)));
                let (tx, rx) = sync_channel(srv.queue);
                let (s2, c2) = (Arc::clone(srv), Arc::clone(cl));
                ses.q = Some((tx, thread::spawn(move || tx_loop(s2, c2, rx))));
                ses.start_rx(srv, cl);
                Some("< ok >".into())
            }
            Err(e) => Some(format!("< error open {iface}: {e} >")),
        };
    }
    match cmd {
        Command::Echo => return Some("< echo >".into()),
        Command::Unsupported(w) => return Some(format!("< error unsupported command {w} >")),
        _ => {}
    }
    let Some((iface, mode)) = &ses.mode else {
        return Some("< error no interface open >".into());
    };
    let iface = iface.clone();
    let raw = matches!(mode, Mode::Raw(_));
    match cmd {
        Command::RawMode if raw => return Some("< ok >".into()),
        Command::BcmMode if !raw => return Some("< ok >".into()),
        Command::RawMode => {
            let p = match CanPort::open(&iface, false)
                .and_then(|p| p.set_read_timeout(Some(TICK)).map(|()| p))
            {
                Ok(p) => p,
                Err(e) => return Some(format!("< error rawmode {iface}: {e} >")),
            };
            ses.stop_rx();
            // The BCM socket closes here: its jobs and filters end.
            ses.mode = Some((iface, Mode::Raw(Arc::new(p))));
            // The reply goes out before the first frame can.
            if cl.send("< ok >").is_err() {
                cl.closed.store(true, Ordering::Relaxed);
                return None;
            }
            ses.start_rx(srv, cl);
            return None;
        }
        Command::BcmMode => {
            let b = match socketcan::CanAddr::from_iface(&iface)
                .and_then(|a| bcm_socket(a, &cl.peer))
            {
                Ok(b) => b,
                Err(e) => return Some(format!("< error bcmmode {iface}: {e} >")),
            };
            ses.stop_rx();
            ses.mode = Some((iface, Mode::Bcm(b)));
            ses.start_rx(srv, cl);
            return Some("< ok >".into());
        }
        _ => {}
    }
    let Some((_, mode)) = &ses.mode else {
        return None;
    };
    match cmd {
        Command::Open(_)
        | Command::Echo
        | Command::Unsupported(_)
        | Command::RawMode
        | Command::BcmMode => None,
        Command::Send(f) => match mode {
            Mode::Raw(p) => match p.send(&f) {
                Ok(()) => None,
                Err(e) => Some(format!("< error send: {e} >")),
            },
            Mode::Bcm(_) => bcm_req(
                mode,
                "send",
                bcm_msg(bcm::TX_SEND, 0, (0, 0), f.id, Some(f)),
            ),
        },
        Command::Add { ival, frame } => bcm_req(
            mode,
            "add",
            bcm_msg(
                bcm::TX_SETUP,
                bcm::SETTIMER | bcm::STARTTIMER,
                ival,
                frame.id,
                Some(frame),
            ),
        ),
        Command::Update(frame) => bcm_req(
            mode,
            "update",
            bcm_msg(bcm::TX_SETUP, 0, (0, 0), frame.id, Some(frame)),
        ),
        Command::Delete(id) => {
            bcm_req(mode, "delete", bcm_msg(bcm::TX_DELETE, 0, (0, 0), id, None))
        }
        Command::Filter { ival, mask } => bcm_req(
            mode,
            "filter",
            bcm_msg(bcm::RX_SETUP, bcm::SETTIMER, ival, mask.id, Some(mask)),
        ),
        Command::Subscribe { ival, id } => bcm_req(
            mode,
            "subscribe",
            bcm_msg(
                bcm::RX_SETUP,
                bcm::RX_FILTER_ID | bcm::SETTIMER,
                ival,
                id,
                Some(Frame {
                    id,
                    ..Frame::default()
                }),
            ),
        ),
        Command::Unsubscribe(id) => bcm_req(
            mode,
            "unsubscribe",
            bcm_msg(bcm::RX_DELETE, 0, (0, 0), id, None),
        ),
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
    let mut ses = Session {
        mode: None,
        q: None,
        rx: None,
    };
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
                if let Some(reply) = handle(&srv, &cl, &mut ses, m) {
                    if cl.send(&reply).is_err() {
                        cl.closed.store(true, Ordering::Relaxed);
                    }
                }
            }
        }
    }
    cl.closed.store(true, Ordering::Relaxed);
    let _ = input.shutdown(Shutdown::Both);
    ses.end();
    let d = cl.dropped.load(Ordering::Relaxed);
    eprintln!("cantcpd: {}: closed, {d} frames dropped in all", cl.peer);
    srv.active.fetch_sub(1, Ordering::SeqCst);
}

fn run(cli: TcpCli) -> Result<(), String> {
    // Blocked before any thread starts, so every thread inherits the mask
    // and only the signalfd sees the signals.
    let sfd = signals::stop_signals()?;
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
            let sig = signals::signo(&sfd);
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
