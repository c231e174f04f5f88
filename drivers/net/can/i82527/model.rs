// SPDX-License-Identifier: GPL-2.0

//! A register-level model of the Intel 82527, for the host tests of the
//! driver core (`i82527::Chip`) and for the kernel's simulated card
//! (`rcan_i82527_sim`), which runs the unchanged driver on it. No
//! allocation, fixed-size state: one model is one chip.
//!
//! It follows the datasheet for everything the driver touches: the
//! control register (INIT, IE, SIE, EIE, CCE; bit timing writable only
//! with INIT and CCE), the status register (TXOK, RXOK, WARN, BOFF;
//! reading it clears the status interrupt), the CPU interface register's
//! reset flag, the message objects with their two-bit control fields
//! (MsgVal, TXIE, RXIE, IntPnd, RmtPnd, TxRqst, MsgLst/CPUUpd, NewDat),
//! acceptance through the global standard and extended masks and the
//! message-15 mask (ANDed with the global extended mask), the lowest
//! matching object storing a data frame, transmit-direction objects
//! answering remote frames (RmtPnd, TxRqst; not while CPUUpd), receive-
//! direction objects with TxRqst sending remote frames, transmission in
//! object-number order, object 15's double buffer (a shadow buffer that
//! moves in when the host released the object; overwriting the shadow
//! sets MsgLst), the interrupt register's priority order (status change,
//! object 15, objects 1..14), and bus-off with the recovery sequence.
//!
//! Fault injection ([`Fault`], [`I82527Model::attempt`]): a transmission
//! attempt on a faulty bus fails with the last error code the chip would
//! set (ACK error for a missing acknowledgement, bit 0 error for a
//! stuck-recessive bit), the transmit error counter moving as the CAN
//! rules say (+8 per error; an error-passive transmitter's ACK errors do
//! not count), and with it WARN (96) and BOFF (256, INIT set).
//!
//! What it does not model: bit timing on a wire (frames move instantly,
//! the caller is the bus; [`I82527Model::frame_ns`] tells it how long a
//! frame takes at the programmed bit timing), error counters other than through
//! [`I82527Model::set_errors`] and [`I82527Model::attempt`], the ports, serial/parallel interface
//! modes, the high-speed read registers, sleep and wake up.

use super::arb::{CAN_EFF_FLAG, CAN_EFF_MASK, CAN_ERR_FLAG, CAN_RTR_FLAG, CAN_SFF_MASK, MAX_DLC};
use super::bittiming::frame_bits;
use super::frame::CanFrame;
use super::i82527::{
    arb_bytes, arb_id, bit_ns, bits, cpu_if, ctrl, intid, mcfg, reg, status, EXT_RX,
};
use super::sim_bus::{Attempt, BusNode};

/// The contents of one receive buffer: arbitration, configuration, data.
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
struct Buf {
    arb: [u8; 4],
    cfg: u8,
    data: [u8; 8],
}

/// A bus fault for [`I82527Model::attempt`].
#[derive(Clone, Copy, PartialEq, Eq, Debug, Default)]
pub enum Fault {
    /// Every attempt succeeds.
    #[default]
    None,
    /// No node acknowledges: LEC 3 (ACK error), the transmit error
    /// counter climbs by 8 per attempt up to error passive (128) and
    /// stays there (CAN 2.0B 7.1, exception 1).
    NoAck,
    /// Every attempt ends in a bit 0 error (LEC 5: a dominant bit sent,
    /// recessive read): +8 per attempt, warning after 12, bus-off after
    /// 32.
    BitErr,
    /// Every attempt succeeds, and the bus (the caller) offers each frame
    /// twice to the other nodes before their host can read the first: a
    /// receive object still holding it sets MsgLst, as when a host falls
    /// behind a busy bus (a receive overrun).
    Overrun,
}

/// What one transmission attempt did: `Idle` (nothing to send, or off
/// the bus), `Sent` (the frame went out), `Failed` (a bus error; the chip
/// retries by itself).
pub type TxAttempt = Attempt<CanFrame>;

/// One 82527.
#[derive(Clone, Debug)]
pub struct I82527Model {
    /// Register file; message object control registers hold two-bit
    /// fields as the chip presents them.
    mem: [u8; 256],
    /// Object 15's shadow buffer.
    shadow: Option<Buf>,
    /// The status interrupt is pending (cleared by reading STATUS).
    status_irq: bool,
    /// Transmit and receive error counters.
    tec: u16,
    rec: u16,
    /// Reads of CPU_IF that still show RSTST (hardware reset).
    reset_reads: u8,
    /// Nothing at this address: reads give 0xFF, writes vanish.
    pub absent: bool,
    /// Frames this chip put on the bus.
    pub sent: u64,
    /// Remote frames it answered by itself.
    pub answered: u64,
    /// Data frames from the bus no object took (masks, INIT).
    pub not_taken: u64,
}

