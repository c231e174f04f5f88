// SPDX-License-Identifier: GPL-2.0
//! The system calls the fuzzer makes, as safe functions over slices: every
//! buffer the kernel may write is a Rust buffer at least as long as the
//! length passed, so no call can corrupt the fuzzer's memory whatever the
//! kernel does with it (except [`getsockopt_guarded`], which gives the
//! kernel a page of its own with a guard page behind). Every `unsafe`
//! block of the crate is here. Errors are the raw errno.

use std::ffi::CString;
use std::fs::File;
use std::mem::zeroed;
use std::os::fd::AsRawFd;
use std::path::Path;
use std::ptr;

use libc::{c_int, c_void, socklen_t};

/// A call's result: the return value, or errno.
pub type Res<T> = Result<T, c_int>;

fn errno() -> c_int {
    std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
}

fn cvt(r: isize) -> Res<usize> {
    if r < 0 {
        Err(errno())
    } else {
        Ok(r as usize)
    }
}

/// `socket(2)`.
pub fn socket(domain: c_int, ty: c_int, proto: c_int) -> Res<c_int> {
    // SAFETY: plain integer arguments.
    cvt(unsafe { libc::socket(domain, ty, proto) } as isize).map(|f| f as c_int)
}

/// `close(2)` of a raw descriptor number (which may be stale: the kernel
/// then says EBADF, or closes whatever now has that number, which the
/// fuzzer owns too: see main.rs, "descriptor table").
pub fn close(fd: c_int) -> Res<()> {
    // SAFETY: closing a number touches no memory of ours; the fuzzer
    // keeps every descriptor it may close out of Rust-owned objects.
    cvt(unsafe { libc::close(fd) } as isize).map(drop)
}

/// Clears `O_NONBLOCK` on `fd` (`fcntl(2)` `F_GETFL`, `F_SETFL`).
pub fn set_blocking(fd: c_int) -> Res<()> {
    // SAFETY: integer arguments.
    let fl = cvt(unsafe { libc::fcntl(fd, libc::F_GETFL) } as isize)? as c_int;
    // SAFETY: integer arguments.
    cvt(unsafe { libc::fcntl(fd, libc::F_SETFL, fl & !libc::O_NONBLOCK) } as isize).map(drop)
}

/// `dup(2)`.
pub fn dup(fd: c_int) -> Res<c_int> {
    // SAFETY: integer argument.
    cvt(unsafe { libc::dup(fd) } as isize).map(|f| f as c_int)
}

/// `bind(2)` with the bytes of `addr` as address (any length).
pub fn bind(fd: c_int, addr: &[u8]) -> Res<()> {
    // SAFETY: the kernel reads `addr.len()` bytes of `addr`.
    cvt(unsafe { libc::bind(fd, addr.as_ptr().cast(), addr.len() as socklen_t) } as isize).map(drop)
}

/// `connect(2)`, likewise.
pub fn connect(fd: c_int, addr: &[u8]) -> Res<()> {
    // SAFETY: the kernel reads `addr.len()` bytes of `addr`.
    cvt(unsafe { libc::connect(fd, addr.as_ptr().cast(), addr.len() as socklen_t) } as isize)
        .map(drop)
}

/// `setsockopt(2)` with `val` as value and `len` as optlen; `len` may be
/// larger than `val` only when it is negative as a C int (the kernel
/// refuses those before reading).
pub fn setsockopt(fd: c_int, level: c_int, name: c_int, val: &[u8], len: u32) -> Res<()> {
    let len = if (len as usize) <= val.len() || (len as c_int) < 0 {
        len
    } else {
        val.len() as u32
    };
    // SAFETY: the kernel reads at most `len` bytes, which `val` holds, or
    // rejects a negative length without reading.
    cvt(unsafe { libc::setsockopt(fd, level, name, val.as_ptr().cast(), len) } as isize).map(drop)
}

/// `getsockopt(2)` into `buf` with optlen `buf.len()`; returns the
/// optlen the kernel wrote back.
pub fn getsockopt(fd: c_int, level: c_int, name: c_int, buf: &mut [u8]) -> Res<usize> {
    let mut len = buf.len() as socklen_t;
    // SAFETY: `buf` is writable for `len` bytes; `len` is a valid socklen_t.
    cvt(unsafe { libc::getsockopt(fd, level, name, buf.as_mut_ptr().cast(), &mut len) } as isize)?;
    Ok(len as usize)
}

