// SPDX-License-Identifier: GPL-2.0

//! A register-level model of one CTU CAN FD core, for the host tests of
//! the driver core ([`super::ctucanfd::Chip`]). No allocation, fixed-size
//! state: one model is one core.
//!
//! It does what QEMU's `ctucan_core.c` does (the device the VM tests
//! run on), which is the datasheet's behaviour for what the driver
//! touches, without the bus timing: DEVICE_ID/VERSION, MODE/SETTINGS with
//! the self-clearing soft reset (which empties the RX buffer, sets every
//! TX buffer empty, clears the interrupt enable and mask, leaves FDE set),
//! COMMAND (RRB, CDO, the frame counter resets), the interrupt status,
//! enable and mask registers (a masked cause is never latched; RBNEI is
//! raised again at every register write while a frame is buffered), the
//! bit-timing registers (stored; QEMU ignores them), four TX buffers with
//! the TX_COMMAND state changes and the priority the core sends by, the
//! RX buffer as a ring of words with RX_DATA popping one word per read,
//! the frame counters, data overrun, and YOLO.
//!
//! Beyond QEMU (whose core has no fault confinement: FAULT_STATE and the
//! counters read 0 there), fault confinement as the CTU CAN FD datasheet
//! describes it: the 9-bit error counters REC and TEC (a failed
//! transmission +8, a missing acknowledgement while error passive not
//! counted, a frame sent -1, a frame received -1 or from above 127 back
//! to 119), the error warning limit EWL (reset value 96) and error-passive
//! limit ERP (128) in the EWL word, FAULT_STATE (ERA, ERP, BOF) from
//! them, bus-off when TEC passes 255. Interrupts: EWLI when a counter
//! crosses the warning limit (either way, as the SJA1000's EI), FCSI at
//! each fault confinement state change, BEI at each bus error with its
//! type and position in ERR_CAPT, ALI with the bit in ALC, DOI as before;
//! the retransmit counter (RETR_CTR) and the retransmit limit (RTRLE,
//! RTRTH: a frame that fails more than RTRTH times goes to TX failed).
//! Bus-off moves every ready TX buffer to TX failed and takes the core
//! off the bus (it sends, receives and acknowledges nothing) until a soft
//! reset (the driver's restart) or an ERCRST command (here at once: the
//! model has no bus time for the 128 recessive sequences).
//!
//! The model is not a bus: the caller (a test, or the simulated card
//! `rcan_ctucanfd_sim`) asks a core to make one attempt to send its
//! highest-priority ready buffer under a named [`Fault`] with
//! [`CtuModel::transmit`] and offers frames with [`CtuModel::deliver`]. The frame (de)coding here is
//! written from the datasheet's field table on its own, not with
//! [`super::ctucanfd::encode`], so the tests compare two readings of it.

use super::ctucanfd::{reg, DEVICE_ID, YOLO_VALUE};
use super::sim_bus::{Attempt, BusNode};

/// RX buffer size in bytes (QEMU's `CTUCAN_RCV_BUF_LEN`).
pub const RX_BUF_BYTES: usize = 8192;
/// RX buffer size in words of [`CtuModel`]'s default core (the RX buffer
/// size is a synthesis parameter of the core; RX_MEM_INFO reports it).
pub const RX_WORDS: usize = RX_BUF_BYTES / 4;
/// TX buffers of the modelled core (as QEMU's).
pub const TXT_BUFFERS: usize = 4;
/// Words of one TX buffer.
const TXTB_WORDS: usize = 20;

/// A frame on the bus (QEMU's `qemu_can_frame` plus its flags).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct BusFrame {
    /// 11- or 29-bit identifier.
    pub id: u32,
    /// Extended identifier.
    pub ext: bool,
    /// Remote frame (classic only).
    pub rtr: bool,
    /// CAN FD frame.
    pub fd: bool,
    /// Bit rate switch (FD only).
    pub brs: bool,
    /// Error state indicator (FD only).
    pub esi: bool,
    /// Payload length in bytes.
    pub len: u8,
    /// Payload.
    pub data: [u8; 64],
}

