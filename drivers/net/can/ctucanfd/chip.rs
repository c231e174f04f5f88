// SPDX-License-Identifier: GPL-2.0

//! The CTU CAN FD IP core (Czech Technical University's open CAN FD
//! controller; QEMU's `-device ctucan_pci` puts two on one PCI card):
//! register map, the frame <-> TX/RX buffer word encoding for classic and
//! FD frames, bit-timing register packing with the core's limits, status
//! and interrupt decoding, the TX buffer ring, and [`Chip`], the driver's
//! register programming over a front-end's [`Regs`]. Pure logic: `no_std`,
//! no allocation; the kernel driver (`drivers/net/can/ctucanfd/`) and the
//! host tests against [`super::ctucanfd_model`] run the same code.
//!
//! Source of truth: the core's datasheet ("CTU CAN FD IP Core, System
//! Architecture" and its register map), whose generated register headers
//! mainline and QEMU both carry. All registers are 32-bit little-endian
//! words; the 16-bit and 8-bit registers the map names (SETTINGS at 0x06,
//! FAULT_STATE at 0x2E, ...) are halves or bytes of the word at the
//! offset rounded down, and the driver only ever makes 32-bit accesses.

use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK};
use super::bittiming::Bittiming;
use super::candev::{err, error_frame, CanState, CanStats, NetErrStats};
use core::num::NonZeroU32;

use super::frame::{
    can_fd_dlc2len, can_fd_len2dlc, AnyFrame, CanFdFrame, CanFrame, CANFD_BRS, CANFD_ESI,
    CANFD_FDF, CANFD_MAX_DLEN,
};

/// Register offsets (byte addresses of 32-bit words).
pub mod reg {
    /// DEVICE_ID (bits 15..0, reads [`super::DEVICE_ID`]) and VERSION
    /// (minor 23..16, major 31..24).
    pub const DEVICE_ID: usize = 0x00;
    /// MODE (bits 15..0) and SETTINGS (bits 31..16): [`super::mode`].
    pub const MODE: usize = 0x04;
    /// STATUS: [`super::status`].
    pub const STATUS: usize = 0x08;
    /// COMMAND: [`super::command`].
    pub const COMMAND: usize = 0x0C;
    /// Interrupt status; writing 1s clears them ([`super::int`]).
    pub const INT_STAT: usize = 0x10;
    /// Interrupt enable, set by writing 1s (reads the enable mask).
    pub const INT_ENA_SET: usize = 0x14;
    /// Interrupt enable, cleared by writing 1s.
    pub const INT_ENA_CLR: usize = 0x18;
    /// Interrupt mask (a masked cause is not even latched), set by 1s.
    pub const INT_MASK_SET: usize = 0x1C;
    /// Interrupt mask, cleared by 1s.
    pub const INT_MASK_CLR: usize = 0x20;
    /// Nominal bit timing: [`super::btr`].
    pub const BTR: usize = 0x24;
    /// Data bit timing: [`super::btr_fd`].
    pub const BTR_FD: usize = 0x28;
    /// EWL (7..0), ERP (15..8) limits and FAULT_STATE (ERA 16, ERP 17,
    /// BOF 18).
    pub const EWL: usize = 0x2C;
    /// REC (8..0) and TEC (24..16).
    pub const REC: usize = 0x30;
    /// ERR_NORM (15..0) and ERR_FD (31..16) error counters.
    pub const ERR_NORM: usize = 0x34;
    /// Counter preset (writes only).
    pub const CTR_PRES: usize = 0x38;
    /// Filter A mask (identifier bits 28..0).
    pub const FILTER_A_MASK: usize = 0x3C;
    /// FILTER_CONTROL (15..0) and FILTER_STATUS (31..16).
    pub const FILTER_CONTROL: usize = 0x5C;
    /// RX buffer size (12..0) and free space (28..16), in words.
    pub const RX_MEM_INFO: usize = 0x60;
    /// RX buffer write (11..0) and read (27..16) pointers.
    pub const RX_POINTERS: usize = 0x64;
    /// RX_STATUS (RXE 0, RXF 1, RXFRC 14..4) and RX_SETTINGS (RTSOP 16).
    pub const RX_STATUS: usize = 0x68;
    /// Reading pops the next word of the RX buffer.
    pub const RX_DATA: usize = 0x6C;
    /// Four bits of [`super::TxState`] per TX buffer.
    pub const TX_STATUS: usize = 0x70;
    /// TX_COMMAND (15..0, [`super::txcmd`]) and TXTB_INFO (the number
    /// of TX buffers in bits 19..16, on cores of version 2.3 and later).
    pub const TX_COMMAND: usize = 0x74;
    /// Three bits of priority per TX buffer (buffer `i` at bits 4i+2..4i).
    pub const TX_PRIORITY: usize = 0x78;
    /// ERR_CAPT, RETR_CTR, ALC, TS_INFO.
    pub const ERR_CAPT: usize = 0x7C;
    /// Frames received since the counter was cleared.
    pub const RX_FR_CTR: usize = 0x84;
    /// Frames sent since the counter was cleared.
    pub const TX_FR_CTR: usize = 0x88;
    /// A fixed test pattern (0xDEADBEEF).
    pub const YOLO: usize = 0x90;
    /// First word of TX buffer 0; buffer `i` at `TXTB1 + i * TXTB_SPAN`.
    pub const TXTB1: usize = 0x100;
    /// Distance between TX buffers.
    pub const TXTB_SPAN: usize = 0x100;
}

/// What DEVICE_ID's low half reads on every CTU CAN FD core.
pub const DEVICE_ID: u16 = 0xCAFD;
/// What the YOLO register reads.
pub const YOLO_VALUE: u32 = 0xDEAD_BEEF;
/// Bytes of register space one core decodes.
pub const CORE_SPAN: usize = 0x4000;

/// MODE (low half) and SETTINGS (high half) bits.
pub mod mode {
    /// Soft reset (self-clearing).
    pub const RST: u32 = 1 << 0;
    /// Bus monitoring (listen-only).
    pub const BMM: u32 = 1 << 1;
    /// Self-test: transmissions need no acknowledgement.
    pub const STM: u32 = 1 << 2;
    /// Acceptance filters on.
    pub const AFM: u32 = 1 << 3;
    /// CAN FD frames accepted (set after reset).
    pub const FDE: u32 = 1 << 4;
    /// Acknowledge forbidden.
    pub const ACF: u32 = 1 << 7;
    /// Retransmit limit enabled (SETTINGS.RTRLE).
    pub const RTRLE: u32 = 1 << 16;
    /// Retransmit limit (SETTINGS.RTRTH, 4 bits) shift.
    pub const RTRTH_SHIFT: u32 = 17;
    /// Internal loopback: own frames received too.
    pub const ILBP: u32 = 1 << 21;
    /// Core enabled (SETTINGS.ENA): on the bus.
    pub const ENA: u32 = 1 << 22;
    /// Non-ISO CAN FD (Bosch's original CRC without stuff count).
    pub const NISOFD: u32 = 1 << 23;
    /// Protocol exception handling.
    pub const PEX: u32 = 1 << 24;
}

