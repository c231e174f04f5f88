// SPDX-License-Identifier: GPL-2.0

//! The abstract Intel 82527 network driver (thesis 5.3.10, module
//! `i82527`): everything but register access, which the front-ends supply
//! through [`Regs`] (5.3.11: readb/writeb/memcpy_fromio/memcpy_toio).
//!
//! This file is compiled into each front-end module (`#[path]`), like the
//! SJA1000 driver; the chip logic (message-object allocation, masks,
//! interrupt handling) is the pure, host-tested `crate::rcan_chips::i82527`.
//!
//! Per device ([`I82527Priv`]): the chip, the echo skb of the frame in
//! the transmit object, the receive queue, the programmed masks and the
//! running flag behind an [`IrqSpinLock`]: the interrupt handler (hardirq
//! on a real card, softirq on the simulated one), `start_xmit`,
//! `open`/`stop`, `set_rx_mode`, the filter listener, the NAPI poll and the
//! ioctls all touch them. The TX queue is stopped from `start_xmit` until
//! the transmit object's completion: exactly one object transmits (thesis
//! 5.3.10).
//!
//! Receive path (mainline's `can_rx_offload` scheme): the interrupt
//! handler only moves frames from the chip into the device's receive
//! queue (a [`Ring`] of skbs, under the chip lock) and schedules the device's
//! NAPI poll; the poll, in NET_RX softirq with interrupts on and no lock
//! held, takes them out one at a time and hands each to the protocol
//! handlers (`netif_receive_skb`: pf_can, packet sockets, tc). Echoes go
//! through the same queue. Frames keep the order in which the chip gave
//! them: the queue is FIFO, and a NAPI instance is polled by one CPU at a
//! time, whichever CPU ran the "interrupt" (the simulated card's runs on
//! varying CPUs, where `netif_rx`'s per-CPU backlogs could reorder them).
//! No receiver ever runs under the chip lock or with interrupts off. A
//! handler that finds the queue without room for what it may add
//! ([`RX_HEADROOM`]) leaves the frames in the chip and turns the chip's
//! interrupt output off; the poll turns it back on once half the queue
//! is free, and the pending causes raise the line again (mainline c_can
//! masks its interrupts around its NAPI poll in the same way). On a real
//! bus an object left unread meanwhile is overrun and reported (MsgLst:
//! `rx_over_errors` and an error frame) instead of a frame being dropped
//! from a full queue; the simulated bus holds its next frame until the
//! object is read (`sim.rs`).
//!
//! The CAN device layer (`ip link set canX type can ...`, `rcan_dev`):
//! the device's bit timing and control modes live in its [`CanDev`] (one
//! source of truth; `i82527config`'s GET ioctl reports BT0/BT1 computed
//! from it). At probe the front-end's configured BT0/BT1 (module
//! parameters; the simulated card's default 500 kbit/s) become the
//! device's bit timing, if not both 0; `open` refuses a device without a
//! bit timing (`EINVAL`, "bit-timing not yet defined", as mainline) and
//! writes BT0/BT1 computed from it. The clock is the chip's system clock
//! (the crystal, halved with the CPU interface register's DSC), the
//! limits [`I82527_BITTIMING_CONST`]; control modes: triple sampling
//! (BT1.SPL) and berr-reporting (the status change interrupt); the rest
//! is refused with `EOPNOTSUPP`.
//!
//! Errors (the status register: LEC, WARN, BOFF): error warning, leaving
//! it, receive overruns and, with `berr-reporting on`, each last error
//! code become mainline-format error frames, queued like received frames
//! (sockets with `CAN_RAW_ERR_FILTER`, `candump -e`) and counted in the
//! CAN device statistics (`ip -s -d`). The 82527 has no readable error
//! counters and no error-passive flag: `ip -d` shows ERROR-ACTIVE,
//! ERROR-WARNING or BUS-OFF and `berr-counter tx 0 rx 0`.
//!
//! Bus-off (mainline `can_bus_off`): the chip sets INIT by itself and
//! stays off the bus; the handler turns the carrier off, keeps the queue
//! stopped and, with `restart-ms` set, arms the device's restart timer
//! ([`CanDev::bus_off`]). The restart (the timer, or `ip link set canX
//! type can restart`) sends `CAN_ERR_RESTARTED`, counts the restart and
//! initialises and starts the chip again, which rejoins the bus after 128
//! occurrences of 11 recessive bits.
#![forbid(unsafe_code)]

