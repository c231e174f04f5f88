// SPDX-License-Identifier: GPL-2.0

//! The one place a CAN skb is built (issue 19): the buffer, mainline's
//! `struct can_skb_priv` in front of the frame (`can_skb_reserve`,
//! `can_skb_prv(skb)->ifindex`), and the frame itself, classic (16 bytes,
//! ETH_P_CAN) or CAN FD (72 bytes, ETH_P_CANFD) in mainline's canonical
//! layout. The protocol (ETH_P_CAN or ETH_P_CANFD) is set from the length
//! when the skb is marked for sending ([`Skb::set_can_tx`], by pf_can) or
//! as received ([`Skb::set_can_rx`]), as mainline's `can_send` decides it.
//!
//! Every allocator returns a [`UniqueSkb`] (writable: nobody else holds or
//! shares it) except [`alloc_rx`], whose [`OwnedSkb`] a driver only marks
//! and hands up.
//!
//! Every CAN skb of rcan is made here:
//!
//! * a socket's send path: [`alloc_tx`] (charged to the socket's send
//!   buffer, the caller appends the user's bytes: CAN_RAW) or
//!   [`alloc_tx_frame`] (with a frame built in the kernel: CANPROTO_CAN);
//! * senders without a send buffer to charge (timers, receive callbacks):
//!   [`alloc_frame`] (a typed frame: the time service) or
//!   [`alloc_image`] (a frame image, copied verbatim: as the user wrote
//!   it, as mainline's `bcm_can_tx` copies it, or as the DSOR engine
//!   built it), and
//!   [`alloc_image_for`] for such a frame a socket sends (CAN_BCM);
//! * drivers, for frames from the bus: [`alloc_rx`] (the SJA1000 and
//!   82527 drivers).
//!
//! Echoes are not built: an echoing driver hands the sent skb back
//! ([`Skb::can_echo_done`], canloop's reflection), as mainline does.

use crate::glue::bindings;
use crate::glue::netdev::NetDev;
use crate::glue::skb::{Exclusive, OwnedSkb, Skb, UniqueSkb};
use crate::glue::sock::{Proto, Sock, SockView};
use crate::rcan_core::frame::{AnyFrame, CANFD_MTU, CAN_MTU};
use kernel::prelude::*;

/// Headroom for mainline's `struct can_skb_priv { int ifindex; int
/// skbcnt; }`.
pub(crate) const SKB_PRIV_LEN: u32 = core::mem::size_of::<bindings::can_skb_priv>() as u32;

/// Reserves and fills the `struct can_skb_priv` of a fresh skb: the
/// interface it is sent by or received on, `skbcnt` 0. Inline: once a
/// frame on every send path.
#[inline]
fn put_priv(skb: &mut UniqueSkb, ifindex: i32) -> bool {
    skb.reserve(SKB_PRIV_LEN);
    // By constant indices: `copy_from_slice` and iterator adapters are
    // left as calls into `core` on every frame (the kernel's `core` is not
    // inlined across crates), a loop of them costs ~100 instructions.
    let b = ifindex.to_ne_bytes();
    let mut prv = [0u8; SKB_PRIV_LEN as usize];
    prv[0] = b[0];
    prv[1] = b[1];
    prv[2] = b[2];
    prv[3] = b[3];
    skb.write_headroom(&prv)
}

/// Appends the frame's image (16 or 72 bytes).
fn put_frame(skb: &mut UniqueSkb, frame: &AnyFrame) -> bool {
    match frame {
        AnyFrame::Classic(f) => skb.put_data(&f.to_bytes()),
        AnyFrame::Fd(f) => skb.put_data(&f.to_bytes()),
    }
}

/// Whether `image` has the size of a classic (`CAN_MTU`) or CAN FD
/// (`CANFD_MTU`) frame: the only buffers [`alloc_image`] takes, as
/// pf_can sends nothing else.
fn is_frame_size(image: &[u8]) -> bool {
    image.len() == CAN_MTU || image.len() == CANFD_MTU
}

