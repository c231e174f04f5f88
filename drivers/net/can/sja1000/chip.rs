// SPDX-License-Identifier: GPL-2.0

//! The Philips SJA1000 in PeliCAN mode: registers, frame buffer layout and
//! the chip-level driver logic of the thesis' abstract `sja1000` driver
//! (5.3.6), over a register-access trait that each front-end implements
//! (the thesis' read/write/readn/writen).
//!
//! Everything here is pure: the kernel driver
//! (`drivers/net/can/sja1000/`) supplies a [`Regs`] that touches the
//! hardware and turns the [`Event`]s of [`Chip::irq`] into skbs and
//! statistics; the host tests supply a register-level model of the chip.

use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK, MAX_DLC};
use super::bittiming::{self, Bittiming};
use super::candev::{self, ctrlmode, err, CanState, CanStats, NetErrStats};
use super::frame::CanFrame;

/// Register offsets (PeliCAN mode).
pub mod reg {
    /// Mode.
    pub const MOD: u8 = 0x00;
    /// Command (write only).
    pub const CMR: u8 = 0x01;
    /// Status.
    pub const SR: u8 = 0x02;
    /// Interrupt (read clears all bits but RI).
    pub const IR: u8 = 0x03;
    /// Interrupt enable.
    pub const IER: u8 = 0x04;
    /// Bus timing 0.
    pub const BTR0: u8 = 0x06;
    /// Bus timing 1.
    pub const BTR1: u8 = 0x07;
    /// Output control.
    pub const OCR: u8 = 0x08;
    /// Arbitration lost capture.
    pub const ALC: u8 = 0x0B;
    /// Error code capture.
    pub const ECC: u8 = 0x0C;
    /// Error warning limit.
    pub const EWLR: u8 = 0x0D;
    /// Receive error counter.
    pub const RXERR: u8 = 0x0E;
    /// Transmit error counter.
    pub const TXERR: u8 = 0x0F;
    /// Frame information of the TX/RX buffer (operating mode), or
    /// acceptance code 0 (reset mode).
    pub const FI: u8 = 0x10;
    /// Acceptance code 0..3 (reset mode).
    pub const ACR0: u8 = 0x10;
    /// Acceptance mask 0..3 (reset mode).
    pub const AMR0: u8 = 0x14;
    /// Receive message counter.
    pub const RMC: u8 = 0x1D;
    /// Clock divider.
    pub const CDR: u8 = 0x1F;
}

/// MOD bits.
pub mod mode {
    /// Reset mode.
    pub const RM: u8 = 0x01;
    /// Listen only.
    pub const LOM: u8 = 0x02;
    /// Self test.
    pub const STM: u8 = 0x04;
    /// Acceptance filter mode: 1 = single, 0 = dual.
    pub const AFM: u8 = 0x08;
    /// Sleep.
    pub const SM: u8 = 0x10;
}

/// CMR bits.
pub mod cmd {
    /// Transmission request.
    pub const TR: u8 = 0x01;
    /// Abort transmission.
    pub const AT: u8 = 0x02;
    /// Release receive buffer.
    pub const RRB: u8 = 0x04;
    /// Clear data overrun.
    pub const CDO: u8 = 0x08;
    /// Self reception request.
    pub const SRR: u8 = 0x10;
}

/// SR bits.
pub mod status {
    /// Receive buffer status: a frame is available.
    pub const RBS: u8 = 0x01;
    /// Data overrun.
    pub const DOS: u8 = 0x02;
    /// Transmit buffer released (free).
    pub const TBS: u8 = 0x04;
    /// Last transmission complete.
    pub const TCS: u8 = 0x08;
    /// Receiving.
    pub const RS: u8 = 0x10;
    /// Transmitting.
    pub const TS: u8 = 0x20;
    /// Error status: a counter reached the warning limit.
    pub const ES: u8 = 0x40;
    /// Bus status: bus-off.
    pub const BS: u8 = 0x80;
}

/// IR / IER bits.
pub mod irq {
    /// Receive.
    pub const RI: u8 = 0x01;
    /// Transmit.
    pub const TI: u8 = 0x02;
    /// Error warning (ES or BS changed).
    pub const EI: u8 = 0x04;
    /// Data overrun.
    pub const DOI: u8 = 0x08;
    /// Wake-up.
    pub const WUI: u8 = 0x10;
    /// Error passive.
    pub const EPI: u8 = 0x20;
    /// Arbitration lost.
    pub const ALI: u8 = 0x40;
    /// Bus error.
    pub const BEI: u8 = 0x80;
    /// What the driver enables: all but bus errors (one per bit error
    /// would flood the host on a broken bus).
    pub const ENABLED: u8 = RI | TI | EI | DOI | EPI | ALI;
}

/// CDR: PeliCAN mode.
pub const CDR_PELICAN: u8 = 0x80;
/// CDR: comparator bypass.
pub const CDR_CBP: u8 = 0x40;
/// CDR: clock out off.
pub const CDR_CLK_OFF: u8 = 0x08;
/// FI: extended frame.
pub const FI_FF: u8 = 0x80;
/// FI: remote frame.
pub const FI_RTR: u8 = 0x40;

/// Register access of one chip: what a front-end provides (thesis 5.3.6:
/// `read`, `write`, `readn`, `writen`). Implementations run in any
/// context the driver calls them from (process, softirq, hardirq) and
/// must not sleep.
pub trait Regs {
    /// Reads register `reg`.
    fn read(&mut self, reg: u8) -> u8;
    /// Writes `val` to register `reg`.
    fn write(&mut self, reg: u8, val: u8);
    /// Reads `buf.len()` consecutive registers from `reg`.
    fn readn(&mut self, reg: u8, buf: &mut [u8]) {
        for (i, b) in buf.iter_mut().enumerate() {
            *b = self.read(reg + i as u8);
        }
    }
    /// Writes `buf` to consecutive registers from `reg`.
    fn writen(&mut self, reg: u8, buf: &[u8]) {
        for (i, b) in buf.iter().enumerate() {
            self.write(reg + i as u8, *b);
        }
    }
    /// Board hook after the driver handled the chip's interrupt causes,
    /// e.g. acknowledging the interrupt in a bridge in front of the chip
    /// (PCAN-PCI's PITA); returns whether the board had an interrupt
    /// pending. Default: nothing to do.
    fn irq_done(&mut self) -> bool {
        false
    }
}

