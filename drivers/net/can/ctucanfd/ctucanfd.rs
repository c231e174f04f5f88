// SPDX-License-Identifier: GPL-2.0

//! The CTU CAN FD network driver: one `can%d` device per core, everything
//! but register access and probing, which the front-end supplies through
//! [`Regs`] (32-bit accesses in the core's window). The register
//! programming and frame (de)coding are the pure, host-tested
//! `crate::rcan_chips::ctucanfd` ([`Chip`]).
//!
//! Per device ([`CtuPriv`]):
//!
//! * `st`: the chip (with its TX buffer ring), the echo skb of each TX
//!   buffer, the receive queue and the running flag, behind an
//!   [`IrqSpinLock`]: the interrupt handler (hardirq), `start_xmit`
//!   (softirq/process, BH off), the NAPI poll (NET_RX softirq), `restart`
//!   and `open`/`stop` (process, RTNL) all touch the core's registers
//!   and the rings, which must not interleave.
//! * `restart`: a [`BhLock`] serialising restarts (see `restart`); lock
//!   order: it, then `st`.
//!
//! Receive path (mainline's `can_rx_offload` scheme, as the 82527
//! driver's): the interrupt handler takes the frames off the core (its RX
//! buffer, read until empty, as before) and queues their skbs, with the
//! echoes of completed TX buffers and the error frames in the order the
//! core reported them, in the device's receive queue (a [`Ring`] of skbs
//! under `st`), then schedules the device's NAPI poll (weight
//! [`NAPI_WEIGHT`]). The poll, in NET_RX softirq with interrupts on and no
//! lock held, takes them out one at a time and hands each to the protocol
//! handlers (`netif_receive_skb`). One NAPI instance is polled by one CPU
//! at a time, so frames reach user space in the core's order whichever
//! CPU the interrupt moves to; handing them to `netif_rx` from the
//! handler, as this driver did before, queued them on the backlog of the
//! CPU that took the interrupt, and two CPUs' backlogs drain
//! independently (frames were reordered after an `smp_affinity` change).
//! The core is still read in the handler, not in the poll as mainline's
//! `ctucanfd` does: the card's two cores share one interrupt line, and
//! QEMU's model drives that line from the last core whose registers were
//! touched ([`Regs::irq_sync`]); keeping the register traffic in the
//! handler, under the lock that already orders it, leaves that scheme as
//! it is tested.
//! * The TX queue is stopped while every TX buffer holds a frame and
//!   woken when the oldest completes; frames leave in queueing order (the
//!   ring rotates TX_PRIORITY, as mainline's driver does).
//!
//! Frames: classic CAN, and CAN FD (BRS and ESI as the frame says) once
//! user space turns FD on. As mainline `ctucanfd`, the device starts
//! classic (MTU 16, the core's FDE bit clear) and becomes FD with `ip link
//! set canX type can bitrate N dbitrate M fd on` (or `mtu 72`, which
//! still needs a data bit timing before `up`); `fd off` (or `mtu 16`)
//! goes back. Echo as in the SJA1000 driver: the sent skb is kept until
//! its buffer completes and then handed up (IFF_ECHO).
//!
//! The CAN device layer: nominal and data bit timing over netlink
//! (`bitrate`, `dbitrate`, written to BTR and BTR_FD at `up`), limits and
//! clock as mainline's driver (`ctu_can_fd`, 100 MHz on the PCI card),
//! and the control modes mainline's `ctucanfd` announces, programmed in
//! MODE/SETTINGS at `up` (changing them while up is refused with EBUSY
//! by the device layer): `fd` (FDE), `fd-non-iso` (NISOFD), `loopback`
//! (ILBP), `listen-only` (BMM; frames to send are dropped and counted in
//! `tx_dropped`, as mainline's `can_dev_dropped_skb`), `presume-ack`
//! (STM), `one-shot` (RTRLE, retransmit limit 0), `berr-reporting` (the
//! BEI and ALI interrupts).
//!
//! Errors as mainline's `ctucan_err_interrupt` reports them, decoded by
//! the pure core ([`Event::Error`]): the state from the core's
//! FAULT_STATE and REC/TEC on EWLI/FCSI (error warning, passive,
//! bus-off, active again), arbitration lost and bus errors (with
//! `berr-reporting`), data overrun; one error frame per round for
//! CAN_RAW sockets with `CAN_RAW_ERR_FILTER`, the CAN device statistics
//! (`ip -s -d`), the interface's error counters, `berr-counter` from
//! REC/TEC. Bus-off turns the carrier off and, with `restart-ms`, arms
//! the restart; the restart (timer or `ip link set canX type can
//! restart`) drops the frames in the TX buffers (`tx_dropped`), sends
//! `CAN_ERR_RESTARTED` and starts the core again. QEMU's model has no
//! fault confinement (FAULT_STATE and the counters read 0, no error
//! interrupt but the data overrun): the state stays error active there;
//! the simulated cores of `rcan_ctucanfd_sim` (`sim.rs`) have it, and
//! run this driver unchanged.
//! See Documentation/networking/rcan/ctucanfd.rst.
#![forbid(unsafe_code)]