/// An skb for `len` bytes a socket sends by `dev`, charged to the
/// socket's send buffer (mainline `raw_sendmsg`: `sock_alloc_send_skb`,
/// `can_skb_reserve`, `can_skb_prv(skb)->ifindex`); the caller appends
/// the frame. Process context; blocks while the send buffer is full
/// unless `nonblock` (EAGAIN), honouring SO_SNDTIMEO.
#[inline]
pub(crate) fn alloc_tx<T: Proto>(
    sk: &Sock<T>,
    dev: &NetDev,
    len: usize,
    nonblock: bool,
) -> Result<UniqueSkb> {
    let len = u32::try_from(len).map_err(|_| EINVAL)?;
    let mut skb = sk.alloc_send_skb(SKB_PRIV_LEN + len, nonblock)?;
    if !put_priv(&mut skb, dev.ifindex()) {
        return Err(crate::glue::neterr::ENOBUFS());
    }
    Ok(skb)
}

/// [`alloc_tx`] with `frame` appended: a frame the kernel built for a
/// socket (CANPROTO_CAN's thesis API, 5.2.3). Process context; blocks
/// while the send buffer is full unless `nonblock` (EAGAIN).
pub(crate) fn alloc_tx_frame<T: Proto>(
    sk: &Sock<T>,
    dev: &NetDev,
    frame: &AnyFrame,
    nonblock: bool,
) -> Result<UniqueSkb> {
    let mut skb = alloc_tx(sk, dev, frame.mtu(), nonblock)?;
    if !put_frame(&mut skb, frame) {
        return Err(crate::glue::neterr::ENOBUFS());
    }
    Ok(skb)
}

/// An skb holding `frame`, to be sent by `dev` by a sender without a
/// socket buffer to charge (timers, kernel receivers). Any context with
/// `GFP_ATOMIC`; `None` without memory.
pub(crate) fn alloc_frame(dev: &NetDev, frame: &AnyFrame, gfp: bindings::gfp_t) -> Option<UniqueSkb> {
    let mut skb = UniqueSkb::alloc(SKB_PRIV_LEN + frame.mtu() as u32, gfp)?;
    (put_priv(&mut skb, dev.ifindex()) && put_frame(&mut skb, frame)).then_some(skb)
}

/// An skb holding the frame image `image` (a `struct can_frame` or
/// `struct canfd_frame` as user space wrote it: 16 or 72 bytes, copied
/// byte for byte, reserved fields included), to be sent by `dev`. For a
/// protocol that keeps frames as images and sends them unchanged
/// (mainline `bcm_can_tx`: `skb_put_data(skb, cf, op->cfsiz)`); whether
/// the frame suits the device is pf_can's check at send time. Any context
/// with `GFP_ATOMIC`, process context with `GFP_KERNEL`; `None` without
/// memory or if `image` is neither size.
pub(crate) fn alloc_image(dev: &NetDev, image: &[u8], gfp: bindings::gfp_t) -> Option<UniqueSkb> {
    if !is_frame_size(image) {
        return None;
    }
    let mut skb = UniqueSkb::alloc(SKB_PRIV_LEN + image.len() as u32, gfp)?;
    (put_priv(&mut skb, dev.ifindex()) && skb.put_data(image)).then_some(skb)
}

/// [`alloc_image`] for a frame that `sk` sends outside a system call's
/// send buffer (mainline BCM's timers and replies, and its TX_SEND):
/// `sk` becomes the skb's owner the way mainline's `can_skb_set_owner`
/// makes it (a counted reference, no send-buffer accounting), so that
/// receivers of the echo see who sent it. As mainline's `bcm_can_tx` and
/// `bcm_tx_send`, the skb does not take the socket's priority or mark
/// (`SO_PRIORITY` and `SO_MARK` do not reach BCM frames). Any context with
/// `GFP_ATOMIC`, process context with `GFP_KERNEL`; `None` as
/// [`alloc_image`].
pub(crate) fn alloc_image_for<T: Proto>(
    sk: &SockView<T>,
    dev: &NetDev,
    image: &[u8],
    gfp: bindings::gfp_t,
) -> Option<UniqueSkb> {
    let mut skb = alloc_image(dev, image, gfp)?;
    skb.set_owner(sk);
    Some(skb)
}

/// An skb holding `frame` as received on `dev` (mainline `alloc_can_skb`
/// / `alloc_canfd_skb`): marked with [`Skb::set_can_rx`], ready for the
/// driver to hand up (which sets `skb->dev`). Any context (allocates with `GFP_ATOMIC`); `None`
/// without memory (the driver counts an `rx_dropped`).
pub(crate) fn alloc_rx(dev: &NetDev, frame: &AnyFrame) -> Option<OwnedSkb> {
    let mut skb = alloc_frame(dev, frame, crate::glue::GFP_ATOMIC)?;
    skb.set_can_rx();
    Some(skb.into_owned())
}