/// Encodes `frame` into the 13-byte TX buffer image (FI, identifier,
/// data); returns the image and the number of bytes used. Error frames
/// cannot be sent (`None`).
pub fn encode(frame: &CanFrame) -> Option<([u8; 13], usize)> {
    encode_dlc(frame, frame.dlc() as u8)
}

/// [`encode`] with `code` (0..15) in FI's DLC field in place of the
/// frame's length, for a DLC of 9..15 ([`candev::cc_dlc`]): the data
/// bytes are still the frame's `len` (8 for such a frame).
pub fn encode_dlc(frame: &CanFrame, code: u8) -> Option<([u8; 13], usize)> {
    if frame.can_id & CAN_ERR_FLAG != 0 {
        return None;
    }
    let dlc = frame.dlc();
    let rtr = frame.can_id & CAN_RTR_FLAG != 0;
    let mut b = [0u8; 13];
    b[0] = (code & 0x0F) | if rtr { FI_RTR } else { 0 };
    let data_at = if frame.can_id & CAN_EFF_FLAG != 0 {
        b[0] |= FI_FF;
        let id = (frame.can_id & CAN_EFF_MASK) << 3;
        b[1..5].copy_from_slice(&id.to_be_bytes());
        5
    } else {
        let id = ((frame.can_id & CAN_SFF_MASK) << 5) as u16;
        b[1..3].copy_from_slice(&id.to_be_bytes());
        3
    };
    if !rtr {
        b[data_at..data_at + dlc].copy_from_slice(&frame.data[..dlc]);
    }
    Some((b, data_at + if rtr { 0 } else { dlc }))
}

/// Decodes a 13-byte RX buffer image. A DLC above 8 (legal on the bus)
/// gives 8 data bytes, as mainline does.
pub fn decode(b: &[u8; 13]) -> CanFrame {
    decode_cc(b, 0)
}

/// [`decode`] under the control modes `ctrlmode`: with `cc-len8-dlc` a
/// DLC of 9..15 is kept in `len8_dlc` (mainline `sja1000_rx` with
/// `can_frame_set_cc_len`).
pub fn decode_cc(b: &[u8; 13], ctrlmode: u32) -> CanFrame {
    let fi = b[0];
    let dlc = usize::from(fi & 0x0F).min(MAX_DLC);
    let rtr = fi & FI_RTR != 0;
    let (mut can_id, data_at) = if fi & FI_FF != 0 {
        let id = u32::from_be_bytes([b[1], b[2], b[3], b[4]]) >> 3;
        (id | CAN_EFF_FLAG, 5)
    } else {
        let id = u32::from(u16::from_be_bytes([b[1], b[2]]) >> 5);
        (id, 3)
    };
    let mut f = CanFrame::default();
    candev::set_cc_len(&mut f, fi, ctrlmode);
    if rtr {
        can_id |= CAN_RTR_FLAG;
    } else {
        f.data[..dlc].copy_from_slice(&b[data_at..data_at + dlc]);
    }
    f.can_id = can_id;
    f
}

/// Controller state (mainline `enum can_state`, without the sleeping and
/// stopped states the driver tracks itself).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum State {
    /// Both error counters below 96.
    Active,
    /// A counter reached the warning limit (96).
    Warning,
    /// A counter above 127.
    Passive,
    /// Transmit counter above 255: the chip left the bus (and entered
    /// reset mode by itself).
    BusOff,
}

/// What an interrupt brought.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Event {
    /// A frame was received (and its buffer released).
    Rx(CanFrame),
    /// The frame in the TX buffer was sent.
    TxDone,
    /// The TX buffer was released without the frame being sent: aborted,
    /// or a single-shot transmission (`CAN_CTRLMODE_ONE_SHOT`) failed.
    TxAborted,
    /// Error causes (data overrun, error warning, bus error, error
    /// passive, arbitration lost), decoded as mainline's `sja1000_err`
    /// decodes them ([`sja1000_error`]): the error frame, whether
    /// the chip went bus-off, and what to add to the CAN device and
    /// interface statistics.
    Error(ErrReport),
}

/// One error interrupt round, decoded.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ErrReport {
    /// The error frame for sockets with `CAN_RAW_ERR_FILTER`.
    pub frame: CanFrame,
    /// The chip went bus-off (and is in reset mode): the driver turns the
    /// carrier off and restarts it after `restart-ms` or on request.
    pub bus_off: bool,
    /// The CAN device statistics this round counted.
    pub stats: CanStats,
    /// The interface error statistics this round counted.
    pub net: NetErrStats,
    /// The error state after this round.
    pub state: CanState,
}

/// Static configuration of one chip, from the front-end and the bit
/// timing parameters.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Config {
    /// Bus timing register 0 (thesis Kconfig `SJA1000_BTR0`, default 0x01).
    pub btr0: u8,
    /// Bus timing register 1 (`SJA1000_BTR1`, default 0x14: 500 kbit/s
    /// with a 16 MHz crystal).
    pub btr1: u8,
    /// Output control register (board-specific).
    pub ocr: u8,
    /// Clock divider register bits besides `CDR_PELICAN` (board-specific).
    pub cdr: u8,
}

/// Why an operation failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Sja1000Error {
    /// The chip did not enter or leave reset mode.
    ModeTimeout,
    /// The TX buffer is still in use.
    Busy,
    /// The frame cannot be sent (error frame).
    BadFrame,
    /// No chip answers at this address (probe).
    NoChip,
}

/// Times the mode register is polled when switching modes (the chip
/// switches within a bit time; a few reads suffice on real hardware).
const MODE_POLLS: usize = 100;

/// The driver's view of one SJA1000: its registers and configuration.
pub struct Chip<R: Regs> {
    /// Register access.
    pub regs: R,
    /// Configuration applied by [`Chip::init`].
    pub cfg: Config,
    /// Control modes (`CAN_CTRLMODE_*` of [`candev::ctrlmode`]) applied by
    /// [`Chip::start`], [`Chip::xmit`] and the receive path, as
    /// mainline's `sja1000`: listen-only (MOD.LOM), presume-ack (MOD.STM,
    /// self-test: no acknowledgement needed), loopback (MOD.STM and
    /// CMR.SRR in place of TR: the chip sends the frame, acknowledges and
    /// receives it itself), berr-reporting (IER.BEI), one-shot (CMR.AT
    /// with TR or SRR), cc-len8-dlc (DLC 9..15 both ways through
    /// `len8_dlc`). Triple sampling is in BTR1 ([`Config::btr1`]).
    pub ctrlmode: u32,
    state: CanState,
}

