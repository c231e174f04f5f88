// SPDX-License-Identifier: GPL-2.0

//! What the CAN controller drivers share around their chips (issue 19):
//! the `net_device` a CAN interface is, bringing it up and down around
//! the chip (the bit-timing check, the `restart-ms` timer, the interrupt
//! line, carrier and queue), and the bookkeeping of received frames and
//! echoes with the statistics mainline keeps for them (mainline's
//! `alloc_can_skb` + `netif_rx` pattern, `can_put_echo_skb` /
//! `can_get_echo_skb`, `can_free_echo_skb`, `can_dropped_invalid_skb`).
//!
//! A driver of a chip with one transmit buffer keeps the skb of the frame
//! in it ("the echo", an `Option<OwnedSkb>` under its chip lock) and calls:
//!
//! * [`setup`] from `Driver::setup`; [`btr`] for chips whose bit timing
//!   is an SJA1000-style BTR0/BTR1 pair;
//! * [`open`] first in `Driver::open`, then programs the chip with the
//!   [`Settings`] it returns and calls [`Opening::up`]; dropping the
//!   [`Opening`] instead (an error) undoes what [`open`] did;
//! * [`stop`] as `Driver::stop`, with a closure that stops the chip and
//!   hands back what it held (the echo), freed once the chip lock is
//!   released;
//! * [`rx_skb`] for each frame from the bus (or error frame), then hands
//!   the skb up (`NetDev::rx`, or its NAPI queue);
//! * [`echo_done`] when the chip says the frame went out (the skb comes
//!   back, to be handed up as the echo), [`echo_lost`] when it is lost
//!   (an abort, bus-off, restart), [`tx_drop`] for a frame the driver
//!   cannot send.
//!
//! A driver of a chip with several transmit buffers keeps one such echo
//! per buffer; [`echo_done_any`] and [`echo_dropped`] serve drivers that
//! send CAN FD frames too and count as mainline's `ctucanfd`.
//!
//! Used by the SJA1000, 82527 and CTU CAN FD drivers; canloop uses
//! [`setup`].

use crate::glue::can::dev::{CanDev, CanDevice, CanStat};
use crate::glue::can::skb::alloc_rx;
use crate::glue::netdev::{Dev, NetDev, Setup, Stat};
use crate::glue::ring::Ring;
use crate::glue::skb::{Access, OwnedSkb, Skb};
use crate::rcan_core::arb::CAN_ERR_FLAG;
use crate::rcan_core::bittiming;
use crate::rcan_core::candev::{ctrlmode, CanStats, NetErrStats, Settings};
use crate::rcan_core::frame::AnyFrame;
use kernel::prelude::*;

/// `SIOCDEVPRIVATE`: the first device-private ioctl number (a driver's
/// configuration tool's ioctls count from it).
pub(crate) const SIOCDEVPRIVATE: u32 = crate::glue::bindings::SIOCDEVPRIVATE;

/// The device parameters of a CAN interface (mainline `can_setup`):
/// `ARPHRD_CAN`, no ARP, `IFF_ECHO` (the driver echoes sent frames),
/// MTU `mtu` (`CAN_MTU` or `CANFD_MTU`), no link-layer header, a qdisc
/// with `tx_queue_len` frames. A driver whose queue never stops sets
/// `no_queue` on the result.
pub(crate) fn setup(mtu: usize, tx_queue_len: u32) -> Setup {
    Setup {
        type_: crate::glue::bindings::ARPHRD_CAN as u16,
        flags: crate::glue::bindings::net_device_flags_IFF_NOARP
            | crate::glue::bindings::net_device_flags_IFF_ECHO,
        mtu: mtu as u32,
        hard_header_len: 0,
        tx_queue_len,
        no_queue: false,
    }
}

/// The BTR0/BTR1 register pair of an SJA1000-style bit-timing register
/// (the SJA1000's, the 82527's BT0/BT1) for the device's settings: the
/// bit timing with triple sampling if the control mode asks for it; 0/0
/// while no bit timing is set (what the configuration tools' GET ioctls
/// report then). Any context.
pub(crate) fn btr(set: &Settings) -> (u8, u8) {
    if set.bittiming.bitrate == 0 {
        return (0, 0);
    }
    bittiming::to_btr(&set.bittiming, set.ctrlmode & ctrlmode::THREE_SAMPLES != 0)
}

