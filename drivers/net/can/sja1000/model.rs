// SPDX-License-Identifier: GPL-2.0

//! A register-level model of the Philips SJA1000 in PeliCAN mode, for the
//! host tests of the driver core ([`super::sja1000::Chip`]) and for the
//! kernel's simulated card (`rcan_sja1000_sim`), which runs the unchanged
//! driver on it. No allocation, fixed-size state: one model is one chip.
//!
//! It follows the datasheet for what the driver touches: reset and
//! operating mode (listen-only LOM, self-test STM), the acceptance
//! registers that exist only in reset mode, the TX buffer and the TR,
//! AT (single shot) and SRR (self reception: the frame goes on the bus
//! and into the chip's own receive FIFO) commands, data length codes
//! 9..15 (8 data bytes; the code itself travels on the bus), the 64-byte receive FIFO with RRB
//! and data overrun, the interrupt register (reading it clears all but
//! RI, which follows the FIFO), the status register, the error counters
//! with the CAN fault-confinement rules (a transmit error +8, a
//! successful transmission -1, a receive error +1, a frame received -1),
//! the error warning limit (EWLR, 96 at reset), the error (EI: ES or BS
//! changed), error-passive (EPI: passive entered, or left for active) and
//! bus error (BEI) interrupts, the error code capture (ECC) and
//! arbitration lost capture (ALC), each locked until read, and bus-off
//! (transmit counter past 255: reset mode, TXERR 127, RXERR 0, the
//! transmission dropped).
//!
//! The model is not a bus: its caller (a test, or the simulated card's
//! bus) offers frames with [`Sja1000Model::deliver`] and asks a chip with
//! a pending transmission to make one attempt with
//! [`Sja1000Model::transmit`], naming the [`Fault`] the bus has at that
//! moment (missing acknowledgement, a bus error with a given ECC value,
//! lost arbitration) and whether another node acknowledges. What it does
//! not model: bit timing, the error counters' bus-off recovery sequence
//! in hardware (128 x 11 recessive bits; the driver restarts from reset
//! mode and clears the counters, as mainline's does), sleep beyond the
//! wake-up interrupt, the RX message counter and the basic-CAN mode.

use super::candev::{cc_dlc, ctrlmode::CC_LEN8_DLC};
use super::frame::CanFrame;
use super::sim_bus::{Attempt, BusNode};
use super::sja1000::{cmd, decode_cc, encode_dlc, irq, mode, reg, status, HwFilter, Regs};

/// Receive FIFO size in bytes (datasheet: 64-byte RX FIFO).
pub const FIFO_BYTES: usize = 64;
/// Most frames the FIFO can hold (3-byte standard frames without data).
const FIFO_FRAMES: usize = FIFO_BYTES / 3;
/// Error warning limit after a hardware reset (EWLR).
pub const EWL_DEFAULT: u8 = 96;

/// ECC values for the faults the model injects: error type in bits 7..6,
/// direction in bit 5 (set: during reception), segment in bits 4..0 (the
/// `CAN_ERR_PROT_LOC_*` codes).
pub mod ecc {
    /// Bit error.
    pub const BIT: u8 = 0x00;
    /// Form error.
    pub const FORM: u8 = 0x40;
    /// Stuff error.
    pub const STUFF: u8 = 0x80;
    /// Other error type (the acknowledgement error is one).
    pub const OTHER: u8 = 0xC0;
    /// The error happened during reception.
    pub const RX: u8 = 0x20;
    /// Segment: data field.
    pub const SEG_DATA: u8 = 0x0A;
    /// Segment: acknowledge slot.
    pub const SEG_ACK: u8 = 0x19;
    /// A missing acknowledgement: other error, transmitting, ACK slot.
    pub const NO_ACK: u8 = OTHER | SEG_ACK;
    /// A bit error in the data field while transmitting (a bus the
    /// transceiver cannot drive, e.g. stuck dominant or shorted).
    pub const TX_BIT_DATA: u8 = BIT | SEG_DATA;
}

/// What the bus does to one transmission attempt.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Fault {
    /// Nothing: the frame goes out if some node acknowledges it.
    #[default]
    None,
    /// No node acknowledges (as when the chip is alone on the bus).
    NoAck,
    /// The attempt ends in a bus error whose error code capture reads
    /// `ecc` (see [`ecc`]; direction bit clear: while transmitting).
    BusError {
        /// The ECC value captured.
        ecc: u8,
    },
    /// The chip loses arbitration at bit `bit` (0..31, ALC) on the first
    /// attempt of each frame, and retries.
    ArbitrationLost {
        /// The bit position ALC reports.
        bit: u8,
    },
}