/// STATUS bits.
pub mod status {
    /// The RX buffer holds a frame.
    pub const RXNE: u32 = 1 << 0;
    /// Data overrun: a frame was lost for want of RX buffer space.
    pub const DOR: u32 = 1 << 1;
    /// Some TX buffer is empty.
    pub const TXNF: u32 = 1 << 2;
    /// Error frame being transmitted.
    pub const EFT: u32 = 1 << 3;
    /// Receiving.
    pub const RXS: u32 = 1 << 4;
    /// Transmitting.
    pub const TXS: u32 = 1 << 5;
    /// An error counter reached the warning limit.
    pub const EWL: u32 = 1 << 6;
    /// Bus idle.
    pub const IDLE: u32 = 1 << 7;
}

/// COMMAND bits.
pub mod command {
    /// Release the RX buffer (drop every frame in it).
    pub const RRB: u32 = 1 << 2;
    /// Clear the data overrun flag.
    pub const CDO: u32 = 1 << 3;
    /// Error counters reset (leaves bus-off).
    pub const ERCRST: u32 = 1 << 4;
    /// Clear the RX frame counter.
    pub const RXFCRST: u32 = 1 << 5;
    /// Clear the TX frame counter.
    pub const TXFCRST: u32 = 1 << 6;
}

/// Interrupt causes (INT_STAT and the ENA/MASK registers).
pub mod int {
    /// A frame was received.
    pub const RXI: u32 = 1 << 0;
    /// A frame was sent.
    pub const TXI: u32 = 1 << 1;
    /// Error warning limit reached.
    pub const EWLI: u32 = 1 << 2;
    /// Data overrun.
    pub const DOI: u32 = 1 << 3;
    /// Fault confinement state changed.
    pub const FCSI: u32 = 1 << 4;
    /// Arbitration lost.
    pub const ALI: u32 = 1 << 5;
    /// Bus error.
    pub const BEI: u32 = 1 << 6;
    /// Overload frame.
    pub const OFI: u32 = 1 << 7;
    /// RX buffer full.
    pub const RXFI: u32 = 1 << 8;
    /// Bit rate shifted.
    pub const BSI: u32 = 1 << 9;
    /// RX buffer not empty (level: stays while a frame is in it).
    pub const RBNEI: u32 = 1 << 10;
    /// A TX buffer changed state.
    pub const TXBHCI: u32 = 1 << 11;
    /// Every cause.
    pub const ALL: u32 = 0xFFF;
    /// The error causes the driver decodes into error frames.
    pub const ERRORS: u32 = EWLI | FCSI | ALI | BEI | DOI;
}

/// TX_COMMAND bits.
pub mod txcmd {
    /// Set the selected buffers empty (from done, error or aborted).
    pub const TXCE: u32 = 1 << 0;
    /// Set the selected buffers ready: send them.
    pub const TXCR: u32 = 1 << 1;
    /// Abort the selected buffers.
    pub const TXCA: u32 = 1 << 2;
    /// Selects TX buffer `i` (0-based).
    pub const fn txb(i: usize) -> u32 {
        1 << (8 + i)
    }
}

/// Most TX buffers a core has (8 from version 2.3 on; 4 before, and in
/// QEMU's model).
pub const MAX_TXT_BUFFERS: usize = 8;
/// TX buffers of a core that does not report their number (TXTB_INFO
/// reads 0: cores before version 2.3, QEMU's model).
pub const DEFAULT_TXT_BUFFERS: usize = 4;

/// The number of TX buffers from the TX_COMMAND/TXTB_INFO word.
pub fn txt_buffer_count(tx_command_word: u32) -> usize {
    match ((tx_command_word >> 16) & 0xF) as usize {
        0 => DEFAULT_TXT_BUFFERS,
        n => n.min(MAX_TXT_BUFFERS),
    }
}

/// State of one TX buffer (TX_STATUS nibble).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum TxState {
    /// The buffer does not exist (nibble 0).
    NotExist,
    /// Ready: waiting for the bus.
    Ready,
    /// Being transmitted.
    Transmitting,
    /// Abort requested during transmission.
    AbortPending,
    /// Sent successfully.
    Done,
    /// Failed (retransmit limit reached, or bus-off).
    Error,
    /// Aborted.
    Aborted,
    /// Empty: free for the driver.
    Empty,
    /// A value the datasheet does not define.
    Unknown(u8),
}

impl TxState {
    /// The nibble's meaning.
    pub const fn from_bits(n: u32) -> TxState {
        match n & 0xF {
            0x0 => TxState::NotExist,
            0x1 => TxState::Ready,
            0x2 => TxState::Transmitting,
            0x3 => TxState::AbortPending,
            0x4 => TxState::Done,
            0x6 => TxState::Error,
            0x7 => TxState::Aborted,
            0x8 => TxState::Empty,
            v => TxState::Unknown(v as u8),
        }
    }

    /// The nibble of this state.
    pub const fn bits(self) -> u32 {
        match self {
            TxState::NotExist => 0x0,
            TxState::Ready => 0x1,
            TxState::Transmitting => 0x2,
            TxState::AbortPending => 0x3,
            TxState::Done => 0x4,
            TxState::Error => 0x6,
            TxState::Aborted => 0x7,
            TxState::Empty => 0x8,
            TxState::Unknown(v) => v as u32 & 0xF,
        }
    }

    /// The buffer is finished with its frame: done, failed or aborted.
    pub const fn is_final(self) -> bool {
        matches!(self, TxState::Done | TxState::Error | TxState::Aborted)
    }
}

/// State of TX buffer `i` in the TX_STATUS word `tx_status`.
pub const fn tx_state(tx_status: u32, i: usize) -> TxState {
    TxState::from_bits(tx_status >> (4 * i))
}

// ---------------------------------------------------------------------
// Frame format: the same words in a TX buffer and in the RX buffer.
// ---------------------------------------------------------------------

/// Frame format word (word 0) fields.
pub mod ffw {
    /// Data length code (3..0).
    pub const DLC_MASK: u32 = 0xF;
    /// Remote frame.
    pub const RTR: u32 = 1 << 5;
    /// Extended identifier.
    pub const IDE: u32 = 1 << 6;
    /// CAN FD frame.
    pub const FDF: u32 = 1 << 7;
    /// Bit rate shift (FD only).
    pub const BRS: u32 = 1 << 9;
    /// Error state indicator (FD only; the sender was error passive).
    pub const ESI: u32 = 1 << 10;
    /// RX only: words of the frame after this one (15..11).
    pub const RWCNT_SHIFT: u32 = 11;
    /// RWCNT width mask (after the shift).
    pub const RWCNT_MASK: u32 = 0x1F;
}

/// Identifier word (word 1) fields.
pub mod idw {
    /// Base identifier shift (11 bits at 28..18).
    pub const BASE_SHIFT: u32 = 18;
    /// Identifier extension (17..0).
    pub const EXT_MASK: u32 = 0x3FFFF;
}