const DLC_LEN: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

fn len_to_dlc(len: u8) -> u32 {
    DLC_LEN.iter().position(|&l| l >= len).unwrap_or(15) as u32
}

/// MODE/SETTINGS bits the model acts on.
const MODE_RST: u32 = 1;
const MODE_FDE: u32 = 1 << 4;
const MODE_ENA: u32 = 1 << 22;

/// INT_STAT bits the model raises.
const RXI: u32 = 1 << 0;
const TXI: u32 = 1 << 1;
const DOI: u32 = 1 << 3;
const RXFI: u32 = 1 << 8;
const RBNEI: u32 = 1 << 10;
const EWLI: u32 = 1 << 2;
const FCSI: u32 = 1 << 4;
const ALI: u32 = 1 << 5;
const BEI: u32 = 1 << 6;

/// FAULT_STATE bits of the EWL word.
const FAULT_ERA: u32 = 1 << 16;
const FAULT_ERP: u32 = 1 << 17;
const FAULT_BOF: u32 = 1 << 18;
const TXBHCI: u32 = 1 << 11;

/// MODE bits of the transmitter.
const MODE_BMM: u32 = 1 << 1;
const MODE_STM: u32 = 1 << 2;
const MODE_RTRLE: u32 = 1 << 16;
const RTRTH_SHIFT: u32 = 17;
/// COMMAND ERCRST: error counters reset (leaves bus-off).
const CMD_ERCRST: u32 = 1 << 4;

/// ERR_CAPT's ERR_TYPE (bits 7..5): the kind of a bus error.
pub mod err_type {
    /// Bit error.
    pub const BIT: u8 = 0;
    /// CRC error.
    pub const CRC: u8 = 1;
    /// Form error.
    pub const FORM: u8 = 2;
    /// Acknowledgement error.
    pub const ACK: u8 = 3;
    /// Stuff error.
    pub const STUFF: u8 = 4;
}

/// ERR_CAPT's ERR_POS (bits 4..0): where in the frame a bus error was.
pub mod err_pos {
    /// Start of frame.
    pub const SOF: u8 = 0;
    /// Arbitration field.
    pub const ARB: u8 = 1;
    /// Control field.
    pub const CTRL: u8 = 2;
    /// Data field.
    pub const DATA: u8 = 3;
    /// CRC field.
    pub const CRC: u8 = 4;
    /// Acknowledgement field.
    pub const ACK: u8 = 5;
    /// End of frame.
    pub const EOF: u8 = 6;
}

/// The ERR_CAPT byte of a bus error of type `ty` ([`err_type`]) at
/// position `pos` ([`err_pos`]).
pub const fn err_capt(ty: u8, pos: u8) -> u8 {
    (ty & 0x7) << 5 | (pos & 0x1F)
}

/// ALC_ID_FIELD of an arbitration lost in the base identifier.
const ALC_BASE_ID: u32 = 1;

/// What happens on the bus during one transmission attempt
/// ([`CtuModel::transmit`]).
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Fault {
    /// Nothing: the frame goes out if some node acknowledges it.
    #[default]
    None,
    /// No node acknowledges (as when the core is alone on the bus).
    NoAck,
    /// The attempt ends in a bus error whose ERR_CAPT byte is `capt`
    /// (see [`err_capt`]).
    BusError {
        /// ERR_TYPE and ERR_POS.
        capt: u8,
    },
    /// The core loses arbitration at bit `bit` (0..31, ALC_BIT) of the
    /// base identifier on the first attempt of each frame, and retries.
    ArbitrationLost {
        /// The bit position ALC_BIT reports.
        bit: u8,
    },
}

/// What one transmission attempt came to: `Idle` (nothing to send, or
/// not allowed to: disabled, bus monitoring, bus-off), `Sent` (the frame
/// is on the bus), `Failed` (bus error or arbitration lost; the core
/// retries unless the retransmit limit is reached or it went bus-off).
pub type TxAttempt = Attempt<BusFrame>;