/// A device being brought up by [`open`]: its `restart-ms` timer is
/// armed and its interrupt line requested. [`Opening::up`] completes the
/// open; dropping it undoes it (the line freed, the timer disarmed).
pub(crate) struct Opening<'a, T: CanDevice> {
    dev: &'a Dev<T>,
    can: &'a CanDev,
}

impl<T: CanDevice> Opening<'_, T> {
    /// The chip runs: carrier on, the transmit queue started. Process
    /// context (`Driver::open`), no chip lock held.
    pub(crate) fn up(self) {
        self.dev.set_carrier(true);
        self.dev.start_queue();
        core::mem::forget(self);
    }
}

impl<T: CanDevice> Drop for Opening<'_, T> {
    fn drop(&mut self) {
        self.dev.free_irq();
        self.can.disarm_restart();
    }
}

/// The first half of `Driver::open` (`ip link set canX up`, mainline
/// `open_candev` and `request_irq`): refuses a device without a bit
/// timing (`EINVAL`, logged as mainline), arms the device's `restart-ms`
/// timer and requests interrupt line `irq` (0: none, a front-end that
/// calls the handler itself). The device's [`CanDev`] is the one in its
/// own private data (`T::can_dev`), so the timer restarts this device and
/// no other. Returns the device's settings, for the driver to program the
/// chip with, and the [`Opening`]. Process context, RTNL; no chip lock
/// held.
pub(crate) fn open<T: CanDevice>(dev: &Dev<T>, irq: u32) -> Result<(Settings, Opening<'_, T>)> {
    let set = T::can_dev(dev.priv_data()).open_check(dev.name().as_str())?;
    let can = CanDev::arm_restart(dev)?;
    let opening = Opening { dev, can };
    if irq != 0 {
        // On failure the Opening's drop disarms the timer again.
        dev.request_irq(irq)?;
    }
    Ok((set, opening))
}

/// `Driver::stop` (`ip link set canX down`, mainline `close_candev`):
/// the queue stopped, the `restart-ms` timer disarmed first (so that no
/// restart starts the chip again), then `halt`, which stops the chip
/// under the driver's chip lock and returns what the chip held (the echo
/// skb, frames not yet handed up); that is freed after `halt` returns,
/// outside the lock. Then the interrupt line is freed and the carrier
/// turned off. Last, the frames still queued for the NAPI poll (which no
/// longer runs) are freed: `pop` takes one from the queue under the chip
/// lock and releases the lock before it returns, so each free runs
/// outside it. Process context, RTNL.
pub(crate) fn stop<T: CanDevice, H>(
    dev: &Dev<T>,
    halt: impl FnOnce() -> H,
    mut pop: impl FnMut() -> Option<OwnedSkb>,
) {
    dev.stop_queue();
    T::can_dev(dev.priv_data()).disarm_restart();
    drop(halt());
    dev.free_irq();
    dev.set_carrier(false);
    while let Some(skb) = pop() {
        drop(skb);
    }
}

/// The skb of `frame`, received on `dev` (or an error frame the driver
/// made), built by the one CAN skb builder and counted in the device's
/// statistics: `rx_packets`/`rx_bytes` for a data or remote frame, not
/// for an error frame (as mainline's drivers since 6.2), `rx_dropped`
/// without memory (then `None`). The caller hands it up. Any context
/// (allocates with `GFP_ATOMIC`).
pub(crate) fn rx_skb(dev: &NetDev, frame: &AnyFrame) -> Option<OwnedSkb> {
    let Some(skb) = alloc_rx(dev, frame) else {
        dev.stats_rx_dropped();
        return None;
    };
    if frame.can_id() & CAN_ERR_FLAG == 0 {
        dev.stats_rx(frame.len() as u32);
    }
    Some(skb)
}

/// Queues `skb` for the device's NAPI poll in `rxq`; a full queue drops
/// it (`rx_dropped`). Chip lock held, interrupts off (interrupt handler,
/// restart): the free of a dropped skb (an echo's destructor) is deferred.
pub(crate) fn rx_enqueue(dev: &NetDev, rxq: &mut Ring<OwnedSkb>, skb: OwnedSkb) {
    if let Err(skb) = rxq.push(skb) {
        dev.stats_rx_dropped();
        skb.drop_any();
    }
}

