// SPDX-License-Identifier: GPL-2.0

//! The Intel 82527 "Full CAN" controller: registers, message-object
//! layout and the chip-level logic of the thesis' abstract `i82527`
//! driver (5.3.10), over a register-access trait that each front-end
//! implements (5.3.11: `readb`/`writeb`/`memcpy_fromio`/`memcpy_toio`).
//!
//! Message-object allocation (thesis 5.3.10):
//!
//! * object 15 (double buffered) receives extended data frames;
//! * object [`STD_RX`] (1) receives standard data frames;
//! * objects [`ANSWER_FIRST`]..=[`ANSWER_LAST`] (2..13, twelve) answer
//!   remote frames automatically with a data frame user space published;
//! * object [`TX_OBJ`] (14) is the only transmit object: the global masks
//!   also apply to transmit objects, and a transmit object whose
//!   identifier matches an incoming remote frame under the mask re-sends,
//!   so there is exactly one, and it is invalidated (MsgVal reset) as soon
//!   as its transmission completed.
//!
//! Everything here is pure: the kernel driver (`drivers/net/can/i82527/`)
//! supplies a [`Regs`] and turns the [`Event`]s of [`Chip::irq`] into skbs
//! and statistics; host tests and the simulated card supply the
//! register-level model in `i82527_model.rs`.

use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK, MAX_DLC};
use super::bittiming::{self, Bittiming};
use super::filter::{Cube, Wanted};
use super::frame::CanFrame;

/// Register offsets.
pub mod reg {
    /// Control register.
    pub const CONTROL: u8 = 0x00;
    /// Status register.
    pub const STATUS: u8 = 0x01;
    /// CPU interface register.
    pub const CPU_IF: u8 = 0x02;
    /// Global mask, standard (two bytes).
    pub const GMS: u8 = 0x06;
    /// Global mask, extended (four bytes).
    pub const GME: u8 = 0x08;
    /// Message 15 mask (four bytes).
    pub const M15: u8 = 0x0C;
    /// Clock out register.
    pub const CLKOUT: u8 = 0x1F;
    /// Bus configuration register.
    pub const BUS_CFG: u8 = 0x2F;
    /// Bit timing register 0.
    pub const BT0: u8 = 0x3F;
    /// Bit timing register 1.
    pub const BT1: u8 = 0x4F;
    /// Interrupt register (read only).
    pub const INT: u8 = 0x5F;

    /// Base of message object `n` (1..=15).
    pub const fn obj(n: u8) -> u8 {
        n * 0x10
    }
    /// Offset of control register 0 in an object.
    pub const CTRL0: u8 = 0;
    /// Offset of control register 1.
    pub const CTRL1: u8 = 1;
    /// Offset of the arbitration registers (four bytes).
    pub const ARB: u8 = 2;
    /// Offset of the message configuration register.
    pub const CFG: u8 = 6;
    /// Offset of the data bytes (eight).
    pub const DATA: u8 = 7;
}

/// Control register bits.
pub mod ctrl {
    /// Initialisation: the chip is off the bus.
    pub const INIT: u8 = 0x01;
    /// Interrupt enable (the interrupt line).
    pub const IE: u8 = 0x02;
    /// Status change interrupt enable (TXOK/RXOK/LEC).
    pub const SIE: u8 = 0x04;
    /// Error interrupt enable (WARN/BOFF changes).
    pub const EIE: u8 = 0x08;
    /// Change configuration enable (bit timing writable while INIT).
    pub const CCE: u8 = 0x40;
}

/// Status register bits.
pub mod status {
    /// Last error code (bits 2..0).
    pub const LEC: u8 = 0x07;
    /// A frame was transmitted successfully.
    pub const TXOK: u8 = 0x08;
    /// A frame was received successfully.
    pub const RXOK: u8 = 0x10;
    /// Wake up.
    pub const WAKE: u8 = 0x20;
    /// An error counter reached the warning limit (96).
    pub const WARN: u8 = 0x40;
    /// Bus-off.
    pub const BOFF: u8 = 0x80;
}

/// CPU interface register bits.
pub mod cpu_if {
    /// Hardware reset in progress (read only).
    pub const RSTST: u8 = 0x80;
    /// Divide the system clock by two.
    pub const DSC: u8 = 0x40;
    /// Divide the memory clock by two.
    pub const DMC: u8 = 0x20;
    /// Clock out enable (clears: no clock out).
    pub const CEN: u8 = 0x01;
}

/// Two-bit control fields of message objects: read `10` = set, `01` =
/// reset; write `10` sets, `01` resets, `11` leaves the field unchanged.
/// This lets the CPU change one field without a read-modify-write race
/// against the chip.
pub mod bits {
    /// Field value: set.
    pub const SET: u8 = 0b10;
    /// Field value: reset.
    pub const RES: u8 = 0b01;
    /// Field value on write: unchanged.
    pub const KEEP: u8 = 0b11;

    /// Control 0 / 1: field shifts.
    /// Control 0: MsgVal (bits 7..6).
    pub const MSGVAL: u8 = 6;
    /// Control 0: TXIE (bits 5..4).
    pub const TXIE: u8 = 4;
    /// Control 0: RXIE (bits 3..2).
    pub const RXIE: u8 = 2;
    /// Control 0: IntPnd (bits 1..0).
    pub const INTPND: u8 = 0;
    /// Control 1: RmtPnd (bits 7..6).
    pub const RMTPND: u8 = 6;
    /// Control 1: TxRqst (bits 5..4).
    pub const TXRQST: u8 = 4;
    /// Control 1: MsgLst on receive objects, CPUUpd on transmit objects
    /// (bits 3..2).
    pub const MSGLST: u8 = 2;
    /// Control 1: CPUUpd, the same field as MsgLst.
    pub const CPUUPD: u8 = 2;
    /// Control 1: NewDat (bits 1..0).
    pub const NEWDAT: u8 = 0;

    /// A control byte that changes only the field at `shift` to `v`.
    pub const fn only(shift: u8, v: u8) -> u8 {
        !(0b11 << shift) | (v << shift)
    }

    /// A control byte from four fields, high to low.
    pub const fn byte(f3: u8, f2: u8, f1: u8, f0: u8) -> u8 {
        (f3 << 6) | (f2 << 4) | (f1 << 2) | f0
    }