use crate::glue::can::ctrl::{self, SIOCDEVPRIVATE};
use crate::glue::can::dev::{link_setup, CanDev, CanDevice, CanStat, LinkSetup};
use crate::glue::module::ModuleScope;
use crate::glue::lock::{new_bh_spinlock, new_irq_spinlock, BhLock, IrqSpinLock};
use crate::glue::netdev::{capable_net_admin, Dev, Driver, NetDev, Stat, UserBuf, Xmit};
use crate::glue::ring::Ring;
use crate::glue::skb::{OwnedSkb, Skb};
use crate::rcan_api::{self, FilterListener};
use crate::rcan_chips::i82527::{
    bitrate, error_frame, masks_for, sys_clock, AnswerReq, Chip, Config, Event, I82527Error, Masks,
    Regs, State, ANSWER_LEN, CTRLMODE_SUPPORTED,
};
use crate::rcan_core::bittiming::{self, I82527_BITTIMING_CONST};
use crate::rcan_core::candev::{self, CanState, Settings};
use crate::rcan_core::frame::{AnyFrame, CAN_MTU};
use core::marker::PhantomData;
use kernel::prelude::*;

/// Interrupt-register reads per interrupt: bounds the time spent in the
/// handler on a busy bus.
const MAX_IRQ_ROUNDS: usize = 32;

/// Transmit queue length (see the SJA1000 driver: a fast sender blocks in
/// sendmsg rather than getting ENOBUFS).
const TX_QUEUE_LEN: u32 = 1000;

/// Frames the receive queue holds between two polls (a full queue drops,
/// counted in `rx_dropped`): as many as mainline's `can_rx_offload`
/// queues for NAPI weight 64 (`skb_queue_len_max`, (2 << fls(64)) * 4),
/// about the per-CPU backlog a `netif_rx` driver fills (1000). The
/// interrupt handler may run on one CPU while the device's NAPI poll is
/// owned by another that does not get to run (a busy host descheduling
/// a VM's vCPU, real-time load): 128 overflowed after some 50-100 ms of
/// that at the simulated bus's rate (`i82527_burst` under load, 54 and
/// 86 frames dropped). Allocated at probe (8 KiB per device), not on the
/// stack.
const RXQ_LEN: usize = 1024;

/// NAPI weight: frames handed up per poll.
const NAPI_WEIGHT: u32 = 64;

/// Free queue slots the interrupt handler needs before it serves the
/// chip: what one run may queue (a frame and an error frame per
/// interrupt-register read). With less room it leaves the frames in the
/// chip and turns the chip's interrupt output off until the poll has
/// made [`RX_RESUME`] room.
const RX_HEADROOM: usize = 2 * MAX_IRQ_ROUNDS;

/// Free queue slots at which the poll turns the interrupt output back on.
const RX_RESUME: usize = RXQ_LEN / 2;

/// The chip and what goes with it, under the device's lock.
pub(crate) struct ChipState<R: Regs> {
    pub(crate) chip: Chip<R>,
    /// The frame in the transmit object, kept for the echo.
    echo: Option<OwnedSkb>,
    /// Frames taken from the chip, waiting for the NAPI poll (FIFO).
    rxq: Ring<OwnedSkb>,
    running: bool,
    /// The handler turned the chip's interrupt output off: the queue had
    /// no room for what the chip holds ([`RX_HEADROOM`]). The poll turns
    /// it on again ([`RX_RESUME`]); so do open and restart.
    rx_off: bool,
}

