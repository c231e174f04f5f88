// SPDX-License-Identifier: GPL-2.0
//! Userspace side of the rcan CAN socket API (thesis "CAN socket API",
//! section 5.2), mirroring `include/uapi/linux/can/rcan.h`.
//!
//! `socket(AF_CAN, SOCK_RAW, CANPROTO_CAN)` opens a socket of the CAN 2.0A/B
//! data link protocol. Its address, [`SockaddrCanArb`], carries a 32-bit
//! *arbitration field* in host byte order:
//!
//! | bits   | meaning                                             |
//! |--------|-----------------------------------------------------|
//! | 31..21 | 11-bit (base) identifier                            |
//! | 20..3  | 18-bit identifier extension (zero in standard frames)|
//! | 2      | IDE ([`CAN_IDE`]): extended format frame            |
//! | 1      | RTR ([`CAN_RTR`]): remote frame                     |
//! | 0      | unused, must be 0                                   |
//!
//! In a filter mask a 1 bit means "don't care".
//!
//! [`ArbSocket`] is a thin, safe wrapper around such a socket. The [`raw`]
//! module exposes the underlying system calls with arbitrary address bytes
//! and deliberately faulting pointers, for tests of the kernel's error paths.
//! All `unsafe` code of the crate lives in [`raw`].

pub mod dsor;
pub mod raw;
mod socket;

pub use socket::{ArbSocket, RecvMsg};

use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};

/// Address family of CAN sockets (`AF_CAN`), as stored in `sa_family_t`.
pub const AF_CAN: u16 = 29;
/// Protocol family of CAN sockets (`PF_CAN`), as passed to `socket()`.
pub const PF_CAN: libc::c_int = AF_CAN as libc::c_int;
/// `AF_UNSPEC`: used with `connect()` to dissolve an association.
pub const AF_UNSPEC: u16 = 0;

/// Thesis CAN 2.0 data link protocol (`SOCK_RAW`).
pub const CANPROTO_CAN: libc::c_int = 16;
/// DSOR higher-layer protocol (`SOCK_DGRAM`).
pub const CANPROTO_DSOR: libc::c_int = 17;
/// Size of the pf_can protocol table.
pub const CANPROTO_MAX: libc::c_int = 24;

/// Arbitration field bit: extended format frame (29-bit identifier).
pub const CAN_IDE: u32 = 0x0000_0004;
/// Arbitration field bit: remote frame.
pub const CAN_RTR: u32 = 0x0000_0002;
/// Arbitration field bit 0: unused, must be 0.
pub const CAN_ARB_UNUSED: u32 = 0x0000_0001;
/// Bits 20..3: identifier extension, only meaningful with [`CAN_IDE`].
pub const CAN_ARB_EXT_BITS: u32 = 0x001F_FFF8;

/// Mask matching one identifier of one format and frame type exactly.
pub const CAN_MASK_EXACT: u32 = 0x0000_0001;
/// Mask accepting every frame.
pub const CAN_MASK_ANY: u32 = 0xFFFF_FFFF;

/// Maximum data length code (CAN 2.0).
pub const CAN_ARB_MAX_DLC: usize = 8;

/// `struct sockaddr_canarb`: the address of a CANPROTO_CAN socket.
///
/// The C struct has two bytes of implicit padding after `family`; here they
/// are the explicit field `pad`, which is zero when built by this crate.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SockaddrCanArb {
    /// Address family: [`AF_CAN`].
    pub family: u16,
    /// Padding of the C layout; zero.
    pub pad: u16,
    /// Arbitration field (bind: filter value; sendto/connect: frame).
    pub arb: u32,
    /// Filter mask, 1 bits = don't care (ignored by sendto/connect).
    pub mask: u32,
    /// Interface index, 0 = all CAN interfaces.
    pub ifindex: u32,
}

/// Size of [`SockaddrCanArb`] in bytes, the `addrlen` the kernel expects.
pub const SOCKADDR_CANARB_LEN: usize = 16;

const _: () = assert!(std::mem::size_of::<SockaddrCanArb>() == SOCKADDR_CANARB_LEN);
const _: () = assert!(std::mem::align_of::<SockaddrCanArb>() == 4);

impl SockaddrCanArb {
    /// An `AF_CAN` address.
    pub const fn new(arb: u32, mask: u32, ifindex: u32) -> Self {
        Self {
            family: AF_CAN,
            pad: 0,
            arb,
            mask,
            ifindex,
        }
    }

    /// The address as the kernel sees it (native byte order).
    pub fn to_bytes(&self) -> [u8; SOCKADDR_CANARB_LEN] {
        let mut b = [0u8; SOCKADDR_CANARB_LEN];
        b[0..2].copy_from_slice(&self.family.to_ne_bytes());
        b[2..4].copy_from_slice(&self.pad.to_ne_bytes());
        b[4..8].copy_from_slice(&self.arb.to_ne_bytes());
        b[8..12].copy_from_slice(&self.mask.to_ne_bytes());
        b[12..16].copy_from_slice(&self.ifindex.to_ne_bytes());
        b
    }

