// SPDX-License-Identifier: GPL-2.0

//! The CTU CAN FD network driver: one `can%d` device per core, everything
//! but register access and probing, which the front-end supplies through
//! [`Regs`] (32-bit accesses in the core's window). The register
//! programming and frame (de)coding are the pure, host-tested
//! `rcan_core::ctucanfd` ([`Chip`]).
//!
//! Per device ([`CtuPriv`]):
//!
//! * `st`: the chip (with its TX buffer ring), the echo skb of each TX
//!   buffer and the running flag, behind an [`IrqSpinLock`]: the
//!   interrupt handler (hardirq), `start_xmit` (softirq/process, BH off)
//!   and `open`/`stop` (process, RTNL) all touch the core's registers
//!   and the ring, which must not interleave.
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
//! control modes `fd` and `fd-non-iso` (NISOFD). Not yet: the other
//! control modes mainline announces (loopback, listen-only, presume-ack,
//! one-shot, berr-reporting), error frames and the error states beyond
//! what FAULT_STATE reports (QEMU reads 0 there, so the state stays error
//! active), restart after bus-off. See
//! Documentation/networking/rcan/ctucanfd.rst.
#![forbid(unsafe_code)]

use crate::glue::bindings;
use crate::glue::can::dev::{link_setup, CanDev, CanDevice, LinkSetup};
use crate::glue::can::skb::alloc_rx;
use crate::glue::lock::{new_irq_spinlock, IrqSpinLock};
use crate::glue::netdev::{Dev, Driver, NetDev, Stat, Xmit};
use crate::glue::skb::Skb;
use crate::rcan_core::bittiming;
use crate::rcan_core::candev::{ctrlmode, CanState, Settings, CTUCANFD_CTRLMODE_SUPPORTED};
use crate::rcan_core::ctucanfd::{
    reg, Chip, Config, Event, Regs, CORE_SPAN, DATA_CONST, MAX_TXT_BUFFERS, NOMINAL_CONST,
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
    fn irq_sync(&mut self) {
        for c in 0..self.cores {
            let b = c * CORE_SPAN;
            if self.io.read32(b + reg::INT_STAT) & self.io.read32(b + reg::INT_ENA_SET) != 0 {
                self.io.write32(b + reg::INT_STAT, 0);
            }
        }
    }
}

/// Transmit queue length, as the SJA1000 driver's: longer than what a
/// socket's default send buffer holds, so a fast sender blocks in
/// sendmsg instead of getting ENOBUFS.
const TX_QUEUE_LEN: u32 = 1000;

/// One echo slot: the skb of the frame in a TX buffer, and its payload
/// length if it is an FD frame (the glue counts classic frames' bytes
/// itself when the echo completes).
struct EchoSlot {
    skb: Skb,
    fd_len: Option<u32>,
}

/// The chip and what goes with it, under the device's lock.
pub(crate) struct ChipState<R: Regs> {
    chip: Chip<R>,
    echo: [Option<EchoSlot>; MAX_TXT_BUFFERS],
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
}

/// One registered core.
pub(crate) struct Core<R: Regs + Send + 'static> {
    _reg: crate::glue::netdev::Registration<CtuCanFd<R>>,
}

/// Probes the core behind `regs` and, if one answers (DEVICE_ID 0xCAFD),
/// registers a `can%d` device for it on interrupt line `irq`; `None` if
/// there is none. Logs the device name with `what`. Process context
/// (front-end probe).
pub(crate) fn add_core<R: Regs + Send + 'static>(
    regs: R,
    irq: u32,
    clock_hz: u32,
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
                running: false,
            },
            "CtuPriv::st"
        )?,
        irq,
        clock_hz,
        can: CanDev::new(Settings::default())?,
    };
    let reg =
        crate::glue::netdev::Registration::<CtuCanFd<R>>::register(kernel::c_str!("can%d"), prv)?;
    pr_info!(
        "{}: CTU CAN FD, {}, irq {}, {} TX buffers\n",
        reg.dev().name(),
        what,
        irq,
        bufs
    );
    Ok(Some(Core { _reg: reg }))
}

/// The CTU CAN FD driver for register access `R`.
pub(crate) struct CtuCanFd<R>(PhantomData<R>);

/// Hands a frame to the network stack. Any context.
fn rx_frame(dev: &NetDev, frame: &AnyFrame) {
    let Some(skb) = alloc_rx(dev, frame) else {
        dev.stats_rx_dropped();
        return;
    };
    dev.stats_rx(frame.len() as u32);
    dev.rx(skb);
}

/// What [`Chip::start`] programs for the device layer's settings: BTR
/// from the bit timing, BTR_FD from the data bit timing (the nominal one
/// while none is set: classic CAN has no data phase), FDE with `fd on`,
/// NISOFD with `fd-non-iso on`.
fn config(s: &Settings) -> Config {
    let fd = s.ctrlmode & ctrlmode::FD != 0;
    Config {
        nominal: s.bittiming,
        data: if s.data_bittiming.bitrate != 0 {
            s.data_bittiming
        } else {
            s.bittiming
        },
        fd,
        fd_non_iso: fd && s.ctrlmode & ctrlmode::FD_NON_ISO != 0,
        ..Config::default()
    }
}

