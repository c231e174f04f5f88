// SPDX-License-Identifier: GPL-2.0
//! The CAN frame as carried in socket buffers: byte-identical to mainline
//! `struct can_frame`, with conversions from and to the arbitration field of
//! the CAN socket API (thesis 5.2.2, figure 5-5; frames thesis 5.2.3).
//!
//! The CAN FD frame (`struct canfd_frame`) and the ISO 11898-1:2015 data
//! length code mapping are here too (Documentation/networking/rcan/can-fd.rst).
//!
//! `can_id` is in host byte order, as in the skb.

use super::arb::{Arb, EINVAL, MAX_DLC};

/// Mainline `struct can_frame` (16 bytes).
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct CanFrame {
    /// Canonical identifier with `CAN_EFF_FLAG`/`CAN_RTR_FLAG`/`CAN_ERR_FLAG`.
    pub can_id: u32,
    /// Data length code (0..=8).
    pub len: u8,
    /// Padding.
    pub pad: u8,
    /// Reserved.
    pub res0: u8,
    /// Raw DLC 9..15 for `len == 8` (mainline `CAN_CTRLMODE_CC_LEN8_DLC`).
    pub len8_dlc: u8,
    /// Payload; bytes beyond `len` are zero in frames built here.
    pub data: [u8; MAX_DLC],
}

const _: () = assert!(core::mem::size_of::<CanFrame>() == 16);

/// Size of [`CanFrame`] in bytes.
pub const CAN_FRAME_LEN: usize = 16;

/// Why a frame cannot be built or used.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum FrameError {
    /// The data length code exceeds 8.
    DlcTooLarge,
    /// A data frame was given fewer bytes than its data length code.
    DataTooShort,
    /// The frame is an error frame (`CAN_ERR_FLAG`), which has no
    /// arbitration field.
    ErrorFrame,
}

impl FrameError {
    /// Positive Linux errno for this error (always `EINVAL`).
    pub const fn errno(self) -> i32 {
        EINVAL
    }
}

impl CanFrame {
    /// Builds a frame with field `arb` and data length code `dlc`.
    ///
    /// Data frames copy `data[..dlc]` (extra bytes are ignored); remote
    /// frames ignore `data` and carry `dlc` with all data bytes zero.
    /// Unused data bytes, `pad`, `res0` and `len8_dlc` are zero.
    pub fn from_arb(arb: Arb, dlc: usize, data: &[u8]) -> Result<CanFrame, FrameError> {
        if dlc > MAX_DLC {
            return Err(FrameError::DlcTooLarge);
        }
        let mut frame = CanFrame {
            can_id: arb.to_can_id(),
            // dlc <= 8, so this does not truncate.
            len: dlc as u8,
            ..CanFrame::default()
        };
        if !arb.is_rtr() {
            let src = data.get(..dlc).ok_or(FrameError::DataTooShort)?;
            frame.data[..dlc].copy_from_slice(src);
        }
        Ok(frame)
    }

    /// The arbitration field; `None` for error frames.
    pub fn arb(&self) -> Option<Arb> {
        Arb::from_can_id(self.can_id)
    }

    /// The arbitration field; [`FrameError::ErrorFrame`] for error frames.
    pub fn try_arb(&self) -> Result<Arb, FrameError> {
        self.arb().ok_or(FrameError::ErrorFrame)
    }

    /// The data length code, clamped to 8.
    pub fn dlc(&self) -> usize {
        usize::from(self.len).min(MAX_DLC)
    }

    /// `data[..dlc]` (all zero for remote frames built by [`Self::from_arb`]).
    pub fn payload(&self) -> &[u8] {
        &self.data[..self.dlc()]
    }

    /// The 16-byte wire image (native-endian `can_id`).
    pub fn to_bytes(self) -> [u8; CAN_FRAME_LEN] {
        let id = self.can_id.to_ne_bytes();
        let d = self.data;
        [
            id[0],
            id[1],
            id[2],
            id[3],
            self.len,
            self.pad,
            self.res0,
            self.len8_dlc,
            d[0],
            d[1],
            d[2],
            d[3],
            d[4],
            d[5],
            d[6],
            d[7],
        ]
    }

    /// Parses a 16-byte image (native-endian `can_id`). Every image is
    /// accepted; validation is up to the user of the frame.
    pub fn from_bytes(b: &[u8; CAN_FRAME_LEN]) -> CanFrame {
        CanFrame {
            can_id: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
            len: b[4],
            pad: b[5],
            res0: b[6],
            len8_dlc: b[7],
            data: [b[8], b[9], b[10], b[11], b[12], b[13], b[14], b[15]],
        }
    }
}

