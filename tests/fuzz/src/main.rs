// SPDX-License-Identifier: GPL-2.0
//! # rcan-fuzz: a syscall fuzzer for the rcan protocols
//!
//! Runs as root inside the test VM (it loads the rcan modules unless
//! `--no-load`), best on the debug kernel, where KASAN, lockdep and
//! kmemleak watch and vm-run.sh fails the run on any kernel report:
//!
//! ```text
//! RCAN_KERNEL=debug tools/testing/rcan/vm-run.sh --qemu-extra "$RCAN_QEMU_CAN" -- \
//!     target/release/rcan-fuzz --seed 1 --seconds 120
//! ```
//!
//! Usage: `rcan-fuzz [--seed S]... [--iterations N] [--seconds T]
//! [--threads K] [--watchdog SECS] [--no-modchurn] [--no-load] [--root DIR]`
//!
//! For each seed in turn (default: one, 1), `K` worker threads (default 4)
//! make random calls on sockets of every protocol in [`table::PROTOS`]
//! (socket, close, dup, bind, connect, setsockopt, getsockopt, send,
//! sendto, sendmsg with control messages, recv, recvfrom, recvmsg, ioctl,
//! shutdown, poll, getsockname, getpeername) until `N` calls in all
//! (default 20000) or `T` seconds (default 60) are done, while one more
//! thread churns the devices (can0/can1 down and up, MTU changes, rmmod and
//! insmod of rcan_loop under traffic unless `--no-modchurn`).
//!
//! **Descriptor table.** The sockets live in one table of slots shared by
//! all threads, so a descriptor is often closed, or `dup`ed over, by one
//! thread while another is in a call on it. The fuzzer never holds a
//! descriptor it may close in a Rust object, so this cannot break the
//! program itself.
//!
//! **Determinism.** Each thread draws from its own PRNG stream derived from
//! the seed and its number ([`rng::Rng::for_thread`]). `--threads 1
//! --no-modchurn` replays a seed's calls and arguments exactly (outcomes
//! that depend on timing may differ); with several threads the shared
//! slot table makes the per-thread sequences diverge once threads race
//! (a thread that finds a slot empty opens a socket instead), so a
//! failure's seed/thread/iteration locate it rather than replay it.
//!
//! **Checks.** A call fails the run when it returns an errno outside the
//! documented set for that call ([`table::Call::allowed`]; also any
//! kernel-internal errno above 133), a socket of a registered protocol
//! cannot be created, a receive returns more bytes than its buffer (or,
//! with `MSG_TRUNC`, more than the longest message), a getsockopt/
//! getsockname/recvmsg length comes back out of bounds, poll reports events
//! nobody asked for, an MTU other than 16 is accepted, or a call is still
//! in the kernel after the watchdog (default 120 s). The first failure ends
//! the run with its seed, thread, iteration and call and a reproducer line.
//! A kernel report (oops, KASAN, lockdep, kmemleak, WARNING) is caught by
//! vm-run.sh, which fails the VM run.
//!
//! Output: per seed, calls made per syscall and the errno histogram as `#`
//! comments and `ok - fuzz seed S` or `not ok - ...`; at the end one line
//! `1 passed, 0 failed` (the whole run counts as one test in make check)
//! or `0 passed, 1 failed`; exit status 1 on failure.

mod leak;
mod rng;
mod sys;
mod table;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use libc::c_int;

use rng::Rng;
use table::{Call, Field, Layout, Proto, Val, AF_CAN, PF_CAN, PROTOS, SOCKET_OPTS};

/// Socket slots shared by all worker threads.
const NSLOTS: usize = 24;
/// Largest value a `MSG_TRUNC` receive may return: the longest message
/// of any protocol (the socket in a slot may have changed protocol since
/// the call was chosen).
fn max_msg() -> usize {
    PROTOS.iter().map(|p| p.max_msg).max().unwrap_or(0)
}
/// Largest address the kernel may report (`sizeof(struct
/// sockaddr_storage)`).
const MAX_ADDR: usize = 128;
/// Highest errno number user space may see (`EHWPOISON`); above are
/// kernel-internal codes (ERESTARTSYS 512, ENOIOCTLCMD 515, ...).
const MAX_ERRNO: c_int = 133;
/// rcan_loop interfaces the fuzzer uses.
const NDEV: usize = 2;

/// Run parameters (the command line).
#[derive(Clone, Debug)]
struct Args {
    seeds: Vec<u64>,
    iterations: u64,
    seconds: u64,
    threads: usize,
    watchdog: u64,
    modchurn: bool,
    load: bool,
    root: PathBuf,
}

fn usage() -> ! {
    eprintln!(
        "usage: rcan-fuzz [--seed S]... [--iterations N] [--seconds T] [--threads K] \
         [--watchdog SECS] [--no-modchurn] [--no-load] [--root DIR]"
    );
    std::process::exit(2)
}

fn parse_args(mut it: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut a = Args {
        seeds: Vec::new(),
        iterations: 20000,
        seconds: 60,
        threads: 4,
        watchdog: 120,
        modchurn: true,
        load: true,
        root: std::env::var_os("RCAN_ROOT").map_or_else(|| PathBuf::from("."), PathBuf::from),
    };
    fn num(v: Option<String>, o: &str) -> Result<u64, String> {
        let v = v.ok_or(format!("{o} needs a value"))?;
        let r = match v.strip_prefix("0x") {
            Some(h) => u64::from_str_radix(h, 16),
            None => v.parse(),
        };
        r.map_err(|e| format!("{o} {v}: {e}"))
    }
    while let Some(o) = it.next() {
        match o.as_str() {
            "--seed" => a.seeds.push(num(it.next(), &o)?),
            "--iterations" => a.iterations = num(it.next(), &o)?,
            "--seconds" => a.seconds = num(it.next(), &o)?,
            "--threads" => a.threads = num(it.next(), &o)?.clamp(1, 64) as usize,
            "--watchdog" => a.watchdog = num(it.next(), &o)?.max(1),
            "--no-modchurn" => a.modchurn = false,
            "--no-load" => a.load = false,
            "--root" => a.root = PathBuf::from(it.next().ok_or("--root needs a value")?),
            "-h" | "--help" => usage(),
            _ => return Err(format!("unknown argument {o:?}")),
        }
    }
    if a.seeds.is_empty() {
        a.seeds.push(1);
    }
    Ok(a)
}

/// What a worker is doing, for the watchdog.
#[derive(Default)]
struct Progress {
    /// Milliseconds since the run's start when the current call began;
    /// 0 while between calls.
    since_ms: AtomicU64,
    iteration: AtomicU64,
    desc: Mutex<String>,
}

/// State shared by the threads of one seed's run.
struct Shared {
    seed: u64,
    slots: [AtomicI32; NSLOTS],
    /// Index into PROTOS of the socket in each slot (a hint: another
    /// thread may have replaced the socket since).
    slot_proto: [AtomicUsize; NSLOTS],
    /// Current ifindex of can0, can1 (0 while rcan_loop is unloaded).
    can_ifindex: [AtomicU32; NDEV],
    /// ifindexes of interfaces that went away.
    stale_ifindex: AtomicU32,
    /// ifindex of canip0 (a non-CAN device), 0 if none.
    canip_ifindex: AtomicU32,
    stop: AtomicBool,
    calls: AtomicU64,
    failure: Mutex<Option<String>>,
    progress: Vec<Progress>,
    start: Instant,
    /// Info-leak checks made ([`leak`]), per [`LeakCheck`].
    leak_checks: [AtomicU64; LEAK_CHECKS],
}

/// The kinds of info-leak check, for the summary.
#[derive(Clone, Copy)]
enum LeakCheck {
    /// Receive data: nothing past the returned length.
    Data = 0,
    /// An address, layout unknown (the socket changed under the call).
    Addr,
    /// An address with its protocol's padding checked.
    AddrLayout,
    /// A getsockopt value.
    Opt,
    /// A control message buffer.
    Cmsg,
    /// The head of a BCM reply.
    BcmReply,
}
const LEAK_CHECKS: usize = 6;

impl Shared {
    fn now_ms(&self) -> u64 {
        self.start.elapsed().as_millis() as u64 + 1
    }

    fn fail(&self, msg: String) {
        let mut f = self.failure.lock().unwrap();
        if f.is_none() {
            *f = Some(msg);
        }
        self.stop.store(true, Ordering::SeqCst);
    }

    fn ifindex(&self, r: &mut Rng) -> u32 {
        match r.below(10) {
            0..=4 => self.can_ifindex[r.below(NDEV)].load(Ordering::Relaxed),
            5 => 0,
            6 => 1, // lo: not a CAN device
            7 => self.stale_ifindex.load(Ordering::Relaxed),
            8 => self.canip_ifindex.load(Ordering::Relaxed),
            _ => r.pick_or_rand(&[9999, u32::MAX, 0x8000_0000]),
        }
    }
}

/// Per-thread counts: calls per syscall and errnos (0 = success).
type Hist = BTreeMap<(Call, c_int), u64>;

/// One worker's state.
struct Worker<'a> {
    sh: &'a Shared,
    id: usize,
    rng: Rng,
    hist: Hist,
}

fn hex(b: &[u8]) -> String {
    let s: String = b.iter().take(32).map(|x| format!("{x:02x}")).collect();
    if b.len() > 32 {
        format!("{s}..")
    } else {
        s
    }
}