use crate::glue::can::ctrl;
use crate::glue::can::dev::{link_setup, CanDev, CanDevice, CanStat, LinkSetup};
use crate::glue::lock::{
    new_bh_spinlock, new_irq_spinlock, BhLock, IrqSpinLock, StaticIrqSpinLock,
};
use crate::glue::module::ModuleScope;
use crate::glue::netdev::{Dev, Driver, NetDev, Xmit};
use crate::glue::ring::Ring;
use crate::glue::skb::{OwnedSkb, Skb};
use crate::rcan_chips::ctucanfd::{
    reg, Chip, Config, ErrReport, Event, Regs, CORE_SPAN, DATA_CONST, MAX_TXT_BUFFERS,
    NOMINAL_CONST,
};
use crate::rcan_core::bittiming;
use crate::rcan_core::candev::{
    ctrlmode, err, error_frame, CanState, Settings, CTUCANFD_CTRLMODE_SUPPORTED,
};
use crate::rcan_core::frame::{AnyFrame, CAN_MTU};
use core::marker::PhantomData;
use kernel::prelude::*;

/// Register access through one mapped PCI BAR holding `cores` cores
/// `CORE_SPAN` bytes apart: this core's window starts at `base`.
pub(crate) struct IoRegs {
    pub(crate) io: crate::glue::pci::IoMem,
    pub(crate) base: usize,
    pub(crate) cores: usize,
}

impl Regs for IoRegs {
    fn read32(&mut self, off: usize) -> u32 {
        self.io.read32(self.base + off)
    }
    fn write32(&mut self, off: usize, val: u32) {
        self.io.write32(self.base + off, val);
    }
    /// Re-raises the card's shared line for every core with an enabled
    /// cause pending (see [`Regs::irq_sync`]): writing 0 to a core's
    /// INT_STAT clears nothing, and makes QEMU's model drive the line
    /// from that core's state; only pending cores are written, so the
    /// line ends high if any core wants service. On the real card the
    /// writes change nothing. Another core's registers are read and
    /// written without its lock: INT_STAT and INT_ENA reads have no side
    /// effect and a 0 write to INT_STAT none either.
    ///
    /// The read and the write of another core are not atomic: between
    /// them that core's own interrupt handler (on another CPU, under its
    /// own lock) may acknowledge its cause, and the 0 written then drives
    /// the line from a core with nothing pending: low, while a third
    /// cause (this core's next TX completion) is pending. Nothing raises
    /// it again once traffic stops on both cores: a lost TX-done
    /// interrupt, a full TX ring, a stopped queue (`ctucanfd_burst` hung
    /// once in about 20 runs: can1 had received four frames more than
    /// can0 had completed, its four TX buffers). [`IRQ_SYNC`] makes the
    /// syncs of all cores one at a time; each operation that writes a
    /// core's registers ends with one, so the last sync runs after the
    /// last write and sees every core as it is (QEMU's own events, a
    /// frame delivered or sent, only raise the line). Taken inside a
    /// core's chip lock (hardirq, or BH off), never the other way round.
    fn irq_sync(&mut self) {
        let _one_at_a_time = IRQ_SYNC.lock();
        for c in 0..self.cores {
            let b = c * CORE_SPAN;
            if self.io.read32(b + reg::INT_STAT) & self.io.read32(b + reg::INT_ENA_SET) != 0 {
                self.io.write32(b + reg::INT_STAT, 0);
            }
        }
    }
}

