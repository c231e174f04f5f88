// SPDX-License-Identifier: GPL-2.0
//! The CAN_BCM (broadcast manager) message format of mainline
//! `include/uapi/linux/can/bcm.h`, and the checks mainline's
//! `net/can/bcm.c` (`bcm_sendmsg`, `bcm_tx_setup`, `bcm_rx_setup`) makes on
//! every message user space writes, with the same errno in the same order.
//!
//! A message is a [`MsgHead`] (56 bytes on 64-bit: see [`MHSIZ`]) followed by
//! `nframes` frames of 16 bytes (`struct can_frame`) or, with
//! [`CAN_FD_FRAME`], 72 bytes (`struct canfd_frame`). One message per
//! `write()`/`sendmsg()`; replies and notifications come back in the same
//! format from `read()`.
//!
//! The per-operation state machines are in [`super::bcm_tx`] (cyclic
//! transmission) and [`super::bcm_rx`] (content filtering); this file only
//! encodes, decodes and validates. Pure, allocation-free: the kernel module
//! hands in the bytes it copied from user space.

use super::arb::EINVAL;
use super::frame::{CanFdFrame, CanFrame, CANFD_MTU, CAN_FRAME_LEN};

/// Linux `E2BIG`: an update brings more frames than the operation holds.
pub const E2BIG: i32 = 7;
/// Linux `EFAULT`: the message is shorter than its `nframes` announces
/// (mainline's `memcpy_from_msg` runs out of bytes).
pub const EFAULT: i32 = 14;
/// Linux `ENODEV`: a transmit opcode on a socket connected to "any"
/// interface (ifindex 0).
pub const ENODEV: i32 = 19;

/// `TX_SETUP`: create or update a (cyclic) transmission.
pub const TX_SETUP: u32 = 1;
/// `TX_DELETE`: remove a transmission.
pub const TX_DELETE: u32 = 2;
/// `TX_READ`: ask for a `TX_STATUS` reply with the transmission's state.
pub const TX_READ: u32 = 3;
/// `TX_SEND`: send one frame once.
pub const TX_SEND: u32 = 4;
/// `RX_SETUP`: create or update a content filter subscription.
pub const RX_SETUP: u32 = 5;
/// `RX_DELETE`: remove a subscription.
pub const RX_DELETE: u32 = 6;
/// `RX_READ`: ask for an `RX_STATUS` reply.
pub const RX_READ: u32 = 7;
/// Reply to `TX_READ`.
pub const TX_STATUS: u32 = 8;
/// Notification: the `count` transmissions at `ival1` are done
/// (with [`TX_COUNTEVT`]).
pub const TX_EXPIRED: u32 = 9;
/// Reply to `RX_READ`.
pub const RX_STATUS: u32 = 10;
/// Notification: no matching frame for `ival1`.
pub const RX_TIMEOUT: u32 = 11;
/// Notification: a received frame changed (under the filter mask).
pub const RX_CHANGED: u32 = 12;

/// Take `ival1`, `ival2` (and for TX, `count`) from this message.
pub const SETTIMER: u32 = 0x0001;
/// Start the timer with the values now in the operation.
pub const STARTTIMER: u32 = 0x0002;
/// TX: send `TX_EXPIRED` when `count` reaches 0 in the timer.
pub const TX_COUNTEVT: u32 = 0x0004;
/// TX: send the current frame at once, before the first timer expiry.
pub const TX_ANNOUNCE: u32 = 0x0008;
/// TX (and RX with [`RX_RTR_FRAME`]): copy the head's `can_id` into the frames.
pub const TX_CP_CAN_ID: u32 = 0x0010;
/// RX: filter on the identifier only, every frame is "changed".
pub const RX_FILTER_ID: u32 = 0x0020;
/// RX: a change of the length alone counts as a change.
pub const RX_CHECK_DLC: u32 = 0x0040;
/// RX: do not restart the timeout on each received frame.
pub const RX_NO_AUTOTIMER: u32 = 0x0080;
/// RX: after an `RX_TIMEOUT`, the next frame is reported as changed.
pub const RX_ANNOUNCE_RESUME: u32 = 0x0100;
/// TX: an update restarts a multi-frame sequence at its first frame.
pub const TX_RESET_MULTI_IDX: u32 = 0x0200;
/// RX: answer a remote frame with the frame in the message.
pub const RX_RTR_FRAME: u32 = 0x0400;
/// The frames in the message are `struct canfd_frame` (72 bytes).
pub const CAN_FD_FRAME: u32 = 0x0800;