impl<R: Regs> Chip<R> {
    /// A chip behind `regs`; nothing is written yet.
    pub fn new(regs: R, cfg: Config) -> Self {
        Chip {
            regs,
            cfg,
            ctrlmode: 0,
            state: CanState::ErrorActive,
        }
    }

    /// The last error state reported (as `sja1000config` shows it).
    pub fn state(&self) -> State {
        match self.state {
            CanState::ErrorWarning => State::Warning,
            CanState::ErrorPassive => State::Passive,
            CanState::BusOff => State::BusOff,
            _ => State::Active,
        }
    }

    /// The device layer's error state since the last start.
    pub fn can_state(&self) -> CanState {
        self.state
    }

    /// The interrupts [`Chip::start`] enables: all but wake-up, bus error
    /// only with berr-reporting (as mainline's `set_normal_mode`).
    pub fn ier(&self) -> u8 {
        if self.ctrlmode & ctrlmode::BERR_REPORTING != 0 {
            irq::ENABLED | irq::BEI
        } else {
            irq::ENABLED
        }
    }

    /// Probes for a chip (mainline `sja1000_probe_chip`-style): after a
    /// reset request the mode register must read back with RM set and the
    /// clock divider must keep the PeliCAN bit. Leaves the chip in reset.
    pub fn probe(&mut self) -> Result<(), Sja1000Error> {
        if self.regs.read(reg::MOD) == 0xFF {
            return Err(Sja1000Error::NoChip);
        }
        self.enter_reset()?;
        self.regs.write(reg::CDR, CDR_PELICAN | self.cfg.cdr);
        if self.regs.read(reg::CDR) & CDR_PELICAN == 0 {
            return Err(Sja1000Error::NoChip);
        }
        Ok(())
    }

    /// Puts the chip into reset mode (interrupts off); polls until it is.
    pub fn enter_reset(&mut self) -> Result<(), Sja1000Error> {
        for _ in 0..MODE_POLLS {
            if self.regs.read(reg::MOD) & mode::RM != 0 {
                self.regs.write(reg::IER, 0);
                return Ok(());
            }
            self.regs.write(reg::MOD, mode::RM);
        }
        Err(Sja1000Error::ModeTimeout)
    }

    /// Full initialisation in reset mode: PeliCAN mode, output control,
    /// bit timing, and the acceptance filter `filter`. The chip stays in
    /// reset mode.
    pub fn init(&mut self, filter: &HwFilter) -> Result<(), Sja1000Error> {
        self.enter_reset()?;
        self.regs.write(reg::CDR, CDR_PELICAN | self.cfg.cdr);
        self.regs.write(reg::OCR, self.cfg.ocr);
        self.regs.write(reg::BTR0, self.cfg.btr0);
        self.regs.write(reg::BTR1, self.cfg.btr1);
        self.write_filter(filter);
        Ok(())
    }

    /// Writes the acceptance filter registers and the AFM bit. Reset mode
    /// only (the registers are the frame buffer in operating mode).
    fn write_filter(&mut self, filter: &HwFilter) {
        self.regs.writen(reg::ACR0, &filter.acr);
        self.regs.writen(reg::AMR0, &filter.amr);
        let afm = if filter.single { mode::AFM } else { 0 };
        self.regs.write(reg::MOD, mode::RM | afm);
    }

    /// Reprograms the acceptance filter: reset mode, filter, and with
    /// `running` back to operating mode. Frames the chip has already
    /// accepted are read out of the receive FIFO first and reported as
    /// [`Event::Rx`] through `ev` (a reset empties the FIFO on a real
    /// chip); only a frame arriving during the few register writes in
    /// reset mode is missed, as on any SJA1000 filter change. Entering
    /// reset mode aborts a transmission in progress: the caller changes
    /// the filter only while the TX buffer is free.
    pub fn set_filter(
        &mut self,
        filter: &HwFilter,
        running: bool,
        mut ev: impl FnMut(Event),
    ) -> Result<(), Sja1000Error> {
        if running {
            self.drain_rx(&mut ev);
        }
        self.enter_reset()?;
        self.write_filter(filter);
        if running {
            self.start(filter)?;
        }
        Ok(())
    }

    /// Leaves reset mode: clears error counters and pending interrupts,
    /// enables interrupts and enters operating mode (thesis: `open`).
    pub fn start(&mut self, filter: &HwFilter) -> Result<(), Sja1000Error> {
        if self.regs.read(reg::MOD) & mode::RM == 0 {
            self.enter_reset()?;
        }
        self.regs.write(reg::TXERR, 0);
        self.regs.write(reg::RXERR, 0);
        let _ = self.regs.read(reg::ECC);
        let mut afm = if filter.single { mode::AFM } else { 0 };
        if self.ctrlmode & ctrlmode::LISTENONLY != 0 {
            afm |= mode::LOM;
        }
        if self.ctrlmode & (ctrlmode::PRESUME_ACK | ctrlmode::LOOPBACK) != 0 {
            afm |= mode::STM;
        }
        if afm & (mode::LOM | mode::STM) != 0 {
            // LOM and STM are written in reset mode, then RM cleared.
            self.regs.write(reg::MOD, mode::RM | afm);
        }
        let mut operating = false;
        for _ in 0..MODE_POLLS {
            if self.regs.read(reg::MOD) & mode::RM == 0 {
                operating = true;
                break;
            }
            self.regs.write(reg::MOD, afm);
        }
        if !operating {
            return Err(Sja1000Error::ModeTimeout);
        }
        // Frames left in the receive FIFO from before the reset belong to
        // nobody (a real chip clears the FIFO in reset mode; QEMU's model
        // does not): release them before interrupts are enabled.
        for _ in 0..64 {
            if self.regs.read(reg::SR) & status::RBS == 0 {
                break;
            }
            self.regs.write(reg::CMR, cmd::RRB);
        }
        self.regs.write(reg::CMR, cmd::CDO);
        let _ = self.regs.read(reg::IR);
        let ier = self.ier();
        self.regs.write(reg::IER, ier);
        self.state = CanState::ErrorActive;
        Ok(())
    }

    /// Stops the chip (thesis: `stop`): reset mode, interrupts off.
    pub fn stop(&mut self) -> Result<(), Sja1000Error> {
        self.enter_reset()
    }

