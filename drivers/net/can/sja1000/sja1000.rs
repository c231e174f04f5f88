// SPDX-License-Identifier: GPL-2.0

//! The abstract SJA1000 network driver (thesis 5.3.6, module `sja1000`):
//! everything but register access and probing, which the front-ends
//! supply through [`Regs`] (thesis: read/write/readn/writen).
//!
//! This file is compiled into each front-end module (`#[path]`), so a
//! front-end and the driver it drives are one module; the chip logic
//! itself is the pure, host-tested `crate::rcan_chips::sja1000`.
//!
//! Per device ([`Sja1000Priv`]):
//!
//! * `chip`: the chip, the echo skb of the frame in the TX buffer, the
//!   programmed hardware filter, the receive queue and the running flag,
//!   behind an [`IrqSpinLock`]: the interrupt handler (hardirq), `start_xmit`
//!   (softirq/process, BH off), `open`/`stop` (process, RTNL),
//!   `set_rx_mode` (BH off), the filter listener (process), `restart` and
//!   the NAPI poll (NET_RX softirq) all touch the chip's registers or the
//!   queue, which must not interleave.
//! * `bh`: a [`BhLock`] taken around the process-context paths that queue
//!   frames (the filter listener, `restart`), so that the NAPI poll they
//!   schedule runs when bottom halves come back on. Lock order: it, then
//!   `chip`.
//!
//! Receive path (mainline's `can_rx_offload` scheme, as the 82527 and CTU
//! CAN FD drivers'; mainline's `sja1000` hands frames to `netif_rx` from
//! its interrupt): the interrupt handler reads the receive FIFO and
//! queues the frames' skbs, with the echoes and error frames in the order
//! the chip reported them, in the device's receive queue (a [`Ring`] of
//! skbs under `chip`), then schedules the device's NAPI poll (weight
//! [`NAPI_WEIGHT`]); the poll (NET_RX softirq, interrupts on, no lock
//! held) hands them to the stack one at a time (`netif_receive_skb`).
//! One NAPI instance is polled by one CPU at a time, so frames keep the
//! chip's order whichever CPU takes the interrupt; with `netif_rx`, frames
//! queued in two CPUs' backlogs after the interrupt moved drained
//! independently. The frames a filter change reads out of the FIFO go
//! through the same queue.
//! * The TX queue is stopped from `start_xmit` until the chip reports the
//!   frame sent or aborted (one TX buffer, thesis 5.3.6).
//!
//! Echo (IFF_ECHO): the sent skb is kept until transmission completes and
//! then fed back into the receive path (the receive queue) if its sender asked for
//! loopback (`PACKET_LOOPBACK`; a frame written through a packet socket
//! asks for it too, as on mainline), so local sockets see frames only once
//! they are really on the bus. The echo is marked as mainline's
//! `__can_get_echo_skb` marks it: `PACKET_BROADCAST`, the sending socket
//! kept in `skb->sk`. Frames from the bus are `PACKET_BROADCAST` too.
//!
//! Hardware filter and packet sockets: the acceptance filter follows what
//! CAN sockets want and opens fully while the device is promiscuous
//! (`tcpdump` without `-p`). A non-promiscuous packet socket changes
//! neither: the kernel tells a driver nothing when a packet socket binds
//! (`dev_add_pack` has no notifier or device op), so such a socket sees
//! what the CAN sockets' filters let in, like a non-promiscuous capture on
//! an Ethernet card whose MAC filter passes only the host's traffic. See
//! Documentation/networking/rcan/sja1000.rst.
//!
//! The CAN device layer (`ip link set canX type can ...`, `rcan_dev`):
//! the device's bit timing and control modes live in its
//! [`CanDev`] (one source of truth, shared with `sja1000config`'s
//! ioctl, which reads and writes them as BTR0/BTR1); `open` refuses a
//! device without a bit timing (`EINVAL`, "bit-timing not yet defined",
//! as mainline) and writes BTR0/BTR1 computed from it. The limits are
//! mainline's `sja1000` ones, the clock half the board's crystal.
//!
//! Errors (mainline `sja1000_err`): data overrun, error warning, error
//! passive, arbitration lost and, with `berr-reporting on`, bus errors are
//! decoded by the pure core ([`Event::Error`]) into one mainline-format
//! error frame per interrupt round, handed up like a received frame
//! (sockets with `CAN_RAW_ERR_FILTER`, `candump -e`), and counted in the
//! CAN device statistics (`ip -s -d`) and the interface's error counters.
//!
//! Bus-off (mainline `can_bus_off`): the chip enters reset mode by itself;
//! the handler turns the carrier off and, with `restart-ms` set, arms the
//! device's restart timer ([`CanDev::bus_off`]). The restart (the timer,
//! or `ip link set canX type can restart` when `restart-ms` is 0) drops
//! the frame that was in the TX buffer, sends `CAN_ERR_RESTARTED`, counts
//! the restart and starts the chip again (mainline `can_restart`).
//!
//! Control modes (mainline `sja1000`'s, all of them): triple sampling
//! (BTR1.SAM), listen-only (MOD.LOM; frames to send are dropped, as
//! mainline's `can_dev_dropped_skb`), presume-ack (MOD.STM), loopback
//! (MOD.STM and the self reception request CMR.SRR: the chip sends the
//! frame, needs no acknowledgement and receives it itself, so local
//! sockets see the echo and then the frame from the chip; QEMU's model
//! ignores SRR and sends nothing, as it would for mainline's driver),
//! one-shot (CMR.AT: a failed transmission is not retried and counts as
//! a TX error), berr-reporting (IER.BEI), cc-len8-dlc (a frame of 8
//! bytes with `len8_dlc` 9..15 is sent with that DLC; a received DLC
//! above 8 is kept in `len8_dlc`).
#![forbid(unsafe_code)]