impl Worker<'_> {
    /// Notes the call about to be made (for the watchdog and failures).
    fn begin(&self, desc: String) {
        let p = &self.sh.progress[self.id];
        *p.desc.lock().unwrap() = desc;
        p.since_ms.store(self.sh.now_ms(), Ordering::SeqCst);
    }

    /// Records a call's result; fails the run on an undocumented errno.
    fn end<T>(&mut self, call: Call, r: &sys::Res<T>) -> bool {
        self.end_with(call, r, &[])
    }

    /// [`Self::end`], with `extra` errnos documented for this protocol.
    fn end_with<T>(&mut self, call: Call, r: &sys::Res<T>, extra: &[c_int]) -> bool {
        self.sh.progress[self.id]
            .since_ms
            .store(0, Ordering::SeqCst);
        self.sh.calls.fetch_add(1, Ordering::Relaxed);
        let e = match r {
            Ok(_) => 0,
            Err(e) => *e,
        };
        *self.hist.entry((call, e)).or_default() += 1;
        if e != 0 && (e > MAX_ERRNO || !(call.allowed().contains(&e) || extra.contains(&e))) {
            self.violation(format!(
                "returned {}, not in the documented set",
                table::errno_name(e)
            ));
            return false;
        }
        true
    }

    /// [`Self::end_with`] for a send on `fd`, a socket of `p` when the slot
    /// was read: `p`'s own errnos are allowed too. If the errno is not in
    /// either set, the descriptor may have been closed and reused by
    /// another thread for a socket of another protocol meanwhile (the
    /// lowest free number is reused at once): then that protocol's errnos
    /// apply (e.g. `ENOTCONN` of a BCM socket on a slot that held a DSOR
    /// socket; found by seed 7).
    fn end_send(&mut self, call: Call, r: &sys::Res<usize>, fd: c_int, p: &Proto) -> bool {
        let extra = match r {
            Err(e) if !call.allowed().contains(e) && !p.extra_send.contains(e) => {
                match Self::ident(fd).and_then(|(_, k)| k) {
                    Some(leak::Kind::Bcm) => PROTOS
                        .iter()
                        .find(|q| q.msg == table::Msg::Bcm)
                        .map_or(p.extra_send, |q| q.extra_send),
                    Some(leak::Kind::Isotp) => table::ISOTP_ERRS,
                    Some(leak::Kind::J1939) => table::J1939_SEND_ERRS,
                    _ => p.extra_send,
                }
            }
            _ => p.extra_send,
        };
        self.end_with(call, r, extra)
    }

    /// [`Self::end`] for a call on `fd`, a socket of `p` when the slot
    /// was read: the errnos of `p`'s protocol for this call are allowed
    /// too ([`table::extra_errs`]). If the errno is in neither set, the
    /// descriptor may have been reused by another thread for a socket of
    /// another protocol meanwhile (as in [`Self::end_send`]): then that
    /// protocol's apply.
    fn end_on<T>(&mut self, call: Call, r: &sys::Res<T>, fd: c_int, p: &Proto) -> bool {
        let mine = table::extra_errs(p.protocol, call);
        let extra: &[c_int] = match r {
            Err(e) if !call.allowed().contains(e) && !mine.contains(e) => {
                let now = match Self::ident(fd).and_then(|(_, k)| k) {
                    Some(leak::Kind::Isotp) => 6,
                    Some(leak::Kind::J1939) => 7,
                    _ => p.protocol,
                };
                table::extra_errs(now, call)
            }
            _ => mine,
        };
        self.end_with(call, r, extra)
    }

    fn violation(&self, what: String) {
        let p = &self.sh.progress[self.id];
        let desc = p.desc.lock().unwrap().clone();
        self.sh.fail(format!(
            "seed {} thread {} iteration {}: {desc}: {what}",
            self.sh.seed,
            self.id,
            p.iteration.load(Ordering::Relaxed)
        ));
    }

    /// What socket `fd` is now: its inode and, for a CAN socket, its
    /// [`leak::Kind`] (SO_TYPE; a SOCK_RAW socket that has
    /// CAN_RAW_LOOPBACK is CAN_RAW, else CANPROTO_CAN). Not counted as
    /// calls.
    fn ident(fd: c_int) -> Option<(u64, Option<leak::Kind>)> {
        let ino = sys::ino(fd).ok()?;
        let int = |level, name| {
            let mut b = [0u8; 4];
            sys::getsockopt(fd, level, name, &mut b)
                .ok()
                .map(|_| c_int::from_ne_bytes(b))
        };
        let kind = match (
            int(libc::SOL_SOCKET, libc::SO_DOMAIN),
            int(libc::SOL_SOCKET, libc::SO_TYPE),
        ) {
            // DSOR, BCM, ISO-TP and J1939 are datagram sockets; rcan
            // sets SO_PROTOCOL (CAN_BCM 2, CAN_ISOTP 6, CAN_J1939 7).
            (Some(PF_CAN), Some(libc::SOCK_DGRAM)) => {
                Some(match int(libc::SOL_SOCKET, libc::SO_PROTOCOL) {
                    Some(2) => leak::Kind::Bcm,
                    Some(6) => leak::Kind::Isotp,
                    Some(7) => leak::Kind::J1939,
                    _ => leak::Kind::Dsor,
                })
            }
            (Some(PF_CAN), Some(libc::SOCK_RAW)) => Some(match int(table::SOL_CAN_RAW, 3) {
                Some(_) => leak::Kind::Raw,
                None => leak::Kind::Arb,
            }),
            _ => None,
        };
        Some((ino, kind))
    }

    /// The layout to check an address from `fd` against: its kind if `fd`
    /// names the socket it named before the call (inode `before`).
    /// `fd` must name that socket after [`Self::ident`]'s queries too:
    /// another thread may close the number and reuse it for a socket of
    /// another protocol between `ident`'s `fstat` and its `getsockopt`s,
    /// which would pair the old inode with the new socket's kind (seed
    /// 1795764822 took a DSOR socket's address for a CAN_RAW one's).
    fn layout_after(&self, fd: c_int, before: Option<u64>) -> Option<leak::Kind> {
        match (before, Self::ident(fd), sys::ino(fd).ok()) {
            (Some(b), Some((a, kind)), Some(c)) if a == b && c == b => kind,
            _ => None,
        }
    }

    /// Records an info-leak check; a failed one fails the run.
    fn leak(&self, check: LeakCheck, r: Result<(), String>) {
        self.sh.leak_checks[check as usize].fetch_add(1, Ordering::Relaxed);
        if let Err(e) = r {
            self.violation(format!("info leak: {e}"));
        }
    }

    /// Checks an address the kernel reported ([`leak::check_addr`]).
    fn leak_addr(&self, fd: c_int, before: Option<u64>, buf: &[u8], reported: usize, what: &str) {
        if reported == 0 && buf.iter().all(|&b| b == leak::POISON) {
            return;
        }
        let kind = self.layout_after(fd, before);
        let check = if kind.is_some() {
            LeakCheck::AddrLayout
        } else {
            LeakCheck::Addr
        };
        self.leak(check, leak::check_addr(kind, buf, reported, what));
    }

    /// A received BCM reply ([`leak::check_bcm_reply`]), if `fd` is
    /// still the BCM socket it was.
    fn leak_bcm(&self, fd: c_int, before: Option<u64>, buf: &[u8], n: usize) {
        if n < table::BCM_HEAD || buf.len() < table::BCM_HEAD {
            return;
        }
        if self.layout_after(fd, before) == Some(leak::Kind::Bcm) {
            self.leak(
                LeakCheck::BcmReply,
                leak::check_bcm_reply(buf, n, "BCM reply"),
            );
        }
    }

    /// A slot and the descriptor in it (-1: empty).
    fn slot(&mut self) -> (usize, c_int, &'static Proto) {
        let s = self.rng.below(NSLOTS);
        let fd = self.sh.slots[s].load(Ordering::SeqCst);
        let p = &PROTOS[self.sh.slot_proto[s].load(Ordering::Relaxed) % PROTOS.len()];
        (s, fd, p)
    }

    /// Puts `fd` into slot `s`, closing what was there.
    fn store(&mut self, s: usize, fd: c_int, proto: usize) {
        self.sh.slot_proto[s].store(proto, Ordering::Relaxed);
        let old = self.sh.slots[s].swap(fd, Ordering::SeqCst);
        if old >= 0 {
            self.begin(format!("close(fd {old}) (replaced in slot {s})"));
            let r = sys::close(old);
            self.end(Call::Close, &r);
        }
    }

    fn op_socket(&mut self, s: usize) {
        let r = &mut self.rng;
        let pi = r.below(PROTOS.len());
        let p = &PROTOS[pi];
        let valid = r.chance(9, 10);
        let (ty, proto) = if valid {
            (p.sock_type, p.protocol)
        } else {
            (
                *r.pick(&[0, 1, 2, 3, 5, 10, 11, -1]),
                *r.pick(&[
                    0, 1, 2, 3, 4, 5, 6, 7, 8, 15, 16, 17, 18, 23, 24, 25, -1, 256,
                ]),
            )
        };
        let flags = *r.pick(&[0, 0, libc::SOCK_NONBLOCK, libc::SOCK_CLOEXEC]);
        // Every socket starts non-blocking, and only becomes blocking (if
        // the draw wants that) once it has the timeouts below. Another
        // thread may hold this descriptor number from a slot whose socket
        // was closed since (socket() takes the lowest free number): its
        // receive must not reach a socket without SO_RCVTIMEO and wait
        // for ever (make check of 04564a5: a "HANG" in a BCM recvmsg on
        // the debug kernel, the call labelled with the slot's former
        // ISO-TP socket).
        self.begin(format!("socket(PF_CAN, {ty:#x}, {proto})"));
        let res = sys::socket(PF_CAN, ty | flags | libc::SOCK_NONBLOCK, proto);
        if !self.end(Call::Socket, &res) {
            return;
        }
        match res {
            Ok(fd) => {
                // Bounded blocking: no call waits longer than these unless
                // the kernel ignores them (which the watchdog catches).
                let tv = |us: i64| {
                    let t = libc::timeval {
                        tv_sec: 0,
                        tv_usec: us,
                    };
                    let mut b = [0u8; 16];
                    b[..8].copy_from_slice(&t.tv_sec.to_ne_bytes());
                    b[8..].copy_from_slice(&t.tv_usec.to_ne_bytes());
                    b
                };
                let _ = sys::setsockopt(fd, libc::SOL_SOCKET, libc::SO_RCVTIMEO, &tv(20_000), 16);
                let _ = sys::setsockopt(fd, libc::SOL_SOCKET, libc::SO_SNDTIMEO, &tv(100_000), 16);
                if flags != libc::SOCK_NONBLOCK {
                    let _ = sys::set_blocking(fd);
                }
                let pi = PROTOS
                    .iter()
                    .position(|p| p.protocol == proto)
                    .unwrap_or(pi);
                self.store(s, fd, pi);
                // ISO-TP options can only be set before bind (EISCONN
                // after): most new ISO-TP sockets get a few first, drawn
                // within the fuzzer's bounds, so that every flag, link
                // layer and flow-control parameter meets the bound paths.
                if valid && PROTOS[pi].msg == table::Msg::Isotp && self.rng.chance(3, 4) {
                    for _ in 0..1 + self.rng.below(4) {
                        let o = self.rng.pick(PROTOS[pi].opts);
                        let Val::Isotp(name) = o.val else { continue };
                        let v = isotp_value(&mut self.rng, name);
                        self.begin(format!(
                            "setsockopt(CAN_ISOTP fd {fd}, {} [{}]) before bind",
                            o.label,
                            hex(&v)
                        ));
                        let r = sys::setsockopt(fd, o.level, o.name, &v, v.len() as u32);
                        self.end_on(Call::Setsockopt, &r, fd, &PROTOS[pi]);
                    }
                }
                // Half the new sockets get a well-formed bind at once, so
                // that frames and messages flow and the receive paths run.
                // (BCM has no bind: its sockets are connect()-ed.)
                if valid && self.rng.chance(1, 2) {
                    let a = self.valid_addr(p);
                    let bcm = p.msg == table::Msg::Bcm;
                    self.begin(format!(
                        "{}({} fd {fd}, well-formed [{}])",
                        if bcm { "connect" } else { "bind" },
                        p.name,
                        hex(&a)
                    ));
                    if bcm {
                        let r = sys::connect(fd, &a);
                        self.end_on(Call::Connect, &r, fd, p);
                    } else {
                        let r = sys::bind(fd, &a);
                        self.end_on(Call::Bind, &r, fd, p);
                    }
                }
            }
            Err(e) if valid && ![libc::ENOBUFS, libc::ENOMEM, libc::EMFILE].contains(&e) => {
                self.violation(format!(
                    "{} socket refused with {} (protocol registered)",
                    p.name,
                    table::errno_name(e)
                ));
            }
            Err(_) => {}
        }
    }

    /// A well-formed address of one of `p`'s layouts: `AF_CAN`, a CAN
    /// device that exists, wildcards where the layout has them.
    fn valid_addr(&mut self, p: &Proto) -> Vec<u8> {
        let l = &p.addrs[self.rng.below(p.addrs.len())];
        let mut b = vec![0u8; l.len];
        for &(off, size, kind) in l.fields {
            let r = &mut self.rng;
            let v: u64 = match kind {
                Field::Family => AF_CAN.into(),
                Field::Ifindex => self.sh.can_ifindex[r.below(NDEV)]
                    .load(Ordering::Relaxed)
                    .into(),
                Field::Arb => ((r.next_u32() & 0x7ff) << 21).into(),
                Field::Mask => 0xffff_ffff,
                Field::Node => *r.pick(&[0, 0xff]),
                Field::Port => (r.next_u32() & 0xff).into(), // a port of node 0, ours
                Field::MsgId => {
                    let small = r.below(8) as u64;
                    *r.pick(&[0xffff_ffff, small])
                }
                Field::Any => (r.next_u32() & 0xff).into(),
                Field::IsotpId => isotp_id(r).into(),
                // Bound by address, no PGN filter or a PGN to receive.
                Field::J1939Name => table::J1939_NO_NAME,
                Field::J1939Pgn => *r.pick(&[table::J1939_NO_PGN, 0x12300, 0xfeca]),
                Field::J1939Addr => *r.pick(&J1939_ADDRS),
            };
            b[off..off + size].copy_from_slice(&v.to_ne_bytes()[..size]);
        }
        b
    }

    fn addr(&mut self, p: &Proto) -> Vec<u8> {
        self.addr_named(p).1
    }

    /// A random address for `p` and the name of the layout it follows.
    fn addr_named(&mut self, p: &Proto) -> (&'static str, Vec<u8>) {
        let r = &mut self.rng;
        let l: &Layout = if r.chance(1, 10) {
            {
                let q = r.pick(PROTOS);
                r.pick(q.addrs)
            }
        } else {
            r.pick(p.addrs)
        };
        let mut b = vec![0u8; l.len];
        if r.chance(1, 10) {
            r.fill(&mut b);
        }
        for &(off, size, kind) in l.fields {
            let v: u64 = match kind {
                Field::Family => {
                    if r.chance(9, 10) {
                        AF_CAN.into()
                    } else {
                        r.pick_or_rand(&[0, 1, 2, 0xffff]).into()
                    }
                }
                Field::Ifindex => self.sh.ifindex(r).into(),
                Field::J1939Name => match r.below(4) {
                    0 | 1 => table::J1939_NO_NAME,
                    2 => *r.pick(&J1939_NAMES),
                    _ => r.next_u64(),
                },
                Field::J1939Pgn => r
                    .pick_or_rand(&[
                        table::J1939_NO_PGN as u32,
                        0x12300, // PDU1, destination byte 0
                        0x12345, // PDU1 with a destination byte
                        0xfeca,  // PDU2
                        0xea00,  // request
                        0xee00,  // address claimed
                        0xec00,  // TP.CM
                        0xeb00,  // TP.DT
                        0xc800,  // ETP.CM
                        0xc700,  // ETP.DT
                        0x3ffff,
                        0x40001,
                    ])
                    .into(),
                Field::J1939Addr => match r.below(4) {
                    0 | 1 => *r.pick(&J1939_ADDRS),
                    2 => *r.pick(&[table::J1939_IDLE_ADDR, table::J1939_NO_ADDR, 0]),
                    _ => r.below(256) as u64,
                },
                Field::Arb => {
                    let id = r.next_u32();
                    let rtr = if r.chance(1, 4) { 2 } else { 0 };
                    u64::from(match r.below(6) {
                        0 | 1 => ((id & 0x7ff) << 21) | rtr,
                        2 | 3 => ((id & 0x1fff_ffff) << 3) | 4 | rtr,
                        4 => (id & 0x7ff) << 21 | 8, // std with extension bits
                        _ => id,                     // bit 0 may be set
                    })
                }
                Field::Mask => r.pick_or_rand(&[1, 0xffff_ffff, 0]).into(),
                Field::Node => r.pick_or_rand(&[0, 0, 1, 5, 0x7f, 0x80, 0xff]).into(),
                Field::Port => {
                    let node = r.pick_or_rand(&[0u32, 0, 1, 0x7f, 0xff]) & 0xff;
                    ((node << 8) | (r.next_u32() & 0xff)).into()
                }
                Field::MsgId => r.pick_or_rand(&[0, 1, 2, 7, 0xffff_ffff]).into(),
                Field::Any => r.next_u32().into(),
                Field::IsotpId => u64::from(match r.below(4) {
                    0 => r.pick_or_rand(&[
                        0x800,       // beyond 11 bits
                        0x8000_0000, // CAN_EFF_FLAG, id 0
                        0xA000_0700, // EFF with CAN_ERR_FLAG
                        0x4000_0700, // CAN_RTR_FLAG
                        0x3fff_ffff, // beyond 29 bits, no EFF
                        0x9fff_ffff, // 29 bits + EFF
                    ]),
                    _ => isotp_id(r),
                }),
            };
            b[off..off + size].copy_from_slice(&v.to_ne_bytes()[..size]);
        }
        if r.chance(1, 5) {
            let any = r.below(130);
            let n = *r.pick(&[0, 1, 2, l.len - 1, l.len + 1, 6, 8, 16, 24, 128, any]);
            let old = b.len();
            b.resize(n, 0);
            if n > old {
                r.fill(&mut b[old..]);
            }
        }
        (l.name, b)
    }

    fn op_bind_connect(&mut self, connect: bool) {
        let (_, fd, p) = self.slot();
        let (layout, a) = self.addr_named(p);
        let (name, call) = if connect {
            ("connect", Call::Connect)
        } else {
            ("bind", Call::Bind)
        };
        self.begin(format!(
            "{name}({} fd {fd}, {layout} [{}] len {})",
            p.name,
            hex(&a),
            a.len()
        ));
        let r = if connect {
            sys::connect(fd, &a)
        } else {
            sys::bind(fd, &a)
        };
        self.end_on(call, &r, fd, p);
    }

    /// An option to try: (label, level, name, natural value).
    fn option(&mut self, p: &Proto) -> (&'static str, c_int, c_int, Vec<u8>) {
        let r = &mut self.rng;
        let value = |r: &mut Rng, v: Val| -> Vec<u8> {
            match v {
                Val::Int => {
                    let small = r.below(64) as i32;
                    let x = r.pick_or_rand(&[0, 1, 1, u32::MAX, 2, 0x7fff_ffff, small as u32]);
                    x.to_ne_bytes().to_vec()
                }
                Val::Array { elem, max } => {
                    let any = r.below(max + 1);
                    let n = *r.pick(&[0, 1, 2, 3, max, max + 1, any]);
                    let mut b = vec![0u8; n * elem];
                    r.fill(&mut b);
                    b
                }
                Val::Bytes(n) => {
                    let mut b = vec![0u8; n];
                    r.fill(&mut b);
                    b
                }
                Val::Isotp(name) => isotp_value(r, name),
            }
        };
        match r.below(10) {
            0..=3 if !p.opts.is_empty() => {
                let o = r.pick(p.opts);
                (o.label, o.level, o.name, value(r, o.val))
            }
            0..=5 => {
                let o = r.pick(SOCKET_OPTS);
                (o.label, o.level, o.name, value(r, o.val))
            }
            6 | 7 => {
                // A random name at the protocol's level (or at a level no
                // rcan protocol has).
                let level = p.level.unwrap_or(*r.pick(&[100, 101, 102, 105]));
                let any = r.below(64) as c_int;
                let name = *r.pick(&[0, 9, 16, -1, any]);
                ("random name", level, name, value(r, Val::Bytes(4)))
            }
            _ => {
                let level = r.pick_or_rand(&[0, 6, 17, 100, 101, 102, 107, 263, u32::MAX]) as c_int;
                let any = r.below(256) as c_int;
                let name = *r.pick(&[0, 1, 2, 5, 8, any]);
                let n = *r.pick(&[4, 8, 16]);
                ("random level", level, name, value(r, Val::Bytes(n)))
            }
        }
    }

    fn op_setsockopt(&mut self) {
        let (_, fd, p) = self.slot();
        let (label, level, name, mut val) = self.option(p);
        let r = &mut self.rng;
        let len = if r.chance(4, 5) {
            val.len() as u32
        } else {
            *r.pick(&[0u32, 1, 3, 5, 7, 9, 4097, 65536, u32::MAX, 0x8000_0000])
        };
        if (len as c_int) >= 0 && len as usize > val.len() {
            let old = val.len();
            val.resize(len as usize, 0);
            r.fill(&mut val[old..]);
        }
        if level == table::SOL_CAN_ISOTP {
            // Whatever made the value (a random name may be a real one).
            let n = (len as usize).min(val.len());
            table::isotp_bound(name, &mut val[..n]);
        }
        self.begin(format!(
            "setsockopt({} fd {fd}, {label}: level {level}, name {name}, [{}], len {len})",
            p.name,
            hex(&val)
        ));
        let res = sys::setsockopt(fd, level, name, &val, len);
        self.end_on(Call::Setsockopt, &res, fd, p);
    }

    fn op_getsockopt(&mut self) {
        let (_, fd, p) = self.slot();
        let (label, level, name, _) = self.option(p);
        let r = &mut self.rng;
        if r.chance(1, 10) {
            let len = *r.pick(&[u32::MAX, 0x8000_0000, 0xffff_fff0]);
            self.begin(format!(
                "getsockopt({} fd {fd}, {label}: level {level}, name {name}, optlen {:#x} (negative))",
                p.name, len
            ));
            let res = sys::getsockopt_guarded(fd, level, name, len);
            if !self.end_on(Call::Getsockopt, &res, fd, p) {
                return;
            }
            if let Ok(l) = res {
                if l > 4096 {
                    self.violation(format!("succeeded with optlen {l:#x} written back"));
                }
            }
            return;
        }
        let n = *r.pick(&[0, 1, 3, 4, 5, 8, 16, 64, 4096, 8 * 513]);
        let mut buf = vec![0xAAu8; n];
        self.begin(format!(
            "getsockopt({} fd {fd}, {label}: level {level}, name {name}, optlen {n})",
            p.name
        ));
        let res = sys::getsockopt(fd, level, name, &mut buf);
        if !self.end_on(Call::Getsockopt, &res, fd, p) {
            return;
        }
        if let Ok(l) = res {
            if l > n {
                self.violation(format!("optlen {n} came back as {l}"));
                return;
            }
        }
        self.leak(
            LeakCheck::Opt,
            leak::check_opt(&buf, res, level, "getsockopt value"),
        );
    }

    fn send_len(&mut self, p: &Proto) -> usize {
        let r = &mut self.rng;
        match r.below(100) {
            0..=49 => *r.pick(p.send_lens),
            50..=97 => r.below(20),
            _ => r.below(70_000),
        }
    }

    fn send_flags(&mut self) -> c_int {
        let r = &mut self.rng;
        let mut f = if r.chance(4, 5) {
            libc::MSG_DONTWAIT
        } else {
            0
        };
        for (flag, n) in [
            (libc::MSG_OOB, 3),
            (libc::MSG_CONFIRM, 5),
            (libc::MSG_NOSIGNAL, 10),
            (libc::MSG_MORE, 5),
            (libc::MSG_EOR, 5),
            (0x10, 2), // MSG_PROBE
        ] {
            if r.chance(n, 100) {
                f |= flag;
            }
        }
        if r.chance(1, 50) {
            // Random high bits, but never MSG_FASTOPEN/MSG_ZEROCOPY
            // (pinned user pages) semantics by accident: they are only
            // meaningful to TCP/UDP and rejected or ignored here.
            f |= (r.next_u32() & 0x00ff_0000) as c_int;
        }
        f
    }

    /// A BCM message (bcm.rst): an opcode a user sends (sometimes a reply
    /// opcode or junk), a random subset of the flags, small counts,
    /// intervals of 0, 1 ms to 1 s and sometimes invalid ones, an
    /// identifier, `nframes` 0 to 4 (sometimes 256 to 258), the frames,
    /// and a length that matches `nframes` nine times in ten.
    fn bcm_msg(&mut self) -> Vec<u8> {
        let r = &mut self.rng;
        let opcode = match r.below(20) {
            0 => r.pick_or_rand(&[0, 8, 9, 10, 11, 12, 13]),
            _ => *r.pick(table::BCM_OPCODES),
        };
        let mut flags = 0u32;
        for &f in table::BCM_FLAGS {
            if r.chance(1, 4) {
                flags |= f;
            }
        }
        if r.chance(1, 30) {
            flags |= r.next_u32() & 0xffff_f000;
        }
        let fd = flags & 0x800 != 0;
        let count = *r.pick(&[0u32, 0, 1, 2, 3, 10, u32::MAX]);
        // Intervals: mostly harmless ones, so that cyclic operations do
        // not flood the debug kernel; a few invalid ones for the checks.
        let ival = |r: &mut Rng| -> (i64, i64) {
            match r.below(12) {
                0..=4 => (0, 0),
                5 => (0, 1_000),
                6..=7 => (0, 10_000),
                8 => (0, 100_000),
                9 => (1, 0),
                10 => (0, 1_000_000),
                _ => (
                    *r.pick(&[-1i64, 0, 40_000_000, i64::MAX]),
                    *r.pick(&[-1i64, 0, 999_999]),
                ),
            }
        };
        let (s1, u1) = ival(r);
        let (s2, u2) = ival(r);
        let can_id = match r.below(4) {
            0 => r.next_u32(),
            1 => r.next_u32() & 0x1fff_ffff | 0x8000_0000,
            _ => r.below(8) as u32 | 0x100,
        };
        let nframes = match r.below(20) {
            0 => *r.pick(&[256u32, 257, 258, u32::MAX]),
            _ => r.below(5) as u32,
        };
        let flen = if fd { 72 } else { 16 };
        let mut len = table::BCM_HEAD + nframes.min(258) as usize * flen;
        if r.chance(1, 10) {
            len = match r.below(3) {
                0 => len.saturating_sub(1 + r.below(flen)),
                1 => len + 1 + r.below(flen),
                _ => r.below(table::BCM_HEAD + 1),
            };
        }
        let mut b = vec![0u8; len];
        let mut head = [0u8; table::BCM_HEAD];
        head[0..4].copy_from_slice(&opcode.to_ne_bytes());
        head[4..8].copy_from_slice(&flags.to_ne_bytes());
        head[8..12].copy_from_slice(&count.to_ne_bytes());
        head[16..24].copy_from_slice(&s1.to_ne_bytes());
        head[24..32].copy_from_slice(&u1.to_ne_bytes());
        head[32..40].copy_from_slice(&s2.to_ne_bytes());
        head[40..48].copy_from_slice(&u2.to_ne_bytes());
        head[48..52].copy_from_slice(&can_id.to_ne_bytes());
        head[52..56].copy_from_slice(&nframes.to_ne_bytes());
        let h = len.min(table::BCM_HEAD);
        b[..h].copy_from_slice(&head[..h]);
        // Frames: the head's identifier mostly, a valid length mostly
        // (9..255 sometimes), random data.
        let mut off = table::BCM_HEAD;
        while off < len {
            let end = (off + flen).min(len);
            let mut f = vec![0u8; flen];
            r.fill(&mut f);
            let id = if r.chance(3, 4) { can_id } else { r.next_u32() };
            f[0..4].copy_from_slice(&id.to_ne_bytes());
            f[4] = if r.chance(9, 10) {
                r.below(if fd { 65 } else { 9 }) as u8
            } else {
                r.next_u32() as u8
            };
            b[off..end].copy_from_slice(&f[..end - off]);
            off = end;
        }
        b
    }

    fn op_send(&mut self) {
        let (_, fd, p) = self.slot();
        let data = if p.msg == table::Msg::Bcm && self.rng.chance(9, 10) {
            self.bcm_msg()
        } else {
            let mut n = self.send_len(p);
            if p.msg == table::Msg::Isotp {
                n = self.isotp_send_len(fd, n);
            }
            if n > table::J1939_MAX_SEND
                && (p.msg == table::Msg::J1939
                    || Self::ident(fd).and_then(|(_, k)| k) == Some(leak::Kind::J1939))
            {
                // Whatever the slot held: a descriptor reused for a J1939
                // socket gets the bound too (bar a reuse between this
                // query and the send).
                n = table::j1939_bound(n, self.rng.next_u32() as usize);
            }
            let mut data = vec![0u8; n];
            self.rng.fill(&mut data);
            data
        };
        let n = data.len();
        let flags = self.send_flags();
        match self.rng.below(3) {
            0 => {
                self.begin(format!(
                    "send({} fd {fd}, len {n}, flags {flags:#x})",
                    p.name
                ));
                let r = sys::sendto(fd, &data, flags, None);
                if self.end_send(Call::Send, &r, fd, p) {
                    self.check_sent(&r, n);
                }
            }
            1 => {
                let a = self.addr(p);
                self.begin(format!(
                    "sendto({} fd {fd}, len {n}, flags {flags:#x}, [{}] len {})",
                    p.name,
                    hex(&a),
                    a.len()
                ));
                let r = sys::sendto(fd, &data, flags, Some(&a));
                if self.end_send(Call::Sendto, &r, fd, p) {
                    self.check_sent(&r, n);
                }
            }
            _ => {
                let a = if self.rng.chance(2, 3) {
                    Some(self.addr(p))
                } else {
                    None
                };
                let (c, clen) = self.cmsg();
                self.begin(format!(
                    "sendmsg({} fd {fd}, len {n}, flags {flags:#x}, addr {:?}, control [{}] len {clen})",
                    p.name,
                    a.as_deref().map(hex),
                    hex(&c.0[..clen])
                ));
                let r = sys::sendmsg(fd, &data, a.as_deref(), &c, clen, flags);
                if self.end_send(Call::Sendmsg, &r, fd, p) {
                    self.check_sent(&r, n);
                }
            }
        }
    }

    /// `n` bounded for an ISO-TP send on `fd` ([`table::ISOTP_MAX_GAP_MS`]):
    /// a length the kernel accepts is at most [`table::isotp_max_send`] of
    /// the socket's TX_DL. The link layer of a bound socket cannot change
    /// (setsockopt answers EISCONN), and an unbound one refuses the send;
    /// only a descriptor closed and reused by another thread between the
    /// query and the send (for a socket with a smaller TX_DL) escapes the
    /// bound, and then only a transfer whose every gap is 127 ms would be
    /// long. Not counted as a call.
    fn isotp_send_len(&mut self, fd: c_int, n: usize) -> usize {
        let mut ll = [0u8; 3];
        let tx_dl =
            match sys::getsockopt(fd, table::SOL_CAN_ISOTP, table::CAN_ISOTP_LL_OPTS, &mut ll) {
                Ok(3) => ll[1],
                _ => 8,
            };
        let cap = table::isotp_max_send(tx_dl);
        if n > cap && n <= table::ISOTP_MAX_PDU {
            1 + self.rng.below(cap)
        } else {
            n
        }
    }

    fn check_sent(&self, r: &sys::Res<usize>, n: usize) {
        if let Ok(k) = *r {
            if k > n {
                self.violation(format!("sent {k} bytes of {n}"));
            }
        }
    }

    /// Control messages for sendmsg: well-formed SOL_SOCKET ones (mark,
    /// priority, timestamping, credentials, rights of nothing), a
    /// truncated header, or garbage.
    fn cmsg(&mut self) -> (sys::Cmsg, usize) {
        let r = &mut self.rng;
        let mut c = sys::Cmsg([0; 256]);
        if r.chance(1, 2) {
            return (c, 0);
        }
        let hdr = std::mem::size_of::<libc::cmsghdr>(); // 16 on x86_64
        let mut off = 0;
        for _ in 0..1 + r.below(3) {
            let (level, ty, dlen) = *r.pick(&[
                (libc::SOL_SOCKET, libc::SO_MARK, 4usize),
                (libc::SOL_SOCKET, libc::SO_PRIORITY, 4),
                (libc::SOL_SOCKET, libc::SO_TIMESTAMPING, 4),
                (libc::SOL_SOCKET, libc::SO_TXTIME, 8),
                (libc::SOL_SOCKET, libc::SCM_CREDENTIALS, 12),
                (100, 1, 4), // SOL_CAN_BASE
                (101, 1, 8),
                (0, 0, 3),
            ]);
            let total = hdr + dlen;
            let cmlen = if r.chance(1, 8) {
                *r.pick(&[0usize, 1, hdr - 1, 255, total + 1])
            } else {
                total
            };
            if off + ((total + 7) & !7) > c.0.len() {
                break;
            }
            c.0[off..off + 8].copy_from_slice(&cmlen.to_ne_bytes());
            c.0[off + 8..off + 12].copy_from_slice(&level.to_ne_bytes());
            c.0[off + 12..off + 16].copy_from_slice(&ty.to_ne_bytes());
            r.fill(&mut c.0[off + 16..off + total]);
            if ty == libc::SCM_CREDENTIALS && level == libc::SOL_SOCKET {
                // Our own pid/uid/gid, or the kernel refuses with EPERM...
                // which is a fine thing to try too, sometimes.
                if r.chance(3, 4) {
                    c.0[off + 16..off + 20].copy_from_slice(&std::process::id().to_ne_bytes());
                    c.0[off + 20..off + 28].fill(0);
                }
            }
            off += (total + 7) & !7;
        }
        let clen = if r.chance(1, 8) {
            r.below(off + 1)
        } else {
            off
        };
        (c, clen)
    }

    fn recv_flags(&mut self) -> c_int {
        let r = &mut self.rng;
        let mut f = if r.chance(7, 10) {
            libc::MSG_DONTWAIT
        } else {
            0
        };
        for (flag, n) in [
            (libc::MSG_PEEK, 20),
            (libc::MSG_TRUNC, 20),
            (libc::MSG_ERRQUEUE, 10),
            (libc::MSG_WAITALL, 2),
            (libc::MSG_OOB, 3),
            (libc::MSG_CMSG_CLOEXEC, 3),
        ] {
            if r.chance(n, 100) {
                f |= flag;
            }
        }
        f
    }

    fn op_recv(&mut self) {
        let (_, fd, p) = self.slot();
        let r = &mut self.rng;
        let n = *r.pick(&[0, 1, 5, 7, 8, 15, 16, 17, 56, 72, 100, 200, 65536]);
        let flags = self.recv_flags();
        let mut buf = vec![0xAAu8; n];
        let kind = self.rng.below(3);
        let res = match kind {
            0 | 1 => {
                let mut name = vec![0xAAu8; *self.rng.pick(&[0, 1, 2, 6, 8, 16, 24, 128])];
                let with_name = kind == 1;
                self.begin(format!(
                    "{}({} fd {fd}, len {n}, flags {flags:#x}, addrlen {})",
                    if with_name { "recvfrom" } else { "recv" },
                    p.name,
                    name.len()
                ));
                let before = sys::ino(fd).ok();
                let res = sys::recvfrom(fd, &mut buf, flags, with_name.then_some(&mut name[..]));
                let call = if with_name {
                    Call::Recvfrom
                } else {
                    Call::Recv
                };
                if !self.end_on(call, &res, fd, p) {
                    return;
                }
                if let Ok((k, al)) = res {
                    if with_name && al > MAX_ADDR {
                        self.violation(format!("address length {al}"));
                        return;
                    }
                    self.leak(LeakCheck::Data, leak::check_data(&buf, k, "received data"));
                    self.leak_bcm(fd, before, &buf, k);
                    if with_name {
                        self.leak_addr(fd, before, &name, al, "recvfrom address");
                    }
                }
                res.map(|(k, _)| k)
            }
            _ => {
                let mut name = vec![0xAAu8; *self.rng.pick(&[0, 2, 8, 16, 24, 128])];
                let mut c = sys::Cmsg([0xAA; 256]);
                let clen = *self.rng.pick(&[0, 8, 16, 17, 24, 32, 64, 256]);
                self.begin(format!(
                    "recvmsg({} fd {fd}, len {n}, flags {flags:#x}, namelen {}, controllen {clen})",
                    p.name,
                    name.len()
                ));
                let before = sys::ino(fd).ok();
                let res = sys::recvmsg(fd, &mut buf, &mut name, &mut c, clen, flags);
                if !self.end_on(Call::Recvmsg, &res, fd, p) {
                    return;
                }
                if let Ok(m) = &res {
                    if m.namelen > MAX_ADDR.max(name.len()) {
                        self.violation(format!("msg_namelen {}", m.namelen));
                    } else if m.controllen > clen {
                        self.violation(format!("msg_controllen {} > {clen}", m.controllen));
                    } else if m.n > n
                        && m.flags & libc::MSG_TRUNC == 0
                        && flags & libc::MSG_ERRQUEUE == 0
                    {
                        self.violation(format!(
                            "returned {} > buffer {n} without MSG_TRUNC in msg_flags",
                            m.n
                        ));
                    } else {
                        self.leak(
                            LeakCheck::Data,
                            leak::check_data(&buf, m.n, "received data"),
                        );
                        self.leak_bcm(fd, before, &buf, m.n);
                        self.leak_addr(fd, before, &name, m.namelen, "recvmsg msg_name");
                        self.leak(
                            LeakCheck::Cmsg,
                            leak::check_cmsgs(&c.0[..], m.controllen, "recvmsg control"),
                        );
                    }
                }
                res.map(|m| m.n)
            }
        };
        if let Ok(k) = res {
            let bound = if flags & libc::MSG_TRUNC != 0 {
                max_msg().max(n)
            } else {
                n
            };
            if k > bound {
                self.violation(format!("returned {k} bytes for a {n}-byte buffer"));
            }
        }
    }

    fn op_ioctl(&mut self) {
        let (_, fd, p) = self.slot();
        let r = &mut self.rng;
        let mut arg = sys::IoctlArg([0; 256]);
        r.fill(&mut arg.0);
        let dev = *r.pick(&["can0", "can1", "canip0", "lo", "nosuch0", ""]);
        let set_name = |a: &mut sys::IoctlArg| {
            a.0[..16].fill(0);
            a.0[..dev.len()].copy_from_slice(dev.as_bytes());
        };
        let cmd: libc::c_ulong = match r.below(12) {
            0 => 0x8906, // SIOCGSTAMP
            1 => 0x8907, // SIOCGSTAMPNS
            2 => libc::FIONREAD,
            3 => libc::TIOCOUTQ, // SIOCOUTQ
            4 => {
                arg.0[..4].copy_from_slice(&(r.below(2) as i32).to_ne_bytes());
                libc::FIONBIO
            }
            5 => 0x8905, // SIOCATMARK
            6 => {
                set_name(&mut arg);
                *r.pick(&[libc::SIOCGIFINDEX, libc::SIOCGIFMTU, libc::SIOCGIFFLAGS])
            }
            7 => {
                let ifi = self.sh.ifindex(r);
                arg.0[16..20].copy_from_slice(&ifi.to_ne_bytes());
                libc::SIOCGIFNAME
            }
            8 => 0x89E0 + r.below(16) as libc::c_ulong, // SIOCPROTOPRIVATE
            9 => {
                let cmd = 0x89F0 + r.below(16) as libc::c_ulong; // SIOCDEVPRIVATE
                let mut data = [0u8; 256];
                r.fill(&mut data);
                self.begin(format!(
                    "ioctl({} fd {fd}, {cmd:#x}, ifreq {dev:?} with data)",
                    p.name
                ));
                let res = sys::ioctl_ifr_data(fd, cmd, dev, &mut data);
                self.end(Call::Ioctl, &res);
                return;
            }
            _ => *r.pick(&[0x8901, 0x8902, 0x8903, 0x8904, 0x5401, 0x12345678, 0]), // FIOSETOWN.., TCGETS, junk
        };
        self.begin(format!("ioctl({} fd {fd}, {cmd:#x})", p.name));
        let res = sys::ioctl(fd, cmd, &mut arg);
        self.end(Call::Ioctl, &res);
    }

    fn op_misc(&mut self) {
        let (_, fd, p) = self.slot();
        match self.rng.below(4) {
            0 => {
                let how = *self.rng.pick(&[0, 1, 2, 3, -1]);
                self.begin(format!("shutdown({} fd {fd}, {how})", p.name));
                let r = sys::shutdown(fd, how);
                self.end(Call::Shutdown, &r);
            }
            1 => {
                let mut fds: Vec<libc::pollfd> = (0..1 + self.rng.below(4))
                    .map(|_| {
                        let (_, fd, _) = self.slot();
                        let ev = (self.rng.next_u32() & 0x3ff) as libc::c_short;
                        libc::pollfd {
                            fd,
                            events: ev,
                            revents: 0,
                        }
                    })
                    .collect();
                let t = *self.rng.pick(&[0, 0, 1, 10]);
                self.begin(format!(
                    "poll({:?}, {t})",
                    fds.iter().map(|f| (f.fd, f.events)).collect::<Vec<_>>()
                ));
                let r = sys::poll(&mut fds, t);
                if !self.end(Call::Poll, &r) {
                    return;
                }
                let always = libc::POLLERR | libc::POLLHUP | libc::POLLNVAL;
                if let Ok(k) = r {
                    let bad = fds.iter().find(|f| f.revents & !(f.events | always) != 0);
                    if k > fds.len() {
                        self.violation(format!("returned {k}"));
                    } else if let Some(f) = bad {
                        self.violation(format!(
                            "fd {} events {:#x} revents {:#x}",
                            f.fd, f.events, f.revents
                        ));
                    }
                }
            }
            k => {
                let peer = k == 3;
                let n = *self.rng.pick(&[0, 1, 2, 6, 8, 15, 16, 24, 128]);
                let mut buf = vec![0xAAu8; n];
                self.begin(format!(
                    "{}({} fd {fd}, len {n})",
                    if peer { "getpeername" } else { "getsockname" },
                    p.name
                ));
                let before = sys::ino(fd).ok();
                let r = sys::getname(fd, &mut buf, peer);
                let call = if peer {
                    Call::Getpeername
                } else {
                    Call::Getsockname
                };
                if self.end_on(call, &r, fd, p) {
                    if let Ok(l) = r {
                        if l > MAX_ADDR {
                            self.violation(format!("address length {l}"));
                        } else {
                            let what = if peer { "getpeername" } else { "getsockname" };
                            self.leak_addr(fd, before, &buf, l, what);
                        }
                    }
                }
            }
        }
    }

    fn one(&mut self) {
        // socket, close, dup, bind, connect, setsockopt, getsockopt, send,
        // recv, ioctl, shutdown/poll/getsockname/getpeername
        const WEIGHTS: [u32; 11] = [6, 3, 3, 8, 5, 10, 8, 20, 20, 5, 8];
        let (s, fd, _) = self.slot();
        let op = self.rng.weighted(&WEIGHTS);
        if fd < 0 && op != 0 {
            self.op_socket(s);
            return;
        }
        match op {
            0 => self.op_socket(s),
            1 => {
                let fd = self.sh.slots[s].swap(-1, Ordering::SeqCst);
                self.begin(format!("close(fd {fd})"));
                let r = sys::close(fd);
                self.end(Call::Close, &r);
            }
            2 => {
                let to = self.rng.below(NSLOTS);
                self.begin(format!("dup(fd {fd}) into slot {to}"));
                let r = sys::dup(fd);
                if self.end(Call::Dup, &r) {
                    if let Ok(nfd) = r {
                        let p = self.sh.slot_proto[s].load(Ordering::Relaxed);
                        self.store(to, nfd, p);
                    }
                }
            }
            3 => self.op_bind_connect(false),
            4 => self.op_bind_connect(true),
            5 => self.op_setsockopt(),
            6 => self.op_getsockopt(),
            7 => self.op_send(),
            8 => self.op_recv(),
            9 => self.op_ioctl(),
            _ => self.op_misc(),
        }
    }
}

