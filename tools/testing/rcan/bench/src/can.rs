// SPDX-License-Identifier: GPL-2.0
//! Minimal `PF_CAN`/`CAN_RAW` sockets through libc, mainline SocketCAN ABI
//! only (`struct can_frame`, `struct sockaddr_can`, `SOL_CAN_RAW` options),
//! so that the very same code drives mainline `can-raw.ko` and rcan's
//! `rcan_raw.ko`.
//!
//! Also the other libc calls the benchmark needs (interface index,
//! `RLIMIT_NOFILE`, CPU affinity). Every `unsafe` block of the benchmark
//! lives here, each one for a libc call.

use std::ffi::CString;
use std::io;
use std::mem;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::time::Duration;

use libc::{c_int, c_void, socklen_t};

/// Standard (11-bit) identifier mask.
pub const CAN_SFF_MASK: u32 = 0x0000_07ff;
/// Extended frame format flag in `can_id`.
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// Remote transmission request flag in `can_id`.
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// Filter mask for "exactly this 11-bit data frame id": mainline keeps
/// such filters in a per-identifier table instead of a list.
pub const EXACT_SFF_MASK: u32 = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;

const CAN_RAW: c_int = 1;
const SOL_CAN_BASE: c_int = 100;
const SOL_CAN_RAW: c_int = SOL_CAN_BASE + CAN_RAW;
const CAN_RAW_FILTER: c_int = 1;
const CAN_RAW_LOOPBACK: c_int = 3;
/// `sizeof(struct can_frame)`: the only size a classic CAN_RAW socket
/// reads or writes.
const CAN_MTU: usize = 16;

/// `struct sockaddr_can` (24 bytes; the protocol-specific union after
/// `can_ifindex` is 8-byte aligned and unused by CAN_RAW).
#[repr(C)]
struct SockaddrCan {
    can_family: libc::sa_family_t,
    can_ifindex: c_int,
    can_addr: [u64; 2],
}

/// `struct can_filter`.
#[repr(C)]
#[derive(Clone, Copy)]
struct CanFilter {
    can_id: u32,
    can_mask: u32,
}

/// `CAN_RAW_FD_FRAMES`: the socket reads and writes `struct canfd_frame`.
const CAN_RAW_FD_FRAMES: c_int = 5;
/// `sizeof(struct canfd_frame)`: what a CAN_RAW socket with
/// `CAN_RAW_FD_FRAMES` reads for an FD frame (classic frames stay 16).
pub const CANFD_MTU: usize = 72;
/// Payload bytes of an FD frame at most.
pub const CANFD_MAX_DLEN: usize = 64;
/// `CANFD_BRS`: bit rate switch (the data phase at the data bit rate).
pub const CANFD_BRS: u8 = 0x01;
/// `CANFD_ESI`: error state indicator.
pub const CANFD_ESI: u8 = 0x02;

/// What a benchmark frame looks like on the wire: its payload length and,
/// for an FD frame, its flags (`CANFD_BRS`, `CANFD_ESI`; the kernel's
/// `CANFD_FDF` is not part of the shape).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shape {
    /// Payload bytes: 8 for classic frames (the two words), 8..=64 and a
    /// valid FD length for FD frames.
    pub len: u8,
    /// `None`: a classic frame (`struct can_frame`); `Some(flags)`: an FD
    /// frame (`struct canfd_frame`) with these flags.
    pub fd: Option<u8>,
}

impl Shape {
    /// The classic 8-byte data frame every part sends.
    pub const CLASSIC8: Shape = Shape { len: 8, fd: None };
    /// A 64-byte FD frame with bit rate switch.
    pub const FD64_BRS: Shape = Shape {
        len: 64,
        fd: Some(CANFD_BRS),
    };
}

/// A CAN data frame: `struct can_frame` or `struct canfd_frame` minus the
/// padding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// `can_id` including the EFF/RTR/ERR flags.
    pub id: u32,
    /// Data length: 0..=8, or 0..=64 for an FD frame.
    pub len: u8,
    /// `None` for a classic frame, else the FD flags as received or to
    /// send (`CANFD_BRS`, `CANFD_ESI`, the kernel's `CANFD_FDF`).
    pub fd: Option<u8>,
    /// Payload; bytes past `len` are zero.
    pub data: [u8; CANFD_MAX_DLEN],
}