use crate::glue::can::ctrl::{self, SIOCDEVPRIVATE};
use crate::glue::can::dev::{link_setup, CanDev, CanDevice, CanStat, LinkSetup};
use crate::glue::module::ModuleScope;
use crate::glue::lock::{new_bh_spinlock, new_irq_spinlock, BhLock, IrqSpinLock};
use crate::glue::netdev::{capable_net_admin, Dev, Driver, NetDev, Stat, UserBuf, Xmit};
use crate::glue::params::Param;
use crate::glue::ring::Ring;
use crate::glue::skb::{OwnedSkb, Skb};
use crate::rcan_api::{self, FilterListener};
use crate::rcan_chips::sja1000::{
    bitrate, hw_filter, restarted_frame, Chip, Config, Event, HwFilter, Regs, Setup, CDR_PELICAN,
    SETUP_LEN,
};
use crate::rcan_core::bittiming::{self, SJA1000_BITTIMING_CONST};
use crate::rcan_core::candev::{self, CanState, Settings};
use crate::rcan_core::frame::{AnyFrame, CAN_MTU};
use core::marker::PhantomData;
use kernel::prelude::*;

/// Register access through one mapped PCI BAR: register `r` at byte
/// `base + (r << shift)` (shift 0: byte spacing, 2: 32-bit spacing). The
/// access code the PCI front-ends share.
pub(crate) struct IoRegs {
    pub(crate) io: crate::glue::pci::IoMem,
    pub(crate) base: usize,
    pub(crate) shift: u32,
}

impl Regs for IoRegs {
    fn read(&mut self, reg: u8) -> u8 {
        self.io.read8(self.base + (usize::from(reg) << self.shift))
    }
    fn write(&mut self, reg: u8, val: u8) {
        self.io
            .write8(self.base + (usize::from(reg) << self.shift), val);
    }
}

/// Register access through a claimed ISA/PC/104 window
/// ([`crate::glue::isa::IoWindow`]) for the board logic of
/// `crate::rcan_chips::sja1000_boards`.
impl crate::rcan_chips::sja1000_boards::Io for crate::glue::isa::IoWindow {
    fn inb(&mut self, off: usize) -> u8 {
        self.read8(off)
    }
    fn outb(&mut self, off: usize, val: u8) {
        self.write8(off, val);
    }
}

/// The same for a mapped PCI BAR (the PITA of a PCAN-PCI), with real
/// 16-bit accesses.
impl crate::rcan_chips::sja1000_boards::Io for crate::glue::pci::IoMem {
    fn inb(&mut self, off: usize) -> u8 {
        self.read8(off)
    }
    fn outb(&mut self, off: usize, val: u8) {
        self.write8(off, val);
    }
    fn inw(&mut self, off: usize) -> u16 {
        self.read16(off)
    }
    fn outw(&mut self, off: usize, val: u16) {
        self.write16(off, val);
    }
}