impl Default for I82527Model {
    fn default() -> Self {
        Self::new()
    }
}

/// Field `shift` of control byte `b` is set.
const fn set(b: u8, shift: u8) -> bool {
    bits::is_set(b, shift)
}

/// Merges a CPU write into a control byte: `01`/`10` fields replace,
/// `11` (and the undefined `00`) keep.
const fn merge(old: u8, new: u8) -> u8 {
    let mut out = 0;
    let mut shift = 0;
    while shift < 8 {
        let f = (new >> shift) & 3;
        let keep = (old >> shift) & 3;
        out |= if f == bits::SET || f == bits::RES {
            f
        } else {
            keep
        } << shift;
        shift += 2;
    }
    out
}

/// A control byte with every field reset.
const ALL_RES: u8 = 0x55;

impl I82527Model {
    /// A chip after power-on: INIT set, every object's fields reset,
    /// a hardware reset that lasts two reads of the CPU interface
    /// register.
    pub fn new() -> Self {
        let mut m = I82527Model {
            mem: [0; 256],
            shadow: None,
            status_irq: false,
            tec: 0,
            rec: 0,
            reset_reads: 2,
            absent: false,
            sent: 0,
            answered: 0,
            not_taken: 0,
        };
        m.mem[usize::from(reg::CONTROL)] = ctrl::INIT;
        for n in 1..=15u8 {
            m.mem[usize::from(reg::obj(n) + reg::CTRL0)] = ALL_RES;
            m.mem[usize::from(reg::obj(n) + reg::CTRL1)] = ALL_RES;
        }
        m
    }

    fn r(&self, a: u8) -> u8 {
        self.mem[usize::from(a)]
    }

    fn w(&mut self, a: u8, v: u8) {
        self.mem[usize::from(a)] = v;
    }

    /// Sets (`true`) or resets field `shift` of control register `c` of
    /// object `n` (the chip's own updates).
    fn field(&mut self, n: u8, c: u8, shift: u8, on: bool) {
        let a = reg::obj(n) + c;
        let v = if on { bits::SET } else { bits::RES };
        self.w(a, merge(self.r(a), bits::only(shift, v)));
    }

    fn c0(&self, n: u8) -> u8 {
        self.r(reg::obj(n) + reg::CTRL0)
    }

    fn c1(&self, n: u8) -> u8 {
        self.r(reg::obj(n) + reg::CTRL1)
    }

    fn control(&self) -> u8 {
        self.r(reg::CONTROL)
    }

    /// A transmission attempt on a bus with `fault`: as
    /// [`I82527Model::transmit`] without a fault; with one, a chip that
    /// has a frame to send records the error (LEC, status interrupt with
    /// SIE) and its counters move (WARN/BOFF, status interrupt with EIE).
    pub fn attempt(&mut self, fault: Fault) -> TxAttempt {
        if matches!(fault, Fault::None | Fault::Overrun) {
            return match self.transmit() {
                Some(f) => TxAttempt::Sent(f),
                None => TxAttempt::Idle,
            };
        }
        if !self.tx_pending() {
            return TxAttempt::Idle;
        }
        let (lec, tec) = match fault {
            Fault::NoAck if self.tec >= 128 => (3, self.tec),
            Fault::NoAck => (3, self.tec + 8),
            _ => (5, self.tec.saturating_add(8)),
        };
        let s = (self.r(reg::STATUS) & !status::LEC) | lec;
        self.w(reg::STATUS, s);
        self.status_event(0, ctrl::SIE);
        self.set_errors(tec, self.rec);
        TxAttempt::Failed
    }

    /// Whether the chip is on the bus with an object that wants to send.
    pub fn tx_pending(&self) -> bool {
        if self.absent || self.in_init() || self.bus_off() {
            return false;
        }
        (1..=14u8).any(|n| {
            let (c0, c1) = (self.c0(n), self.c1(n));
            set(c0, bits::MSGVAL)
                && set(c1, bits::TXRQST)
                && !(self.is_tx(n) && set(c1, bits::CPUUPD))
        })
    }

    /// The transmit error counter.
    pub fn tec(&self) -> u16 {
        self.tec
    }