    /// Loads `frame` into the TX buffer and requests transmission. The
    /// caller keeps its queue stopped until [`Event::TxDone`] or
    /// [`Event::TxAborted`]: the chip has one TX buffer.
    pub fn xmit(&mut self, frame: &CanFrame) -> Result<(), Sja1000Error> {
        let code = candev::cc_dlc(frame, self.ctrlmode);
        let (img, n) = encode_dlc(frame, code).ok_or(Sja1000Error::BadFrame)?;
        if self.regs.read(reg::SR) & status::TBS == 0 {
            return Err(Sja1000Error::Busy);
        }
        self.regs.writen(reg::FI, &img[..n]);
        let at = if self.ctrlmode & ctrlmode::ONE_SHOT != 0 {
            cmd::AT
        } else {
            0
        };
        // Loopback (mainline): self reception request in place of the
        // transmission request.
        let go = if self.ctrlmode & ctrlmode::LOOPBACK != 0 {
            cmd::SRR
        } else {
            cmd::TR
        };
        self.regs.write(reg::CMR, go | at);
        Ok(())
    }

    /// Handles one interrupt (thesis: the interrupt handler): reads IR
    /// until no cause is left (at most `max_rounds` rounds), draining the
    /// receive FIFO and reporting each event through `ev`. Returns whether
    /// the chip had raised anything (for shared interrupt lines). Hardirq
    /// context in the kernel: must not sleep, and does not.
    pub fn irq(&mut self, max_rounds: usize, mut ev: impl FnMut(Event)) -> bool {
        let mut handled = false;
        for _ in 0..max_rounds {
            let ir = self.regs.read(reg::IR);
            if ir == 0 || ir == 0xFF {
                // 0xFF: the device went away (hot unplug).
                break;
            }
            handled = true;
            // The status as the round began (mainline reads it once per
            // round too, for the error decoding).
            let sr = self.regs.read(reg::SR);
            if ir & irq::TI != 0 {
                ev(if sr & status::TCS != 0 {
                    Event::TxDone
                } else {
                    Event::TxAborted
                });
            }
            if ir & irq::RI != 0 {
                self.drain_rx(&mut ev);
            }
            if ir & irq::DOI != 0 {
                self.regs.write(reg::CMR, cmd::CDO);
                // Whatever made it into the FIFO before the overrun.
                self.drain_rx(&mut ev);
            }
            if ir & (irq::DOI | irq::EI | irq::BEI | irq::EPI | irq::ALI) != 0 {
                let r = self.err(ir, sr);
                let bus_off = r.bus_off;
                ev(Event::Error(r));
                if bus_off {
                    // The chip is in reset mode: nothing more to read.
                    break;
                }
            }
        }
        handled
    }

    /// Reads what an error interrupt needs (the counters; ECC only for a
    /// bus error and ALC only for lost arbitration, as reading each
    /// re-arms its capture) and decodes it as mainline's `sja1000_err`.
    fn err(&mut self, ir: u8, sr: u8) -> ErrReport {
        let txerr = self.regs.read(reg::TXERR);
        let rxerr = self.regs.read(reg::RXERR);
        let ecc = if ir & irq::BEI != 0 {
            self.regs.read(reg::ECC)
        } else {
            0
        };
        let alc = if ir & irq::ALI != 0 {
            self.regs.read(reg::ALC)
        } else {
            0
        };
        let regs = Sja1000ErrRegs {
            ir,
            sr,
            txerr,
            rxerr,
            ecc,
            alc,
        };
        let mut stats = CanStats::default();
        let mut net = NetErrStats::default();
        let e = sja1000_error(&mut self.state, &mut stats, &mut net, &regs);
        ErrReport {
            frame: e.frame,
            bus_off: e.bus_off,
            stats,
            net,
            state: self.state,
        }
    }

    /// Reads every frame in the receive FIFO, releasing each buffer.
    fn drain_rx(&mut self, ev: &mut impl FnMut(Event)) {
        // The FIFO holds at most 64 bytes: 21 three-byte-minimum frames.
        for _ in 0..32 {
            if self.regs.read(reg::SR) & status::RBS == 0 {
                break;
            }
            let mut img = [0u8; 13];
            self.regs.readn(reg::FI, &mut img);
            self.regs.write(reg::CMR, cmd::RRB);
            ev(Event::Rx(decode_cc(&img, self.ctrlmode)));
        }
    }
}

/// Contents of the acceptance filter registers.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct HwFilter {
    /// Single filter mode (MOD.AFM = 1); else dual.
    pub single: bool,
    /// Acceptance code ACR0..3.
    pub acr: [u8; 4],
    /// Acceptance mask AMR0..3 (1 = don't care).
    pub amr: [u8; 4],
}

impl HwFilter {
    /// Accepts every frame (dual mode, every bit "don't care", as
    /// mainline's driver programs the chip).
    pub const OPEN: HwFilter = HwFilter {
        single: false,
        acr: [0; 4],
        amr: [0xFF; 4],
    };