/// `CAN_MTU`: the size of a classic frame in an skb and on a socket.
pub const CAN_MTU: usize = 16;

/// Size of [`CanFdFrame`] in bytes (mainline `CANFD_MTU`).
pub const CANFD_MTU: usize = 72;
/// Most payload bytes of a CAN FD frame (`CANFD_MAX_DLEN`).
pub const CANFD_MAX_DLEN: usize = 64;
/// Largest CAN FD data length code (`CANFD_MAX_DLC`).
pub const CANFD_MAX_DLC: u8 = 15;
/// `CANFD_BRS`: bit rate switch (the data phase at the second bit rate).
pub const CANFD_BRS: u8 = 0x01;
/// `CANFD_ESI`: error state indicator of the transmitting node.
pub const CANFD_ESI: u8 = 0x02;
/// `CANFD_FDF`: marks a CAN FD frame in `flags` (mainline `can_send`
/// sets it on every FD frame it sends).
pub const CANFD_FDF: u8 = 0x04;

/// Mainline `struct canfd_frame` (72 bytes): the classic layout with
/// `flags` in place of `pad` and 64 data bytes.
#[repr(C)]
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct CanFdFrame {
    /// Canonical identifier with `CAN_EFF_FLAG`/`CAN_ERR_FLAG` (CAN FD has
    /// no remote frames).
    pub can_id: u32,
    /// Payload length in bytes (0..=64; on the bus one of the 16 lengths
    /// [`can_fd_dlc2len`] gives).
    pub len: u8,
    /// `CANFD_BRS`, `CANFD_ESI`, `CANFD_FDF`.
    pub flags: u8,
    /// Reserved.
    pub res0: u8,
    /// Reserved.
    pub res1: u8,
    /// Payload; bytes beyond `len` are zero in frames built here.
    pub data: [u8; CANFD_MAX_DLEN],
}

const _: () = assert!(core::mem::size_of::<CanFdFrame>() == CANFD_MTU);

impl Default for CanFdFrame {
    fn default() -> Self {
        CanFdFrame {
            can_id: 0,
            len: 0,
            flags: 0,
            res0: 0,
            res1: 0,
            data: [0; CANFD_MAX_DLEN],
        }
    }
}

/// Payload length of each CAN FD data length code (ISO 11898-1:2015,
/// table of section 8.4.2.4; mainline `dlc2len`).
const DLC2LEN: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// Mainline `can_fd_dlc2len`: the payload length of CAN FD data length
/// code `dlc` (only its low four bits count).
pub const fn can_fd_dlc2len(dlc: u8) -> u8 {
    DLC2LEN[(dlc & 0x0F) as usize]
}

/// Mainline `can_fd_len2dlc`: the smallest CAN FD data length code whose
/// payload holds `len` bytes; 15 for anything above 64.
pub const fn can_fd_len2dlc(len: u8) -> u8 {
    if len <= 8 {
        return len;
    }
    let mut dlc = 9;
    while dlc < CANFD_MAX_DLC && DLC2LEN[dlc as usize] < len {
        dlc += 1;
    }
    dlc
}

impl CanFdFrame {
    /// `data[..len]` with `len` clamped to 64.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len).min(CANFD_MAX_DLEN)]
    }

    /// The 72-byte wire image (native-endian `can_id`).
    pub fn to_bytes(&self) -> [u8; CANFD_MTU] {
        let mut b = [0u8; CANFD_MTU];
        b[..4].copy_from_slice(&self.can_id.to_ne_bytes());
        b[4] = self.len;
        b[5] = self.flags;
        b[6] = self.res0;
        b[7] = self.res1;
        b[8..].copy_from_slice(&self.data);
        b
    }

    /// Parses a 72-byte image (native-endian `can_id`). Every image is
    /// accepted; validation is up to the user of the frame.
    pub fn from_bytes(b: &[u8; CANFD_MTU]) -> CanFdFrame {
        let mut data = [0u8; CANFD_MAX_DLEN];
        data.copy_from_slice(&b[8..]);
        CanFdFrame {
            can_id: u32::from_ne_bytes([b[0], b[1], b[2], b[3]]),
            len: b[4],
            flags: b[5],
            res0: b[6],
            res1: b[7],
            data,
        }
    }
}

/// A frame of either flavour as the stack carries it in an skb. Which one
/// a buffer holds is told by its length alone, as in mainline
/// (`can_is_can_skb`, `can_is_canfd_skb`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum AnyFrame {
    /// A classic frame (16 bytes, `len <= 8`).
    Classic(CanFrame),
    /// A CAN FD frame (72 bytes, `len <= 64`).
    Fd(CanFdFrame),
}