    /// Whether the field at `shift` reads as set.
    pub const fn is_set(b: u8, shift: u8) -> bool {
        (b >> shift) & 0b11 == SET
    }
}

/// Message configuration register bits.
pub mod mcfg {
    /// Direction: transmit (answers remote frames) when set.
    pub const DIR: u8 = 0x08;
    /// Extended identifier.
    pub const XTD: u8 = 0x04;
    /// DLC shift (bits 7..4).
    pub const DLC_SHIFT: u8 = 4;
}

/// Interrupt register values: none, status change, object 15, objects
/// 1..14 as `n + 2`.
pub mod intid {
    /// Nothing pending.
    pub const NONE: u8 = 0;
    /// Status change (highest priority).
    pub const STATUS: u8 = 1;
    /// Message object 15.
    pub const OBJ15: u8 = 2;

    /// The message object an interrupt register value names.
    pub const fn object(v: u8) -> Option<u8> {
        match v {
            OBJ15 => Some(15),
            3..=16 => Some(v - 2),
            _ => None,
        }
    }
}

/// Object receiving standard data frames.
pub const STD_RX: u8 = 1;
/// First remote-answer object.
pub const ANSWER_FIRST: u8 = 2;
/// Last remote-answer object.
pub const ANSWER_LAST: u8 = 13;
/// Number of remote-answer objects.
pub const ANSWERS: usize = (ANSWER_LAST - ANSWER_FIRST + 1) as usize;
/// The one transmit object.
pub const TX_OBJ: u8 = 14;
/// Object receiving extended data frames (double buffered).
pub const EXT_RX: u8 = 15;

/// Register access of one chip: what a front-end provides. Implementations
/// run in any context the driver calls them from and must not sleep.
pub trait Regs {
    /// Reads register `reg`.
    fn read(&mut self, reg: u8) -> u8;
    /// Writes `val` to register `reg`.
    fn write(&mut self, reg: u8, val: u8);
    /// Reads `buf.len()` consecutive registers from `reg`
    /// (`memcpy_fromio`).
    fn readn(&mut self, reg: u8, buf: &mut [u8]) {
        for (i, b) in buf.iter_mut().enumerate() {
            *b = self.read(reg + i as u8);
        }
    }
    /// Writes `buf` to consecutive registers from `reg` (`memcpy_toio`).
    fn writen(&mut self, reg: u8, buf: &[u8]) {
        for (i, b) in buf.iter().enumerate() {
            self.write(reg + i as u8, *b);
        }
    }
}

/// Arbitration register image of an identifier: standard identifiers
/// in bits 31..21 (ID28..18), extended ones in bits 31..3.
pub fn arb_bytes(id: u32, ext: bool) -> [u8; 4] {
    if ext {
        ((id & CAN_EFF_MASK) << 3).to_be_bytes()
    } else {
        ((id & CAN_SFF_MASK) << 21).to_be_bytes()
    }
}

/// The identifier in an arbitration register image.
pub fn arb_id(b: [u8; 4], ext: bool) -> u32 {
    let v = u32::from_be_bytes(b);
    if ext {
        v >> 3
    } else {
        v >> 21
    }
}

/// Message configuration byte of a data (`dir` set: transmit object) or
/// remote frame.
pub fn cfg_byte(frame: &CanFrame, dir: bool) -> u8 {
    let mut c = (frame.dlc() as u8) << mcfg::DLC_SHIFT;
    if frame.can_id & CAN_EFF_FLAG != 0 {
        c |= mcfg::XTD;
    }
    if dir {
        c |= mcfg::DIR;
    }
    c
}

/// A data frame from an object's arbitration, configuration and data
/// registers. A DLC above 8 gives 8 data bytes.
pub fn decode(arb: [u8; 4], cfg: u8, data: &[u8; 8]) -> CanFrame {
    let ext = cfg & mcfg::XTD != 0;
    let dlc = usize::from(cfg >> mcfg::DLC_SHIFT).min(MAX_DLC);
    let mut f = CanFrame {
        can_id: arb_id(arb, ext) | if ext { CAN_EFF_FLAG } else { 0 },
        len: dlc as u8,
        ..CanFrame::default()
    };
    f.data[..dlc].copy_from_slice(&data[..dlc]);
    f
}

/// Controller state as far as the 82527 tells it: it has no readable
/// error counters, only the WARN and BOFF status bits.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum State {
    /// Neither WARN nor BOFF.
    Active,
    /// WARN: an error counter reached 96.
    Warning,
    /// BOFF: the chip left the bus (and set INIT).
    BusOff,
}

/// What an interrupt brought.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Event {
    /// A data frame was received.
    Rx(CanFrame),
    /// The transmit object's frame was sent.
    TxDone,
    /// The transmit object's frame was dropped unsent (bus-off).
    TxAborted,
    /// A receive object was overwritten before the host read it (MsgLst):
    /// frames were lost.
    Overrun {
        /// The object (1 or 15).
        obj: u8,
    },
    /// The error state changed.
    State(State),
    /// A bus error (status change interrupt, only with
    /// [`Chip::berr_reporting`]): the status register's last error code
    /// (1..6; datasheet: stuff, form, ACK, bit 1, bit 0, CRC).
    BusError {
        /// LEC, status register bits 2..0.
        lec: u8,
    },
    /// The chip is back on the bus after bus-off (the recovery the driver
    /// started when it saw BOFF completed).
    Restarted,
}

/// The control modes the 82527 driver implements (`ip link set canX
/// type can ...`): triple sampling (BT1's SPL bit, as mainline's
/// `cc770`) and berr-reporting (the status change interrupt, whose last
/// error code the driver turns into bus-error frames). The chip has no
/// loopback, listen-only, single-shot or presume-ack mode.
pub const CTRLMODE_SUPPORTED: u32 =
    super::candev::ctrlmode::THREE_SAMPLES | super::candev::ctrlmode::BERR_REPORTING;

/// Static configuration of one chip (module parameters and board).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Config {
    /// CPU interface register: DSC/DMC/CEN (board clocking).
    pub cpu_if: u8,
    /// Clock out register (divider and slew rate).
    pub clkout: u8,
    /// Bus configuration register (comparator bypass, polarities).
    pub bus_cfg: u8,
    /// Bit timing register 0 (SJW, BRP).
    pub bt0: u8,
    /// Bit timing register 1 (SPL, TSEG2, TSEG1).
    pub bt1: u8,
}