/// ISO-TP identifiers the fuzzer binds to: few, so that sockets often
/// pair up (one's `tx_id` the other's `rx_id`) on one interface and
/// multi-frame transfers with flow control run between them; two
/// extended ones for 29-bit addressing.
/// J1939 addresses the fuzzer's sockets bind to and send to, so that
/// they find each other (the kernel then runs both ends of a session).
const J1939_ADDRS: [u64; 3] = [0x20, 0x30, 0x40];
/// A few J1939 NAMEs (no claim on the bus makes them resolve: sends to
/// them get EADDRNOTAVAIL, binds to them reach the claim table).
const J1939_NAMES: [u64; 2] = [0x1122_3344_5566_7788, 0x8000_0000_0000_0001];

const ISOTP_IDS: &[u32] = &[0x700, 0x701, 0x702, 0x8000_0700, 0x8000_0701];

/// A well-formed ISO-TP identifier (mostly standard).
fn isotp_id(r: &mut Rng) -> u32 {
    if r.chance(1, 6) {
        *r.pick(&ISOTP_IDS[3..])
    } else {
        *r.pick(&ISOTP_IDS[..3])
    }
}

/// A value for the ISO-TP option `name`, of the size mainline takes,
/// every field drawn so that all flags and link layers are reached but a
/// transfer stays short ([`table::ISOTP_MAX_GAP_MS`]).
fn isotp_value(r: &mut Rng, name: c_int) -> Vec<u8> {
    match name {
        table::CAN_ISOTP_OPTS => {
            // Each flag one time in five; unknown bits sometimes (taken
            // as given, as mainline).
            let mut flags = 0u32;
            for &f in table::ISOTP_FLAGS {
                if r.chance(1, 5) {
                    flags |= f;
                }
            }
            if r.chance(1, 20) {
                flags |= r.next_u32() & !0x3fff;
            }
            // frame_txtime: default (0), "zero" or up to 1 ms (the bound).
            let txtime = match r.below(4) {
                0 => 0,
                1 => table::ISOTP_TXTIME_ZERO,
                2 => r.below(table::ISOTP_MAX_TXTIME_NS as usize + 1) as u32,
                _ => *r.pick(&[1_000, 50_000, 100_000]),
            };
            // Addresses 0 or 1 so that extended-addressing sockets pair
            // up too; pad bytes the default 0xCC, 0 or random.
            let pad = |r: &mut Rng| r.pick_or_rand(&[0xCC, 0xCC, 0]) as u8;
            let mut b = Vec::with_capacity(12);
            b.extend_from_slice(&flags.to_ne_bytes());
            b.extend_from_slice(&txtime.to_ne_bytes());
            b.push(r.pick_or_rand(&[0, 1]) as u8);
            b.push(pad(r));
            b.push(pad(r));
            b.push(r.pick_or_rand(&[0, 1]) as u8);
            b
        }
        table::CAN_ISOTP_RECV_FC => {
            // BS 0 (no further FC), small, or any; STmin any byte (at most
            // 127 ms: reserved values mean 127 ms) but mostly short ones
            // (0, 1 ms, 0xF1..0xF9 = 100..900 us); wftmax any (stored).
            let bs = r.pick_or_rand(&[0, 0, 1, 2, 4, 8]) as u8;
            let stmin = match r.below(8) {
                0 => r.next_u32() as u8,
                1 => 0xF1 + r.below(9) as u8,
                2 => *r.pick(&[0x7F, 0x80, 0xF0, 0xFA, 0xFF, 5, 10]),
                3 => 1,
                _ => 0,
            };
            vec![bs, stmin, r.next_u32() as u8]
        }
        table::CAN_ISOTP_TX_STMIN => {
            let ns = match r.below(4) {
                0 => r.below(table::ISOTP_MAX_TX_STMIN_NS as usize + 1) as u32,
                1 => *r.pick(&[100_000, 1_000_000, table::ISOTP_MAX_TX_STMIN_NS]),
                _ => r.below(200_000) as u32,
            };
            ns.to_ne_bytes().to_vec()
        }
        table::CAN_ISOTP_RX_STMIN => {
            // Only makes the receiver drop CFs (the transfer then times
            // out in 1 s): any value.
            r.pick_or_rand(&[0, 100_000, 1_000_000, 50_000_000])
                .to_ne_bytes()
                .to_vec()
        }
        _ => {
            // CAN_ISOTP_LL_OPTS: classic (16, TX_DL 8) or FD (72, every
            // TX_DL, BRS or not), sometimes invalid combinations (EINVAL).
            let (mtu, dl, fl) = match r.below(6) {
                0 | 1 => (16u8, 8u8, 0u8),
                2..=4 => (
                    72,
                    *r.pick(&[8u8, 12, 16, 20, 24, 32, 48, 64, 64, 64]),
                    r.below(2) as u8,
                ),
                _ => (
                    r.pick_or_rand(&[16, 72, 0]) as u8,
                    r.pick_or_rand(&[8, 9, 64, 65]) as u8,
                    r.pick_or_rand(&[0, 1, 2]) as u8,
                ),
            };
            vec![mtu, dl, fl]
        }
    }
}