/// Words before the data: format, identifier, 64-bit timestamp.
pub const HEADER_WORDS: usize = 4;
/// Most words of one frame (header and 64 data bytes).
pub const FRAME_WORDS: usize = HEADER_WORDS + CANFD_MAX_DLEN / 4;

/// One frame as the words of a TX buffer (or of the RX buffer).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FrameWords {
    /// The words; those from `len` on are zero.
    pub words: [u32; FRAME_WORDS],
    /// Words in use: the header and the data rounded up to words.
    pub len: usize,
}

/// Why a frame cannot go to the core.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum EncodeError {
    /// Error frames (`CAN_ERR_FLAG`) are reports, never sent.
    ErrorFrame,
    /// The payload exceeds the flavour's maximum (8 or 64 bytes).
    TooLong,
}

fn id_word(can_id: u32) -> (u32, u32) {
    if can_id & CAN_EFF_FLAG != 0 {
        let id = can_id & CAN_EFF_MASK;
        (
            ffw::IDE,
            ((id >> 18) << idw::BASE_SHIFT) | (id & idw::EXT_MASK),
        )
    } else {
        (0, (can_id & CAN_SFF_MASK) << idw::BASE_SHIFT)
    }
}

fn put_data(words: &mut [u32; FRAME_WORDS], data: &[u8]) -> usize {
    for (i, chunk) in data.chunks(4).enumerate() {
        let mut b = [0u8; 4];
        b[..chunk.len()].copy_from_slice(chunk);
        words[HEADER_WORDS + i] = u32::from_le_bytes(b);
    }
    HEADER_WORDS + data.len().div_ceil(4)
}

/// Encodes `frame` for a TX buffer (mainline `ctucan_hw_xmit`'s layout):
/// the DLC of the payload length (classic frames: the length itself,
/// 0..8; FD frames: the smallest FD DLC holding it), RTR only for classic
/// remote frames (which carry no data words), FDF with BRS and ESI from
/// the FD flags. The timestamp words stay zero: send at once.
pub fn encode(frame: &AnyFrame) -> Result<FrameWords, EncodeError> {
    let mut words = [0u32; FRAME_WORDS];
    if frame.can_id() & CAN_ERR_FLAG != 0 {
        return Err(EncodeError::ErrorFrame);
    }
    let (ide, id) = id_word(frame.can_id());
    words[1] = id;
    let len = match frame {
        AnyFrame::Classic(f) => {
            let n = usize::from(f.len);
            if n > 8 {
                return Err(EncodeError::TooLong);
            }
            if f.can_id & CAN_RTR_FLAG != 0 {
                words[0] = ide | ffw::RTR | n as u32;
                HEADER_WORDS
            } else {
                words[0] = ide | n as u32;
                put_data(&mut words, &f.data[..n])
            }
        }
        AnyFrame::Fd(f) => {
            let n = usize::from(f.len);
            if n > CANFD_MAX_DLEN {
                return Err(EncodeError::TooLong);
            }
            let dlc = can_fd_len2dlc(f.len);
            let mut w = ide | ffw::FDF | u32::from(dlc);
            if f.flags & CANFD_BRS != 0 {
                w |= ffw::BRS;
            }
            if f.flags & CANFD_ESI != 0 {
                w |= ffw::ESI;
            }
            words[0] = w;
            // The bus carries the DLC's length: pad with the zeros the
            // frame already has beyond `len`.
            put_data(&mut words, &f.data[..usize::from(can_fd_dlc2len(dlc))])
        }
    };
    Ok(FrameWords { words, len })
}

/// Words of the frame whose format word is `w0`, after `w0` (RWCNT).
pub const fn rx_words_after(w0: u32) -> usize {
    ((w0 >> ffw::RWCNT_SHIFT) & ffw::RWCNT_MASK) as usize
}

/// Decodes a received frame from its words (`w[0]` the format word; the
/// caller read `1 + rx_words_after(w[0])` words, or fewer if the buffer
/// is shorter: missing data reads as zero). Classic frames: length
/// min(DLC, 8) (mainline `can_cc_dlc2len`), no data for remote frames;
/// FD frames: the DLC's length, `CANFD_FDF` always, BRS and ESI as
/// received.
pub fn decode(w: &[u32]) -> AnyFrame {
    let word = |i: usize| w.get(i).copied().unwrap_or(0);
    let w0 = word(0);
    let w1 = word(1);
    let can_id = if w0 & ffw::IDE != 0 {
        CAN_EFF_FLAG | ((w1 >> idw::BASE_SHIFT) & CAN_SFF_MASK) << 18 | (w1 & idw::EXT_MASK)
    } else {
        (w1 >> idw::BASE_SHIFT) & CAN_SFF_MASK
    };
    let dlc = (w0 & ffw::DLC_MASK) as u8;
    let avail = w.len().saturating_sub(HEADER_WORDS).min(CANFD_MAX_DLEN / 4);
    let mut data = [0u8; CANFD_MAX_DLEN];
    for i in 0..avail {
        data[4 * i..4 * i + 4].copy_from_slice(&w[HEADER_WORDS + i].to_le_bytes());
    }
    if w0 & ffw::FDF != 0 {
        let len = can_fd_dlc2len(dlc);
        data[usize::from(len)..].fill(0);
        let mut flags = CANFD_FDF;
        if w0 & ffw::BRS != 0 {
            flags |= CANFD_BRS;
        }
        if w0 & ffw::ESI != 0 {
            flags |= CANFD_ESI;
        }
        AnyFrame::Fd(CanFdFrame {
            can_id,
            len,
            flags,
            res0: 0,
            res1: 0,
            data,
        })
    } else {
        let len = dlc.min(8);
        let mut f = CanFrame {
            can_id,
            len,
            ..CanFrame::default()
        };
        if w0 & ffw::RTR != 0 {
            f.can_id |= CAN_RTR_FLAG;
        } else {
            f.data.copy_from_slice(&data[..8]);
            f.data[usize::from(len)..].fill(0);
        }
        AnyFrame::Classic(f)
    }
}

// ---------------------------------------------------------------------
// Bit timing.
// ---------------------------------------------------------------------

/// Nominal and data-phase bit-timing limits, beside the other chips' in
/// the device layer's bit-timing file.
pub use super::bittiming::{
    CTUCANFD_DATA_CONST as DATA_CONST, CTUCANFD_NOMINAL_CONST as NOMINAL_CONST,
};

/// The fields of a BTR or BTR_FD register.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct BtrFields {
    /// Propagation segment, quanta.
    pub prop: u32,
    /// Phase segment 1, quanta.
    pub ph1: u32,
    /// Phase segment 2, quanta.
    pub ph2: u32,
    /// Prescaler (clock periods per quantum).
    pub brp: u32,
    /// Synchronisation jump width, quanta.
    pub sjw: u32,
}

/// Widths of (PROP, PH1, PH2) in BTR and BTR_FD; BRP is 8 bits at 19,
/// SJW 5 bits at 27 in both; PROP at 0, PH1 at 7, PH2 at 13 in both.
const NOMINAL_WIDTHS: (u32, u32, u32) = (7, 6, 6);
const DATA_WIDTHS: (u32, u32, u32) = (6, 5, 5);

