// SPDX-License-Identifier: GPL-2.0

//! rcan_can: the thesis' CAN 2.0 data link protocol, CANPROTO_CAN
//! (thesis 5.2.1-5.2.5 and 5.3.2, module `can`).
//!
//! `socket(PF_CAN, SOCK_RAW, CANPROTO_CAN)`; addresses are
//! `struct sockaddr_canarb` (thesis figure 5-5 arbitration field). `bind`
//! sets the acceptance filter, `connect` the default arbitration field,
//! `sendmsg` sends one frame (data length = DLC), `recvmsg` returns one
//! frame's data bytes. CAN 2.0 only: on a CAN FD interface these sockets
//! send and receive classic frames, never FD ones. Reference: Documentation/networking/rcan/canproto-can.rst.
//!
//! Contexts and locks:
//!
//! * System calls (process context) take RTNL, then the socket lock (the
//!   order mainline raw.c uses), then pf_can's writers' mutex inside
//!   `rcan_rx_set`.
//! * `CanProtoOps::rx` runs in NET_RX softirq under RCU, for bus frames and echoes
//!   alike; it only clones (or takes over) the skb and queues it on the
//!   socket (receive-queue spinlock). (A receive callback may transmit;
//!   this one has no reason to.)
//! * `MODULE.sockets` (every open socket, for the netdevice notifier) is protected
//!   by RTNL.

#![forbid(unsafe_code)]

use crate::{glue, rcan_api, rcan_core};
use kernel::prelude::*;

use glue::netdev::{DevRef, NetDev};
use glue::neterr;
use glue::sock::{Msg, Sock, SockView};
use glue::sync::{Rtnl, RtnlProof};
use crate::glue::module::{ModuleScope, ScopedModule};
use kernel::c_str;
use rcan_api::{
    CanProtocol, NetdevEvent, ProtoModule, ProtoRegistration, RxFilter, RxSkb, Sockets,
    CANPROTO_CAN, RX_FILTER_ARB, SOCK_RAW,
};
use rcan_core::arb::{Arb, MAX_DLC};
use rcan_core::frame::{AnyFrame, CanFrame, CAN_FRAME_LEN};
use rcan_core::sockaddr::{self, SockaddrArb, AF_UNSPEC, SOCKADDR_CANARB_LEN};

/// A CANPROTO_CAN socket's state, protected by its socket lock.
#[derive(Default)]
struct CanSock {
    /// The filter given to bind, as given (for getsockname).
    bound: Option<SockaddrArb>,
    /// The arbitration field and interface given to connect.
    peer: Option<(Arb, i32)>,
}

struct CanProtoOps;

/// This module's registrations (proto, CAN protocol, notifier).
static MODULE: ProtoModule<CanProtoOps> = ProtoModule::new();

type S = Sock<CanProtoOps>;

impl CanProtocol for CanProtoOps {
    const PROTOCOL: i32 = CANPROTO_CAN;
    const SOCK_TYPE: i32 = SOCK_RAW;
    /// All state is in the socket; devices are looked up in the
    /// socket's namespace.
    const ALL_NAMESPACES: bool = true;

    fn module() -> &'static ProtoModule<Self> {
        &MODULE
    }

    /// NET_RX softirq, RCU read side. Every classic frame is delivered,
    /// the socket's own ones included (on canloop the sender sees its frames
    /// come back, thesis 5.3.5).
    fn rx(sk: &SockView<Self>, skb: RxSkb<'_>, _cookie: u32) {
        // The thesis API is CAN 2.0 only: CAN FD frames (72 bytes) from an
        // FD-capable device are not for it (can-fd.rst).
        if skb.skb().len() as usize != CAN_FRAME_LEN {
            skb.done();
            return;
        }
        // The receiving interface may be gone by the time recvmsg runs:
        // its index is read now, while the callback holds it.
        let ifindex = skb.ifindex();
        let Some(mut skb) = skb.into_owned() else {
            return;
        };
        skb.set_cb_u32(0, ifindex as u32);
        // A full receive queue drops the frame (counted by the socket layer).
        let _ = sk.queue_rcv(skb);
    }

    /// A CAN device is going away. Process context, RTNL held. Sockets
    /// bound to it lose their filter and get ENODEV once.
    fn netdev_event(event: NetdevEvent, dev: &NetDev, sockets: &Sockets<'_, Self>) {
        if event != NetdevEvent::Unregister || !dev.is_can() {
            return;
        }
        let ifindex = dev.ifindex();
        sockets.for_each(|sk| {
            let mut s = sk.lock();
            if matches!(s.bound, Some(b) if b.ifindex as i32 == ifindex) {
                s.bound = None;
                let _ = set_receivers(sk, None);
                drop(s);
                sk.report_error(-ENODEV.to_errno());
            }
        });
    }
}