/// Reads the ifindex of `dev` (0 if it does not exist).
fn ifindex(dev: &str) -> u32 {
    std::fs::read_to_string(format!("/sys/class/net/{dev}/ifindex"))
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0)
}

fn module_loaded(name: &str) -> bool {
    std::fs::read_to_string("/proc/modules")
        .map(|s| s.lines().any(|l| l.split(' ').next() == Some(name)))
        .unwrap_or(false)
}

/// The modules the fuzzer loads: name, path, parameters.
const MODULES: &[(&str, &str, &str)] = &[
    ("rcan_pf", "net/can/rcan_pf.ko", ""),
    ("rcan_can", "net/can/rcan_can.ko", ""),
    ("rcan_raw", "net/can/rcan_raw.ko", ""),
    ("rcan_loop", "drivers/net/can/rcan_loop.ko", "count=2"),
    ("rcan_dsor", "net/can/dsor/rcan_dsor.ko", "ifname=can0"),
    ("rcan_bcm", "net/can/rcan_bcm.ko", ""),
    ("rcan_isotp", "net/can/rcan_isotp.ko", ""),
    ("rcan_j1939", "net/can/rcan_j1939.ko", ""),
];

fn rmmod_retrying(name: &str, secs: u64) -> Result<(), String> {
    let start = Instant::now();
    while module_loaded(name) {
        match sys::delete_module(name) {
            Ok(()) => break,
            Err(e) if start.elapsed() > Duration::from_secs(secs) => {
                return Err(format!("rmmod {name}: {}", table::errno_name(e)))
            }
            Err(_) => thread::sleep(Duration::from_millis(50)),
        }
    }
    Ok(())
}

