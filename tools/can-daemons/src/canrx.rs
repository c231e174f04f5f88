// SPDX-License-Identifier: GPL-2.0
//! A CAN_RAW socket on one interface that reads frames with their kernel
//! receive timestamps (SO_TIMESTAMP) and the socket's drop counter
//! (SO_RXQ_OVFL), and writes frames.

use std::io::{self, IoSliceMut};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd};

use nix::errno::Errno;
use nix::sys::socket::{self, sockopt, ControlMessageOwned, MsgFlags};
use nix::sys::time::TimeVal;
use socketcan::{CanSocket, Socket, SocketOptions};

use crate::frame::{Frame, CAN_MTU};

/// One received frame.
#[derive(Clone, Copy, Debug)]
pub struct Received {
    /// The frame.
    pub frame: Frame,
    /// Kernel receive time, seconds since the epoch.
    pub sec: i64,
    /// Microseconds within `sec`.
    pub usec: i64,
    /// The socket's SO_RXQ_OVFL counter with this frame: frames dropped
    /// since the socket was opened because its receive queue was full.
    pub dropped: u32,
}

/// A CAN_RAW socket bound to one interface.
pub struct CanPort {
    sock: CanSocket,
    /// The interface name.
    pub iface: String,
}

impl CanPort {
    /// Opens and binds a CAN_RAW socket on `iface`; with `errors`, error
    /// frames are received too (CAN_RAW_ERR_FILTER = CAN_ERR_MASK).
    pub fn open(iface: &str, errors: bool) -> io::Result<Self> {
        let sock = CanSocket::open(iface)?;
        if errors {
            sock.set_error_filter_accept_all()?;
        }
        socket::setsockopt(&sock, sockopt::ReceiveTimestamp, &true)?;
        socket::setsockopt(&sock, sockopt::RxqOvfl, &1)?;
        Ok(Self {
            sock,
            iface: iface.to_string(),
        })
    }

    /// Lets only frames through whose `can_id & mask == id & mask`
    /// (CAN_RAW_FILTER with one filter).
    pub fn set_filter(&self, id: u32, mask: u32) -> io::Result<()> {
        self.sock
            .set_filters(&[socketcan::CanFilter::new(id, mask)])
    }

    /// Sets SO_RCVBUF (the kernel doubles it; CAP_NET_ADMIN may exceed
    /// rmem_max with SO_RCVBUFFORCE, which we do not use).
    pub fn set_rcvbuf(&self, bytes: usize) -> io::Result<()> {
        socket::setsockopt(&self.sock, sockopt::RcvBuf, &bytes)?;
        Ok(())
    }

    /// Sets a receive timeout for blocking reads (`None`: wait forever).
    pub fn set_read_timeout(&self, t: Option<std::time::Duration>) -> io::Result<()> {
        match t {
            Some(d) => self.sock.set_read_timeout(d),
            None => socket::setsockopt(&self.sock, sockopt::ReceiveTimeout, &TimeVal::new(0, 0))
                .map_err(io::Error::from),
        }
    }

    /// Reads one frame. `nonblocking`: `Ok(None)` when none is queued;
    /// otherwise waits (up to the read timeout, then `Ok(None)` too).
    /// Anything but a whole classic frame (a CAN FD frame cannot come: the
    /// socket does not enable CAN_RAW_FD_FRAMES) is an error.
    pub fn recv(&self, nonblocking: bool) -> io::Result<Option<Received>> {
        let mut buf = [0u8; CAN_MTU];
        let mut cmsg = nix::cmsg_space!(TimeVal, u32);
        let flags = if nonblocking {
            MsgFlags::MSG_DONTWAIT
        } else {
            MsgFlags::empty()
        };
        let mut iov = [IoSliceMut::new(&mut buf)];
        let (n, ts, dropped) =
            match socket::recvmsg::<()>(self.sock.as_raw_fd(), &mut iov, Some(&mut cmsg), flags) {
                Ok(m) => {
                    let mut ts = None;
                    let mut dropped = 0;
                    for c in m.cmsgs().map_err(io::Error::from)? {
                        match c {
                            ControlMessageOwned::ScmTimestamp(tv) => ts = Some(tv),
                            ControlMessageOwned::RxqOvfl(d) => dropped = d,
                            _ => {}
                        }
                    }
                    (m.bytes, ts, dropped)
                }
                Err(Errno::EAGAIN) => return Ok(None),
                Err(e) => return Err(e.into()),
            };
        let frame = Frame::from_bytes(&buf[..n]).ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{n}-byte CAN_RAW record"),
            )
        })?;
        let ts = ts.ok_or_else(|| io::Error::other("no SO_TIMESTAMP control message"))?;
        Ok(Some(Received {
            frame,
            sec: ts.tv_sec(),
            usec: ts.tv_usec(),
            dropped,
        }))
    }

    /// Writes one frame.
    pub fn send(&self, f: &Frame) -> io::Result<()> {
        let n = socket::send(self.sock.as_raw_fd(), &f.to_bytes(), MsgFlags::empty())?;
        if n != CAN_MTU {
            return Err(io::Error::other(format!("short write: {n} bytes")));
        }
        Ok(())
    }
}

impl AsFd for CanPort {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.sock.as_fd()
    }
}