/// Size of `struct bcm_msg_head` on LP64 (x86_64): three `u32` (12 bytes),
/// 4 bytes of padding so that the two `struct bcm_timeval { long, long }`
/// start 8-aligned (offsets 16 and 32), then `can_id` at 48 and `nframes`
/// at 52. The flexible array of frames starts at 56, which is also 8-aligned
/// as `struct can_frame` needs.
pub const MHSIZ: usize = 56;
/// Size of a CAN FD frame (`struct canfd_frame`, `CANFD_MTU`).
pub const CANFD_FRAME_LEN: usize = 72;
/// Most frames in a `TX_SETUP` (and mux entries in an `RX_SETUP`, which
/// may carry one more: the mux mask). Mainline's reason: a one-byte index.
pub const MAX_NFRAMES: u32 = 256;
/// Largest timer seconds mainline accepts: 400 days.
pub const BCM_TIMER_SEC_MAX: i64 = 400 * 24 * 60 * 60;

/// `struct bcm_timeval` (two `long`s on LP64).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct BcmTimeval {
    /// Seconds.
    pub sec: i64,
    /// Microseconds.
    pub usec: i64,
}

impl BcmTimeval {
    /// Whether mainline accepts it (`bcm_is_invalid_tv`): seconds in
    /// `0..=400 days`, microseconds in `0..1_000_000`.
    pub const fn is_valid(self) -> bool {
        self.sec >= 0 && self.sec <= BCM_TIMER_SEC_MAX && self.usec >= 0 && self.usec < 1_000_000
    }

    /// The interval in nanoseconds (`bcm_timeval_to_ktime`); 0 for an
    /// invalid value (never reached: setups reject them first).
    pub const fn to_ns(self) -> u64 {
        if !self.is_valid() {
            return 0;
        }
        self.sec as u64 * 1_000_000_000 + self.usec as u64 * 1_000
    }

    /// Builds one from microseconds (test and tool convenience).
    pub const fn from_us(us: u64) -> Self {
        Self {
            sec: (us / 1_000_000) as i64,
            usec: (us % 1_000_000) as i64,
        }
    }
}

/// `struct bcm_msg_head`, host byte order.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct MsgHead {
    /// One of `TX_SETUP` .. `RX_CHANGED`.
    pub opcode: u32,
    /// `SETTIMER` .. `CAN_FD_FRAME`.
    pub flags: u32,
    /// Number of transmissions at `ival1` (TX).
    pub count: u32,
    /// First interval (TX: while `count` > 0; RX: timeout).
    pub ival1: BcmTimeval,
    /// Second interval (TX: after `count`; RX: throttle).
    pub ival2: BcmTimeval,
    /// The identifier the operation is about (with EFF/RTR flags).
    pub can_id: u32,
    /// Number of frames following the head.
    pub nframes: u32,
}