    /// Whether the chip accepts `frame` with this filter (datasheet
    /// section 6.4.15; the data bytes of standard frames take part).
    pub fn accepts(&self, frame: &CanFrame) -> bool {
        let acr = u32::from_be_bytes(self.acr);
        let amr = u32::from_be_bytes(self.amr);
        let (img, _) = match encode(frame) {
            Some(x) => x,
            None => return false,
        };
        let eff = frame.can_id & CAN_EFF_FLAG != 0;
        let rtr = frame.can_id & CAN_RTR_FLAG != 0;
        let pass = |code: u32, mask: u32, bits: u32, sel: u32| (code ^ bits) & !mask & sel == 0;
        if self.single {
            let bits = if eff {
                // ID28..0 left-aligned, RTR in bit 2, bits 1..0 unused.
                let id = u32::from_be_bytes([img[1], img[2], img[3], img[4]]) & !0x7;
                id | if rtr { 0x4 } else { 0 }
            } else {
                // ID10..0 in bits 31..21, RTR bit 20, data bytes 1 and 2
                // (bits 15..0); bits 19..16 unused.
                let id = u32::from(u16::from_be_bytes([img[1], img[2]]) & 0xFFE0) << 16;
                let d = if rtr {
                    [0, 0]
                } else {
                    [frame.data[0], frame.data[1]]
                };
                let d = if frame.dlc() < 1 || rtr {
                    0
                } else {
                    u32::from(d[0]) << 8 | if frame.dlc() >= 2 { u32::from(d[1]) } else { 0 }
                };
                id | if rtr { 1 << 20 } else { 0 } | d
            };
            let sel = if eff {
                0xFFFF_FFFC
            } else {
                // Data bytes beyond the DLC are not compared.
                let mut s = 0xFFF0_0000;
                if !rtr && frame.dlc() >= 1 {
                    s |= 0xFF00;
                }
                if !rtr && frame.dlc() >= 2 {
                    s |= 0x00FF;
                }
                s
            };
            pass(acr, amr, bits, sel)
        } else if eff {
            // Two filters over ID28..13: ACR0/1 and ACR2/3.
            let id = (frame.can_id & CAN_EFF_MASK) >> 13;
            let f1 = pass(acr >> 16, amr >> 16, id, 0xFFFF);
            let f2 = pass(acr & 0xFFFF, amr & 0xFFFF, id, 0xFFFF);
            f1 || f2
        } else {
            // Filter 1: ID10..0 + RTR in ACR0/ACR1[7..4], data byte 1 in
            // ACR1[3..0] (high nibble) and ACR3[3..0] (low nibble).
            // Filter 2: ID10..0 + RTR in ACR2/ACR3[7..4].
            let id_rtr = ((frame.can_id & CAN_SFF_MASK) << 1) | u32::from(rtr);
            let d1 = if !rtr && frame.dlc() >= 1 {
                Some(u32::from(frame.data[0]))
            } else {
                None
            };
            let code1 = u32::from(self.acr[0]) << 4 | u32::from(self.acr[1] >> 4);
            let mask1 = u32::from(self.amr[0]) << 4 | u32::from(self.amr[1] >> 4);
            let mut f1 = pass(code1, mask1, id_rtr, 0xFFF);
            if let Some(d) = d1 {
                let dcode = u32::from(self.acr[1] & 0xF) << 4 | u32::from(self.acr[3] & 0xF);
                let dmask = u32::from(self.amr[1] & 0xF) << 4 | u32::from(self.amr[3] & 0xF);
                f1 = f1 && pass(dcode, dmask, d, 0xFF);
            }
            let code2 = u32::from(self.acr[2]) << 4 | u32::from(self.acr[3] >> 4);
            let mask2 = u32::from(self.amr[2]) << 4 | u32::from(self.amr[3] >> 4);
            let f2 = pass(code2, mask2, id_rtr, 0xFFF);
            f1 || f2
        }
    }
}

/// The error frame sent after a restart from bus-off (mainline
/// `can_restart`: `CAN_ERR_RESTARTED`).
pub fn restarted_frame() -> CanFrame {
    CanFrame {
        can_id: CAN_ERR_FLAG | candev::err::RESTARTED,
        len: 8,
        ..CanFrame::default()
    }
}

/// Bit rate of bus timing `btr0`/`btr1` on a chip with crystal `xtal_hz`
/// (datasheet 6.5.1: tq = 2 (BRP + 1) / fXTAL, bit = (1 + TSEG1+1 +
/// TSEG2+1) tq): the registers decoded by [`bittiming::from_btr`], the
/// one decoder of the SJA1000 and 82527 timing registers, with the
/// bit-timing clock at half the crystal (as mainline's front-ends set
/// `clock.freq`).
pub fn bitrate(btr0: u8, btr1: u8, xtal_hz: u32) -> u32 {
    bittiming::from_btr(btr0, btr1, xtal_hz / 2).0.bitrate
}

/// Bus timing for `bitrate` on a chip with crystal `xtal_hz`: the exact
/// setting with the most time quanta per bit (8..25) and a sample point
/// nearest 87.5 %, SJW 1, one sample, within
/// [`bittiming::SJA1000_BITTIMING_CONST`], encoded by
/// [`bittiming::to_btr`]. `None` if no setting gives the bit rate exactly.
/// (`sja1000config`'s search; `ip link set ... type can bitrate` uses
/// mainline's, [`bittiming::calc`], which also accepts the nearest rate.)
pub fn timing_for(bitrate: u32, xtal_hz: u32) -> Option<(u8, u8)> {
    let c = &bittiming::SJA1000_BITTIMING_CONST;
    if bitrate == 0 {
        return None;
    }
    let mut best: Option<(u32, u32, Bittiming)> = None;
    for tq in (8u32..=25).rev() {
        let div = 2 * tq * bitrate;
        if !xtal_hz.is_multiple_of(div) {
            continue;
        }
        let brp = xtal_hz / div;
        if brp < c.brp_min || brp > c.brp_max {
            continue;
        }
        // Sample point after 1 + TSEG1 quanta.
        for tseg2 in c.tseg2_min..=c.tseg2_max {
            let Some(tseg1) = (tq - 1).checked_sub(tseg2) else {
                continue;
            };
            if !(c.tseg1_min..=c.tseg1_max).contains(&tseg1) {
                continue;
            }
            let sp = (1 + tseg1) * 1000 / tq;
            let err = sp.abs_diff(875);
            let better = match best {
                None => true,
                Some((btq, berr, _)) => tq > btq || (tq == btq && err < berr),
            };
            if better {
                let bt = Bittiming {
                    brp,
                    sjw: 1,
                    prop_seg: tseg1 / 2,
                    phase_seg1: tseg1 - tseg1 / 2,
                    phase_seg2: tseg2,
                    ..Bittiming::default()
                };
                best = Some((tq, err, bt));
            }
        }
        if best.is_some() {
            break;
        }
    }
    best.map(|(_, _, bt)| bittiming::to_btr(&bt, false))
}

/// The controller setup exchanged with user space by the
/// `SIOCRCANSJA1000GET`/`SET` device ioctls (`sja1000config`), laid out as
/// `struct rcan_sja1000_setup` in `<linux/can/rcan_sja1000.h>`.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Setup {
    /// Bus timing register 0.
    pub btr0: u8,
    /// Bus timing register 1.
    pub btr1: u8,
    /// Output control register.
    pub ocr: u8,
    /// Clock divider register (without the PeliCAN bit).
    pub cdr: u8,
    /// Error state: 0 active, 1 warning, 2 passive, 3 bus-off (GET only).
    pub state: u8,
    /// Receive error counter (GET only).
    pub rxerr: u8,
    /// Transmit error counter (GET only).
    pub txerr: u8,
    /// Automatic restarts after bus-off (GET only).
    pub restarts: u32,
    /// Crystal frequency in Hz (GET only).
    pub xtal_hz: u32,
}

/// Size of `struct rcan_sja1000_setup`.
pub const SETUP_LEN: usize = 16;

impl Setup {
    /// The C layout: seven bytes, one pad byte, then two native-endian
    /// 32-bit words.
    pub fn to_bytes(&self) -> [u8; SETUP_LEN] {
        let mut b = [0u8; SETUP_LEN];
        b[..7].copy_from_slice(&[
            self.btr0, self.btr1, self.ocr, self.cdr, self.state, self.rxerr, self.txerr,
        ]);
        b[8..12].copy_from_slice(&self.restarts.to_ne_bytes());
        b[12..16].copy_from_slice(&self.xtal_hz.to_ne_bytes());
        b
    }