/// Per-device driver data.
pub(crate) struct I82527Priv<R: Regs> {
    pub(crate) chip: IrqSpinLock<ChipState<R>>,
    /// Interrupt line; 0: the front-end calls the handler itself (the
    /// simulated card, whose "interrupt" is a softirq on varying CPUs).
    irq: u32,
    /// The system clock the bit timing counts, Hz (fixed at probe: the
    /// crystal and the configured DSC bit).
    clock_hz: u32,
    /// The device layer's state: bit timing, control modes, statistics.
    can: CanDev,
    /// Serialises restarts (`ip ... restart` in process context, the
    /// `restart-ms` timer in softirq) with bottom halves off, so the NAPI
    /// poll a restart schedules for `CAN_ERR_RESTARTED` runs when they
    /// come back on. Lock order: this, then the chip lock.
    restart: BhLock<()>,
}

/// The device's settings at probe: the configured BT0/BT1 decoded (bit
/// timing, triple sampling), none if both are 0 (as mainline: no bit
/// timing until user space sets one).
fn preset_settings(cfg: &Config, clock_hz: u32) -> Settings {
    if cfg.bt0 == 0 && cfg.bt1 == 0 {
        return Settings::default();
    }
    candev::settings_from_btr(cfg.bt0, cfg.bt1, clock_hz)
}

/// One registered channel: its network device, whose hardware filter
/// follows the sockets (the listening owns the registration, and drops
/// its listener before the device).
pub(crate) struct Channel<R: Regs + Send + 'static> {
    dev: rcan_api::Listening<I82527<R>>,
}

impl<R: Regs + Send + 'static> Channel<R> {
    /// Runs the device's interrupt handler, for a front-end without an
    /// interrupt line (the simulated card's timer; the ISA front-end has a
    /// real line). Whether the chip had a cause. Any context that may take
    /// the chip lock (not under it).
    #[allow(dead_code)]
    pub(crate) fn irq(&self) -> bool {
        let reg = self.dev.registration();
        <I82527<R> as Driver>::irq(reg.dev(), reg.priv_data())
    }
}

/// Probes the chip behind `regs` and, if one answers, registers a `can%d`
/// device for it on interrupt line `irq` (0: none, see [`I82527Priv`]);
/// `None` if there is no chip. Process context.
pub(crate) fn add_channel<R: Regs + Send + 'static>(
    scope: &ModuleScope,
    regs: R,
    cfg: Config,
    irq: u32,
    xtal_hz: u32,
    what: core::fmt::Arguments<'_>,
) -> Result<Option<Channel<R>>> {
    let mut chip = Chip::new(regs, cfg);
    if chip.probe().is_err() {
        return Ok(None);
    }
    let clock_hz = sys_clock(cfg.cpu_if, xtal_hz);
    let prv = I82527Priv {
        chip: new_irq_spinlock!(
            ChipState {
                chip,
                echo: None,
                rxq: Ring::new(RXQ_LEN)?,
                running: false,
                rx_off: false,
            },
            "I82527Priv::chip"
        )?,
        irq,
        clock_hz,
        can: CanDev::new(preset_settings(&cfg, clock_hz))?,
        restart: new_bh_spinlock!((), "I82527Priv::restart")?,
    };
    let reg =
        crate::glue::netdev::Registration::<I82527<R>>::register(kernel::c_str!("can%d"), prv, scope)?;
    pr_info!(
        "{}: Intel 82527, {}, irq {}, {} bit/s\n",
        reg.dev().name(),
        what,
        irq,
        bitrate(cfg.bt0, cfg.bt1, cfg.cpu_if, xtal_hz)
    );
    let dev = rcan_api::Listening::new(reg)?;
    Ok(Some(Channel { dev }))
}

/// The 82527 driver for register access `R`.
pub(crate) struct I82527<R>(PhantomData<R>);

/// The tightest masks for what the sockets bound to `dev` (or to every
/// interface) want. Any context.
fn wanted_masks(dev: &NetDev) -> Masks {
    rcan_api::wanted(dev, |w| masks_for(w, false)).unwrap_or(Masks::OPEN)
}

