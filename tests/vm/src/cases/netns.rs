// SPDX-License-Identifier: GPL-2.0
//! Network namespaces (Documentation/networking/rcan/netns.rst): CAN
//! interfaces moved into namespaces with `ip link set DEV netns`, sockets
//! made inside them, frames that never cross, interface indexes that mean
//! a device of the socket's namespace, devices moved under traffic and
//! namespaces deleted with sockets open.
//!
//! A namespace is made by a thread of this program (`unshare(CLONE_NEWNET)`)
//! that stays in it and runs the work it is given: sockets it opens belong
//! to its namespace for their whole life, whichever thread uses them later,
//! and the `ip` it starts runs there. `ip link set DEV netns TID` moves a
//! device in; the namespace goes when the thread has ended and its last
//! socket is closed, as after `ip netns del` with nothing left in it. No
//! `/run/netns` mount is needed.
//!
//! The `raw_`/`bcm_` tests are portable: on mainline they run with vcan,
//! which can be moved too. What differs is written down where it is
//! checked: a vcan device (it has `rtnl_link_ops`) dies with its
//! namespace, a canloop device (no link ops, like a physical device)
//! comes back to the initial namespace.

use std::io;
use std::os::fd::AsRawFd;
use std::os::unix::fs::MetadataExt;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::thread;
use std::time::{Duration, Instant};

use rcan_uapi::dsor::{dsor_port, DsorAddr, DsorSocket};
use rcan_uapi::raw;
use rcan_uapi::ArbSocket;
use socketcan::{CanFilter, CanSocket, Socket, SocketOptions};

use crate::canraw::{self, std as sff};
use crate::check::{ensure, wait_until, OrFail, TestResult, QUIET, SETTLE};
use crate::ctx::{tool, Ctx, Module, Stack};

use super::{portable_table, test_table};

pub const TESTS: &[crate::Test] = portable_table![
    raw_netns_isolation,
    raw_netns_move_under_traffic,
    raw_netns_delete_with_sockets,
    bcm_netns_send,
    candev_netns_returns,
];

pub const OURS: &[crate::Test] =
    test_table![netns_thesis_api, netns_canloop_returns, i82527_netns_move,];

type Job = Box<dyn FnOnce() + Send>;

/// A network namespace of this test: a thread that made it and runs jobs
/// in it until dropped. Also used by `isotp.rs` (the isotptun test).
pub(super) struct Ns {
    tid: i32,
    jobs: Option<mpsc::Sender<Job>>,
    thread: Option<thread::JoinHandle<()>>,
}

impl Ns {
    pub(super) fn new() -> Result<Ns, String> {
        let (jobs, rx) = mpsc::channel::<Job>();
        let (ttx, trx) = mpsc::channel::<Result<i32, String>>();
        let thread = thread::spawn(move || {
            // SAFETY: unshare(2) with a flag only; it changes this thread's
            // namespace, nothing in this program's memory.
            if unsafe { libc::unshare(libc::CLONE_NEWNET) } != 0 {
                let _ = ttx.send(Err(format!(
                    "unshare(CLONE_NEWNET): {}",
                    io::Error::last_os_error()
                )));
                return;
            }
            // SAFETY: gettid(2) has no arguments.
            let _ = ttx.send(Ok(unsafe { libc::gettid() }));
            for job in rx {
                job();
            }
        });
        let tid = trx
            .recv()
            .map_err(|_| "namespace thread died".to_string())??;
        Ok(Ns {
            tid,
            jobs: Some(jobs),
            thread: Some(thread),
        })
    }

