// SPDX-License-Identifier: GPL-2.0
//! System calls the CAN_RAW tests need and neither the `socketcan` crate
//! nor `rcan_uapi::raw` offers: `recvmsg` with control messages into
//! pattern-filled buffers, `SIOCGSTAMP`, `getsockopt` with a chosen
//! `optlen`, and socket options whose pointers fault; and the module and
//! interface calls the runner makes between every two tests
//! (`finit_module`, `delete_module`, `SIOCSIFFLAGS`), which on the debug
//! kernel under TCG cost a fraction of an `insmod`/`rmmod`/`ip` process
//! each; CPU pinning and a one-descriptor `poll`; `recv`, `shutdown` and
//! `close` on a descriptor number several threads share (the teardown
//! races); another process's socket (`pidfd_getfd`). Every `unsafe` block of
//! the test suite is here.

use std::ffi::CString;
use std::fs::File;
use std::io;
use std::mem::{size_of, size_of_val, zeroed};
use std::os::fd::{AsFd, AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::path::Path;
use std::ptr;

use libc::{c_int, c_void, socklen_t};

/// Byte the receive buffers are filled with before a call, so that a byte
/// the kernel did not write is recognisable.
pub const FILL: u8 = 0xAA;

/// `sizeof(struct sockaddr_can)` on x86_64: family, padding, ifindex and the
/// 16-byte union of the transport protocol addresses.
pub const SOCKADDR_CAN_LEN: usize = 24;

/// `SIOCGSTAMP` (`SIOCGSTAMP_OLD`, which is the 64-bit time one on x86_64).
const SIOCGSTAMP: libc::c_ulong = 0x8906;
/// `SIOCGSTAMPNS` (`SIOCGSTAMPNS_OLD`, likewise).
const SIOCGSTAMPNS: libc::c_ulong = 0x8907;

fn cvt(r: c_int) -> io::Result<c_int> {
    if r < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(r)
    }
}

/// What one `recvmsg` returned.
#[derive(Clone, Debug)]
pub struct Received {
    /// The return value.
    pub len: usize,
    /// The data buffer (room for a CAN FD frame): the first `len` bytes are
    /// the frame, the rest is whatever the call left there ([`FILL`] unless
    /// the kernel wrote it).
    pub data: [u8; 72],
    /// The address buffer, filled with [`FILL`] before the call.
    pub name: [u8; SOCKADDR_CAN_LEN],
    /// `msg_namelen` after the call.
    pub namelen: usize,
    /// `msg_flags` after the call.
    pub flags: c_int,
    /// `SCM_TIMESTAMP` payload, if that control message came.
    pub timeval: Option<libc::timeval>,
    /// `SCM_TIMESTAMPNS` payload, if that control message came.
    pub timespec: Option<libc::timespec>,
    /// (level, type) of every control message, in order.
    pub cmsgs: Vec<(c_int, c_int)>,
    /// The payload of every control message, in the same order.
    pub cdata: Vec<Vec<u8>>,
}

/// Control message buffer, aligned for `struct cmsghdr`.
#[repr(C, align(8))]
struct CmsgBuf([u8; 256]);