fn links_up(ctl: c_int) {
    for i in 0..NDEV {
        let _ = sys::link_set(ctl, &format!("can{i}"), true, None);
    }
}

/// Device churn, until `stop`: links down/up, MTU changes, rcan_loop
/// unload/load. Errors outside the documented set fail the run.
fn churn(sh: &Shared, root: &Path, modchurn: bool, ctl: c_int) {
    let mut r = Rng::for_thread(sh.seed, 1000);
    let mut hist = Hist::new();
    let mut note = |call: Call, res: &sys::Res<()>, what: &str| -> bool {
        let e = res.err().unwrap_or(0);
        *hist.entry((call, e)).or_default() += 1;
        if e != 0 && !call.allowed().contains(&e) {
            sh.fail(format!(
                "seed {} device churn: {what}: {}",
                sh.seed,
                table::errno_name(e)
            ));
            return false;
        }
        true
    };
    while !sh.stop.load(Ordering::SeqCst) {
        thread::sleep(Duration::from_millis(20 + r.below(180) as u64));
        let dev = *r.pick(&["can0", "can1", "can0", "can1", "canip0"]);
        match r.below(20) {
            0..=11 => {
                let up = r.chance(1, 2);
                let res = sys::link_set(ctl, dev, up, None);
                note(
                    Call::LinkUpDown,
                    &res,
                    &format!("ip link set {dev} {}", if up { "up" } else { "down" }),
                );
            }
            12..=16 => {
                if dev == "canip0" {
                    continue;
                }
                let mtu =
                    r.pick_or_rand(&[16, 16, 72, 0, 8, 15, 17, 2060, 65535, u32::MAX]) as c_int;
                let res = sys::link_set(ctl, dev, true, Some(mtu));
                let what = format!("ip link set {dev} mtu {mtu}");
                // canloop takes CAN_MTU (16) and CANFD_MTU (72), the
                // latter only while down (EBUSY when up), as vcan.
                if note(Call::Mtu, &res, &what) && res.is_ok() && mtu != 16 && mtu != 72 {
                    sh.fail(format!(
                        "seed {} device churn: {what} accepted (CAN: only 16 or 72)",
                        sh.seed
                    ));
                }
            }
            _ if modchurn => {
                let res = sys::delete_module("rcan_loop");
                if !note(Call::Rmmod, &res, "rmmod rcan_loop") {
                    break;
                }
                if res.is_ok() {
                    for (i, x) in sh.can_ifindex.iter().enumerate() {
                        let old = x.swap(0, Ordering::Relaxed);
                        if old != 0 && (i == 0 || r.chance(1, 2)) {
                            sh.stale_ifindex.store(old, Ordering::Relaxed);
                        }
                    }
                    thread::sleep(Duration::from_millis(r.below(100) as u64));
                    let res = sys::finit_module(&root.join(MODULES[3].1), MODULES[3].2);
                    if !note(Call::Insmod, &res, "insmod rcan_loop count=2") {
                        break;
                    }
                    links_up(ctl);
                    for (i, x) in sh.can_ifindex.iter().enumerate() {
                        x.store(ifindex(&format!("can{i}")), Ordering::Relaxed);
                    }
                }
            }
            _ => {}
        }
    }
    CHURN_HIST.lock().unwrap().extend(hist);
}