/// Fault confinement state (FAULT_STATE).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Confinement {
    /// Error active (ERA).
    Active,
    /// Error passive (ERP).
    Passive,
    /// Bus-off (BOF): off the bus until a reset or ERCRST.
    BusOff,
}

const ST_RXNE: u32 = 1;
const ST_DOR: u32 = 2;
const ST_TXNF: u32 = 4;
const ST_IDLE: u32 = 1 << 7;

const TXT_RDY: u32 = 0x1;
const TXT_TOK: u32 = 0x4;
const TXT_ERR: u32 = 0x6;
const TXT_ABT: u32 = 0x7;
const TXT_ETY: u32 = 0x8;

/// One modelled core with an RX buffer of `RXW` words (a synthesis
/// parameter of the core; [`RX_WORDS`] by default, as QEMU's).
pub struct CtuModel<const RXW: usize = RX_WORDS> {
    mode: u32,
    status: u32,
    int_stat: u32,
    int_ena: u32,
    int_mask: u32,
    btr: u32,
    btr_fd: u32,
    tx_status: u32,
    tx_priority: u32,
    txtb: [[u32; TXTB_WORDS]; TXT_BUFFERS],
    rx: [u32; RXW],
    /// Word index of the next word to read.
    rx_tail: usize,
    /// Words buffered.
    rx_cnt: usize,
    /// Words left of the frame being read (0: at a frame start).
    rx_frame_rem: usize,
    /// Frames buffered (RXFRC).
    rxfrc: u32,
    rx_fr_ctr: u32,
    tx_fr_ctr: u32,
    /// Error warning limit (EWL bits 7..0).
    ewl_limit: u8,
    /// Error passive limit (EWL bits 15..8).
    erp_limit: u8,
    /// Receive and transmit error counters (9 bits each).
    rec: u16,
    tec: u16,
    /// Fault confinement state.
    conf: Confinement,
    /// An EWL word injected by [`CtuModel::set_fault`], read instead of
    /// the modelled one until the next reset.
    ewl_pinned: Option<u32>,
    /// ERR_CAPT (7..0, the last bus error) and ALC (23..16).
    err_capt: u32,
    /// Retransmit counter of the frame being sent.
    retr: u32,
    /// Which TX buffers' frames have lost arbitration once
    /// ([`Fault::ArbitrationLost`]).
    lost_once: [bool; TXT_BUFFERS],
    /// Register accesses since creation (reads, writes).
    pub accesses: (u64, u64),
    /// Frames sent and transmission attempts failed since creation.
    pub sent: u64,
    /// See `sent`.
    pub tx_failed: u64,
}

impl Default for CtuModel {
    fn default() -> Self {
        Self::new()
    }
}

impl CtuModel {
    /// A core after power-on, with QEMU's RX buffer size.
    pub fn new() -> Self {
        Self::with_rx_words()
    }
}

impl<const RXW: usize> CtuModel<RXW> {
    /// A core after power-on whose RX buffer holds `RXW` words.
    pub fn with_rx_words() -> Self {
        let mut m = CtuModel {
            mode: 0,
            status: 0,
            int_stat: 0,
            int_ena: 0,
            int_mask: 0,
            btr: 0,
            btr_fd: 0,
            tx_status: 0,
            tx_priority: 0,
            txtb: [[0; TXTB_WORDS]; TXT_BUFFERS],
            rx: [0; RXW],
            rx_tail: 0,
            rx_cnt: 0,
            rx_frame_rem: 0,
            rxfrc: 0,
            rx_fr_ctr: 0,
            tx_fr_ctr: 0,
            ewl_limit: 96,
            erp_limit: 128,
            rec: 0,
            tec: 0,
            conf: Confinement::Active,
            ewl_pinned: None,
            err_capt: 0,
            retr: 0,
            lost_once: [false; TXT_BUFFERS],
            accesses: (0, 0),
            sent: 0,
            tx_failed: 0,
        };
        m.hw_reset();
        m
    }