impl Frame {
    /// An 8-byte classic data frame with `id` carrying two 32-bit words
    /// (little endian): the benchmark's sequence number and run tag.
    pub fn with_words(id: u32, seq: u32, tag: u32) -> Self {
        Self::shaped(id, seq, tag, Shape::CLASSIC8)
    }

    /// A frame of `shape` whose first 8 bytes are the two words of
    /// [`Frame::with_words`] and the rest a fixed pattern (byte i = i).
    pub fn shaped(id: u32, seq: u32, tag: u32, shape: Shape) -> Self {
        let mut data = [0u8; CANFD_MAX_DLEN];
        for (i, b) in data.iter_mut().enumerate().take(shape.len.into()) {
            *b = i as u8;
        }
        data[..4].copy_from_slice(&seq.to_le_bytes());
        data[4..8].copy_from_slice(&tag.to_le_bytes());
        Frame {
            id,
            len: shape.len,
            fd: shape.fd,
            data,
        }
    }

    /// The frame's [`Shape`] (FD flags other than BRS and ESI ignored).
    pub fn shape(&self) -> Shape {
        Shape {
            len: self.len,
            fd: self.fd.map(|f| f & (CANFD_BRS | CANFD_ESI)),
        }
    }

    /// The first data word (the sequence number).
    pub fn seq(&self) -> u32 {
        u32::from_le_bytes([self.data[0], self.data[1], self.data[2], self.data[3]])
    }

    /// The second data word (the run tag).
    pub fn tag(&self) -> u32 {
        u32::from_le_bytes([self.data[4], self.data[5], self.data[6], self.data[7]])
    }

    /// Encodes into `buf` as `struct can_frame` (16 bytes) or `struct
    /// canfd_frame` (72); returns the size.
    fn encode(&self, buf: &mut [u8; CANFD_MTU]) -> usize {
        *buf = [0u8; CANFD_MTU];
        buf[..4].copy_from_slice(&self.id.to_ne_bytes());
        buf[4] = self.len;
        match self.fd {
            None => {
                buf[8..CAN_MTU].copy_from_slice(&self.data[..8]);
                CAN_MTU
            }
            Some(flags) => {
                buf[5] = flags;
                buf[8..].copy_from_slice(&self.data);
                CANFD_MTU
            }
        }
    }

    /// Decodes the `n` bytes a socket read: 16 (classic) or 72 (FD).
    fn decode(buf: &[u8; CANFD_MTU], n: usize) -> io::Result<Self> {
        let mut data = [0u8; CANFD_MAX_DLEN];
        let fd = match n {
            CAN_MTU => {
                data[..8].copy_from_slice(&buf[8..CAN_MTU]);
                None
            }
            CANFD_MTU => {
                data.copy_from_slice(&buf[8..]);
                Some(buf[5])
            }
            _ => {
                return Err(io::Error::other(format!(
                    "received {n} bytes, want {CAN_MTU} or {CANFD_MTU}"
                )))
            }
        };
        Ok(Frame {
            id: u32::from_ne_bytes([buf[0], buf[1], buf[2], buf[3]]),
            len: buf[4],
            fd,
            data,
        })
    }
}

/// Converts a libc return value (-1 = error in `errno`) into a `Result`.
fn cvt(ret: isize) -> io::Result<usize> {
    if ret < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(ret as usize)
    }
}

/// `if_nametoindex(3)`.
pub fn ifindex(name: &str) -> io::Result<i32> {
    let cname = CString::new(name).map_err(|_| io::Error::from(io::ErrorKind::InvalidInput))?;
    // SAFETY: `cname` is a valid NUL-terminated string that outlives the call.
    let idx = unsafe { libc::if_nametoindex(cname.as_ptr()) };
    if idx == 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(idx as i32)
    }
}

/// Raises `RLIMIT_NOFILE` (soft and, if needed, hard) to at least `want`.
/// Returns the new soft limit.
pub fn raise_nofile(want: u64) -> io::Result<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `lim` is a valid, writable `struct rlimit`.
    cvt(unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) } as isize)?;
    if lim.rlim_cur >= want {
        return Ok(lim.rlim_cur);
    }
    lim.rlim_cur = want;
    lim.rlim_max = lim.rlim_max.max(want);
    // SAFETY: `lim` is a valid `struct rlimit`; the kernel only reads it.
    cvt(unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &lim) } as isize)?;
    Ok(want)
}

