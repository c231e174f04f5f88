// SPDX-License-Identifier: GPL-2.0

//! rcan_pf: the PF_CAN protocol family (thesis 5.3.1, module `pf_can`).
//!
//! * Registers PF_CAN (29) with the socket layer and hands `socket()` to the
//!   CAN protocol registered for its protocol number, holding a reference
//!   on that protocol's module while its `create` runs.
//! * Receives every ETH_P_CAN and ETH_P_CANFD frame (two packet_type
//!   handlers, NET_RX softirq; mainline `can_rcv` and `canfd_rcv`) and
//!   dispatches it to the receivers whose filters match, through one
//!   receive table shared by every protocol (`rcan_core::rxtable`). This is
//!   the only way in: drivers hand up bus frames and echoes alike through
//!   the network core (`netif_rx` or NAPI), so receive callbacks always run
//!   in NET_RX softirq, with no driver lock held, and may transmit.
//! * Sends frames for the protocols (`rcan_send`, mainline `can_send`),
//!   looping them back to local receivers when the device cannot echo.
//!
//! Shared state and its discipline:
//!
//! * The protocol table and the list of drivers that follow the receive
//!   table: kept by the glue (`rust/glue/can/family.rs`), under
//!   `rcan_pf_mutex` for writers (process context) and RCU for readers.
//!   The thesis uses a spinlock for writers; a mutex serves the same
//!   purpose here because every writer is in process context.
//! * `TABLE`: the receive table (`glue::can::rx::RxTable`), read without
//!   locks in NET_RX softirq (`can_rcv`) and changed incrementally, one
//!   receiver at a time, under its own mutex (`rcan_rx_mutex`) by
//!   `rcan_rx_set`, `rcan_rx_reserve` and `rcan_rx_set_reserved` (process
//!   context; the last names a reserved receiver by the handle the
//!   reservation returned, so it walks no map). Removed registrations are freed by
//!   `call_rcu` callbacks, so neither writers nor `close()` wait for a grace
//!   period; each socket receiver holds a reference on its socket until
//!   then. `TABLE` serves the initial namespace; every other network
//!   namespace gets a table of its own at its first subscription (kept by
//!   the glue as pernet data, freed at the namespace's exit), so interface
//!   indexes, "every interface" receivers and frames stay inside their
//!   namespace (mainline keeps its receive lists per namespace too). All
//!   tables share `rcan_rx_mutex`.
//!
//! Lock order (outermost first): RTNL, socket lock, `rcan_rx_mutex`;
//! `rcan_pf_mutex` is never held together with `rcan_rx_mutex`.
//!
//! This file is safe Rust: the C entry points, the family and packet
//! handler registrations and every raw pointer are in the glue
//! (`glue::can::family`), which calls the [`Family`] implementation here.

#![forbid(unsafe_code)]

use crate::{family, glue, rcan_api, rcan_core};
use kernel::prelude::*;

use family::{Family, RxRequest, Target};
use glue::can::rx::{RcvHandle, RxTable, Spec};
use glue::net::Net;
use glue::netdev::NetDev;
use glue::module::{ModuleScope, ScopedModule};
use glue::skb::{Skb, UniqueSkb};
use glue::sync::RcuReadGuard;
use rcan_api::{RX_FILTER_ARB, RX_FILTER_CAN_ID};
use rcan_core::filter::ArbFilter;
use rcan_core::frame::{AnyFrame, CANFD_FDF};
use rcan_core::rxtable::{self, CanFilterKind, Filter};

/// The receive table of the initial namespace, which also holds every
/// in-kernel receiver (RCU readers in softirq, `rcan_rx_mutex` for
/// writers). Every other namespace has a table of its own
/// (`family::net_table`), made at its first subscription: its sockets'
/// interface indexes (and 0, "every interface") mean its devices, and
/// frames never cross namespaces.
static TABLE: RxTable<Target> = RxTable::new(family::RX_MUTEX);

/// The receive table of `net`, if it has one. Any context; the table
/// lives as long as `net` is borrowed.
fn table(net: &Net) -> Option<&RxTable<Target>> {
    if net.is_init() {
        Some(&TABLE)
    } else {
        family::net_table(net)
    }
}

/// The receive table of `net`, made if it has none yet. Process context;
/// sleeps. ENOMEM.
fn table_make(net: &Net) -> Result<&RxTable<Target>> {
    if net.is_init() {
        Ok(&TABLE)
    } else {
        family::net_table_make(net)
    }
}

/// Filters of a request converted on the stack; more go to the heap.
const STACK_FILTERS: usize = 8;