    /// Off the bus: INIT set (by the host, or by the chip at bus-off).
    pub fn in_init(&self) -> bool {
        self.control() & ctrl::INIT != 0
    }

    /// Bus-off (BOFF) is set.
    pub fn bus_off(&self) -> bool {
        self.r(reg::STATUS) & status::BOFF != 0
    }

    /// Raises the status interrupt if `cause` is enabled.
    fn status_event(&mut self, bits_set: u8, enable: u8) {
        let s = self.r(reg::STATUS) | bits_set;
        self.w(reg::STATUS, s);
        if self.control() & enable != 0 {
            self.status_irq = true;
        }
    }

    /// The interrupt register: the highest-priority cause pending.
    pub fn int_reg(&self) -> u8 {
        if self.status_irq {
            return intid::STATUS;
        }
        if set(self.c0(15), bits::INTPND) {
            return intid::OBJ15;
        }
        for n in 1..=14u8 {
            if set(self.c0(n), bits::INTPND) {
                return n + 2;
            }
        }
        intid::NONE
    }

    /// The interrupt output: IE and something pending.
    pub fn irq_line(&self) -> bool {
        !self.absent && self.control() & ctrl::IE != 0 && self.int_reg() != intid::NONE
    }

    /// A CPU read.
    pub fn read(&mut self, a: u8) -> u8 {
        if self.absent {
            return 0xFF;
        }
        match a {
            reg::INT => self.int_reg(),
            reg::STATUS => {
                self.status_irq = false;
                self.r(a)
            }
            reg::CPU_IF => {
                let mut v = self.r(a) & !cpu_if::RSTST;
                if self.reset_reads > 0 {
                    self.reset_reads -= 1;
                    v |= cpu_if::RSTST;
                }
                v
            }
            _ => self.r(a),
        }
    }

    /// A CPU write.
    pub fn write(&mut self, a: u8, v: u8) {
        if self.absent {
            return;
        }
        match a {
            reg::INT => {}
            reg::STATUS => {
                // WARN and BOFF are read only.
                let keep = self.r(a) & (status::WARN | status::BOFF);
                self.w(a, (v & !(status::WARN | status::BOFF)) | keep);
            }
            reg::CONTROL => {
                self.w(
                    a,
                    v & (ctrl::INIT | ctrl::IE | ctrl::SIE | ctrl::EIE | ctrl::CCE),
                );
            }
            reg::CPU_IF => self.w(a, v & !cpu_if::RSTST),
            reg::BT0 | reg::BT1 => {
                if self.control() & (ctrl::INIT | ctrl::CCE) == ctrl::INIT | ctrl::CCE {
                    self.w(a, v);
                }
            }
            _ if a >= 0x10 && a & 0x0F <= reg::CTRL1 => {
                // Control 0/1 of objects 1..15.
                let merged = merge(self.r(a), v);
                self.w(a, merged);
                if a == reg::obj(EXT_RX) + reg::CTRL0 || a == reg::obj(EXT_RX) + reg::CTRL1 {
                    self.obj15_release();
                }
            }
            _ => self.w(a, v),
        }
    }

    /// Object 15 released by the host (IntPnd and NewDat reset): the
    /// shadow buffer moves in.
    fn obj15_release(&mut self) {
        if set(self.c0(15), bits::INTPND) || set(self.c1(15), bits::NEWDAT) {
            return;
        }
        if let Some(b) = self.shadow.take() {
            self.store(15, &b);
        }
    }

    /// The mask (1 = must match) and identifier width object `n` is
    /// compared with.
    fn mask_of(&self, n: u8, ext: bool) -> u32 {
        if ext {
            let g = u32::from_be_bytes(self.regs4(reg::GME)) >> 3;
            if n == 15 {
                g & (u32::from_be_bytes(self.regs4(reg::M15)) >> 3)
            } else {
                g
            }
        } else {
            u32::from(u16::from_be_bytes([self.r(reg::GMS), self.r(reg::GMS + 1)]) >> 5)
        }
    }

    fn regs4(&self, a: u8) -> [u8; 4] {
        [self.r(a), self.r(a + 1), self.r(a + 2), self.r(a + 3)]
    }

