// SPDX-License-Identifier: GPL-2.0
//! `dsor-peer`: a DSOR node over a CAN_RAW socket, for testing rcan's DSOR
//! against an implementation written from the wire specification alone.
//! See Documentation/networking/rcan/dsor-peer.rst for the command line.

use clap::Parser;
use dsor_peer::cli::{Cli, Mode};
use dsor_peer::node::{Event, Node, SendError};
use dsor_peer::wire::{fmt_ipv4, fnv1a64, pattern, Frame, Kind, Status};
use socketcan::{CanAnyFrame, CanFdFrame, CanFdSocket, CanFrame, CanSocket, Socket};
use std::collections::{HashMap, VecDeque};
use std::io::ErrorKind;
use std::process::exit;
use std::time::{Duration, Instant};

/// splitmix64: a small deterministic generator for `--drop`.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// True with probability `pct` percent.
    fn chance(&mut self, pct: f64) -> bool {
        pct > 0.0 && ((self.next() % 1_000_000) as f64) < pct * 10_000.0
    }
}

fn show(f: &Frame) -> String {
    let d: String = f.bytes().iter().map(|b| format!("{b:02X}")).collect();
    let sep = if f.fd { "##" } else { "#" };
    format!("{:08X}{sep}{d}", f.id)
}

fn status_reason(s: Status) -> &'static str {
    match s {
        Status::Ok => "ok",
        Status::Refused => "refused",
        Status::NoMemory => "nomem",
        Status::TooLong => "toolong",
    }
}

fn kind_str(k: &Kind) -> String {
    match k {
        Kind::Segm { id } => format!("kind=segm id={id:#010x}"),
        Kind::Port { dport, sport } => format!("kind=port dport={dport:#04x} sport={sport:#04x}"),
        Kind::Udp { dport, daddr } => format!("kind=udp dport={dport} daddr={}", fmt_ipv4(*daddr)),
    }
}

/// The CAN_RAW socket: classic (struct can_frame only), or with
/// CAN_RAW_FD_FRAMES on an interface in CAN FD mode (MTU 72), where it
/// reads and writes both kinds.
enum Sock {
    Classic(CanSocket),
    Fd(CanFdSocket),
}

struct Io {
    sock: Sock,
    rng: Rng,
    drop_pct: f64,
    verbose: bool,
}

/// Whether `ifname` is in CAN FD mode (MTU 72, `CANFD_MTU`).
fn fd_interface(ifname: &str) -> bool {
    std::fs::read_to_string(format!("/sys/class/net/{ifname}/mtu"))
        .ok()
        .and_then(|m| m.trim().parse::<u32>().ok())
        == Some(72)
}

impl Io {
    fn write(&mut self, f: &Frame) {
        if self.rng.chance(self.drop_pct) {
            if self.verbose {
                eprintln!("drop {}", show(f));
            }
            return;
        }
        if self.verbose {
            eprintln!("tx   {}", show(f));
        }
        let any: CanAnyFrame = if f.fd {
            let mut c = socketcan::frame::canfd_frame_default();
            c.can_id = f.id | libc::CAN_EFF_FLAG;
            c.len = f.len;
            c.flags = libc::CANFD_FDF as u8;
            c.data = f.data;
            CanAnyFrame::Fd(CanFdFrame::from(c))
        } else {
            let mut c = socketcan::frame::can_frame_default();
            c.can_id = f.id | libc::CAN_EFF_FLAG;
            c.can_dlc = f.len;
            c.data.copy_from_slice(&f.data[..8]);
            CanAnyFrame::from(CanFrame::from(c))
        };
        for _ in 0..1000 {
            let r = match (&self.sock, &any) {
                (Sock::Fd(s), a) => s.write_frame(a),
                (Sock::Classic(s), CanAnyFrame::Normal(d)) => s.write_frame(d),
                (Sock::Classic(_), _) => unreachable!("an FD frame on a classic node"),
            };
            match r {
                Ok(()) => return,
                // Transmit queue full: wait for it to drain.
                Err(e)
                    if e.raw_os_error() == Some(libc::ENOBUFS)
                        || e.kind() == ErrorKind::WouldBlock =>
                {
                    std::thread::sleep(Duration::from_millis(1))
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    eprintln!("dsor-peer: write: {e}");
                    exit(3)
                }
            }
        }
        eprintln!(
            "dsor-peer: write: queue full for 1 s, frame lost: {}",
            show(f)
        );
    }

