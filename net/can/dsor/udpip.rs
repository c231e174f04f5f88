// SPDX-License-Identifier: GPL-2.0

//! `canip0`: UDP/IP over DSOR (thesis 5.3.3, `dsor/udpip.c`).
//!
//! A virtual device (ARPHRD_VOID, IFF_POINTOPOINT, IFF_NOARP, no link
//! header). IPv4 UDP datagrams routed to it become DSOR UDP/IP messages
//! (header: length, destination port, destination address) to node
//! `daddr & 0x7f`; everything else is dropped and counted (`tx_dropped`).
//! Received UDP/IP messages get rebuilt IPv4 and UDP headers (source
//! address: parameter `udp_saddr`, source port 0, correct checksums) and
//! go up the IP stack through `netif_rx`.
//!
//! Contexts: `start_xmit` runs with BH disabled (qdisc or direct
//! transmit) and only starts a transfer under the engine lock;
//! [`deliver`] runs under the engine lock in the receive path.
//! The engine keeps a counted reference on the registered device
//! (`Engine::canip`, under the engine lock): set after registration,
//! taken back before unregistration; the functions here get it from
//! their caller, who holds the engine lock.

#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicU16, Ordering};
use kernel::alloc::KVec;
use kernel::prelude::*;

use crate::engine::{now_ms, restart_over_ms, Owner, ENGINE};
use crate::glue::module::ModuleScope;
use crate::glue::net::Net;
use crate::glue::netdev::{Dev, DevRef, Driver, NetDev, Registration, Setup, Xmit};
use crate::glue::skb::{Skb, UniqueSkb};
use crate::rcan_core::dsor_addr::udp_node;
use crate::rcan_core::dsor_udp::{self, HDR_LEN};
use crate::rcan_core::dsor_wire::{AckStatus, Header, MsgKind};
use kernel::c_str;

/// IPv4 identification of rebuilt headers.
static IP_ID: AtomicU16 = AtomicU16::new(1);

pub(crate) struct CanipDriver;

/// The registered device; unregistered when dropped.
pub(crate) struct Canip {
    reg: Option<Registration<CanipDriver>>,
}

impl Canip {
    /// Registers `canip%d`. Process context.
    pub(crate) fn register(scope: &ModuleScope) -> Result<Canip> {
        let reg = Registration::<CanipDriver>::register(c_str!("canip%d"), (), scope)?;
        // The index names our device until we unregister it (dropping
        // `reg` on an error return does).
        let dev = DevRef::by_index(Net::init(), reg.dev().ifindex()).ok_or(ENODEV)?;
        match ENGINE.lock().as_mut() {
            Some(e) => e.canip = Some(dev),
            None => return Err(ENODEV),
        }
        pr_info!("{}: UDP/IP over DSOR\n", reg.dev().name());
        Ok(Canip { reg: Some(reg) })
    }
}

impl Drop for Canip {
    fn drop(&mut self) {
        // Nothing reaches canip0 through the engine after this: every user
        // holds the engine lock. The reference is dropped outside it, and
        // before unregistering (which waits for every reference).
        let dev = ENGINE.lock().as_mut().and_then(|e| e.canip.take());
        drop(dev);
        self.reg = None;
    }
}

/// Whether canip0 exists and is up (engine lock held, `canip` from the
/// engine).
pub(crate) fn is_up(canip: Option<&NetDev>) -> bool {
    canip.is_some_and(|d| d.is_up())
}

/// Counts a UDP/IP message that could not be delivered to its peer.
pub(crate) fn count_tx_error(canip: Option<&NetDev>) {
    if let Some(d) = canip {
        d.stats_tx_dropped();
    }
}

