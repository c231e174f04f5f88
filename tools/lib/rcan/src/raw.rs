// SPDX-License-Identifier: GPL-2.0
//! Thin system call wrappers: every `unsafe` block of the crate is here.
//!
//! Addresses are passed as byte slices so that tests can hand the kernel
//! malformed ones (short `addrlen`, wrong family, odd padding). The
//! `*_fault` functions pass a pointer into a mapped but inaccessible
//! (`PROT_NONE`) page, which the kernel must reject with `EFAULT` without
//! touching any memory of this process.

use std::ffi::{CStr, CString};
use std::io::{self, IoSlice, IoSliceMut};
use std::os::fd::{AsFd, AsRawFd, FromRawFd, OwnedFd};
use std::ptr;
use std::time::Duration;

use libc::{c_int, c_void, socklen_t};

fn cvt(r: c_int) -> io::Result<c_int> {
    if r < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(r)
    }
}

fn cvt_size(r: isize) -> io::Result<usize> {
    usize::try_from(r).map_err(|_| io::Error::last_os_error())
}

fn len_of(b: &[u8]) -> io::Result<socklen_t> {
    socklen_t::try_from(b.len()).map_err(|_| io::Error::from_raw_os_error(libc::EINVAL))
}

/// `socket(domain, ty | SOCK_CLOEXEC, proto)`.
pub fn socket(domain: c_int, ty: c_int, proto: c_int) -> io::Result<OwnedFd> {
    // SAFETY: socket() takes no pointers.
    let fd = cvt(unsafe { libc::socket(domain, ty | libc::SOCK_CLOEXEC, proto) })?;
    // SAFETY: `fd` is a descriptor just created for us and owned by no one else.
    Ok(unsafe { OwnedFd::from_raw_fd(fd) })
}

/// `bind(fd, addr, addr.len())`.
pub fn bind(fd: impl AsFd, addr: &[u8]) -> io::Result<()> {
    let len = len_of(addr)?;
    // SAFETY: `addr` is readable for `len` bytes during the call.
    cvt(unsafe { libc::bind(fd.as_fd().as_raw_fd(), addr.as_ptr().cast(), len) }).map(drop)
}

/// `connect(fd, addr, addr.len())`.
pub fn connect(fd: impl AsFd, addr: &[u8]) -> io::Result<()> {
    let len = len_of(addr)?;
    // SAFETY: `addr` is readable for `len` bytes during the call.
    cvt(unsafe { libc::connect(fd.as_fd().as_raw_fd(), addr.as_ptr().cast(), len) }).map(drop)
}

/// `sendto(fd, data, data.len(), flags, addr, addr.len())`; `None` passes a
/// null address (plain `send`).
pub fn sendto(fd: impl AsFd, data: &[u8], flags: c_int, addr: Option<&[u8]>) -> io::Result<usize> {
    let (aptr, alen) = match addr {
        Some(a) => (a.as_ptr(), len_of(a)?),
        None => (ptr::null(), 0),
    };
    // SAFETY: `data` and `addr` (if any) are readable for their lengths
    // during the call; a null address with length 0 is allowed.
    let r = unsafe {
        libc::sendto(
            fd.as_fd().as_raw_fd(),
            data.as_ptr().cast(),
            data.len(),
            flags,
            aptr.cast(),
            alen,
        )
    };
    cvt_size(r)
}