impl MsgHead {
    /// Decodes the 56-byte image (native endian, padding ignored).
    pub fn from_bytes(b: &[u8; MHSIZ]) -> Self {
        let u32_at = |o: usize| u32::from_ne_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
        let i64_at = |o: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[o..o + 8]);
            i64::from_ne_bytes(w)
        };
        Self {
            opcode: u32_at(0),
            flags: u32_at(4),
            count: u32_at(8),
            ival1: BcmTimeval {
                sec: i64_at(16),
                usec: i64_at(24),
            },
            ival2: BcmTimeval {
                sec: i64_at(32),
                usec: i64_at(40),
            },
            can_id: u32_at(48),
            nframes: u32_at(52),
        }
    }

    /// The 56-byte image, padding zeroed (as mainline's `memset` does for
    /// the notifications it builds).
    pub fn to_bytes(&self) -> [u8; MHSIZ] {
        let mut b = [0u8; MHSIZ];
        b[0..4].copy_from_slice(&self.opcode.to_ne_bytes());
        b[4..8].copy_from_slice(&self.flags.to_ne_bytes());
        b[8..12].copy_from_slice(&self.count.to_ne_bytes());
        b[16..24].copy_from_slice(&self.ival1.sec.to_ne_bytes());
        b[24..32].copy_from_slice(&self.ival1.usec.to_ne_bytes());
        b[32..40].copy_from_slice(&self.ival2.sec.to_ne_bytes());
        b[40..48].copy_from_slice(&self.ival2.usec.to_ne_bytes());
        b[48..52].copy_from_slice(&self.can_id.to_ne_bytes());
        b[52..56].copy_from_slice(&self.nframes.to_ne_bytes());
        b
    }

    /// Size of one frame after this head: 72 with [`CAN_FD_FRAME`], else 16
    /// (mainline's `CFSIZ`).
    pub const fn cfsiz(&self) -> usize {
        if self.flags & CAN_FD_FRAME != 0 {
            CANFD_FRAME_LEN
        } else {
            CAN_FRAME_LEN
        }
    }

    /// Whether both intervals pass mainline's `bcm_is_invalid_tv`.
    pub const fn ivals_valid(&self) -> bool {
        self.ival1.is_valid() && self.ival2.is_valid()
    }
}

/// A message written by user space, after the checks every opcode shares
/// ([`parse`]); the opcode's own checks follow in [`check_tx_setup`],
/// [`check_rx_setup`] and [`check_tx_send`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Request<'a> {
    /// The head as written.
    pub head: MsgHead,
    /// The bytes after the head: a whole number of `head.cfsiz()` frames,
    /// not necessarily `nframes` of them.
    pub payload: &'a [u8],
}

/// The checks of `bcm_sendmsg` before it looks at the opcode: a whole head
/// (else `EINVAL`), a whole number of frames after it (else `EINVAL`), and a
/// known request opcode (else `EINVAL`; the reply opcodes `TX_STATUS` ..
/// `RX_CHANGED` are unknown as requests). A socket that is not connected
/// gets `ENOTCONN` before any of this: that is the socket's business.
pub fn parse(msg: &[u8]) -> Result<Request<'_>, i32> {
    let head_bytes: &[u8; MHSIZ] = msg
        .get(..MHSIZ)
        .and_then(|h| h.try_into().ok())
        .ok_or(EINVAL)?;
    let head = MsgHead::from_bytes(head_bytes);
    let payload = &msg[MHSIZ..];
    if !payload.len().is_multiple_of(head.cfsiz()) {
        return Err(EINVAL);
    }
    if !(TX_SETUP..=RX_READ).contains(&head.opcode) {
        return Err(EINVAL);
    }
    Ok(Request { head, payload })
}

/// Frame `i` of a classic payload (16-byte frames); `None` past its end.
pub fn classic_frame(payload: &[u8], i: usize) -> Option<CanFrame> {
    let b = payload.get(i * CAN_FRAME_LEN..(i + 1) * CAN_FRAME_LEN)?;
    b.try_into().ok().map(CanFrame::from_bytes)
}

/// A classic frame in the CAN FD layout: `struct can_frame` is the first
/// 16 bytes of `struct canfd_frame` (`pad` is `flags`, `len8_dlc` is
/// `res1`), the data bytes past 8 are zero. The BCM core keeps every frame
/// so, as mainline's `bcm.c` keeps both kinds in `struct canfd_frame`
/// pointers and uses the first `cfsiz` bytes.
pub fn widen(f: &CanFrame) -> CanFdFrame {
    let mut b = [0u8; CANFD_MTU];
    b[..CAN_FRAME_LEN].copy_from_slice(&f.to_bytes());
    CanFdFrame::from_bytes(&b)
}

/// Frame `i` of a payload of `cfsiz`-byte frames (16 or 72), in the CAN
/// FD layout ([`widen`]); `None` past its end.
pub fn frame_at(payload: &[u8], cfsiz: usize, i: usize) -> Option<CanFdFrame> {
    let cfsiz = cfsiz.min(CANFD_MTU);
    let src = payload.get(i * cfsiz..(i + 1) * cfsiz)?;
    let mut b = [0u8; CANFD_MTU];
    b[..cfsiz].copy_from_slice(src);
    Some(CanFdFrame::from_bytes(&b))
}

