// SPDX-License-Identifier: GPL-2.0

//! rcan_rtime: the redundant DSOR time service (thesis 5.3.3,
//! `net/can/dsor/rtime.c`; section 3.2, `CONFIG_DSOR_RTIME`).
//!
//! Listens for the time frame (standard identifier `vehicle`) on the
//! interface `dev`. While another source sends it, the service is silent;
//! when none has arrived for `timeout_ms`, it sends the time frame (source
//! 2) at every second like `rcan_time`, and it stops at the first second
//! after the other source's frame is back. The decision is
//! `rcan_core::timesvc::Takeover`; the timers and the sending are in
//! `ticker.rs`. See Documentation/networking/rcan/time.rst.
//!
//! Parameters (C side, `rtime_c.c`): `vehicle` (default 0xc0), `dev`
//! (default "can0"), both fixed at load; `timeout_ms` (default 2500,
//! 1200-60000), writable at run time.
//!
//! Contexts: the receiver ([`TimeRx`]) runs in NET_RX softirq under RCU
//! and only stores the frame's monotonic arrival time
//! (`ticker::saw_foreign`, an atomic) or consumes the echo token of its
//! own last frame (`ticker::take_own_echo`, an atomic); the ticker's
//! realtime timer callback owns the state machine.

#![forbid(unsafe_code)]

use kernel::prelude::*;

use crate::glue::module::{ModuleScope, ScopedModule};
use crate::ticker;
use crate::{glue, rcan_api, rcan_core};

use glue::netdev::NetDev;
use glue::skb::Skb;
use rcan_api::{KernelRx, KernelRxReg, RxFilter, RX_FILTER_CAN_ID};
use rcan_core::arb::{CAN_EFF_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
use rcan_core::frame::{CanFrame, CAN_FRAME_LEN};
use rcan_core::timesvc::{is_time_id, TimeFrame, SOURCE_RTIME};

/// The receiver of time frames from every interface.
struct TimeRx;

impl KernelRx for TimeRx {
    /// Every standard data frame with the time identifier on `dev` counts
    /// as another source, whatever its payload, except the echo of this
    /// service's own frame: no sending socket, source 2, and the payload
    /// of the frame it sent last, whose echo is still due (see
    /// `ticker::take_own_echo`; an echo is marked like a bus frame, so
    /// `pkt_type` cannot tell). Frames from the bus, from user-space
    /// sockets and from `rcan_time` on this host all count. NET_RX
    /// softirq.
    fn rx(&self, skb: &Skb, dev: &NetDev) {
        let Ok(bytes) = <&[u8; CAN_FRAME_LEN]>::try_from(skb.data()) else {
            return;
        };
        let frame = CanFrame::from_bytes(bytes);
        let p = ticker::params();
        if !is_time_id(&frame, p.vehicle) || dev.name().as_bytes() != p.dev.as_bytes() {
            return;
        }
        let ours = TimeFrame::decode(&frame, p.vehicle).is_some_and(|t| t.source == SOURCE_RTIME);
        if ours && !skb.is_local() && ticker::take_own_echo(&frame.data) {
            return;
        }
        ticker::saw_foreign(glue::hrtimer::ktime_get_mono_ns());
    }
}

static RX: TimeRx = TimeRx;

pub(crate) struct RtimeModule {
    /// Dropped after `drop()` has stopped the ticker.
    _rx: KernelRxReg<TimeRx>,
}

impl ScopedModule for RtimeModule {
    fn init(_module: &'static ThisModule, scope: &ModuleScope) -> Result<Self> {
        let p = ticker::params();
        // Exactly the standard data frame `vehicle`.
        let filter = RxFilter {
            kind: RX_FILTER_CAN_ID,
            id: p.vehicle,
            mask: CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
        };
        let rx = rcan_api::rx_set_kernel(scope, &RX, 0, &[filter])?;
        ticker::start(scope, true)?;
        pr_info!(
            "{}: redundant time service for frame {:03x}: passive, takeover after {} ms of silence\n",
            p.dev.as_str(),
            p.vehicle,
            ticker::timeout_ms()
        );
        Ok(RtimeModule { _rx: rx })
    }
}

impl Drop for RtimeModule {
    fn drop(&mut self) {
        ticker::stop();
        let s = ticker::stats();
        pr_info!(
            "stopped: {} frames sent, {} seconds skipped, {} seconds missed (late timer), {} takeovers, {} backward clock steps caught\n",
            s.sent,
            s.skipped,
            s.missed,
            s.takeovers,
            s.steps_back
        );
    }
}
