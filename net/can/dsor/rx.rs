// SPDX-License-Identifier: GPL-2.0

//! Receiving in `rcan_dsor`: [`DsorRx`], the one in-kernel receiver of
//! every DSOR frame addressed to this node (NET_RX softirq), which hands
//! each frame to the engine; and the engine's decisions on incoming
//! messages: whether a new one is wanted ([`accept`], [`wanted`]) and the
//! delivery of a complete one to the bound sockets or to canip0
//! ([`deliver`]). Everything but [`DsorRx`]'s `rx` itself runs under
//! [`ENGINE`], called by the engine.

#![forbid(unsafe_code)]

use core::sync::atomic::Ordering;

use crate::engine::{now_ms, Bind, ENGINE, NODE, WAITQ};
use crate::glue;
use crate::glue::netdev::NetDev;
use crate::glue::skb::{OwnedSkb, Skb, UniqueSkb};
use crate::params::Config;
use crate::rcan_api::KernelRx;
use crate::rcan_core::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG};
use crate::rcan_core::dsor_addr::{self, DsorAddr};
use crate::rcan_core::dsor_rx::{Delivered, Incoming};
use crate::rcan_core::dsor_wire::{AckStatus, DsorId, MsgKind};
use crate::rcan_core::frame::{AnyFrame, CANFD_MTU};
use crate::stats::Stats;
use crate::timers::drain_locked;
use crate::udpip;

/// Headroom of reassembly buffers: rebuilt IPv4 + UDP headers of canip0.
const RX_HEADROOM: u32 = crate::rcan_core::dsor_udp::HDR_LEN as u32 + 2;

/// A reassembly buffer: an skb with room in front for canip0's headers.
pub(crate) struct RxBuf(UniqueSkb);

impl AsMut<[u8]> for RxBuf {
    fn as_mut(&mut self) -> &mut [u8] {
        self.0.data_mut()
    }
}

/// Hands a complete message to its sockets or to canip0, before its last
/// frame is acked (dsor-wire.rst, "Delivery rule"): `Ok` if at least one
/// socket queued it (or canip0 took it), else the status the last frame is
/// acked with: REFUSED if nobody wants it any more, NO_MEMORY if every
/// socket that wants it has a full receive queue. Counts the outcome.
/// Under ENGINE (softirq or a driver's transmit path).
pub(crate) fn deliver(
    binds: &[Bind],
    canip: Option<&NetDev>,
    cfg: &Config,
    stats: &mut Stats,
    d: Delivered<RxBuf>,
) -> core::result::Result<(), AckStatus> {
    let Delivered {
        src,
        prio,
        header,
        buf,
    } = d;
    let skb = buf.0;
    let mut cb = [0u8; 12];
    cb[0] = src;
    cb[1] = prio;
    let q = match header.kind {
        MsgKind::Udp { dport, daddr } => {
            udpip::deliver(canip, skb, src, cfg.udp_saddr, daddr, dport).map(|()| Queued {
                wanted: 1,
                queued: 1,
            })
        }
        MsgKind::Segm { id } => {
            cb[2] = 0;
            cb[4..8].copy_from_slice(&id.to_ne_bytes());
            Ok(queue_to(binds, skb.into_owned(), &cb, |a| a.segm_accepts(src, id)))
        }
        MsgKind::Port { dport, sport } => {
            cb[2] = 1;
            cb[3] = sport;
            let want = dsor_addr::make_port(cfg.node, dport);
            Ok(queue_to(
                binds,
                skb.into_owned(),
                &cb,
                |a| matches!(*a, DsorAddr::Port { port, .. } if port == want),
            ))
        }
    };
    match q {
        Ok(Queued {
            queued: 0,
            wanted: 0,
        })
        | Err(AckStatus::Refused) => {
            stats.rx_unwanted_at_end += 1;
            Err(AckStatus::Refused)
        }
        Ok(Queued { queued: 0, .. }) | Err(_) => {
            stats.rx_queue_full += 1;
            Err(AckStatus::NoMemory)
        }
        Ok(Queued { queued, wanted }) => {
            stats.rx_delivered += 1;
            stats.rx_copies_dropped += (wanted - queued) as u64;
            Ok(())
        }
    }
}

/// How many sockets wanted a message and how many queued it.
struct Queued {
    wanted: usize,
    queued: usize,
}