/// Pins the calling thread to `cpu` (`sched_setaffinity`); threads it
/// creates afterwards inherit that.
pub fn pin_current_thread(cpu: usize) -> io::Result<()> {
    if cpu >= libc::CPU_SETSIZE as usize {
        return Err(io::Error::from(io::ErrorKind::InvalidInput));
    }
    // SAFETY: `cpu_set_t` is a plain bit array, for which all zeroes is a
    // valid (empty) value.
    let mut set: libc::cpu_set_t = unsafe { mem::zeroed() };
    // SAFETY: `set` is a valid `cpu_set_t` and `cpu` is below
    // `CPU_SETSIZE`, checked above.
    unsafe { libc::CPU_SET(cpu, &mut set) };
    // SAFETY: `set` is a valid `cpu_set_t` of the size passed; pid 0 is the
    // calling thread.
    let ret = unsafe { libc::sched_setaffinity(0, mem::size_of::<libc::cpu_set_t>(), &set) };
    cvt(ret as isize).map(drop)
}

/// A `socket(PF_CAN, SOCK_RAW, CAN_RAW)`.
pub struct RawSocket {
    fd: OwnedFd,
}

impl RawSocket {
    /// Opens an unbound CAN_RAW socket (blocking).
    pub fn new() -> io::Result<Self> {
        // SAFETY: plain system call with constant arguments.
        let fd =
            unsafe { libc::socket(libc::PF_CAN, libc::SOCK_RAW | libc::SOCK_CLOEXEC, CAN_RAW) };
        cvt(fd as isize)?;
        // SAFETY: `fd` was just returned by socket(2) and is owned by nobody else.
        Ok(RawSocket {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
        })
    }

    fn setsockopt_raw(
        &self,
        level: c_int,
        name: c_int,
        val: *const c_void,
        len: usize,
    ) -> io::Result<()> {
        // SAFETY: `val` points to `len` readable bytes (or `len` is 0) for
        // the duration of the call; the kernel copies them.
        let ret =
            unsafe { libc::setsockopt(self.fd.as_raw_fd(), level, name, val, len as socklen_t) };
        cvt(ret as isize).map(drop)
    }

    fn setsockopt<T>(&self, level: c_int, name: c_int, val: &T) -> io::Result<()> {
        self.setsockopt_raw(level, name, (val as *const T).cast(), mem::size_of::<T>())
    }

    fn getsockopt_int(&self, level: c_int, name: c_int) -> io::Result<c_int> {
        let mut val: c_int = 0;
        let mut len = mem::size_of::<c_int>() as socklen_t;
        // SAFETY: `val` and `len` are valid and writable; `len` holds the
        // size of `val`.
        let ret = unsafe {
            libc::getsockopt(
                self.fd.as_raw_fd(),
                level,
                name,
                (&mut val as *mut c_int).cast(),
                &mut len,
            )
        };
        cvt(ret as isize)?;
        Ok(val)
    }

    /// `bind()` to the interface `ifindex` (0: all CAN interfaces).
    pub fn bind(&self, ifindex: i32) -> io::Result<()> {
        let addr = SockaddrCan {
            can_family: libc::AF_CAN as libc::sa_family_t,
            can_ifindex: ifindex,
            can_addr: [0; 2],
        };
        // SAFETY: `addr` is a complete `struct sockaddr_can` whose size is
        // passed along; the kernel only reads it.
        let ret = unsafe {
            libc::bind(
                self.fd.as_raw_fd(),
                (&addr as *const SockaddrCan).cast(),
                mem::size_of::<SockaddrCan>() as socklen_t,
            )
        };
        cvt(ret as isize).map(drop)
    }

    /// `CAN_RAW_FILTER` with the given `(can_id, can_mask)` pairs. An empty
    /// list means "receive nothing" (a pure sender).
    pub fn set_filters(&self, filters: &[(u32, u32)]) -> io::Result<()> {
        let f: Vec<CanFilter> = filters
            .iter()
            .map(|&(can_id, can_mask)| CanFilter { can_id, can_mask })
            .collect();
        self.setsockopt_raw(
            SOL_CAN_RAW,
            CAN_RAW_FILTER,
            f.as_ptr().cast(),
            mem::size_of_val(f.as_slice()),
        )
    }

    /// `CAN_RAW_LOOPBACK` (mainline default: on).
    pub fn set_loopback(&self, on: bool) -> io::Result<()> {
        self.setsockopt(SOL_CAN_RAW, CAN_RAW_LOOPBACK, &c_int::from(on))
    }