/// Serialises [`IoRegs::irq_sync`] across every core of every card of
/// this module (see there); protects nothing but the order of those
/// register accesses. Any context, interrupts off while held.
static IRQ_SYNC: StaticIrqSpinLock<()> =
    StaticIrqSpinLock::new((), kernel::c_str!("ctucanfd_irq_sync"));

/// Transmit queue length, as the SJA1000 driver's: longer than what a
/// socket's default send buffer holds, so a fast sender blocks in
/// sendmsg instead of getting ENOBUFS.
const TX_QUEUE_LEN: u32 = 1000;

/// Frames the receive queue holds between two polls (a full queue drops,
/// counted in `rx_dropped`): as the 82527 driver's, about the per-CPU
/// backlog `netif_rx` gave (1000) and mainline's `can_rx_offload` queue
/// for weight 64; the handler may run on one CPU while the poll is owned
/// by another that does not get to run. Allocated at probe.
const RXQ_LEN: usize = 1024;

/// NAPI weight: frames handed up per poll (mainline `ctucanfd`'s).
const NAPI_WEIGHT: u32 = 64;

/// The chip and what goes with it, under the device's lock.
pub(crate) struct ChipState<R: Regs> {
    chip: Chip<R>,
    /// The skb of the frame in each TX buffer (its echo).
    echo: [Option<OwnedSkb>; MAX_TXT_BUFFERS],
    /// Frames taken from the core (and echoes, error frames) waiting for
    /// the NAPI poll (FIFO).
    rxq: Ring<OwnedSkb>,
    running: bool,
}

/// Per-device driver data.
pub(crate) struct CtuPriv<R: Regs> {
    st: IrqSpinLock<ChipState<R>>,
    /// Interrupt line (shared by the card's cores and others).
    irq: u32,
    /// Core clock in Hz (the bit timing counts its periods).
    clock_hz: u32,
    /// The device layer's state: bit timing, statistics.
    can: CanDev,
    /// Serialises restarts (`ip ... restart` in process context, the
    /// `restart-ms` timer in softirq) with bottom halves off, so the NAPI
    /// poll a restart schedules for `CAN_ERR_RESTARTED` runs when they
    /// come back on. Lock order: this, then `st`.
    restart: BhLock<()>,
}

/// One registered core.
pub(crate) struct Core<R: Regs + Send + 'static> {
    reg: crate::glue::netdev::Registration<CtuCanFd<R>>,
}

impl<R: Regs + Send + 'static> Core<R> {
    /// Runs the device's interrupt handler, for a front-end without an
    /// interrupt line (irq 0: the simulated card `rcan_ctucanfd_sim`,
    /// whose bus is a softirq timer). Whether the core had a cause. Any
    /// context that may take the chip lock (not under it).
    #[allow(dead_code)]
    pub(crate) fn irq(&self) -> bool {
        <CtuCanFd<R> as Driver>::irq(self.reg.dev(), self.reg.priv_data())
    }
}