    /// Whether object `n` is valid and compares equal to identifier `id`
    /// of format `ext` under its mask.
    fn matches(&self, n: u8, id: u32, ext: bool) -> bool {
        let base = reg::obj(n);
        if !set(self.c0(n), bits::MSGVAL) {
            return false;
        }
        let cfg = self.r(base + reg::CFG);
        if (cfg & mcfg::XTD != 0) != ext {
            return false;
        }
        let own = arb_id(self.regs4(base + reg::ARB), ext);
        let width = if ext { CAN_EFF_MASK } else { CAN_SFF_MASK };
        (own ^ id) & self.mask_of(n, ext) & width == 0
    }

    /// Object `n` is transmit direction (object 15 never is).
    fn is_tx(&self, n: u8) -> bool {
        n != 15 && self.r(reg::obj(n) + reg::CFG) & mcfg::DIR != 0
    }

    /// Stores a received data frame in object `n` (foreground).
    fn store(&mut self, n: u8, b: &Buf) {
        let base = reg::obj(n);
        if set(self.c1(n), bits::NEWDAT) {
            // The host had not read the previous one.
            self.field(n, reg::CTRL1, bits::MSGLST, true);
        }
        for (i, x) in b.arb.iter().enumerate() {
            self.w(base + reg::ARB + i as u8, *x);
        }
        let cfg = (self.r(base + reg::CFG) & (mcfg::DIR | mcfg::XTD | 0x03)) | (b.cfg & 0xF0);
        self.w(base + reg::CFG, cfg);
        for (i, x) in b.data.iter().enumerate() {
            self.w(base + reg::DATA + i as u8, *x);
        }
        self.field(n, reg::CTRL1, bits::NEWDAT, true);
        // A receive object that had requested this frame (remote
        // request) got it.
        self.field(n, reg::CTRL1, bits::TXRQST, false);
        if set(self.c0(n), bits::RXIE) {
            self.field(n, reg::CTRL0, bits::INTPND, true);
        }
    }

    /// A frame from the bus (another node's). Returns whether an object
    /// took it: stored (data frame) or answer requested (remote frame).
    /// Nothing happens in INIT (off the bus).
    pub fn receive(&mut self, f: &CanFrame) -> bool {
        if self.absent || f.can_id & CAN_ERR_FLAG != 0 {
            return false;
        }
        if self.in_init() || self.bus_off() {
            self.not_taken += 1;
            return false;
        }
        let ext = f.can_id & CAN_EFF_FLAG != 0;
        let id = f.can_id & if ext { CAN_EFF_MASK } else { CAN_SFF_MASK };
        let rtr = f.can_id & CAN_RTR_FLAG != 0;
        self.status_event(status::RXOK, ctrl::SIE);
        if rtr {
            // The first valid transmit object with this identifier sets
            // RmtPnd and TxRqst: it will answer.
            for n in 1..=14u8 {
                if self.is_tx(n) && self.matches(n, id, ext) {
                    self.field(n, reg::CTRL1, bits::RMTPND, true);
                    self.field(n, reg::CTRL1, bits::TXRQST, true);
                    return true;
                }
            }
            return false;
        }
        let dlc = f.dlc().min(MAX_DLC);
        let mut b = Buf {
            arb: arb_bytes(id, ext),
            cfg: (f.len.min(15)) << mcfg::DLC_SHIFT,
            data: [0; 8],
        };
        b.data[..dlc].copy_from_slice(&f.data[..dlc]);
        for n in 1..=15u8 {
            if self.is_tx(n) || !self.matches(n, id, ext) {
                continue;
            }
            if n == 15 && (set(self.c0(15), bits::INTPND) || set(self.c1(15), bits::NEWDAT)) {
                // Foreground in use: into the shadow buffer; a full
                // shadow is overwritten and the loss flagged.
                if self.shadow.is_some() {
                    self.field(15, reg::CTRL1, bits::MSGLST, true);
                }
                self.shadow = Some(b);
            } else {
                self.store(n, &b);
            }
            return true;
        }
        self.not_taken += 1;
        false
    }

    /// How long frame `f` takes on the bus at the bit timing this chip's
    /// BT0/BT1 and CPU interface registers program from crystal `xtal_hz`,
    /// ns ([`frame_bits`]: no stuff bits, the intermission included).
    pub fn frame_ns(&self, f: &CanFrame, xtal_hz: u32) -> u64 {
        let bit = bit_ns(
            self.r(reg::BT0),
            self.r(reg::BT1),
            self.r(reg::CPU_IF),
            xtal_hz,
        );
        u64::from(frame_bits(f.can_id, f.len)) * u64::from(bit)
    }

