// SPDX-License-Identifier: GPL-2.0
//! Assertion helpers shared by the test cases: frames, expected errnos,
//! "receive exactly this" and "receive nothing" checks.

use std::fmt;
use std::io;
use std::thread;
use std::time::{Duration, Instant};

use rcan_uapi::{arb_ext, arb_is_rtr, arb_std, format_frame, ArbSocket, AF_CAN};

/// Outcome of one test or step.
pub type TestResult = Result<(), String>;

/// Receive timeout of every test socket: long enough for a loaded VM,
/// short enough that a missing frame fails quickly instead of hanging.
pub const RX_TIMEOUT: Duration = Duration::from_secs(2);

/// Time given to the stack to deliver a frame that must *not* arrive,
/// before checking with `MSG_DONTWAIT` that none did.
pub const QUIET: Duration = Duration::from_millis(200);

/// Fails the current test with a formatted message unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($fmt:tt)+) => {
        if !$cond {
            return Err(format!($($fmt)+));
        }
    };
}
pub(crate) use ensure;

/// Adds context to an `io::Result`, turning it into a test failure.
pub trait OrFail<T> {
    /// `what: error` on failure.
    fn or_fail(self, what: impl fmt::Display) -> Result<T, String>;
}

impl<T> OrFail<T> for io::Result<T> {
    fn or_fail(self, what: impl fmt::Display) -> Result<T, String> {
        self.map_err(|e| format!("{what}: {}", errno_text(&e)))
    }
}

/// Symbolic name of the errnos the tests deal with.
pub fn errno_name(e: i32) -> String {
    let name = match e {
        libc::EPERM => "EPERM",
        libc::ENOENT => "ENOENT",
        libc::EINTR => "EINTR",
        libc::EIO => "EIO",
        libc::ENXIO => "ENXIO",
        libc::EBADF => "EBADF",
        libc::EAGAIN => "EAGAIN",
        libc::ENOMEM => "ENOMEM",
        libc::EACCES => "EACCES",
        libc::EFAULT => "EFAULT",
        libc::EBUSY => "EBUSY",
        libc::EEXIST => "EEXIST",
        libc::ENODEV => "ENODEV",
        libc::EINVAL => "EINVAL",
        libc::ENOSPC => "ENOSPC",
        libc::EPIPE => "EPIPE",
        libc::ENOTSOCK => "ENOTSOCK",
        libc::EDESTADDRREQ => "EDESTADDRREQ",
        libc::EMSGSIZE => "EMSGSIZE",
        libc::EPROTOTYPE => "EPROTOTYPE",
        libc::ENOPROTOOPT => "ENOPROTOOPT",
        libc::EPROTONOSUPPORT => "EPROTONOSUPPORT",
        libc::ESOCKTNOSUPPORT => "ESOCKTNOSUPPORT",
        libc::EOPNOTSUPP => "EOPNOTSUPP",
        libc::EAFNOSUPPORT => "EAFNOSUPPORT",
        libc::EADDRINUSE => "EADDRINUSE",
        libc::EADDRNOTAVAIL => "EADDRNOTAVAIL",
        libc::ENETDOWN => "ENETDOWN",
        libc::ENETUNREACH => "ENETUNREACH",
        libc::ENOBUFS => "ENOBUFS",
        libc::EISCONN => "EISCONN",
        libc::ENOTCONN => "ENOTCONN",
        libc::ETIMEDOUT => "ETIMEDOUT",
        libc::ECONNREFUSED => "ECONNREFUSED",
        libc::EBADMSG => "EBADMSG",
        libc::ECOMM => "ECOMM",
        libc::EILSEQ => "EILSEQ",
        _ => return format!("errno {e}"),
    };
    name.to_string()
}

/// `EINVAL (Invalid argument)` style rendering of an `io::Error`.
pub fn errno_text(e: &io::Error) -> String {
    match e.raw_os_error() {
        Some(n) => format!("{} ({e})", errno_name(n)),
        None => e.to_string(),
    }
}

/// Checks that `r` failed with `want`.
pub fn expect_errno<T: fmt::Debug>(r: io::Result<T>, want: i32, what: &str) -> TestResult {
    match r {
        Ok(v) => Err(format!(
            "{what}: succeeded ({v:?}), expected {}",
            errno_name(want)
        )),
        Err(e) if e.raw_os_error() == Some(want) => Ok(()),
        Err(e) => Err(format!(
            "{what}: got {}, expected {}",
            errno_text(&e),
            errno_name(want)
        )),
    }
}

/// The errno of an `io::Error`, or 0.
pub fn errno_of(e: &io::Error) -> i32 {
    e.raw_os_error().unwrap_or(0)
}

/// A CAN frame as seen through the socket API: arbitration field and data.
/// A remote frame's `data` is `dlc` zero bytes (what `recv` returns).
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Frame {
    /// Arbitration field.
    pub arb: u32,
    /// Data field; its length is the DLC.
    pub data: Vec<u8>,
}