    /// Receive buffer of at least `bytes`: `SO_RCVBUFFORCE` (root, ignores
    /// `rmem_max`), else `SO_RCVBUF`. Returns what the kernel reports.
    pub fn set_rcvbuf(&self, bytes: usize) -> io::Result<usize> {
        let val = c_int::try_from(bytes).unwrap_or(c_int::MAX);
        if self
            .setsockopt(libc::SOL_SOCKET, libc::SO_RCVBUFFORCE, &val)
            .is_err()
        {
            self.setsockopt(libc::SOL_SOCKET, libc::SO_RCVBUF, &val)?;
        }
        Ok(self.getsockopt_int(libc::SOL_SOCKET, libc::SO_RCVBUF)? as usize)
    }

    /// `SO_RCVTIMEO`: a blocking receive fails with `WouldBlock` after `t`.
    pub fn set_rcvtimeo(&self, t: Duration) -> io::Result<()> {
        let tv = libc::timeval {
            tv_sec: t.as_secs() as libc::time_t,
            tv_usec: t.subsec_micros() as libc::suseconds_t,
        };
        self.setsockopt(libc::SOL_SOCKET, libc::SO_RCVTIMEO, &tv)
    }

    /// `CAN_RAW_FD_FRAMES` (mainline default: off): FD frames are
    /// delivered to and may be sent from this socket.
    pub fn set_fd_frames(&self, on: bool) -> io::Result<()> {
        self.setsockopt(SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &c_int::from(on))
    }

    /// `SO_TIMESTAMPNS`: every frame read with
    /// [`RawSocket::recv_stamped`] carries its receive time.
    pub fn set_timestampns(&self, on: bool) -> io::Result<()> {
        self.setsockopt(libc::SOL_SOCKET, libc::SO_TIMESTAMPNS, &c_int::from(on))
    }

    /// Receives one frame with `recvmsg(2)` and its `SCM_TIMESTAMPNS`
    /// (ns of `CLOCK_REALTIME`; `None` if the kernel sent none); blocking
    /// (subject to `SO_RCVTIMEO`) unless `dontwait`.
    pub fn recv_stamped(&self, dontwait: bool) -> io::Result<(Frame, Option<i64>)> {
        let mut buf = [0u8; CANFD_MTU];
        // u64 words: aligned for `struct cmsghdr`.
        let mut ctl = [0u64; 16];
        let mut iov = libc::iovec {
            iov_base: buf.as_mut_ptr().cast(),
            iov_len: buf.len(),
        };
        // SAFETY: all-zero is a valid `struct msghdr` (null name, no iov).
        let mut mh: libc::msghdr = unsafe { mem::zeroed() };
        mh.msg_iov = &mut iov;
        mh.msg_iovlen = 1;
        mh.msg_control = ctl.as_mut_ptr().cast();
        mh.msg_controllen = mem::size_of_val(&ctl) as _;
        let flags = if dontwait { libc::MSG_DONTWAIT } else { 0 };
        // SAFETY: `mh` points to `iov` (and it to `buf`) and to `ctl`, all
        // writable for the lengths given and alive during the call.
        let n = cvt(unsafe { libc::recvmsg(self.fd.as_raw_fd(), &mut mh, flags) })?;
        let frame = Frame::decode(&buf, n)?;
        let mut stamp = None;
        // SAFETY: `mh` was filled by recvmsg; the CMSG_* walk stays inside
        // `msg_controllen` bytes of `ctl`.
        unsafe {
            let mut c = libc::CMSG_FIRSTHDR(&mh);
            while !c.is_null() {
                if (*c).cmsg_level == libc::SOL_SOCKET && (*c).cmsg_type == libc::SCM_TIMESTAMPNS {
                    let ts: libc::timespec = std::ptr::read_unaligned(libc::CMSG_DATA(c).cast());
                    stamp = Some(ts.tv_sec as i64 * 1_000_000_000 + ts.tv_nsec as i64);
                }
                c = libc::CMSG_NXTHDR(&mh, c);
            }
        }
        Ok((frame, stamp))
    }