impl<R: Regs + Send + 'static> Driver for CtuCanFd<R> {
    type Priv = CtuPriv<R>;

    fn setup() -> crate::glue::netdev::Setup {
        crate::glue::netdev::Setup {
            type_: bindings::ARPHRD_CAN as u16,
            flags: bindings::net_device_flags_IFF_NOARP | bindings::net_device_flags_IFF_ECHO,
            // Classic until `fd on` (mainline's alloc_candev: CAN_MTU).
            mtu: CAN_MTU as u32,
            hard_header_len: 0,
            tx_queue_len: TX_QUEUE_LEN,
            no_queue: false,
        }
    }

    fn link() -> Option<LinkSetup> {
        Some(link_setup::<Self>())
    }

    const HAS_CHANGE_MTU: bool = true;

    /// `ip link set canX mtu 72|16`: FD on or off (mainline
    /// `can_change_mtu`). Process context, RTNL.
    fn change_mtu(dev: &Dev<Self>, p: &Self::Priv, new_mtu: u32) -> Result {
        p.can.change_mtu(dev, new_mtu)
    }

    /// Process context, RTNL: refuses a device without a bit timing,
    /// requests the (shared) interrupt, starts the core.
    fn open(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        let set = p.can.open_check(dev.name())?;
        dev.request_irq(p.irq)?;
        {
            let mut st = p.st.lock();
            st.chip.start(&config(&set));
            st.running = true;
        }
        dev.set_carrier(true);
        dev.start_queue();
        Ok(())
    }

    /// Process context, RTNL: stops the core and drops the frames still
    /// in its TX buffers.
    fn stop(dev: &Dev<Self>, p: &Self::Priv) -> Result {
        dev.stop_queue();
        let mut lost: [Option<EchoSlot>; MAX_TXT_BUFFERS] = Default::default();
        {
            let mut st = p.st.lock();
            st.running = false;
            st.chip.stop();
            core::mem::swap(&mut lost, &mut st.echo);
        }
        drop(lost);
        dev.free_irq();
        dev.set_carrier(false);
        Ok(())
    }

    /// Transmit path (softirq or process context, BH off).
    fn start_xmit(skb: Skb, dev: &Dev<Self>, p: &Self::Priv) -> Xmit {
        let Some((skb, frame)) = skb.can_xmit_start_any(dev) else {
            return Xmit::Ok;
        };
        let mut st = p.st.lock();
        match st.chip.xmit(&frame) {
            Ok((buf, full)) => {
                if full {
                    dev.stop_queue();
                }
                let fd_len = frame.is_fd().then_some(frame.len() as u32);
                st.echo[buf] = Some(EchoSlot { skb, fd_len });
            }
            Err(_) => {
                // Error frames cannot be sent; with the queue stopped
                // while the ring is full, a busy ring cannot happen.
                drop(st);
                dev.stats_tx_dropped();
                drop(skb);
            }
        }
        Xmit::Ok
    }

    /// Hardirq context; the line is shared with the card's other core.
    fn irq(dev: &Dev<Self>, p: &Self::Priv) -> bool {
        let mut st = p.st.lock();
        let ChipState {
            chip,
            echo,
            running,
        } = &mut *st;
        if !*running {
            return false;
        }
        let mut woke = false;
        let handled = chip.irq(|ev| match ev {
            Event::Rx(f) => rx_frame(dev, &f),
            Event::TxDone { buf, ok } => {
                if let Some(slot) = echo.get_mut(buf).and_then(|e| e.take()) {
                    if ok {
                        if let Some(n) = slot.fd_len {
                            dev.stats_tx(n);
                        }
                        if let Some(skb) = slot.skb.can_echo_done(dev) {
                            dev.rx(skb);
                        }
                    } else {
                        // Interrupts are off: the free is deferred.
                        slot.skb.drop_any();
                        dev.stats_err(Stat::TxErrors);
                    }
                }
                woke = true;
            }
            Event::Overrun => {
                dev.stats_err(Stat::RxOverErrors);
            }
            Event::State(_) => {}
        });
        if woke {
            dev.wake_queue();
        }
        handled
    }
}

/// The CTU CAN FD as the CAN device layer sees it: mainline
/// `ctucanfd`'s nominal and data bit-timing limits, CAN FD (ISO or not),
/// no restart.
impl<R: Regs + Send + 'static> CanDevice for CtuCanFd<R> {
    const BITTIMING_CONST: &'static bittiming::BittimingConst = &NOMINAL_CONST;
    const DATA_BITTIMING_CONST: Option<&'static bittiming::BittimingConst> = Some(&DATA_CONST);
    const CTRLMODE_SUPPORTED: u32 = CTUCANFD_CTRLMODE_SUPPORTED;
    const CAN_RESTART: bool = false;

    fn can_dev(p: &Self::Priv) -> &CanDev {
        &p.can
    }

    fn clock_hz(p: &Self::Priv) -> u32 {
        p.clock_hz
    }

    fn state(_dev: &Dev<Self>, p: &Self::Priv) -> CanState {
        let st = p.st.lock();
        if !st.running {
            return CanState::Stopped;
        }
        st.chip.state()
    }

    fn berr_counter(_dev: &Dev<Self>, p: &Self::Priv) -> (u16, u16) {
        p.st.lock().chip.berr_counter()
    }

    fn restart(_dev: &Dev<Self>, _p: &Self::Priv) -> Result {
        Err(crate::glue::neterr::EOPNOTSUPP())
    }
}