/// What one transmission attempt came to: `Idle` (nothing to send, or
/// not allowed to: reset mode, listen-only), `Sent` (the frame is on the
/// bus), `Failed` (error or arbitration lost; the chip retries unless
/// single shot was asked for or it went bus-off).
pub type TxAttempt = Attempt<CanFrame>;

/// The 64-byte receive FIFO: frame images, oldest first.
#[derive(Clone, Copy, Debug)]
pub struct Fifo {
    imgs: [[u8; 13]; FIFO_FRAMES],
    head: usize,
    len: usize,
}

impl Default for Fifo {
    fn default() -> Self {
        Fifo {
            imgs: [[0; 13]; FIFO_FRAMES],
            head: 0,
            len: 0,
        }
    }
}

impl Fifo {
    /// Frames held.
    pub fn len(&self) -> usize {
        self.len
    }
    /// No frame held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// The oldest frame's image.
    pub fn front(&self) -> Option<&[u8; 13]> {
        (self.len > 0).then(|| &self.imgs[self.head])
    }
    fn pop_front(&mut self) {
        if self.len > 0 {
            self.head = (self.head + 1) % FIFO_FRAMES;
            self.len -= 1;
        }
    }
    /// Bytes used.
    fn used(&self) -> usize {
        (0..self.len)
            .map(|i| fifo_bytes(&self.imgs[(self.head + i) % FIFO_FRAMES]))
            .sum()
    }
    /// Appends `img` if it fits; returns whether it did.
    fn push_back(&mut self, img: [u8; 13]) -> bool {
        if self.len == FIFO_FRAMES || self.used() + fifo_bytes(&img) > FIFO_BYTES {
            return false;
        }
        self.imgs[(self.head + self.len) % FIFO_FRAMES] = img;
        self.len += 1;
        true
    }
}

/// Bytes a frame takes in the 64-byte FIFO.
fn fifo_bytes(img: &[u8; 13]) -> usize {
    let dlc = usize::from(img[0] & 0x0F).min(8);
    let rtr = img[0] & 0x40 != 0;
    (if img[0] & 0x80 != 0 { 5 } else { 3 }) + if rtr { 0 } else { dlc }
}

/// Fault-confinement state, as the interrupts see it.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
enum Confinement {
    #[default]
    Active,
    Passive,
    BusOff,
}

/// One SJA1000.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sja1000Model {
    /// Mode register.
    pub mode: u8,
    /// Interrupt enable register.
    pub ier: u8,
    /// Interrupt register (pending causes; only enabled ones are set).
    pub ir: u8,
    /// Data overrun status.
    pub dos: bool,
    /// Transmission complete status.
    pub tcs: bool,
    /// Bus timing registers.
    pub btr: [u8; 2],
    /// Output control register.
    pub ocr: u8,
    /// Clock divider register.
    pub cdr: u8,
    /// Acceptance code.
    pub acr: [u8; 4],
    /// Acceptance mask.
    pub amr: [u8; 4],
    /// TX buffer image.
    pub tx: [u8; 13],
    /// Receive error counter.
    pub rxerr: u8,
    /// Transmit error counter.
    pub txerr: u8,
    /// Error warning limit.
    pub ewl: u8,
    /// Bus-off.
    pub busoff: bool,
    /// A transmission is requested and not finished.
    pub tx_pending: bool,
    /// The pending transmission is single shot (CMR.AT with TR).
    tx_single: bool,
    /// The pending transmission was requested with SRR: the chip
    /// receives its own frame when it goes out.
    tx_self: bool,
    /// The pending frame has already lost arbitration once
    /// ([`Fault::ArbitrationLost`]).
    tx_lost_once: bool,
    /// Error code capture; `ecc_locked` until read.
    pub ecc: u8,
    ecc_locked: bool,
    /// Arbitration lost capture; `alc_locked` until read.
    pub alc: u8,
    alc_locked: bool,
    conf: Confinement,
    /// The receive FIFO.
    pub fifo: Fifo,
    /// Frames the chip put on the bus.
    pub sent: u64,
    /// The last frame it put on the bus (a DLC of 9..15 in `len8_dlc`,
    /// as frames on the bus are given to [`Self::deliver`]).
    pub last_sent: Option<CanFrame>,
    /// Transmission attempts that failed (errors and lost arbitration).
    pub tx_failed: u64,
    /// Every register access, for counting.
    pub accesses: usize,
    /// No chip at this address: reads give 0xFF, writes vanish.
    pub absent: bool,
}