    /// Sends one frame with `send(2)` on the bound interface (an FD frame
    /// needs [`RawSocket::set_fd_frames`]).
    pub fn send(&self, frame: &Frame) -> io::Result<()> {
        let mut buf = [0u8; CANFD_MTU];
        let len = frame.encode(&mut buf);
        // SAFETY: `buf` is readable for `len` <= its size bytes during the call.
        let n = cvt(unsafe { libc::send(self.fd.as_raw_fd(), buf.as_ptr().cast(), len, 0) })?;
        if n != len {
            return Err(io::Error::other(format!("short send: {n} bytes")));
        }
        Ok(())
    }

    /// Receives one frame; blocking (subject to `SO_RCVTIMEO`) unless
    /// `dontwait`. No frame: `ErrorKind::WouldBlock`.
    pub fn recv(&self, dontwait: bool) -> io::Result<Frame> {
        let mut buf = [0u8; CANFD_MTU];
        let flags = if dontwait { libc::MSG_DONTWAIT } else { 0 };
        // SAFETY: `buf` is writable for its full length during the call.
        let n = cvt(unsafe {
            libc::recv(
                self.fd.as_raw_fd(),
                buf.as_mut_ptr().cast(),
                buf.len(),
                flags,
            )
        })?;
        Frame::decode(&buf, n)
    }

    /// Reads and discards whatever is queued; returns how many frames.
    pub fn drain(&self) -> u64 {
        let mut n = 0;
        while self.recv(true).is_ok() {
            n += 1;
        }
        n
    }
}

/// `CAN_ISOTP`: protocol number of mainline's `can-isotp.ko`.
const CAN_ISOTP: c_int = 6;
/// `CAN_ISOTP_OPTS` at level `SOL_CAN_ISOTP`.
const CAN_ISOTP_OPTS: c_int = 1;
/// `CAN_ISOTP_RECV_FC` at level `SOL_CAN_ISOTP`.
const CAN_ISOTP_RECV_FC: c_int = 2;
/// `CAN_ISOTP_LL_OPTS` at level `SOL_CAN_ISOTP`.
const CAN_ISOTP_LL_OPTS: c_int = 5;
/// `frame_txtime` value meaning "no gap" (0 means "default").
const CAN_ISOTP_FRAME_TXTIME_ZERO: u32 = 0xffff_ffff;

/// `struct sockaddr_can` with the `can_addr.tp` member of ISO-TP.
#[repr(C)]
struct SockaddrCanTp {
    can_family: libc::sa_family_t,
    can_ifindex: c_int,
    rx_id: u32,
    tx_id: u32,
    /// Rest of the 16-byte, 8-byte aligned union.
    _pad: u64,
}

/// A mainline `socket(PF_CAN, SOCK_DGRAM, CAN_ISOTP)` with default options
/// (no `CAN_ISOTP_OPTS`/`CAN_ISOTP_RECV_FC` set: block size 0, STmin 0, no
/// padding, no extended addressing).
pub struct IsotpSocket {
    fd: OwnedFd,
}

impl IsotpSocket {
    /// Opens an unbound ISO-TP socket (blocking).
    pub fn new() -> io::Result<Self> {
        // SAFETY: plain system call with constant arguments.
        let fd = unsafe {
            libc::socket(
                libc::PF_CAN,
                libc::SOCK_DGRAM | libc::SOCK_CLOEXEC,
                CAN_ISOTP,
            )
        };
        cvt(fd as isize)?;
        // SAFETY: `fd` was just returned by socket(2) and is owned by nobody else.
        Ok(IsotpSocket {
            fd: unsafe { OwnedFd::from_raw_fd(fd) },
        })
    }

    /// `bind()` to `ifindex`: receive PDUs on `rx_id`, send on `tx_id`
    /// (`can_id` values, `CAN_EFF_FLAG` for 29-bit identifiers).
    pub fn bind(&self, ifindex: i32, rx_id: u32, tx_id: u32) -> io::Result<()> {
        let addr = SockaddrCanTp {
            can_family: libc::AF_CAN as libc::sa_family_t,
            can_ifindex: ifindex,
            rx_id,
            tx_id,
            _pad: 0,
        };
        // SAFETY: `addr` is a complete `struct sockaddr_can` whose size is
        // passed along; the kernel only reads it.
        let ret = unsafe {
            libc::bind(
                self.fd.as_raw_fd(),
                (&addr as *const SockaddrCanTp).cast(),
                mem::size_of::<SockaddrCanTp>() as socklen_t,
            )
        };
        cvt(ret as isize).map(drop)
    }