    fn hw_reset(&mut self) {
        self.tx_status = 0;
        for i in 0..TXT_BUFFERS {
            self.tx_status |= TXT_ETY << (4 * i);
        }
        self.status = ST_IDLE | ST_TXNF;
        self.rx_tail = 0;
        self.rx_cnt = 0;
        self.rx_frame_rem = 0;
        self.rxfrc = 0;
        self.mode = MODE_FDE;
        self.int_stat = 0;
        self.int_ena = 0;
        self.int_mask = 0;
        self.rx_fr_ctr = 0;
        self.tx_fr_ctr = 0;
        // Fault confinement starts over: error active, counters 0, the
        // limits at their reset values.
        self.ewl_limit = 96;
        self.erp_limit = 128;
        self.rec = 0;
        self.tec = 0;
        self.conf = Confinement::Active;
        self.ewl_pinned = None;
        self.err_capt = 0;
        self.retr = 0;
        self.lost_once = [false; TXT_BUFFERS];
    }

    /// Fault injection: the EWL word (`ewl_word`: warning limit in bits
    /// 7..0, FAULT_STATE bits 18..16, all 0 as QEMU's core reads it) the
    /// core reports until its next reset, and the error counters. Raises
    /// nothing: see [`CtuModel::raise_error`]. Fault confinement follows
    /// the injected state (bus-off included) from then on.
    pub fn set_fault(&mut self, ewl_word: u32, rec: u16, tec: u16) {
        self.ewl_pinned = Some(ewl_word);
        self.rec = rec & 0x1FF;
        self.tec = tec & 0x1FF;
        self.conf = if ewl_word & FAULT_BOF != 0 {
            Confinement::BusOff
        } else if ewl_word & FAULT_ERP != 0 {
            Confinement::Passive
        } else {
            Confinement::Active
        };
    }

    /// The fault confinement state.
    pub fn confinement(&self) -> Confinement {
        self.conf
    }

    /// (REC, TEC).
    pub fn error_counters(&self) -> (u16, u16) {
        (self.rec, self.tec)
    }

    /// Whether this core acknowledges frames on the bus: enabled, not
    /// bus-off, not in bus monitoring (listen-only) mode.
    pub fn acks(&self) -> bool {
        self.enabled() && self.conf != Confinement::BusOff && self.mode & MODE_BMM == 0
    }

    /// Whether a TX buffer is ready (the core has something to send).
    pub fn tx_pending(&self) -> bool {
        (0..TXT_BUFFERS).any(|i| (self.tx_status >> (4 * i)) & 0xF == TXT_RDY)
    }

    fn warning(&self) -> bool {
        let l = u16::from(self.ewl_limit);
        self.rec >= l || self.tec >= l
    }

    /// Changes the counters with `f` and raises EWLI and FCSI for what
    /// that changed (not out of bus-off: only a reset or ERCRST leaves
    /// it).
    fn counters(&mut self, f: impl FnOnce(&mut Self)) {
        let warn = self.warning();
        f(self);
        self.rec = self.rec.min(0x1FF);
        self.tec = self.tec.min(0x1FF);
        if self.warning() != warn {
            self.raise(EWLI);
        }
        if self.conf == Confinement::BusOff {
            return;
        }
        let next = if self.tec > 255 {
            Confinement::BusOff
        } else if self.rec >= u16::from(self.erp_limit) || self.tec >= u16::from(self.erp_limit) {
            Confinement::Passive
        } else {
            Confinement::Active
        };
        if next != self.conf {
            self.conf = next;
            self.raise(FCSI);
            if next == Confinement::BusOff {
                self.enter_bus_off();
            }
        }
    }

    /// Bus-off: every ready TX buffer goes to TX failed (TXBHCI); the
    /// core stays off the bus until a reset or ERCRST.
    fn enter_bus_off(&mut self) {
        let mut changed = false;
        for i in 0..TXT_BUFFERS {
            if (self.tx_status >> (4 * i)) & 0xF == TXT_RDY {
                self.tx_status = (self.tx_status & !(0xF << (4 * i))) | TXT_ERR << (4 * i);
                changed = true;
            }
        }
        self.retr = 0;
        if changed {
            self.raise(TXBHCI);
        }
        self.update_txnf();
    }