/// `recvfrom(fd, buf, buf.len(), flags, addr, &addrlen)` with addrlen
/// initialised to `addr.len()`; returns the byte count and the addrlen the
/// kernel wrote back. `None` passes null address pointers (plain `recv`).
pub fn recvfrom(
    fd: impl AsFd,
    buf: &mut [u8],
    flags: c_int,
    addr: Option<&mut [u8]>,
) -> io::Result<(usize, socklen_t)> {
    let (aptr, mut alen) = match addr {
        Some(a) => {
            let l = len_of(a)?;
            (a.as_mut_ptr(), l)
        }
        None => (ptr::null_mut(), 0),
    };
    let alenp: *mut socklen_t = if aptr.is_null() {
        ptr::null_mut()
    } else {
        &mut alen
    };
    // SAFETY: `buf` is writable for its length, `addr` (if any) for `alen`
    // bytes, and `alen` is a live socklen_t; all outlive the call.
    let r = unsafe {
        libc::recvfrom(
            fd.as_fd().as_raw_fd(),
            buf.as_mut_ptr().cast(),
            buf.len(),
            flags,
            aptr.cast(),
            alenp,
        )
    };
    Ok((cvt_size(r)?, alen))
}

/// `write(fd, data, data.len())`.
pub fn write(fd: impl AsFd, data: &[u8]) -> io::Result<usize> {
    // SAFETY: `data` is readable for its length during the call.
    cvt_size(unsafe { libc::write(fd.as_fd().as_raw_fd(), data.as_ptr().cast(), data.len()) })
}

/// `read(fd, buf, buf.len())`.
pub fn read(fd: impl AsFd, buf: &mut [u8]) -> io::Result<usize> {
    // SAFETY: `buf` is writable for its length during the call.
    cvt_size(unsafe { libc::read(fd.as_fd().as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) })
}

