// SPDX-License-Identifier: GPL-2.0

//! rcan_loop: the CAN loopback device (thesis 5.3.5, module `canloop`).
//!
//! Registers `count` devices `can%d` (ARPHRD_CAN, IFF_NOARP, IFF_ECHO).
//! Every frame handed to a device for transmission with a loopback request
//! (`skb->pkt_type == PACKET_LOOPBACK`, set by `rcan_send` for thesis
//! sockets and for CAN_RAW sockets with CAN_RAW_LOOPBACK on, and for
//! frames written through a packet socket, as mainline's
//! `can_skb_headroom_valid` does) is reflected into the receive path as if
//! it had come back from a bus, unless the `droprate` parameter makes the
//! device drop it to simulate loss. Frames sent without a loopback request
//! are counted as sent and freed: the device is an echoing device in
//! mainline's sense (IFF_ECHO), like `vcan echo=1`. With `verbose`, each
//! frame is logged with the device name.
//!
//! A device starts as a classic CAN device (MTU 16); `ip link set canN mtu
//! 72` while it is down makes it a CAN FD device that carries both
//! flavours, `mtu 16` a classic one again (mainline vcan's rule: EBUSY
//! while up, EINVAL for other values; CAN XL MTUs are not taken).
//!
//! The echo takes the path every received frame takes: marked
//! `PACKET_BROADCAST` (the sending socket stays in `skb->sk`), queued on
//! the device's receive FIFO and handed up by the device's NAPI poll to
//! pf_can, packet sockets and tc in NET_RX softirq, never from inside
//! `start_xmit`. So a receiver may send on the device it receives from.
//!
//! Like a CAN bus, the device never reorders frames: they come back in the
//! order they were transmitted, whichever CPUs transmit them. Mainline
//! `vcan_rx` hands the echo to `netif_rx`, which queues it on the backlog
//! of the transmitting CPU; two frames sent one after the other from two
//! CPUs can then come back in the opposite order (each CPU's backlog is
//! processed on its own, and under load ksoftirqd may run one much later).
//! A stop-and-wait protocol with a 1-bit sequence number (DSOR) takes such
//! a late copy for a new frame and delivers corrupted messages
//! (dsor-wire.rst, "Guarantees"). The single FIFO, drained by the one NAPI
//! poll that never runs concurrently with itself, keeps the order.
//!
//! Contexts: `start_xmit` runs with BH disabled under the device's TX lock
//! (so the per-device counters need no lock of their own); the receive
//! FIFO (an [`SkbRing`] of `FIFO_LEN` skbs) takes no lock: it has one
//! producer, `start_xmit` (serialised by the TX lock, as canloop sets no
//! LLTX), and one consumer at a time, the NAPI poll (NET_RX softirq, never
//! concurrent with itself) or `stop` (process context, under RTNL, after
//! the core stopped transmissions and disabled the poll), which may run
//! on two CPUs at once (the ring's slot protocol is made for that);
//! `open`/`stop` run in process context under RTNL. `verbose` and `droprate` may change at any time through
//! sysfs: `start_xmit` reads them from Rust atomics ([`Mirror`]) that the
//! parameter setter writes, so a frame costs no call into the C shim.
#![forbid(unsafe_code)]

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use kernel::prelude::*;

use crate::{glue, rcan_core};

use glue::can::ctrl;
use glue::module::{ModuleScope, ScopedModule};
use glue::netdev::{Dev, Driver, Napi, Registration, Setup, Xmit};
use glue::params::Param;
use glue::ring::SkbRing;
use glue::skb::Skb;
use kernel::c_str;
use rcan_core::canloop::{DropRate, FrameDump};
use rcan_core::frame::{AnyFrame, CANFD_MTU, CAN_MTU};

/// Most devices one module instance registers.
const MAX_COUNT: u32 = 16;

// Parameter numbers shared with canloop_c.c (its rcan_module_param).
const PARAM_COUNT: i32 = 0;
const PARAM_VERBOSE: i32 = 1;
const PARAM_DROPRATE: i32 = 2;
const COUNT: Param<u32> = Param::new(PARAM_COUNT as u32);
const DROPRATE: Param<u32> = Param::new(PARAM_DROPRATE as u32);

/// The values of `verbose` and `droprate` as `start_xmit` reads them.
///
/// Starts with the C variables' defaults (0: quiet, no drops) and is
/// written only by [`param_set`], which the C setter calls for every value
/// it stores (at load, before [`CanLoop::init`], and on each sysfs write,
/// under the kernel's parameter lock): so it always holds what the C
/// variable holds or is about to. Read with relaxed loads in any context:
/// a frame sees the old or the new value, as with the C variable's
/// READ_ONCE. (`count` is read once, in `init`, through [`Param`].)
struct Mirror {
    verbose: AtomicBool,
    /// A valid [`DropRate`] percentage (0-100).
    droprate: AtomicU32,
}

static MIRROR: Mirror = Mirror {
    verbose: AtomicBool::new(false),
    droprate: AtomicU32::new(0),
};

/// Validates a parameter value for the C parameter setter
/// (`rcan_loop_param_record` in canloop_mod.rs) and, if valid, records it
/// in [`MIRROR`] just before the setter stores it: refusing a bad value
/// at insmod time makes the load fail with EINVAL. Process context.
pub(crate) fn param_set(which: i32, val: u32) -> bool {
    match which {
        PARAM_COUNT => (1..=MAX_COUNT).contains(&val),
        PARAM_VERBOSE if val <= 1 => {
            MIRROR.verbose.store(val == 1, Ordering::Relaxed);
            true
        }
        PARAM_DROPRATE if DropRate::new(val).is_some() => {
            MIRROR.droprate.store(val, Ordering::Relaxed);
            true
        }
        _ => false,
    }
}