/// Probes the core behind `regs` and, if one answers (DEVICE_ID 0xCAFD),
/// registers a `can%d` device for it on interrupt line `irq` with the
/// settings `preset` (a front-end's module parameters through
/// [`preset_settings`](crate::glue::can::dev::preset_settings), or none);
/// `None` if there is no core. Logs the device name with `what`. Process context
/// (front-end probe).
pub(crate) fn add_core<R: Regs + Send + 'static>(
    scope: &ModuleScope,
    regs: R,
    irq: u32,
    clock_hz: u32,
    preset: Settings,
    what: core::fmt::Arguments<'_>,
) -> Result<Option<Core<R>>> {
    let mut chip = Chip::new(regs);
    if chip.probe().is_err() {
        return Ok(None);
    }
    let bufs = chip.ring().buffers();
    let prv = CtuPriv {
        st: new_irq_spinlock!(
            ChipState {
                chip,
                echo: Default::default(),
                rxq: Ring::new(RXQ_LEN)?,
                running: false,
            },
            "CtuPriv::st"
        )?,
        irq,
        clock_hz,
        can: CanDev::new(preset)?,
        restart: new_bh_spinlock!((), "CtuPriv::restart")?,
    };
    let reg = crate::glue::netdev::Registration::<CtuCanFd<R>>::register(
        kernel::c_str!("can%d"),
        prv,
        scope,
    )?;
    pr_info!(
        "{}: CTU CAN FD, {}, irq {}, {} TX buffers\n",
        reg.dev().name(),
        what,
        irq,
        bufs
    );
    if preset.bittiming.bitrate != 0 {
        pr_info!(
            "{}: bit timing from module parameters: bitrate {}, dbitrate {}\n",
            reg.dev().name(),
            preset.bittiming.bitrate,
            preset.data_bittiming.bitrate
        );
    }
    Ok(Some(Core { reg }))
}

/// The CTU CAN FD driver for register access `R`.
pub(crate) struct CtuCanFd<R>(PhantomData<R>);

/// Mainline's names of the states (`ctucan_state_to_str`), for the log.
fn state_name(s: CanState) -> &'static str {
    match s {
        CanState::ErrorActive => "CAN_STATE_ERROR_ACTIVE",
        CanState::ErrorWarning => "CAN_STATE_ERROR_WARNING",
        CanState::ErrorPassive => "CAN_STATE_ERROR_PASSIVE",
        CanState::BusOff => "CAN_STATE_BUS_OFF",
        CanState::Stopped => "CAN_STATE_STOPPED",
        CanState::Sleeping => "CAN_STATE_SLEEPING",
    }
}

/// Counts what an error round reported (the CAN device statistics and
/// the interface's error counters), logs a state change as mainline
/// does, and queues the error frame for the NAPI poll. Hardirq context
/// (the chip lock held).
fn report_error<R: Regs>(dev: &NetDev, p: &CtuPriv<R>, rxq: &mut Ring<OwnedSkb>, r: &ErrReport) {
    ctrl::count_errors(dev, &p.can, &r.stats, &r.net);
    if let Some((from, to)) = r.state {
        pr_info!(
            "{}: state changes from {} to {}\n",
            dev.name(),
            state_name(from),
            state_name(to)
        );
    }
    ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(r.frame));
}

/// What [`Chip::start`] programs for the device layer's settings: BTR
/// from the bit timing, BTR_FD from the data bit timing (the nominal one
/// while none is set: classic CAN has no data phase), and the control
/// modes (FDE with `fd on`, NISOFD with `fd-non-iso on`, ILBP, BMM, STM,
/// RTRLE, the BEI/ALI interrupts).
fn config(s: &Settings) -> Config {
    let on = |m: u32| s.ctrlmode & m != 0;
    let fd = on(ctrlmode::FD);
    Config {
        nominal: s.bittiming,
        data: if s.data_bittiming.bitrate != 0 {
            s.data_bittiming
        } else {
            s.bittiming
        },
        fd,
        fd_non_iso: fd && on(ctrlmode::FD_NON_ISO),
        listen_only: on(ctrlmode::LISTENONLY),
        loopback: on(ctrlmode::LOOPBACK),
        presume_ack: on(ctrlmode::PRESUME_ACK),
        one_shot: on(ctrlmode::ONE_SHOT),
        berr_reporting: on(ctrlmode::BERR_REPORTING),
    }
}