static CHURN_HIST: Mutex<Hist> = Mutex::new(BTreeMap::new());

/// Runs one seed; returns (calls, histogram, failure).
fn run_seed(
    a: &Args,
    seed: u64,
    ctl: c_int,
) -> (u64, Hist, Option<String>, Duration, [u64; LEAK_CHECKS]) {
    let sh = Arc::new(Shared {
        seed,
        slots: std::array::from_fn(|_| AtomicI32::new(-1)),
        slot_proto: std::array::from_fn(|_| AtomicUsize::new(0)),
        can_ifindex: std::array::from_fn(|i| AtomicU32::new(ifindex(&format!("can{i}")))),
        stale_ifindex: AtomicU32::new(4242),
        canip_ifindex: AtomicU32::new(ifindex("canip0")),
        stop: AtomicBool::new(false),
        calls: AtomicU64::new(0),
        failure: Mutex::new(None),
        progress: (0..a.threads).map(|_| Progress::default()).collect(),
        start: Instant::now(),
        leak_checks: Default::default(),
    });
    CHURN_HIST.lock().unwrap().clear();
    let per_thread = a.iterations.div_ceil(a.threads as u64);
    let deadline = Duration::from_secs(a.seconds);
    let workers: Vec<_> = (0..a.threads)
        .map(|id| {
            let sh = Arc::clone(&sh);
            thread::spawn(move || {
                let mut w = Worker {
                    sh: &sh,
                    id,
                    rng: Rng::for_thread(seed, id as u64),
                    hist: Hist::new(),
                };
                for i in 0..per_thread {
                    if sh.stop.load(Ordering::Relaxed) || sh.start.elapsed() > deadline {
                        break;
                    }
                    sh.progress[id].iteration.store(i, Ordering::Relaxed);
                    w.one();
                }
                w.hist
            })
        })
        .collect();
    let churner = {
        let sh = Arc::clone(&sh);
        let root = a.root.clone();
        let modchurn = a.modchurn;
        thread::spawn(move || churn(&sh, &root, modchurn, ctl))
    };
    // Watchdog: the main thread polls the workers' progress.
    let wd = Duration::from_secs(a.watchdog).as_millis() as u64;
    while workers.iter().any(|w| !w.is_finished()) {
        thread::sleep(Duration::from_millis(200));
        let now = sh.now_ms();
        for (id, p) in sh.progress.iter().enumerate() {
            let since = p.since_ms.load(Ordering::SeqCst);
            if since != 0 && now.saturating_sub(since) > wd {
                println!(
                    "not ok - fuzz seed {seed}: HANG: thread {id} iteration {}: {} still in the kernel after {} s",
                    p.iteration.load(Ordering::Relaxed),
                    p.desc.lock().unwrap(),
                    a.watchdog
                );
                dump_stacks();
                println!("# reproduce: {}", repro(a, seed));
                println!("0 passed, 1 failed");
                sys::exit_now(1);
            }
        }
    }
    let mut hist = Hist::new();
    for w in workers {
        match w.join() {
            Ok(h) => {
                for (k, v) in h {
                    *hist.entry(k).or_default() += v;
                }
            }
            Err(_) => sh.fail(format!("seed {seed}: a worker thread panicked")),
        }
    }
    sh.stop.store(true, Ordering::SeqCst);
    let _ = churner.join();
    for (k, v) in CHURN_HIST.lock().unwrap().iter() {
        *hist.entry(*k).or_default() += v;
    }
    let elapsed = sh.start.elapsed();
    for s in &sh.slots {
        let fd = s.swap(-1, Ordering::SeqCst);
        if fd >= 0 {
            let _ = sys::close(fd);
        }
    }
    let f = sh.failure.lock().unwrap().clone();
    let leaks = sh.leak_checks.each_ref().map(|x| x.load(Ordering::Relaxed));
    (sh.calls.load(Ordering::Relaxed), hist, f, elapsed, leaks)
}

