// SPDX-License-Identifier: GPL-2.0
//! CAN_BCM messages (`struct bcm_msg_head` followed by `struct
//! can_frame`s, linux/can/bcm.h) as bytes, for cantcpd's BCM mode. Only
//! classic frames; the layout is the one of the target's C ABI (`struct
//! bcm_timeval` holds two `long`s).

use std::io::{self, IoSliceMut};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use nix::errno::Errno;
use nix::sys::socket::{self as nsock, sockopt, ControlMessageOwned, MsgFlags};
use nix::sys::time::TimeVal;
use socket2::{Domain, Protocol, Socket, Type};
use socketcan::CanAddr;

use crate::frame::{Frame, CAN_MTU};

/// `CAN_BCM`, the protocol number of the broadcast manager.
const CAN_BCM: i32 = 2;
/// `AF_CAN`.
const AF_CAN: i32 = 29;

/// `TX_SETUP`: create or update a transmission job.
pub const TX_SETUP: u32 = 1;
/// `TX_DELETE`: remove a transmission job.
pub const TX_DELETE: u32 = 2;
/// `TX_SEND`: send one frame.
pub const TX_SEND: u32 = 4;
/// `RX_SETUP`: create or update a receive filter.
pub const RX_SETUP: u32 = 5;
/// `RX_DELETE`: remove a receive filter.
pub const RX_DELETE: u32 = 6;
/// `RX_CHANGED`: a received frame that passed a filter (kernel to user).
pub const RX_CHANGED: u32 = 12;
/// `SETTIMER`: take `ival1`/`ival2` from the message.
pub const SETTIMER: u32 = 0x1;
/// `STARTTIMER`: start the transmission timer.
pub const STARTTIMER: u32 = 0x2;
/// `RX_FILTER_ID`: match the identifier only, no content filter.
pub const RX_FILTER_ID: u32 = 0x20;

/// Size of a `long` in the target's C ABI.
const LONG: usize = std::mem::size_of::<std::ffi::c_long>();
/// Offsets in `struct bcm_msg_head`: opcode, flags, count (u32 each),
/// then `ival1`, `ival2` (two longs each, aligned to a long), can_id,
/// nframes; the frames follow at the next 8-byte boundary.
const IVAL1: usize = 12usize.div_ceil(LONG) * LONG;
const IVAL2: usize = IVAL1 + 2 * LONG;
const CAN_ID: usize = IVAL2 + 2 * LONG;
const NFRAMES: usize = CAN_ID + 4;
/// `sizeof(struct bcm_msg_head)` (`can_frame` is 8-byte aligned).
pub const HEAD_LEN: usize = (NFRAMES + 4).div_ceil(8) * 8;

/// One BCM message with at most one frame (all cantcpd needs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Msg {
    /// `opcode`.
    pub opcode: u32,
    /// `flags`.
    pub flags: u32,
    /// `ival2` as (seconds, microseconds): the cycle of a transmission
    /// job, the throttle of a receive filter.
    pub ival2: (u64, u64),
    /// `can_id` of the head (the job's or filter's identifier).
    pub can_id: u32,
    /// The frame, if any (`nframes` 1 or 0).
    pub frame: Option<Frame>,
}

fn put_long(b: &mut [u8], off: usize, v: u64) {
    // A `long`: 8 bytes on 64-bit targets, 4 on 32-bit ones (where the
    // value is truncated; cantcpd's parser keeps it under 2^31).
    let bytes = v.to_ne_bytes();
    if cfg!(target_endian = "little") {
        b[off..off + LONG].copy_from_slice(&bytes[..LONG]);
    } else {
        b[off..off + LONG].copy_from_slice(&bytes[8 - LONG..]);
    }
}

impl Msg {
    /// The message as written to a CAN_BCM socket.
    pub fn encode(&self) -> Vec<u8> {
        let n = usize::from(self.frame.is_some());
        let mut b = vec![0u8; HEAD_LEN + n * CAN_MTU];
        b[0..4].copy_from_slice(&self.opcode.to_ne_bytes());
        b[4..8].copy_from_slice(&self.flags.to_ne_bytes());
        put_long(&mut b, IVAL2, self.ival2.0);
        put_long(&mut b, IVAL2 + LONG, self.ival2.1);
        b[CAN_ID..CAN_ID + 4].copy_from_slice(&self.can_id.to_ne_bytes());
        b[NFRAMES..NFRAMES + 4].copy_from_slice(&(n as u32).to_ne_bytes());
        if let Some(f) = &self.frame {
            b[HEAD_LEN..].copy_from_slice(&f.to_bytes());
        }
        b
    }

    /// A message read from a CAN_BCM socket: its opcode, head can_id and
    /// first frame (`None` without one). `None` for fewer bytes than a
    /// head, or a frame cut short.
    pub fn decode(b: &[u8]) -> Option<(u32, u32, Option<Frame>)> {
        if b.len() < HEAD_LEN {
            return None;
        }
        let u32_at = |o: usize| u32::from_ne_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let nframes = u32_at(NFRAMES);
        let frame = if nframes == 0 {
            None
        } else {
            Some(Frame::from_bytes(b.get(HEAD_LEN..HEAD_LEN + CAN_MTU)?)?)
        };
        Some((u32_at(0), u32_at(CAN_ID), frame))
    }
}