/// `recvmsg` of at most `buflen` (<= 72) bytes with `flags`, into buffers
/// filled with [`FILL`], with room for the timestamp control messages.
pub fn recvmsg(fd: impl AsFd, buflen: usize, flags: c_int) -> io::Result<Received> {
    let mut r = Received {
        len: 0,
        data: [FILL; 72],
        name: [FILL; SOCKADDR_CAN_LEN],
        namelen: 0,
        flags: 0,
        timeval: None,
        timespec: None,
        cmsgs: Vec::new(),
        cdata: Vec::new(),
    };
    let mut ctrl = CmsgBuf([0; 256]);
    let mut iov = libc::iovec {
        iov_base: r.data.as_mut_ptr().cast(),
        iov_len: buflen.min(r.data.len()),
    };
    // SAFETY: msghdr is plain old data; all-zero is a valid value.
    let mut msg: libc::msghdr = unsafe { zeroed() };
    msg.msg_name = r.name.as_mut_ptr().cast();
    msg.msg_namelen = SOCKADDR_CAN_LEN as socklen_t;
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = ctrl.0.as_mut_ptr().cast();
    msg.msg_controllen = ctrl.0.len() as _;
    // SAFETY: every pointer in msg (address, iovec and its buffer, control
    // buffer) is writable for the length given next to it and outlives the
    // call.
    let n = unsafe { libc::recvmsg(fd.as_fd().as_raw_fd(), &mut msg, flags) };
    if n < 0 {
        return Err(io::Error::last_os_error());
    }
    r.len = n as usize;
    r.namelen = msg.msg_namelen as usize;
    r.flags = msg.msg_flags;
    // msg describes the control buffer the kernel just filled;
    // CMSG_FIRSTHDR/CMSG_NXTHDR stay inside msg_controllen, and a payload's
    // bytes are copied as cmsg_len gives them, which put_cmsg never sets
    // beyond the buffer (it cuts a message that does not fit).
    // SAFETY: that, and each payload is read unaligned only when complete.
    unsafe {
        let mut c = libc::CMSG_FIRSTHDR(&msg);
        while !c.is_null() {
            let (level, ty, len) = ((*c).cmsg_level, (*c).cmsg_type, (*c).cmsg_len as usize);
            r.cmsgs.push((level, ty));
            let data = libc::CMSG_DATA(c);
            let hdr = libc::CMSG_LEN(0) as usize;
            r.cdata.push(
                std::slice::from_raw_parts(data.cast_const(), len.saturating_sub(hdr)).to_vec(),
            );
            let tv_len = libc::CMSG_LEN(size_of::<libc::timeval>() as u32) as usize;
            let ts_len = libc::CMSG_LEN(size_of::<libc::timespec>() as u32) as usize;
            if level == libc::SOL_SOCKET && ty == libc::SCM_TIMESTAMP && len >= tv_len {
                r.timeval = Some(ptr::read_unaligned(data.cast()));
            }
            if level == libc::SOL_SOCKET && ty == libc::SCM_TIMESTAMPNS && len >= ts_len {
                r.timespec = Some(ptr::read_unaligned(data.cast()));
            }
            c = libc::CMSG_NXTHDR(&msg, c);
        }
    }
    Ok(r)
}

/// What [`recvmsg_into`] returned: return value, `msg_namelen`,
/// `msg_controllen`, `msg_flags`.
#[derive(Clone, Copy, Debug)]
pub struct RecvLens {
    pub len: usize,
    pub namelen: usize,
    pub controllen: usize,
    pub flags: c_int,
}

/// `recvmsg` into the caller's buffers as they are (the caller poisons
/// them): `data`, `name` (its whole length as `msg_namelen`) and
/// `control` (its whole length as `msg_controllen`, 8-byte aligned by
/// the caller's use of a `u64` array).
pub fn recvmsg_into(
    fd: impl AsFd,
    data: &mut [u8],
    name: &mut [u8],
    control: &mut [u64],
    flags: c_int,
) -> io::Result<RecvLens> {
    let mut iov = libc::iovec {
        iov_base: data.as_mut_ptr().cast(),
        iov_len: data.len(),
    };
    // SAFETY: msghdr is plain old data; all-zero is a valid value.
    let mut msg: libc::msghdr = unsafe { zeroed() };
    msg.msg_name = name.as_mut_ptr().cast();
    msg.msg_namelen = name.len() as socklen_t;
    msg.msg_iov = &mut iov;
    msg.msg_iovlen = 1;
    msg.msg_control = control.as_mut_ptr().cast();
    msg.msg_controllen = size_of_val(control) as _;
    // SAFETY: every pointer in msg (address, iovec and its buffer, control
    // buffer) is writable for the length given next to it and outlives the
    // call.
    let n = unsafe { libc::recvmsg(fd.as_fd().as_raw_fd(), &mut msg, flags) };
    if n < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(RecvLens {
        len: n as usize,
        namelen: msg.msg_namelen as usize,
        controllen: msg.msg_controllen as usize,
        flags: msg.msg_flags,
    })
}