    /// Runs `f` on the namespace's thread: sockets it opens are the
    /// namespace's, programs it starts run there.
    pub(super) fn run<T: Send + 'static>(&self, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = mpsc::channel();
        self.jobs
            .as_ref()
            .expect("namespace thread")
            .send(Box::new(move || {
                let _ = tx.send(f());
            }))
            .expect("namespace thread gone");
        rx.recv().expect("namespace job lost")
    }

    /// `ip link set DEV netns TID` from the initial namespace.
    pub(super) fn take(&self, dev: &str) -> TestResult {
        ip(&["link", "set", "dev", dev, "netns", &self.tid.to_string()])
    }

    /// `ip ARGS` inside the namespace.
    pub(super) fn ip(&self, args: &[&str]) -> TestResult {
        let args: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        self.run(move || ip(&args.iter().map(String::as_str).collect::<Vec<_>>()))
    }

    /// The index of `dev` in the namespace (`if_nametoindex` there).
    fn ifindex(&self, dev: &str) -> Result<u32, String> {
        let d = dev.to_string();
        self.run(move || ifindex_here(&d))
    }

    /// Moves `dev` in and sets it up there; returns its index there.
    fn take_up(&self, dev: &str) -> Result<u32, String> {
        self.take(dev)?;
        self.ip(&["link", "set", "dev", dev, "up"])?;
        self.ifindex(dev)
    }

    /// A CAN_RAW socket of the namespace bound to `ifindex` (0: every CAN
    /// interface of the namespace).
    fn raw(&self, ifindex: u32) -> Result<CanSocket, String> {
        self.run(move || canraw::open(ifindex))
    }
}