/// Prints the kernel stacks of this process' threads (root only).
fn dump_stacks() {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return;
    };
    for t in dir.flatten() {
        let stack = std::fs::read_to_string(t.path().join("stack")).unwrap_or_default();
        let wchan = std::fs::read_to_string(t.path().join("wchan")).unwrap_or_default();
        println!("# task {:?} wchan {wchan}", t.file_name());
        for l in stack.lines() {
            println!("#   {l}");
        }
    }
}

fn repro(a: &Args, seed: u64) -> String {
    format!(
        "rcan-fuzz --seed {seed} --iterations {} --seconds {} --threads {}{}",
        a.iterations,
        a.seconds,
        a.threads,
        if a.modchurn { "" } else { " --no-modchurn" }
    )
}

fn load(a: &Args) -> Result<(), String> {
    for (name, path, params) in MODULES {
        if module_loaded(name) {
            continue;
        }
        sys::finit_module(&a.root.join(path), params)
            .map_err(|e| format!("insmod {path} {params}: {}", table::errno_name(e)))?;
    }
    Ok(())
}

fn main() {
    let a = parse_args(std::env::args().skip(1)).unwrap_or_else(|e| {
        eprintln!("rcan-fuzz: {e}");
        usage()
    });
    if a.load {
        if let Err(e) = load(&a) {
            println!("not ok - fuzz: {e}");
            println!("0 passed, 1 failed");
            std::process::exit(1);
        }
    }
    let ctl = match sys::socket(libc::AF_INET, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0) {
        Ok(fd) => fd,
        Err(e) => {
            println!("not ok - fuzz: control socket: {}", table::errno_name(e));
            println!("0 passed, 1 failed");
            std::process::exit(1);
        }
    };
    links_up(ctl);
    let mut failed = false;
    let mut total = 0;
    let t0 = Instant::now();
    for &seed in &a.seeds {
        println!(
            "# rcan-fuzz: seed {seed}, {} threads, up to {} calls or {} s, module churn {}",
            a.threads,
            a.iterations,
            a.seconds,
            if a.modchurn { "on" } else { "off" }
        );
        let (calls, hist, failure, took, leaks) = run_seed(&a, seed, ctl);
        total += calls;
        print_hist(&hist);
        println!(
            "# seed {seed}: {calls} calls in {:.1} s ({:.0}/s)",
            took.as_secs_f64(),
            calls as f64 / took.as_secs_f64().max(0.001)
        );
        println!(
            "# seed {seed}: info-leak checks: received data {}, addresses {} ({} against \
             their protocol's layout), getsockopt values {}, control buffers {}, BCM reply \
             heads {}",
            leaks[LeakCheck::Data as usize],
            leaks[LeakCheck::Addr as usize] + leaks[LeakCheck::AddrLayout as usize],
            leaks[LeakCheck::AddrLayout as usize],
            leaks[LeakCheck::Opt as usize],
            leaks[LeakCheck::Cmsg as usize],
            leaks[LeakCheck::BcmReply as usize]
        );
        match failure {
            None => println!("ok - fuzz seed {seed}"),
            Some(f) => {
                println!("not ok - fuzz {f}");
                println!("# reproduce: {}", repro(&a, seed));
                failed = true;
                break;
            }
        }
        links_up(ctl);
    }
    let _ = sys::close(ctl);
    if a.load {
        for (name, ..) in MODULES.iter().rev() {
            if let Err(e) = rmmod_retrying(name, 15) {
                println!("not ok - fuzz: after the run: {e}");
                failed = true;
            }
        }
    }
    println!(
        "# rcan-fuzz: {total} calls in {:.1} s over {} seed(s)",
        t0.elapsed().as_secs_f64(),
        a.seeds.len()
    );
    if failed {
        println!("0 passed, 1 failed");
        std::process::exit(1);
    }
    println!("1 passed, 0 failed");
}