/// `ioctl(fd, SIOCGSTAMP)`: the receive time of the last frame read.
pub fn siocgstamp(fd: impl AsFd) -> io::Result<libc::timeval> {
    let mut tv = libc::timeval {
        tv_sec: 0,
        tv_usec: 0,
    };
    // SAFETY: SIOCGSTAMP writes one struct timeval to the pointer given,
    // which is `tv`, live and writable.
    cvt(unsafe { libc::ioctl(fd.as_fd().as_raw_fd(), SIOCGSTAMP, &mut tv) })?;
    Ok(tv)
}

/// `ioctl(fd, SIOCGSTAMPNS)`: the same as [`siocgstamp`] in nanoseconds.
pub fn siocgstampns(fd: impl AsFd) -> io::Result<libc::timespec> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: SIOCGSTAMPNS writes one struct timespec to the pointer given,
    // which is `ts`, live and writable.
    cvt(unsafe { libc::ioctl(fd.as_fd().as_raw_fd(), SIOCGSTAMPNS, &mut ts) })?;
    Ok(ts)
}

/// `getsockopt` into `buf` with `optlen` set to `optlen` beforehand, which
/// may differ from `buf.len()` (but is never larger). Returns the result
/// and the `optlen` the kernel left, also on failure (`ERANGE` reports the
/// length needed there).
pub fn getsockopt_len(
    fd: impl AsFd,
    level: c_int,
    name: c_int,
    buf: &mut [u8],
    optlen: c_int,
) -> (io::Result<()>, c_int) {
    assert!(optlen < 0 || optlen as usize <= buf.len());
    let mut len = optlen as socklen_t;
    // SAFETY: `buf` is writable for at least `optlen` bytes when that is
    // not negative; a negative optlen must be refused before any write, and
    // even then the pointer is valid for `buf.len()` bytes.
    let r = cvt(unsafe {
        libc::getsockopt(
            fd.as_fd().as_raw_fd(),
            level,
            name,
            buf.as_mut_ptr().cast(),
            &mut len,
        )
    });
    (r.map(drop), len as c_int)
}

/// One mapped, inaccessible page: any kernel access to it faults.
struct NoAccessPage(*mut c_void);

const PAGE: usize = 4096;

impl NoAccessPage {
    fn new() -> io::Result<Self> {
        // SAFETY: an anonymous private mapping at a kernel-chosen address
        // cannot alias any existing Rust object.
        let addr = unsafe {
            libc::mmap(
                ptr::null_mut(),
                PAGE,
                libc::PROT_NONE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            )
        };
        if addr == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        Ok(Self(addr))
    }
}

impl Drop for NoAccessPage {
    fn drop(&mut self) {
        // SAFETY: unmaps exactly the mapping made in new(); nothing points
        // into it.
        unsafe { libc::munmap(self.0, PAGE) };
    }
}

/// `setsockopt` whose value (`len` bytes) lies in an inaccessible page.
pub fn setsockopt_fault(fd: impl AsFd, level: c_int, name: c_int, len: usize) -> io::Result<()> {
    let page = NoAccessPage::new()?;
    // SAFETY: the value pointer is in a PROT_NONE page owned by `page`; the
    // kernel can only fail to read it.
    cvt(unsafe {
        libc::setsockopt(
            fd.as_fd().as_raw_fd(),
            level,
            name,
            page.0,
            len.min(PAGE) as socklen_t,
        )
    })
    .map(drop)
}

/// `getsockopt` whose value buffer (`len` bytes) is inaccessible.
pub fn getsockopt_val_fault(
    fd: impl AsFd,
    level: c_int,
    name: c_int,
    len: usize,
) -> io::Result<()> {
    let page = NoAccessPage::new()?;
    let mut optlen = len.min(PAGE) as socklen_t;
    // SAFETY: the value pointer is in a PROT_NONE page owned by `page`, so
    // no memory of ours changes; `optlen` is live and writable.
    cvt(unsafe { libc::getsockopt(fd.as_fd().as_raw_fd(), level, name, page.0, &mut optlen) })
        .map(drop)
}