/// Module parameter `btr0` of every SJA1000 front-end (number 0 in each
/// front-end's C shim): with `btr1`, an optional preset of the bit timing
/// (the thesis' CONFIG_SJA1000_BTR0/1 way); -1 (the default): none.
const BTR0: Param<i32> = Param::new(0);
/// Module parameter `btr1` (number 1).
const BTR1: Param<i32> = Param::new(1);

/// The BTR0/BTR1 preset of the module parameters, if both are given
/// (0..255). Process context (probe).
fn preset_btr() -> Option<(u8, u8)> {
    let (b0, b1) = (BTR0.get(), BTR1.get());
    Some((u8::try_from(b0).ok()?, u8::try_from(b1).ok()?))
}

/// The chip configuration of a front-end: its board's output control and
/// clock divider. The bit timing registers are written at `open` from the
/// device's bit timing ([`CanDev`]); until then they hold the module
/// parameters' preset, or 0. Process context (probe).
pub(crate) fn module_config(ocr: u8, cdr: u8) -> Config {
    let (btr0, btr1) = preset_btr().unwrap_or((0, 0));
    Config {
        btr0,
        btr1,
        ocr,
        cdr,
    }
}

/// The device's settings at probe: the module parameters' preset decoded
/// (bit timing, triple sampling), else none (as mainline: no bit timing
/// until user space sets one).
fn preset_settings(clock_hz: u32) -> Settings {
    preset_btr()
        .map(|(b0, b1)| candev::settings_from_btr(b0, b1, clock_hz))
        .unwrap_or_default()
}

/// Interrupt causes handled per interrupt before returning (mainline
/// `SJA1000_MAX_IRQ`): bounds the time spent in hardirq on a babbling bus.
const MAX_IRQ_ROUNDS: usize = 20;

/// Transmit queue length: longer than the number of frames a socket's
/// default send buffer holds (about 280 skbs of ~750 bytes in 212992), so
/// a fast sender blocks in sendmsg (thesis 5.2.3) instead of getting
/// ENOBUFS from a full queue, as it would with mainline's 10.
const TX_QUEUE_LEN: u32 = 1000;

/// Frames the receive queue holds between two polls (a full queue drops,
/// counted in `rx_dropped`): as the 82527 and CTU CAN FD drivers', about
/// the per-CPU backlog `netif_rx` gave (1000). Allocated at probe.
const RXQ_LEN: usize = 1024;

/// NAPI weight: frames handed up per poll (mainline's CAN drivers' 64).
const NAPI_WEIGHT: u32 = 64;

/// The chip and what goes with it, under the device's lock.
pub(crate) struct ChipState<R: Regs> {
    pub(crate) chip: Chip<R>,
    /// The frame in the TX buffer, kept for the echo.
    echo: Option<OwnedSkb>,
    /// The acceptance filter programmed (or to program at open, or once
    /// the TX buffer is free: `filter_pending`).
    filter: HwFilter,
    /// `filter` differs from what the chip has.
    filter_pending: bool,
    /// Frames read from the chip (and echoes, error frames) waiting for
    /// the NAPI poll (FIFO).
    rxq: Ring<OwnedSkb>,
    running: bool,
}

/// Per-device driver data.
pub(crate) struct Sja1000Priv<R: Regs> {
    pub(crate) chip: IrqSpinLock<ChipState<R>>,
    /// Interrupt line (shared); 0: none, the front-end calls the handler
    /// itself ([`Channel::irq`]).
    irq: u32,
    /// Crystal frequency of the board, for bit rates in logs and GET.
    xtal_hz: u32,
    /// The device layer's state: bit timing, control modes, statistics.
    can: CanDev,
    /// Bottom halves off around the process-context paths that queue
    /// frames and schedule the poll (see the module doc). Lock order:
    /// this, then `chip`.
    bh: BhLock<()>,
}

impl<R: Regs + Send + 'static> Sja1000Priv<R> {
    /// Driver data for a probed chip on interrupt line `irq`. Process
    /// context.
    pub(crate) fn new(chip: Chip<R>, irq: u32, xtal_hz: u32) -> Result<Self> {
        Ok(Sja1000Priv {
            chip: new_irq_spinlock!(
                ChipState {
                    chip,
                    echo: None,
                    filter: HwFilter::OPEN,
                    filter_pending: false,
                    rxq: Ring::new(RXQ_LEN)?,
                    running: false,
                },
                "Sja1000Priv::chip"
            )?,
            irq,
            xtal_hz,
            can: CanDev::new(preset_settings(xtal_hz / 2))?,
            bh: new_bh_spinlock!((), "Sja1000Priv::bh")?,
        })
    }
}