    /// `CAN_ISOTP_OPTS` with all defaults except `frame_txtime` = 0
    /// (`CAN_ISOTP_FRAME_TXTIME_ZERO`): consecutive frames in a burst,
    /// each sent from the echo of the previous one, instead of one every
    /// 50 us (`CAN_ISOTP_DEFAULT_FRAME_TXTIME`) from a timer.
    pub fn set_no_frame_gap(&self) -> io::Result<()> {
        // struct can_isotp_options: flags, frame_txtime, ext_address,
        // txpad_content, rxpad_content, rx_ext_address (12 bytes).
        #[repr(C)]
        struct Opts {
            flags: u32,
            frame_txtime: u32,
            ext_address: u8,
            txpad_content: u8,
            rxpad_content: u8,
            rx_ext_address: u8,
        }
        let o = Opts {
            flags: 0,
            frame_txtime: CAN_ISOTP_FRAME_TXTIME_ZERO,
            ext_address: 0,
            txpad_content: 0xcc,
            rxpad_content: 0xcc,
            rx_ext_address: 0,
        };
        // SAFETY: `o` is a valid `struct can_isotp_options` whose size is
        // passed; the kernel only reads it.
        let ret = unsafe {
            libc::setsockopt(
                self.fd.as_raw_fd(),
                SOL_CAN_BASE + CAN_ISOTP,
                CAN_ISOTP_OPTS,
                (&o as *const Opts).cast(),
                mem::size_of::<Opts>() as socklen_t,
            )
        };
        cvt(ret as isize).map(drop)
    }

    /// `setsockopt(SOL_CAN_ISOTP, name, bytes)`.
    fn set_isotp_opt(&self, name: c_int, bytes: &[u8]) -> io::Result<()> {
        // SAFETY: `bytes` is readable for its full length during the call;
        // the kernel copies it.
        let ret = unsafe {
            libc::setsockopt(
                self.fd.as_raw_fd(),
                SOL_CAN_BASE + CAN_ISOTP,
                name,
                bytes.as_ptr().cast(),
                bytes.len() as socklen_t,
            )
        };
        cvt(ret as isize).map(drop)
    }

    /// `CAN_ISOTP_RECV_FC` (`struct can_isotp_fc_options {bs, stmin,
    /// wftmax}`): the block size and STmin this socket's flow control
    /// frames ask the sender for.
    pub fn set_recv_fc(&self, bs: u8, stmin: u8) -> io::Result<()> {
        self.set_isotp_opt(CAN_ISOTP_RECV_FC, &[bs, stmin, 0])
    }

    /// `CAN_ISOTP_LL_OPTS` (`struct can_isotp_ll_options {mtu, tx_dl,
    /// tx_flags}`): 72, 64, 0 is CAN FD with 64-byte frames (no BRS).
    pub fn set_ll_opts(&self, mtu: u8, tx_dl: u8, tx_flags: u8) -> io::Result<()> {
        self.set_isotp_opt(CAN_ISOTP_LL_OPTS, &[mtu, tx_dl, tx_flags])
    }

    /// `SO_RCVTIMEO` and `SO_SNDTIMEO`.
    pub fn set_timeouts(&self, t: Duration) -> io::Result<()> {
        let tv = libc::timeval {
            tv_sec: t.as_secs() as libc::time_t,
            tv_usec: t.subsec_micros() as libc::suseconds_t,
        };
        for name in [libc::SO_RCVTIMEO, libc::SO_SNDTIMEO] {
            // SAFETY: `tv` is a valid `struct timeval` whose size is
            // passed; the kernel only reads it.
            let ret = unsafe {
                libc::setsockopt(
                    self.fd.as_raw_fd(),
                    libc::SOL_SOCKET,
                    name,
                    (&tv as *const libc::timeval).cast(),
                    mem::size_of::<libc::timeval>() as socklen_t,
                )
            };
            cvt(ret as isize)?;
        }
        Ok(())
    }

    /// Sends one PDU (`write(2)`); returns the bytes taken.
    pub fn send(&self, data: &[u8]) -> io::Result<usize> {
        // SAFETY: `data` is readable for its full length during the call.
        cvt(unsafe { libc::write(self.fd.as_raw_fd(), data.as_ptr().cast(), data.len()) })
    }

    /// Receives one PDU (`read(2)`); returns its length.
    pub fn recv(&self, buf: &mut [u8]) -> io::Result<usize> {
        // SAFETY: `buf` is writable for its full length during the call.
        cvt(unsafe { libc::read(self.fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) })
    }
}

