// SPDX-License-Identifier: GPL-2.0
//! The CAN frame as carried in socket buffers: byte-identical to mainline
//! `struct can_frame`, with conversions from and to the arbitration field of
//! the CAN socket API (thesis 5.2.2, figure 5-5; frames thesis 5.2.3).
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

#[cfg(test)]
mod tests {
    use super::super::arb::CAN_ERR_FLAG;
    use super::*;

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