/// One registered channel: its network device, whose hardware filter
/// follows the sockets (the listening owns the registration, and drops
/// its listener before the device).
pub(crate) struct Channel<R: Regs + Send + 'static> {
    dev: rcan_api::Listening<Sja1000<R>>,
}

impl<R: Regs + Send + 'static> Channel<R> {
    /// Runs the device's interrupt handler, for a front-end without an
    /// interrupt line (irq 0: the simulated card, whose bus is a softirq
    /// timer). Whether the chip had a cause. Any context that may take
    /// the chip lock (not under it).
    #[allow(dead_code)]
    pub(crate) fn irq(&self) -> bool {
        let reg = self.dev.registration();
        <Sja1000<R> as Driver>::irq(reg.dev(), reg.priv_data())
    }
}

/// Probes the chip behind `regs` and, if one answers, registers a `can%d`
/// device for it on interrupt line `irq`; `None` if there is no chip.
/// Logs the device name with `what` (the card and channel). Process
/// context (front-end probe).
// The ISA front-end probes itself (interrupt autoprobe) and uses
// `add_probed`.
#[allow(dead_code)]
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
    add_probed(scope, chip, irq, xtal_hz, what).map(Some)
}

/// Registers a `can%d` device for a chip the front-end has already
/// probed (and, e.g., autoprobed the interrupt line of). Process context.
pub(crate) fn add_probed<R: Regs + Send + 'static>(
    scope: &ModuleScope,
    chip: Chip<R>,
    irq: u32,
    xtal_hz: u32,
    what: core::fmt::Arguments<'_>,
) -> Result<Channel<R>> {
    let prv = Sja1000Priv::new(chip, irq, xtal_hz)?;
    let reg =
        crate::glue::netdev::Registration::<Sja1000<R>>::register(kernel::c_str!("can%d"), prv, scope)?;
    pr_info!("{}: SJA1000, {}, irq {}\n", reg.dev().name(), what, irq);
    let dev = rcan_api::Listening::new(reg)?;
    Ok(Channel { dev })
}

/// The SJA1000 driver for register access `R`.
pub(crate) struct Sja1000<R>(PhantomData<R>);

/// The tightest hardware filter for what the sockets bound to `dev` (or
/// to every interface) want. Any context.
fn wanted_filter(dev: &NetDev) -> HwFilter {
    rcan_api::wanted(dev, |w| hw_filter(w, false)).unwrap_or(HwFilter::OPEN)
}

/// Reprograms the hardware filter if it changed. Process context (the
/// filter listener, [`FilterListener::filters_changed`]) or with BH
/// disabled (`set_rx_mode`, under the device's address lock); takes the
/// BH lock, then the chip lock. Frames already accepted are read out
/// first into the receive queue; while a frame waits in the TX buffer (a
/// reset would abort it) the change is left to the transmit-completion
/// interrupt.
fn refilter<R: Regs + Send + 'static>(dev: &Dev<Sja1000<R>>, p: &Sja1000Priv<R>) {
    let f = wanted_filter(dev);
    let _bh = p.bh.lock();
    let (failed, queued) = {
        let mut st = p.chip.lock();
        if st.filter == f && !st.filter_pending {
            return;
        }
        st.filter = f;
        st.filter_pending = true;
        let failed = apply_pending_filter(dev, &mut st);
        (failed, !st.rxq.is_empty())
    };
    // Outside the chip lock (the poll takes it); the poll runs when `_bh`
    // lets bottom halves run again.
    if queued {
        dev.napi_schedule();
    }
    if failed {
        pr_warn!("{}: cannot reprogram the acceptance filter\n", dev.name());
    }
}