impl Config {
    /// 500 kbit/s from a 16 MHz crystal with DSC set (8 MHz system
    /// clock): BRP 0, TSEG1 11, TSEG2 2 (16 quanta, sample point 81 %),
    /// SJW 1, comparator bypass, clock out off.
    pub const DEFAULT: Config = Config {
        cpu_if: cpu_if::DSC,
        clkout: 0x00,
        bus_cfg: 0x40,
        bt0: 0x00,
        bt1: 0x2B,
    };
}

/// Bit rate of bit timing `bt0`/`bt1` with crystal `xtal_hz` and CPU
/// interface register `cpu_if` (datasheet: system clock = XTAL / (DSC +
/// 1); tq = (BRP + 1) / system clock; bit = (3 + TSEG1 + TSEG2) tq): the
/// registers decoded by [`bittiming::from_btr`] (the 82527's layout is
/// the SJA1000's) with the system clock as the bit-timing clock.
pub fn bitrate(bt0: u8, bt1: u8, cpu_if: u8, xtal_hz: u32) -> u32 {
    bittiming::from_btr(bt0, bt1, sys_clock(cpu_if, xtal_hz))
        .0
        .bitrate
}

/// Length of one bit in ns of bit timing `bt0`/`bt1` with crystal
/// `xtal_hz` and CPU interface register `cpu_if` (BRP + 1 system clock
/// periods per tq, 3 + TSEG1 + TSEG2 tq per bit), rounded down; 0 with a
/// zero crystal. The simulated bus gives a frame its bus time with it.
pub fn bit_ns(bt0: u8, bt1: u8, cpu_if: u8, xtal_hz: u32) -> u32 {
    let sys = sys_clock(cpu_if, xtal_hz);
    if sys == 0 {
        return 0;
    }
    let (bt, _) = bittiming::from_btr(bt0, bt1, sys);
    let clocks = u64::from(bt.brp) * u64::from(bt.bit_time());
    (clocks * 1_000_000_000 / u64::from(sys)) as u32
}

/// The system clock, which the bit timing counts: the crystal, halved
/// when the CPU interface register's DSC bit is set.
pub fn sys_clock(cpu_if: u8, xtal_hz: u32) -> u32 {
    if cpu_if & self::cpu_if::DSC != 0 {
        xtal_hz / 2
    } else {
        xtal_hz
    }
}

/// Bit timing for `bitrate` with system clock `sys_hz`: the exact setting
/// with the most quanta per bit (8..=25) and a sample point nearest 87.5
/// %, SJW 1, one sample, within [`bittiming::I82527_BITTIMING_CONST`]
/// (programmed TSEG1 2..15, TSEG2 1..7), encoded by
/// [`bittiming::to_btr`]. `None` if no setting gives the rate exactly.
pub fn timing_for(bitrate: u32, sys_hz: u32) -> Option<(u8, u8)> {
    let c = &bittiming::I82527_BITTIMING_CONST;
    if bitrate == 0 {
        return None;
    }
    for tq in (8u32..=25).rev() {
        let div = tq * bitrate;
        if !sys_hz.is_multiple_of(div) {
            continue;
        }
        let brp = sys_hz / div;
        if brp < c.brp_min || brp > c.brp_max {
            continue;
        }
        let mut best: Option<(u32, Bittiming)> = None;
        // bit = 1 (sync) + TSEG1 + TSEG2 quanta.
        for tseg2 in c.tseg2_min..=c.tseg2_max {
            let Some(tseg1) = (tq - 1).checked_sub(tseg2) else {
                continue;
            };
            if !(c.tseg1_min..=c.tseg1_max).contains(&tseg1) {
                continue;
            }
            let sp = (1 + tseg1) * 1000 / tq;
            let err = sp.abs_diff(875);
            if best.is_none_or(|(e, _)| err < e) {
                let bt = Bittiming {
                    brp,
                    sjw: 1,
                    prop_seg: tseg1 / 2,
                    phase_seg1: tseg1 - tseg1 / 2,
                    phase_seg2: tseg2,
                    ..Bittiming::default()
                };
                best = Some((err, bt));
            }
        }
        if let Some((_, bt)) = best {
            return Some(bittiming::to_btr(&bt, false));
        }
    }
    None
}

/// Clock-out frequency of clock out register `clkout` (CD3..0: divider
/// CD + 1) with CPU interface register `cpu_if` (CEN clear: no clock).
pub fn clkout_hz(clkout: u8, cpu_if: u8, xtal_hz: u32) -> u32 {
    if cpu_if & self::cpu_if::CEN == 0 {
        return 0;
    }
    xtal_hz / (u32::from(clkout & 0x0F) + 1)
}

/// The global masks and the receive objects' arbitration the driver
/// programs: a mask bit of 1 means the bit must match the object's
/// arbitration ("must match"), 0 "don't care" (datasheet polarity).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Masks {
    /// Global standard mask over ID10..0.
    pub gms: u32,
    /// Global extended mask over ID28..0.
    pub gme: u32,
    /// Message 15 mask over ID28..0 (ANDed with `gme` for object 15).
    pub m15: u32,
    /// Object [`STD_RX`]'s identifier, `None`: invalid (no standard data
    /// frame wanted).
    pub std_rx: Option<u32>,
    /// Object 15's identifier, `None`: invalid.
    pub ext_rx: Option<u32>,
}

impl Masks {
    /// Everything received (promiscuous).
    pub const OPEN: Masks = Masks {
        gms: 0,
        gme: CAN_EFF_MASK,
        m15: 0,
        std_rx: Some(0),
        ext_rx: Some(0),
    };

    /// Whether a chip programmed with these masks stores data frame
    /// `frame` in a receive object (object 1 or 15). Remote frames are
    /// never stored by receive objects (they only make transmit objects
    /// answer).
    pub fn receives(&self, frame: &CanFrame) -> bool {
        if frame.can_id & (CAN_RTR_FLAG | CAN_ERR_FLAG) != 0 {
            return false;
        }
        if frame.can_id & CAN_EFF_FLAG != 0 {
            let id = frame.can_id & CAN_EFF_MASK;
            self.ext_rx
                .is_some_and(|a| (a ^ id) & self.gme & self.m15 & CAN_EFF_MASK == 0)
        } else {
            let id = frame.can_id & CAN_SFF_MASK;
            self.std_rx
                .is_some_and(|a| (a ^ id) & self.gms & CAN_SFF_MASK == 0)
        }
    }