/// Calls `f` with the table's spec for a receiver's request: its filters
/// converted (into a buffer on the stack, or the heap for more than
/// [`STACK_FILTERS`]), the classes of its error filters added to its error
/// mask, and that cut to the classes that exist. EINVAL (bad filter),
/// ENOMEM.
fn with_spec<T>(req: &RxRequest<'_>, f: impl FnOnce(Spec<'_>) -> Result<T>) -> Result<T> {
    let mut err_mask = req.err_mask & rxtable::CAN_ERR_MASK;
    let mut stack = [Filter::Id {
        id: 0,
        mask: 0,
        inv: false,
    }; STACK_FILTERS];
    let mut heap = KVec::new();
    let mut n = 0;
    for x in req.filters {
        let t = match x.kind {
            RX_FILTER_ARB => {
                Filter::Arb(ArbFilter::new(x.id, x.mask).map_err(|e| glue::errno(e.errno()))?)
            }
            RX_FILTER_CAN_ID => match Filter::from_can_filter(x.id, x.mask) {
                CanFilterKind::Frames(t) => t,
                CanFilterKind::Errors(m) => {
                    err_mask |= m;
                    continue;
                }
            },
            _ => return Err(EINVAL),
        };
        if req.filters.len() <= STACK_FILTERS {
            // Fewer filters than STACK_FILTERS, so within the buffer.
            if let Some(slot) = stack.get_mut(n) {
                *slot = t;
                n += 1;
            }
        } else {
            heap.push(t, GFP_KERNEL)?;
        }
    }
    let filters: &[Filter] = if req.filters.len() <= STACK_FILTERS {
        stack.get(..n).unwrap_or(&[])
    } else {
        &heap
    };
    f(Spec {
        ifindex: req.ifindex,
        filters,
        join: req.join,
        err_mask,
        cookie: req.cookie,
    })
}