impl AnyFrame {
    /// Mainline `can_is_can_skb` / `can_is_canfd_skb` on `bytes`: a
    /// classic frame if 16 bytes with `len <= 8`, an FD frame if 72 bytes
    /// with `len <= 64`, else `None` (malformed, or CAN XL).
    pub fn parse(bytes: &[u8]) -> Option<AnyFrame> {
        if let Ok(b) = <&[u8; CAN_FRAME_LEN]>::try_from(bytes) {
            let f = CanFrame::from_bytes(b);
            return (usize::from(f.len) <= MAX_DLC).then_some(AnyFrame::Classic(f));
        }
        if let Ok(b) = <&[u8; CANFD_MTU]>::try_from(bytes) {
            let f = CanFdFrame::from_bytes(b);
            return (usize::from(f.len) <= CANFD_MAX_DLEN).then_some(AnyFrame::Fd(f));
        }
        None
    }

    /// Which flavour [`AnyFrame::parse`] would find in `bytes`, without
    /// building the frame: `Some(false)` classic, `Some(true)` CAN FD,
    /// `None` exactly when `parse` gives `None`. Mainline `can_send`'s
    /// checks (the buffer's length, then the frame's `len`), for a send
    /// path that only needs to know which and that the frame is sound.
    pub fn kind(bytes: &[u8]) -> Option<bool> {
        let len = usize::from(*bytes.get(4)?);
        match bytes.len() {
            CAN_FRAME_LEN => (len <= MAX_DLC).then_some(false),
            CANFD_MTU => (len <= CANFD_MAX_DLEN).then_some(true),
            _ => None,
        }
    }

    /// What [`AnyFrame::parse`] would give as `(can_id(), payload,
    /// is_fd())`, read in place: the identifier with its flags, the
    /// payload (`data[..len]`) as a slice of `bytes`, and the flavour;
    /// `None` exactly when `parse` gives `None`. For a receive path that
    /// only reads the frame (no 72-byte copy).
    pub fn view(bytes: &[u8]) -> Option<(u32, &[u8], bool)> {
        let fd = AnyFrame::kind(bytes)?;
        let len = usize::from(bytes[4]);
        let can_id = u32::from_ne_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        Some((can_id, bytes.get(8..8 + len)?, fd))
    }

    /// The identifier with its flags.
    pub fn can_id(&self) -> u32 {
        match self {
            AnyFrame::Classic(f) => f.can_id,
            AnyFrame::Fd(f) => f.can_id,
        }
    }

    /// Payload length in bytes (what device statistics count).
    pub fn len(&self) -> usize {
        match self {
            AnyFrame::Classic(f) => f.dlc(),
            AnyFrame::Fd(f) => f.payload().len(),
        }
    }

    /// Whether the payload is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether this is a CAN FD frame.
    pub fn is_fd(&self) -> bool {
        matches!(self, AnyFrame::Fd(_))
    }