/// The 8-byte word `w` (0..8) of a frame's data in native byte order, as
/// mainline's `get_u64(frame, 8 * w)` reads it; the unit of every
/// mask comparison.
pub fn data_word(f: &CanFdFrame, w: usize) -> u64 {
    let mut b = [0u8; 8];
    if let Some(s) = f.data.get(8 * w..8 * w + 8) {
        b.copy_from_slice(s);
    }
    u64::from_ne_bytes(b)
}

/// The `len` byte of frame `i` (offset 4 in both frame layouts).
fn frame_len(payload: &[u8], cfsiz: usize, i: usize) -> Option<u8> {
    payload.get(i * cfsiz + 4).copied()
}

/// Largest payload length of a frame of this message: 64 for CAN FD, 8.
const fn max_len(head: &MsgHead) -> u8 {
    if head.flags & CAN_FD_FRAME != 0 {
        64
    } else {
        8
    }
}

/// The checks of `bcm_tx_setup`, in mainline's order: a real interface
/// (`ifindex` 0: `ENODEV`); 1..=256 frames (`EINVAL`); with [`SETTIMER`],
/// valid intervals (`EINVAL`); for an update of an operation that holds
/// `existing` frames, no more than those (`E2BIG`); then frame by frame,
/// present (`EFAULT`) and of a valid length (`EINVAL`). Returns what the
/// `write()` returns on success: `MHSIZ + nframes * cfsiz`.
pub fn check_tx_setup(
    req: &Request<'_>,
    ifindex: i32,
    existing: Option<u32>,
) -> Result<usize, i32> {
    let h = &req.head;
    if ifindex == 0 {
        return Err(ENODEV);
    }
    if h.nframes < 1 || h.nframes > MAX_NFRAMES {
        return Err(EINVAL);
    }
    if h.flags & SETTIMER != 0 && !h.ivals_valid() {
        return Err(EINVAL);
    }
    if existing.is_some_and(|n| h.nframes > n) {
        return Err(E2BIG);
    }
    let cfsiz = h.cfsiz();
    for i in 0..h.nframes as usize {
        let len = frame_len(req.payload, cfsiz, i).ok_or(EFAULT)?;
        if len > max_len(h) {
            return Err(EINVAL);
        }
    }
    Ok(MHSIZ + h.nframes as usize * cfsiz)
}

/// The head of an `RX_SETUP` as mainline keeps it: with [`RX_FILTER_ID`]
/// or without frames, the operation filters on the identifier only, the
/// flag is set and any frames in the message are ignored (`nframes` 0).
pub fn rx_setup_head(h: &MsgHead) -> MsgHead {
    let mut h = *h;
    if h.flags & RX_FILTER_ID != 0 || h.nframes == 0 {
        h.flags |= RX_FILTER_ID;
        h.nframes = 0;
    }
    h
}

/// The checks of `bcm_rx_setup` on the normalized head
/// ([`rx_setup_head`]), in mainline's order: at most 257 frames (the mux
/// mask and 256 entries; `EINVAL`); with [`RX_RTR_FRAME`], exactly one
/// frame and an identifier with `CAN_RTR_FLAG` (`EINVAL`); with
/// [`SETTIMER`], valid intervals (`EINVAL`); for an update, no more frames
/// than the operation holds (`E2BIG`); all frames present (`EFAULT`);
/// with [`RX_RTR_FRAME`], a reply of valid length (`EINVAL`). Any
/// interface, including ifindex 0 ("any"), is fine. Returns what the
/// `write()` returns: `MHSIZ + nframes * cfsiz` of the normalized head (so
/// an `RX_FILTER_ID` setup returns 56 whatever frames followed).
pub fn check_rx_setup(req: &Request<'_>, existing: Option<u32>) -> Result<usize, i32> {
    let h = rx_setup_head(&req.head);
    if h.nframes > MAX_NFRAMES + 1 {
        return Err(EINVAL);
    }
    if h.flags & RX_RTR_FRAME != 0 && (h.nframes != 1 || h.can_id & super::arb::CAN_RTR_FLAG == 0) {
        return Err(EINVAL);
    }
    if h.flags & SETTIMER != 0 && !h.ivals_valid() {
        return Err(EINVAL);
    }
    if existing.is_some_and(|n| h.nframes > n) {
        return Err(E2BIG);
    }
    let cfsiz = h.cfsiz();
    if req.payload.len() < h.nframes as usize * cfsiz {
        return Err(EFAULT);
    }
    if h.flags & RX_RTR_FRAME != 0
        && frame_len(req.payload, cfsiz, 0).is_some_and(|l| l > max_len(&h))
    {
        return Err(EINVAL);
    }
    Ok(MHSIZ + h.nframes as usize * cfsiz)
}

