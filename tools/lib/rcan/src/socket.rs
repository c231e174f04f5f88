// SPDX-License-Identifier: GPL-2.0
//! [`ArbSocket`]: a safe wrapper around one CANPROTO_CAN socket.

use std::io::{self, IoSlice, IoSliceMut};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, OwnedFd, RawFd};
use std::time::Duration;

use libc::{c_int, socklen_t};

use crate::{raw, SockaddrCanArb, AF_UNSPEC, CANPROTO_CAN, PF_CAN, SOCKADDR_CANARB_LEN};

/// Result of [`ArbSocket::recv_msg`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecvMsg {
    /// Byte count returned by `recvmsg`.
    pub len: usize,
    /// `msg_flags` (e.g. `MSG_TRUNC`).
    pub flags: c_int,
    /// Source address.
    pub addr: SockaddrCanArb,
    /// `msg_namelen` as written by the kernel.
    pub addrlen: socklen_t,
}

/// A `socket(PF_CAN, SOCK_RAW, CANPROTO_CAN)`, closed on drop.
///
/// All methods map one-to-one onto system calls and return the kernel's
/// error unchanged.
#[derive(Debug)]
pub struct ArbSocket {
    fd: OwnedFd,
}

impl ArbSocket {
    /// Opens a new CANPROTO_CAN socket (unbound: it receives nothing).
    pub fn new() -> io::Result<Self> {
        raw::socket(PF_CAN, libc::SOCK_RAW, CANPROTO_CAN).map(Self::from)
    }

    /// Opens a new socket with `O_NONBLOCK` set.
    pub fn new_nonblocking() -> io::Result<Self> {
        raw::socket(PF_CAN, libc::SOCK_RAW | libc::SOCK_NONBLOCK, CANPROTO_CAN).map(Self::from)
    }

    /// Sets the acceptance filter (`arb`, `mask`: 1 bits = don't care) and
    /// the interface (`0` = all CAN interfaces).
    pub fn bind(&self, arb: u32, mask: u32, ifindex: u32) -> io::Result<()> {
        self.bind_addr(&SockaddrCanArb::new(arb, mask, ifindex))
    }

    /// `bind` with a complete address.
    pub fn bind_addr(&self, addr: &SockaddrCanArb) -> io::Result<()> {
        raw::bind(self, &addr.to_bytes())
    }

    /// Fixes the arbitration field and interface for [`send`](Self::send)
    /// and [`write`](Self::write).
    pub fn connect(&self, arb: u32, ifindex: u32) -> io::Result<()> {
        raw::connect(self, &SockaddrCanArb::new(arb, 0, ifindex).to_bytes())
    }

    /// Dissolves the association made by [`connect`](Self::connect)
    /// (`connect` with family `AF_UNSPEC`).
    pub fn disconnect(&self) -> io::Result<()> {
        let addr = SockaddrCanArb {
            family: AF_UNSPEC,
            ..SockaddrCanArb::default()
        };
        raw::connect(self, &addr.to_bytes())
    }

    /// Transmits one frame with arbitration field `arb` on `ifindex` (0: on
    /// every CAN interface that is up). `data.len()` is the DLC; for remote
    /// frames the bytes themselves are ignored.
    pub fn send_to(&self, data: &[u8], arb: u32, ifindex: u32) -> io::Result<usize> {
        self.send_to_flags(data, arb, ifindex, 0)
    }

    /// [`send_to`](Self::send_to) with `flags`.
    pub fn send_to_flags(
        &self,
        data: &[u8],
        arb: u32,
        ifindex: u32,
        flags: c_int,
    ) -> io::Result<usize> {
        let addr = SockaddrCanArb::new(arb, 0, ifindex).to_bytes();
        raw::sendto(self, data, flags, Some(&addr))
    }

    /// `send` on a connected socket.
    pub fn send(&self, data: &[u8]) -> io::Result<usize> {
        self.send_flags(data, 0)
    }

    /// `send` with `flags`.
    pub fn send_flags(&self, data: &[u8], flags: c_int) -> io::Result<usize> {
        raw::sendto(self, data, flags, None)
    }

    /// `write` on a connected socket.
    pub fn write(&self, data: &[u8]) -> io::Result<usize> {
        raw::write(self, data)
    }