/// Programs `st.filter` if a change is pending and the TX buffer is free;
/// the frames the chip had accepted before the reset go to the receive
/// queue. Whether the programming failed (for the caller to log after
/// the lock). Chip lock held: process context, BH-disabled, or the
/// interrupt handler (hardirq).
fn apply_pending_filter<R: Regs>(dev: &NetDev, st: &mut ChipState<R>) -> bool {
    if !st.filter_pending || st.echo.is_some() {
        return false;
    }
    if st.chip.can_state() == CanState::BusOff {
        // Leaving reset mode would end bus-off: the restart programs it.
        return false;
    }
    st.filter_pending = false;
    if !st.running {
        // Programmed at the next open.
        return false;
    }
    let f = st.filter;
    let ChipState { chip, rxq, .. } = st;
    chip.set_filter(&f, true, |ev| {
        if let Event::Rx(fr) = ev {
            ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(fr));
        }
    })
    .is_err()
}

/// Reads `struct rcan_sja1000_setup` (`<linux/can/rcan_sja1000.h>`).
const SIOCRCANSJA1000GET: u32 = SIOCDEVPRIVATE;
/// Writes the bit timing and output control of a stopped device
/// (CAP_NET_ADMIN; EBUSY while the interface is up).
const SIOCRCANSJA1000SET: u32 = SIOCDEVPRIVATE + 1;

