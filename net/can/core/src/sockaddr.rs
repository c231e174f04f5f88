// SPDX-License-Identifier: GPL-2.0
//! `struct sockaddr_canarb`, the address of the CAN socket API
//! (thesis 5.2.1 and 5.2.4; arbitration field thesis 5.2.2, figure 5-5).
//!
//! ```text
//! struct sockaddr_canarb {        offset
//!     sa_family_t  family;        0   (u16, then 2 bytes padding)
//!     __u32        arb;           4
//!     __u32        mask;          8
//!     unsigned int ifindex;       12
//! };                              16 bytes, native endian
//! ```

use super::arb::{Arb, ArbError, EINVAL};
use super::filter::{ArbFilter, Receiver};

/// Address family of CAN sockets.
pub const AF_CAN: u16 = 29;
/// Unspecified address family.
pub const AF_UNSPEC: u16 = 0;
/// Size of `struct sockaddr_canarb`.
pub const SOCKADDR_CANARB_LEN: usize = 16;

/// A parsed `struct sockaddr_canarb`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct SockaddrArb {
    /// Address family (`AF_CAN`).
    pub family: u16,
    /// Arbitration field (bind: filter pattern; sendto/connect: destination).
    pub arb: u32,
    /// Filter mask, 1 bits = don't care (bind only).
    pub mask: u32,
    /// Interface index; 0 = all CAN interfaces.
    pub ifindex: u32,
}

/// Why a socket address is invalid.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum AddrError {
    /// Fewer than [`SOCKADDR_CANARB_LEN`] bytes.
    TooShort,
    /// `family` is not `AF_CAN`.
    BadFamily,
    /// The arbitration field is invalid for this use.
    BadArb(ArbError),
    /// `ifindex` does not fit a (non-negative) `int`.
    BadIfindex,
}

impl AddrError {
    /// Positive Linux errno for this error (always `EINVAL`).
    pub const fn errno(self) -> i32 {
        EINVAL
    }
}

/// Parses a user-space address. Bytes beyond the first 16 are ignored.
///
/// Checks the length, the family and the interface index; the arbitration
/// field is validated by [`SockaddrArb::bind_filter`] or
/// [`SockaddrArb::dest`], depending on its use.
pub fn parse(bytes: &[u8]) -> Result<SockaddrArb, AddrError> {
    let Some(b) = bytes.first_chunk::<SOCKADDR_CANARB_LEN>() else {
        return Err(AddrError::TooShort);
    };
    let family = u16::from_ne_bytes([b[0], b[1]]);
    if family != AF_CAN {
        return Err(AddrError::BadFamily);
    }
    let addr = SockaddrArb {
        family,
        arb: u32::from_ne_bytes([b[4], b[5], b[6], b[7]]),
        mask: u32::from_ne_bytes([b[8], b[9], b[10], b[11]]),
        ifindex: u32::from_ne_bytes([b[12], b[13], b[14], b[15]]),
    };
    addr.ifindex_i32()?;
    Ok(addr)
}

impl SockaddrArb {
    /// The 16-byte image for user space; the padding bytes are zero.
    pub fn encode(&self) -> [u8; SOCKADDR_CANARB_LEN] {
        let f = self.family.to_ne_bytes();
        let a = self.arb.to_ne_bytes();
        let m = self.mask.to_ne_bytes();
        let i = self.ifindex.to_ne_bytes();
        [
            f[0], f[1], 0, 0, a[0], a[1], a[2], a[3], m[0], m[1], m[2], m[3], i[0], i[1], i[2],
            i[3],
        ]
    }

    /// The receiver registered by `bind()`: filter (`arb`, `mask`) on
    /// `ifindex`. [`AddrError::BadArb`] if bit 0 of `arb` is set.
    pub fn bind_filter(&self) -> Result<Receiver, AddrError> {
        let filter = ArbFilter::new(self.arb, self.mask).map_err(AddrError::BadArb)?;
        Ok(Receiver {
            ifindex: self.ifindex_i32()?,
            filter,
        })
    }

    /// The destination of `sendto()`/`connect()`: a valid arbitration field
    /// and an interface index (`mask` is ignored).
    pub fn dest(&self) -> Result<(Arb, i32), AddrError> {
        let arb = Arb::from_raw(self.arb).map_err(AddrError::BadArb)?;
        Ok((arb, self.ifindex_i32()?))
    }

    fn ifindex_i32(&self) -> Result<i32, AddrError> {
        i32::try_from(self.ifindex).map_err(|_| AddrError::BadIfindex)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> SockaddrArb {
        SockaddrArb {
            family: AF_CAN,
            arb: 0x123 << 21,
            mask: 0x1F_FFFF,
            ifindex: 3,
        }
    }

    #[test]
    fn round_trip() {
        let a = sample();
        let b = a.encode();
        assert_eq!(&b[2..4], &[0, 0]);
        assert_eq!(parse(&b), Ok(a));
        let mut long = [0xAAu8; 20];
        long[..16].copy_from_slice(&b);
        assert_eq!(parse(&long), Ok(a));
    }

    #[test]
    fn errors() {
        let b = sample().encode();
        assert_eq!(parse(&b[..15]), Err(AddrError::TooShort));
        assert_eq!(parse(&[]), Err(AddrError::TooShort));
        let bad = SockaddrArb {
            family: AF_UNSPEC,
            ..sample()
        };
        assert_eq!(parse(&bad.encode()), Err(AddrError::BadFamily));
        let bad = SockaddrArb {
            ifindex: 0x8000_0000,
            ..sample()
        };
        assert_eq!(parse(&bad.encode()), Err(AddrError::BadIfindex));
        assert_eq!(bad.dest(), Err(AddrError::BadIfindex));
        assert_eq!(AddrError::TooShort.errno(), 22);
    }

    #[test]
    fn uses() {
        let a = sample();
        let r = a.bind_filter().unwrap();
        assert_eq!(r.ifindex, 3);
        assert_eq!(r.filter.mask(), 0x1F_FFFF);
        assert_eq!(a.dest(), Ok((Arb::std(0x123, false).unwrap(), 3)));
        let odd = SockaddrArb { arb: 0x9, ..a };
        assert_eq!(
            odd.bind_filter(),
            Err(AddrError::BadArb(ArbError::UnusedBitSet))
        );
        let ext_bits = SockaddrArb { arb: 0x8, ..a };
        assert!(ext_bits.bind_filter().is_ok());
        assert_eq!(
            ext_bits.dest(),
            Err(AddrError::BadArb(ArbError::ExtBitsInStandard))
        );
    }
}