    /// Parses the kernel's representation (native byte order).
    pub fn from_bytes(b: &[u8; SOCKADDR_CANARB_LEN]) -> Self {
        let u16_at = |i: usize| u16::from_ne_bytes([b[i], b[i + 1]]);
        let u32_at = |i: usize| u32::from_ne_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Self {
            family: u16_at(0),
            pad: u16_at(2),
            arb: u32_at(4),
            mask: u32_at(8),
            ifindex: u32_at(12),
        }
    }
}

/// Arbitration field of a standard frame with 11-bit identifier `id`
/// (higher bits of `id` are ignored, as by `CAN_ARB_STD`).
pub const fn arb_std(id: u32, rtr: bool) -> u32 {
    ((id & 0x7FF) << 21) | if rtr { CAN_RTR } else { 0 }
}

/// Arbitration field of an extended frame with 29-bit identifier `id`
/// (higher bits of `id` are ignored, as by `CAN_ARB_EXT`).
pub const fn arb_ext(id: u32, rtr: bool) -> u32 {
    ((id & 0x1FFF_FFFF) << 3) | CAN_IDE | if rtr { CAN_RTR } else { 0 }
}

/// True if `arb` describes an extended format frame.
pub const fn arb_is_ext(arb: u32) -> bool {
    arb & CAN_IDE != 0
}

/// True if `arb` describes a remote frame.
pub const fn arb_is_rtr(arb: u32) -> bool {
    arb & CAN_RTR != 0
}

/// The identifier in `arb`: 11 bits for standard, 29 bits for extended frames.
pub const fn arb_id(arb: u32) -> u32 {
    if arb_is_ext(arb) {
        (arb >> 3) & 0x1FFF_FFFF
    } else {
        (arb >> 21) & 0x7FF
    }
}

/// `STD 123` or `EXT 1ABCDEF0`: format and identifier of `arb` in hex.
pub fn describe_arb(arb: u32) -> String {
    if arb_is_ext(arb) {
        format!("EXT {:08X}", arb_id(arb))
    } else {
        format!("STD {:03X}", arb_id(arb))
    }
}