impl Sja1000Model {
    /// A chip after a hardware reset: reset mode.
    pub fn new() -> Self {
        Sja1000Model {
            mode: mode::RM,
            ewl: EWL_DEFAULT,
            ..Default::default()
        }
    }

    fn in_reset(&self) -> bool {
        self.mode & mode::RM != 0
    }

    /// Whether this chip acknowledges frames on the bus: operating mode,
    /// not listen-only.
    pub fn acks(&self) -> bool {
        !self.absent && !self.in_reset() && self.mode & mode::LOM == 0
    }

    /// The acceptance filter programmed.
    pub fn filter(&self) -> HwFilter {
        HwFilter {
            single: self.mode & mode::AFM != 0,
            acr: self.acr,
            amr: self.amr,
        }
    }

    fn raise(&mut self, bit: u8) {
        if self.ier & bit != 0 {
            self.ir |= bit;
        }
    }

    /// A frame from the bus (a data length code of 9..15 in `len8_dlc`
    /// with `len` 8, as [`TxAttempt::Sent`] gives it). Returns whether it
    /// reached the FIFO. A frame received without error decrements the
    /// receive error counter (a counter above 127 drops back to 119),
    /// whether or not the acceptance filter takes it.
    pub fn deliver(&mut self, f: &CanFrame) -> bool {
        if self.absent || self.in_reset() {
            return false;
        }
        self.rx_ok();
        self.store(f)
    }

    /// Puts `f` into the receive FIFO if the acceptance filter takes it
    /// and it fits (else data overrun); RI.
    fn store(&mut self, f: &CanFrame) -> bool {
        if !self.filter().accepts(f) {
            return false;
        }
        let Some((img, _)) = encode_dlc(f, cc_dlc(f, CC_LEN8_DLC)) else {
            return false;
        };
        if !self.fifo.push_back(img) {
            if !self.dos {
                self.dos = true;
                self.raise(irq::DOI);
            }
            return false;
        }
        self.raise(irq::RI);
        true
    }

    fn rx_ok(&mut self) {
        if self.mode & mode::LOM != 0 {
            // Listen-only: the error counters stand still.
            return;
        }
        self.counters(|m| {
            m.rxerr = if m.rxerr > 127 {
                119
            } else {
                m.rxerr.saturating_sub(1)
            }
        });
    }

    /// A receive error with capture `ecc_val` (direction bit forced to
    /// RX): the receive counter +1, BEI.
    pub fn rx_error(&mut self, ecc_val: u8) {
        if self.absent || self.in_reset() || self.mode & mode::LOM != 0 {
            return;
        }
        self.bus_error(ecc_val | ecc::RX);
        self.counters(|m| m.rxerr = m.rxerr.saturating_add(1));
    }

    /// Captures a bus error (if the capture is free) and raises BEI.
    fn bus_error(&mut self, ecc_val: u8) {
        if !self.ecc_locked {
            self.ecc = ecc_val;
            self.ecc_locked = true;
            self.raise(irq::BEI);
        }
    }

    /// Sets the error counters as bus errors would, raising EI/EPI like
    /// the chip; `busoff` enters bus-off (reset mode, counters as the
    /// chip sets them).
    pub fn set_errors(&mut self, rxerr: u8, txerr: u8, busoff: bool) {
        if busoff {
            self.enter_bus_off();
            return;
        }
        self.counters(|m| {
            m.rxerr = rxerr;
            m.txerr = txerr;
        });
    }

    fn es(&self) -> bool {
        self.rxerr >= self.ewl || self.txerr >= self.ewl
    }

    fn enter_bus_off(&mut self) {
        self.busoff = true;
        self.txerr = 127;
        self.rxerr = 0;
        self.mode |= mode::RM;
        self.tx_pending = false;
        // BS set (ES may change too): one EI either way.
        self.raise(irq::EI);
        self.conf = Confinement::BusOff;
    }

    /// Re-evaluates ES and the passive state after a counter change and
    /// raises EI/EPI for what changed.
    fn update_confinement(&mut self) {
        if self.busoff {
            return;
        }
        let passive = self.rxerr > 127 || self.txerr > 127;
        let next = if passive {
            Confinement::Passive
        } else {
            Confinement::Active
        };
        if next != self.conf {
            // Entering passive, or leaving it for active (not for
            // bus-off: that is EI's).
            self.raise(irq::EPI);
            self.conf = next;
        }
    }