    /// `sendmsg` gathering `iov`; `dest` = (arb, ifindex), or `None` to use
    /// the connected address.
    pub fn send_msg(
        &self,
        iov: &[IoSlice<'_>],
        dest: Option<(u32, u32)>,
        flags: c_int,
    ) -> io::Result<usize> {
        let addr = dest.map(|(arb, ifindex)| SockaddrCanArb::new(arb, 0, ifindex).to_bytes());
        raw::sendmsg(self, iov, addr.as_ref().map(|a| &a[..]), flags)
    }

    /// `recvfrom`: data bytes received and the frame's address.
    pub fn recv_from(&self, buf: &mut [u8]) -> io::Result<(usize, SockaddrCanArb)> {
        self.recv_from_flags(buf, 0)
    }

    /// `recvfrom` with `flags` (`MSG_PEEK`, `MSG_DONTWAIT`, `MSG_TRUNC`...).
    pub fn recv_from_flags(
        &self,
        buf: &mut [u8],
        flags: c_int,
    ) -> io::Result<(usize, SockaddrCanArb)> {
        let mut a = [0u8; SOCKADDR_CANARB_LEN];
        let (n, _) = raw::recvfrom(self, buf, flags, Some(&mut a))?;
        Ok((n, SockaddrCanArb::from_bytes(&a)))
    }

    /// `recv` with `flags`.
    pub fn recv(&self, buf: &mut [u8], flags: c_int) -> io::Result<usize> {
        raw::recvfrom(self, buf, flags, None).map(|(n, _)| n)
    }

    /// `read`.
    pub fn read(&self, buf: &mut [u8]) -> io::Result<usize> {
        raw::read(self, buf)
    }

    /// `recvmsg` scattering into `iov`, reporting `msg_flags`.
    pub fn recv_msg(&self, iov: &mut [IoSliceMut<'_>], flags: c_int) -> io::Result<RecvMsg> {
        let mut a = [0u8; SOCKADDR_CANARB_LEN];
        let (len, addrlen, mflags) = raw::recvmsg(self, iov, &mut a, flags)?;
        Ok(RecvMsg {
            len,
            flags: mflags,
            addr: SockaddrCanArb::from_bytes(&a),
            addrlen,
        })
    }

    /// `recvmsg` into one buffer.
    pub fn recv_msg_buf(&self, buf: &mut [u8], flags: c_int) -> io::Result<RecvMsg> {
        self.recv_msg(&mut [IoSliceMut::new(buf)], flags)
    }

    /// Sets `SO_RCVTIMEO`: blocking receives fail with `EAGAIN` after `t`
    /// (zero = wait forever).
    pub fn set_rcvtimeo(&self, t: Duration) -> io::Result<()> {
        raw::set_timeout(self, libc::SO_RCVTIMEO, t)
    }

    /// Reads `SO_RCVTIMEO`.
    pub fn rcvtimeo(&self) -> io::Result<Duration> {
        raw::get_timeout(self, libc::SO_RCVTIMEO)
    }

    /// Sets or clears `O_NONBLOCK`.
    pub fn set_nonblocking(&self, on: bool) -> io::Result<()> {
        raw::set_nonblocking(self, on)
    }

    /// `getsockname`: the filter given to `bind`.
    pub fn local_addr(&self) -> io::Result<SockaddrCanArb> {
        let mut a = [0u8; SOCKADDR_CANARB_LEN];
        raw::getsockname(self, &mut a)?;
        Ok(SockaddrCanArb::from_bytes(&a))
    }

    /// `getpeername`: the connected arbitration field and interface.
    pub fn peer_addr(&self) -> io::Result<SockaddrCanArb> {
        let mut a = [0u8; SOCKADDR_CANARB_LEN];
        raw::getpeername(self, &mut a)?;
        Ok(SockaddrCanArb::from_bytes(&a))
    }

    /// `listen` (not supported by CANPROTO_CAN).
    pub fn listen(&self, backlog: c_int) -> io::Result<()> {
        raw::listen(self, backlog)
    }

    /// `accept` (not supported by CANPROTO_CAN).
    pub fn accept(&self) -> io::Result<OwnedFd> {
        raw::accept(self)
    }
}

impl From<OwnedFd> for ArbSocket {
    fn from(fd: OwnedFd) -> Self {
        Self { fd }
    }
}

impl From<ArbSocket> for OwnedFd {
    fn from(s: ArbSocket) -> Self {
        s.fd
    }
}

impl AsFd for ArbSocket {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.fd.as_fd()
    }
}

impl AsRawFd for ArbSocket {
    fn as_raw_fd(&self) -> RawFd {
        self.fd.as_raw_fd()
    }
}