    /// The size of the frame's image (`CAN_MTU` or `CANFD_MTU`).
    pub fn mtu(&self) -> usize {
        if self.is_fd() {
            CANFD_MTU
        } else {
            CAN_MTU
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::arb::CAN_ERR_FLAG;
    use super::*;

    /// Mainline's `len2dlc` table (drivers/net/can/dev/length.c), copied
    /// as data to test against.
    const MAINLINE_LEN2DLC: [u8; 65] = [
        0, 1, 2, 3, 4, 5, 6, 7, 8, // 0 - 8
        9, 9, 9, 9, // 9 - 12
        10, 10, 10, 10, // 13 - 16
        11, 11, 11, 11, // 17 - 20
        12, 12, 12, 12, // 21 - 24
        13, 13, 13, 13, 13, 13, 13, 13, // 25 - 32
        14, 14, 14, 14, 14, 14, 14, 14, // 33 - 40
        14, 14, 14, 14, 14, 14, 14, 14, // 41 - 48
        15, 15, 15, 15, 15, 15, 15, 15, // 49 - 56
        15, 15, 15, 15, 15, 15, 15, 15, // 57 - 64
    ];

    #[test]
    fn fd_dlc_tables_match_mainline() {
        for len in 0..=255u8 {
            let want = if usize::from(len) <= CANFD_MAX_DLEN {
                MAINLINE_LEN2DLC[usize::from(len)]
            } else {
                CANFD_MAX_DLC
            };
            assert_eq!(can_fd_len2dlc(len), want, "len {len}");
        }
        let lens: Vec<u8> = (0..16).map(can_fd_dlc2len).collect();
        assert_eq!(
            lens,
            [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64]
        );
        // Only the low nibble counts.
        for dlc in 0..=255u8 {
            assert_eq!(can_fd_dlc2len(dlc), can_fd_dlc2len(dlc & 0xF));
        }
    }

    #[test]
    fn fd_dlc_round_trip() {
        for dlc in 0..=CANFD_MAX_DLC {
            assert_eq!(can_fd_len2dlc(can_fd_dlc2len(dlc)), dlc);
        }
        // The dlc chosen for a length holds it, and no smaller dlc does.
        for len in 0..=CANFD_MAX_DLEN as u8 {
            let dlc = can_fd_len2dlc(len);
            assert!(can_fd_dlc2len(dlc) >= len);
            assert!(dlc == 0 || can_fd_dlc2len(dlc - 1) < len);
        }
    }

    #[test]
    fn fd_frame_image() {
        let mut f = CanFdFrame {
            can_id: 0x8000_0123,
            len: 12,
            flags: CANFD_BRS | CANFD_ESI,
            ..CanFdFrame::default()
        };
        for (i, b) in f.data[..12].iter_mut().enumerate() {
            *b = i as u8 + 1;
        }
        let b = f.to_bytes();
        assert_eq!(b.len(), 72);
        assert_eq!(&b[..4], &0x8000_0123u32.to_ne_bytes());
        assert_eq!((b[4], b[5]), (12, 3));
        assert_eq!(&b[8..20], &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(CanFdFrame::from_bytes(&b), f);
        assert_eq!(f.payload().len(), 12);
        assert_eq!(AnyFrame::parse(&b), Some(AnyFrame::Fd(f)));
    }

    #[test]
    fn any_frame_by_length() {
        let c = CanFrame {
            can_id: 0x123,
            len: 8,
            ..CanFrame::default()
        };
        let p = AnyFrame::parse(&c.to_bytes()).unwrap();
        assert!(!p.is_fd());
        assert_eq!((p.can_id(), p.len(), p.mtu()), (0x123, 8, CAN_MTU));
        let mut bad = c.to_bytes();
        bad[4] = 9;
        assert_eq!(AnyFrame::parse(&bad), None);
        let mut fd = CanFdFrame::default().to_bytes();
        fd[4] = 64;
        assert_eq!(
            AnyFrame::parse(&fd).map(|f| (f.len(), f.mtu())),
            Some((64, 72))
        );
        fd[4] = 65;
        assert_eq!(AnyFrame::parse(&fd), None);
        for n in [0, 15, 17, 71, 73, 2060] {
            assert_eq!(AnyFrame::parse(&vec![0u8; n]), None, "{n} bytes");
        }
    }

    #[test]
    fn data_frame() {
        let a = Arb::std(0x123, false).unwrap();
        let f = CanFrame::from_arb(a, 2, &[0xDE, 0xAD, 0xBE]).unwrap();
        assert_eq!(f.can_id, 0x123);
        assert_eq!(f.payload(), &[0xDE, 0xAD]);
        assert_eq!(f.data, [0xDE, 0xAD, 0, 0, 0, 0, 0, 0]);
        assert_eq!(f.arb(), Some(a));
        assert_eq!(CanFrame::from_bytes(&f.to_bytes()), f);
    }

    #[test]
    fn remote_frame() {
        let a = Arb::ext(0x1234_5678, true).unwrap();
        let f = CanFrame::from_arb(a, 8, &[]).unwrap();
        assert_eq!(f.len, 8);
        assert_eq!(f.data, [0; 8]);
        assert_eq!(f.try_arb(), Ok(a));
    }

    #[test]
    fn bounds() {
        let a = Arb::std(1, false).unwrap();
        assert_eq!(
            CanFrame::from_arb(a, 9, &[0; 9]),
            Err(FrameError::DlcTooLarge)
        );
        assert_eq!(
            CanFrame::from_arb(a, 3, &[0; 2]),
            Err(FrameError::DataTooShort)
        );
        let f = CanFrame {
            len: 15,
            ..CanFrame::default()
        };
        assert_eq!(f.dlc(), 8);
        let e = CanFrame {
            can_id: CAN_ERR_FLAG | 4,
            ..CanFrame::default()
        };
        assert_eq!(e.arb(), None);
        assert_eq!(e.try_arb(), Err(FrameError::ErrorFrame));
        assert_eq!(FrameError::ErrorFrame.errno(), 22);
    }
}