    /// The object that goes out next and its frame: the lowest-numbered
    /// valid object with a transmission request (a transmit object's
    /// data frame, or a receive object's remote frame); transmit objects
    /// under CPU update wait. `None` off the bus or with nothing to send.
    fn next_tx(&self) -> Option<(u8, CanFrame)> {
        if self.absent || self.in_init() || self.bus_off() {
            return None;
        }
        for n in 1..=14u8 {
            let (c0, c1) = (self.c0(n), self.c1(n));
            if !set(c0, bits::MSGVAL) || !set(c1, bits::TXRQST) {
                continue;
            }
            let tx = self.is_tx(n);
            if tx && set(c1, bits::CPUUPD) {
                continue;
            }
            let base = reg::obj(n);
            let cfg = self.r(base + reg::CFG);
            let ext = cfg & mcfg::XTD != 0;
            let dlc = (cfg >> mcfg::DLC_SHIFT).min(MAX_DLC as u8);
            let mut f = CanFrame {
                can_id: arb_id(self.regs4(base + reg::ARB), ext)
                    | if ext { CAN_EFF_FLAG } else { 0 },
                len: dlc,
                ..CanFrame::default()
            };
            if tx {
                for i in 0..usize::from(dlc) {
                    f.data[i] = self.r(base + reg::DATA + i as u8);
                }
            } else {
                f.can_id |= CAN_RTR_FLAG;
            }
            return Some((n, f));
        }
        None
    }

    /// The frame [`I82527Model::transmit`] would send now, without
    /// sending it (the simulated bus asks before it lets the chip go).
    pub fn pending_frame(&self) -> Option<CanFrame> {
        self.next_tx().map(|(_, f)| f)
    }

    /// The bus is free for this chip: the lowest-numbered object with a
    /// transmission request goes out (a transmit object's data frame, or
    /// a receive object's remote frame). Returns the frame, with the
    /// transmission already acknowledged (the caller offers it to the
    /// other nodes). Transmit objects under CPU update wait.
    pub fn transmit(&mut self) -> Option<CanFrame> {
        let (n, f) = self.next_tx()?;
        let (c0, c1) = (self.c0(n), self.c1(n));
        let tx = self.is_tx(n);
        let answered = tx && set(c1, bits::RMTPND);
        self.field(n, reg::CTRL1, bits::TXRQST, false);
        self.field(n, reg::CTRL1, bits::RMTPND, false);
        if tx {
            self.field(n, reg::CTRL1, bits::NEWDAT, false);
        }
        if set(c0, bits::TXIE) {
            self.field(n, reg::CTRL0, bits::INTPND, true);
        }
        self.status_event(status::TXOK, ctrl::SIE);
        self.sent += 1;
        if answered {
            self.answered += 1;
        }
        Some(f)
    }

    /// Whether this chip can take data frame `f` from the bus now without
    /// losing a frame its host has not read yet, or making the host read
    /// them out of bus order: the object [`I82527Model::receive`] would
    /// store it in must be free (object 15: its foreground buffer, or else
    /// its shadow buffer), and no other receive object may hold an unread
    /// frame that the host would read after this one (the interrupt
    /// register names object 15 first, then objects 1..14 in turn; with
    /// two objects holding frames, only a frame in object 15 that came
    /// first keeps its place). Remote frames, frames no object takes and
    /// any frame while the chip is off the bus: always.
    pub fn ready_for(&self, f: &CanFrame) -> bool {
        if self.absent || self.in_init() || self.bus_off() {
            return true;
        }
        if f.can_id & (CAN_ERR_FLAG | CAN_RTR_FLAG) != 0 {
            return true;
        }
        let ext = f.can_id & CAN_EFF_FLAG != 0;
        let id = f.can_id & if ext { CAN_EFF_MASK } else { CAN_SFF_MASK };
        let Some(n) = (1..=15u8).find(|&n| !self.is_tx(n) && self.matches(n, id, ext)) else {
            return true;
        };
        let unread = |m: u8| {
            set(self.c0(m), bits::MSGVAL)
                && !self.is_tx(m)
                && (set(self.c1(m), bits::NEWDAT) || (m == 15 && set(self.c0(m), bits::INTPND)))
        };
        if (1..=14u8).any(unread) {
            // Object n (1..14) would be overwritten, or would be read
            // before an older frame of a higher-numbered object; a frame
            // for object 15 would be read before every one of them.
            return false;
        }
        !(n == 15 && unread(15) && self.shadow.is_some())
    }