fn pack(bt: &Bittiming, (wp, w1, w2): (u32, u32, u32)) -> u32 {
    // The calculation splits TSEG1 evenly between PROP and PH1; PH1 is
    // the narrower field, so the excess goes to PROP (as mainline's
    // `ctucan_set_btr` redistributes).
    let ph1_max = (1 << w1) - 1;
    let tseg1 = bt.prop_seg + bt.phase_seg1;
    let ph1 = bt.phase_seg1.min(ph1_max);
    let prop = tseg1 - ph1;
    let m = |v: u32, w: u32| v & ((1 << w) - 1);
    m(prop, wp)
        | m(ph1, w1) << 7
        | m(bt.phase_seg2, w2) << 13
        | m(bt.brp, 8) << 19
        | m(bt.sjw, 5) << 27
}

fn unpack(v: u32, (wp, w1, w2): (u32, u32, u32)) -> BtrFields {
    let f = |s: u32, w: u32| (v >> s) & ((1 << w) - 1);
    BtrFields {
        prop: f(0, wp),
        ph1: f(7, w1),
        ph2: f(13, w2),
        brp: f(19, 8),
        sjw: f(27, 5),
    }
}

/// The BTR word of the nominal timing `bt` (within [`NOMINAL_CONST`]).
pub fn btr(bt: &Bittiming) -> u32 {
    pack(bt, NOMINAL_WIDTHS)
}

/// The BTR_FD word of the data timing `bt` (within [`DATA_CONST`]).
pub fn btr_fd(bt: &Bittiming) -> u32 {
    pack(bt, DATA_WIDTHS)
}

/// The fields of a BTR word.
pub fn btr_fields(v: u32) -> BtrFields {
    unpack(v, NOMINAL_WIDTHS)
}

/// The fields of a BTR_FD word.
pub fn btr_fd_fields(v: u32) -> BtrFields {
    unpack(v, DATA_WIDTHS)
}

impl BtrFields {
    /// Bit rate these fields give with core clock `clock_hz` (0 if the
    /// prescaler is 0).
    pub fn bitrate(&self, clock_hz: u32) -> u32 {
        let quanta = 1 + self.prop + self.ph1 + self.ph2;
        let div = u64::from(self.brp) * u64::from(quanta);
        if div == 0 {
            0
        } else {
            (u64::from(clock_hz) / div) as u32
        }
    }
}

// ---------------------------------------------------------------------
// Error state.
// ---------------------------------------------------------------------

/// FAULT_STATE bits in the EWL word.
pub mod fault {
    /// Error active.
    pub const ERA: u32 = 1 << 16;
    /// Error passive.
    pub const ERP: u32 = 1 << 17;
    /// Bus-off.
    pub const BOF: u32 = 1 << 18;
}

/// The error state from the EWL word (limits and FAULT_STATE) and the
/// REC/TEC word, as mainline's `ctucan_read_fault_state`: error active
/// splits into active and warning by the counters against the warning
/// limit. `None` if no FAULT_STATE bit is set (QEMU's model does not
/// implement fault confinement and reads 0 there): the caller keeps the
/// state it had.
pub fn fault_state(ewl_word: u32, rec_tec: u32) -> Option<CanState> {
    let (rec, tec) = counters(rec_tec);
    let ewl = (ewl_word & 0xFF) as u16;
    if ewl_word & fault::ERA != 0 {
        Some(if rec < ewl && tec < ewl {
            CanState::ErrorActive
        } else {
            CanState::ErrorWarning
        })
    } else if ewl_word & fault::ERP != 0 {
        Some(CanState::ErrorPassive)
    } else if ewl_word & fault::BOF != 0 {
        Some(CanState::BusOff)
    } else {
        None
    }
}

/// (REC, TEC) from the REC/TEC word.
pub const fn counters(rec_tec: u32) -> (u16, u16) {
    ((rec_tec & 0x1FF) as u16, ((rec_tec >> 16) & 0x1FF) as u16)
}

/// ERR_CAPT fields (the error capture register, with the arbitration
/// lost capture in its upper half). Mainline's `ctucanfd` only logs them:
/// its error frames say "unspecified" for the bus error's type and
/// location and for the bit arbitration was lost at.
pub mod err_capt {
    /// ERR_POS: where in the frame the last bus error happened.
    pub const ERR_POS_MASK: u32 = 0x1F;
    /// ERR_TYPE: the kind of the last bus error (bits 7..5).
    pub const ERR_TYPE_SHIFT: u32 = 5;
    /// ALC_BIT: the bit arbitration was lost at (bits 20..16).
    pub const ALC_BIT_SHIFT: u32 = 16;
    /// ALC_ID_FIELD: the field arbitration was lost in (bits 23..21).
    pub const ALC_ID_FIELD_SHIFT: u32 = 21;
}

/// The registers an error interrupt round is decoded from.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct ErrRegs {
    /// INT_STAT as read: EWLI, FCSI, ALI, BEI are looked at.
    pub isr: u32,
    /// The EWL word (limits and FAULT_STATE).
    pub ewl: u32,
    /// The REC/TEC word.
    pub rec_tec: u32,
    /// ERR_CAPT (error and arbitration-lost capture).
    pub err_capt: u32,
}

/// One error interrupt round (or data overrun), decoded.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct ErrReport {
    /// The error frame for sockets with `CAN_RAW_ERR_FILTER`.
    pub frame: CanFrame,
    /// The core went bus-off: the driver turns the carrier off and
    /// restarts it after `restart-ms` or on request (mainline
    /// `can_bus_off`).
    pub bus_off: bool,
    /// The CAN device statistics this round counted.
    pub stats: CanStats,
    /// The interface error statistics this round counted.
    pub net: NetErrStats,
    /// The state before and after the round, if FCSI or EWLI reported
    /// one (mainline logs "state changes from .. to ..").
    pub state: Option<(CanState, CanState)>,
    /// ERR_CAPT as read (for the log).
    pub err_capt: u32,
}