/// `getsockopt` whose `optlen` pointer is inaccessible.
pub fn getsockopt_len_fault(fd: impl AsFd, level: c_int, name: c_int) -> io::Result<()> {
    let page = NoAccessPage::new()?;
    let mut val = [0u8; 64];
    // SAFETY: `val` is writable; the optlen pointer is in a PROT_NONE page
    // owned by `page`, which the kernel can only fail to access.
    cvt(unsafe {
        libc::getsockopt(
            fd.as_fd().as_raw_fd(),
            level,
            name,
            val.as_mut_ptr().cast(),
            page.0.cast(),
        )
    })
    .map(drop)
}

/// `write` of `len` bytes from an inaccessible buffer.
pub fn write_fault(fd: impl AsFd, len: usize) -> io::Result<usize> {
    let page = NoAccessPage::new()?;
    // SAFETY: the buffer is in a PROT_NONE page owned by `page`; the kernel
    // can only fail to read it.
    let n = unsafe { libc::write(fd.as_fd().as_raw_fd(), page.0, len.min(PAGE)) };
    usize::try_from(n).map_err(|_| io::Error::last_os_error())
}

/// `SO_RCVBUFFORCE` (root): a receive buffer of `bytes`, beyond
/// `rmem_max`.
pub fn set_rcvbufforce(fd: impl AsFd, bytes: c_int) -> io::Result<()> {
    // SAFETY: setsockopt with a pointer to a live int of the given size.
    let rc = unsafe {
        libc::setsockopt(
            fd.as_fd().as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUFFORCE,
            (&bytes as *const c_int).cast(),
            std::mem::size_of::<c_int>() as libc::socklen_t,
        )
    };
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// A duplicate of descriptor `fd` of process `pid` (`pidfd_open` and
/// `pidfd_getfd`, root): the same open file, so a socket option set on
/// it is set on the other process's socket.
pub fn fd_of_process(pid: u32, fd: RawFd) -> io::Result<OwnedFd> {
    let pid = libc::pid_t::try_from(pid).map_err(|_| io::Error::from_raw_os_error(libc::ESRCH))?;
    // SAFETY: pidfd_open(2) takes a number and flags, no memory.
    let pidfd = cvt(unsafe { libc::syscall(libc::SYS_pidfd_open, pid, 0) } as c_int)?;
    // SAFETY: the kernel just returned `pidfd`, a new descriptor nobody
    // else owns.
    let pidfd = unsafe { OwnedFd::from_raw_fd(pidfd) };
    // SAFETY: pidfd_getfd(2) takes numbers and flags, no memory.
    let dup =
        cvt(unsafe { libc::syscall(libc::SYS_pidfd_getfd, pidfd.as_raw_fd(), fd, 0) } as c_int)?;
    // SAFETY: as above, a new descriptor owned by nobody else.
    Ok(unsafe { OwnedFd::from_raw_fd(dup) })
}

fn cstring(s: &str) -> io::Result<CString> {
    CString::new(s).map_err(|_| io::Error::from_raw_os_error(libc::EINVAL))
}

/// `insmod KO PARAMS...`: `finit_module(2)` with the parameters joined by
/// spaces, as insmod passes them.
pub fn finit_module(ko: &Path, params: &[&str]) -> io::Result<()> {
    let file = File::open(ko)?;
    let params = cstring(&params.join(" "))?;
    // SAFETY: `file` is an open descriptor and `params` a NUL-terminated
    // string, both alive for the call; flags 0.
    let r = unsafe {
        libc::syscall(
            libc::SYS_finit_module,
            file.as_raw_fd(),
            params.as_ptr(),
            0 as c_int,
        )
    };
    if r < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// `rmmod NAME`: `delete_module(2)` with `O_NONBLOCK`, as rmmod calls it
/// (fails with EWOULDBLOCK while the module is in use).
pub fn delete_module(name: &str) -> io::Result<()> {
    let name = cstring(name)?;
    // SAFETY: `name` is a NUL-terminated string alive for the call.
    let r = unsafe { libc::syscall(libc::SYS_delete_module, name.as_ptr(), libc::O_NONBLOCK) };
    if r < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

/// `socket(family, ty, proto)` with `SOCK_CLOEXEC`, owned.
pub fn socket(family: c_int, ty: c_int, proto: c_int) -> io::Result<OwnedFd> {
    // SAFETY: plain socket(2) call; the result is checked before use.
    let fd = cvt(unsafe { libc::socket(family, ty | libc::SOCK_CLOEXEC, proto) })?;
    // SAFETY: `fd` was just returned by socket(2) and is owned by nobody else.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// `ip link set DEV up` or `down`: `SIOCGIFFLAGS`, then `SIOCSIFFLAGS`
/// with `IFF_UP` set or cleared, through an AF_INET datagram socket.
pub fn set_link_up(dev: &str, up: bool) -> io::Result<()> {
    if dev.is_empty() || dev.len() >= libc::IFNAMSIZ {
        return Err(io::Error::from_raw_os_error(libc::ENODEV));
    }
    // SAFETY: plain socket(2) call; the result is checked before use.
    let fd = cvt(unsafe { libc::socket(libc::AF_INET, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0) })?;
    // SAFETY: `fd` was just returned by socket(2) and is owned by nobody else.
    let sock = unsafe { OwnedFd::from_raw_fd(fd) };
    // SAFETY: all-zero bytes are a valid `ifreq` (a name and a union of
    // plain integers and pointers).
    let mut ifr: libc::ifreq = unsafe { zeroed() };
    for (d, s) in ifr.ifr_name.iter_mut().zip(dev.bytes()) {
        *d = s as libc::c_char;
    }
    // SAFETY: `ifr` is a valid, writable `ifreq` with a NUL-terminated name
    // (the buffer is zeroed and the name shorter than IFNAMSIZ).
    cvt(unsafe { libc::ioctl(sock.as_raw_fd(), libc::SIOCGIFFLAGS, &mut ifr) })?;
    // SAFETY: SIOCGIFFLAGS filled in `ifru_flags`, the union member read
    // and written here.
    unsafe {
        let flags = &mut ifr.ifr_ifru.ifru_flags;
        if up {
            *flags |= libc::IFF_UP as libc::c_short;
        } else {
            *flags &= !(libc::IFF_UP as libc::c_short);
        }
    }
    // SAFETY: as for SIOCGIFFLAGS; the kernel only reads `ifr`.
    cvt(unsafe { libc::ioctl(sock.as_raw_fd(), libc::SIOCSIFFLAGS, &ifr) })?;
    Ok(())
}

/// `ip link set DEV mtu MTU` (`SIOCSIFMTU` through an AF_INET datagram
/// socket): a CAN interface takes it only while down (16 classic CAN, 72
/// CAN FD).
pub fn set_mtu(dev: &str, mtu: i32) -> io::Result<()> {
    if dev.is_empty() || dev.len() >= libc::IFNAMSIZ {
        return Err(io::Error::from_raw_os_error(libc::ENODEV));
    }
    // SAFETY: plain socket(2) call; the result is checked before use.
    let fd = cvt(unsafe { libc::socket(libc::AF_INET, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0) })?;
    // SAFETY: `fd` was just returned by socket(2) and is owned by nobody else.
    let sock = unsafe { OwnedFd::from_raw_fd(fd) };
    // SAFETY: all-zero bytes are a valid `ifreq` (a name and a union of
    // plain integers and pointers).
    let mut ifr: libc::ifreq = unsafe { zeroed() };
    for (d, s) in ifr.ifr_name.iter_mut().zip(dev.bytes()) {
        *d = s as libc::c_char;
    }
    ifr.ifr_ifru.ifru_mtu = mtu;
    // SAFETY: `ifr` is a valid `ifreq` with a NUL-terminated name (the
    // buffer is zeroed and the name shorter than IFNAMSIZ) and the MTU in
    // `ifru_mtu`; the kernel only reads it.
    cvt(unsafe { libc::ioctl(sock.as_raw_fd(), libc::SIOCSIFMTU, &ifr) })?;
    Ok(())
}

/// `recv(fd, buf, flags)` on a descriptor *number* that other threads
/// share and one of them may close meanwhile (the teardown tests: a thread
/// blocked in `recv` while another closes the socket). A number that was
/// closed gives `EBADF`; the caller must not open descriptors while such
/// calls may still start, or the number may name another file by then.
pub fn recv_fd(fd: RawFd, buf: &mut [u8], flags: c_int) -> io::Result<usize> {
    // SAFETY: `buf` is writable for `buf.len()` bytes for the call; a
    // stale or closed descriptor number can only make the call fail.
    let n = unsafe { libc::recv(fd, buf.as_mut_ptr().cast(), buf.len(), flags) };
    usize::try_from(n).map_err(|_| io::Error::last_os_error())
}

/// `shutdown(fd, how)` on a shared descriptor number (see [`recv_fd`]).
pub fn shutdown_fd(fd: RawFd, how: c_int) -> io::Result<()> {
    // SAFETY: no memory is passed; a bad number only fails.
    cvt(unsafe { libc::shutdown(fd, how) }).map(drop)
}

/// `close(fd)` of a descriptor number taken out of its owner with
/// `into_raw_fd`, while other threads may be inside calls on it (see
/// [`recv_fd`]). Closing it again, or a number still owned elsewhere,
/// would close whatever file has that number then: callers close each
/// number they took once.
pub fn close_fd(fd: RawFd) -> io::Result<()> {
    // SAFETY: no memory is passed; the caller owns the number (it came
    // from `into_raw_fd`) and closes it once.
    cvt(unsafe { libc::close(fd) }).map(drop)
}

/// Pins the calling thread to CPU 0 (`sched_setaffinity`).
pub fn pin_to_cpu0() -> io::Result<()> {
    // SAFETY: an all-zero cpu_set_t is empty; CPU_SET and
    // sched_setaffinity only touch the set we own.
    let rc = unsafe {
        let mut set: libc::cpu_set_t = zeroed();
        libc::CPU_SET(0, &mut set);
        libc::sched_setaffinity(0, size_of::<libc::cpu_set_t>(), &set)
    };
    cvt(rc).map(drop)
}

/// The calling thread's CPU affinity as it was before [`pin_to_cpu0_for`]
/// pinned it; restored when dropped.
pub struct Pinned(libc::cpu_set_t);

/// Pins the calling thread to CPU 0 until the returned guard is dropped,
/// which puts its former affinity back: a test that pins does not leave
/// every later test of the run (and the threads and programs they start,
/// which inherit it) on one CPU.
pub fn pin_to_cpu0_for() -> io::Result<Pinned> {
    // SAFETY: an all-zero cpu_set_t is a valid (empty) set; the call
    // fills the one we own.
    let mut old: libc::cpu_set_t = unsafe { zeroed() };
    // SAFETY: `old` is a writable cpu_set_t of the size given.
    cvt(unsafe { libc::sched_getaffinity(0, size_of::<libc::cpu_set_t>(), &mut old) })?;
    pin_to_cpu0()?;
    Ok(Pinned(old))
}

impl Drop for Pinned {
    fn drop(&mut self) {
        // SAFETY: the set we saved, of the size given. Failure leaves the
        // thread pinned: nothing better to do in a destructor.
        let _ = unsafe { libc::sched_setaffinity(0, size_of::<libc::cpu_set_t>(), &self.0) };
    }
}

/// The CPUs the calling thread may run on (`sched_getaffinity`).
pub fn affinity() -> io::Result<Vec<usize>> {
    // SAFETY: an all-zero cpu_set_t is a valid (empty) set; the call
    // fills the one we own, of the size given.
    let mut set: libc::cpu_set_t = unsafe { zeroed() };
    // SAFETY: as above.
    cvt(unsafe { libc::sched_getaffinity(0, size_of::<libc::cpu_set_t>(), &mut set) })?;
    // SAFETY: CPU_ISSET reads the set we own, within CPU_SETSIZE.
    Ok((0..libc::CPU_SETSIZE as usize)
        .filter(|&c| unsafe { libc::CPU_ISSET(c, &set) })
        .collect())
}

/// Lets the calling thread run on `cpus` (`sched_setaffinity`).
pub fn set_affinity(cpus: &[usize]) -> io::Result<()> {
    // SAFETY: an all-zero cpu_set_t is a valid (empty) set.
    let mut set: libc::cpu_set_t = unsafe { zeroed() };
    for &c in cpus.iter().filter(|&&c| c < libc::CPU_SETSIZE as usize) {
        // SAFETY: CPU_SET writes the set we own, within CPU_SETSIZE.
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    // SAFETY: the set we own, of the size given.
    cvt(unsafe { libc::sched_setaffinity(0, size_of::<libc::cpu_set_t>(), &set) }).map(drop)
}

/// `poll` on one descriptor for `events`, up to `timeout_ms`; returns
/// `revents` (0 on timeout).
pub fn poll_one(
    fd: impl AsFd,
    events: libc::c_short,
    timeout_ms: c_int,
) -> io::Result<libc::c_short> {
    let mut pfd = libc::pollfd {
        fd: fd.as_fd().as_raw_fd(),
        events,
        revents: 0,
    };
    // SAFETY: one valid, writable pollfd for the call.
    cvt(unsafe { libc::poll(&mut pfd, 1, timeout_ms) })?;
    Ok(pfd.revents)
}

#[cfg(test)]
mod tests {
    //! The helpers against an AF_UNIX datagram pair, which any host has.
    use super::*;
    use std::os::unix::net::UnixDatagram;

    #[test]
    fn recvmsg_fills_and_reports() {
        let (a, b) = UnixDatagram::pair().unwrap();
        a.send(&[1, 2, 3]).unwrap();
        let r = recvmsg(&b, 16, 0).unwrap();
        assert_eq!(r.len, 3);
        assert_eq!(&r.data[..4], &[1, 2, 3, FILL]);
        assert!(r.cmsgs.is_empty());
        assert!(r.timeval.is_none());
    }

    #[test]
    fn faults() {
        let (a, _b) = UnixDatagram::pair().unwrap();
        let e = write_fault(&a, 16).unwrap_err();
        assert_eq!(e.raw_os_error(), Some(libc::EFAULT));
        let e = setsockopt_fault(&a, libc::SOL_SOCKET, libc::SO_RCVBUF, 4).unwrap_err();
        assert_eq!(e.raw_os_error(), Some(libc::EFAULT));
        let e = getsockopt_len_fault(&a, libc::SOL_SOCKET, libc::SO_RCVBUF).unwrap_err();
        assert_eq!(e.raw_os_error(), Some(libc::EFAULT));
    }
}

/// The calling thread's id (what `/proc/self/task/` names it by).
pub fn gettid() -> i32 {
    // SAFETY: gettid(2) has no arguments and cannot fail.
    unsafe { libc::gettid() }
}

extern "C" fn on_sigusr1(_: c_int) {}

/// Installs an empty `SIGUSR1` handler without `SA_RESTART`, so that the
/// signal ends a blocking call with `EINTR` instead of restarting it (what
/// a program that handles signals sees), and nothing else happens.
pub fn catch_sigusr1() -> io::Result<()> {
    // SAFETY: a zeroed sigaction is valid (empty mask, no flags); the
    // handler is a plain `extern "C" fn(c_int)` that touches nothing, so
    // it is async-signal-safe; the old action is not asked for.
    let rc = unsafe {
        let mut sa: libc::sigaction = zeroed();
        sa.sa_sigaction = on_sigusr1 as extern "C" fn(c_int) as libc::sighandler_t;
        libc::sigemptyset(&mut sa.sa_mask);
        libc::sigaction(libc::SIGUSR1, &sa, std::ptr::null_mut())
    };
    cvt(rc).map(drop)
}

/// Sends `SIGUSR1` to process 1 (the VM's init; see
/// tools/testing/rcan/vm/init), ignoring failure.
pub fn sigusr1_to_init() {
    // SAFETY: no memory is passed.
    unsafe { libc::kill(1, libc::SIGUSR1) };
}

/// Sends `SIGUSR1` to thread `tid` of this process (`tgkill`); see
/// [`catch_sigusr1`].
pub fn sigusr1_to(tid: i32) -> io::Result<()> {
    // SAFETY: no memory is passed; a thread id that is gone gives ESRCH.
    cvt(unsafe { libc::syscall(libc::SYS_tgkill, libc::getpid(), tid, libc::SIGUSR1) } as c_int)
        .map(drop)
}