impl<R: Regs + Send + 'static> Driver for CtuCanFd<R> {
    type Priv = CtuPriv<R>;

    /// Classic until `fd on` (mainline's alloc_candev: CAN_MTU).
    fn setup() -> crate::glue::netdev::Setup {
        ctrl::setup(CAN_MTU, TX_QUEUE_LEN)
    }

    fn link() -> Option<LinkSetup> {
        Some(link_setup::<Self>())
    }

    const HAS_CHANGE_MTU: bool = true;
    const NAPI_WEIGHT: u32 = NAPI_WEIGHT;

    /// `ip link set canX mtu 72|16`: FD on or off (mainline
    /// `can_change_mtu`). Process context, RTNL.
    fn change_mtu(dev: &Dev<Self>, p: &Self::Priv, new_mtu: u32) -> Result {
        p.can.change_mtu(dev, new_mtu)
    }

    /// `ip link set canX up`. Process context, RTNL: refuses a device
    /// without a bit timing, arms the restart timer and requests the
    /// (shared) interrupt line ([`ctrl::open`]), then starts the core
    /// under the chip lock.
    fn open(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let (set, opening) = ctrl::open(dev, p.irq)?;
        {
            let mut st = p.st.lock();
            st.chip.start(&config(&set));
            st.running = true;
        }
        opening.up();
        Ok(())
    }

    /// `ip link set canX down`. Process context, RTNL: stops the core;
    /// the frames still in its TX buffers are freed after the chip lock
    /// ([`ctrl::stop`]). The glue has disabled NAPI: no poll runs or
    /// starts until the next open, and the handler queues nothing once
    /// `running` is off, so what is left in the receive queue is freed
    /// by [`ctrl::stop`], one frame per lock hold, outside the chip lock.
    fn stop(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        ctrl::stop(
            dev,
            || {
                let mut st = p.st.lock();
                st.running = false;
                st.chip.stop();
                core::mem::take(&mut st.echo)
            },
            || p.st.lock().rxq.pop(),
        );
        Ok(())
    }

    /// Transmit path (softirq or process context, BH off); takes the
    /// chip lock.
    fn start_xmit(skb: Skb, dev: &Dev<Self>, p: &Self::Priv) -> Xmit {
        let Some((skb, frame)) = skb.can_xmit_start_any(dev) else {
            return Xmit::Ok;
        };
        let mut st = p.st.lock();
        if st.chip.cfg.listen_only {
            // Mainline can_dev_dropped_skb: a listen-only controller
            // sends nothing.
            drop(st);
            ctrl::tx_drop(dev, skb);
            return Xmit::Ok;
        }
        match st.chip.xmit(&frame) {
            Ok((buf, full)) => {
                if full {
                    dev.stop_queue();
                }
                st.echo[buf] = Some(skb);
            }
            Err(_) => {
                // Error frames cannot be sent; with the queue stopped
                // while the ring is full, a busy ring cannot happen.
                drop(st);
                ctrl::tx_drop(dev, skb);
            }
        }
        Xmit::Ok
    }

    /// Hardirq context; the line is shared with the card's other core.
    /// Takes the frames, echoes and error frames off the core into the
    /// receive queue, in the core's order, and schedules the NAPI poll.
    fn irq(dev: &Dev<Self>, p: &Self::Priv) -> bool {
        let (handled, queued) = {
            let mut st = p.st.lock();
            let ChipState {
                chip,
                echo,
                rxq,
                running,
            } = &mut *st;
            if !*running {
                return false;
            }
            let mut woke = false;
            let mut bus_off = false;
            let handled = chip.irq(|ev| match ev {
                Event::Rx(f) => ctrl::rx_frame(dev, rxq, &f),
                Event::TxDone { buf, ok } => {
                    if let Some(e) = echo.get_mut(buf) {
                        if ok {
                            if let Some(skb) = ctrl::echo_done_any(dev, e) {
                                ctrl::rx_enqueue(dev, rxq, skb);
                            }
                        } else {
                            // Mainline: a frame the core gave up on
                            // (one-shot, abort) is dropped, not echoed.
                            ctrl::echo_dropped(dev, e);
                        }
                    }
                    woke = true;
                }
                Event::Error(r) => {
                    report_error(dev, p, rxq, &r);
                    bus_off |= r.bus_off;
                }
            });
            if bus_off {
                // Mainline can_bus_off: carrier off, restart timer armed
                // with restart-ms; the frames in the TX buffers wait for
                // the restart.
                p.can.bus_off(dev);
            }
            if woke {
                dev.wake_queue();
            }
            (handled, !rxq.is_empty())
        };
        // Outside the chip lock (the poll takes it).
        if queued {
            dev.napi_schedule();
        }
        handled
    }

    /// The NAPI poll (NET_RX softirq): hands up to `budget` queued frames
    /// to the protocol handlers, oldest first.
    fn poll(
        _dev: &Dev<Self>,
        p: &Self::Priv,
        napi: &crate::glue::netdev::Napi,
        budget: usize,
    ) -> usize {
        // One frame per lock hold: the guard goes when the closure
        // returns, before the frame is handed up.
        napi.drain(budget, || p.st.lock().rxq.pop())
    }
}