/// Queues `skb` on every bound socket whose address `want`s it (clones
/// for all but the last). Each Bind holds a reference on its socket, so
/// they are valid here; release removes them under the ENGINE lock, which
/// the caller holds.
fn queue_to(
    binds: &[Bind],
    mut skb: OwnedSkb,
    cb: &[u8; 12],
    want: impl Fn(&DsorAddr) -> bool,
) -> Queued {
    skb.cb_write(0, cb);
    skb.stamp_if_unset();
    let n = binds.iter().filter(|b| want(&b.addr)).count();
    let mut skb = Some(skb);
    let mut queued = 0;
    for (k, b) in binds.iter().filter(|b| want(&b.addr)).enumerate() {
        let one = if k + 1 == n {
            skb.take()
        } else {
            skb.as_ref().and_then(|s| s.clone_atomic())
        };
        let Some(one) = one else { continue };
        if b.sk.sock().queue_rcv(one).is_ok() {
            queued += 1;
        }
    }
    Queued { wanted: n, queued }
}

/// Whether some socket (or canip0) wants the message `inc` (under ENGINE).
pub(crate) fn wanted(binds: &[Bind], canip_up: bool, inc: &Incoming<'_>) -> bool {
    match inc.header.kind {
        MsgKind::Segm { id } => binds.iter().any(|b| b.addr.segm_accepts(inc.src, id)),
        MsgKind::Port { dport, .. } => binds.iter().any(
            |b| matches!(b.addr, DsorAddr::Port { port, .. } if dsor_addr::port_sub(port) == dport),
        ),
        MsgKind::Udp { .. } => canip_up,
    }
}

/// The acceptance decision for a new incoming message (under ENGINE).
pub(crate) fn accept(
    binds: &[Bind],
    canip_up: bool,
    inc: &Incoming<'_>,
) -> core::result::Result<RxBuf, AckStatus> {
    // The rebuilt IPv4 + UDP headers must fit in 65535 bytes.
    if matches!(inc.header.kind, MsgKind::Udp { .. })
        && usize::from(inc.header.len) > crate::rcan_core::dsor_udp::MAX_PAYLOAD
    {
        return Err(AckStatus::TooLong);
    }
    if !wanted(binds, canip_up, inc) {
        return Err(AckStatus::Refused);
    }
    let len = u32::from(inc.header.len);
    let mut skb = UniqueSkb::alloc(RX_HEADROOM + len, glue::GFP_ATOMIC).ok_or(AckStatus::NoMemory)?;
    skb.reserve(RX_HEADROOM);
    if !skb.put_zeroed(len) {
        return Err(AckStatus::NoMemory);
    }
    Ok(RxBuf(skb))
}

/// The receiver of every DSOR frame addressed to this node, classic or
/// CAN FD (pf_can hands kernel receivers both).
pub(crate) struct DsorRx;

impl KernelRx for DsorRx {
    /// NET_RX softirq, under RCU. The frame's answers (acks, the next
    /// body) are queued under ENGINE and sent right here, by the same
    /// critical section turning drainer ([`drain_locked`]; sent after the
    /// lock is dropped), instead of a timer hop later: a receive callback
    /// runs in NET_RX softirq with no device lock held, so it may
    /// transmit.
    fn rx(&self, skb: &Skb, dev: &NetDev) {
        // Read in place: no copy of the frame.
        let Some((can_id, data, _)) = AnyFrame::view(skb.data()) else {
            return;
        };
        if can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG) != CAN_EFF_FLAG {
            return;
        }
        let Some(id) = DsorId::from_can_id(can_id & CAN_EFF_MASK) else {
            return;
        };
        if u32::from(id.dst) != NODE.load(Ordering::Relaxed) {
            return;
        }
        // The interface's mode now decides whether FD headers are
        // answered (a CAN FD frame arrives only on an FD interface).
        let fd_iface = dev.mtu() as usize == CANFD_MTU;
        let now = now_ms();
        let mut g = ENGINE.lock();
        let Some(e) = g.as_mut() else { return };
        if dev.name().as_bytes() != e.cfg.ifname.bytes() {
            return;
        }
        let finished_before = e.stats.tx_ok + e.stats.tx_failed;
        let queued = e.on_frame(&id, data, fd_iface, now);
        let finished = e.stats.tx_ok + e.stats.tx_failed != finished_before;
        if queued {
            // Becomes the drainer unless one runs (which then takes these
            // frames too), without dropping ENGINE in between; sends on
            // the device the frame came in on (the DSOR interface: its
            // name checked above under this same ENGINE hold; valid for
            // this call) without a lookup by name, a reference of its own
            // or a second name check for this frame's answer.
            drain_locked(g, finished, Some(dev));
        } else {
            drop(g);
            if finished {
                WAITQ.wake_all();
            }
        }
    }
}

pub(crate) static RX: DsorRx = DsorRx;