impl Frame {
    /// A standard data frame.
    pub fn std(id: u32, data: &[u8]) -> Self {
        Self {
            arb: arb_std(id, false),
            data: data.to_vec(),
        }
    }

    /// An extended data frame.
    pub fn ext(id: u32, data: &[u8]) -> Self {
        Self {
            arb: arb_ext(id, false),
            data: data.to_vec(),
        }
    }

    /// A standard remote frame with DLC `dlc`.
    pub fn remote_std(id: u32, dlc: usize) -> Self {
        Self {
            arb: arb_std(id, true),
            data: vec![0; dlc],
        }
    }

    /// An extended remote frame with DLC `dlc`.
    pub fn remote_ext(id: u32, dlc: usize) -> Self {
        Self {
            arb: arb_ext(id, true),
            data: vec![0; dlc],
        }
    }

    /// A data frame with arbitration field `arb`.
    pub fn with_arb(arb: u32, data: &[u8]) -> Self {
        Self {
            arb,
            data: data.to_vec(),
        }
    }

    /// Whether this is a remote frame.
    pub fn is_remote(&self) -> bool {
        arb_is_rtr(self.arb)
    }

    /// The bytes handed to `sendto`: the data, or for a remote frame `dlc`
    /// bytes of 0x5A, which the stack must ignore.
    pub fn tx_bytes(&self) -> Vec<u8> {
        if self.is_remote() {
            vec![0x5A; self.data.len()]
        } else {
            self.data.clone()
        }
    }

    /// `sendto` on `ifindex`; checks that the whole DLC was accepted.
    pub fn send(&self, sock: &ArbSocket, ifindex: u32) -> TestResult {
        let n = sock
            .send_to(&self.tx_bytes(), self.arb, ifindex)
            .or_fail(format_args!("sendto {self} on ifindex {ifindex}"))?;
        ensure!(
            n == self.data.len(),
            "sendto {self}: returned {n}, expected {}",
            self.data.len()
        );
        Ok(())
    }
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(format_frame("", self.arb, &self.data).trim_start())
    }
}

/// A received frame and the interface it arrived on.
#[derive(Clone, PartialEq, Eq, Debug)]
pub struct Rx {
    /// The frame.
    pub frame: Frame,
    /// `ifindex` of the source address.
    pub ifindex: u32,
}

/// Receives one frame with `recvfrom` (blocking up to the socket's
/// timeout), checking the invariant parts of the source address.
pub fn recv_frame(sock: &ArbSocket) -> Result<Rx, String> {
    let mut buf = [0xAAu8; 16];
    let (n, addr) = sock.recv_from(&mut buf).or_fail("recvfrom")?;
    ensure!(n <= 8, "recvfrom returned {n} bytes (> 8)");
    ensure!(
        addr.family == AF_CAN,
        "recvfrom address family {} (expected AF_CAN)",
        addr.family
    );
    ensure!(
        addr.mask == 0,
        "recvfrom address mask {:#x} (expected 0)",
        addr.mask
    );
    let frame = Frame::with_arb(addr.arb, &buf[..n]);
    if frame.is_remote() {
        ensure!(
            frame.data.iter().all(|&b| b == 0),
            "remote frame {frame}: data bytes not zero: {:02X?}",
            frame.data
        );
    }
    Ok(Rx {
        frame,
        ifindex: addr.ifindex,
    })
}

/// Receives one frame and checks that it is `want`, from `ifindex`.
pub fn expect_frame(sock: &ArbSocket, want: &Frame, ifindex: u32) -> TestResult {
    let rx = recv_frame(sock).map_err(|e| format!("waiting for {want}: {e}"))?;
    ensure!(
        rx.frame == *want && rx.ifindex == ifindex,
        "expected {want} from ifindex {ifindex}, got {} from ifindex {}",
        rx.frame,
        rx.ifindex
    );
    Ok(())
}

/// Receives `want.len()` frames and checks them in order.
pub fn expect_frames(sock: &ArbSocket, want: &[Frame], ifindex: u32) -> TestResult {
    want.iter().try_for_each(|f| expect_frame(sock, f, ifindex))
}

/// Waits [`QUIET`], then checks that none of `socks` has a frame queued.
pub fn expect_none(socks: &[&ArbSocket]) -> TestResult {
    // Not synchronisation: a negative check ("nothing arrives"), which has
    // no event to wait for; the window only gives a wrong frame the chance
    // to show up.
    thread::sleep(QUIET);
    for (i, s) in socks.iter().enumerate() {
        let mut buf = [0u8; 16];
        match s.recv_from_flags(&mut buf, libc::MSG_DONTWAIT) {
            Ok((n, a)) => {
                return Err(format!(
                    "socket #{i}: unexpected frame {} from ifindex {}",
                    Frame::with_arb(a.arb, &buf[..n.min(8)]),
                    a.ifindex
                ))
            }
            Err(e) if errno_of(&e) == libc::EAGAIN => {}
            Err(e) => {
                return Err(format!(
                    "socket #{i}: recv MSG_DONTWAIT: {}",
                    errno_text(&e)
                ))
            }
        }
    }
    Ok(())
}

