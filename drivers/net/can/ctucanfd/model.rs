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
//! the frame counters, data overrun, and YOLO. Fault confinement is not
//! modelled (as in QEMU: FAULT_STATE reads 0, the counters 0).
//!
//! The model is not a bus: the caller (a test) asks a core to send its
//! highest-priority ready buffer with [`CtuModel::transmit`] and offers
//! frames with [`CtuModel::deliver`]. The frame (de)coding here is
//! written from the datasheet's field table on its own, not with
//! [`super::ctucanfd::encode`], so the tests compare two readings of it.

use super::ctucanfd::{reg, DEVICE_ID, YOLO_VALUE};

/// RX buffer size in bytes (QEMU's `CTUCAN_RCV_BUF_LEN`).
pub const RX_BUF_BYTES: usize = 8192;
const RX_WORDS: usize = RX_BUF_BYTES / 4;
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
const FAULT_MASK: u32 = 0x7 << 16;
const TXBHCI: u32 = 1 << 11;

const ST_RXNE: u32 = 1;
const ST_DOR: u32 = 2;
const ST_TXNF: u32 = 4;
const ST_IDLE: u32 = 1 << 7;

const TXT_RDY: u32 = 0x1;
const TXT_TOK: u32 = 0x4;
const TXT_ERR: u32 = 0x6;
const TXT_ABT: u32 = 0x7;
const TXT_ETY: u32 = 0x8;

/// One modelled core.
pub struct CtuModel {
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
    rx: [u32; RX_WORDS],
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
    /// Injected EWL word (limits, FAULT_STATE); 0 as on QEMU.
    ewl: u32,
    /// Injected REC/TEC word.
    rec_tec: u32,
    /// Injected ERR_CAPT.
    err_capt: u32,
    /// Register accesses since creation (reads, writes).
    pub accesses: (u64, u64),
}

impl Default for CtuModel {
    fn default() -> Self {
        Self::new()
    }
}

impl CtuModel {
    /// A core after power-on.
    pub fn new() -> Self {
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
            rx: [0; RX_WORDS],
            rx_tail: 0,
            rx_cnt: 0,
            rx_frame_rem: 0,
            rxfrc: 0,
            rx_fr_ctr: 0,
            tx_fr_ctr: 0,
            ewl: 0,
            rec_tec: 0,
            err_capt: 0,
            accesses: (0, 0),
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
        self.rec_tec = 0;
        if self.ewl & FAULT_MASK != 0 {
            self.ewl = (self.ewl & !FAULT_MASK) | FAULT_ERA;
        }
    }

    /// Fault injection: the EWL word (`ewl_word`: warning limit in bits
    /// 7..0, FAULT_STATE bits 18..16) and the error counters the core
    /// reports from now on. Raises nothing: see [`CtuModel::raise_error`].
    pub fn set_fault(&mut self, ewl_word: u32, rec: u16, tec: u16) {
        self.ewl = ewl_word;
        self.rec_tec = u32::from(rec & 0x1FF) | u32::from(tec & 0x1FF) << 16;
    }

    /// Fault injection: latches the error interrupt causes `ints` (of
    /// EWLI, FCSI, ALI, BEI; masked ones are not latched) and sets
    /// ERR_CAPT to `err_capt`, as the core does on such an event.
    pub fn raise_error(&mut self, ints: u32, err_capt: u32) {
        self.err_capt = err_capt;
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
            reg::RX_MEM_INFO => (RX_WORDS as u32) | (((RX_WORDS - self.rx_cnt) as u32) << 16),
            reg::RX_POINTERS => {
                let head = (self.rx_tail + self.rx_cnt) % RX_WORDS;
                (head as u32 * 4) | ((self.rx_tail as u32 * 4) << 16)
            }
            reg::RX_STATUS => {
                let rxe = u32::from(self.rxfrc == 0);
                let rxf = u32::from(self.rx_cnt == RX_WORDS) << 1;
                rxe | rxf | (self.rxfrc & 0x7FF) << 4
            }
            reg::RX_DATA => self.pop_rx(),
            reg::TX_STATUS => self.tx_status,
            reg::TX_PRIORITY => self.tx_priority,
            reg::RX_FR_CTR => self.rx_fr_ctr,
            reg::TX_FR_CTR => self.tx_fr_ctr,
            reg::YOLO => YOLO_VALUE,
            reg::EWL => self.ewl,
            reg::REC => self.rec_tec,
            reg::ERR_CAPT => self.err_capt,
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
        self.rx_tail = (self.rx_tail + 1) % RX_WORDS;
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

    /// Sends the ready TX buffer of highest priority (the lowest-numbered
    /// one among equals, as QEMU scans), if the core is enabled: marks it
    /// done, counts it and raises TXI and TXBHCI. QEMU does this within
    /// the TX_COMMAND write; a test calls it when it wants the bus to
    /// move.
    pub fn transmit(&mut self) -> Option<BusFrame> {
        if !self.enabled() {
            return None;
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
        let (i, _) = best?;
        let f = Self::from_words(&self.txtb[i]);
        self.tx_fr_ctr = self.tx_fr_ctr.wrapping_add(1);
        self.raise(TXI | TXBHCI);
        self.tx_status = (self.tx_status & !(0xF << (4 * i))) | TXT_TOK << (4 * i);
        self.update_txnf();
        self.update_irq();
        Some(f)
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

    /// Offers a frame from the bus. An enabled core stores it (RXI, and
    /// RXFI when the buffer is full afterwards) or, without room, drops
    /// it with a data overrun (DOR, DOI). Returns whether it was stored.
    pub fn deliver(&mut self, f: &BusFrame) -> bool {
        if !self.enabled() {
            return false;
        }
        let data_words = usize::from(f.len).div_ceil(4);
        let words = 4 + data_words;
        if self.rx_cnt + words > RX_WORDS {
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
            self.rx[(self.rx_tail + self.rx_cnt) % RX_WORDS] = *w;
            self.rx_cnt += 1;
        }
        self.rxfrc += 1;
        self.rx_fr_ctr = self.rx_fr_ctr.wrapping_add(1);
        self.status |= ST_RXNE;
        let mut bits = RXI;
        if self.rx_cnt == RX_WORDS {
            bits |= RXFI;
        }
        self.raise(bits);
        self.update_irq();
        true
    }
}

impl super::ctucanfd::Regs for CtuModel {
    fn read32(&mut self, off: usize) -> u32 {
        CtuModel::read32(self, off)
    }

    fn write32(&mut self, off: usize, val: u32) {
        CtuModel::write32(self, off, val)
    }
}
