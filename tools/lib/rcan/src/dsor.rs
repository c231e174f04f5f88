// SPDX-License-Identifier: GPL-2.0
//! [`DsorSocket`]: `socket(PF_CAN, SOCK_DGRAM, CANPROTO_DSOR)` and its
//! addresses (`<linux/can/rcan_dsor.h>`, thesis 5.2.6).

use std::io;
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::time::Duration;

use libc::c_int;

use crate::{raw, AF_CAN, CANPROTO_DSOR, PF_CAN};

/// `DSOR_NODE_ANY`: a segmented bind that accepts every source node.
pub const DSOR_NODE_ANY: u8 = 0xff;
/// `DSOR_ID_ANY`: a segmented bind that accepts every message id.
pub const DSOR_ID_ANY: u32 = 0xffff_ffff;
/// `DSOR_MAX_LEN`.
pub const DSOR_MAX_LEN: usize = 65535;

/// A DSOR address: `struct sockaddr_cansegm` (8 bytes) or
/// `struct sockaddr_canport` (6 bytes); the length selects the type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DsorAddr {
    /// Segmented: priority, peer node, 32-bit message id.
    Segm { prio: u8, node: u8, id: u32 },
    /// Port: priority, `node << 8 | sub-port`.
    Port { prio: u8, port: u16 },
}

/// `DSOR_PORT(node, sub)`.
pub const fn dsor_port(node: u8, sub: u8) -> u16 {
    ((node as u16 & 0x7f) << 8) | sub as u16
}

impl DsorAddr {
    /// The address as the kernel takes it.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = AF_CAN.to_ne_bytes().to_vec();
        match *self {
            DsorAddr::Segm { prio, node, id } => {
                b.push(prio);
                b.push(node);
                b.extend_from_slice(&id.to_ne_bytes());
            }
            DsorAddr::Port { prio, port } => {
                b.extend_from_slice(&port.to_ne_bytes());
                b.push(prio);
                b.push(0);
            }
        }
        b
    }

    /// Decodes what the kernel wrote (`len` bytes).
    pub fn from_bytes(b: &[u8]) -> Option<Self> {
        if b.len() < 2 || u16::from_ne_bytes([b[0], b[1]]) != AF_CAN {
            return None;
        }
        match b.len() {
            8 => Some(DsorAddr::Segm {
                prio: b[2],
                node: b[3],
                id: u32::from_ne_bytes([b[4], b[5], b[6], b[7]]),
            }),
            6 => Some(DsorAddr::Port {
                port: u16::from_ne_bytes([b[2], b[3]]),
                prio: b[4],
            }),
            _ => None,
        }
    }
}

/// A DSOR socket, closed on drop. Methods map onto system calls and return
/// the kernel's error unchanged.
#[derive(Debug)]
pub struct DsorSocket {
    fd: OwnedFd,
}

impl AsFd for DsorSocket {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.fd.as_fd()
    }
}

impl DsorSocket {
    /// Opens a new DSOR socket.
    pub fn new() -> io::Result<Self> {
        raw::socket(PF_CAN, libc::SOCK_DGRAM, CANPROTO_DSOR).map(|fd| DsorSocket { fd })
    }

    pub fn bind(&self, a: &DsorAddr) -> io::Result<()> {
        raw::bind(self, &a.to_bytes())
    }

    pub fn connect(&self, a: &DsorAddr) -> io::Result<()> {
        raw::connect(self, &a.to_bytes())
    }

    pub fn send_to(&self, data: &[u8], a: &DsorAddr) -> io::Result<usize> {
        raw::sendto(self, data, 0, Some(&a.to_bytes()))
    }

    pub fn send_to_flags(&self, data: &[u8], a: &DsorAddr, flags: c_int) -> io::Result<usize> {
        raw::sendto(self, data, flags, Some(&a.to_bytes()))
    }

    pub fn send(&self, data: &[u8]) -> io::Result<usize> {
        raw::sendto(self, data, 0, None)
    }

    pub fn write(&self, data: &[u8]) -> io::Result<usize> {
        raw::write(self, data)
    }

    /// `recvfrom`: bytes copied and the source address.
    pub fn recv_from(&self, buf: &mut [u8]) -> io::Result<(usize, Option<DsorAddr>)> {
        self.recv_from_flags(buf, 0)
    }

    pub fn recv_from_flags(
        &self,
        buf: &mut [u8],
        flags: c_int,
    ) -> io::Result<(usize, Option<DsorAddr>)> {
        let mut a = [0u8; 16];
        let (n, alen) = raw::recvfrom(self, buf, flags, Some(&mut a))?;
        let alen = (alen as usize).min(a.len());
        Ok((n, DsorAddr::from_bytes(&a[..alen])))
    }

    pub fn read(&self, buf: &mut [u8]) -> io::Result<usize> {
        raw::read(self, buf)
    }

    /// `getsockname`.
    pub fn local_addr(&self) -> io::Result<Option<DsorAddr>> {
        let mut a = [0u8; 16];
        let n = raw::getsockname(self, &mut a)? as usize;
        Ok(DsorAddr::from_bytes(&a[..n.min(16)]))
    }

    pub fn set_rcvtimeo(&self, t: Duration) -> io::Result<()> {
        raw::set_timeout(self, libc::SO_RCVTIMEO, t)
    }

    pub fn set_sndtimeo(&self, t: Duration) -> io::Result<()> {
        raw::set_timeout(self, libc::SO_SNDTIMEO, t)
    }

    pub fn set_nonblocking(&self, on: bool) -> io::Result<()> {
        raw::set_nonblocking(self, on)
    }

    /// `SO_ERROR` (reading clears it).
    pub fn take_error(&self) -> io::Result<i32> {
        let mut v = [0u8; 4];
        raw::getsockopt(self, libc::SOL_SOCKET, libc::SO_ERROR, &mut v)?;
        Ok(i32::from_ne_bytes(v))
    }
}