/// Rebuilds the IPv4/UDP headers in front of a received UDP/IP message
/// (whose skb has the headroom) and hands it to the IP stack. Engine lock
/// held (softirq or transmit path). If it cannot, the message is dropped
/// and the error is the status its last frame is acked with: REFUSED when
/// canip0 is gone or down, NO_MEMORY when the headers do not fit.
pub(crate) fn deliver(
    canip: Option<&NetDev>,
    mut skb: UniqueSkb,
    _src: u8,
    saddr: u32,
    daddr: u32,
    dport: u16,
) -> Result<(), AckStatus> {
    let Some(d) = canip else {
        return Err(AckStatus::Refused);
    };
    if !d.is_up() {
        d.stats_rx_dropped();
        return Err(AckStatus::Refused);
    }
    let mut hdr = [0u8; HDR_LEN];
    let id = IP_ID.fetch_add(1, Ordering::Relaxed);
    dsor_udp::build_inbound(&mut hdr, saddr, daddr, 0, dport, id, skb.data());
    let len = skb.len();
    match skb.push(HDR_LEN as u32) {
        Some(h) => h.copy_from_slice(&hdr),
        None => {
            d.stats_rx_dropped();
            return Err(AckStatus::NoMemory);
        }
    }
    skb.set_ipv4_rx();
    d.stats_rx(len);
    d.rx(skb.into_owned());
    Ok(())
}

impl Driver for CanipDriver {
    type Priv = ();
    /// DSOR is one engine of the initial namespace (netns.rst): its UDP/IP
    /// device stays there.
    const NETNS_IMMUTABLE: bool = true;

    fn setup() -> Setup {
        Setup {
            type_: crate::glue::netdev::arphrd::VOID,
            flags: crate::glue::netdev::iff::POINTOPOINT | crate::glue::netdev::iff::NOARP,
            // No IP fragments: a datagram of any length the protocol
            // carries fits. The transmit path refuses longer ones.
            mtu: 65535,
            hard_header_len: 0,
            tx_queue_len: 100,
            no_queue: false,
        }
    }

    fn open(dev: &Dev<Self>, _p: &()) -> Result {
        dev.set_carrier(true);
        dev.start_queue();
        Ok(())
    }

    fn stop(dev: &Dev<Self>, _p: &()) -> Result {
        dev.stop_queue();
        Ok(())
    }

    /// BH disabled. Takes the datagram's payload into a new transfer.
    fn start_xmit(skb: Skb, dev: &Dev<Self>, _p: &()) -> Xmit {
        let pkt = skb.data();
        if pkt.len() as u32 != skb.len() {
            dev.stats_tx_dropped();
            return Xmit::Ok;
        }
        let max = {
            let g = ENGINE.lock();
            g.as_ref().map_or(0, |e| usize::from(e.cfg.limits_max_len))
        };
        let out = match dsor_udp::parse_outbound(pkt, max) {
            Ok(o) => o,
            Err(_) => {
                dev.stats_tx_dropped();
                return Xmit::Ok;
            }
        };
        let payload = &pkt[out.payload_off..out.payload_off + out.payload_len];
        let mut msg = KVec::new();
        if msg
            .extend_from_slice(payload, kernel::alloc::flags::GFP_ATOMIC)
            .is_err()
        {
            dev.stats_tx_dropped();
            return Xmit::Ok;
        }
        let header = Header {
            len: out.payload_len as u16,
            kind: MsgKind::Udp {
                dport: out.dport,
                daddr: out.daddr,
            },
        };
        if start_udp(udp_node(out.daddr), header, msg) {
            dev.stats_tx(out.payload_len as u32);
        } else {
            dev.stats_tx_dropped();
        }
        skb.consume();
        Xmit::Ok
    }
}

/// Starts a UDP/IP message for canip0 (its transmit path, BH disabled).
/// Returns false when no slot or channel is free, and for an empty
/// datagram while the restart rule holds (see `restart_hold` in
/// socket.rs; this
/// path cannot wait, and UDP may drop).
fn start_udp(dst: u8, header: Header, payload: KVec<u8>) -> bool {
    if payload.is_empty() && now_ms() < restart_over_ms() {
        return false;
    }
    let mut g = ENGINE.lock();
    let Some(e) = g.as_mut() else { return false };
    let prio = e.cfg.udp_prio;
    match e.start(dst, prio, header, payload, Owner::Canip) {
        Ok(_) => {
            e.kick();
            true
        }
        Err(_) => false,
    }
}