/// `sendmsg` gathering `iov`, to `addr` (`None`: no msg_name).
pub fn sendmsg(
    fd: impl AsFd,
    iov: &[IoSlice<'_>],
    addr: Option<&[u8]>,
    flags: c_int,
) -> io::Result<usize> {
    // SAFETY: msghdr is plain old data; all-zero is a valid value.
    let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
    if let Some(a) = addr {
        msg.msg_name = a.as_ptr().cast_mut().cast();
        msg.msg_namelen = len_of(a)?;
    }
    // IoSlice is guaranteed ABI compatible with struct iovec on Unix.
    msg.msg_iov = iov.as_ptr().cast_mut().cast();
    msg.msg_iovlen = iov.len() as _;
    // SAFETY: msg points to the iovecs and address, which are readable and
    // outlive the call; the kernel does not write through them for sendmsg.
    cvt_size(unsafe { libc::sendmsg(fd.as_fd().as_raw_fd(), &msg, flags) })
}

/// `recvmsg` scattering into `iov`, the source address into `addr`.
/// Returns (byte count, msg_namelen, msg_flags).
pub fn recvmsg(
    fd: impl AsFd,
    iov: &mut [IoSliceMut<'_>],
    addr: &mut [u8],
    flags: c_int,
) -> io::Result<(usize, socklen_t, c_int)> {
    // SAFETY: msghdr is plain old data; all-zero is a valid value.
    let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
    msg.msg_name = addr.as_mut_ptr().cast();
    msg.msg_namelen = len_of(addr)?;
    // IoSliceMut is guaranteed ABI compatible with struct iovec on Unix.
    msg.msg_iov = iov.as_mut_ptr().cast();
    msg.msg_iovlen = iov.len() as _;
    // SAFETY: the iovecs describe writable buffers and `addr` is writable for
    // msg_namelen bytes; all outlive the call.
    let n = cvt_size(unsafe { libc::recvmsg(fd.as_fd().as_raw_fd(), &mut msg, flags) })?;
    Ok((n, msg.msg_namelen, msg.msg_flags))
}

/// `getsockname` into `addr`; returns the length the kernel reported.
pub fn getsockname(fd: impl AsFd, addr: &mut [u8]) -> io::Result<socklen_t> {
    let mut len = len_of(addr)?;
    // SAFETY: `addr` is writable for `len` bytes and `len` is live.
    cvt(unsafe { libc::getsockname(fd.as_fd().as_raw_fd(), addr.as_mut_ptr().cast(), &mut len) })?;
    Ok(len)
}

/// `getpeername` into `addr`; returns the length the kernel reported.
pub fn getpeername(fd: impl AsFd, addr: &mut [u8]) -> io::Result<socklen_t> {
    let mut len = len_of(addr)?;
    // SAFETY: `addr` is writable for `len` bytes and `len` is live.
    cvt(unsafe { libc::getpeername(fd.as_fd().as_raw_fd(), addr.as_mut_ptr().cast(), &mut len) })?;
    Ok(len)
}

/// `setsockopt(fd, level, name, val, val.len())`.
pub fn setsockopt(fd: impl AsFd, level: c_int, name: c_int, val: &[u8]) -> io::Result<()> {
    let len = len_of(val)?;
    // SAFETY: `val` is readable for `len` bytes during the call.
    cvt(unsafe {
        libc::setsockopt(
            fd.as_fd().as_raw_fd(),
            level,
            name,
            val.as_ptr().cast(),
            len,
        )
    })
    .map(drop)
}

/// `getsockopt(fd, level, name, val, &len)`; returns the length reported.
pub fn getsockopt(
    fd: impl AsFd,
    level: c_int,
    name: c_int,
    val: &mut [u8],
) -> io::Result<socklen_t> {
    let mut len = len_of(val)?;
    // SAFETY: `val` is writable for `len` bytes and `len` is live.
    cvt(unsafe {
        libc::getsockopt(
            fd.as_fd().as_raw_fd(),
            level,
            name,
            val.as_mut_ptr().cast(),
            &mut len,
        )
    })?;
    Ok(len)
}

/// Sets `SO_RCVTIMEO` or `SO_SNDTIMEO` (`name`) to `t` (zero = forever).
pub fn set_timeout(fd: impl AsFd, name: c_int, t: Duration) -> io::Result<()> {
    let tv = libc::timeval {
        tv_sec: t.as_secs().try_into().unwrap_or(libc::time_t::MAX),
        tv_usec: t.subsec_micros().into(),
    };
    let len = std::mem::size_of::<libc::timeval>() as socklen_t;
    // SAFETY: `tv` is a live timeval of `len` bytes.
    cvt(unsafe {
        libc::setsockopt(
            fd.as_fd().as_raw_fd(),
            libc::SOL_SOCKET,
            name,
            ptr::from_ref(&tv).cast(),
            len,
        )
    })
    .map(drop)
}

/// Reads `SO_RCVTIMEO` or `SO_SNDTIMEO` (`name`).
pub fn get_timeout(fd: impl AsFd, name: c_int) -> io::Result<Duration> {
    let mut tv = libc::timeval {
        tv_sec: 0,
        tv_usec: 0,
    };
    let mut len = std::mem::size_of::<libc::timeval>() as socklen_t;
    // SAFETY: `tv` is a live, writable timeval of `len` bytes.
    cvt(unsafe {
        libc::getsockopt(
            fd.as_fd().as_raw_fd(),
            libc::SOL_SOCKET,
            name,
            ptr::from_mut(&mut tv).cast(),
            &mut len,
        )
    })?;
    let secs = u64::try_from(tv.tv_sec).unwrap_or(0);
    let micros = u32::try_from(tv.tv_usec).unwrap_or(0);
    Ok(Duration::from_secs(secs) + Duration::from_micros(micros.into()))
}

/// `listen(fd, backlog)`.
pub fn listen(fd: impl AsFd, backlog: c_int) -> io::Result<()> {
    // SAFETY: listen() takes no pointers.
    cvt(unsafe { libc::listen(fd.as_fd().as_raw_fd(), backlog) }).map(drop)
}

/// `accept(fd, NULL, NULL)`.
pub fn accept(fd: impl AsFd) -> io::Result<OwnedFd> {
    // SAFETY: null address pointers are allowed.
    let nfd = cvt(unsafe {
        libc::accept4(
            fd.as_fd().as_raw_fd(),
            ptr::null_mut(),
            ptr::null_mut(),
            libc::SOCK_CLOEXEC,
        )
    })?;
    // SAFETY: `nfd` is a descriptor just created for us.
    Ok(unsafe { OwnedFd::from_raw_fd(nfd) })
}

/// Sets or clears `O_NONBLOCK`.
pub fn set_nonblocking(fd: impl AsFd, on: bool) -> io::Result<()> {
    let raw = fd.as_fd().as_raw_fd();
    // SAFETY: F_GETFL takes no pointer.
    let fl = cvt(unsafe { libc::fcntl(raw, libc::F_GETFL) })?;
    let fl = if on {
        fl | libc::O_NONBLOCK
    } else {
        fl & !libc::O_NONBLOCK
    };
    // SAFETY: F_SETFL takes an int.
    cvt(unsafe { libc::fcntl(raw, libc::F_SETFL, fl) }).map(drop)
}

/// `if_nametoindex(name)`.
pub fn if_nametoindex(name: &str) -> io::Result<u32> {
    let c = CString::new(name).map_err(|_| io::Error::from_raw_os_error(libc::EINVAL))?;
    // SAFETY: `c` is a valid NUL-terminated string.
    match unsafe { libc::if_nametoindex(c.as_ptr()) } {
        0 => Err(io::Error::last_os_error()),
        i => Ok(i),
    }
}

/// `if_indextoname(ifindex)`.
pub fn if_indextoname(ifindex: u32) -> io::Result<String> {
    let mut buf = [0 as libc::c_char; libc::IF_NAMESIZE];
    // SAFETY: `buf` has the IF_NAMESIZE bytes if_indextoname may write.
    let p = unsafe { libc::if_indextoname(ifindex, buf.as_mut_ptr()) };
    if p.is_null() {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: on success `buf` holds a NUL-terminated name.
    let name = unsafe { CStr::from_ptr(buf.as_ptr()) };
    Ok(name.to_string_lossy().into_owned())
}

/// One mapped, inaccessible page: any kernel access to it faults.
struct NoAccessPage {
    addr: *mut c_void,
    len: usize,
}

impl NoAccessPage {
    fn new() -> io::Result<Self> {
        const LEN: usize = 4096;
        // SAFETY: an anonymous private mapping at a kernel-chosen address
        // cannot alias any existing Rust object.
        let addr = unsafe {
            libc::mmap(
                ptr::null_mut(),
                LEN,
                libc::PROT_NONE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            )
        };
        if addr == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        Ok(Self { addr, len: LEN })
    }
}

impl Drop for NoAccessPage {
    fn drop(&mut self) {
        // SAFETY: unmaps exactly the mapping created in new(), which no
        // reference points into.
        unsafe { libc::munmap(self.addr, self.len) };
    }
}

/// `sendto` whose data pointer (`len` bytes) is inaccessible: expect EFAULT.
pub fn sendto_fault(fd: impl AsFd, len: usize, flags: c_int, addr: &[u8]) -> io::Result<usize> {
    let page = NoAccessPage::new()?;
    let alen = len_of(addr)?;
    // SAFETY: the data pointer lies in a PROT_NONE page owned by `page`; the
    // kernel can only fail to read it. `addr` is readable for `alen` bytes.
    let r = unsafe {
        libc::sendto(
            fd.as_fd().as_raw_fd(),
            page.addr,
            len.min(page.len),
            flags,
            addr.as_ptr().cast(),
            alen,
        )
    };
    cvt_size(r)
}

/// `recv` into an inaccessible buffer of `len` bytes: expect EFAULT.
pub fn recv_fault(fd: impl AsFd, len: usize, flags: c_int) -> io::Result<usize> {
    let page = NoAccessPage::new()?;
    // SAFETY: the buffer lies in a PROT_NONE page owned by `page`; the kernel
    // cannot write to it, so no memory of ours changes.
    let r = unsafe { libc::recv(fd.as_fd().as_raw_fd(), page.addr, len.min(page.len), flags) };
    cvt_size(r)
}

/// `bind` with an inaccessible address of `len` bytes: expect EFAULT.
pub fn bind_fault(fd: impl AsFd, len: socklen_t) -> io::Result<()> {
    let page = NoAccessPage::new()?;
    // SAFETY: the address lies in a PROT_NONE page owned by `page`; the
    // kernel can only fail to read it.
    cvt(unsafe { libc::bind(fd.as_fd().as_raw_fd(), page.addr.cast(), len) }).map(drop)
}

/// `recvfrom` into a valid buffer but an inaccessible address: expect EFAULT.
pub fn recvfrom_addr_fault(fd: impl AsFd, buf: &mut [u8], flags: c_int) -> io::Result<usize> {
    let page = NoAccessPage::new()?;
    let mut alen: socklen_t = 16;
    // SAFETY: `buf` is writable for its length and `alen` is live; the
    // address pointer lies in a PROT_NONE page the kernel cannot write.
    let r = unsafe {
        libc::recvfrom(
            fd.as_fd().as_raw_fd(),
            buf.as_mut_ptr().cast(),
            buf.len(),
            flags,
            page.addr.cast(),
            &mut alen,
        )
    };
    cvt_size(r)
}

#[cfg(test)]
mod tests {
    //! The wrappers against an AF_UNIX datagram pair, which exists on any
    //! host (AF_CAN with CANPROTO_CAN needs the rcan modules).
    use super::*;
    use std::os::unix::net::UnixDatagram;

    fn errno<T: std::fmt::Debug>(r: io::Result<T>) -> Option<i32> {
        r.expect_err("call should have failed").raw_os_error()
    }

    #[test]
    fn faulting_pointers_give_efault() {
        let (a, b) = UnixDatagram::pair().unwrap();
        assert_eq!(errno(sendto_fault(&a, 8, 0, &[])), Some(libc::EFAULT));
        assert_eq!(sendto(&a, b"abc", 0, None).unwrap(), 3);
        assert_eq!(errno(recv_fault(&b, 8, 0)), Some(libc::EFAULT));
    }

    #[test]
    fn scatter_gather_and_flags() {
        let (a, b) = UnixDatagram::pair().unwrap();
        let n = sendmsg(&a, &[IoSlice::new(b"abc"), IoSlice::new(b"defgh")], None, 0).unwrap();
        assert_eq!(n, 8);
        let (mut x, mut y) = ([0u8; 3], [0u8; 2]);
        let mut addr = [0u8; 16];
        let iov = &mut [IoSliceMut::new(&mut x), IoSliceMut::new(&mut y)];
        let (n, _, flags) = recvmsg(&b, iov, &mut addr, 0).unwrap();
        assert_eq!((n, &x, &y), (5, b"abc", b"de"));
        assert_ne!(flags & libc::MSG_TRUNC, 0);
    }

    #[test]
    fn timeouts_and_nonblocking() {
        let (_a, b) = UnixDatagram::pair().unwrap();
        let t = Duration::from_millis(20);
        set_timeout(&b, libc::SO_RCVTIMEO, t).unwrap();
        assert_eq!(get_timeout(&b, libc::SO_RCVTIMEO).unwrap(), t);
        let mut buf = [0u8; 4];
        assert_eq!(errno(read(&b, &mut buf)), Some(libc::EAGAIN));
        set_nonblocking(&b, true).unwrap();
        let r = recvfrom(&b, &mut buf, 0, None);
        assert_eq!(errno(r), Some(libc::EAGAIN));
    }

    #[test]
    fn interface_names() {
        assert!(if_nametoindex("no-such-if0").is_err());
        if let Ok(i) = if_nametoindex("lo") {
            assert_eq!(if_indextoname(i).unwrap(), "lo");
        }
    }
}