/// Reprograms the masks if they changed. Any context; takes the chip lock.
fn remask<R: Regs + Send + 'static>(dev: &NetDev, p: &I82527Priv<R>) {
    let m = wanted_masks(dev);
    let mut st = p.chip.lock();
    if st.chip.masks == m {
        return;
    }
    if st.running {
        st.chip.set_masks(&m);
    } else {
        st.chip.masks = m;
    }
}

/// Reads `struct rcan_i82527_setup` (`<linux/can/rcan_i82527.h>`).
const SIOCRCANI82527GET: u32 = SIOCDEVPRIVATE;
/// Publishes or withdraws a remote-frame answer (`struct
/// rcan_i82527_answer`; CAP_NET_ADMIN).
const SIOCRCANI82527ANSWER: u32 = SIOCDEVPRIVATE + 2;

impl<R: Regs + Send + 'static> Driver for I82527<R> {
    type Priv = I82527Priv<R>;
    const HAS_SET_RX_MODE: bool = true;
    const HAS_PRIVATE_IOCTL: bool = true;
    const NAPI_WEIGHT: u32 = NAPI_WEIGHT;

    fn private_ioctl(_dev: &Dev<Self>, p: &Self::Priv, cmd: u32, data: &UserBuf) -> Result {
        match cmd {
            SIOCRCANI82527GET => {
                // BT0/BT1 from the device's bit timing (what `ip link`
                // set), 0/0 while none is set.
                let set = p.can.settings();
                let (bt0, bt1) = ctrl::btr(&set);
                let mut s = p.chip.lock().chip.setup();
                s.bt0 = bt0;
                s.bt1 = bt1;
                s.restarts = p.can.stats().restarts;
                data.write(&s.to_bytes())
            }
            SIOCRCANI82527ANSWER => {
                if !capable_net_admin() {
                    return Err(EPERM);
                }
                let mut b = [0u8; ANSWER_LEN];
                data.read(&mut b)?;
                let req = AnswerReq::from_bytes(&b);
                let slot = usize::try_from(req.slot).map_err(|_| EINVAL)?;
                let mut st = p.chip.lock();
                match st.chip.set_answer(slot, req.frame.as_ref()) {
                    Ok(()) => Ok(()),
                    Err(I82527Error::BadSlot) => Err(ERANGE),
                    Err(_) => Err(EINVAL),
                }
            }
            _ => Err(crate::glue::neterr::EOPNOTSUPP()),
        }
    }

    fn setup() -> crate::glue::netdev::Setup {
        ctrl::setup(CAN_MTU, TX_QUEUE_LEN)
    }

    fn link() -> Option<LinkSetup> {
        Some(link_setup::<Self>())
    }

    const HAS_CHANGE_MTU: bool = true;

    /// `ip link set canX mtu N` (mainline `can_change_mtu`): `EBUSY` while
    /// up, `EINVAL` for 72 (no CAN FD) or any other size. Process
    /// context, RTNL.
    fn change_mtu(dev: &Dev<Self>, p: &Self::Priv, new_mtu: u32) -> Result {
        p.can.change_mtu(dev, new_mtu)
    }

    /// `ip link set canX up`. Process context, RTNL; requests the
    /// interrupt line ([`ctrl::open`]) before it takes the chip lock.
    fn open(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let (set, opening) = ctrl::open(dev, p.irq)?;
        let (bt0, bt1) = ctrl::btr(&set);
        let m = wanted_masks(dev);
        {
            let mut st = p.chip.lock();
            st.chip.cfg.bt0 = bt0;
            st.chip.cfg.bt1 = bt1;
            st.chip.berr_reporting = set.ctrlmode & candev::ctrlmode::BERR_REPORTING != 0;
            st.chip.init(&m);
            st.chip.start();
            st.running = true;
            st.rx_off = false;
        }
        opening.up();
        Ok(())
    }

    /// `ip link set canX down`. Process context, RTNL. The glue has
    /// disabled NAPI: no poll runs or starts until the next open, and the
    /// handler queues nothing once `running` is off, so what is left in
    /// the queue is freed by [`ctrl::stop`], one frame per lock hold,
    /// after the echo, outside the chip lock.
    fn stop(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        ctrl::stop(
            dev,
            || {
                let mut st = p.chip.lock();
                st.running = false;
                st.chip.stop();
                st.echo.take()
            },
            || p.chip.lock().rxq.pop(),
        );
        Ok(())
    }

    fn start_xmit(skb: Skb, dev: &Dev<Self>, p: &Self::Priv) -> Xmit {
        let Some((skb, frame)) = skb.can_xmit_start(dev) else {
            return Xmit::Ok;
        };
        // One transmit object: no next frame until this one is done.
        dev.stop_queue();
        let mut st = p.chip.lock();
        if !st.running || st.chip.state() == State::BusOff {
            // Down, or off the bus until the restart (which wakes the
            // queue): nothing to send it with.
            drop(st);
            ctrl::tx_drop(dev, skb);
            return Xmit::Ok;
        }
        match st.chip.xmit(&frame) {
            Ok(()) => st.echo = Some(skb),
            Err(_) => {
                // Error frames cannot be sent; a busy object cannot happen
                // with the queue stopped. Drop it and go on.
                drop(st);
                ctrl::tx_drop(dev, skb);
                dev.wake_queue();
            }
        }
        Xmit::Ok
    }

    fn set_rx_mode(dev: &Dev<Self>, p: &Self::Priv) {
        remask(dev, p);
    }

    fn irq(dev: &Dev<Self>, p: &Self::Priv) -> bool {
        let (handled, queued) = {
            let mut st = p.chip.lock();
            let ChipState {
                chip,
                echo,
                rxq,
                running,
                rx_off,
            } = &mut *st;
            if !*running || *rx_off {
                // Down; or the output is off (a shared line's other
                // device, or a late call): the poll turns it back on.
                return false;
            }
            if RXQ_LEN - rxq.len() < RX_HEADROOM {
                // No room for what this run may queue: the frames stay in
                // the chip and its interrupt output goes off until the
                // poll, scheduled below (the queue is not empty), has
                // made room (mainline c_can masks its interrupts around
                // its NAPI poll the same way). Meanwhile a real bus
                // overruns an unread object, reported when it is read
                // (MsgLst); the simulated bus holds the next frame.
                chip.set_irq_enabled(false);
                *rx_off = true;
                (true, true)
            } else {
                let mut bus_off = false;
                let handled = chip.irq(MAX_IRQ_ROUNDS, |ev| {
                    match ev {
                        Event::Rx(f) => ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(f)),
                        Event::TxDone => {
                            if let Some(skb) = ctrl::echo_done(dev, echo) {
                                ctrl::rx_enqueue(dev, rxq, skb);
                            }
                            dev.wake_queue();
                        }
                        Event::TxAborted => {
                            // The frame is lost with the bus-off (mainline's
                            // can_flush_echo_skb counts it as a TX error).
                            // Interrupts are off: the free is deferred. The
                            // queue stays stopped until the restart.
                            ctrl::echo_lost(dev, echo, Stat::TxErrors);
                        }
                        Event::Overrun { .. } => dev.stats_err(Stat::RxOverErrors),
                        Event::BusError { .. } => {
                            p.can.count(CanStat::BusError);
                            dev.stats_err(Stat::RxErrors);
                        }
                        Event::State(State::Warning) => p.can.count(CanStat::ErrorWarning),
                        Event::State(State::BusOff) => {
                            p.can.count(CanStat::BusOff);
                            bus_off = true;
                        }
                        Event::State(State::Active) | Event::Restarted => {}
                    }
                    if let Some(ef) = error_frame(&ev) {
                        ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(ef));
                    }
                });
                if bus_off {
                    // Off the bus until restarted: carrier off, the restart
                    // timer armed (restart-ms), the queue stopped.
                    dev.stop_queue();
                    p.can.bus_off(dev);
                }
                (handled, !rxq.is_empty())
            }
        };
        // Outside the chip lock (the poll takes it).
        if queued {
            dev.napi_schedule();
        }
        handled
    }

    fn poll(
        _dev: &Dev<Self>,
        p: &Self::Priv,
        napi: &crate::glue::netdev::Napi,
        budget: usize,
    ) -> usize {
        // One frame per lock hold: the guard goes when the closure
        // returns, before the frame is handed up.
        let done = napi.drain(budget, || p.chip.lock().rxq.pop());
        // Room again for what the handler left in the chip: its output
        // back on, which raises the line at once if a cause is pending.
        let mut st = p.chip.lock();
        if st.rx_off && RXQ_LEN - st.rxq.len() >= RX_RESUME {
            st.rx_off = false;
            if st.running {
                st.chip.set_irq_enabled(true);
            }
        }
        done
    }
}