fn set_receivers(sk: &S, filter: Option<&SockaddrArb>) -> Result {
    match filter {
        Some(a) => {
            let f = RxFilter {
                kind: RX_FILTER_ARB,
                id: a.arb,
                mask: a.mask,
            };
            rcan_api::rx_set(sk, 0, a.ifindex as i32, &[f], false, 0)
        }
        None => {
            rcan_api::rx_remove(sk);
            Ok(())
        }
    }
}

/// Checks that `ifindex` is 0 or a CAN device of `sk`'s namespace. Caller
/// holds RTNL, so the answer stays true until it is dropped.
fn check_ifindex(sk: &S, ifindex: i32, _rtnl: &dyn RtnlProof) -> Result {
    if ifindex == 0 {
        return Ok(());
    }
    match DevRef::by_index(sk.net(), ifindex) {
        Some(dev) if dev.is_can() => Ok(()),
        _ => Err(ENODEV),
    }
}

impl glue::sock::Proto for CanProtoOps {
    type Data = CanSock;
    type Shared = ();

    fn new_data() -> CanSock {
        CanSock::default()
    }

    fn new_shared() {}

    fn release(sk: &S) {
        let mut rtnl = Rtnl::lock();
        MODULE.sockets.get(&mut rtnl).remove(sk);
        let mut s = sk.lock();
        if s.bound.take().is_some() {
            let _ = set_receivers(sk, None);
        }
        s.peer = None;
    }

    fn bind(sk: &S, addr: &[u8]) -> Result {
        let a = sockaddr::parse(addr).map_err(|e| glue::errno(e.errno()))?;
        let rx = a.bind_filter().map_err(|e| glue::errno(e.errno()))?;
        let rtnl = Rtnl::lock();
        check_ifindex(sk, rx.ifindex, &rtnl)?;
        let mut s = sk.lock();
        set_receivers(sk, Some(&a))?;
        s.bound = Some(a);
        Ok(())
    }

    fn connect(sk: &S, addr: &[u8], _flags: i32) -> Result {
        if addr.len() >= 2 && u16::from_ne_bytes([addr[0], addr[1]]) == AF_UNSPEC {
            sk.lock().peer = None;
            return Ok(());
        }
        let a = sockaddr::parse(addr).map_err(|e| glue::errno(e.errno()))?;
        let dest = a.dest().map_err(|e| glue::errno(e.errno()))?;
        let rtnl = Rtnl::lock();
        check_ifindex(sk, dest.1, &rtnl)?;
        sk.lock().peer = Some(dest);
        Ok(())
    }

    fn getname(sk: &S, peer: bool, out: &mut [u8]) -> Result<usize> {
        let s = sk.lock();
        let a = if peer {
            let (arb, ifindex) = s.peer.ok_or(neterr::ENOTCONN())?;
            SockaddrArb {
                family: sockaddr::AF_CAN,
                arb: arb.raw(),
                mask: 0,
                ifindex: ifindex as u32,
            }
        } else {
            s.bound.unwrap_or(SockaddrArb {
                family: sockaddr::AF_CAN,
                arb: 0,
                mask: 0,
                ifindex: 0,
            })
        };
        out[..SOCKADDR_CANARB_LEN].copy_from_slice(&a.encode());
        Ok(SOCKADDR_CANARB_LEN)
    }

