// SPDX-License-Identifier: GPL-2.0

//! rcan_dsor: the DSOR higher-layer CAN protocol (thesis 5.2.6 and 5.3.3,
//! module `candsor`: `dsor/protocol.c`, `dsor/socket.c`, `dsor/udpip.c`).
//!
//! `socket(PF_CAN, SOCK_DGRAM, CANPROTO_DSOR)` sends and receives messages
//! of up to 65535 bytes, carried reliably (stop-and-wait) in header, body
//! and ack frames on one CAN interface (parameter `ifname`). The wire
//! format is Documentation/networking/rcan/dsor-wire.rst; the socket API,
//! parameters and errors are Documentation/networking/rcan/dsor.rst. The
//! protocol machines are the pure `rcan_core::dsor_tx` / `dsor_rx`; this
//! module runs them: it owns their state, feeds them frames and time, and
//! sends what they produce.
//!
//! One file per concern, each `#![forbid(unsafe_code)]`, all under the
//! crate root `candsor_mod.rs`:
//!
//! * `candsor.rs` (this file): load, registrations, unload.
//! * `params.rs`: the module parameters, validated into a [`Config`](crate::params::Config).
//! * `engine.rs`: the protocol state ([`Engine`](crate::engine::Engine) under [`ENGINE`]):
//!   running transfers, reassembly, bound sockets, the send queue.
//! * `rx.rs`: the in-kernel receiver of DSOR frames ([`DsorRx`]) and the
//!   delivery of complete messages to sockets and `canip0`.
//! * `timers.rs`: [`Tick`](crate::timers::Tick), the soft hrtimer that sends queued frames and
//!   runs the protocol timers.
//! * `socket.rs`: the `CANPROTO_DSOR` socket calls ([`DsorProto`]).
//! * `stats.rs`: the counters printed at unload ([`Stats`](crate::stats::Stats)).
//! * `udpip.rs`: the `canip0` device (UDP/IP over DSOR).
//!
//! Contexts and locks:
//!
//! * [`ENGINE`] (a BH spinlock, lockdep class `rcan_dsor::ENGINE`) protects all
//!   protocol state: the reassembly table, the running transfers, the
//!   stream table, the bound sockets and the queue of frames to send. It is
//!   taken in process context (system calls), in the NET_RX softirq
//!   ([`DsorRx`]'s `rx`, the receive callback), in the `HRTIMER_SOFTIRQ`
//!   ([`Tick`](crate::timers::Tick)) and in `canip0`'s transmit path. Nothing sleeps or sends
//!   frames under it; socket receive queues (their own spinlock) are fed
//!   under it, so the order is ENGINE -> queue lock.
//! * Frames are queued on `Engine::out` under [`ENGINE`] and sent by one
//!   drainer at a time after the lock is dropped (`timers::drain_locked`):
//!   the receive callback itself when a frame it handled queued answers
//!   (it runs in NET_RX softirq and may send, see `KernelRx` in
//!   rust/glue/can/proto.rs), else [`Tick`](crate::timers::Tick), a soft
//!   hrtimer that is kicked to "now" when frames are queued and otherwise
//!   armed for the earliest protocol deadline.
//! * Blocking senders sleep on [`WAITQ`] until their
//!   transfer has finished; every finished transfer and every freed
//!   channel wakes all waiters, which re-check under the lock.
//! * [`MODULE`]`.sockets` (every open socket, for the notifier) is under
//!   RTNL, as in the other protocol modules.

#![forbid(unsafe_code)]

use core::sync::atomic::Ordering;
use kernel::c_str;
use kernel::prelude::*;

use crate::engine::{new_engine, now_ms, ENGINE, LOADED_MS, NODE, WAITQ};
use crate::glue::hrtimer::{ClockId, HrTimerMode};
use crate::glue::module::{ModuleScope, ScopedModule};
use crate::glue::neterr;
use crate::params::load_config;
use crate::rcan_api::{self, KernelRxReg, ProtoRegistration, RxFilter, RX_FILTER_CAN_ID};
use crate::rcan_core::arb::{CAN_EFF_FLAG, CAN_RTR_FLAG};
use crate::rcan_core::dsor_wire;
use crate::rx::{DsorRx, RX};
use crate::socket::{DsorProto, CANPROTO_DSOR, MODULE};
use crate::timers::{STOPPING, TIMER};
use crate::udpip;

/// Registrations that pf_can and the network core hold; dropped in
/// this order (the protocol, then the receiver, then canip0).
struct Regs {
    _proto: ProtoRegistration<DsorProto>,
    _rx: KernelRxReg<DsorRx>,
    _canip: Option<udpip::Canip>,
}

pub(crate) struct DsorModule {
    regs: Option<Regs>,
}

/// Stops the sender timer and frees all protocol state: running transfers
/// fail (their owners are told), partial messages are freed. Process
/// context; no receiver, socket or canip0 transmit can reach the engine
/// any more.
fn teardown_engine() {
    STOPPING.store(true, Ordering::Relaxed);
    TIMER.cancel();
    let engine = ENGINE.lock().take();
    // A callback that ran before the take may have re-armed the timer.
    TIMER.cancel();
    if let Some(mut e) = engine {
        e.fail_all(neterr::ENETDOWN().to_errno());
        e.stats.log_at_unload();
        drop(e);
    }
    WAITQ.wake_all();
}

fn register_all(scope: &ModuleScope, node: u8, canip: bool) -> Result<Regs> {
    let (fid, fmask) = dsor_wire::rx_filter(node);
    let filter = RxFilter {
        kind: RX_FILTER_CAN_ID,
        id: fid | CAN_EFF_FLAG,
        mask: fmask | CAN_EFF_FLAG | CAN_RTR_FLAG,
    };
    let rx = rcan_api::rx_set_kernel(scope, &RX, 0, &[filter])?;
    let canip = if canip {
        Some(udpip::Canip::register(scope)?)
    } else {
        None
    };
    let proto = MODULE.register(c_str!("CANPROTO_DSOR"), scope)?;
    Ok(Regs {
        _proto: proto,
        _rx: rx,
        _canip: canip,
    })
}

impl ScopedModule for DsorModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let cfg = load_config()?;
        let (node, canip, ifname) = (cfg.node, cfg.canip, cfg.ifname);
        let engine = new_engine(cfg)?;
        NODE.store(u32::from(node), Ordering::Relaxed);
        LOADED_MS.store(now_ms(), Ordering::Relaxed);
        TIMER.init(scope, ClockId::Monotonic, HrTimerMode::AbsoluteSoft, ())?;
        *ENGINE.lock() = Some(engine);
        match register_all(scope, node, canip) {
            Ok(regs) => {
                pr_info!(
                    "{}: CANPROTO_DSOR ({}) node 0x{:02x}\n",
                    ifname.as_str(),
                    CANPROTO_DSOR,
                    node
                );
                Ok(DsorModule { regs: Some(regs) })
            }
            Err(e) => {
                // register_all undid its own partial work (guards dropped).
                teardown_engine();
                Err(e)
            }
        }
    }
}

impl Drop for DsorModule {
    fn drop(&mut self) {
        // Sockets hold the module, so none is left when this runs. The
        // protocol goes first (Regs' field order); no receive callback
        // runs after the receiver guard is dropped, and canip0's transmit
        // path is gone with its registration.
        self.regs = None;
        teardown_engine();
    }
}