/// Deadline of [`wait_for`] for conditions that come as soon as the
/// kernel (or a helper process) has done its work: long enough for the
/// KASAN/lockdep kernel under emulation on a loaded host; a deadline only
/// ends a wait for something that never comes, it never paces a test.
pub const SETTLE: Duration = Duration::from_secs(60);

/// Polls `f` every 20 ms until it returns `Some`, or fails after `limit`
/// with the last value `f` described.
pub fn wait_for<T>(
    limit: Duration,
    what: &str,
    mut f: impl FnMut() -> Result<Option<T>, String>,
) -> Result<T, String> {
    let start = Instant::now();
    loop {
        if let Some(v) = f()? {
            return Ok(v);
        }
        if start.elapsed() > limit {
            return Err(format!("timed out after {limit:?} waiting for {what}"));
        }
        // The poll interval, not synchronisation: the condition is
        // checked again after it.
        thread::sleep(Duration::from_millis(20));
    }
}

/// [`wait_for`] a condition that has no value: polls `cond` until it
/// holds, failing after `limit`.
pub fn wait_until(limit: Duration, what: &str, mut cond: impl FnMut() -> bool) -> TestResult {
    wait_for(limit, what, || Ok(cond().then_some(())))
}

/// The system call thread `tid` of this process is blocked in, from
/// `/proc/self/task/TID/syscall`: `None` while it runs (or has ended).
pub fn blocked_syscall(tid: i32) -> Option<i64> {
    let t = std::fs::read_to_string(format!("/proc/self/task/{tid}/syscall")).ok()?;
    t.split_whitespace().next()?.parse().ok()
}

/// The system calls a receive blocks in: `read`, `recv`/`recvfrom`
/// (glibc's `recv` is `recvfrom`), `recvmsg`.
pub const RECV_SYSCALLS: [i64; 3] = [libc::SYS_read, libc::SYS_recvfrom, libc::SYS_recvmsg];

/// Waits until thread `tid` (see [`crate::sys::gettid`]; 0: not known
/// yet) sleeps in one of the system calls `nrs` (e.g. `libc::SYS_read`):
/// it has entered the kernel and blocks there, the state a test that
/// wants "a reader blocked in recv" needs before it acts. (A woken thread
/// reads "running" there until it blocks again.)
pub fn wait_blocked(tid: &std::sync::atomic::AtomicI32, nrs: &[i64], what: &str) -> TestResult {
    wait_until(SETTLE, what, || {
        let t = tid.load(std::sync::atomic::Ordering::SeqCst);
        t != 0 && blocked_syscall(t).is_some_and(|nr| nrs.contains(&nr))
    })
}

/// The `i`-th frame of a reproducible test sequence: alternating standard
/// and extended data frames, DLC `i % 9`, data derived from `i`.
pub fn seq_frame(i: usize) -> Frame {
    let dlc = i % 9;
    let data: Vec<u8> = (0..dlc)
        .map(|j| (i.wrapping_mul(7) ^ (j << 4) ^ (i >> 8)) as u8)
        .collect();
    let n = i as u32;
    if i.is_multiple_of(2) {
        Frame::std(n.wrapping_mul(5) & 0x7FF, &data)
    } else {
        Frame::ext(n.wrapping_mul(2_654_435_761) & 0x1FFF_FFFF, &data)
    }
}

/// Whether `got` is `sent` with some elements left out (order kept).
pub fn is_subsequence(got: &[Frame], sent: &[Frame]) -> bool {
    let mut it = sent.iter();
    got.iter().all(|g| it.any(|s| s == g))
}

/// Calls `f` when dropped: used to stop helper threads on every exit path.
pub struct OnDrop<F: FnMut()>(pub F);

impl<F: FnMut()> Drop for OnDrop<F> {
    fn drop(&mut self) {
        (self.0)();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subsequence() {
        let s: Vec<Frame> = (0..10).map(seq_frame).collect();
        assert!(is_subsequence(&s, &s));
        assert!(is_subsequence(&[s[1].clone(), s[7].clone()], &s));
        assert!(!is_subsequence(&[s[7].clone(), s[1].clone()], &s));
        assert!(is_subsequence(&[], &s));
    }

    #[test]
    fn sequence_frames_are_valid() {
        for i in 0..2000 {
            let f = seq_frame(i);
            assert_eq!(f.data.len(), i % 9);
            assert_eq!(f.arb & 1, 0);
            assert!(!f.is_remote());
        }
        assert_ne!(seq_frame(9), seq_frame(11));
    }

    #[test]
    fn display() {
        assert_eq!(
            Frame::std(0x123, &[1, 2]).to_string(),
            "STD 123  [2]  01 02"
        );
        assert_eq!(
            Frame::remote_ext(5, 3).to_string(),
            "EXT 00000005  [3]  remote"
        );
        assert_eq!(errno_name(libc::ENODEV), "ENODEV");
    }
}