/// One line per frame, as printed by the samples:
/// `can0  STD 123  [4]  DE AD BE EF`, or `... [4]  remote` for a remote
/// frame, whose DLC is `data.len()`.
pub fn format_frame(ifname: &str, arb: u32, data: &[u8]) -> String {
    let payload = if arb_is_rtr(arb) {
        "remote".to_string()
    } else {
        data.iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    format!(
        "{ifname}  {}  [{}]  {payload}",
        describe_arb(arb),
        data.len()
    )
    .trim_end()
    .to_string()
}

/// Interface index of the network interface `name` (`if_nametoindex`).
pub fn ifindex(name: &str) -> io::Result<u32> {
    raw::if_nametoindex(name)
}

/// Name of the network interface with index `ifindex` (`if_indextoname`).
pub fn ifname(ifindex: u32) -> io::Result<String> {
    raw::if_indextoname(ifindex)
}

/// `SIOCDEVPRIVATE`, the first of the device-private ioctl commands.
pub const SIOCDEVPRIVATE: libc::c_ulong = 0x89F0;

/// A device-private ioctl (`SIOCDEVPRIVATE + n`, as the rcan drivers'
/// setup ioctls) on interface `iface`: `ifr_data` points to `buf`, which
/// must be as large as the command's structure. Issued on a throw-away
/// AF_UNIX datagram socket.
pub fn dev_ioctl(iface: &str, cmd: libc::c_ulong, buf: &mut [u8]) -> io::Result<()> {
    if iface.is_empty() || iface.len() >= libc::IFNAMSIZ {
        return Err(io::Error::from_raw_os_error(libc::ENODEV));
    }
    // SAFETY: plain socket(2) call; the result is checked before use.
    let fd = unsafe { libc::socket(libc::AF_UNIX, libc::SOCK_DGRAM | libc::SOCK_CLOEXEC, 0) };
    if fd < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: `fd` was just returned by socket(2) and is owned by nobody
    // else; dropping the OwnedFd closes it.
    let sock = unsafe { OwnedFd::from_raw_fd(fd) };
    // SAFETY: an all-zero ifreq (a name and a union of integers and
    // pointers) is valid.
    let mut ifr: libc::ifreq = unsafe { std::mem::zeroed() };
    for (d, s) in ifr.ifr_name.iter_mut().zip(iface.bytes()) {
        *d = s as libc::c_char;
    }
    ifr.ifr_ifru.ifru_data = buf.as_mut_ptr().cast();
    // SAFETY: `ifr` holds a NUL-terminated name (shorter than IFNAMSIZ in
    // a zeroed buffer) and points to `buf`, writable for its length, which
    // the caller sized for `cmd`.
    let ret = unsafe { libc::ioctl(sock.as_raw_fd(), cmd, &mut ifr) };
    if ret < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sockaddr_layout() {
        assert_eq!(std::mem::size_of::<SockaddrCanArb>(), 16);
        assert_eq!(std::mem::offset_of!(SockaddrCanArb, family), 0);
        assert_eq!(std::mem::offset_of!(SockaddrCanArb, arb), 4);
        assert_eq!(std::mem::offset_of!(SockaddrCanArb, mask), 8);
        assert_eq!(std::mem::offset_of!(SockaddrCanArb, ifindex), 12);
    }

    #[test]
    fn sockaddr_bytes_round_trip() {
        let a = SockaddrCanArb::new(0x2468_0000, 0x1357_9BDF, 7);
        let b = a.to_bytes();
        assert_eq!(&b[0..2], &AF_CAN.to_ne_bytes());
        assert_eq!(&b[2..4], &[0, 0]);
        assert_eq!(&b[4..8], &0x2468_0000u32.to_ne_bytes());
        assert_eq!(&b[12..16], &7u32.to_ne_bytes());
        assert_eq!(SockaddrCanArb::from_bytes(&b), a);
    }

    #[test]
    fn arb_standard() {
        assert_eq!(arb_std(0x123, false), 0x123 << 21);
        assert_eq!(arb_std(0x7FF, false), 0xFFE0_0000);
        assert_eq!(arb_std(0x123, true), (0x123 << 21) | CAN_RTR);
        assert_eq!(arb_std(0x923, false), arb_std(0x123, false));
        assert_eq!(arb_std(0x7FF, true) & (CAN_ARB_EXT_BITS | CAN_IDE | 1), 0);
        assert_eq!(arb_id(arb_std(0x456, true)), 0x456);
        assert!(!arb_is_ext(arb_std(0x456, true)));
        assert!(arb_is_rtr(arb_std(0x456, true)));
    }

    #[test]
    fn arb_extended() {
        assert_eq!(arb_ext(0x1ABC_DEF0, false), (0x1ABC_DEF0 << 3) | CAN_IDE);
        assert_eq!(arb_ext(0x1FFF_FFFF, true), 0xFFFF_FFFE);
        assert_eq!(arb_ext(0, false), CAN_IDE);
        assert_eq!(arb_id(arb_ext(0x1ABC_DEF0, true)), 0x1ABC_DEF0);
        assert!(arb_is_ext(arb_ext(1, false)));
        assert!(!arb_is_rtr(arb_ext(1, false)));
        // The top 11 bits of a 29-bit id land where a standard id would.
        assert_eq!(
            arb_ext(0x1ABC_DEF0, false) & 0xFFE0_0000,
            arb_std(0x1ABC_DEF0 >> 18, false)
        );
    }

    #[test]
    fn header_macros_agree() {
        // CAN_ARB_STD / CAN_ARB_EXT / *_ID from rcan.h, transcribed.
        let c_std = |id: u32| (id & 0x7ff) << 21;
        let c_ext = |id: u32| ((id & 0x1fff_ffff) << 3) | CAN_IDE;
        for id in [0, 1, 0x123, 0x400, 0x7FF] {
            assert_eq!(arb_std(id, false), c_std(id));
            assert_eq!((arb_std(id, false) >> 21) & 0x7ff, id);
        }
        for id in [0, 1, 0x123, 0x1ABC_DEF0, 0x1FFF_FFFF] {
            assert_eq!(arb_ext(id, false), c_ext(id));
            assert_eq!((arb_ext(id, false) >> 3) & 0x1fff_ffff, id);
        }
    }

    #[test]
    fn formatting() {
        assert_eq!(describe_arb(arb_std(0x12, false)), "STD 012");
        assert_eq!(describe_arb(arb_ext(0x1ABC_DEF0, true)), "EXT 1ABCDEF0");
        assert_eq!(
            format_frame("can0", arb_std(0x123, false), &[0xDE, 0xAD, 0xBE, 0xEF]),
            "can0  STD 123  [4]  DE AD BE EF"
        );
        assert_eq!(
            format_frame("can0", arb_std(0x456, true), &[0; 4]),
            "can0  STD 456  [4]  remote"
        );
        assert_eq!(
            format_frame(
                "can1",
                arb_ext(0x1ABC_DEF0, false),
                &[0, 1, 2, 3, 4, 5, 6, 7]
            ),
            "can1  EXT 1ABCDEF0  [8]  00 01 02 03 04 05 06 07"
        );
        assert_eq!(
            format_frame("can0", arb_std(1, false), &[]),
            "can0  STD 001  [0]"
        );
    }
}