    /// Whether the standard remote-answer objects are exact (the global
    /// standard mask compares every identifier bit). When not, a standard
    /// answer object also answers remote frames for the identifiers equal
    /// to its own under the mask (with its own identifier): the price of
    /// receiving a range of standard frames through one object.
    pub fn std_answers_exact(&self) -> bool {
        self.gms & CAN_SFF_MASK == CAN_SFF_MASK
    }
}

/// The masks that make the chip receive every data frame some filter in
/// `wanted` wants, and as few others as a cube per format allows (thesis
/// 5.3.4, 5.3.10): object 1 and the global standard mask hold the smallest
/// cube over the wanted standard identifiers; the global extended mask
/// stays exact (it also governs the extended answer objects and the
/// transmit object), and the message-15 mask, ANDed with it, holds the
/// smallest cube over the wanted extended identifiers. A format nobody
/// wants gets its receive object invalidated. `promisc` opens both.
///
/// Remote frames a filter wants cannot be received: on an 82527 only
/// transmit-direction objects react to remote frames (by answering them).
pub fn masks_for(wanted: &[Wanted], promisc: bool) -> Masks {
    if promisc {
        return Masks::OPEN;
    }
    let mut sff: Option<Cube> = None;
    let mut eff: Option<Cube> = None;
    // Cubes carry the RTR bit in bit 0: drop it (the masks cover only the
    // identifier).
    let id_only = |c: Cube| (c.value >> 1, c.care >> 1);
    for w in wanted {
        if let Some(c) = w.sff {
            sff = Some(sff.map_or(c, |x| x.merge(c)));
        }
        if let Some(c) = w.eff {
            eff = Some(eff.map_or(c, |x| x.merge(c)));
        }
    }
    let (std_rx, gms) = match sff.map(id_only) {
        Some((v, care)) => (Some(v & CAN_SFF_MASK), care & CAN_SFF_MASK),
        // Nothing standard wanted: the mask stays exact so that standard
        // answer objects are exact.
        None => (None, CAN_SFF_MASK),
    };
    let (ext_rx, m15) = match eff.map(id_only) {
        Some((v, care)) => (Some(v & CAN_EFF_MASK), care & CAN_EFF_MASK),
        None => (None, CAN_EFF_MASK),
    };
    Masks {
        gms,
        gme: CAN_EFF_MASK,
        m15,
        std_rx,
        ext_rx,
    }
}

/// Why an operation failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum I82527Error {
    /// No chip answers at this address (probe).
    NoChip,
    /// The transmit object is still sending.
    Busy,
    /// The frame cannot be sent or published (error frame, or a remote
    /// frame as an answer).
    BadFrame,
    /// No such remote-answer slot.
    BadSlot,
}

/// Reads of the CPU interface register while waiting for the end of a
/// hardware reset.
const RESET_POLLS: usize = 100;

/// The driver's view of one 82527: its registers, configuration and the
/// few things the chip does not tell (whether the transmit object is in
/// use, the error state last reported).
pub struct Chip<R: Regs> {
    /// Register access.
    pub regs: R,
    /// Configuration applied by [`Chip::init`].
    pub cfg: Config,
    /// The masks last programmed.
    pub masks: Masks,
    state: State,
    tx_busy: bool,
    /// Restarts after bus-off ([`Chip::restart`]).
    pub restarts: u32,
    /// Bus errors reported (`berr-reporting on`): the status change
    /// interrupt (SIE) is enabled at [`Chip::start`] and every last error
    /// code becomes an [`Event::BusError`]. Off by default: with SIE the
    /// chip interrupts for every frame on the bus (TXOK/RXOK).
    pub berr_reporting: bool,
    answers: [Option<CanFrame>; ANSWERS],
}

/// Writes control register `c` (0 or 1) of object `n`.
fn ctl<R: Regs>(regs: &mut R, n: u8, c: u8, v: u8) {
    regs.write(reg::obj(n) + c, v);
}

impl<R: Regs> Chip<R> {
    /// A chip behind `regs`; nothing is written yet.
    pub fn new(regs: R, cfg: Config) -> Self {
        Chip {
            regs,
            cfg,
            masks: masks_for(&[], false),
            state: State::Active,
            tx_busy: false,
            restarts: 0,
            berr_reporting: false,
            answers: [None; ANSWERS],
        }
    }

    /// The last error state reported.
    pub fn state(&self) -> State {
        self.state
    }

    /// Whether the transmit object holds a frame not yet sent.
    pub fn tx_busy(&self) -> bool {
        self.tx_busy
    }

    /// The published answer of slot `slot`.
    pub fn answer(&self, slot: usize) -> Option<CanFrame> {
        self.answers.get(slot).copied().flatten()
    }

    /// Probes for a chip: a floating bus reads 0xFF everywhere; a chip
    /// leaves hardware reset (RSTST clear), keeps INIT in its control
    /// register after it is set, and merges writes to a message object's
    /// two-bit control fields (memory would store them). Leaves the chip
    /// in INIT.
    pub fn probe(&mut self) -> Result<(), I82527Error> {
        let mut out_of_reset = false;
        for _ in 0..RESET_POLLS {
            let v = self.regs.read(reg::CPU_IF);
            if v == 0xFF {
                return Err(I82527Error::NoChip);
            }
            if v & cpu_if::RSTST == 0 {
                out_of_reset = true;
                break;
            }
        }
        if !out_of_reset {
            return Err(I82527Error::NoChip);
        }
        self.regs.write(reg::CONTROL, ctrl::INIT | ctrl::CCE);
        let c = self.regs.read(reg::CONTROL);
        if c & (ctrl::INIT | ctrl::CCE) != ctrl::INIT | ctrl::CCE || c == 0xFF {
            return Err(I82527Error::NoChip);
        }
        // Plain memory (an ISA hole backed by RAM) would pass the above.
        // The two-bit control fields do not store what is written: after
        // "all reset", "set MsgVal, keep the rest" reads back as MsgVal set
        // and the rest reset.
        let (s, r, k) = (bits::SET, bits::RES, bits::KEEP);
        ctl(&mut self.regs, STD_RX, reg::CTRL0, bits::byte(r, r, r, r));
        ctl(&mut self.regs, STD_RX, reg::CTRL0, bits::byte(s, k, k, k));
        let v = self.regs.read(reg::obj(STD_RX) + reg::CTRL0);
        self.invalidate(STD_RX);
        if v != bits::byte(s, r, r, r) {
            return Err(I82527Error::NoChip);
        }
        Ok(())
    }