    /// Updates counters by `f` and raises EI when ES changed.
    fn counters(&mut self, f: impl FnOnce(&mut Self)) {
        let es = self.es();
        f(self);
        if self.es() != es {
            self.raise(irq::EI);
        }
        self.update_confinement();
    }

    /// One transmission attempt of the pending frame, with `fault` on the
    /// bus and `acked` telling whether another node acknowledges. A
    /// failed attempt counts a transmit error (+8; not for a missing
    /// acknowledgement while error passive, as the CAN rules say) and
    /// raises BEI with the capture; past 255 the chip goes bus-off. Lost
    /// arbitration raises ALI and counts nothing. A single-shot frame is
    /// not retried: TI with TCS clear.
    pub fn transmit(&mut self, fault: Fault, acked: bool) -> TxAttempt {
        if !self.tx_pending || self.absent || self.in_reset() || self.mode & mode::LOM != 0 {
            return TxAttempt::Idle;
        }
        let self_test = self.mode & mode::STM != 0;
        let err = match fault {
            Fault::ArbitrationLost { bit } if !self.tx_lost_once => {
                self.tx_lost_once = true;
                if !self.alc_locked {
                    self.alc = bit & 0x1F;
                    self.alc_locked = true;
                    self.raise(irq::ALI);
                }
                self.tx_failed += 1;
                self.tx_fail_end();
                return TxAttempt::Failed;
            }
            Fault::BusError { ecc } => Some(ecc & !ecc::RX),
            Fault::NoAck if !self_test => Some(ecc::NO_ACK),
            _ if !acked && !self_test => Some(ecc::NO_ACK),
            _ => None,
        };
        if let Some(e) = err {
            self.tx_failed += 1;
            self.bus_error(e);
            let ack_err = e == ecc::NO_ACK;
            if ack_err && self.conf == Confinement::Passive {
                // Fault confinement, rule 3 exception: an error-passive
                // transmitter that sees no ACK does not count it.
            } else if u16::from(self.txerr) + 8 > 255 {
                self.enter_bus_off();
                return TxAttempt::Failed;
            } else {
                self.counters(|m| m.txerr += 8);
            }
            self.tx_fail_end();
            return TxAttempt::Failed;
        }
        let f = decode_cc(&self.tx, CC_LEN8_DLC);
        self.sent += 1;
        self.last_sent = Some(f);
        self.tx_pending = false;
        self.tcs = true;
        self.counters(|m| m.txerr = m.txerr.saturating_sub(1));
        self.raise(irq::TI);
        if self.tx_self {
            // Self reception (SRR): the chip's own frame, through its
            // acceptance filter, into its FIFO.
            self.store(&f);
        }
        TxAttempt::Sent(f)
    }

    /// After a failed attempt: a single-shot frame is given up (TI, TCS
    /// clear); others stay pending.
    fn tx_fail_end(&mut self) {
        if self.tx_single {
            self.tx_pending = false;
            self.tcs = false;
            self.raise(irq::TI);
        }
    }

    fn sr(&self) -> u8 {
        let mut sr = 0;
        if !self.tx_pending {
            sr |= status::TBS;
        }
        if !self.fifo.is_empty() {
            sr |= status::RBS;
        }
        if self.dos {
            sr |= status::DOS;
        }
        if self.tcs {
            sr |= status::TCS;
        }
        if self.tx_pending && !self.in_reset() {
            sr |= status::TS;
        }
        if self.es() || self.busoff {
            sr |= status::ES;
        }
        if self.busoff {
            sr |= status::BS;
        }
        sr
    }

    /// Whether the interrupt line is asserted.
    pub fn irq_pending(&self) -> bool {
        self.ir & self.ier != 0
    }
}

impl Regs for Sja1000Model {
    fn read(&mut self, r: u8) -> u8 {
        self.accesses += 1;
        if self.absent {
            return 0xFF;
        }
        match r {
            reg::MOD => self.mode,
            reg::SR => self.sr(),
            reg::IR => {
                let v = self.ir;
                // Reading clears everything but RI, which stays while the
                // FIFO holds frames.
                self.ir = if self.fifo.is_empty() { 0 } else { v & irq::RI };
                v
            }
            reg::IER => self.ier,
            reg::BTR0 => self.btr[0],
            reg::BTR1 => self.btr[1],
            reg::OCR => self.ocr,
            reg::ALC => {
                self.alc_locked = false;
                self.alc
            }
            reg::ECC => {
                self.ecc_locked = false;
                self.ecc
            }
            reg::EWLR => self.ewl,
            reg::RXERR => self.rxerr,
            reg::TXERR => self.txerr,
            reg::CDR => self.cdr,
            0x10..=0x13 if self.in_reset() => self.acr[usize::from(r - 0x10)],
            0x14..=0x17 if self.in_reset() => self.amr[usize::from(r - 0x14)],
            0x10..=0x1C => self
                .fifo
                .front()
                .map_or(0, |img| img[usize::from(r - 0x10)]),
            _ => 0,
        }
    }