/// `getsockopt(2)` with optlen `len` (any value, e.g. negative or huge)
/// into a fresh page followed by an inaccessible guard page: a kernel that
/// trusts the length writes into the guard page and fails with EFAULT
/// instead of corrupting the fuzzer. Returns the optlen written back.
pub fn getsockopt_guarded(fd: c_int, level: c_int, name: c_int, len: u32) -> Res<u32> {
    const PAGE: usize = 4096;
    // SAFETY: a fresh anonymous mapping, not shared with anything.
    let map = unsafe {
        libc::mmap(
            ptr::null_mut(),
            2 * PAGE,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    if map == libc::MAP_FAILED {
        return Err(errno());
    }
    // SAFETY: the second page of our own mapping.
    unsafe { libc::mprotect(map.cast::<u8>().add(PAGE).cast(), PAGE, libc::PROT_NONE) };
    let mut l = len as socklen_t;
    // SAFETY: the kernel may write the mapping's first page (ours alone)
    // and faults on the second; `l` is a valid socklen_t.
    let r = unsafe { libc::getsockopt(fd, level, name, map, &mut l) };
    let e = errno();
    // SAFETY: unmaps exactly what was mapped above; nothing refers to it.
    unsafe { libc::munmap(map, 2 * PAGE) };
    if r < 0 {
        Err(e)
    } else {
        Ok(l)
    }
}

/// `sendto(2)` (`send` when `addr` is None).
pub fn sendto(fd: c_int, data: &[u8], flags: c_int, addr: Option<&[u8]>) -> Res<usize> {
    let (ap, al) = addr.map_or((ptr::null(), 0), |a| (a.as_ptr(), a.len()));
    // SAFETY: the kernel reads `data` and `addr` within their lengths.
    cvt(unsafe {
        libc::sendto(
            fd,
            data.as_ptr().cast(),
            data.len(),
            flags,
            ap.cast(),
            al as socklen_t,
        )
    })
}

/// Control buffer, aligned for `struct cmsghdr`.
#[repr(C, align(8))]
pub struct Cmsg(pub [u8; 256]);

/// `sendmsg(2)` with one data buffer, an optional address and `control`
/// (the first `clen` bytes of it, raw: the fuzzer builds the cmsghdrs).
pub fn sendmsg(
    fd: c_int,
    data: &[u8],
    addr: Option<&[u8]>,
    control: &Cmsg,
    clen: usize,
    flags: c_int,
) -> Res<usize> {
    let mut iov = libc::iovec {
        iov_base: data.as_ptr() as *mut c_void,
        iov_len: data.len(),
    };
    // SAFETY: all-zero is a valid msghdr (null pointers, zero lengths).
    let mut m: libc::msghdr = unsafe { zeroed() };
    if let Some(a) = addr {
        m.msg_name = a.as_ptr() as *mut c_void;
        m.msg_namelen = a.len() as socklen_t;
    }
    m.msg_iov = &mut iov;
    m.msg_iovlen = 1;
    if clen > 0 {
        m.msg_control = control.0.as_ptr() as *mut c_void;
        m.msg_controllen = clen.min(control.0.len());
    }
    // SAFETY: every pointer in `m` points at memory alive for the call,
    // with the length given; sendmsg only reads them.
    cvt(unsafe { libc::sendmsg(fd, &m, flags) })
}

/// `recvfrom(2)` into `buf` (`recv` when `addr` is None); returns the
/// return value and the address length written back.
pub fn recvfrom(
    fd: c_int,
    buf: &mut [u8],
    flags: c_int,
    addr: Option<&mut [u8]>,
) -> Res<(usize, usize)> {
    let (ap, mut al) = match addr {
        Some(a) => (a.as_mut_ptr(), a.len() as socklen_t),
        None => (ptr::null_mut(), 0),
    };
    let alp = if ap.is_null() {
        ptr::null_mut()
    } else {
        &mut al as *mut socklen_t
    };
    // SAFETY: `buf` and the address buffer are writable within the
    // lengths given; `alp` is null exactly when the address is.
    let n = cvt(unsafe {
        libc::recvfrom(
            fd,
            buf.as_mut_ptr().cast(),
            buf.len(),
            flags,
            ap.cast(),
            alp,
        )
    })?;
    Ok((n, al as usize))
}

/// What [`recvmsg`] returns: return value, `msg_namelen`,
/// `msg_controllen`, `msg_flags`.
pub struct RecvMsg {
    pub n: usize,
    pub namelen: usize,
    pub controllen: usize,
    pub flags: c_int,
}

/// `recvmsg(2)` into `buf`, `name` and the first `clen` bytes of
/// `control`.
pub fn recvmsg(
    fd: c_int,
    buf: &mut [u8],
    name: &mut [u8],
    control: &mut Cmsg,
    clen: usize,
    flags: c_int,
) -> Res<RecvMsg> {
    let mut iov = libc::iovec {
        iov_base: buf.as_mut_ptr().cast(),
        iov_len: buf.len(),
    };
    // SAFETY: all-zero is a valid msghdr.
    let mut m: libc::msghdr = unsafe { zeroed() };
    if !name.is_empty() {
        m.msg_name = name.as_mut_ptr().cast();
        m.msg_namelen = name.len() as socklen_t;
    }
    m.msg_iov = &mut iov;
    m.msg_iovlen = 1;
    if clen > 0 {
        m.msg_control = control.0.as_mut_ptr().cast();
        m.msg_controllen = clen.min(control.0.len());
    }
    // SAFETY: every pointer in `m` points at writable memory alive for
    // the call, with the length given.
    let n = cvt(unsafe { libc::recvmsg(fd, &mut m, flags) })?;
    Ok(RecvMsg {
        n,
        namelen: m.msg_namelen as usize,
        controllen: m.msg_controllen,
        flags: m.msg_flags,
    })
}

/// A buffer for ioctl arguments, large and aligned enough for every
/// argument struct the fuzzer uses (`ifreq`, `timeval`, `int`).
#[repr(C, align(8))]
pub struct IoctlArg(pub [u8; 256]);

/// `ioctl(fd, cmd, arg)` with `arg` pointing at `buf`. Only for commands
/// whose argument is a plain struct of at most 256 bytes with no pointers
/// in it (the fuzzer's command table, main.rs).
pub fn ioctl(fd: c_int, cmd: libc::c_ulong, buf: &mut IoctlArg) -> Res<usize> {
    // SAFETY: for the commands used the kernel reads/writes at most the
    // 256 bytes of `buf`.
    cvt(unsafe { libc::ioctl(fd, cmd, buf.0.as_mut_ptr()) } as isize)
}

/// `ioctl(fd, cmd, &ifr)` for an `ifreq` named `dev` whose `ifr_data`
/// points at `data` (`SIOCDEVPRIVATE` + n: the driver may read and write
/// `data`).
pub fn ioctl_ifr_data(
    fd: c_int,
    cmd: libc::c_ulong,
    dev: &str,
    data: &mut [u8; 256],
) -> Res<usize> {
    // SAFETY: all-zero bytes are a valid ifreq.
    let mut ifr: libc::ifreq = unsafe { zeroed() };
    for (d, s) in ifr
        .ifr_name
        .iter_mut()
        .zip(dev.bytes().take(libc::IFNAMSIZ - 1))
    {
        *d = s as libc::c_char;
    }
    ifr.ifr_ifru.ifru_data = data.as_mut_ptr().cast();
    // SAFETY: `ifr` is a valid ifreq with a NUL-terminated name; its data
    // pointer covers 256 writable bytes, more than any private ioctl of
    // rcan's drivers transfers (they check the length they copy).
    cvt(unsafe { libc::ioctl(fd, cmd, &mut ifr) } as isize)
}

/// `shutdown(2)`.
pub fn shutdown(fd: c_int, how: c_int) -> Res<()> {
    // SAFETY: integer arguments.
    cvt(unsafe { libc::shutdown(fd, how) } as isize).map(drop)
}

/// `poll(2)` on `fds`.
pub fn poll(fds: &mut [libc::pollfd], timeout_ms: c_int) -> Res<usize> {
    // SAFETY: `fds` is a writable array of that many pollfds.
    cvt(unsafe { libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, timeout_ms) } as isize)
}

/// `getsockname(2)` (or `getpeername` when `peer`) into `buf`; returns
/// the address length the kernel reported (may exceed `buf`).
pub fn getname(fd: c_int, buf: &mut [u8], peer: bool) -> Res<usize> {
    let mut len = buf.len() as socklen_t;
    // SAFETY: `buf` is writable for `len` bytes.
    let r = unsafe {
        if peer {
            libc::getpeername(fd, buf.as_mut_ptr().cast(), &mut len)
        } else {
            libc::getsockname(fd, buf.as_mut_ptr().cast(), &mut len)
        }
    };
    cvt(r as isize)?;
    Ok(len as usize)
}

/// The inode number of the file `fd` refers to (`fstat(2)`): tells
/// whether a descriptor number still names the same socket after a call.
pub fn ino(fd: c_int) -> Res<u64> {
    // SAFETY: all-zero is a valid `stat`; fstat writes one into `st`.
    let mut st: libc::stat = unsafe { zeroed() };
    // SAFETY: `st` is a live, writable `stat`.
    cvt(unsafe { libc::fstat(fd, &mut st) } as isize)?;
    Ok(st.st_ino)
}

/// `insmod KO PARAMS`: `finit_module(2)`.
pub fn finit_module(ko: &Path, params: &str) -> Res<()> {
    let file = File::open(ko).map_err(|e| e.raw_os_error().unwrap_or(libc::EIO))?;
    let params = CString::new(params).map_err(|_| libc::EINVAL)?;
    // SAFETY: an open descriptor and a NUL-terminated string alive for the
    // call; flags 0.
    let r = unsafe {
        libc::syscall(
            libc::SYS_finit_module,
            file.as_raw_fd(),
            params.as_ptr(),
            0 as c_int,
        )
    };
    cvt(r as isize).map(drop)
}

/// `rmmod NAME`: `delete_module(2)` with `O_NONBLOCK`.
pub fn delete_module(name: &str) -> Res<()> {
    let name = CString::new(name).map_err(|_| libc::EINVAL)?;
    // SAFETY: a NUL-terminated string alive for the call.
    let r = unsafe { libc::syscall(libc::SYS_delete_module, name.as_ptr(), libc::O_NONBLOCK) };
    cvt(r as isize).map(drop)
}

/// An interface request on an AF_INET control socket `ctl`:
/// `SIOCGIFFLAGS`+`SIOCSIFFLAGS` (set `IFF_UP` to `up`) when `mtu` is
/// None, else `SIOCSIFMTU`.
pub fn link_set(ctl: c_int, dev: &str, up: bool, mtu: Option<c_int>) -> Res<()> {
    if dev.is_empty() || dev.len() >= libc::IFNAMSIZ {
        return Err(libc::ENODEV);
    }
    // SAFETY: all-zero bytes are a valid ifreq.
    let mut ifr: libc::ifreq = unsafe { zeroed() };
    for (d, s) in ifr.ifr_name.iter_mut().zip(dev.bytes()) {
        *d = s as libc::c_char;
    }
    if let Some(m) = mtu {
        ifr.ifr_ifru.ifru_mtu = m;
        // SAFETY: a valid ifreq with a NUL-terminated name; read only.
        return cvt(unsafe { libc::ioctl(ctl, libc::SIOCSIFMTU, &ifr) } as isize).map(drop);
    }
    // SAFETY: a valid, writable ifreq with a NUL-terminated name.
    cvt(unsafe { libc::ioctl(ctl, libc::SIOCGIFFLAGS, &mut ifr) } as isize)?;
    // SAFETY: SIOCGIFFLAGS filled in `ifru_flags`, the member used.
    unsafe {
        let f = &mut ifr.ifr_ifru.ifru_flags;
        if up {
            *f |= libc::IFF_UP as libc::c_short;
        } else {
            *f &= !(libc::IFF_UP as libc::c_short);
        }
    }
    // SAFETY: as above; the kernel only reads `ifr`.
    cvt(unsafe { libc::ioctl(ctl, libc::SIOCSIFFLAGS, &ifr) } as isize).map(drop)
}

/// `_exit(2)`: ends the process at once, whatever the other threads are
/// doing (a thread stuck in the kernel cannot be joined).
pub fn exit_now(code: c_int) -> ! {
    // SAFETY: terminates the process; nothing runs after it.
    unsafe { libc::_exit(code) }
}

#[cfg(test)]
mod tests {
    //! The wrappers against AF_UNIX sockets, which any host has.
    use super::*;

    #[test]
    fn roundtrip_and_errors() {
        let a = socket(libc::AF_UNIX, libc::SOCK_DGRAM, 0).unwrap();
        assert_eq!(bind(a, &[2, 0]), Err(libc::EINVAL));
        assert_eq!(connect(a, &[]), Err(libc::EINVAL));
        let mut buf = [0u8; 4];
        assert_eq!(
            getsockopt(a, libc::SOL_SOCKET, libc::SO_TYPE, &mut buf),
            Ok(4)
        );
        assert_eq!(i32::from_ne_bytes(buf), libc::SOCK_DGRAM);
        // A negative optlen is refused, and the guard page holds.
        assert_eq!(
            getsockopt_guarded(a, libc::SOL_SOCKET, libc::SO_TYPE, u32::MAX),
            Err(libc::EINVAL)
        );
        assert_eq!(
            setsockopt(a, libc::SOL_SOCKET, libc::SO_RCVBUF, &[0; 4], u32::MAX),
            Err(libc::EINVAL)
        );
        let mut ioc = IoctlArg([0; 256]);
        assert_eq!(ioctl(a, 0x8906, &mut ioc), Err(libc::ENOTTY));
        let mut p = [libc::pollfd {
            fd: a,
            events: libc::POLLIN,
            revents: 0,
        }];
        assert_eq!(poll(&mut p, 0), Ok(0));
        let b = dup(a).unwrap();
        assert_eq!(close(a), Ok(()));
        assert_eq!(close(a), Err(libc::EBADF));
        assert_eq!(close(b), Ok(()));
        assert_eq!(recvfrom(b, &mut buf, 0, None), Err(libc::EBADF));
    }
}