struct LoopDriver;

/// Echoed frames not yet handed up, oldest first. A device whose FIFO is
/// full drops the echo (counted as `rx_dropped`), like a CAN controller
/// whose receive FIFO overflows.
const FIFO_LEN: usize = 512;

impl Driver for LoopDriver {
    type Priv = SkbRing;

    const NAPI_WEIGHT: u32 = 64;

    fn setup() -> Setup {
        Setup {
            // start_xmit never stops the queue: a qdisc would only add
            // work per frame.
            no_queue: true,
            ..ctrl::setup(CAN_MTU, 0)
        }
    }

    const HAS_CHANGE_MTU: bool = true;

    /// Mainline `vcan_change_mtu` without CAN XL. Process context, RTNL.
    fn change_mtu(dev: &Dev<Self>, _p: &Self::Priv, new_mtu: u32) -> Result {
        if dev.is_up() {
            return Err(EBUSY);
        }
        if new_mtu != CAN_MTU as u32 && new_mtu != CANFD_MTU as u32 {
            return Err(EINVAL);
        }
        Ok(())
    }

    fn open(dev: &Dev<Self>, _p: &Self::Priv) -> Result {
        dev.start_queue();
        Ok(())
    }

    /// Process context, RTNL; the NAPI poll is disabled already (the
    /// glue waits for a running one), so the frames still queued are
    /// dropped here.
    fn stop(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        dev.stop_queue();
        while let Some(skb) = p.pop() {
            dev.stats_rx_dropped();
            drop(skb);
        }
        Ok(())
    }

    /// NET_RX softirq; never concurrent with itself, so frames go up in
    /// FIFO order. Inline: the glue's NAPI adapter is its only caller.
    #[inline]
    fn poll(_dev: &Dev<Self>, p: &Self::Priv, napi: &Napi, budget: usize) -> usize {
        // A receiver may send on this device while a frame is handed up:
        // start_xmit pushes while this pops, without a lock. A pop that
        // leaves the FIFO empty ends the poll without looking once more:
        // a frame pushed after it is followed by its sender's
        // `napi_schedule`, which, while this poll runs, marks the instance
        // missed, so `napi_complete_done` polls again (the same handoff as
        // for a frame pushed after a pop that found the FIFO empty).
        let mut more = true;
        napi.drain(budget, || {
            if !more {
                return None;
            }
            let skb = p.pop();
            more = !p.is_empty();
            skb
        })
    }

    fn start_xmit(skb: Skb, dev: &Dev<Self>, p: &Self::Priv) -> Xmit {
        // Not a well-formed classic or FD frame, or no room to prepare a
        // packet socket's frame (mainline can_dropped_invalid_skb):
        // dropped and counted. Only a device with MTU 72 is handed FD
        // frames (pf_can and af_packet check the MTU).
        // Only the flavour is checked here; the frame is parsed only for
        // the verbose dump.
        let Some((mut skb, _fd)) = skb.can_xmit_start_kind(dev) else {
            return Xmit::Ok;
        };
        if MIRROR.verbose.load(Ordering::Relaxed) {
            if let Some(frame) = AnyFrame::parse(skb.data()) {
                pr_info!(
                    "{}: tx {}\n",
                    dev.name(),
                    FrameDump::new_any(&frame).as_str()
                );
            }
        }
        // The parameter setter only stores valid rates.
        let drop_it = match DropRate::new(MIRROR.droprate.load(Ordering::Relaxed)) {
            Some(rate) if rate.percent() > 0 => rate.should_drop(glue::random_u32()),
            _ => false,
        };
        if drop_it {
            dev.stats_tx_dropped();
            drop(skb);
            return Xmit::Ok;
        }
        // The payload length (what the statistics count): the frame's
        // `len` byte, which the check above bounded (<= 8 classic, <= 64
        // CAN FD), as `AnyFrame::len` gives it.
        let bytes = skb.data().get(4).map_or(0, |&l| u32::from(l));
        dev.stats_tx(bytes);
        if !skb.wants_echo() {
            // Nobody asked for the echo: the frame "left on the bus".
            skb.consume();
            return Xmit::Ok;
        }
        // Reflect: the skb (ours to re-mark, can_xmit_start saw to it)
        // comes back as a received, locally originated frame (mainline
        // can_create_echo_skb + vcan_rx).
        skb.set_can_rx();
        let queued = p.push(skb);
        match queued {
            Ok(()) => dev.stats_rx(bytes),
            Err(skb) => {
                dev.stats_rx_dropped();
                drop(skb);
            }
        }
        dev.napi_schedule();
        Xmit::Ok
    }
}

pub(crate) struct CanLoop {
    _devs: KVec<Registration<LoopDriver>>,
}

impl ScopedModule for CanLoop {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let count = COUNT.get();
        let mut devs = KVec::new();
        for _ in 0..count {
            let reg =
                Registration::<LoopDriver>::register(c_str!("can%d"), SkbRing::new(FIFO_LEN)?, scope)?;
            pr_info!(
                "{}: CAN loopback device, droprate {}%\n",
                reg.dev().name(),
                DROPRATE.get()
            );
            devs.push(reg, GFP_KERNEL)?;
        }
        Ok(CanLoop { _devs: devs })
    }
}