    /// The EWL word the core reads: limits and FAULT_STATE.
    fn ewl_word(&self) -> u32 {
        if let Some(w) = self.ewl_pinned {
            return w;
        }
        let fs = match self.conf {
            Confinement::Active => FAULT_ERA,
            Confinement::Passive => FAULT_ERP,
            Confinement::BusOff => FAULT_BOF,
        };
        u32::from(self.ewl_limit) | u32::from(self.erp_limit) << 8 | fs
    }

    /// Fault injection: latches the error interrupt causes `ints` (of
    /// EWLI, FCSI, ALI, BEI; masked ones are not latched) and sets
    /// ERR_CAPT to `err_capt`, as the core does on such an event.
    pub fn raise_error(&mut self, ints: u32, err_capt: u32) {
        self.err_capt = err_capt & 0x00FF_00FF;
        self.retr = (err_capt >> 8) & 0xF;
        self.raise(ints & (EWLI | FCSI | ALI | BEI));
        self.update_irq();
    }

    /// Whether the core is enabled (on the bus).
    pub fn enabled(&self) -> bool {
        self.mode & MODE_ENA != 0
    }

    /// The interrupt output: a latched cause that is enabled.
    pub fn irq_line(&self) -> bool {
        self.int_stat & self.int_ena != 0
    }

    /// BTR and BTR_FD as last written.
    pub fn bit_timing(&self) -> (u32, u32) {
        (self.btr, self.btr_fd)
    }

    /// Frames in the RX buffer.
    pub fn rx_frames(&self) -> u32 {
        self.rxfrc
    }

    fn raise(&mut self, bits: u32) {
        self.int_stat |= bits & !self.int_mask;
    }

    fn update_irq(&mut self) {
        if self.rxfrc != 0 {
            self.raise(RBNEI);
        }
    }

    fn update_txnf(&mut self) {
        let any_empty = (0..TXT_BUFFERS).any(|i| (self.tx_status >> (4 * i)) & 0xF == TXT_ETY);
        if any_empty {
            self.status |= ST_TXNF;
        } else {
            self.status &= !ST_TXNF;
        }
    }

    /// A 32-bit read at byte offset `off` of the core.
    pub fn read32(&mut self, off: usize) -> u32 {
        self.accesses.0 += 1;
        match off & !3 {
            reg::DEVICE_ID => u32::from(DEVICE_ID) | 2 << 16 | 2 << 24,
            reg::MODE => self.mode,
            reg::STATUS => self.status,
            reg::INT_STAT => self.int_stat,
            reg::INT_ENA_SET | reg::INT_ENA_CLR => self.int_ena,
            reg::INT_MASK_SET | reg::INT_MASK_CLR => self.int_mask,
            reg::BTR => self.btr,
            reg::BTR_FD => self.btr_fd,
            reg::RX_MEM_INFO => (RXW as u32) | (((RXW - self.rx_cnt) as u32) << 16),
            reg::RX_POINTERS => {
                let head = (self.rx_tail + self.rx_cnt) % RXW;
                (head as u32 * 4) | ((self.rx_tail as u32 * 4) << 16)
            }
            reg::RX_STATUS => {
                let rxe = u32::from(self.rxfrc == 0);
                let rxf = u32::from(self.rx_cnt == RXW) << 1;
                rxe | rxf | (self.rxfrc & 0x7FF) << 4
            }
            reg::RX_DATA => self.pop_rx(),
            reg::TX_STATUS => self.tx_status,
            reg::TX_PRIORITY => self.tx_priority,
            reg::RX_FR_CTR => self.rx_fr_ctr,
            reg::TX_FR_CTR => self.tx_fr_ctr,
            reg::YOLO => YOLO_VALUE,
            reg::EWL => self.ewl_word(),
            reg::REC => u32::from(self.rec) | u32::from(self.tec) << 16,
            reg::ERR_CAPT => self.err_capt | (self.retr & 0xF) << 8,
            _ => 0,
        }
    }