    /// Waits up to `wait` for a DSOR frame (extended data frame, classic
    /// or, on an FD socket, CAN FD).
    fn read(&mut self, wait: Duration) -> Option<Frame> {
        let got = match &self.sock {
            Sock::Classic(s) => s.read_frame_timeout(wait).map(|cf| {
                let c: &libc::can_frame = cf.as_ref();
                (c.can_id, c.can_dlc, false, c.data.to_vec())
            }),
            Sock::Fd(s) => s.read_frame_timeout(wait).map(|af| match af {
                CanAnyFrame::Fd(ff) => {
                    let c: &libc::canfd_frame = ff.as_ref();
                    (c.can_id, c.len, true, c.data.to_vec())
                }
                other => {
                    // Classic data, remote and error frames: the flags of
                    // the id tell them apart below.
                    let c: &libc::can_frame = match &other {
                        CanAnyFrame::Normal(d) => d.as_ref(),
                        CanAnyFrame::Remote(r) => r.as_ref(),
                        CanAnyFrame::Error(e) => e.as_ref(),
                        CanAnyFrame::Fd(_) => unreachable!(),
                    };
                    (c.can_id, c.can_dlc, false, c.data.to_vec())
                }
            }),
        };
        match got {
            Ok((can_id, len, fd, bytes)) => {
                let flags = can_id & !libc::CAN_EFF_MASK;
                if flags != libc::CAN_EFF_FLAG || usize::from(len) > bytes.len() {
                    return None; // standard, remote or error frame
                }
                let mut f = Frame::new(can_id & libc::CAN_EFF_MASK, &[]);
                f.data[..bytes.len()].copy_from_slice(&bytes);
                f.len = len;
                f.fd = fd;
                if self.verbose {
                    eprintln!("rx   {}", show(&f));
                }
                Some(f)
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) =>
            {
                None
            }
            Err(e) => {
                eprintln!("dsor-peer: read: {e}");
                exit(3)
            }
        }
    }
}

/// A message waiting for a free channel, with its output tag `n`.
struct Pending {
    dst: u8,
    prio: u8,
    kind: Kind,
    payload: Vec<u8>,
    n: u64,
}