impl Drop for Ns {
    /// Ends the thread. The namespace goes once its sockets are closed too.
    fn drop(&mut self) {
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs `ip ARGS` in the calling thread's namespace.
pub(super) fn ip(args: &[&str]) -> TestResult {
    let out = Command::new(tool("ip"))
        .args(args)
        .output()
        .or_fail(format_args!("ip {}", args.join(" ")))?;
    ensure!(
        out.status.success(),
        "ip {}: {}: {}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stderr).trim()
    );
    Ok(())
}

/// `if_nametoindex(dev)` in the calling thread's namespace.
fn ifindex_here(dev: &str) -> Result<u32, String> {
    let c = std::ffi::CString::new(dev).map_err(|e| format!("{dev}: {e}"))?;
    // SAFETY: a NUL-terminated name, read for the call only.
    let i = unsafe { libc::if_nametoindex(c.as_ptr()) };
    ensure!(i != 0, "{dev}: no such device here");
    Ok(i)
}

/// Whether `dev` is in the initial namespace (this program's main
/// thread's).
fn in_init(dev: &str) -> bool {
    ifindex_here(dev).is_ok()
}

/// Reads from `s` (without blocking) until the error `want` comes; frames
/// queued before it and `ENETDOWN` (the device went down first) are
/// skipped. Fails if the queue runs dry first.
fn expect_error(s: &CanSocket, want: i32, who: &str) -> TestResult {
    s.set_nonblocking(true).or_fail("O_NONBLOCK")?;
    let r = (|| {
        for _ in 0..100_000 {
            match s.read_frame() {
                Ok(_) => continue,
                Err(e) if e.raw_os_error() == Some(want) => return Ok(()),
                Err(e) if e.raw_os_error() == Some(libc::ENETDOWN) => continue,
                Err(e) => {
                    return Err(format!(
                        "{who}: expected {}, got {e}",
                        io::Error::from_raw_os_error(want)
                    ))
                }
            }
        }
        Err(format!("{who}: no error after 100000 frames"))
    })();
    s.set_nonblocking(false).or_fail("clear O_NONBLOCK")?;
    r
}

/// Reads whatever `s` has queued, without blocking.
fn drain(s: &CanSocket) -> TestResult {
    s.set_nonblocking(true).or_fail("O_NONBLOCK")?;
    while s.read_frame().is_ok() {}
    s.set_nonblocking(false).or_fail("clear O_NONBLOCK")
}

/// Two namespaces with one interface each, and the initial namespace
/// without: a frame sent in one reaches the sockets of that namespace
/// only (bound to the interface or to "every interface"), and an
/// interface index of another namespace is no device to bind to (ENODEV,
/// as mainline `raw_bind`'s `dev_get_by_index(sock_net(sk), ...)` fails).
fn raw_netns_isolation(ctx: &mut Ctx) -> TestResult {
    ctx.can_ifaces(2)?;
    let (a, b) = (Ns::new()?, Ns::new()?);
    let ia = a.take_up("can0")?;
    let ib = b.take_up("can1")?;
    let (a_tx, a_dev, a_all) = (a.raw(ia)?, a.raw(ia)?, a.raw(0)?);
    let (b_tx, b_dev, b_all) = (b.raw(ib)?, b.raw(ib)?, b.raw(0)?);
    let init_all = canraw::open(0)?;

    let fa = sff(0x123, &[0xa]);
    canraw::send(&a_tx, &fa)?;
    canraw::expect(&a_dev, &fa, "A, bound to can0")?;
    canraw::expect(&a_all, &fa, "A, every interface")?;
    let fb = sff(0x321, &[0xb]);
    canraw::send(&b_tx, &fb)?;
    canraw::expect(&b_dev, &fb, "B, bound to can1")?;
    canraw::expect(&b_all, &fb, "B, every interface")?;
    canraw::expect_quiet(&[
        ("A, bound to can0", &a_dev),
        ("A, every interface", &a_all),
        ("B, bound to can1", &b_dev),
        ("B, every interface", &b_all),
        ("initial namespace, every interface", &init_all),
    ])?;

    // An index that is not a device of the socket's namespace. (It may
    // name another device there: then there is nothing to check.)
    if ib != ia && a.ifindex("can1").is_err() {
        let r = a.run(move || {
            let s = canraw::unbound()?;
            Ok::<_, String>(raw::bind(&s, &canraw::addr_bytes(libc::AF_CAN as u16, ib)))
        })?;
        let e = r.err().and_then(|e| e.raw_os_error());
        ensure!(
            e == Some(libc::ENODEV),
            "bind in A to B's can1 (ifindex {ib}): expected ENODEV, got {e:?}"
        );
    }
    let s = canraw::unbound()?;
    let e = raw::bind(&s, &canraw::addr_bytes(libc::AF_CAN as u16, ia))
        .err()
        .and_then(|e| e.raw_os_error());
    let taken = ifindex_here("can0").is_err() && ifindex_here("can1").is_err();
    ensure!(taken, "can0/can1 still in the initial namespace");
    ensure!(
        e == Some(libc::ENODEV),
        "bind in the initial namespace to A's can0 (ifindex {ia}): expected ENODEV, got {e:?}"
    );
    Ok(())
}

/// can1 moves to a namespace while a socket of the initial namespace
/// sends on it and another receives: both lose the device as on
/// unregistration (the receiver gets ENODEV, mainline's `sk_err`; a send
/// then has no interface: ENXIO), nothing reaches them afterwards, and in
/// the namespace the device works for new sockets.
fn raw_netns_move_under_traffic(ctx: &mut Ctx) -> TestResult {
    let i = ctx.can_ifaces(2)?;
    let (i0, i1) = (i[0], i[1]);
    let tx = canraw::open(i1)?;
    let rx = canraw::open(i1)?;
    let stop = Arc::new(AtomicBool::new(false));
    let sender = {
        let stop = stop.clone();
        thread::spawn(move || {
            let mut n = 0u64;
            // The 1 ms are a back-off after a failed send and a pace
            // every 64 frames (the receiver keeps up), not synchronisation.
            while !stop.load(Ordering::Relaxed) {
                if tx.write_frame(&sff(0x42, &[n as u8])).is_err() {
                    thread::sleep(Duration::from_millis(1));
                    continue;
                }
                n += 1;
                if n.is_multiple_of(64) {
                    thread::sleep(Duration::from_millis(1));
                }
            }
            (tx, n)
        })
    };
    let t0 = Instant::now();
    while canraw::recv(&rx).is_err() && t0.elapsed() < canraw::RAW_RX_TIMEOUT {}
    let ns = Ns::new()?;
    ns.take("can1")?;
    stop.store(true, Ordering::Relaxed);
    let (tx, sent) = sender.join().map_err(|_| "sender panicked".to_string())?;
    ctx.note(format!("{sent} frames sent before and during the move"));
    ensure!(sent > 0, "nothing sent before the move");
    expect_error(&rx, libc::ENODEV, "receiver bound to can1")?;
    let e = tx
        .write_frame(&sff(0x43, &[]))
        .err()
        .and_then(|e| e.raw_os_error());
    ensure!(
        e == Some(libc::ENXIO),
        "send on the socket that lost can1: expected ENXIO, got {e:?}"
    );
    // Unbound now: once the frames queued before the move are read, a
    // frame on can0 of the initial namespace does not reach it either.
    drain(&rx)?;
    let s0 = canraw::open(i0)?;
    canraw::send(&s0, &sff(0x44, &[]))?;
    canraw::expect_quiet(&[("receiver that lost can1", &rx)])?;

    let j = ns.ifindex("can1")?;
    ns.ip(&["link", "set", "dev", "can1", "up"])?;
    let (ntx, nrx) = (ns.raw(j)?, ns.raw(0)?);
    let f = sff(0x45, &[1, 2]);
    canraw::send(&ntx, &f)?;
    canraw::expect(&nrx, &f, "namespace, every interface")?;
    Ok(())
}

/// A namespace with sockets bound to its interface (with filters, one
/// with an error mask) and to every interface, an unbound one and frames
/// queued, goes while the sockets are open (its thread ends first, then
/// the sockets close): no leak or splat (the runner checks the log and,
/// on the debug kernel, kmemleak), and the interface leaves with it (back
/// to the initial namespace or gone, checked per stack) and the modules
/// unload.
fn raw_netns_delete_with_sockets(ctx: &mut Ctx) -> TestResult {
    ctx.can_ifaces(2)?;
    let ns = Ns::new()?;
    let j = ns.take_up("can1")?;
    let socks = ns.run(move || -> Result<Vec<CanSocket>, String> {
        let a = canraw::open(j)?;
        a.set_filters(&[CanFilter::new(0x100, 0x700), CanFilter::new(0x42, 0x7ff)])
            .or_fail("CAN_RAW_FILTER")?;
        let b = canraw::open(j)?;
        b.set_error_filter(0x1ff).or_fail("CAN_RAW_ERR_FILTER")?;
        let all = canraw::open(0)?;
        let unbound = canraw::unbound()?;
        for k in 0..4u8 {
            canraw::send(&b, &sff(0x100 + u16::from(k), &[k]))?;
        }
        Ok(vec![a, b, all, unbound])
    })?;
    canraw::recv(&socks[2]).map_err(|e| format!("namespace, every interface: {e}"))?;
    // Its thread has ended (drop joins it); then the sockets close.
    drop(ns);
    drop(socks);
    // The namespace is torn down by a kernel worker: wait for it.
    match ctx.stack() {
        // canloop has no link ops: like a physical device, it comes back.
        Stack::Ours => wait_until(SETTLE, "can1 back from its namespace", || in_init("can1"))?,
        // vcan has link ops without netns_refund: it dies with the
        // namespace. A negative check: nothing in the initial namespace
        // marks the end of that namespace's teardown, so 2 s are given
        // for can1 to (wrongly) come back; not synchronisation.
        Stack::Mainline => {
            let t0 = Instant::now();
            while t0.elapsed() < Duration::from_secs(2) {
                ensure!(!in_init("can1"), "vcan can1 came back from its namespace");
                thread::sleep(Duration::from_millis(50));
            }
        }
    }
    ctx.unload_all()
}

/// CAN_BCM in a namespace: `connect` names an interface of the socket's
/// namespace (another's index is ENODEV), TX_SEND sends there only, and
/// the socket's `/proc/net/can-bcm/<inode>` file is in its namespace's
/// `/proc/net`, not the initial namespace's.
fn bcm_netns_send(ctx: &mut Ctx) -> TestResult {
    ctx.bcm_ifaces(2)?;
    let ns = Ns::new()?;
    let j = ns.take_up("can1")?;
    let init_all = canraw::open(0)?;
    let i0 = ctx.ifindex("can0")?;
    let (rx, res, ino) = ns.run(move || -> Result<_, String> {
        let rx = canraw::open(0)?;
        let b = raw::socket(libc::PF_CAN, libc::SOCK_DGRAM, 2).or_fail("socket(CAN_BCM)")?;
        let other = raw::connect(&b, &canraw::addr_bytes(libc::AF_CAN as u16, i0)).err();
        let b = raw::socket(libc::PF_CAN, libc::SOCK_DGRAM, 2).or_fail("socket(CAN_BCM)")?;
        raw::connect(&b, &canraw::addr_bytes(libc::AF_CAN as u16, j)).or_fail("BCM connect")?;
        let mut m = vec![0u8; 56];
        m[0..4].copy_from_slice(&4u32.to_ne_bytes()); // TX_SEND
        m[48..52].copy_from_slice(&0x77u32.to_ne_bytes());
        m[52..56].copy_from_slice(&1u32.to_ne_bytes());
        let mut f = [0u8; 16];
        f[..4].copy_from_slice(&0x77u32.to_ne_bytes());
        f[4] = 1;
        f[8] = 0x5a;
        m.extend_from_slice(&f);
        raw::write(&b, &m).or_fail("TX_SEND")?;
        // The socket's file is in its namespace's /proc/net/can-bcm
        // (this thread's /proc/net), named by its inode.
        let ino = std::fs::metadata(format!("/proc/self/fd/{}", b.as_raw_fd()))
            .or_fail("stat of the BCM socket")?
            .ino();
        let mine = format!("/proc/thread-self/net/can-bcm/{ino}");
        let text = std::fs::read_to_string(&mine).or_fail(&mine)?;
        ensure!(
            text.starts_with(">>> socket "),
            "{mine}: unexpected text {text:?}"
        );
        Ok((rx, other, ino))
    })?;
    let init_file = format!("/proc/net/can-bcm/{ino}");
    ensure!(
        !std::path::Path::new(&init_file).exists(),
        "the namespace's BCM socket has a file in the initial namespace: {init_file}"
    );
    canraw::expect(&rx, &sff(0x77, &[0x5a]), "namespace, every interface")?;
    canraw::expect_quiet(&[("initial namespace, every interface", &init_all)])?;
    if ns.ifindex("can0").is_err() {
        let e = res.and_then(|e| e.raw_os_error());
        ensure!(
            e == Some(libc::ENODEV),
            "BCM connect to can0 of the initial namespace (ifindex {i0}): expected ENODEV, got {e:?}"
        );
    }
    Ok(())
}

/// An SJA1000 controller (QEMU's Kvaser card; link kind "can") in a
/// namespace that goes comes back to the initial namespace, as mainline's
/// can-dev devices do (`netns_refund`), rather than being unregistered
/// under its driver; the driver then unloads cleanly.
fn candev_netns_returns(ctx: &mut Ctx) -> TestResult {
    ctx.sja1000_cards()?;
    let ns = Ns::new()?;
    ns.take("can0")?;
    ns.ifindex("can0")?;
    ensure!(!in_init("can0"), "can0 still in the initial namespace");
    drop(ns);
    wait_until(SETTLE, "can0 back from its namespace", || in_init("can0"))?;
    ctx.unload_all()
}

/// The thesis API (CANPROTO_CAN) in two namespaces: a socket bound to
/// every interface receives what is sent in its namespace only; sending to
/// ifindex 0 ("every CAN interface", thesis 5.2.2) sends on the
/// namespace's interfaces only. DSOR stays in the initial namespace
/// (netns.rst): its traffic there never reaches a namespace's sockets,
/// socket() elsewhere is EAFNOSUPPORT, and `canip0` cannot be moved.
fn netns_thesis_api(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&["count=3"])?;
    let (a, b) = (Ns::new()?, Ns::new()?);
    a.take_up("can0")?;
    b.take_up("can1")?;
    let arb = rcan_uapi::arb_std(0x155, false);
    let open_all = || -> Result<ArbSocket, String> {
        let s = ArbSocket::new().or_fail("socket(CANPROTO_CAN)")?;
        s.bind(0, rcan_uapi::CAN_MASK_ANY, 0)
            .or_fail("bind to every interface")?;
        set_rcvtimeo(&s)?;
        Ok(s)
    };
    let (a_rx, a_tx) = a.run(move || Ok::<_, String>((open_all()?, open_all()?)))?;
    let (b_rx, b_tx) = b.run(move || Ok::<_, String>((open_all()?, open_all()?)))?;
    let init_rx = open_all()?;
    a_tx.send_to(&[0xa], arb, 0)
        .or_fail("A: sendto ifindex 0")?;
    let mut buf = [0u8; 8];
    let (n, from) = a_rx.recv_from(&mut buf).or_fail("A: recvfrom")?;
    ensure!(
        n == 1 && buf[0] == 0xa && from.arb == arb,
        "A: got {n} bytes, arb {:#x}",
        from.arb
    );
    b_tx.send_to(&[0xb], arb, 0)
        .or_fail("B: sendto ifindex 0")?;
    let (n, _) = b_rx.recv_from(&mut buf).or_fail("B: recvfrom")?;
    ensure!(n == 1 && buf[0] == 0xb, "B: got {n} bytes {:x?}", &buf[..n]);
    // A negative check (nothing else arrives), not synchronisation.
    thread::sleep(QUIET);
    for (who, s) in [("A", &a_rx), ("B", &b_rx), ("initial namespace", &init_rx)] {
        let r = s.recv(&mut buf, libc::MSG_DONTWAIT);
        ensure!(
            r.as_ref().err().and_then(|e| e.raw_os_error()) == Some(libc::EAGAIN),
            "{who}: a frame from another namespace: {r:?}"
        );
    }
    // DSOR runs in the initial namespace, on can2: a port message to
    // this node goes out on can2 (an initial-namespace socket on can2
    // sees its frames) and arrives, and namespace A's socket bound to
    // every interface of A sees none of it.
    ctx.insmod(Module::Dsor, &["ifname=can2"])?;
    let watch = canraw::open(ctx.ifindex("can2")?)?;
    let a_all = a.raw(0)?;
    let port = DsorAddr::Port {
        prio: 0,
        port: dsor_port(0, 7),
    };
    let (p, q) = (DsorSocket::new(), DsorSocket::new());
    let (p, q) = (
        p.or_fail("socket(CANPROTO_DSOR)")?,
        q.or_fail("socket(CANPROTO_DSOR)")?,
    );
    p.set_rcvtimeo(canraw::RAW_RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")?;
    p.bind(&port).or_fail("DSOR bind 0:7")?;
    let msg: Vec<u8> = (0..40u8).collect();
    q.send_to(&msg, &port).or_fail("DSOR send to 0:7")?;
    let mut got = vec![0u8; 256];
    let (n, _) = p.recv_from(&mut got).or_fail("DSOR recvfrom")?;
    ensure!(
        got[..n] == msg[..],
        "DSOR message corrupted: {:x?}",
        &got[..n]
    );
    canraw::recv(&watch).map_err(|e| format!("no DSOR frame on can2: {e}"))?;
    canraw::expect_quiet(&[("namespace A, every interface, during DSOR", &a_all)])?;
    let e = a
        .run(|| raw::socket(libc::PF_CAN, libc::SOCK_DGRAM, 17).err())
        .and_then(|e| e.raw_os_error());
    ensure!(
        e == Some(libc::EAFNOSUPPORT),
        "socket(CANPROTO_DSOR) in a namespace: expected EAFNOSUPPORT, got {e:?}"
    );
    ensure!(
        a.take("canip0").is_err() && in_init("canip0"),
        "DSOR's canip0 moved out of the initial namespace"
    );
    Ok(())
}

/// A canloop device in a namespace that goes comes back to the initial
/// namespace under its name (mainline's rule for devices without link
/// ops) and works there; rmmod then removes it wherever it is.
fn netns_canloop_returns(ctx: &mut Ctx) -> TestResult {
    ctx.load_stack(&["count=2"])?;
    let ns = Ns::new()?;
    ns.take_up("can1")?;
    ensure!(!in_init("can1"), "can1 still in the initial namespace");
    drop(ns);
    wait_until(SETTLE, "can1 back from its namespace", || in_init("can1"))?;
    ctx.link_up("can1")?;
    let i = ctx.ifindex("can1")?;
    let (tx, rx) = (canraw::open(i)?, canraw::open(i)?);
    let f = sff(0x9, &[9]);
    canraw::send(&tx, &f)?;
    canraw::expect(&rx, &f, "can1 back in the initial namespace")?;
    // Moved again and removed while away.
    let ns = Ns::new()?;
    ns.take_up("can1")?;
    ctx.rmmod(Module::Loop)?;
    ensure!(
        ns.ifindex("can1").is_err(),
        "can1 survived rmmod in its namespace"
    );
    Ok(())
}

/// An Intel 82527 controller (the simulated card, link kind "can")
/// moved into a namespace:
///
/// * a socket of the initial namespace bound to it loses it (ENODEV), as
///   on unregistration;
/// * its message objects follow the sockets of the namespace it is in
///   now (DESIGN decision 7): with only a filtered socket of the
///   namespace bound to it, and none of the initial namespace, the frame
///   that filter wants still gets in;
/// * frames never cross: an initial-namespace socket bound to every
///   interface sees a frame once (can0's reception), not can1's echo;
/// * when the namespace goes, the controller comes back (`netns_refund`)
///   and works in the initial namespace;
/// * moved again, with a socket bound to it there, `rmmod` of the driver
///   unregisters it in that namespace: the socket gets ENODEV.
fn i82527_netns_move(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = super::i82527::sim2(ctx)?;
    let tx0 = canraw::open(i0)?;
    let lost = canraw::open(i1)?;
    let ns = Ns::new()?;
    let j = ns.take_up("can1")?;
    ensure!(!in_init("can1"), "can1 still in the initial namespace");
    expect_error(
        &lost,
        libc::ENODEV,
        "initial-namespace socket bound to can1",
    )?;
    drop(lost);
    let rx = ns.run(move || -> Result<CanSocket, String> {
        let s = canraw::open(j)?;
        s.set_filters(&[CanFilter::new(0x123, 0x7ff)])
            .or_fail("CAN_RAW_FILTER")?;
        Ok(s)
    })?;
    let want = sff(0x123, &[1, 2, 3]);
    canraw::send(&tx0, &sff(0x456, &[4]))?;
    canraw::send(&tx0, &want)?;
    canraw::expect(&rx, &want, "filtered socket of the namespace on can1")?;

    let init_all = canraw::open(0)?;
    let ntx = ns.raw(j)?;
    let back = sff(0x124, &[5]);
    canraw::send(&ntx, &back)?;
    canraw::expect(&tx0, &back, "can0, from can1 in the namespace")?;
    canraw::expect(&init_all, &back, "initial namespace, every interface")?;
    canraw::expect_quiet(&[
        ("initial namespace, every interface", &init_all),
        ("filtered socket of the namespace", &rx),
    ])?;

    drop((rx, ntx));
    drop(ns);
    wait_until(SETTLE, "can1 back from its namespace", || in_init("can1"))?;
    ctx.link_up("can1")?;
    let rx1 = canraw::open(ctx.ifindex("can1")?)?;
    let f = sff(0x125, &[6]);
    canraw::send(&tx0, &f)?;
    canraw::expect(&rx1, &f, "can1 back in the initial namespace")?;
    drop(rx1);

    let ns = Ns::new()?;
    let j = ns.take_up("can1")?;
    let held = ns.raw(j)?;
    ctx.rmmod(Module::I82527Sim)?;
    ensure!(
        ns.ifindex("can1").is_err(),
        "can1 survived rmmod in its namespace"
    );
    expect_error(&held, libc::ENODEV, "socket bound to can1 in the namespace")
}

/// SO_RCVTIMEO of [`canraw::RAW_RX_TIMEOUT`] on a thesis socket.
fn set_rcvtimeo(s: &ArbSocket) -> TestResult {
    s.set_rcvtimeo(canraw::RAW_RX_TIMEOUT)
        .or_fail("SO_RCVTIMEO")
        .map(|_| ())
}