/// A CAN_BCM socket connected to one interface. Its jobs and filters end
/// when it is closed (dropped).
pub struct BcmSocket {
    sock: Socket,
    /// The SO_RCVTIMEO set last (set again only when it changes).
    timeout: Option<Duration>,
}

/// A message read from the socket: opcode, head can_id, frame, receive
/// time (seconds, microseconds; the kernel's SO_TIMESTAMP when it gives
/// one, the time of reading otherwise).
pub type Received = (u32, u32, Option<Frame>, i64, i64);

impl BcmSocket {
    /// `socket(PF_CAN, SOCK_DGRAM, CAN_BCM)` and `connect()` to `iface`.
    pub fn open(iface: &str) -> io::Result<Self> {
        Self::open_addr(CanAddr::from_iface(iface)?)
    }

    /// [`open`](Self::open) with the interface looked up already.
    pub fn open_addr(addr: CanAddr) -> io::Result<Self> {
        let sock = Socket::new(
            Domain::from(AF_CAN),
            Type::DGRAM,
            Some(Protocol::from(CAN_BCM)),
        )?;
        sock.connect(&addr.into_sock_addr())?;
        nsock::setsockopt(&sock, sockopt::ReceiveTimestamp, &true)?;
        Ok(Self {
            sock,
            timeout: None,
        })
    }

    /// Writes one message; the kernel's errno as the error. (The count
    /// written may be less than the message: `RX_SETUP` with
    /// `RX_FILTER_ID` returns the head's size, the frame being ignored.)
    pub fn send(&self, m: &Msg) -> io::Result<()> {
        self.sock.send(&m.encode())?;
        Ok(())
    }

    /// Sets how long [`recv`](Self::recv) waits for a message.
    pub fn set_read_timeout(&mut self, timeout: Duration) -> io::Result<()> {
        if self.timeout != Some(timeout) {
            self.sock.set_read_timeout(Some(timeout))?;
            self.timeout = Some(timeout);
        }
        Ok(())
    }

    /// Waits (up to the read timeout, if set) for one message; `Ok(None)`
    /// when none came.
    pub fn recv(&self) -> io::Result<Option<Received>> {
        let mut buf = [0u8; HEAD_LEN + CAN_MTU];
        let mut cmsg = nix::cmsg_space!(TimeVal);
        let mut iov = [IoSliceMut::new(&mut buf)];
        let (n, ts) = match nsock::recvmsg::<()>(
            self.sock.as_raw_fd(),
            &mut iov,
            Some(&mut cmsg),
            MsgFlags::empty(),
        ) {
            Ok(m) => {
                let mut ts = None;
                for c in m.cmsgs().map_err(io::Error::from)? {
                    if let ControlMessageOwned::ScmTimestamp(tv) = c {
                        ts = Some((tv.tv_sec(), tv.tv_usec()));
                    }
                }
                (m.bytes, ts)
            }
            Err(Errno::EAGAIN | Errno::EINTR) => return Ok(None),
            Err(e) => return Err(e.into()),
        };
        let (op, id, f) = Msg::decode(&buf[..n]).ok_or_else(|| {
            io::Error::new(io::ErrorKind::InvalidData, format!("{n}-byte BCM message"))
        })?;
        let (sec, usec) = ts.unwrap_or_else(|| {
            let t = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap_or_default();
            (t.as_secs() as i64, i64::from(t.subsec_micros()))
        });
        Ok(Some((op, id, f, sec, usec)))
    }
}

impl AsFd for BcmSocket {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.sock.as_fd()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(target_pointer_width = "64")]
    fn layout_of_x86_64_and_arm64() {
        assert_eq!(HEAD_LEN, 56);
        let f = Frame {
            id: 0x123,
            len: 2,
            data: [0xAA, 0xBB, 0, 0, 0, 0, 0, 0],
        };
        let m = Msg {
            opcode: TX_SETUP,
            flags: SETTIMER | STARTTIMER,
            ival2: (1, 500_000),
            can_id: 0x123,
            frame: Some(f),
        };
        let b = m.encode();
        assert_eq!(b.len(), 72);
        assert_eq!(&b[0..12], &[1, 0, 0, 0, 3, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(&b[16..32], &[0; 16]);
        assert_eq!(&b[32..40], &1u64.to_ne_bytes());
        assert_eq!(&b[40..48], &500_000u64.to_ne_bytes());
        assert_eq!(&b[48..56], &[0x23, 1, 0, 0, 1, 0, 0, 0]);
        assert_eq!(&b[56..], &f.to_bytes());
        let mut rx = b.clone();
        rx[0..4].copy_from_slice(&RX_CHANGED.to_ne_bytes());
        assert_eq!(Msg::decode(&rx), Some((RX_CHANGED, 0x123, Some(f))));
        assert_eq!(Msg::decode(&rx[..70]), None);
        assert_eq!(Msg::decode(&rx[..55]), None);
    }

    #[test]
    fn no_frame() {
        let m = Msg {
            opcode: TX_DELETE,
            flags: 0,
            ival2: (0, 0),
            can_id: 0x7FF,
            frame: None,
        };
        let b = m.encode();
        assert_eq!(b.len(), HEAD_LEN);
        assert_eq!(Msg::decode(&b), Some((TX_DELETE, 0x7FF, None)));
    }
}