/// User and system CPU time of this process (all threads), from
/// `getrusage(RUSAGE_SELF)`.
pub fn rusage_self() -> io::Result<(Duration, Duration)> {
    // SAFETY: all-zero is a valid `struct rusage`.
    let mut ru: libc::rusage = unsafe { mem::zeroed() };
    // SAFETY: `ru` is a valid, writable `struct rusage`.
    cvt(unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) } as isize)?;
    let tv = |t: libc::timeval| Duration::new(t.tv_sec as u64, t.tv_usec as u32 * 1000);
    Ok((tv(ru.ru_utime), tv(ru.ru_stime)))
}

/// Makes the calling thread `SCHED_IDLE`: it runs only when nothing else
/// on its CPU wants to.
pub fn set_sched_idle() -> io::Result<()> {
    let p = libc::sched_param { sched_priority: 0 };
    // SAFETY: `p` is a valid `struct sched_param`; pid 0 is the calling
    // thread.
    cvt(unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &p) } as isize).map(drop)
}

/// `sysconf(_SC_CLK_TCK)`: the unit of `/proc/stat` (USER_HZ).
pub fn clk_tck() -> u64 {
    // SAFETY: plain library call with a constant argument.
    let v = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if v > 0 {
        v as u64
    } else {
        100
    }
}

/// Kernel CPU time of all CPUs so far (`/proc/stat` system + irq +
/// softirq), in seconds.
pub fn kernel_cpu_s() -> io::Result<f64> {
    let stat = std::fs::read_to_string("/proc/stat")?;
    let cpu: Vec<u64> = stat
        .lines()
        .find(|l| l.starts_with("cpu "))
        .ok_or_else(|| io::Error::other("/proc/stat: no cpu line"))?
        .split_whitespace()
        .skip(1)
        .map(|v| v.parse().unwrap_or(0))
        .collect();
    let f = |i: usize| cpu.get(i).copied().unwrap_or(0);
    Ok((f(2) + f(5) + f(6)) as f64 / clk_tck() as f64)
}

/// Sends `frame`, retrying for up to a second while the device queue
/// pushes back (`ENOBUFS`/`EAGAIN`). Returns how many retries it took.
pub fn send_retrying(sock: &RawSocket, frame: &Frame) -> io::Result<u64> {
    let mut retries = 0;
    loop {
        match sock.send(frame) {
            Ok(()) => return Ok(retries),
            Err(e)
                if e.raw_os_error() == Some(libc::ENOBUFS)
                    || e.kind() == io::ErrorKind::WouldBlock =>
            {
                retries += 1;
                if retries > 10_000 {
                    return Err(e);
                }
                std::thread::sleep(Duration::from_micros(100));
            }
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abi_sizes() {
        assert_eq!(mem::size_of::<SockaddrCan>(), 24);
        assert_eq!(mem::size_of::<CanFilter>(), 8);
        assert_eq!(mem::size_of::<SockaddrCanTp>(), 24);
    }

    #[test]
    fn frame_round_trip() {
        let f = Frame::with_words(0x123, 77, 0xdead_beef);
        let mut buf = [0u8; CANFD_MTU];
        let n = f.encode(&mut buf);
        assert_eq!(n, CAN_MTU);
        let g = Frame::decode(&buf, n).unwrap();
        assert_eq!(f, g);
        assert_eq!(g.seq(), 77);
        assert_eq!(g.tag(), 0xdead_beef);
        assert_eq!(g.shape(), Shape::CLASSIC8);
    }

    #[test]
    fn fd_frame_round_trip() {
        let f = Frame::shaped(0x123, 5, 9, Shape::FD64_BRS);
        let mut buf = [0u8; CANFD_MTU];
        assert_eq!(f.encode(&mut buf), CANFD_MTU);
        // struct canfd_frame: can_id, len, flags, 2 reserved, data[64].
        assert_eq!(buf[4], 64);
        assert_eq!(buf[5], CANFD_BRS);
        assert_eq!(buf[8 + 63], 63);
        // The kernel adds CANFD_FDF (0x04) on receive: same shape.
        buf[5] |= 0x04;
        let g = Frame::decode(&buf, CANFD_MTU).unwrap();
        assert_eq!((g.seq(), g.tag(), g.data), (5, 9, f.data));
        assert_eq!(g.shape(), Shape::FD64_BRS);
        assert!(Frame::decode(&buf, 40).is_err());
    }
}