    fn pop_rx(&mut self) -> u32 {
        if self.rx_cnt == 0 {
            return 0;
        }
        let v = self.rx[self.rx_tail];
        if self.rx_frame_rem == 0 {
            self.rx_frame_rem = ((v >> 11) & 0x1F) as usize + 1;
        }
        self.rx_cnt -= 1;
        self.rx_frame_rem -= 1;
        if self.rx_frame_rem == 0 {
            self.rxfrc -= 1;
            if self.rxfrc == 0 {
                self.status &= !ST_RXNE;
            }
        }
        self.rx_tail = (self.rx_tail + 1) % RXW;
        v
    }

    /// A 32-bit write at byte offset `off` of the core.
    pub fn write32(&mut self, off: usize, val: u32) {
        self.accesses.1 += 1;
        if off >= reg::TXTB1 {
            let buf = (off - reg::TXTB1) / reg::TXTB_SPAN;
            let w = (off - reg::TXTB1) % reg::TXTB_SPAN / 4;
            if buf < TXT_BUFFERS && w < TXTB_WORDS {
                self.txtb[buf][w] = val;
            }
            return;
        }
        match off & !3 {
            reg::MODE => {
                self.mode = val;
                if val & MODE_RST != 0 {
                    self.hw_reset();
                }
            }
            reg::COMMAND => {
                if val & (1 << 3) != 0 {
                    self.status &= !ST_DOR;
                }
                if val & (1 << 2) != 0 {
                    self.rx_tail = 0;
                    self.rx_cnt = 0;
                    self.rx_frame_rem = 0;
                    self.rxfrc = 0;
                    self.status &= !ST_RXNE;
                }
                if val & (1 << 5) != 0 {
                    self.rx_fr_ctr = 0;
                }
                if val & (1 << 6) != 0 {
                    self.tx_fr_ctr = 0;
                }
                if val & CMD_ERCRST != 0 && self.conf == Confinement::BusOff {
                    // Reintegration (128 x 11 recessive bits) takes no
                    // time here.
                    self.rec = 0;
                    self.tec = 0;
                    self.conf = Confinement::Active;
                    self.raise(FCSI | EWLI);
                }
            }
            reg::EWL => {
                self.ewl_limit = val as u8;
                self.erp_limit = (val >> 8) as u8;
            }
            reg::INT_STAT => self.int_stat &= !val,
            reg::INT_ENA_SET => self.int_ena |= val & 0xFFF,
            reg::INT_ENA_CLR => self.int_ena &= !val,
            reg::INT_MASK_SET => self.int_mask |= val & 0xFFF,
            reg::INT_MASK_CLR => self.int_mask &= !val,
            reg::BTR => self.btr = val,
            reg::BTR_FD => self.btr_fd = val,
            reg::TX_COMMAND if self.enabled() => {
                for i in 0..TXT_BUFFERS {
                    if val & (1 << (8 + i)) == 0 {
                        continue;
                    }
                    let mut st = (self.tx_status >> (4 * i)) & 0xF;
                    if val & 4 != 0 && st == TXT_RDY {
                        st = TXT_ABT;
                    }
                    if val & 2 != 0 && matches!(st, TXT_TOK | TXT_ERR | TXT_ABT | TXT_ETY) {
                        st = TXT_RDY;
                        self.lost_once[i] = false;
                    }
                    if val & 1 != 0 && matches!(st, TXT_TOK | TXT_ERR | TXT_ABT) {
                        st = TXT_ETY;
                    }
                    self.tx_status = (self.tx_status & !(0xF << (4 * i))) | st << (4 * i);
                }
                self.update_txnf();
            }
            reg::TX_PRIORITY => self.tx_priority = val,
            _ => {}
        }
        self.update_irq();
    }