    /// Parses the C layout.
    pub fn from_bytes(b: &[u8; SETUP_LEN]) -> Setup {
        Setup {
            btr0: b[0],
            btr1: b[1],
            ocr: b[2],
            cdr: b[3],
            state: b[4],
            rxerr: b[5],
            txerr: b[6],
            restarts: u32::from_ne_bytes([b[8], b[9], b[10], b[11]]),
            xtal_hz: u32::from_ne_bytes([b[12], b[13], b[14], b[15]]),
        }
    }
}

pub use super::filter::{Cube, Wanted};

/// A cube placed in the 32 acceptance bits of single filter mode, or in
/// the 16 bits of one dual-mode filter.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Placed {
    cube: Cube,
    /// Came from a standard-frame cube (dual mode: the data nibbles of
    /// filter 1 must then be "don't care").
    sff: bool,
}

/// Places a format cube into single-filter-mode bit positions.
fn single_bits(c: Cube, sff: bool) -> Cube {
    if sff {
        // ID10..0 + RTR -> bits 31..20.
        Cube::new(c.value << 20, c.care << 20)
    } else {
        // ID28..0 + RTR -> bits 31..2.
        Cube::new(c.value << 2, c.care << 2)
    }
}

/// Places a format cube into one dual-mode filter's 16 bits.
fn dual_bits(c: Cube, sff: bool) -> Cube {
    if sff {
        // ID10..0 + RTR -> bits 15..4; bits 3..0 are data (set apart).
        Cube::new(c.value << 4, c.care << 4)
    } else {
        // ID28..13 -> bits 15..0; the rest of the identifier and RTR are
        // not compared in dual mode.
        Cube::new(c.value >> 14, c.care >> 14)
    }
}

/// Fractions below are fixed point: 1 << `ONE_SHIFT` is "every frame of
/// a format". Integer only: kernel code has no floating point.
const ONE_SHIFT: u32 = 32;

/// `2^(dc - bits)` of a format, in fixed point.
fn frac(dc: u32, bits: u32) -> u64 {
    1u64 << (ONE_SHIFT + dc - bits)
}

/// Cost of a single-mode cube: the accepted fraction of standard frames
/// plus that of extended frames (lower is tighter).
fn cost_single(c: Cube) -> u64 {
    let sff_dc = (!c.care >> 20 & 0xFFF).count_ones();
    let eff_dc = (!c.care >> 2 & 0x3FFF_FFFF).count_ones();
    frac(sff_dc, 12) + frac(eff_dc, 30)
}

/// Cost of dual mode with filters `a` and `b` (16-bit cubes): accepted
/// fraction of standard frames (12 identifier+RTR bits) plus that of
/// extended frames (16 compared bits), by inclusion-exclusion.
fn cost_dual(a: Cube, b: Cube) -> u64 {
    let part = |c: Cube, bits: u32, shift: u32| {
        let dc = (!c.care >> shift & ((1 << bits) - 1)).count_ones();
        frac(dc, bits)
    };
    // Intersection of two cubes: empty if they disagree on a common care
    // bit.
    let both = if (a.value ^ b.value) & a.care & b.care != 0 {
        None
    } else {
        Some(Cube::new(a.value | b.value, a.care | b.care))
    };
    let union = |bits: u32, shift: u32| {
        let inter = both.map_or(0, |i| part(i, bits, shift));
        part(a, bits, shift) + part(b, bits, shift) - inter
    };
    union(12, 4) + union(16, 0)
}

/// Most cubes for which every split into two dual-mode groups is tried;
/// above, a greedy split is used.
const EXHAUSTIVE: usize = 12;

/// The tightest acceptance filter (single or dual mode) that accepts every
/// frame some filter in `wanted` wants (thesis 5.3.4/5.3.6, DESIGN
/// decision 7). An empty `wanted` (nobody listens) gives the tightest
/// filter there is: one identifier. `promisc` (a packet socket or
/// IFF_PROMISC) opens it.
pub fn hw_filter(wanted: &[Wanted], promisc: bool) -> HwFilter {
    if promisc {
        return HwFilter::OPEN;
    }
    let mut cubes: [Option<Placed>; 2 * EXHAUSTIVE] = [None; 2 * EXHAUSTIVE];
    let mut n = 0;
    let mut single: Option<Cube> = None;
    let mut overflow = false;
    for w in wanted {
        for (c, sff) in [(w.sff, true), (w.eff, false)] {
            let Some(c) = c else { continue };
            let s = single_bits(c, sff);
            single = Some(single.map_or(s, |x| x.merge(s)));
            if n < cubes.len() {
                cubes[n] = Some(Placed { cube: c, sff });
                n += 1;
            } else {
                overflow = true;
            }
        }
    }
    let Some(single) = single else {
        // Nobody wants anything: accept only standard remote frame 0x7FF
        // in both dual filters, the least likely frame on a real bus.
        let c = dual_bits(Cube::new(0xFFF, 0xFFF), true);
        let code = (c.value as u16).to_be_bytes();
        let mask = (!(c.care as u16)).to_be_bytes();
        return HwFilter {
            single: false,
            acr: [code[0], code[1], code[0], code[1]],
            amr: [mask[0], mask[1], mask[0], mask[1]],
        };
    };
    // Single filter mode only when no standard frame is wanted: QEMU's
    // model of the chip (hw/net/can/can_sja1000.c, can_sja_single_filter)
    // shifts AMR1 the wrong way for standard frames and then compares
    // identifier bits 2..0 exactly, whatever the mask says. Dual mode is
    // modelled correctly, and it is what mainline's driver uses.
    let any_sff = cubes[..n].iter().flatten().any(|p| p.sff);
    let single_f = to_single(single);
    if n < 2 {
        if !any_sff {
            return single_f;
        }
        let p = cubes[0].unwrap_or(Placed {
            cube: Cube::new(0, 0),
            sff: true,
        });
        let d = dual_bits(p.cube, p.sff);
        return to_dual(d, d, p.sff);
    }
    let best_single = if any_sff {
        u64::MAX
    } else {
        cost_single(single)
    };
    let placed = &cubes[..n];
    let mut best: Option<(u64, [Cube; 2], bool)> = None;
    let mut consider = |groups: [Option<(Cube, bool)>; 2]| {
        let (a, b) = match groups {
            [Some(a), Some(b)] => (a, b),
            _ => return,
        };
        let cost = cost_dual(a.0, b.0);
        if best.as_ref().is_none_or(|(c, _, _)| cost < *c) {
            best = Some((cost, [a.0, b.0], a.1));
        }
    };
    let merge_into = |g: &mut Option<(Cube, bool)>, p: &Placed| {
        let d = dual_bits(p.cube, p.sff);
        *g = Some(match *g {
            None => (d, p.sff),
            Some((c, s)) => (c.merge(d), s || p.sff),
        });
    };
    if !overflow && n <= EXHAUSTIVE {
        // Cube 0 always in group A; every subset of the rest joins B.
        for bits in 0u32..(1 << (n - 1)) {
            let mut g: [Option<(Cube, bool)>; 2] = [None, None];
            for (i, p) in placed.iter().flatten().enumerate() {
                let side = if i == 0 {
                    0
                } else {
                    ((bits >> (i - 1)) & 1) as usize
                };
                merge_into(&mut g[side], p);
            }
            consider(g);
        }
    } else {
        // Greedy: seed with the first cube and the one farthest from it,
        // then add each cube where it widens its group least.
        let first = placed[0].unwrap_or(Placed {
            cube: Cube::new(0, 0),
            sff: true,
        });
        let far = placed
            .iter()
            .flatten()
            .max_by_key(|p| {
                let a = dual_bits(first.cube, first.sff);
                let b = dual_bits(p.cube, p.sff);
                ((a.value ^ b.value) & a.care & b.care).count_ones()
            })
            .copied()
            .unwrap_or(first);
        let mut g: [Option<(Cube, bool)>; 2] = [None, None];
        merge_into(&mut g[0], &first);
        merge_into(&mut g[1], &far);
        let mut add = |p: &Placed| {
            let d = dual_bits(p.cube, p.sff);
            let widen = |x: Option<(Cube, bool)>| {
                x.map_or(0, |(c, _)| (c.care & !c.merge(d).care).count_ones())
            };
            let side = usize::from(widen(g[1]) < widen(g[0]));
            merge_into(&mut g[side], p);
        };
        placed.iter().flatten().for_each(&mut add);
        // Cubes that did not fit the scratch array go to the cheaper side
        // too; the single-mode cube already covers them.
        for w in wanted.iter().skip(EXHAUSTIVE) {
            for (c, sff) in [(w.sff, true), (w.eff, false)] {
                if let Some(c) = c {
                    add(&Placed { cube: c, sff });
                }
            }
        }
        consider(g);
    }
    match best {
        Some((cost, [a, b], sff_in_a)) if cost < best_single || any_sff => to_dual(a, b, sff_in_a),
        _ => single_f,
    }
}