    /// Sets the error counters (what bus errors would do) and updates
    /// WARN and BOFF: at 256 transmit errors the chip goes bus-off and
    /// sets INIT itself. Changes raise the status interrupt with EIE.
    pub fn set_errors(&mut self, tec: u16, rec: u16) {
        self.tec = tec;
        self.rec = rec;
        let old = self.r(reg::STATUS);
        let mut s = old & !(status::WARN | status::BOFF);
        if tec >= 96 || rec >= 96 {
            s |= status::WARN;
        }
        if tec >= 256 || old & status::BOFF != 0 {
            s |= status::BOFF;
            let c = self.control() | ctrl::INIT;
            self.w(reg::CONTROL, c);
        }
        self.w(reg::STATUS, s);
        if s & (status::WARN | status::BOFF) != old & (status::WARN | status::BOFF) {
            self.status_event(0, ctrl::EIE);
        }
    }

    /// The bus was idle for a while (128 occurrences of 11 recessive
    /// bits): a chip in bus-off whose INIT the host cleared rejoins the
    /// bus with its counters reset.
    pub fn bus_idle(&mut self) {
        if self.bus_off() && !self.in_init() {
            self.tec = 0;
            self.rec = 0;
            let s = self.r(reg::STATUS) & !(status::WARN | status::BOFF);
            self.w(reg::STATUS, s);
            self.status_event(0, ctrl::EIE);
        }
    }

    /// Whether object 15's shadow buffer holds a frame.
    pub fn shadow_full(&self) -> bool {
        self.shadow.is_some()
    }

    /// The raw control bytes of object `n` (tests).
    pub fn ctrl_bytes(&self, n: u8) -> (u8, u8) {
        (self.c0(n), self.c1(n))
    }
}

impl super::i82527::Regs for I82527Model {
    fn read(&mut self, reg: u8) -> u8 {
        I82527Model::read(self, reg)
    }

    fn write(&mut self, reg: u8, val: u8) {
        I82527Model::write(self, reg, val)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ns_at_the_programmed_rate() {
        let mut m = I82527Model::new();
        m.write(reg::CONTROL, ctrl::INIT | ctrl::CCE);
        m.write(reg::CPU_IF, cpu_if::DSC);
        // 500 kbit/s from a 16 MHz crystal: 2 us a bit.
        m.write(reg::BT0, 0x00);
        m.write(reg::BT1, 0x2B);
        let sff8 = CanFrame {
            can_id: 0x123,
            len: 8,
            pad: 0,
            res0: 0,
            len8_dlc: 0,
            data: [0; 8],
        };
        assert_eq!(m.frame_ns(&sff8, 16_000_000), 111 * 2_000);
        // 1 Mbit/s: 8 tq a bit.
        m.write(reg::BT1, 0x14);
        assert_eq!(m.frame_ns(&sff8, 16_000_000), 111 * 1_000);
        // Outside INIT + CCE the timing registers do not change.
        m.write(reg::CONTROL, 0);
        m.write(reg::BT1, 0x2B);
        assert_eq!(m.frame_ns(&sff8, 16_000_000), 111 * 1_000);
    }

    #[test]
    fn two_bit_write_merge() {
        assert_eq!(merge(0x55, 0xBF), 0x95);
        assert_eq!(merge(0x95, 0xFD), 0x95);
        assert_eq!(merge(0x96, 0xFD), 0x95);
        assert_eq!(merge(0x95, 0x00), 0x95);
    }
}

/// The chip on a simulated bus ([`super::sim_bus::round`]). It needs no
/// acknowledgement from the bus: [`Fault::NoAck`] stands for a bus where
/// nobody acknowledges.
impl BusNode for I82527Model {
    type Frame = CanFrame;
    type Fault = Fault;

    fn tx_pending(&self) -> bool {
        I82527Model::tx_pending(self)
    }

    fn acks(&self) -> bool {
        !self.absent && !self.in_init() && !self.bus_off()
    }

    fn attempt(&mut self, fault: Fault, _acked: bool) -> TxAttempt {
        I82527Model::attempt(self, fault)
    }

    fn next_frame(&self) -> Option<CanFrame> {
        self.pending_frame()
    }

    /// A receive object the host has not read yet holds the frame back
    /// ([`I82527Model::ready_for`]).
    fn not_ready_for(&self, f: &CanFrame) -> bool {
        !self.ready_for(f)
    }

    /// Every copy arrives (under [`Fault::Overrun`] the second one sets
    /// MsgLst); the model counts each one no object takes.
    fn deliver(&mut self, f: &CanFrame) -> bool {
        self.receive(f);
        true
    }
}