    /// Full initialisation, left in INIT (off the bus, interrupts off):
    /// clocking, bus configuration, bit timing, every object invalid, the
    /// masks and receive objects from `masks`, the published answers
    /// re-written.
    pub fn init(&mut self, masks: &Masks) {
        self.regs.write(reg::CONTROL, ctrl::INIT | ctrl::CCE);
        self.regs.write(reg::CPU_IF, self.cfg.cpu_if);
        self.regs.write(reg::CLKOUT, self.cfg.clkout);
        self.regs.write(reg::BUS_CFG, self.cfg.bus_cfg);
        self.regs.write(reg::BT0, self.cfg.bt0);
        self.regs.write(reg::BT1, self.cfg.bt1);
        for n in 1..=15 {
            self.invalidate(n);
        }
        self.regs.write(reg::STATUS, 0);
        self.write_masks(masks);
        for slot in 0..ANSWERS {
            if let Some(f) = self.answers[slot] {
                self.write_answer(slot, &f);
            }
        }
        self.tx_busy = false;
        self.regs.write(reg::CONTROL, ctrl::INIT);
    }

    /// Resets every field of object `n`'s control registers.
    fn invalidate(&mut self, n: u8) {
        let r = bits::RES;
        ctl(&mut self.regs, n, reg::CTRL0, bits::byte(r, r, r, r));
        ctl(&mut self.regs, n, reg::CTRL1, bits::byte(r, r, r, r));
    }

    /// Programs the global masks and the two receive objects. Objects
    /// are invalidated while their arbitration changes.
    fn write_masks(&mut self, m: &Masks) {
        self.masks = *m;
        let gms = ((m.gms & CAN_SFF_MASK) << 5) as u16 | 0x1F;
        self.regs.writen(reg::GMS, &gms.to_be_bytes());
        self.regs
            .writen(reg::GME, &(((m.gme & CAN_EFF_MASK) << 3) | 7).to_be_bytes());
        self.regs
            .writen(reg::M15, &(((m.m15 & CAN_EFF_MASK) << 3) | 7).to_be_bytes());
        for (n, id, ext) in [(STD_RX, m.std_rx, false), (EXT_RX, m.ext_rx, true)] {
            let (s, r, k) = (bits::SET, bits::RES, bits::KEEP);
            ctl(&mut self.regs, n, reg::CTRL0, bits::byte(r, k, k, k));
            let Some(id) = id else { continue };
            self.regs
                .writen(reg::obj(n) + reg::ARB, &arb_bytes(id, ext));
            let c = if ext { mcfg::XTD } else { 0 };
            self.regs.write(reg::obj(n) + reg::CFG, c);
            ctl(&mut self.regs, n, reg::CTRL1, bits::byte(r, r, r, r));
            ctl(&mut self.regs, n, reg::CTRL0, bits::byte(s, r, s, r));
        }
    }

    /// Reprograms the masks of a running chip (the bound filters
    /// changed). The receive objects are briefly invalid: a frame arriving
    /// in between is not stored, as on any 82527 mask change.
    pub fn set_masks(&mut self, masks: &Masks) {
        // The receive objects are invalid while their masks and
        // arbitration change (write_masks); the chip stays on the bus so
        // the transmit and answer objects keep working.
        self.write_masks(masks);
    }

    /// Goes on the bus (thesis: `open`): clears pending status, enables
    /// the interrupt line and error interrupts (SIE only with
    /// [`Chip::berr_reporting`]: one interrupt per frame on the bus would
    /// otherwise wake the host for frames nobody wants) and clears INIT.
    pub fn start(&mut self) {
        self.regs.write(reg::STATUS, 0);
        let _ = self.regs.read(reg::STATUS);
        self.state = State::Active;
        let sie = if self.berr_reporting { ctrl::SIE } else { 0 };
        self.regs.write(reg::CONTROL, ctrl::IE | ctrl::EIE | sie);
    }

    /// Restarts a chip after bus-off (mainline `cc770`'s
    /// `CAN_MODE_START`): full initialisation with `masks`, then
    /// [`Chip::start`]. Clearing INIT starts the datasheet's recovery: the
    /// chip waits for 128 occurrences of 11 recessive bits before it
    /// sends or receives again; the error state is active from here on
    /// (BOFF clearing later raises no second event).
    pub fn restart(&mut self, masks: &Masks) {
        self.init(masks);
        self.start();
        self.restarts += 1;
    }

    /// Turns the chip's interrupt output off (`on` false) or back on,
    /// leaving everything else in the control register as it is (INIT
    /// above all: the chip sets it by itself at bus-off). While it is off
    /// the chip goes on receiving and sending and keeps its causes
    /// pending (IntPnd, the status interrupt); turning it on raises the
    /// output again if one is. A driver turns it off while it has no room
    /// for more frames and reads the objects again once it has (mainline
    /// `c_can`'s `c_can_irq_control` around its NAPI poll); an object it
    /// leaves unread meanwhile is overrun (MsgLst) by the next frame for
    /// it, which the next read reports as [`Event::Overrun`].
    pub fn set_irq_enabled(&mut self, on: bool) {
        let c = self.regs.read(reg::CONTROL);
        let c = if on { c | ctrl::IE } else { c & !ctrl::IE };
        self.regs.write(reg::CONTROL, c);
    }

    /// Leaves the bus (thesis: `stop`): INIT, interrupts off, the
    /// transmit object invalid.
    pub fn stop(&mut self) {
        self.regs.write(reg::CONTROL, ctrl::INIT);
        self.invalidate(TX_OBJ);
        self.tx_busy = false;
    }