/// Decodes an error interrupt round as mainline's `ctucan_err_interrupt`
/// does, and moves `state` to the core's fault confinement state. Pure;
/// hardirq context in the driver.
///
/// * EWLI or FCSI: the state from FAULT_STATE and the counters
///   ([`fault_state`]; if FAULT_STATE reads 0, as on QEMU's model, the
///   state is kept and this part adds nothing). Bus-off: one `bus_off`
///   and [`err::BUSOFF`]. Error passive: one `error_passive`,
///   [`err::CRTL`] | [`err::CNT`], data[1] RX passive if REC > 127 else
///   TX passive. Error warning: one `error_warning`, CRTL | CNT, data[1]
///   TX warning if TEC > REC else RX warning. Error active: CRTL | CNT,
///   data[1] [`err::CRTL_ACTIVE`]. CNT puts TEC and REC in data[6] and
///   data[7]. Counted even when the state is the one it was (mainline
///   counts each report; it logs a missed interrupt then).
/// * ALI: one `arbitration_lost`, [`err::LOSTARB`], data[0]
///   [`err::LOSTARB_UNSPEC`].
/// * BEI: one `bus_error` and one interface RX error, [`err::PROT`] |
///   [`err::BUSERROR`], data[2] and data[3] unspecified (0).
pub fn error_report(state: &mut CanState, r: &ErrRegs) -> ErrReport {
    let mut rep = ErrReport {
        frame: error_frame(),
        bus_off: false,
        stats: CanStats::default(),
        net: NetErrStats::default(),
        state: None,
        err_capt: r.err_capt,
    };
    let cf = &mut rep.frame;
    let (rec, tec) = counters(r.rec_tec);
    if r.isr & (int::EWLI | int::FCSI) != 0 {
        if let Some(new) = fault_state(r.ewl, r.rec_tec) {
            rep.state = Some((*state, new));
            *state = new;
            let cnt = |cf: &mut CanFrame| {
                cf.can_id |= err::CRTL | err::CNT;
                cf.data[6] = tec.min(255) as u8;
                cf.data[7] = rec.min(255) as u8;
            };
            match new {
                CanState::BusOff => {
                    rep.stats.bus_off += 1;
                    rep.bus_off = true;
                    cf.can_id |= err::BUSOFF;
                }
                CanState::ErrorPassive => {
                    rep.stats.error_passive += 1;
                    cnt(cf);
                    cf.data[1] = if rec > 127 {
                        err::CRTL_RX_PASSIVE
                    } else {
                        err::CRTL_TX_PASSIVE
                    };
                }
                CanState::ErrorWarning => {
                    rep.stats.error_warning += 1;
                    cnt(cf);
                    cf.data[1] |= if tec > rec {
                        err::CRTL_TX_WARNING
                    } else {
                        err::CRTL_RX_WARNING
                    };
                }
                _ => {
                    cnt(cf);
                    cf.data[1] = err::CRTL_ACTIVE;
                }
            }
        }
    }
    if r.isr & int::ALI != 0 {
        rep.stats.arbitration_lost += 1;
        cf.can_id |= err::LOSTARB;
        cf.data[0] = err::LOSTARB_UNSPEC;
    }
    if r.isr & int::BEI != 0 {
        rep.stats.bus_error += 1;
        rep.net.rx_errors += 1;
        cf.can_id |= err::PROT | err::BUSERROR;
        cf.data[2] = 0;
        cf.data[3] = 0;
    }
    rep
}

/// A data overrun (frames lost for want of RX buffer space), as
/// mainline's `ctucan_rx_poll` reports it: one RX overrun and RX error,
/// an error frame with [`err::CRTL`] and data[1]
/// [`err::CRTL_RX_OVERFLOW`]; the state does not change.
pub fn overrun_report() -> ErrReport {
    let mut frame = error_frame();
    frame.can_id |= err::CRTL;
    frame.data[1] |= err::CRTL_RX_OVERFLOW;
    ErrReport {
        frame,
        bus_off: false,
        stats: CanStats::default(),
        net: NetErrStats {
            rx_errors: 1,
            rx_over_errors: 1,
            tx_errors: 0,
        },
        state: None,
        err_capt: 0,
    }
}

// ---------------------------------------------------------------------
// TX buffer ring.
// ---------------------------------------------------------------------

/// The driver's TX buffers used as a ring so frames leave in the order
/// they were queued (mainline's `txb_head`/`txb_tail`): frame `k` goes to
/// buffer `k % n`, and TX_PRIORITY gives the oldest pending buffer the
/// highest priority (n), the next n-1, and so on down to 1 (the core
/// sends the ready buffer of highest priority; priority 0 would never be
/// chosen by QEMU's model). Only the owner of the device's TX path and
/// its interrupt handler touch it, under the driver's lock.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct TxRing {
    head: u32,
    tail: u32,
    /// Non-zero, so that `%` has no division-by-zero panic path (which
    /// objtool would also flag in the kernel build).
    n: NonZeroU32,
}

impl TxRing {
    /// A ring of `n` buffers (1..=8), all free.
    pub const fn new(n: usize) -> TxRing {
        let n = match NonZeroU32::new(n as u32) {
            Some(n) => n,
            None => NonZeroU32::MIN,
        };
        TxRing {
            head: 0,
            tail: 0,
            n,
        }
    }

    /// Buffers in the ring.
    pub const fn buffers(&self) -> usize {
        self.n.get() as usize
    }

    /// Frames queued and not yet completed.
    pub const fn in_flight(&self) -> usize {
        self.head.wrapping_sub(self.tail) as usize
    }

    /// Whether every buffer holds a frame (stop the queue).
    pub const fn is_full(&self) -> bool {
        self.in_flight() >= self.n.get() as usize
    }

    /// The buffer the next frame goes to, if one is free.
    pub fn next(&self) -> Option<usize> {
        if self.is_full() {
            None
        } else {
            Some((self.head % self.n) as usize)
        }
    }

    /// Records that the next frame was written to [`TxRing::next`].
    pub fn push(&mut self) {
        debug_assert!(!self.is_full());
        self.head = self.head.wrapping_add(1);
    }

    /// The oldest frame's buffer, if any.
    pub fn oldest(&self) -> Option<usize> {
        if self.in_flight() == 0 {
            None
        } else {
            Some((self.tail % self.n) as usize)
        }
    }

    /// Records that the oldest frame completed.
    pub fn pop(&mut self) {
        debug_assert!(self.in_flight() > 0);
        self.tail = self.tail.wrapping_add(1);
    }

    /// The TX_PRIORITY word for the current oldest buffer.
    pub fn priority(&self) -> u32 {
        let n = self.n.get();
        let mut w = 0;
        for k in 0..n {
            let buf = self.tail.wrapping_add(k) % self.n;
            w |= (n - k) << (4 * buf);
        }
        w
    }
}

// ---------------------------------------------------------------------
// The chip.
// ---------------------------------------------------------------------

/// Register access of one core: what a front-end provides. 32-bit
/// little-endian accesses at byte offsets within the core's window.
/// Implementations run in any context the driver calls them from
/// (process, softirq, hardirq) and must not sleep.
pub trait Regs {
    /// Reads the word at `off`.
    fn read32(&mut self, off: usize) -> u32;
    /// Writes the word at `off`.
    fn write32(&mut self, off: usize, val: u32);
    /// Called by [`Chip`] after each operation (start, stop, xmit,
    /// interrupt): a board whose cores share one interrupt line in a way
    /// that lets one core's register access drop another core's request
    /// re-raises it here. QEMU's `ctucan_pci` is such a board: every core
    /// drives the card's line directly, so a core with nothing pending
    /// lowers it at each of its register writes even while the other
    /// core has a cause pending, and that cause is lost (until its core
    /// is touched again). Default: nothing to do.
    fn irq_sync(&mut self) {}
}

/// Why an operation failed.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum CtuError {
    /// DEVICE_ID does not read 0xCAFD: no core at this address.
    NoChip,
    /// Every TX buffer is busy.
    Busy,
    /// The frame cannot be sent ([`EncodeError`]), or an FD frame while
    /// FD is off.
    BadFrame,
}