/// The CTU CAN FD as the CAN device layer sees it: mainline
/// `ctucanfd`'s nominal and data bit-timing limits and control modes,
/// restart after bus-off.
impl<R: Regs + Send + 'static> CanDevice for CtuCanFd<R> {
    const BITTIMING_CONST: &'static bittiming::BittimingConst = &NOMINAL_CONST;
    const DATA_BITTIMING_CONST: Option<&'static bittiming::BittimingConst> = Some(&DATA_CONST);
    const CTRLMODE_SUPPORTED: u32 = CTUCANFD_CTRLMODE_SUPPORTED;
    const CAN_RESTART: bool = true;

    fn can_dev(p: &Self::Priv) -> &CanDev {
        &p.can
    }

    fn clock_hz(p: &Self::Priv) -> u32 {
        p.clock_hz
    }

    /// For `ip -d link` and `changelink` (rtnetlink). Process context,
    /// RTNL; takes the chip lock.
    fn state(_dev: &Dev<Self>, p: &Self::Priv) -> CanState {
        let st = p.st.lock();
        if !st.running {
            return CanState::Stopped;
        }
        st.chip.state()
    }

    /// REC/TEC for `ip -d link`'s berr-counter. Process context, RTNL;
    /// takes the chip lock.
    fn berr_counter(_dev: &Dev<Self>, p: &Self::Priv) -> (u16, u16) {
        p.st.lock().chip.berr_counter()
    }

    /// Restarts the core after bus-off (mainline `can_restart`, with
    /// `can_flush_echo_skb`, and `ctucan_do_set_mode(CAN_MODE_START)`):
    /// the frames in the TX buffers are dropped (`tx_dropped`),
    /// the core is reset and started, `CAN_ERR_RESTARTED` is queued for
    /// the NAPI poll (after what the core gave before), the carrier comes
    /// back, the restart is counted and the queue wakes. Process context
    /// (`ip link ... restart`) or softirq (the `restart-ms` timer); takes
    /// the restart lock (bottom halves off), then the chip lock.
    fn restart(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let _bh = p.restart.lock();
        // The echoes taken and the core restarted under one lock hold, so
        // that no frame queued in between is forgotten by the reset.
        let mut lost = {
            let mut st = p.st.lock();
            if !st.running {
                return Err(EINVAL);
            }
            st.chip.restart();
            let mut cf = error_frame();
            cf.can_id |= err::RESTARTED;
            ctrl::rx_frame(dev, &mut st.rxq, &AnyFrame::Classic(cf));
            core::mem::take(&mut st.echo)
        };
        for e in lost.iter_mut() {
            ctrl::echo_dropped(dev, e);
        }
        // Outside the chip lock (the poll takes it); the poll runs when
        // `_bh` lets bottom halves run again.
        dev.napi_schedule();
        dev.set_carrier(true);
        p.can.count(CanStat::Restarts);
        dev.wake_queue();
        Ok(())
    }
}