    /// Loads `frame` into the transmit object and requests transmission.
    /// A remote frame is sent by a receive-direction object with TxRqst
    /// (datasheet: Dir = 0 + TxRqst sends a remote frame). The caller keeps
    /// its queue stopped until [`Event::TxDone`].
    pub fn xmit(&mut self, frame: &CanFrame) -> Result<(), I82527Error> {
        if frame.can_id & CAN_ERR_FLAG != 0 {
            return Err(I82527Error::BadFrame);
        }
        if self.tx_busy {
            return Err(I82527Error::Busy);
        }
        let rtr = frame.can_id & CAN_RTR_FLAG != 0;
        let ext = frame.can_id & CAN_EFF_FLAG != 0;
        let (s, r, k) = (bits::SET, bits::RES, bits::KEEP);
        let base = reg::obj(TX_OBJ);
        // MsgVal reset while arbitration and configuration change; TXIE
        // for the completion interrupt. A remote request leaves the object
        // in receive direction, where it takes the answer if no lower
        // object (object 1) does, and before object 15 would: RXIE, so
        // the answer is read from it (tx_object).
        let rxie = if rtr { s } else { r };
        ctl(
            &mut self.regs,
            TX_OBJ,
            reg::CTRL0,
            bits::byte(r, s, rxie, r),
        );
        ctl(&mut self.regs, TX_OBJ, reg::CTRL1, bits::byte(r, r, s, r));
        self.regs
            .writen(base + reg::ARB, &arb_bytes(frame.can_id, ext));
        self.regs.write(base + reg::CFG, cfg_byte(frame, !rtr));
        if !rtr {
            self.regs
                .writen(base + reg::DATA, &frame.data[..frame.dlc()]);
        }
        let newdat = if rtr { r } else { s };
        ctl(
            &mut self.regs,
            TX_OBJ,
            reg::CTRL1,
            bits::byte(k, k, r, newdat),
        );
        ctl(&mut self.regs, TX_OBJ, reg::CTRL0, bits::byte(s, k, k, k));
        ctl(&mut self.regs, TX_OBJ, reg::CTRL1, bits::byte(k, s, k, k));
        self.tx_busy = true;
        Ok(())
    }