/// The reply frame of an [`RX_RTR_FRAME`] operation as mainline installs
/// it: with [`TX_CP_CAN_ID`], or when the frame carries the operation's
/// identifier, the identifier is the operation's without `CAN_RTR_FLAG`
/// (so the reply is a data frame and cannot trigger itself).
pub fn rtr_reply_frame(head: &MsgHead, mut frame: CanFdFrame) -> CanFdFrame {
    if head.flags & TX_CP_CAN_ID != 0 || frame.can_id == head.can_id {
        frame.can_id = head.can_id & !super::arb::CAN_RTR_FLAG;
    }
    frame
}

/// The checks of `TX_SEND`: exactly one frame, and nothing else, after the
/// head (`EINVAL`), then a real interface (`ENODEV`). The frame itself is
/// checked by the send path (`can_send`: a classic frame longer than 8
/// bytes is `EINVAL`, a CAN FD frame on a classic interface `EMSGSIZE`,
/// as the VM test `bcm_fd_on_classic_interface` shows). Returns
/// `MHSIZ + cfsiz`.
pub fn check_tx_send(req: &Request<'_>, ifindex: i32) -> Result<usize, i32> {
    let cfsiz = req.head.cfsiz();
    if req.head.nframes != 1 || req.payload.len() != cfsiz {
        return Err(EINVAL);
    }
    if ifindex == 0 {
        return Err(ENODEV);
    }
    Ok(MHSIZ + cfsiz)
}

/// The key that names an operation within a socket (`bcm_find_op`): the
/// identifier, the interface and whether it is CAN FD. `TX_DELETE`,
/// `RX_DELETE`, `TX_READ` and `RX_READ` of a key no operation has fail
/// with `EINVAL`.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct OpKey {
    /// `can_id` as in the head.
    pub can_id: u32,
    /// Interface of the operation (0: any).
    pub ifindex: i32,
    /// Whether the operation carries CAN FD frames.
    pub fd: bool,
}

impl OpKey {
    /// The key a message addresses on `ifindex`.
    pub const fn of(head: &MsgHead, ifindex: i32) -> Self {
        Self {
            can_id: head.can_id,
            ifindex,
            fd: head.flags & CAN_FD_FRAME != 0,
        }
    }
}

/// Writes `head` and `frames` into `out` as one message (a reply or a
/// notification); returns the number of bytes written, or `None` when
/// `out` is too small. `head.nframes` is written as given.
pub fn serialize(head: &MsgHead, frames: &[CanFrame], out: &mut [u8]) -> Option<usize> {
    let n = MHSIZ + frames.len() * CAN_FRAME_LEN;
    let out = out.get_mut(..n)?;
    out[..MHSIZ].copy_from_slice(&head.to_bytes());
    for (i, f) in frames.iter().enumerate() {
        let o = MHSIZ + i * CAN_FRAME_LEN;
        out[o..o + CAN_FRAME_LEN].copy_from_slice(&f.to_bytes());
    }
    Some(n)
}

/// [`serialize`] for any frame kind: each frame as its first `head.cfsiz()`
/// bytes (72 with [`CAN_FD_FRAME`], else 16).
pub fn serialize_any(head: &MsgHead, frames: &[CanFdFrame], out: &mut [u8]) -> Option<usize> {
    let cfsiz = head.cfsiz();
    let n = MHSIZ + frames.len() * cfsiz;
    let out = out.get_mut(..n)?;
    out[..MHSIZ].copy_from_slice(&head.to_bytes());
    for (i, f) in frames.iter().enumerate() {
        let o = MHSIZ + i * cfsiz;
        out[o..o + cfsiz].copy_from_slice(&f.to_bytes()[..cfsiz]);
    }
    Some(n)
}