fn main() {
    let cli = Cli::parse();
    let a = cli.args().unwrap_or_else(|e| e.exit());
    let mut cfg = a.cfg.clone();
    // An FD node on an interface in CAN FD mode, unless told to be classic.
    cfg.fd = !a.classic && fd_interface(&a.ifname);
    let opened = if cfg.fd {
        CanFdSocket::open(&a.ifname).map(Sock::Fd)
    } else {
        CanSocket::open(&a.ifname).map(Sock::Classic)
    };
    let sock = opened.unwrap_or_else(|e| {
        eprintln!("dsor-peer: {}: {e}", a.ifname);
        exit(3)
    });
    // The socket is bound: every frame sent to this node from now on is
    // queued for us. Whoever started us waits for this line instead of
    // guessing how long a start takes (dsor-peer.rst, "Output").
    println!(
        "READY if={} node={:#04x} mode={}",
        a.ifname,
        cfg.node,
        if cfg.fd { "fd" } else { "classic" }
    );
    let _ = std::io::Write::flush(&mut std::io::stdout());
    let mut io = Io {
        sock,
        rng: Rng(a.seed),
        drop_pct: a.drop_pct,
        verbose: a.verbose,
    };
    // Without loss the last ack goes out before we exit; with --drop it may be
    // lost, so stay to re-ack the sender's retransmissions.
    let linger = a
        .linger_ms
        .unwrap_or(if a.drop_pct > 0.0 { 3000 } else { 0 });
    let start = Instant::now();
    let now = || start.elapsed().as_millis() as u64;
    let mut node = Node::new(cfg);
    let mut queue: VecDeque<Pending> = VecDeque::new();
    let mut inflight: HashMap<u64, (u64, usize, u64)> = HashMap::new(); // handle -> (n, len, sha)
    let (mut received, mut sent_ok, mut sent_fail, mut started) = (0u64, 0u64, 0u64, 0u64);
    // Messages the application refused (--app-queue, --close-after-*).
    let mut not_delivered = 0u64;
    let deadline = match a.mode {
        Mode::Send { .. } => None,
        _ => Some(a.timeout_s.saturating_mul(1000)),
    };
    let window = match a.mode {
        Mode::Send { window, .. } => window,
        _ => 16,
    };
    let mut done_at: Option<u64> = None;
    loop {
        // Start what the window allows.
        if let Mode::Send {
            to,
            prio,
            kind,
            len,
            seed,
            ..
        } = a.mode
        {
            while started < a.count && queue.len() < window {
                queue.push_back(Pending {
                    dst: to,
                    prio,
                    kind,
                    payload: pattern(len, started, seed),
                    n: started,
                });
                started += 1;
            }
        }
        while inflight.len() < window {
            let Some(p) = queue.pop_front() else { break };
            let (len, sha) = (p.payload.len(), fnv1a64(&p.payload));
            match node.send(now(), p.dst, p.prio, p.kind, p.payload.clone()) {
                Ok(h) => {
                    inflight.insert(h, (p.n, len, sha));
                }
                Err(SendError::Busy) => {
                    queue.push_front(p);
                    break;
                }
                Err(e) => {
                    let reason = if e == SendError::TooLong {
                        "toolong"
                    } else {
                        "badnode"
                    };
                    println!("TX fail reason={reason} len={len} sha={sha:016x} n={}", p.n);
                    sent_fail += 1;
                }
            }
        }
        while let Some(f) = node.pop_frame() {
            io.write(&f);
        }
        let mut progressed = false;
        while let Some(ev) = node.pop_event() {
            progressed = true;
            match ev {
                Event::Delivered(d) => {
                    println!(
                        "RX src={:#04x} prio={:#04x} {} len={} sha={:016x} chan={}",
                        d.src,
                        d.prio,
                        kind_str(&d.kind),
                        d.payload.len(),
                        fnv1a64(&d.payload),
                        d.chan
                    );
                    if matches!(a.mode, Mode::Echo) && received < a.count {
                        let kind = match d.kind {
                            Kind::Port { dport, sport } => Kind::Port {
                                dport: sport,
                                sport: dport,
                            },
                            k => k,
                        };
                        queue.push_back(Pending {
                            dst: d.src,
                            prio: d.prio,
                            kind,
                            payload: d.payload,
                            n: received,
                        });
                    }
                    received += 1;
                }
                Event::NotDelivered { msg: d, status } => {
                    println!(
                        "RXFAIL reason={} src={:#04x} prio={:#04x} {} len={} chan={}",
                        status_reason(status),
                        d.src,
                        d.prio,
                        kind_str(&d.kind),
                        d.payload.len(),
                        d.chan
                    );
                    not_delivered += 1;
                }
                Event::Sent { handle, result, .. } => {
                    let (n, len, sha) = inflight.remove(&handle).expect("handle");
                    match result {
                        Ok(()) => {
                            sent_ok += 1;
                            println!("TX ok len={len} sha={sha:016x} n={n}");
                        }
                        Err(f) => {
                            sent_fail += 1;
                            println!(
                                "TX fail reason={} len={len} sha={sha:016x} n={n}",
                                f.reason()
                            );
                        }
                    }
                }
            }
        }
        if progressed {
            continue; // events may have queued messages or frames
        }
        let finished = match a.mode {
            Mode::Recv => received + not_delivered >= a.count,
            Mode::Send { .. } => sent_ok + sent_fail >= a.count,
            Mode::Echo => received >= a.count && sent_ok + sent_fail >= a.count,
        };
        let t = now();
        if finished && done_at.is_none() {
            done_at = Some(t + linger);
        }
        if let Some(d) = done_at {
            if t >= d {
                break;
            }
        }
        if let Some(d) = deadline {
            if t >= d && done_at.is_none() {
                eprintln!("dsor-peer: timeout: received {received} of {}", a.count);
                exit(1)
            }
        }
        let mut until = [node.next_deadline(), done_at, deadline]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(t + 1000);
        until = until.clamp(t + 1, t + 1000);
        if let Some(f) = io.read(Duration::from_millis(until - t)) {
            node.on_frame(now(), &f);
        }
        node.poll(now());
    }
    let ok = match a.mode {
        Mode::Recv => true,
        _ => sent_fail == 0,
    };
    exit(if ok { 0 } else { 1 })
}