fn to_single(c: Cube) -> HwFilter {
    HwFilter {
        single: true,
        acr: c.value.to_be_bytes(),
        amr: (!c.care).to_be_bytes(),
    }
}

/// Dual-mode registers for filters `a` (ACR0/1) and `b` (ACR2/3). When
/// filter 1 holds standard-frame cubes, its data nibbles (ACR1[3..0],
/// ACR3[3..0]) must not reject anything.
fn to_dual(a: Cube, b: Cube, sff_in_a: bool) -> HwFilter {
    let (mut ca, mut cb) = (a.care, b.care);
    if sff_in_a {
        ca &= !0xF;
        cb &= !0xF;
    }
    let va = (a.value & ca) as u16;
    let vb = (b.value & cb) as u16;
    let (ma, mb) = (!(ca as u16), !(cb as u16));
    HwFilter {
        single: false,
        acr: [(va >> 8) as u8, va as u8, (vb >> 8) as u8, vb as u8],
        amr: [(ma >> 8) as u8, ma as u8, (mb >> 8) as u8, mb as u8],
    }
}

#[cfg(test)]
mod tests {
    use super::super::rxtable::{CanFilterKind, Filter};
    use super::*;

    fn raw(id: u32, mask: u32) -> Filter {
        match Filter::from_can_filter(id, mask) {
            CanFilterKind::Frames(f) => f,
            CanFilterKind::Errors(_) => unreachable!(),
        }
    }

    fn frame(can_id: u32, data: &[u8]) -> CanFrame {
        let mut f = CanFrame {
            can_id,
            len: data.len() as u8,
            ..CanFrame::default()
        };
        f.data[..data.len()].copy_from_slice(data);
        f
    }

    const EXACT_SFF: u32 = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;

    #[test]
    fn codec_round_trip() {
        for f in [
            frame(0x123, &[1, 2, 3]),
            frame(0x7FF | CAN_RTR_FLAG, &[]),
            frame(0x1234_5678 | CAN_EFF_FLAG, &[9; 8]),
            frame(CAN_EFF_FLAG | CAN_RTR_FLAG | 5, &[]),
        ] {
            let (img, n) = encode(&f).unwrap();
            assert!(n <= 13);
            assert_eq!(decode(&img), f);
        }
        assert_eq!(encode(&frame(CAN_ERR_FLAG | 4, &[])), None);
        // The datasheet's layout of a standard frame: ID10..3, ID2..0<<5.
        let (img, n) = encode(&frame(0x123, &[0xAA])).unwrap();
        assert_eq!(&img[..n], &[0x01, 0x24, 0x60, 0xAA]);
    }

    #[test]
    fn exact_sff_filter_is_tight() {
        let hw = hw_filter(&[Wanted::of(&raw(0x123, EXACT_SFF))], false);
        assert!(!hw.single, "standard frames wanted: dual mode (QEMU)");
        assert!(hw.accepts(&frame(0x123, &[1, 2])));
        assert!(!hw.accepts(&frame(0x124, &[])));
        assert!(!hw.accepts(&frame(0x123 | CAN_RTR_FLAG, &[])));
    }

    #[test]
    fn two_ids_use_dual_mode() {
        let w = [
            Wanted::of(&raw(0x100, EXACT_SFF)),
            Wanted::of(&raw(0x7F0, EXACT_SFF)),
        ];
        let hw = hw_filter(&w, false);
        assert!(!hw.single);
        assert!(hw.accepts(&frame(0x100, &[5])));
        assert!(hw.accepts(&frame(0x7F0, &[])));
        assert!(!hw.accepts(&frame(0x101, &[])));
        assert!(!hw.accepts(&frame(0x3F0, &[])));
    }