/// Bytes of `struct sockaddr_can` that CAN_RAW and CAN_BCM return from
/// recvmsg (`can_family`, padding, `can_ifindex`; mainline's
/// `RAW_MIN_NAMELEN`/`BCM_MIN_NAMELEN`).
pub(crate) const MIN_NAMELEN: usize = 8;
/// Offsets in `skb->cb` of a frame queued for [`recvmsg_queued`]: the
/// source address, then the recvmsg flags.
const CB_NAME: usize = 0;
const CB_FLAGS: usize = MIN_NAMELEN;

/// Records in `skb->cb`, for [`recvmsg_queued`], that the skb came from
/// interface `ifindex` and is read with `flags` (MSG_DONTROUTE,
/// MSG_CONFIRM) set: mainline keeps the `sockaddr_can` in the cb too
/// (`raw_rcv`, `bcm_send_to_user`). Any context; the skb is about to be
/// queued on a socket, whose queue owns the cb from then on.
#[inline]
pub(crate) fn set_rx_meta<A: Exclusive>(skb: &mut Skb<A>, ifindex: i32, flags: u32) {
    // Built by constant indices, not `copy_from_slice` (a call into `core`
    // and from there to `memcpy` per slice, on every frame received).
    let (fam, idx, fl) = (
        (bindings::AF_CAN as u16).to_ne_bytes(),
        ifindex.to_ne_bytes(),
        flags.to_ne_bytes(),
    );
    let meta: [u8; MIN_NAMELEN + 4] = [
        fam[0], fam[1], 0, 0, idx[0], idx[1], idx[2], idx[3], fl[0], fl[1], fl[2], fl[3],
    ];
    const _: () = assert!(CB_FLAGS == CB_NAME + MIN_NAMELEN);
    skb.cb_write(CB_NAME, &meta);
}

/// The recvmsg of CAN_RAW and CAN_BCM (mainline `raw_recvmsg`,
/// `bcm_recvmsg`): dequeues one skb queued with [`set_rx_meta`], copies
/// up to `len` bytes of it (`MSG_TRUNC` if it is longer: a 72-byte CAN FD
/// frame read into 16 bytes gives 16 and `MSG_TRUNC`), adds the receive
/// control messages (timestamps), the source address ([`MIN_NAMELEN`]
/// bytes) and the recorded flags; returns the bytes copied. Process
/// context; may sleep (blocking read, SO_RCVTIMEO).
///
/// Always inlined, with what it calls on the way of a linear frame
/// ([`Sock::recv_datagram`], the copy, the control messages' test), into
/// the protocol's recvmsg and so into the glue's recvmsg trampoline: one
/// function a frame, as mainline's `raw_recvmsg` is.
#[inline(always)]
pub(crate) fn recvmsg_queued<T: Proto>(
    sk: &Sock<T>,
    msg: &mut crate::glue::sock::Msg,
    len: usize,
    flags: i32,
) -> Result<usize> {
    let skb = sk.recv_datagram(flags)?;
    let n = skb.len() as usize;
    let size = if len < n {
        msg.add_flags(bindings::MSG_TRUNC);
        len
    } else {
        n
    };
    // A CAN skb holds its frame in its linear part (drivers and pf_can
    // build it so): copied from there with `memcpy_to_msg`'s
    // `_copy_to_iter`, as mainline's `raw_recvmsg` does, without the
    // datagram iterator's walk over fragments (about 70 instructions a
    // frame); a non-linear skb (which a packet socket could hand in) goes
    // through that walk.
    let head = skb.data();
    let copied = match head.get(..size) {
        Some(bytes) if head.len() == n => msg.copy_to_user(bytes),
        _ => msg.copy_from_skb(&skb, 0, size),
    };
    if let Err(e) = copied {
        sk.free_datagram(skb);
        return Err(e);
    }
    msg.recv_cmsgs(sk, &skb);
    let mut name = [0u8; MIN_NAMELEN];
    skb.cb_read(CB_NAME, &mut name);
    msg.set_name(&name);
    let mut f = [0u8; 4];
    skb.cb_read(CB_FLAGS, &mut f);
    msg.add_flags(u32::from_ne_bytes(f));
    sk.free_datagram(skb);
    Ok(size)
}