    /// One attempt to send the ready TX buffer of highest priority (the
    /// lowest-numbered one among equals, as QEMU scans) with `fault` on
    /// the bus and `acked` telling whether another node acknowledges
    /// (self-test mode, STM, needs none). Nothing is sent while the core
    /// is disabled, in bus monitoring mode or bus-off.
    ///
    /// * Sent: the buffer goes to TX OK, TX_FR_CTR counts, TXI and TXBHCI,
    ///   TEC -1.
    /// * Bus error (the fault's, or an acknowledgement error without
    ///   acknowledgement): ERR_CAPT captures it, BEI, TEC +8 (a missing
    ///   acknowledgement while error passive counts nothing); past 255
    ///   bus-off. The retransmit counter counts; with RTRLE a frame that
    ///   failed more than RTRTH times goes to TX failed (TXBHCI).
    /// * Arbitration lost (the first attempt of each frame under
    ///   [`Fault::ArbitrationLost`]): ALC captures the bit, ALI; no
    ///   counter moves but the retransmit counter.
    ///
    /// QEMU sends within the TX_COMMAND write; a test (or the simulated
    /// card's bus) calls this when it wants the bus to move.
    pub fn transmit(&mut self, fault: Fault, acked: bool) -> TxAttempt {
        if !self.enabled() || self.conf == Confinement::BusOff || self.mode & MODE_BMM != 0 {
            return TxAttempt::Idle;
        }
        let mut best: Option<(usize, u32)> = None;
        for i in 0..TXT_BUFFERS {
            if (self.tx_status >> (4 * i)) & 0xF != TXT_RDY {
                continue;
            }
            let prio = (self.tx_priority >> (4 * i)) & 0x7;
            if best.map_or(prio > 0, |(_, p)| prio > p) {
                best = Some((i, prio));
            }
        }
        let Some((i, _)) = best else {
            return TxAttempt::Idle;
        };
        let self_test = self.mode & MODE_STM != 0;
        let capt = match fault {
            Fault::ArbitrationLost { bit } if !self.lost_once[i] => {
                self.lost_once[i] = true;
                self.err_capt =
                    (self.err_capt & 0xFF) | (u32::from(bit & 0x1F) | ALC_BASE_ID << 5) << 16;
                self.raise(ALI);
                self.tx_failed += 1;
                self.retry_or_fail(i);
                self.update_irq();
                return TxAttempt::Failed;
            }
            Fault::BusError { capt } => Some(capt),
            Fault::NoAck if !self_test => Some(err_capt(err_type::ACK, err_pos::ACK)),
            _ if !acked && !self_test => Some(err_capt(err_type::ACK, err_pos::ACK)),
            _ => None,
        };
        if let Some(capt) = capt {
            self.tx_failed += 1;
            self.err_capt = (self.err_capt & 0x00FF_0000) | u32::from(capt);
            self.raise(BEI);
            let ack_err = capt == err_capt(err_type::ACK, err_pos::ACK);
            if !(ack_err && self.conf == Confinement::Passive) {
                self.counters(|m| m.tec += 8);
            }
            if self.conf != Confinement::BusOff {
                self.retry_or_fail(i);
            }
            self.update_irq();
            return TxAttempt::Failed;
        }
        let f = Self::from_words(&self.txtb[i]);
        self.tx_fr_ctr = self.tx_fr_ctr.wrapping_add(1);
        self.sent += 1;
        self.retr = 0;
        self.counters(|m| m.tec = m.tec.saturating_sub(1));
        self.raise(TXI | TXBHCI);
        self.tx_status = (self.tx_status & !(0xF << (4 * i))) | TXT_TOK << (4 * i);
        self.update_txnf();
        self.update_irq();
        TxAttempt::Sent(f)
    }

    /// After a failed attempt of buffer `i`: the retransmit counter
    /// counts; past the limit (RTRLE, RTRTH) the buffer goes to TX failed.
    fn retry_or_fail(&mut self, i: usize) {
        let limit = (self.mode >> RTRTH_SHIFT) & 0xF;
        if self.mode & MODE_RTRLE != 0 && self.retr >= limit {
            self.retr = 0;
            self.tx_status = (self.tx_status & !(0xF << (4 * i))) | TXT_ERR << (4 * i);
            self.raise(TXBHCI);
            self.update_txnf();
        } else {
            self.retr = (self.retr + 1).min(0xF);
        }
    }