    #[test]
    fn bit_timing() {
        // The thesis' Kconfig defaults: 500 kbit/s with a 16 MHz crystal.
        assert_eq!(bitrate(0x01, 0x14, 16_000_000), 500_000);
        for rate in [
            10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
        ] {
            let (b0, b1) = timing_for(rate, 16_000_000).unwrap();
            assert_eq!(bitrate(b0, b1, 16_000_000), rate, "{rate}");
        }
        assert_eq!(timing_for(0, 16_000_000), None);
        assert_eq!(timing_for(333_333, 16_000_000), None);
        let s = Setup {
            btr0: 1,
            btr1: 0x14,
            restarts: 7,
            xtal_hz: 16_000_000,
            ..Setup::default()
        };
        assert_eq!(Setup::from_bytes(&s.to_bytes()), s);
    }

    #[test]
    fn restarted_frame_is_mainlines() {
        let f = restarted_frame();
        assert_eq!(f.can_id, CAN_ERR_FLAG | candev::err::RESTARTED);
        assert_eq!((f.len, f.data), (8, [0; 8]));
    }

    #[test]
    fn nothing_wanted_and_promisc() {
        let hw = hw_filter(&[], false);
        assert!(!hw.accepts(&frame(0x123, &[])));
        assert!(!hw.accepts(&frame(CAN_EFF_FLAG | 0x123, &[])));
        assert_eq!(hw_filter(&[], true), HwFilter::OPEN);
        assert!(HwFilter::OPEN.accepts(&frame(CAN_EFF_FLAG | 0x123, &[])));
    }
}

/// SJA1000 error code capture register (ECC) fields.
pub mod ecc {
    /// Segment where the error happened (bits 4..0); the codes are the
    /// `CAN_ERR_PROT_LOC_*` values.
    pub const SEG: u8 = 0x1F;
    /// Direction: set on reception, clear on transmission.
    pub const DIR: u8 = 0x20;
    /// Error type (bits 7..6).
    pub const MASK: u8 = 0xC0;
    /// Type: bit error.
    pub const BIT: u8 = 0x00;
    /// Type: form error.
    pub const FORM: u8 = 0x40;
    /// Type: stuff error.
    pub const STUFF: u8 = 0x80;
}

/// The registers an SJA1000 error interrupt is decoded from.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Sja1000ErrRegs {
    /// Interrupt register: the causes (DOI, EI, BEI, EPI, ALI are looked at).
    pub ir: u8,
    /// Status register.
    pub sr: u8,
    /// Transmit error counter.
    pub txerr: u8,
    /// Receive error counter.
    pub rxerr: u8,
    /// Error code capture, read by the caller only when IR has BEI
    /// (reading it re-arms the capture); else 0.
    pub ecc: u8,
    /// Arbitration lost capture, read only when IR has ALI; else 0.
    pub alc: u8,
}

/// What one SJA1000 error interrupt reported (mainline `sja1000_err`).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Sja1000Err {
    /// The error frame for CAN_RAW sockets with `CAN_RAW_ERR_FILTER`.
    pub frame: CanFrame,
    /// The chip went bus-off: the driver stops the queue and starts the
    /// restart timer (mainline `can_bus_off`).
    pub bus_off: bool,
}

/// Decodes an SJA1000 error interrupt from `r` as mainline's
/// `sja1000_err` does; updates the device's `state` and statistics.
/// Hardirq context in the driver; pure.
///
/// Data overrun: [`err::CRTL`], [`err::CRTL_RX_OVERFLOW`], one receive
/// overrun and receive error (the caller clears the overrun). Error
/// warning: the state becomes bus-off (SR.BS), warning (SR.ES) or active.
/// Unless that state is bus-off, [`err::CNT`] with the counters in
/// data[6]/data[7]. Bus error: [`err::PROT`] | [`err::BUSERROR`], the
/// ECC type in data[2] (bit, form or stuff; other: unspecified), the ECC
/// segment in data[3], [`err::PROT_TX`] and a transmit error when ECC.DIR
/// is clear, else a receive error. Error passive: the state becomes
/// passive, or warning if it was passive. Arbitration lost:
/// [`err::LOSTARB`] with ALC bits 4..0 in data[0]. A changed state goes
/// through [`candev::change_state`], counted on the side whose counter is the
/// larger (both when equal).
pub fn sja1000_error(
    state: &mut CanState,
    stats: &mut CanStats,
    net: &mut NetErrStats,
    r: &Sja1000ErrRegs,
) -> Sja1000Err {
    let Sja1000ErrRegs {
        ir,
        sr,
        txerr,
        rxerr,
        ecc,
        alc,
    } = *r;
    let mut cf = candev::error_frame();
    let mut new = *state;
    if ir & irq::DOI != 0 {
        cf.can_id |= err::CRTL;
        cf.data[1] = err::CRTL_RX_OVERFLOW;
        net.rx_over_errors += 1;
        net.rx_errors += 1;
    }
    if ir & irq::EI != 0 {
        new = if sr & status::BS != 0 {
            CanState::BusOff
        } else if sr & status::ES != 0 {
            CanState::ErrorWarning
        } else {
            CanState::ErrorActive
        };
    }
    if new != CanState::BusOff {
        cf.can_id |= err::CNT;
        cf.data[6] = txerr;
        cf.data[7] = rxerr;
    }
    if ir & irq::BEI != 0 {
        stats.bus_error += 1;
        cf.can_id |= err::PROT | err::BUSERROR;
        cf.data[2] |= match ecc & ecc::MASK {
            ecc::BIT => err::PROT_BIT,
            ecc::FORM => err::PROT_FORM,
            ecc::STUFF => err::PROT_STUFF,
            _ => 0,
        };
        cf.data[3] = ecc & ecc::SEG;
        if ecc & ecc::DIR == 0 {
            net.tx_errors += 1;
            cf.data[2] |= err::PROT_TX;
        } else {
            net.rx_errors += 1;
        }
    }
    if ir & irq::EPI != 0 {
        new = if new == CanState::ErrorPassive {
            CanState::ErrorWarning
        } else {
            CanState::ErrorPassive
        };
    }
    if ir & irq::ALI != 0 {
        stats.arbitration_lost += 1;
        cf.can_id |= err::LOSTARB;
        cf.data[0] = alc & 0x1F;
    }
    let mut bus_off = false;
    if new != *state {
        let tx = if txerr >= rxerr {
            new
        } else {
            CanState::ErrorActive
        };
        let rx = if txerr <= rxerr {
            new
        } else {
            CanState::ErrorActive
        };
        candev::change_state(state, stats, Some(&mut cf), tx, rx);
        bus_off = new == CanState::BusOff;
    }
    Sja1000Err { frame: cf, bus_off }
}