    /// Publishes (`Some`) or withdraws (`None`) the data frame
    /// remote-answer object `ANSWER_FIRST + slot` answers remote requests
    /// for its identifier with. The chip answers by itself; the host is
    /// not interrupted (TXIE and RXIE stay off).
    pub fn set_answer(&mut self, slot: usize, frame: Option<&CanFrame>) -> Result<(), I82527Error> {
        if slot >= ANSWERS {
            return Err(I82527Error::BadSlot);
        }
        if let Some(f) = frame {
            if f.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG) != 0 {
                return Err(I82527Error::BadFrame);
            }
        }
        self.answers[slot] = frame.copied();
        match frame {
            Some(f) => self.write_answer(slot, f),
            None => self.invalidate(ANSWER_FIRST + slot as u8),
        }
        Ok(())
    }

    /// Writes an answer object. Republishing an identifier keeps the object
    /// valid and only marks it CPUUpd while the data change, so a remote
    /// frame arriving meanwhile is answered afterwards, never with half
    /// old, half new data.
    fn write_answer(&mut self, slot: usize, f: &CanFrame) {
        let n = ANSWER_FIRST + slot as u8;
        let base = reg::obj(n);
        let ext = f.can_id & CAN_EFF_FLAG != 0;
        let (s, r, k) = (bits::SET, bits::RES, bits::KEEP);
        let mut arb = [0u8; 4];
        self.regs.readn(base + reg::ARB, &mut arb);
        let cur_cfg = self.regs.read(base + reg::CFG);
        let c0 = self.regs.read(base + reg::CTRL0);
        let same = bits::is_set(c0, bits::MSGVAL)
            && arb == arb_bytes(f.can_id, ext)
            && cur_cfg & (mcfg::XTD | mcfg::DIR) == cfg_byte(f, true) & (mcfg::XTD | mcfg::DIR);
        if !same {
            ctl(&mut self.regs, n, reg::CTRL0, bits::byte(r, r, r, r));
            ctl(&mut self.regs, n, reg::CTRL1, bits::byte(r, r, r, r));
            self.regs.writen(base + reg::ARB, &arb_bytes(f.can_id, ext));
        }
        ctl(&mut self.regs, n, reg::CTRL1, bits::byte(k, k, s, k));
        self.regs.write(base + reg::CFG, cfg_byte(f, true));
        self.regs.writen(base + reg::DATA, &f.data[..f.dlc()]);
        ctl(&mut self.regs, n, reg::CTRL1, bits::byte(k, k, r, s));
        ctl(&mut self.regs, n, reg::CTRL0, bits::byte(s, k, k, k));
    }

    /// Handles one interrupt: reads the interrupt register until it reads
    /// 0 (at most `max_rounds` times) and serves the cause it names, in
    /// the chip's priority order (status, object 15, objects 1..14).
    /// Returns whether the chip had raised anything (shared lines).
    pub fn irq(&mut self, max_rounds: usize, mut ev: impl FnMut(Event)) -> bool {
        let mut handled = false;
        for _ in 0..max_rounds {
            let v = self.regs.read(reg::INT);
            if v == intid::NONE || v == 0xFF {
                break;
            }
            handled = true;
            if v == intid::STATUS {
                self.status_change(&mut ev);
                continue;
            }
            let Some(n) = intid::object(v) else {
                // Not a value the chip produces: stop rather than loop.
                break;
            };
            match n {
                STD_RX | EXT_RX => self.rx_object(n, &mut ev),
                TX_OBJ => self.tx_object(&mut ev),
                _ => {
                    // An answer object does not enable interrupts; clear
                    // whatever is pending so the line drops.
                    let k = bits::KEEP;
                    ctl(
                        &mut self.regs,
                        n,
                        reg::CTRL0,
                        bits::byte(k, k, k, bits::RES),
                    );
                }
            }
        }
        handled
    }

    /// Reads a receive object: NewDat is reset before the data are read
    /// and checked again after, so a frame stored meanwhile is read whole
    /// (the datasheet's procedure); MsgLst reports an overwritten frame.
    fn rx_object(&mut self, n: u8, ev: &mut impl FnMut(Event)) {
        let (r, k) = (bits::RES, bits::KEEP);
        let base = reg::obj(n);
        // Clearing IntPnd first lets object 15 move its shadow buffer in
        // only after NewDat is reset too (below).
        ctl(&mut self.regs, n, reg::CTRL0, bits::byte(k, k, k, r));
        for _ in 0..4 {
            let c1 = self.regs.read(base + reg::CTRL1);
            if !bits::is_set(c1, bits::NEWDAT) {
                break;
            }
            if bits::is_set(c1, bits::MSGLST) {
                ctl(&mut self.regs, n, reg::CTRL1, bits::byte(k, k, r, k));
                ev(Event::Overrun { obj: n });
            }
            if n != EXT_RX {
                ctl(&mut self.regs, n, reg::CTRL1, bits::byte(k, k, k, r));
            }
            let mut arb = [0u8; 4];
            self.regs.readn(base + reg::ARB, &mut arb);
            let cfg = self.regs.read(base + reg::CFG);
            let mut data = [0u8; 8];
            let dlc = usize::from(cfg >> mcfg::DLC_SHIFT).min(MAX_DLC);
            self.regs.readn(base + reg::DATA, &mut data[..dlc]);
            if n == EXT_RX {
                // Object 15: releasing the foreground buffer (NewDat and
                // IntPnd reset) lets the shadow buffer move in; read
                // completely before that.
                ctl(&mut self.regs, n, reg::CTRL1, bits::byte(k, k, k, r));
                ev(Event::Rx(decode(arb, cfg, &data)));
                // A frame moved in from the shadow buffer sets IntPnd
                // again: the interrupt register names object 15 again.
                break;
            }
            let again = self.regs.read(base + reg::CTRL1);
            if bits::is_set(again, bits::NEWDAT) {
                // Overwritten while being read: read again.
                continue;
            }
            ev(Event::Rx(decode(arb, cfg, &data)));
            break;
        }
    }

    /// The transmit object's interrupt: the frame went out. The object is
    /// invalidated at once so that its identifier, under the global masks,
    /// does not make it answer (re-send) a remote frame, and a remote
    /// request it sent does not catch the answer.
    fn tx_object(&mut self, ev: &mut impl FnMut(Event)) {
        let base = reg::obj(TX_OBJ);
        let c1 = self.regs.read(base + reg::CTRL1);
        let cfg = self.regs.read(base + reg::CFG);
        if cfg & mcfg::DIR == 0 && bits::is_set(c1, bits::NEWDAT) {
            // The answer to our remote request landed here.
            let mut arb = [0u8; 4];
            self.regs.readn(base + reg::ARB, &mut arb);
            let cfg = self.regs.read(base + reg::CFG);
            let mut data = [0u8; 8];
            let dlc = usize::from(cfg >> mcfg::DLC_SHIFT).min(MAX_DLC);
            self.regs.readn(base + reg::DATA, &mut data[..dlc]);
            ev(Event::Rx(decode(arb, cfg, &data)));
        }
        self.invalidate(TX_OBJ);
        if self.tx_busy {
            self.tx_busy = false;
            ev(Event::TxDone);
        }
    }

    /// The status interrupt: reading the status register clears it. With
    /// [`Chip::berr_reporting`] a last error code becomes an
    /// [`Event::BusError`] (first: the error that changed the state comes
    /// before the state change). BOFF: the chip set INIT by itself and
    /// stays off the bus (mainline `can_bus_off`) until the driver
    /// restarts it ([`Chip::restart`], after `restart-ms` or `ip link set
    /// canX type can restart`). A chip whose INIT someone else cleared
    /// rejoins by itself after the recovery sequence: BOFF clears,
    /// [`Event::Restarted`].
    fn status_change(&mut self, ev: &mut impl FnMut(Event)) {
        let st = self.regs.read(reg::STATUS);
        // TXOK/RXOK/LEC are consumed here; clear them (LEC 0: no error).
        self.regs
            .write(reg::STATUS, st & (status::WARN | status::BOFF));
        let lec = st & status::LEC;
        if self.berr_reporting && lec != 0 && lec != 7 {
            ev(Event::BusError { lec });
        }
        let state = if st & status::BOFF != 0 {
            State::BusOff
        } else if st & status::WARN != 0 {
            State::Warning
        } else {
            State::Active
        };
        if state == self.state {
            return;
        }
        let was = self.state;
        self.state = state;
        ev(Event::State(state));
        if state == State::BusOff {
            // The transmit object's frame is lost with the bus; the chip
            // stays in INIT until restarted.
            self.invalidate(TX_OBJ);
            if self.tx_busy {
                self.tx_busy = false;
                ev(Event::TxAborted);
            }
        } else if was == State::BusOff {
            self.restarts += 1;
            ev(Event::Restarted);
        }
    }

    /// The controller setup for the GET ioctl.
    pub fn setup(&self) -> Setup {
        Setup {
            cpu_if: self.cfg.cpu_if,
            clkout: self.cfg.clkout,
            bus_cfg: self.cfg.bus_cfg,
            bt0: self.cfg.bt0,
            bt1: self.cfg.bt1,
            state: match self.state {
                State::Active => 0,
                State::Warning => 1,
                State::BusOff => 3,
            },
            std_answers_exact: u8::from(self.masks.std_answers_exact()),
            restarts: self.restarts,
        }
    }
}

/// Mainline `<linux/can/error.h>` error frame for `ev`; `None` for events
/// that are not errors.
pub fn error_frame(ev: &Event) -> Option<CanFrame> {
    use super::candev::err;
    let mut f = CanFrame {
        len: 8,
        ..CanFrame::default()
    };
    let class = match *ev {
        Event::Overrun { .. } => {
            f.data[1] = err::CRTL_RX_OVERFLOW;
            err::CRTL
        }
        Event::State(State::BusOff) => err::BUSOFF,
        Event::State(State::Warning) => {
            // The 82527 does not say which counter: both.
            f.data[1] = err::CRTL_RX_WARNING | err::CRTL_TX_WARNING;
            err::CRTL
        }
        Event::State(State::Active) => {
            f.data[1] = err::CRTL_ACTIVE;
            err::CRTL
        }
        Event::Restarted => err::RESTARTED,
        Event::BusError { lec } => {
            // i82527_lec adds PROT (with data[2]/[3]) or ACK to can_id.
            f.can_id = err::BUSERROR;
            super::candev::i82527_lec(&mut f, lec);
            f.can_id
        }
        Event::Rx(_) | Event::TxDone | Event::TxAborted => return None,
    };
    f.can_id = CAN_ERR_FLAG | class;
    Some(f)
}