impl<R: Regs + Send + 'static> Driver for Sja1000<R> {
    type Priv = Sja1000Priv<R>;
    const HAS_SET_RX_MODE: bool = true;
    const HAS_PRIVATE_IOCTL: bool = true;
    const NAPI_WEIGHT: u32 = NAPI_WEIGHT;

    /// `sja1000config`'s ioctls. Process context (RTNL held); takes the
    /// chip lock, copies to and from user space outside it.
    fn private_ioctl(dev: &Dev<Self>, p: &Self::Priv, cmd: u32, data: &UserBuf) -> Result {
        match cmd {
            SIOCRCANSJA1000GET => {
                let set = p.can.settings();
                let (btr0, btr1) = ctrl::btr(&set);
                let s = {
                    let mut st = p.chip.lock();
                    let cfg = st.chip.cfg;
                    let rxerr = st.chip.regs.read(crate::rcan_chips::sja1000::reg::RXERR);
                    let txerr = st.chip.regs.read(crate::rcan_chips::sja1000::reg::TXERR);
                    Setup {
                        btr0,
                        btr1,
                        ocr: cfg.ocr,
                        cdr: cfg.cdr,
                        state: st.chip.state() as u8,
                        rxerr,
                        txerr,
                        restarts: p.can.stats().restarts,
                        xtal_hz: p.xtal_hz,
                    }
                };
                data.write(&s.to_bytes())
            }
            SIOCRCANSJA1000SET => {
                if !capable_net_admin() {
                    return Err(EPERM);
                }
                let mut b = [0u8; SETUP_LEN];
                data.read(&mut b)?;
                let s = Setup::from_bytes(&b);
                // The registers can only be written in reset mode; a
                // running bus is not reconfigured under its users.
                if dev.is_up() {
                    return Err(EBUSY);
                }
                // The bit timing goes where `ip link set ... type can`
                // puts it (one source of truth); the registers are
                // written from it at open. 0x00/0x00 (what GET reports
                // while none is set) leaves it unset.
                if s.btr0 != 0 || s.btr1 != 0 {
                    let (bt, triple) = bittiming::from_btr(s.btr0, s.btr1, p.xtal_hz / 2);
                    p.can.set_registers_timing(bt, triple);
                }
                let mut st = p.chip.lock();
                st.chip.cfg.ocr = s.ocr;
                st.chip.cfg.cdr = s.cdr & !CDR_PELICAN;
                drop(st);
                pr_info!(
                    "{}: bit timing btr0 {:#04x} btr1 {:#04x} ({} bit/s)\n",
                    dev.name(),
                    s.btr0,
                    s.btr1,
                    bitrate(s.btr0, s.btr1, p.xtal_hz)
                );
                Ok(())
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
        let (btr0, btr1) = ctrl::btr(&set);
        let f = wanted_filter(dev);
        let started = {
            let mut st = p.chip.lock();
            st.chip.cfg.btr0 = btr0;
            st.chip.cfg.btr1 = btr1;
            st.chip.ctrlmode = set.ctrlmode;
            st.filter = f;
            st.filter_pending = false;
            let ok = st.chip.init(&f).and_then(|()| st.chip.start(&f)).is_ok();
            st.running = ok;
            ok
        };
        if !started {
            // Frees the line and disarms the restart timer.
            drop(opening);
            pr_err!("{}: SJA1000 does not leave reset mode\n", dev.name());
            return Err(EIO);
        }
        opening.up();
        Ok(())
    }

    /// `ip link set canX down`. Process context, RTNL; the echo skb is
    /// freed and the interrupt line released after the chip lock. The
    /// glue has disabled NAPI: no poll runs or starts until the next
    /// open, and nothing queues once `running` is off, so what is left in
    /// the receive queue is freed by [`ctrl::stop`], one frame per lock
    /// hold, outside the chip lock.
    fn stop(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        ctrl::stop(
            dev,
            || {
                let mut st = p.chip.lock();
                st.running = false;
                let _ = st.chip.stop();
                st.echo.take()
            },
            || p.chip.lock().rxq.pop(),
        );
        Ok(())
    }

    /// The transmit path: BH disabled, the device's TX lock held
    /// (softirq, or process context with BH off); takes the chip lock.
    fn start_xmit(skb: Skb, dev: &Dev<Self>, p: &Self::Priv) -> Xmit {
        let Some((skb, frame)) = skb.can_xmit_start(dev) else {
            return Xmit::Ok;
        };
        let mut st = p.chip.lock();
        if st.chip.ctrlmode & candev::ctrlmode::LISTENONLY != 0 {
            // Mainline can_dev_dropped_skb: a listen-only controller
            // sends nothing.
            drop(st);
            ctrl::tx_drop(dev, skb);
            return Xmit::Ok;
        }
        // One TX buffer: no next frame until this one is done.
        dev.stop_queue();
        match st.chip.xmit(&frame) {
            Ok(()) => st.echo = Some(skb),
            Err(_) => {
                // Error frames cannot be sent; a busy buffer cannot happen
                // with the queue stopped. Drop it and go on.
                drop(st);
                ctrl::tx_drop(dev, skb);
                dev.wake_queue();
            }
        }
        Xmit::Ok
    }

    /// Promiscuous mode changed. BH disabled, the device's address lock
    /// held (process context); see [`refilter`].
    fn set_rx_mode(dev: &Dev<Self>, p: &Self::Priv) {
        refilter(dev, p);
    }

    /// Hardirq context (the line may be shared with the other channels
    /// of the card and with other devices), or HRTIMER_SOFTIRQ softirq
    /// for the simulated card, whose bus timer calls it
    /// ([`Channel::irq`]) with interrupts enabled. Takes the chip lock
    /// (interrupts off); frames from the bus, echoes and error frames go
    /// to the receive queue under it, in the chip's order, and the NAPI
    /// poll is scheduled after it.
    fn irq(dev: &Dev<Self>, p: &Self::Priv) -> bool {
        let mut st = p.chip.lock();
        let ChipState {
            chip,
            echo,
            running,
            rxq,
            ..
        } = &mut *st;
        if !*running {
            // A board latch left over from before `stop` (PCAN-PCI's PITA)
            // is still acknowledged, or a shared line would keep firing.
            return chip.regs.irq_done();
        }
        let one_shot = chip.ctrlmode & candev::ctrlmode::ONE_SHOT != 0;
        let mut bus_off = false;
        let handled = chip.irq(MAX_IRQ_ROUNDS, |ev| match ev {
            Event::Rx(f) => ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(f)),
            Event::TxDone => {
                if let Some(skb) = ctrl::echo_done(dev, echo) {
                    ctrl::rx_enqueue(dev, rxq, skb);
                }
                dev.wake_queue();
            }
            Event::TxAborted => {
                // Interrupts are off: the free is deferred.
                if let Some(s) = echo.take() {
                    s.drop_any();
                }
                // Mainline: a failed one-shot transmission is a TX error.
                dev.stats_err(if one_shot {
                    Stat::TxErrors
                } else {
                    Stat::TxAborted
                });
                dev.wake_queue();
            }
            Event::Error(r) => {
                ctrl::count_errors(dev, &p.can, &r.stats, &r.net);
                ctrl::rx_frame(dev, rxq, &AnyFrame::Classic(r.frame));
                bus_off |= r.bus_off;
            }
        });
        if bus_off {
            // The chip is in reset mode until restarted; the frame in the
            // TX buffer (if any) stays with its echo until then.
            p.can.bus_off(dev);
        }
        // The board's acknowledgement (PITA on PCAN-PCI) comes after the
        // chip's causes are cleared, or the line would fire again at once.
        let board = chip.regs.irq_done();
        // A filter change that waited for the TX buffer; the frames it
        // reads out go to the receive queue too.
        let failed = apply_pending_filter(dev, &mut st);
        let queued = !st.rxq.is_empty();
        drop(st);
        // Outside the chip lock (the poll takes it).
        if queued {
            dev.napi_schedule();
        }
        if failed {
            pr_warn!("{}: cannot reprogram the acceptance filter\n", dev.name());
        }
        handled || board
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
        napi.drain(budget, || p.chip.lock().rxq.pop())
    }
}