    fn from_words(w: &[u32; TXTB_WORDS]) -> BusFrame {
        let ffw = w[0];
        let idw = w[1];
        let ext = ffw & (1 << 6) != 0;
        let base = (idw >> 18) & 0x7FF;
        let id = if ext {
            base << 18 | (idw & 0x3FFFF)
        } else {
            base
        };
        let fd = ffw & (1 << 7) != 0;
        let mut data = [0u8; 64];
        for k in 0..16 {
            data[4 * k..4 * k + 4].copy_from_slice(&w[4 + k].to_le_bytes());
        }
        BusFrame {
            id,
            ext,
            rtr: ffw & (1 << 5) != 0,
            fd,
            brs: fd && ffw & (1 << 9) != 0,
            esi: ffw & (1 << 10) != 0,
            // QEMU reads the DLC through the FD table for both kinds.
            len: DLC_LEN[(ffw & 0xF) as usize],
            data,
        }
    }

    /// Offers a frame from the bus. An enabled core that is not bus-off
    /// counts a frame received without error (REC -1, or back to 119
    /// from above 127; not in bus monitoring mode) and stores it (RXI,
    /// and RXFI when the buffer is full afterwards) or, without room,
    /// drops it with a data overrun (DOR, DOI). Returns whether it was
    /// stored.
    pub fn deliver(&mut self, f: &BusFrame) -> bool {
        if !self.enabled() || self.conf == Confinement::BusOff {
            return false;
        }
        if self.mode & MODE_BMM == 0 && self.rec != 0 {
            self.counters(|m| m.rec = if m.rec > 127 { 119 } else { m.rec - 1 });
        }
        let data_words = usize::from(f.len).div_ceil(4);
        let words = 4 + data_words;
        if self.rx_cnt + words > RXW {
            self.status |= ST_DOR;
            self.raise(DOI);
            self.update_irq();
            return false;
        }
        let mut ffw = len_to_dlc(f.len) | ((words as u32 - 1) << 11);
        if f.rtr {
            ffw |= 1 << 5;
        }
        if f.ext {
            ffw |= 1 << 6;
        }
        if f.fd {
            ffw |= 1 << 7;
            if f.brs {
                ffw |= 1 << 9;
            }
        }
        if f.esi {
            ffw |= 1 << 10;
        }
        let idw = if f.ext {
            ((f.id >> 18) & 0x7FF) << 18 | (f.id & 0x3FFFF)
        } else {
            (f.id & 0x7FF) << 18
        };
        let mut img = [0u32; 4 + 16];
        img[0] = ffw;
        img[1] = idw;
        for k in 0..data_words {
            img[4 + k] = u32::from_le_bytes([
                f.data[4 * k],
                f.data[4 * k + 1],
                f.data[4 * k + 2],
                f.data[4 * k + 3],
            ]);
        }
        for w in &img[..words] {
            self.rx[(self.rx_tail + self.rx_cnt) % RXW] = *w;
            self.rx_cnt += 1;
        }
        self.rxfrc += 1;
        self.rx_fr_ctr = self.rx_fr_ctr.wrapping_add(1);
        self.status |= ST_RXNE;
        let mut bits = RXI;
        if self.rx_cnt == RXW {
            bits |= RXFI;
        }
        self.raise(bits);
        self.update_irq();
        true
    }
}

impl<const RXW: usize> super::ctucanfd::Regs for CtuModel<RXW> {
    fn read32(&mut self, off: usize) -> u32 {
        CtuModel::read32(self, off)
    }

    fn write32(&mut self, off: usize, val: u32) {
        CtuModel::write32(self, off, val)
    }
}

/// The core on a simulated bus ([`super::sim_bus::round`]).
impl<const RXW: usize> BusNode for CtuModel<RXW> {
    type Frame = BusFrame;
    type Fault = Fault;

    fn tx_pending(&self) -> bool {
        CtuModel::tx_pending(self)
    }

    fn acks(&self) -> bool {
        CtuModel::acks(self)
    }

    fn attempt(&mut self, fault: Fault, acked: bool) -> TxAttempt {
        self.transmit(fault, acked)
    }

    /// False once the RX buffer refuses it (full, or the core disabled).
    fn deliver(&mut self, f: &BusFrame) -> bool {
        CtuModel::deliver(self, f)
    }
}