    fn write(&mut self, r: u8, v: u8) {
        self.accesses += 1;
        if self.absent {
            return;
        }
        match r {
            reg::MOD => {
                let sleeping = !self.in_reset() && self.mode & mode::SM != 0;
                // LOM and STM can be changed only in reset mode.
                let keep = if self.in_reset() {
                    0
                } else {
                    self.mode & (mode::LOM | mode::STM)
                };
                let fixed = if self.in_reset() {
                    v
                } else {
                    (v & !(mode::LOM | mode::STM)) | keep
                };
                // Bus-off holds the chip in reset until the host clears
                // the counters (TXERR written in reset mode).
                self.mode = if self.busoff { fixed | mode::RM } else { fixed };
                // Sleep is refused in reset mode and while an interrupt
                // is pending; leaving it raises the wake-up interrupt.
                if v & mode::SM != 0 && (v & mode::RM != 0 || self.irq_pending()) {
                    self.mode &= !mode::SM;
                }
                if sleeping && self.mode & mode::SM == 0 {
                    self.raise(irq::WUI);
                }
            }
            reg::CMR => {
                if v & cmd::RRB != 0 {
                    self.fifo.pop_front();
                    if self.fifo.is_empty() {
                        self.ir &= !irq::RI;
                    }
                }
                if v & cmd::CDO != 0 {
                    self.dos = false;
                }
                if v & cmd::AT != 0 && v & (cmd::TR | cmd::SRR) == 0 && self.tx_pending {
                    // Abort of a pending (not yet started) transmission.
                    self.tx_pending = false;
                    self.tcs = false;
                    self.raise(irq::TI);
                }
                if v & (cmd::TR | cmd::SRR) != 0 && !self.in_reset() && !self.tx_pending {
                    self.tcs = false;
                    self.tx_single = v & cmd::AT != 0;
                    self.tx_lost_once = false;
                    // Self reception request: sent like TR (needing an
                    // acknowledgement unless in self-test mode, STM),
                    // and received by the chip itself.
                    self.tx_self = v & cmd::SRR != 0;
                    self.tx_pending = true;
                }
            }
            reg::IER => self.ier = v,
            reg::BTR0 if self.in_reset() => self.btr[0] = v,
            reg::BTR1 if self.in_reset() => self.btr[1] = v,
            reg::OCR if self.in_reset() => self.ocr = v,
            reg::EWLR if self.in_reset() => self.ewl = v,
            reg::RXERR if self.in_reset() => {
                self.rxerr = v;
            }
            reg::TXERR if self.in_reset() => {
                // Writing the counter in reset mode ends bus-off (the
                // driver's restart, as mainline's sja1000_start does).
                self.txerr = v;
                if self.busoff {
                    self.busoff = false;
                    self.conf = Confinement::Active;
                }
            }
            reg::CDR if self.in_reset() => self.cdr = v,
            0x10..=0x13 if self.in_reset() => self.acr[usize::from(r - 0x10)] = v,
            0x14..=0x17 if self.in_reset() => self.amr[usize::from(r - 0x14)] = v,
            0x10..=0x1C if !self.in_reset() => self.tx[usize::from(r - 0x10)] = v,
            _ => {}
        }
    }
}

/// The chip on a simulated bus ([`super::sim_bus::round`]).
impl BusNode for Sja1000Model {
    type Frame = CanFrame;
    type Fault = Fault;

    fn tx_pending(&self) -> bool {
        self.tx_pending
    }

    fn acks(&self) -> bool {
        Sja1000Model::acks(self)
    }

    fn attempt(&mut self, fault: Fault, acked: bool) -> TxAttempt {
        self.transmit(fault, acked)
    }

    /// False once the FIFO refuses it (full, or reset mode).
    fn deliver(&mut self, f: &CanFrame) -> bool {
        Sja1000Model::deliver(self, f)
    }
}