    fn sendmsg(sk: &S, msg: &mut Msg, len: usize) -> Result<usize> {
        let flags = msg_flags(msg);
        if flags & glue::msg::OOB != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let (arb, ifindex) = match msg.name() {
            Some(name) => {
                let a = sockaddr::parse(name).map_err(|e| glue::errno(e.errno()))?;
                a.dest().map_err(|e| glue::errno(e.errno()))?
            }
            None => sk.lock().peer.ok_or(neterr::EDESTADDRREQ())?,
        };
        if len > MAX_DLC {
            return Err(EINVAL);
        }
        let mut data = [0u8; MAX_DLC];
        if !arb.is_rtr() {
            msg.copy_from_user(&mut data[..len])?;
        }
        let frame =
            CanFrame::from_arb(arb, len, &data[..len]).map_err(|e| glue::errno(e.errno()))?;
        let nonblock = flags & glue::msg::DONTWAIT != 0;
        if ifindex != 0 {
            let dev = DevRef::by_index(sk.net(), ifindex).ok_or(ENODEV)?;
            send_one(sk, &dev, &frame, nonblock)?;
            return Ok(len);
        }
        // ifindex 0: every CAN interface of the socket's namespace that is
        // up (thesis 5.2.2).
        let (mut any, mut sent) = (false, false);
        let mut after = 0;
        while let Some(dev) = DevRef::next_can(sk.net(), after) {
            after = dev.ifindex();
            any = true;
            if dev.is_up() {
                send_one(sk, &dev, &frame, nonblock)?;
                sent = true;
            }
        }
        match (any, sent) {
            (_, true) => Ok(len),
            (true, false) => Err(neterr::ENETDOWN()),
            (false, _) => Err(ENODEV),
        }
    }

    fn recvmsg(sk: &S, msg: &mut Msg, len: usize, flags: i32) -> Result<usize> {
        if flags as u32 & (glue::msg::OOB | glue::msg::ERRQUEUE) != 0 {
            return Err(neterr::EOPNOTSUPP());
        }
        let skb = sk.recv_datagram(flags)?;
        let bytes: &[u8; CAN_FRAME_LEN] = skb.data().try_into().map_err(|_| EINVAL)?;
        let frame = CanFrame::from_bytes(bytes);
        let dlc = frame.dlc();
        let n = dlc.min(len);
        if frame.can_id & rcan_core::arb::CAN_RTR_FLAG != 0 {
            // A remote frame has no data field: whatever bytes its sender
            // left in the can_frame (CAN_RAW passes them through, as on
            // mainline), its DLC bytes read as zeros here
            // (canproto-can.rst). The skb may be shared: not written.
            msg.copy_to_user(&[0u8; MAX_DLC][..n])?;
        } else {
            // The data field sits at offset 8 of struct can_frame.
            msg.copy_from_skb(&skb, 8, n)?;
        }
        if n < dlc {
            msg.add_flags(glue::msg::TRUNC);
        }
        msg.recv_cmsgs(sk, &skb);
        if let Some(arb) = frame.arb() {
            let a = SockaddrArb {
                family: sockaddr::AF_CAN,
                arb: arb.raw(),
                mask: 0,
                ifindex: skb.cb_u32(0),
            };
            msg.set_name(&a.encode());
        }
        sk.free_datagram(skb);
        Ok(if flags as u32 & glue::msg::TRUNC != 0 {
            dlc
        } else {
            n
        })
    }
}

fn msg_flags(_msg: &Msg) -> u32 {
    // sendmsg's flags arrive in msg->msg_flags.
    _msg.flags()
}

/// Builds and queues one frame on `dev`. Process context; may block on the
/// send buffer (thesis 5.2.3: a full transmit queue blocks the sender,
/// MSG_DONTWAIT gives EAGAIN).
fn send_one(sk: &S, dev: &DevRef, frame: &CanFrame, nonblock: bool) -> Result {
    if !dev.is_can() {
        return Err(ENODEV);
    }
    if !dev.is_up() {
        return Err(neterr::ENETDOWN());
    }
    // With mainline's `struct can_skb_priv` in front, so mainline CAN
    // drivers accept our skbs too.
    let skb = glue::can::skb::alloc_tx_frame(sk, dev, &AnyFrame::Classic(*frame), nonblock)?;
    // Thesis sockets always loop their frames back to local receivers.
    rcan_api::send(skb, dev, true)
}

/// The module: its registrations, undone when it is dropped (unload).
pub(crate) struct CanProtoModule {
    _reg: ProtoRegistration<CanProtoOps>,
}

impl ScopedModule for CanProtoModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let reg = MODULE.register(c_str!("CANPROTO_CAN"), scope)?;
        pr_info!("CANPROTO_CAN ({}) registered\n", CANPROTO_CAN);
        Ok(CanProtoModule { _reg: reg })
    }
}