impl Family for PfCan {
    /// See [`rcan_api::rx_set`]. Process context; sleeps (allocates, takes
    /// the table's mutex, then `rcan_pf_mutex` to tell the drivers).
    fn rx_set(net: &Net, id: usize, new: Option<(RxRequest<'_>, Target)>) -> Result {
        let changed = match new {
            Some((req, t)) => {
                let table = table_make(net)?;
                with_spec(&req, |spec| table.set(id, Some((spec, t))))?
            }
            // A namespace without a table has no receiver to remove.
            None => match table(net) {
                Some(t) => t.set(id, None)?,
                None => return Ok(()),
            },
        };
        family::notify_listeners(&changed.ifindex);
        Ok(())
    }

    /// See [`rcan_api::rx_reserve`]. Process context; sleeps (allocates,
    /// takes the table's mutex).
    fn rx_reserve(net: &Net, id: usize, t: Target) -> Result<RcvHandle> {
        table_make(net)?.reserve(id, t)
    }

    /// See [`rcan_api::rx_set_reserved`]. Process context; sleeps (may
    /// allocate, takes the table's mutex, then `rcan_pf_mutex` if a driver
    /// listens). The filters come in the table's form: nothing is
    /// converted, and the receiver knows its table (no namespace lookup).
    fn rx_set_reserved(rcv: RcvHandle, new: Option<RxRequest<'_, Filter>>, keep: bool) -> Result {
        let spec = new.map(|req| Spec {
            ifindex: req.ifindex,
            filters: req.filters,
            join: req.join,
            err_mask: req.err_mask & rxtable::CAN_ERR_MASK,
            cookie: req.cookie,
        });
        let changed = RxTable::<Target>::set_reserved(rcv, spec, keep)?;
        family::notify_listeners(&changed.ifindex);
        Ok(())
    }

    fn rx_filters(dev: &NetDev, out: &mut [Filter]) -> Option<usize> {
        let g = RcuReadGuard::new();
        match table(dev.net(&g)) {
            Some(t) => t.filters(dev.ifindex(), out),
            None => Some(0),
        }
    }

    /// Mainline `can_send`. Process or softirq context. A classic frame
    /// (16 bytes) or a CAN FD frame (72 bytes, which gets `CANFD_FDF` set
    /// as mainline sets it); an FD frame on a classic device (MTU 16) is
    /// EMSGSIZE here (CAN_RAW refuses it earlier, with EINVAL).
    #[inline]
    fn send(mut skb: UniqueSkb, dev: &NetDev, loopback: bool) -> Result {
        // Mainline can_send's checks; the frame itself is not needed here
        // (the driver reads it).
        let Some(fd) = AnyFrame::kind(skb.data()) else {
            return Err(EINVAL);
        };
        if fd {
            // The caller gave us the only reference to an uncloned skb
            // (`UniqueSkb`), so it is ours to write.
            if let Some(flags) = skb.data_mut().get_mut(5) {
                *flags |= CANFD_FDF;
            }
        }
        if skb.len() > dev.mtu() {
            return Err(glue::neterr::EMSGSIZE());
        }
        if !dev.is_can() {
            return Err(EPERM);
        }
        if !dev.is_up() {
            return Err(glue::neterr::ENETDOWN());
        }
        skb.set_can_tx(loopback);
        // From here on the data is read-only: it may be shared with the
        // echo's clone.
        let skb = skb.into_owned();
        // A device without IFF_ECHO cannot loop the frame back itself: local
        // receivers get a copy that still names the sending socket, marked as
        // mainline's can_send marks it (PACKET_BROADCAST), through netif_rx.
        let echo = if loopback && !dev.has_echo() {
            let mut e = skb.clone_with_owner().ok_or(ENOMEM)?;
            e.set_can_rx();
            Some(e)
        } else {
            None
        };
        family::queue_xmit(skb, dev)?;
        if let Some(e) = echo {
            dev.rx(e);
        }
        Ok(())
    }

    /// Hands a received frame to every receiver that wants it, each
    /// once. NET_RX softirq, inside the core's RCU read-side section.
    /// All but the last receiver get the skb borrowed (they clone it); the
    /// last one gets our reference, so the common single-receiver case
    /// queues the skb without cloning it. Returns false if the frame was
    /// malformed (dropped). `fd`: the frame came by the ETH_P_CANFD handler
    /// and must be a CAN FD frame, else a classic one (mainline
    /// `canfd_rcv` / `can_rcv`). Receivers get both flavours; each protocol
    /// takes what it understands (CAN_RAW FD frames only with
    /// CAN_RAW_FD_FRAMES, the others classic frames only).
    #[inline(always)]
    fn rcv(g: &RcuReadGuard, skb: Skb, dev: &NetDev, fd: bool) -> bool {
        let Some(can_id) = valid_frame(&skb, dev, fd) else {
            drop(skb); // counted as a drop
            return false;
        };
        // The table of the device's namespace: only its receivers see the
        // frame.
        let Some(table) = table(dev.net(g)) else {
            skb.consume();
            return true;
        };
        let mut pending: Option<(&Target, u32)> = None;
        table.for_each_match(g, dev.ifindex(), can_id, |t, cookie| {
            if let Some((prev, c)) = pending.replace((t, cookie)) {
                // The receiver was found in the table inside our read-side
                // section, so it (with the sock reference it holds, or a
                // kernel receiver's data, whose removal waits for a grace
                // period) lives until the section ends.
                prev.deliver(g, &skb, c);
            }
        });
        match pending {
            Some((last, c)) => last.deliver_last(g, skb, c),
            None => skb.consume(),
        }
        true
    }
}

/// The identifier (with its flags) of the frame in `skb` if it is a
/// well-formed CAN frame of the flavour its handler takes (`fd`) from a
/// CAN device; drivers are trusted for nothing else. Read in place
/// (`AnyFrame::view`: the same test as `parse`, without copying the frame).
fn valid_frame(skb: &Skb, dev: &NetDev, fd: bool) -> Option<u32> {
    if !dev.is_can() {
        return None;
    }
    let (can_id, _, is_fd) = AnyFrame::view(skb.data())?;
    (is_fd == fd).then_some(can_id)
}

/// The module: PF_CAN and the packet handler while loaded.
pub(crate) struct PfCan {
    reg: Option<family::FamilyReg>,
}

impl ScopedModule for PfCan {
    fn init(_module: &'static ThisModule, _scope: &ModuleScope) -> Result<Self> {
        let reg = family::register().inspect_err(|e| {
            if e.to_errno() == EEXIST.to_errno() {
                pr_err!("PF_CAN is already registered (mainline can.ko loaded?): not loading\n");
            }
        })?;
        pr_info!("PF_CAN protocol family registered\n");
        Ok(PfCan { reg: Some(reg) })
    }
}

impl Drop for PfCan {
    fn drop(&mut self) {
        // Protocols and drivers that use us are unloaded already (module
        // dependencies), so no receiver or protocol is left. No handler
        // or socket creation runs once the registration is gone.
        self.reg = None;
        TABLE.shutdown();
        family::shutdown();
        // The table's pending call_rcu callbacks: waited for by the glue
        // after this (glue::module::Scoped).
        pr_info!("PF_CAN protocol family unregistered\n");
    }
}