/// What an interrupt brought.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Event {
    /// A frame was received.
    Rx(AnyFrame),
    /// The oldest queued frame left the ring: sent (`ok`) or failed /
    /// aborted. Comes in queueing order; the driver completes its echo
    /// slot of that buffer.
    TxDone {
        /// The TX buffer it was in.
        buf: usize,
        /// Whether it was sent.
        ok: bool,
    },
    /// An error interrupt round (fault confinement state, arbitration
    /// lost, bus error) or a data overrun, decoded as mainline's
    /// `ctucanfd` reports it ([`error_report`], [`overrun_report`]).
    Error(ErrReport),
}

/// Configuration [`Chip::start`] applies.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub struct Config {
    /// The nominal bit timing.
    pub nominal: Bittiming,
    /// The data bit timing (FD with bit rate switch); all zero: the
    /// nominal one is used for the data phase too.
    pub data: Bittiming,
    /// CAN FD frames on (`CAN_CTRLMODE_FD`).
    pub fd: bool,
    /// Non-ISO CAN FD (`CAN_CTRLMODE_FD_NON_ISO`).
    pub fd_non_iso: bool,
    /// Listen-only (`CAN_CTRLMODE_LISTENONLY`): bus monitoring mode.
    pub listen_only: bool,
    /// Own frames received too (`CAN_CTRLMODE_LOOPBACK`): internal
    /// loopback.
    pub loopback: bool,
    /// Acknowledgement not needed (`CAN_CTRLMODE_PRESUME_ACK`):
    /// self-test mode.
    pub presume_ack: bool,
    /// Single attempt per frame (`CAN_CTRLMODE_ONE_SHOT`): retransmit
    /// limit 0.
    pub one_shot: bool,
    /// Bus errors reported (`CAN_CTRLMODE_BERR_REPORTING`).
    pub berr_reporting: bool,
}

/// The interrupts [`Chip::start`] enables: received, sent, overrun and
/// the state changes; bus errors and arbitration loss only with
/// berr-reporting (as mainline's `ctucan_chip_start`).
pub fn int_enable(cfg: &Config) -> u32 {
    let base = int::RBNEI | int::TXBHCI | int::EWLI | int::FCSI | int::DOI;
    if cfg.berr_reporting {
        base | int::BEI | int::ALI
    } else {
        base
    }
}

/// The MODE/SETTINGS word for `cfg` with the core enabled or not.
pub fn mode_word(cfg: &Config, enable: bool) -> u32 {
    let mut m = 0;
    if cfg.fd {
        m |= mode::FDE;
    }
    if cfg.fd_non_iso {
        m |= mode::NISOFD;
    }
    if cfg.listen_only {
        m |= mode::BMM;
    }
    if cfg.presume_ack {
        m |= mode::STM;
    }
    if cfg.loopback {
        m |= mode::ILBP;
    }
    if cfg.one_shot {
        m |= mode::RTRLE;
    }
    if enable {
        m |= mode::ENA;
    }
    m
}

/// Most frames one [`Chip::irq`] call takes from the RX buffer (the
/// budget keeps the handler bounded; RBNEI stays raised for the rest).
pub const RX_BUDGET: usize = 64;

/// The driver's view of one core.
pub struct Chip<R: Regs> {
    /// Register access.
    pub regs: R,
    /// Configuration of the last [`Chip::start`].
    pub cfg: Config,
    ring: TxRing,
    state: CanState,
}

impl<R: Regs> Chip<R> {
    /// A core behind `regs`; nothing is touched yet.
    pub fn new(regs: R) -> Self {
        Chip {
            regs,
            cfg: Config::default(),
            ring: TxRing::new(DEFAULT_TXT_BUFFERS),
            state: CanState::Stopped,
        }
    }

    /// The error state: [`CanState::Stopped`] before the first start and
    /// after [`Chip::stop`].
    pub fn state(&self) -> CanState {
        self.state
    }

    /// The TX ring (for the driver's echo bookkeeping).
    pub fn ring(&self) -> &TxRing {
        &self.ring
    }

    /// (TX, RX) error counters.
    pub fn berr_counter(&mut self) -> (u16, u16) {
        let (rec, tec) = counters(self.regs.read32(reg::REC));
        (tec, rec)
    }

    /// Checks that a core answers (DEVICE_ID 0xCAFD), resets it and
    /// reads its number of TX buffers. Interrupts stay off.
    pub fn probe(&mut self) -> Result<(), CtuError> {
        if self.regs.read32(reg::DEVICE_ID) & 0xFFFF != u32::from(DEVICE_ID) {
            return Err(CtuError::NoChip);
        }
        self.reset();
        let n = txt_buffer_count(self.regs.read32(reg::TX_COMMAND));
        self.ring = TxRing::new(n);
        Ok(())
    }

    /// Soft reset: the core leaves the bus, forgets its frames and
    /// configuration; interrupts off.
    pub fn reset(&mut self) {
        self.regs.write32(reg::MODE, mode::RST);
        self.regs.write32(reg::INT_ENA_CLR, int::ALL);
        self.ring = TxRing::new(self.ring.buffers());
    }

    /// Configures and enables the core (mainline `ctucan_chip_start`):
    /// reset, bit timing, mode, interrupt mask and enable, TX priorities,
    /// then ENA. The core is error active and the ring empty afterwards.
    pub fn start(&mut self, cfg: &Config) {
        self.cfg = *cfg;
        self.reset();
        self.regs.write32(reg::BTR, btr(&cfg.nominal));
        let data = if cfg.data.brp == 0 {
            &cfg.nominal
        } else {
            &cfg.data
        };
        self.regs.write32(reg::BTR_FD, btr_fd(data));
        self.regs.write32(reg::MODE, mode_word(cfg, false));
        self.regs.write32(reg::COMMAND, command::RRB | command::CDO);
        self.regs.write32(reg::INT_STAT, int::ALL);
        self.regs
            .write32(reg::INT_MASK_SET, !int_enable(cfg) & int::ALL);
        self.regs.write32(reg::INT_MASK_CLR, int_enable(cfg));
        self.regs.write32(reg::INT_ENA_SET, int_enable(cfg));
        self.regs.write32(reg::TX_PRIORITY, self.ring.priority());
        self.regs.write32(reg::MODE, mode_word(cfg, true));
        self.state = CanState::ErrorActive;
        self.regs.irq_sync();
    }

    /// Restarts the core after bus-off with the configuration of the
    /// last [`Chip::start`] (mainline `ctucan_do_set_mode(CAN_MODE_START)`:
    /// reset, then start): error active again, the TX buffers and the
    /// ring empty (the frames in them are the caller's to drop).
    pub fn restart(&mut self) {
        let cfg = self.cfg;
        self.start(&cfg);
    }