/// The setup exchanged with user space by the `SIOCRCANI82527GET` device
/// ioctl, laid out as `struct rcan_i82527_setup` in
/// `<linux/can/rcan_i82527.h>`.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Setup {
    /// CPU interface register.
    pub cpu_if: u8,
    /// Clock out register.
    pub clkout: u8,
    /// Bus configuration register.
    pub bus_cfg: u8,
    /// Bit timing 0.
    pub bt0: u8,
    /// Bit timing 1.
    pub bt1: u8,
    /// 0 active, 1 warning, 3 bus-off.
    pub state: u8,
    /// 1 when standard answer objects answer only their own identifier.
    pub std_answers_exact: u8,
    /// Restarts after bus-off.
    pub restarts: u32,
}

/// Size of `struct rcan_i82527_setup`.
pub const SETUP_LEN: usize = 12;

impl Setup {
    /// The C layout: seven bytes, one pad byte, a native-endian u32.
    pub fn to_bytes(&self) -> [u8; SETUP_LEN] {
        let mut b = [0u8; SETUP_LEN];
        b[..7].copy_from_slice(&[
            self.cpu_if,
            self.clkout,
            self.bus_cfg,
            self.bt0,
            self.bt1,
            self.state,
            self.std_answers_exact,
        ]);
        b[8..12].copy_from_slice(&self.restarts.to_ne_bytes());
        b
    }

    /// Parses the C layout.
    pub fn from_bytes(b: &[u8; SETUP_LEN]) -> Setup {
        Setup {
            cpu_if: b[0],
            clkout: b[1],
            bus_cfg: b[2],
            bt0: b[3],
            bt1: b[4],
            state: b[5],
            std_answers_exact: b[6],
            restarts: u32::from_ne_bytes([b[8], b[9], b[10], b[11]]),
        }
    }
}

/// One remote-answer request exchanged by the `SIOCRCANI82527ANSWER`
/// device ioctl (`struct rcan_i82527_answer`): slot 0..11 and a
/// `struct can_frame` (a zero `can_id` with zero length withdraws).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct AnswerReq {
    /// Slot (object `ANSWER_FIRST + slot`).
    pub slot: u32,
    /// The answer, `None`: withdraw.
    pub frame: Option<CanFrame>,
}

/// Size of `struct rcan_i82527_answer`: u32 slot, u32 flags (bit 0:
/// publish), 16-byte frame.
pub const ANSWER_LEN: usize = 24;

impl AnswerReq {
    /// Parses the C layout.
    pub fn from_bytes(b: &[u8; ANSWER_LEN]) -> AnswerReq {
        let slot = u32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
        let flags = u32::from_ne_bytes([b[4], b[5], b[6], b[7]]);
        let mut fb = [0u8; 16];
        fb.copy_from_slice(&b[8..24]);
        AnswerReq {
            slot,
            frame: (flags & 1 != 0).then(|| CanFrame::from_bytes(&fb)),
        }
    }

    /// The C layout.
    pub fn to_bytes(&self) -> [u8; ANSWER_LEN] {
        let mut b = [0u8; ANSWER_LEN];
        b[0..4].copy_from_slice(&self.slot.to_ne_bytes());
        b[4..8].copy_from_slice(&u32::from(self.frame.is_some()).to_ne_bytes());
        if let Some(f) = self.frame {
            b[8..24].copy_from_slice(&f.to_bytes());
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_ns_of_the_registers() {
        // The simulated card's preset: 500 kbit/s, 2 us a bit.
        let c = Config::DEFAULT;
        assert_eq!(bit_ns(c.bt0, c.bt1, c.cpu_if, 16_000_000), 2_000);
        // 1 Mbit/s from the same 8 MHz system clock: BRP 1, 8 tq.
        assert_eq!(bit_ns(0x00, 0x14, cpu_if::DSC, 16_000_000), 1_000);
        // No DSC: the 16 MHz crystal is the system clock.
        assert_eq!(bit_ns(c.bt0, c.bt1, 0, 16_000_000), 1_000);
        assert_eq!(bit_ns(c.bt0, c.bt1, c.cpu_if, 0), 0);
    }

    #[test]
    fn two_bit_fields() {
        assert_eq!(bits::only(bits::INTPND, bits::RES), 0xFD);
        assert_eq!(
            bits::byte(bits::SET, bits::KEEP, bits::KEEP, bits::RES),
            0xBD
        );
        assert!(bits::is_set(0x80, bits::MSGVAL));
        assert!(!bits::is_set(0x40, bits::MSGVAL));
    }

    #[test]
    fn arbitration_layout() {
        assert_eq!(arb_bytes(0x7FF, false), [0xFF, 0xE0, 0, 0]);
        assert_eq!(arb_bytes(0x1FFF_FFFF, true), [0xFF, 0xFF, 0xFF, 0xF8]);
        assert_eq!(arb_id(arb_bytes(0x123, false), false), 0x123);
        assert_eq!(arb_id(arb_bytes(0x1234_5678, true), true), 0x1234_5678);
    }

    #[test]
    fn bit_timing() {
        let d = Config::DEFAULT;
        assert_eq!(bitrate(d.bt0, d.bt1, d.cpu_if, 16_000_000), 500_000);
        for rate in [
            10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 1_000_000,
        ] {
            let (b0, b1) = timing_for(rate, 8_000_000).unwrap();
            assert_eq!(bitrate(b0, b1, cpu_if::DSC, 16_000_000), rate, "{rate}");
        }
        assert_eq!(timing_for(333_333, 8_000_000), None);
        assert_eq!(clkout_hz(0x01, cpu_if::CEN, 16_000_000), 8_000_000);
        assert_eq!(clkout_hz(0x01, 0, 16_000_000), 0);
    }

    #[test]
    fn answer_req_round_trip() {
        let mut f = CanFrame {
            can_id: 0x321,
            len: 2,
            ..CanFrame::default()
        };
        f.data[..2].copy_from_slice(&[7, 8]);
        for r in [
            AnswerReq {
                slot: 3,
                frame: Some(f),
            },
            AnswerReq {
                slot: 11,
                frame: None,
            },
        ] {
            assert_eq!(AnswerReq::from_bytes(&r.to_bytes()), r);
        }
    }
}