impl<R: Regs + Send + 'static> FilterListener for I82527<R> {
    fn filters_changed(dev: &Dev<Self>, p: &Self::Priv) {
        remask(dev, p);
    }
}

/// The 82527 as the CAN device layer sees it: [`I82527_BITTIMING_CONST`]
/// over the chip's system clock; control modes triple sampling and
/// berr-reporting ([`CTRLMODE_SUPPORTED`]; the others are refused with
/// `EOPNOTSUPP`); restart after bus-off.
impl<R: Regs + Send + 'static> CanDevice for I82527<R> {
    const BITTIMING_CONST: &'static bittiming::BittimingConst = &I82527_BITTIMING_CONST;
    const CTRLMODE_SUPPORTED: u32 = CTRLMODE_SUPPORTED;
    const CAN_RESTART: bool = true;

    fn can_dev(p: &Self::Priv) -> &CanDev {
        &p.can
    }

    fn clock_hz(p: &Self::Priv) -> u32 {
        p.clock_hz
    }

    /// From the status register's WARN and BOFF: the chip tells no
    /// error-passive state.
    fn state(_dev: &Dev<Self>, p: &Self::Priv) -> CanState {
        let st = p.chip.lock();
        if !st.running {
            return CanState::Stopped;
        }
        match st.chip.state() {
            State::Active => CanState::ErrorActive,
            State::Warning => CanState::ErrorWarning,
            State::BusOff => CanState::BusOff,
        }
    }

    /// The 82527 has no readable error counters.
    fn berr_counter(_dev: &Dev<Self>, _p: &Self::Priv) -> (u16, u16) {
        (0, 0)
    }

    /// Restarts the chip after bus-off (mainline `can_restart` with
    /// `cc770`'s `CAN_MODE_START`): `CAN_ERR_RESTARTED` is queued, the
    /// carrier comes back, the restart is counted, the chip is
    /// initialised with the current masks and started, and the queue
    /// wakes. Process context (`ip link ... restart`) or softirq (the
    /// `restart-ms` timer); takes the chip lock.
    fn restart(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let m = wanted_masks(dev);
        let _bh = p.restart.lock();
        let mut echo = {
            let mut st = p.chip.lock();
            if !st.running {
                return Err(EINVAL);
            }
            let ChipState {
                chip,
                echo,
                rxq,
                rx_off,
                ..
            } = &mut *st;
            if let Some(ef) = error_frame(&Event::Restarted) {
                ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(ef));
            }
            // The restart turns the interrupt output on.
            chip.restart(&m);
            *rx_off = false;
            echo.take()
        };
        // Not expected (dropped at bus-off); freed outside the lock.
        ctrl::echo_lost(dev, &mut echo, Stat::TxErrors);
        // Outside the chip lock (the poll takes it); the poll runs when
        // `_bh` lets bottom halves run again.
        dev.napi_schedule();
        dev.set_carrier(true);
        p.can.count(CanStat::Restarts);
        dev.wake_queue();
        Ok(())
    }
}