impl<R: Regs + Send + 'static> FilterListener for Sja1000<R> {
    /// Process context, pf_can's writers' mutex held; see [`refilter`].
    fn filters_changed(dev: &Dev<Self>, p: &Self::Priv) {
        refilter(dev, p);
    }
}

/// The SJA1000 as the CAN device layer sees it: mainline `sja1000`'s
/// bit-timing limits and control modes (loopback, listen-only, triple
/// sampling, one-shot, berr-reporting, presume-ack, cc-len8-dlc);
/// restart after bus-off.
impl<R: Regs + Send + 'static> CanDevice for Sja1000<R> {
    const BITTIMING_CONST: &'static bittiming::BittimingConst = &SJA1000_BITTIMING_CONST;
    const CTRLMODE_SUPPORTED: u32 = candev::SJA1000_CTRLMODE_SUPPORTED;
    const CAN_RESTART: bool = true;

    fn can_dev(p: &Self::Priv) -> &CanDev {
        &p.can
    }

    /// The SJA1000 counts its bit timing in periods of half the crystal.
    fn clock_hz(p: &Self::Priv) -> u32 {
        p.xtal_hz / 2
    }

    /// For `ip -d link` and `changelink` (rtnetlink). Process context,
    /// RTNL; takes the chip lock.
    fn state(_dev: &Dev<Self>, p: &Self::Priv) -> CanState {
        let st = p.chip.lock();
        if !st.running {
            return CanState::Stopped;
        }
        st.chip.can_state()
    }

    /// The chip's error counters for `ip -d link`. Process context,
    /// RTNL; takes the chip lock.
    fn berr_counter(_dev: &Dev<Self>, p: &Self::Priv) -> (u16, u16) {
        let mut st = p.chip.lock();
        let tx = st.chip.regs.read(crate::rcan_chips::sja1000::reg::TXERR);
        let rx = st.chip.regs.read(crate::rcan_chips::sja1000::reg::RXERR);
        (u16::from(tx), u16::from(rx))
    }

    /// Restarts the chip after bus-off (mainline `can_restart` and
    /// `sja1000_set_mode(CAN_MODE_START)`): the frame lost with the
    /// bus-off is dropped (a TX error), `CAN_ERR_RESTARTED` is queued for
    /// the NAPI poll, the carrier comes back, the restart is counted, the
    /// chip starts (with a filter change that waited, if any) and the
    /// queue wakes. Process context (`ip link ... restart`) or softirq
    /// (the `restart-ms` timer); takes the BH lock, then the chip lock.
    fn restart(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let _bh = p.bh.lock();
        let mut echo = {
            let mut st = p.chip.lock();
            if !st.running {
                return Err(EINVAL);
            }
            ctrl::rx_frame(dev, &mut st.rxq, &AnyFrame::Classic(restarted_frame()));
            st.echo.take()
        };
        ctrl::echo_lost(dev, &mut echo, Stat::TxErrors);
        // Outside the chip lock (the poll takes it); the poll runs when
        // `_bh` lets bottom halves run again.
        dev.napi_schedule();
        dev.set_carrier(true);
        p.can.count(CanStat::Restarts);
        let started = {
            let mut st = p.chip.lock();
            let f = st.filter;
            if core::mem::replace(&mut st.filter_pending, false) {
                // A filter change waited for the restart: the whole
                // initialisation, in reset mode, then start.
                st.chip.init(&f).and_then(|()| st.chip.start(&f))
            } else {
                st.chip.start(&f)
            }
        };
        if started.is_err() {
            dev.set_carrier(false);
            pr_err!(
                "{}: restart failed: SJA1000 does not leave reset mode\n",
                dev.name()
            );
            return Err(EIO);
        }
        dev.wake_queue();
        Ok(())
    }
}