    /// Takes the core off the bus: disabled, interrupts off, every TX
    /// buffer aborted. Frames still in the ring are the caller's to drop
    /// (their echo slots).
    pub fn stop(&mut self) {
        self.regs.write32(reg::INT_ENA_CLR, int::ALL);
        self.regs.write32(reg::MODE, mode_word(&self.cfg, false));
        self.reset();
        self.state = CanState::Stopped;
        self.regs.irq_sync();
    }

    /// Writes `frame` into the next free TX buffer and marks it ready.
    /// Returns the buffer (the driver keeps the echo skb under that
    /// index) and whether the ring is full now (stop the queue).
    pub fn xmit(&mut self, frame: &AnyFrame) -> Result<(usize, bool), CtuError> {
        if frame.is_fd() && !self.cfg.fd {
            return Err(CtuError::BadFrame);
        }
        let img = encode(frame).map_err(|_| CtuError::BadFrame)?;
        let buf = self.ring.next().ok_or(CtuError::Busy)?;
        let base = reg::TXTB1 + buf * reg::TXTB_SPAN;
        for (i, w) in img.words[..img.len].iter().enumerate() {
            self.regs.write32(base + 4 * i, *w);
        }
        self.ring.push();
        self.regs
            .write32(reg::TX_COMMAND, txcmd::TXCR | txcmd::txb(buf));
        self.regs.irq_sync();
        Ok((buf, self.ring.is_full()))
    }

    /// Handles one interrupt: reports received frames (at most
    /// [`RX_BUDGET`]), completed TX buffers in queueing order, overruns
    /// and state changes through `ev`, and acknowledges what it handled.
    /// Returns whether the core had raised anything (shared lines).
    /// Hardirq context in the kernel: must not sleep, and does not.
    pub fn irq(&mut self, mut ev: impl FnMut(Event)) -> bool {
        let stat = self.regs.read32(reg::INT_STAT);
        if stat == 0 || stat == u32::MAX {
            // u32::MAX: the device went away.
            return false;
        }
        if stat & (int::RBNEI | int::RXI | int::RXFI) != 0 {
            self.drain_rx(&mut ev);
        }
        if stat & int::DOI != 0 {
            self.regs.write32(reg::COMMAND, command::CDO);
            ev(Event::Error(overrun_report()));
        }
        if stat & (int::EWLI | int::FCSI | int::ALI | int::BEI) != 0 {
            let r = ErrRegs {
                isr: stat,
                ewl: self.regs.read32(reg::EWL),
                rec_tec: self.regs.read32(reg::REC),
                err_capt: self.regs.read32(reg::ERR_CAPT),
            };
            let rep = error_report(&mut self.state, &r);
            // A round that says nothing (FCSI while FAULT_STATE reads
            // 0, as on QEMU's core) makes no error frame.
            if rep.frame.can_id != CAN_ERR_FLAG {
                ev(Event::Error(rep));
            }
        }
        // Acknowledge before looking at the TX buffers: a buffer that
        // completes after the TX_STATUS read raises TXBHCI again.
        self.regs.write32(reg::INT_STAT, stat & !int::RBNEI);
        if stat & (int::TXBHCI | int::TXI) != 0 {
            self.complete_tx(&mut ev);
        }
        // RBNEI is a level: clearing it while frames remain re-raises it.
        self.regs.write32(reg::INT_STAT, stat & int::RBNEI);
        self.regs.irq_sync();
        true
    }

    /// Reads received frames out of the RX buffer.
    fn drain_rx(&mut self, ev: &mut impl FnMut(Event)) {
        for _ in 0..RX_BUDGET {
            let rxs = self.regs.read32(reg::RX_STATUS);
            if (rxs >> 4) & 0x7FF == 0 {
                break;
            }
            let mut w = [0u32; FRAME_WORDS];
            w[0] = self.regs.read32(reg::RX_DATA);
            let n = rx_words_after(w[0]);
            // Every word of the frame is popped, even beyond what a
            // frame can carry, to stay aligned with the next frame.
            for i in 1..=n {
                let v = self.regs.read32(reg::RX_DATA);
                if i < FRAME_WORDS {
                    w[i] = v;
                }
            }
            ev(Event::Rx(decode(&w[..(n + 1).min(FRAME_WORDS)])));
        }
    }