/// The skb of `frame` ([`rx_skb`]), queued for the NAPI poll
/// ([`rx_enqueue`]). Chip lock held, interrupts off.
pub(crate) fn rx_frame(dev: &NetDev, rxq: &mut Ring<OwnedSkb>, frame: &AnyFrame) {
    if let Some(skb) = rx_skb(dev, frame) {
        rx_enqueue(dev, rxq, skb);
    }
}

/// The frame in the transmit buffer went out: its skb, taken from
/// `echo`, comes back as the echo to hand up (`None` if there was none,
/// or if the sender asked for no echo; see [`OwnedSkb::can_echo_done`], which
/// counts the sent frame). Any context.
pub(crate) fn echo_done(dev: &NetDev, echo: &mut Option<OwnedSkb>) -> Option<OwnedSkb> {
    echo.take().and_then(|s| s.can_echo_done(dev))
}

/// The frame in the transmit buffer is lost (aborted, bus-off, a
/// restart): its skb, taken from `echo`, is freed (deferred: any context,
/// interrupts off included) and counted as `stat`. Whether there was
/// one. Any context.
pub(crate) fn echo_lost(dev: &NetDev, echo: &mut Option<OwnedSkb>, stat: Stat) -> bool {
    match echo.take() {
        Some(s) => {
            s.drop_any();
            dev.stats_err(stat);
            true
        }
        None => false,
    }
}

/// [`echo_done`] for a driver of CAN FD frames too: the echo of a
/// sent CAN FD frame counts its payload in `tx_bytes` and one
/// `tx_packets` (a classic one is counted by [`OwnedSkb::can_echo_done`]).
/// Any context.
pub(crate) fn echo_done_any(dev: &NetDev, echo: &mut Option<OwnedSkb>) -> Option<OwnedSkb> {
    let skb = echo.take()?;
    if let Some(f @ AnyFrame::Fd(_)) = AnyFrame::parse(skb.data()) {
        dev.stats_tx(f.len() as u32);
    }
    skb.can_echo_done(dev)
}

/// The frame in the transmit buffer was not sent and will not be (the
/// chip gave up on it, or a restart or bus-off flushed it): its skb,
/// taken from `echo`, is freed (deferred: any context) and counted in
/// `tx_dropped` (mainline `can_free_echo_skb` with `tx_dropped++`, and
/// `can_flush_echo_skb`). Whether there was one. Any context.
pub(crate) fn echo_dropped(dev: &NetDev, echo: &mut Option<OwnedSkb>) -> bool {
    match echo.take() {
        Some(s) => {
            s.drop_any();
            dev.stats_tx_dropped();
            true
        }
        None => false,
    }
}

/// Adds one error round's counts, as a controller core decoded them, to
/// the CAN device statistics (`ip -s -d`: bus errors, error warning,
/// error passive, bus off, arbitration lost) and the interface's error
/// statistics (an RX overrun counts as an RX error too, as in mainline).
/// Any context.
pub(crate) fn count_errors(dev: &NetDev, can: &CanDev, stats: &CanStats, net: &NetErrStats) {
    can.add(CanStat::BusError, stats.bus_error);
    can.add(CanStat::ErrorWarning, stats.error_warning);
    can.add(CanStat::ErrorPassive, stats.error_passive);
    can.add(CanStat::BusOff, stats.bus_off);
    can.add(CanStat::ArbitrationLost, stats.arbitration_lost);
    for _ in 0..net.rx_over_errors {
        dev.stats_err(Stat::RxOverErrors);
    }
    for _ in 0..net.rx_errors.saturating_sub(net.rx_over_errors) {
        dev.stats_err(Stat::RxErrors);
    }
    for _ in 0..net.tx_errors {
        dev.stats_err(Stat::TxErrors);
    }
}

/// A frame the driver does not send (listen-only, down, off the bus, a
/// frame the chip cannot send): counted in `tx_dropped` and freed
/// (mainline `can_dev_dropped_skb`). The transmit path, no chip lock
/// held.
pub(crate) fn tx_drop<A: Access>(dev: &NetDev, skb: Skb<A>) {
    dev.stats_tx_dropped();
    drop(skb);
}