fn print_hist(h: &Hist) {
    let mut by_call: BTreeMap<Call, Vec<(c_int, u64)>> = BTreeMap::new();
    for (&(c, e), &n) in h {
        by_call.entry(c).or_default().push((e, n));
    }
    for (c, v) in by_call {
        let total: u64 = v.iter().map(|x| x.1).sum();
        let errs: Vec<String> = v
            .iter()
            .map(|&(e, n)| format!("{} {n}", table::errno_name(e)))
            .collect();
        println!("# {:<12} {total:>8}: {}", c.name(), errs.join(", "));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &[&str]) -> Result<Args, String> {
        parse_args(s.iter().map(|x| x.to_string()))
    }

    #[test]
    fn command_line() {
        let a = args(&[
            "--seed",
            "5",
            "--seed",
            "0x10",
            "--threads",
            "2",
            "--no-modchurn",
        ])
        .unwrap();
        assert_eq!(a.seeds, [5, 16]);
        assert_eq!(a.threads, 2);
        assert!(!a.modchurn);
        assert_eq!(args(&[]).unwrap().seeds, [1]);
        assert!(args(&["--seed"]).is_err());
        assert!(args(&["--bogus"]).is_err());
        assert_eq!(
            repro(&a, 16),
            "rcan-fuzz --seed 16 --iterations 20000 --seconds 60 --threads 2 --no-modchurn"
        );
    }

    fn shared(seed: u64) -> Shared {
        Shared {
            seed,
            slots: std::array::from_fn(|_| AtomicI32::new(-1)),
            slot_proto: std::array::from_fn(|_| AtomicUsize::new(0)),
            can_ifindex: std::array::from_fn(|i| AtomicU32::new(10 + i as u32)),
            stale_ifindex: AtomicU32::new(7),
            canip_ifindex: AtomicU32::new(9),
            stop: AtomicBool::new(false),
            calls: AtomicU64::new(0),
            failure: Mutex::new(None),
            progress: vec![Progress::default()],
            start: Instant::now(),
            leak_checks: Default::default(),
        }
    }

    #[test]
    fn addresses_follow_the_tables() {
        let sh = shared(3);
        let mut w = Worker {
            sh: &sh,
            id: 0,
            rng: Rng::new(3),
            hist: Hist::new(),
        };
        let mut exact = 0;
        for _ in 0..2000 {
            for p in PROTOS {
                let a = w.addr(p);
                if p.addrs.iter().any(|l| l.len == a.len())
                    && a.len() >= 2
                    && u16::from_ne_bytes([a[0], a[1]]) == AF_CAN
                {
                    exact += 1;
                }
            }
        }
        // Mostly well-formed (right length, AF_CAN), some not.
        let total = 2000 * PROTOS.len();
        assert!(exact > total * 2 / 3 && exact < total, "{exact} of {total}");
        // Same seed, same addresses.
        let mut w2 = Worker {
            sh: &sh,
            id: 0,
            rng: Rng::new(3),
            hist: Hist::new(),
        };
        let mut w3 = Worker {
            sh: &sh,
            id: 0,
            rng: Rng::new(3),
            hist: Hist::new(),
        };
        assert_eq!(w2.addr(&PROTOS[2]), w3.addr(&PROTOS[2]));
    }

    #[test]
    fn bcm_messages_mostly_well_formed() {
        let sh = shared(5);
        let mut w = Worker {
            sh: &sh,
            id: 0,
            rng: Rng::new(5),
            hist: Hist::new(),
        };
        let (mut exact, mut user_op, mut with_frames) = (0, 0, 0);
        for _ in 0..2000 {
            let m = w.bcm_msg();
            if m.len() < table::BCM_HEAD {
                continue;
            }
            let word = |o: usize| u32::from_ne_bytes(m[o..o + 4].try_into().unwrap());
            let flen = if word(4) & 0x800 != 0 { 72 } else { 16 };
            let nframes = word(52) as usize;
            if m.len() == table::BCM_HEAD + nframes * flen {
                exact += 1;
                with_frames += usize::from(nframes > 0);
            }
            user_op += usize::from(table::BCM_OPCODES.contains(&word(0)));
            // The hole after count is never set by the fuzzer.
            assert_eq!(&m[12..16], &[0; 4]);
        }
        assert!(exact > 1500 && exact < 2000, "{exact}");
        assert!(with_frames > 1000, "{with_frames}");
        assert!(user_op > 1700 && user_op < 2000, "{user_op}");
        // The BCM entry is in the table, with its EFAULT.
        let bcm = PROTOS.iter().find(|p| p.name == "CAN_BCM").unwrap();
        assert_eq!((bcm.sock_type, bcm.protocol), (libc::SOCK_DGRAM, 2));
        assert!(bcm.extra_send.contains(&libc::EFAULT));
    }

    #[test]
    fn undocumented_errno_fails() {
        let sh = shared(9);
        let mut w = Worker {
            sh: &sh,
            id: 0,
            rng: Rng::new(1),
            hist: Hist::new(),
        };
        w.begin("bind(x)".into());
        assert!(w.end(Call::Bind, &sys::Res::<()>::Err(libc::EINVAL)));
        assert!(sh.failure.lock().unwrap().is_none());
        assert!(!w.end(Call::Bind, &sys::Res::<()>::Err(515)));
        let f = sh.failure.lock().unwrap().clone().unwrap();
        assert!(
            f.contains("seed 9 thread 0") && f.contains("errno515"),
            "{f}"
        );
        assert!(sh.stop.load(Ordering::SeqCst));
        assert_eq!(w.hist[&(Call::Bind, libc::EINVAL)], 1);
    }
}