    /// Completes finished TX buffers, oldest first, and rotates the
    /// priorities so that the new oldest goes first.
    fn complete_tx(&mut self, ev: &mut impl FnMut(Event)) {
        let mut changed = false;
        loop {
            let Some(buf) = self.ring.oldest() else { break };
            let st = tx_state(self.regs.read32(reg::TX_STATUS), buf);
            if !st.is_final() {
                break;
            }
            self.regs
                .write32(reg::TX_COMMAND, txcmd::TXCE | txcmd::txb(buf));
            self.ring.pop();
            changed = true;
            ev(Event::TxDone {
                buf,
                ok: st == TxState::Done,
            });
        }
        if changed {
            self.regs.write32(reg::TX_PRIORITY, self.ring.priority());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bittiming;

    fn classic(can_id: u32, data: &[u8]) -> AnyFrame {
        let mut f = CanFrame {
            can_id,
            len: data.len() as u8,
            ..CanFrame::default()
        };
        f.data[..data.len()].copy_from_slice(data);
        AnyFrame::Classic(f)
    }

    fn fd(can_id: u32, flags: u8, data: &[u8]) -> AnyFrame {
        let mut f = CanFdFrame {
            can_id,
            len: data.len() as u8,
            flags: flags | CANFD_FDF,
            ..CanFdFrame::default()
        };
        f.data[..data.len()].copy_from_slice(data);
        AnyFrame::Fd(f)
    }

    #[test]
    fn classic_standard_layout() {
        let img = encode(&classic(0x123, &[1, 2, 3, 4, 5])).unwrap();
        assert_eq!(img.words[0], 5);
        assert_eq!(img.words[1], 0x123 << 18);
        assert_eq!(img.words[4], 0x0403_0201);
        assert_eq!(img.words[5], 0x05);
        assert_eq!(img.len, 6);
    }

    #[test]
    fn extended_remote_layout() {
        let img = encode(&classic(CAN_EFF_FLAG | CAN_RTR_FLAG | 0x1234_5678, &[0; 3])).unwrap();
        assert_eq!(img.words[0], ffw::IDE | ffw::RTR | 3);
        let id = 0x1234_5678 & CAN_EFF_MASK;
        assert_eq!(img.words[1], ((id >> 18) << 18) | (id & 0x3FFFF));
        assert_eq!(img.len, HEADER_WORDS);
    }

    #[test]
    fn fd_layout_pads_to_dlc() {
        let data: [u8; 13] = core::array::from_fn(|i| i as u8 + 1);
        let img = encode(&fd(0x7FF, CANFD_BRS | CANFD_ESI, &data)).unwrap();
        // 13 bytes need DLC 10 (16 bytes).
        assert_eq!(img.words[0], ffw::FDF | ffw::BRS | ffw::ESI | 10);
        assert_eq!(img.len, HEADER_WORDS + 4);
        assert_eq!(img.words[7], 0x0000_000D);
    }

    #[test]
    fn error_frames_and_overlong_refused() {
        assert_eq!(
            encode(&classic(CAN_ERR_FLAG | 4, &[0; 8])),
            Err(EncodeError::ErrorFrame)
        );
        let mut f = CanFrame::default();
        f.len = 9;
        assert_eq!(encode(&AnyFrame::Classic(f)), Err(EncodeError::TooLong));
    }

    fn roundtrip(f: &AnyFrame) -> AnyFrame {
        let img = encode(f).unwrap();
        // The RX side adds RWCNT, as the core does.
        let mut w = img.words;
        w[0] |= ((img.len as u32) - 1) << ffw::RWCNT_SHIFT;
        assert_eq!(rx_words_after(w[0]), img.len - 1);
        decode(&w[..img.len])
    }

    #[test]
    fn roundtrip_every_length() {
        for n in 0..=8usize {
            let data: [u8; 8] = core::array::from_fn(|i| (i * 7 + n) as u8);
            for id in [0, 0x555, CAN_EFF_FLAG | 0x1ABC_DEF0] {
                let f = classic(id, &data[..n]);
                assert_eq!(roundtrip(&f), f);
                let r = classic(id | CAN_RTR_FLAG, &[0; 8][..n]);
                assert_eq!(roundtrip(&r), r);
            }
        }
        for dlc in 0..16u8 {
            let n = usize::from(can_fd_dlc2len(dlc));
            let data: [u8; 64] = core::array::from_fn(|i| (i as u8) ^ 0xA5);
            for flags in [0, CANFD_BRS, CANFD_ESI, CANFD_BRS | CANFD_ESI] {
                let f = fd(CAN_EFF_FLAG | 0x0123_4567, flags, &data[..n]);
                assert_eq!(roundtrip(&f), f);
            }
        }
    }

    #[test]
    fn classic_dlc_above_8_reads_as_8() {
        let w = [
            9 | (5 << ffw::RWCNT_SHIFT),
            0x100 << 18,
            0,
            0,
            0x0403_0201,
            0x0807_0605,
        ];
        match decode(&w) {
            AnyFrame::Classic(f) => {
                assert_eq!(f.len, 8);
                assert_eq!(f.data, [1, 2, 3, 4, 5, 6, 7, 8]);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn btr_packing_matches_fields() {
        let bt = Bittiming {
            prop_seg: 40,
            phase_seg1: 40,
            phase_seg2: 19,
            sjw: 1,
            brp: 2,
            ..Bittiming::default()
        };
        let v = btr(&bt);
        assert_eq!(
            btr_fields(v),
            BtrFields {
                prop: 40,
                ph1: 40,
                ph2: 19,
                brp: 2,
                sjw: 1
            }
        );
        assert_eq!(v, 40 | 40 << 7 | 19 << 13 | 2 << 19 | 1 << 27);
    }

    #[test]
    fn phase1_overflow_moves_to_prop() {
        // TSEG1 190: PH1 holds 63 at most.
        let bt = Bittiming {
            prop_seg: 95,
            phase_seg1: 95,
            phase_seg2: 63,
            sjw: 31,
            brp: 1,
            ..Bittiming::default()
        };
        let f = btr_fields(btr(&bt));
        assert_eq!((f.prop, f.ph1, f.ph2, f.sjw, f.brp), (127, 63, 63, 31, 1));
        let d = Bittiming {
            prop_seg: 47,
            phase_seg1: 47,
            phase_seg2: 31,
            sjw: 31,
            brp: 2,
            ..Bittiming::default()
        };
        let f = btr_fd_fields(btr_fd(&d));
        assert_eq!((f.prop, f.ph1, f.ph2, f.sjw, f.brp), (63, 31, 31, 31, 2));
    }

    /// Every bit rate the calculation finds within the limits packs into
    /// fields that give the same bit rate back (no field overflows).
    #[test]
    fn calculated_timings_fit_the_registers() {
        let clock = 100_000_000;
        for rate in [
            10_000u32, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
        ] {
            let want = Bittiming {
                bitrate: rate,
                ..Bittiming::default()
            };
            let Ok(c) = bittiming::calc(&NOMINAL_CONST, clock, &want) else {
                // Below what brp_max 8 reaches (100 MHz / 8 / 255 quanta).
                assert!(rate < 100_000_000 / 8 / 255);
                continue;
            };
            let f = btr_fields(btr(&c.bt));
            assert_eq!(f.bitrate(clock), c.bt.bitrate, "{rate}");
            assert_eq!(f.prop + f.ph1, c.bt.prop_seg + c.bt.phase_seg1);
        }
        for rate in [1_000_000u32, 2_000_000, 4_000_000, 5_000_000, 8_000_000] {
            let want = Bittiming {
                bitrate: rate,
                ..Bittiming::default()
            };
            let c = bittiming::calc(&DATA_CONST, clock, &want).unwrap();
            let f = btr_fd_fields(btr_fd(&c.bt));
            assert_eq!(f.bitrate(clock), c.bt.bitrate, "{rate}");
        }
    }

    #[test]
    fn fault_states() {
        let ewl = 96;
        assert_eq!(
            fault_state(ewl | fault::ERA, 0),
            Some(CanState::ErrorActive)
        );
        assert_eq!(
            fault_state(ewl | fault::ERA, 100 << 16),
            Some(CanState::ErrorWarning)
        );
        assert_eq!(
            fault_state(ewl | fault::ERA, 96),
            Some(CanState::ErrorWarning)
        );
        assert_eq!(
            fault_state(ewl | fault::ERP, 0),
            Some(CanState::ErrorPassive)
        );
        assert_eq!(fault_state(ewl | fault::BOF, 0), Some(CanState::BusOff));
        assert_eq!(fault_state(0, 0), None);
        assert_eq!(counters(0x0102_0003), (3, 0x102));
    }

    #[test]
    fn tx_states_roundtrip() {
        for v in 0..16 {
            assert_eq!(TxState::from_bits(v).bits(), v);
        }
        assert_eq!(tx_state(0x8848, 1), TxState::Done);
        assert_eq!(tx_state(0x8848, 0), TxState::Empty);
        assert_eq!(txt_buffer_count(0), 4);
        assert_eq!(txt_buffer_count(8 << 16), 8);
    }

    #[test]
    fn ring_priorities_follow_the_oldest() {
        let mut r = TxRing::new(4);
        assert_eq!(r.priority(), 0x1234);
        for k in 0..4 {
            assert_eq!(r.next(), Some(k));
            r.push();
        }
        assert!(r.is_full());
        assert_eq!(r.next(), None);
        r.pop();
        // Oldest is buffer 1 now: priority 4, then 2, 3, 0.
        assert_eq!(r.priority(), 0x2341);
        assert_eq!(r.next(), Some(0));
        // Wrap-around of the counters keeps working.
        let mut w = TxRing {
            head: u32::MAX,
            tail: u32::MAX - 1,
            n: NonZeroU32::new(4).unwrap(),
        };
        assert_eq!(w.in_flight(), 1);
        w.push();
        assert_eq!(w.in_flight(), 2);
    }
}
