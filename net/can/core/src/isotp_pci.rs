// SPDX-License-Identifier: GPL-2.0
//! The ISO 15765-2 network protocol control information (N_PCI) on CAN
//! frames: building and parsing single, first, consecutive and flow
//! control frames, classic and CAN FD, with the optional address byte of
//! extended (and mixed) addressing, padding and its checks, and STmin.
//! Documentation/networking/rcan/isotp.rst, "Wire formats".
//!
//! A frame here is its payload only ([`LlFrame`], `data[..len]` of a
//! `can_frame` or `canfd_frame`); the identifier (`tx_id`) and the FD
//! flags (`tx_flags`) are the socket's and the glue adds them. Every
//! function is pure: no state, no allocation, no panics on any input.

use super::isotp::{
    Config, CAN_ISOTP_CHK_PAD_DATA, CAN_ISOTP_CHK_PAD_LEN, CAN_ISOTP_DEFAULT_PAD_CONTENT,
    CAN_ISOTP_RX_PADDING, CAN_ISOTP_TX_PADDING, MAX_12BIT_PDU_SIZE,
};

/// N_PCI type of a single frame (bits 7-4 of the first N_PCI byte).
pub const N_PCI_SF: u8 = 0x00;
/// N_PCI type of a first frame.
pub const N_PCI_FF: u8 = 0x10;
/// N_PCI type of a consecutive frame.
pub const N_PCI_CF: u8 = 0x20;
/// N_PCI type of a flow control frame.
pub const N_PCI_FC: u8 = 0x30;

/// Flow status "continue to send" (FS = 0).
pub const FS_CTS: u8 = 0;
/// Flow status "wait" (FS = 1).
pub const FS_WAIT: u8 = 1;
/// Flow status "overflow" (FS = 2).
pub const FS_OVFLW: u8 = 2;

/// Bytes of a flow control frame after the address byte: FS, BS, STmin.
pub const FC_CONTENT_SZ: usize = 3;

/// Most payload bytes of a link-layer frame (CAN FD).
pub const LL_MAX_DLEN: usize = 64;

/// The payload of one CAN frame as ISO-TP builds and reads it.
///
/// The state machines write the frames they send into a buffer of this
/// type that the caller owns and reuses (`Tx::*_into`, `Rx::*_into`, the
/// `write_*` functions here): they write `len` and every byte of
/// `data[..len]` and leave the bytes from `len` on as they were, so that
/// no frame is zeroed, built and then moved by value (65 bytes each time)
/// on the per-frame path. The `build_*` functions and the machines'
/// by-value steps start from a zeroed frame, so there the bytes from
/// `len` on are zero.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct LlFrame {
    /// Payload length (`can_dlc`/`len`): at most 8 classic, 64 FD.
    pub len: u8,
    /// Payload; bytes from `len` on: see above.
    pub data: [u8; LL_MAX_DLEN],
}

impl Default for LlFrame {
    fn default() -> Self {
        LlFrame {
            len: 0,
            data: [0; LL_MAX_DLEN],
        }
    }
}

impl LlFrame {
    /// `data[..len]`.
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.len).min(LL_MAX_DLEN)]
    }

    /// The first 8 bytes of the payload with the bytes from `len` on
    /// zeroed: the data of a classic `can_frame`, whatever the buffer held
    /// before (see above). Built without a variable-length copy.
    #[inline]
    pub fn classic_data(&self) -> [u8; 8] {
        let mut d = [0u8; 8];
        d.copy_from_slice(&self.data[..8]);
        let w = u64::from_le_bytes(d);
        let keep = match self.len {
            0 => 0,
            n @ 1..=7 => (1u64 << (8 * u32::from(n))) - 1,
            _ => u64::MAX,
        };
        (w & keep).to_le_bytes()
    }
}

/// `dst.copy_from_slice(src)` (equal lengths), with the 7 data bytes of a
/// full classic consecutive frame (or single frame) copied by a
/// fixed-size move: a copy of variable length is a call of the kernel's
/// `memcpy`, and this one runs twice per frame (the sender's build, the
/// receiver's reassembly).
#[inline(always)]
pub fn copy_payload(dst: &mut [u8], src: &[u8]) {
    match (
        <&mut [u8; 7]>::try_from(&mut *dst),
        <&[u8; 7]>::try_from(src),
    ) {
        (Ok(d), Ok(s)) => *d = *s,
        _ => dst.copy_from_slice(src),
    }
}

/// The smallest valid CAN (FD) data length holding `len` bytes, at least
/// 8 (mainline's `padlen`): 8, 12, 16, 20, 24, 32, 48 or 64.
pub const fn padlen(len: u8) -> u8 {
    match len {
        0..=8 => 8,
        9..=12 => 12,
        13..=16 => 16,
        17..=20 => 20,
        21..=24 => 24,
        25..=32 => 32,
        33..=48 => 48,
        _ => 64,
    }
}

/// Whether `raw` is an STmin value ISO 15765-2 defines: 0x00-0x7F
/// (0-127 ms) or 0xF1-0xF9 (100-900 µs).
pub const fn stmin_valid(raw: u8) -> bool {
    raw <= 0x7F || (raw >= 0xF1 && raw <= 0xF9)
}

/// The separation time of STmin `raw` in ns; a reserved value counts as
/// 0x7F (127 ms), as ISO 15765-2 tells a sender to do and mainline does.
pub const fn stmin_ns(raw: u8) -> u32 {
    if raw <= 0x7F {
        raw as u32 * 1_000_000
    } else if raw >= 0xF1 && raw <= 0xF9 {
        (raw as u32 - 0xF0) * 100_000
    } else {
        127_000_000
    }
}

/// The STmin value that asks for at least `ns` between consecutive
/// frames: the shortest valid one whose time is `ns` or more; 127 ms
/// (0x7F) at most.
pub const fn stmin_from_ns(ns: u32) -> u8 {
    if ns == 0 {
        0
    } else if ns <= 900_000 {
        // 100..900 µs in steps of 100 µs, rounded up.
        0xF0 + ns.div_ceil(100_000) as u8
    } else if ns <= 127_000_000 {
        ns.div_ceil(1_000_000) as u8
    } else {
        0x7F
    }
}

/// Bytes a single frame can carry with the socket's TX_DL: TX_DL minus
/// the N_PCI (1 byte, 2 with the SF_DL escape that TX_DL > 8 needs) and
/// the address byte.
pub fn sf_max(cfg: &Config) -> usize {
    let dl = usize::from(cfg.ll.tx_dl);
    let esc = usize::from(dl > 8);
    dl.saturating_sub(1 + cfg.ae() + esc)
}

/// Puts `src` (as much as fits) into `f` behind `pcilen` N_PCI bytes,
/// with the frame length TX_DL if full, else the shortest length, padded
/// to a valid length with `txpad_content` ([`CAN_ISOTP_TX_PADDING`]) or,
/// for CAN FD lengths above 8, with 0xCC; writes the address byte. The
/// caller writes the N_PCI bytes (`data[ae..pcilen]`); with them every
/// byte of `data[..len]` is written. Returns how many bytes of `src` went
/// in (mainline `isotp_fill_dataframe`).
fn fill(cfg: &Config, f: &mut LlFrame, pcilen: usize, src: &[u8]) -> usize {
    let dl = usize::from(cfg.ll.tx_dl).min(LL_MAX_DLEN);
    let pcilen = pcilen.min(dl);
    let space = dl - pcilen;
    let num = src.len().min(space);
    let mut len = num + pcilen;
    copy_payload(&mut f.data[pcilen..len], &src[..num]);
    if num < space {
        let pad = if cfg.has(CAN_ISOTP_TX_PADDING) {
            Some(cfg.opt.txpad_content)
        } else if len > 8 {
            Some(CAN_ISOTP_DEFAULT_PAD_CONTENT)
        } else {
            None
        };
        if let Some(p) = pad {
            // len <= dl <= 64 here.
            let end = usize::from(padlen(len as u8));
            f.data[len..end].fill(p);
            len = end;
        }
    }
    if cfg.ae() == 1 {
        f.data[0] = cfg.opt.ext_address;
    }
    f.len = len as u8;
    num
}

/// [`write_sf`] into a zeroed frame.
pub fn build_sf(cfg: &Config, pdu: &[u8]) -> LlFrame {
    let mut f = LlFrame::default();
    write_sf(cfg, pdu, &mut f);
    f
}

/// Writes the single frame of `pdu` into `f` (see [`LlFrame`]), which
/// must fit ([`sf_max`]; longer PDUs are cut). The SF_DL escape (N_PCI
/// 0x00, length in the next byte) is used only when the PDU does not fit
/// a frame of 8 bytes, so that a short PDU on CAN FD stays an 8-byte
/// frame, as in mainline.
pub fn write_sf(cfg: &Config, pdu: &[u8], f: &mut LlFrame) {
    let ae = cfg.ae();
    let pdu = &pdu[..pdu.len().min(sf_max(cfg))];
    let esc = cfg.ll.tx_dl > 8 && pdu.len() > 8 - 1 - ae;
    fill(cfg, f, 1 + ae + usize::from(esc), pdu);
    // sf_max() <= 62, so the length fits a byte (and 4 bits without esc).
    if esc {
        f.data[ae] = N_PCI_SF;
        f.data[ae + 1] = pdu.len() as u8;
    } else {
        f.data[ae] = N_PCI_SF | pdu.len() as u8;
    }
}

/// [`write_ff`] into a zeroed frame.
pub fn build_ff(cfg: &Config, pdu_len: usize, head: &[u8]) -> (LlFrame, usize) {
    let mut f = LlFrame::default();
    let n = write_ff(cfg, pdu_len, head, &mut f);
    (f, n)
}

/// Writes the first frame of a `pdu_len`-byte PDU starting with `head`
/// into `f` (see [`LlFrame`]; at least TX_DL bytes of `head` are needed to
/// fill the frame, the rest of a full-length frame is zero): FF_DL in 12
/// bits, or for PDUs over 4095 bytes the escape (12-bit 0, then 32 bits).
/// Returns how many bytes of `head` it carries. `pdu_len` over
/// `u32::MAX` is the caller's error ([`super::isotp_tx::Tx::start`]
/// refuses it).
pub fn write_ff(cfg: &Config, pdu_len: usize, head: &[u8], f: &mut LlFrame) -> usize {
    let ae = cfg.ae();
    let pci = if pdu_len > MAX_12BIT_PDU_SIZE as usize {
        let l = (pdu_len as u32).to_be_bytes();
        f.data[ae] = N_PCI_FF;
        f.data[ae + 1] = 0;
        f.data[ae + 2..ae + 6].copy_from_slice(&l);
        6
    } else {
        f.data[ae] = N_PCI_FF | (pdu_len >> 8) as u8;
        f.data[ae + 1] = pdu_len as u8;
        2
    };
    let dl = usize::from(cfg.ll.tx_dl).min(LL_MAX_DLEN).max(ae + pci);
    let num = (dl - ae - pci).min(head.len());
    f.data[ae + pci..ae + pci + num].copy_from_slice(&head[..num]);
    f.data[ae + pci + num..dl].fill(0);
    if ae == 1 {
        f.data[0] = cfg.opt.ext_address;
    }
    f.len = dl as u8;
    num
}

/// [`write_cf`] into a zeroed frame.
pub fn build_cf(cfg: &Config, sn: u8, rest: &[u8]) -> (LlFrame, usize) {
    let mut f = LlFrame::default();
    let n = write_cf(cfg, sn, rest, &mut f);
    (f, n)
}

/// Writes a consecutive frame with sequence number `sn` (low 4 bits)
/// carrying the start of `rest` into `f` (see [`LlFrame`]); returns how
/// many bytes it carries.
pub fn write_cf(cfg: &Config, sn: u8, rest: &[u8], f: &mut LlFrame) -> usize {
    let ae = cfg.ae();
    let n = fill(cfg, f, 1 + ae, rest);
    f.data[ae] = N_PCI_CF | (sn & 0x0F);
    n
}

/// [`write_fc`] into a zeroed frame.
pub fn build_fc(cfg: &Config, fs: u8) -> LlFrame {
    let mut f = LlFrame::default();
    write_fc(cfg, fs, &mut f);
    f
}

/// Writes a flow control frame with flow status `fs` and the socket's
/// `CAN_ISOTP_RECV_FC` block size and STmin into `f` (see [`LlFrame`]):
/// 3 bytes (plus address) or, with [`CAN_ISOTP_TX_PADDING`], 8 bytes
/// padded with `txpad_content` (also on CAN FD, as mainline).
pub fn write_fc(cfg: &Config, fs: u8, f: &mut LlFrame) {
    let ae = cfg.ae();
    if cfg.has(CAN_ISOTP_TX_PADDING) {
        f.data[..8].fill(cfg.opt.txpad_content);
        f.len = 8;
    } else {
        f.len = (ae + FC_CONTENT_SZ) as u8;
    }
    f.data[ae] = N_PCI_FC | (fs & 0x0F);
    f.data[ae + 1] = cfg.rxfc.bs;
    f.data[ae + 2] = cfg.rxfc.stmin;
    if ae == 1 {
        f.data[0] = cfg.opt.ext_address;
    }
}

/// The padding check of a received frame whose protocol bytes end at
/// `start` (mainline `check_pad`, applied only when
/// [`CAN_ISOTP_CHK_PAD_LEN`] or [`CAN_ISOTP_CHK_PAD_DATA`] is set):
///
/// - without [`CAN_ISOTP_RX_PADDING`]: with CHK_PAD_LEN the frame must
///   have the optimised length (`start`, or for CAN FD lengths above 8
///   the next valid length); with CHK_PAD_DATA alone every frame fails,
///   as in mainline ("no valid test against empty value");
/// - with RX_PADDING: CHK_PAD_LEN wants a valid padded length (8 or a
///   CAN FD length), CHK_PAD_DATA wants every byte from `start` to be
///   `rxpad_content`.
///
/// Returns whether the frame passes.
pub fn pad_ok(cfg: &Config, data: &[u8], start: usize) -> bool {
    let chk_len = cfg.has(CAN_ISOTP_CHK_PAD_LEN);
    let chk_data = cfg.has(CAN_ISOTP_CHK_PAD_DATA);
    if !chk_len && !chk_data {
        return true;
    }
    let len = data.len();
    if !cfg.has(CAN_ISOTP_RX_PADDING) {
        if !chk_len {
            return false;
        }
        if len <= 8 {
            return len == start;
        }
        return len == usize::from(padlen(start.min(255) as u8));
    }
    if chk_len && len != usize::from(padlen(len.min(255) as u8)) {
        return false;
    }
    if chk_data {
        return data
            .get(start..)
            .unwrap_or(&[])
            .iter()
            .all(|&b| b == cfg.opt.rxpad_content);
    }
    true
}

/// A received single frame: where its data starts in the payload and how
/// long it is, or `None` if it is to be ignored (mainline ignores an SF
/// with SF_DL 0 or one longer than the frame, and an escape SF on a
/// classic link layer). Lengths: a frame of up to 8 bytes uses the 4-bit
/// SF_DL (also on CAN FD); a longer CAN FD frame must use the escape
/// (SF_DL 0, the length in the next byte). As in mainline, an escape
/// length that would have fit the 4-bit form is accepted.
pub fn parse_sf(cfg: &Config, data: &[u8]) -> Option<(usize, usize)> {
    let ae = cfg.ae();
    let sf_dl = usize::from(*data.get(ae)? & 0x0F);
    let (pcilen, len) = if data.len() <= 8 {
        (ae + 1, sf_dl)
    } else if cfg.ll.is_fd() && sf_dl == 0 {
        (ae + 2, usize::from(*data.get(ae + 1)?))
    } else {
        return None;
    };
    if len == 0 || len > data.len().saturating_sub(pcilen) {
        return None;
    }
    Some((pcilen, len))
}

/// A received first frame's header.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct FfHeader {
    /// FF_DL: the PDU length.
    pub len: u32,
    /// N_PCI bytes plus address byte: where the data starts.
    pub pcilen: usize,
    /// The sender's TX_DL, taken from this frame's length (every CF but
    /// the last has this length).
    pub ll_dl: u8,
}

/// Parses a received first frame; `None`: ignore it. Mainline ignores an
/// FF not of a full valid length, and one whose FF_DL would have fit
/// into this frame as a single frame; we also ignore one whose PDU ends
/// within the FF itself (FF_DL 6 on classic CAN, for example), which no
/// conforming sender produces.
pub fn parse_ff(cfg: &Config, data: &[u8]) -> Option<FfHeader> {
    let ae = cfg.ae();
    let flen = u8::try_from(data.len()).ok()?;
    let ll_dl = padlen(flen);
    if flen != ll_dl {
        return None;
    }
    let d = |i: usize| data.get(i).copied().unwrap_or(0);
    let short = u32::from(d(ae) & 0x0F) << 8 | u32::from(d(ae + 1));
    let (len, pci) = if short != 0 {
        (short, 2)
    } else {
        (
            u32::from_be_bytes([d(ae + 2), d(ae + 3), d(ae + 4), d(ae + 5)]),
            6,
        )
    };
    let esc = u64::from(ll_dl > 8);
    if u64::from(len) + (ae as u64) + esc + pci < u64::from(ll_dl) {
        return None;
    }
    // Differs from mainline: a PDU that ends inside this frame is ignored
    // too (mainline waits for one more CF, then delivers).
    if u64::from(len) <= u64::from(ll_dl) - (ae as u64) - pci {
        return None;
    }
    Some(FfHeader {
        len,
        pcilen: ae + pci as usize,
        ll_dl,
    })
}

/// A received flow control frame's content.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct Fc {
    /// Flow status (low 4 bits of the N_PCI byte).
    pub fs: u8,
    /// Block size.
    pub bs: u8,
    /// STmin as received.
    pub stmin: u8,
}

/// Parses a received flow control frame; `Err(())` for a malformed one
/// (too short, or failing the padding check), which ends the sender's
/// transfer with `EBADMSG`.
#[allow(clippy::result_unit_err)]
pub fn parse_fc(cfg: &Config, data: &[u8]) -> Result<Fc, ()> {
    let ae = cfg.ae();
    if data.len() < ae + FC_CONTENT_SZ || !pad_ok(cfg, data, ae + FC_CONTENT_SZ) {
        return Err(());
    }
    Ok(Fc {
        fs: data[ae] & 0x0F,
        bs: data[ae + 1],
        stmin: data[ae + 2],
    })
}

#[cfg(test)]
// Tests start from the defaults and change what they exercise.
#[allow(clippy::field_reassign_with_default)]
mod tests {
    use super::super::isotp::{LlOptions, CAN_ISOTP_EXTEND_ADDR};
    use super::*;

    fn fd(tx_dl: u8) -> Config {
        let mut c = Config::default();
        c.ll = LlOptions {
            mtu: 72,
            tx_dl,
            tx_flags: 1,
        };
        c
    }

    #[test]
    fn padlen_is_mainlines_table() {
        let table: [u8; 49] = [
            8, 8, 8, 8, 8, 8, 8, 8, 8, 12, 12, 12, 12, 16, 16, 16, 16, 20, 20, 20, 20, 24, 24, 24,
            24, 32, 32, 32, 32, 32, 32, 32, 32, 48, 48, 48, 48, 48, 48, 48, 48, 48, 48, 48, 48, 48,
            48, 48, 48,
        ];
        for l in 0..=255u8 {
            let want = table.get(usize::from(l)).copied().unwrap_or(64);
            assert_eq!(padlen(l), want, "{l}");
        }
    }

    #[test]
    fn stmin_decoding() {
        assert_eq!(stmin_ns(0), 0);
        assert_eq!(stmin_ns(1), 1_000_000);
        assert_eq!(stmin_ns(0x7F), 127_000_000);
        assert_eq!(stmin_ns(0xF1), 100_000);
        assert_eq!(stmin_ns(0xF9), 900_000);
        for r in (0x80..=0xF0).chain(0xFA..=0xFF) {
            assert!(!stmin_valid(r));
            assert_eq!(stmin_ns(r), 127_000_000, "reserved {r:#x}");
        }
        assert_eq!((0..=255u8).filter(|&r| stmin_valid(r)).count(), 128 + 9);
    }

    #[test]
    fn stmin_encoding_is_shortest_sufficient() {
        for ns in (0..2_000_000u32).step_by(7_919).chain([
            0,
            1,
            100_000,
            900_000,
            900_001,
            127_000_000,
            u32::MAX,
        ]) {
            let r = stmin_from_ns(ns);
            assert!(stmin_valid(r));
            if ns <= 127_000_000 {
                assert!(stmin_ns(r) >= ns, "{ns} -> {r:#x}");
                // No valid code with a shorter time still suffices.
                for s in 0..=255u8 {
                    if stmin_valid(s) && stmin_ns(s) >= ns {
                        assert!(stmin_ns(s) >= stmin_ns(r));
                    }
                }
            } else {
                assert_eq!(r, 0x7F);
            }
        }
    }

    #[test]
    fn classic_sf() {
        let c = Config::default();
        let f = build_sf(&c, &[1, 2, 3]);
        assert_eq!(f.payload(), &[0x03, 1, 2, 3]);
        assert_eq!(parse_sf(&c, f.payload()), Some((1, 3)));
        assert_eq!(sf_max(&c), 7);
        let f = build_sf(&c, &[9; 7]);
        assert_eq!(f.payload(), &[0x07, 9, 9, 9, 9, 9, 9, 9]);
        // SF_DL 0 and SF_DL past the frame are ignored.
        assert_eq!(parse_sf(&c, &[0x00, 1, 2]), None);
        assert_eq!(parse_sf(&c, &[0x03, 1, 2]), None);
        assert_eq!(parse_sf(&c, &[0x08, 1, 2, 3, 4, 5, 6, 7]), None);
    }

    #[test]
    fn sf_padding_and_extended_address() {
        let mut c = Config::default();
        c.opt.flags = CAN_ISOTP_TX_PADDING | CAN_ISOTP_EXTEND_ADDR;
        c.opt.ext_address = 0xEA;
        c.opt.rx_ext_address = 0xEA;
        c.opt.txpad_content = 0xAA;
        let f = build_sf(&c, &[1, 2]);
        assert_eq!(f.payload(), &[0xEA, 0x02, 1, 2, 0xAA, 0xAA, 0xAA, 0xAA]);
        assert_eq!(sf_max(&c), 6);
        assert_eq!(parse_sf(&c, f.payload()), Some((2, 2)));
    }

    #[test]
    fn fd_sf_escape() {
        let c = fd(64);
        assert_eq!(sf_max(&c), 62);
        // Fits 8 bytes: no escape, no FD length.
        let f = build_sf(&c, &[7; 7]);
        assert_eq!(f.len, 8);
        assert_eq!(f.data[0], 0x07);
        // 8 bytes need the escape and the FD length 12, padded with 0xCC.
        let f = build_sf(&c, &[7; 8]);
        assert_eq!(f.len, 12);
        assert_eq!(&f.payload()[..2], &[0x00, 8]);
        assert_eq!(&f.payload()[10..], &[0xCC, 0xCC]);
        assert_eq!(parse_sf(&c, f.payload()), Some((2, 8)));
        let f = build_sf(&c, &[5; 62]);
        assert_eq!((f.len, f.data[0], f.data[1]), (64, 0, 62));
        assert_eq!(parse_sf(&c, f.payload()), Some((2, 62)));
        // A long FD frame with a 4-bit SF_DL is ignored, as is the escape
        // on a classic link layer.
        let mut long = [0u8; 12];
        long[0] = 0x05;
        assert_eq!(parse_sf(&c, &long), None);
        assert_eq!(
            parse_sf(&Config::default(), &[0x00, 5, 1, 2, 3, 4, 5, 6]),
            None
        );
        // TX_DL 12: the escape form leaves 10 bytes.
        assert_eq!(sf_max(&fd(12)), 10);
    }

    #[test]
    fn ff_12_and_32_bit() {
        let c = Config::default();
        let pdu: Vec<u8> = (0..100u8).collect();
        let (f, n) = build_ff(&c, 100, &pdu);
        assert_eq!(n, 6);
        assert_eq!(f.payload(), &[0x10, 100, 0, 1, 2, 3, 4, 5]);
        assert_eq!(
            parse_ff(&c, f.payload()),
            Some(FfHeader {
                len: 100,
                pcilen: 2,
                ll_dl: 8
            })
        );
        let (f, n) = build_ff(&c, 4095, &pdu);
        assert_eq!((&f.payload()[..2], n), (&[0x1F, 0xFF][..], 6));
        let (f, n) = build_ff(&c, 4096, &pdu);
        assert_eq!(n, 2);
        assert_eq!(f.payload(), &[0x10, 0, 0, 0, 0x10, 0x00, 0, 1]);
        assert_eq!(parse_ff(&c, f.payload()).unwrap().len, 4096);
        assert_eq!(parse_ff(&c, f.payload()).unwrap().pcilen, 6);
        let c = fd(64);
        let (f, n) = build_ff(&c, 70_000, &[3u8; 100]);
        assert_eq!((f.len, n), (64, 58));
        assert_eq!(&f.payload()[..6], &[0x10, 0, 0, 0x01, 0x11, 0x70]);
        assert_eq!(parse_ff(&c, f.payload()).unwrap().len, 70_000);
    }

    #[test]
    fn ff_rejections() {
        let c = Config::default();
        // Not a full frame.
        assert_eq!(parse_ff(&c, &[0x10, 20, 1, 2, 3, 4, 5]), None);
        // FF_DL that would have fit: 5 + 0 + 0 + 2 < 8.
        assert_eq!(parse_ff(&c, &[0x10, 5, 1, 2, 3, 4, 5, 6]), None);
        // A PDU that ends inside the FF (mainline would wait for a CF).
        assert_eq!(parse_ff(&c, &[0x10, 6, 1, 2, 3, 4, 5, 6]), None);
        assert!(parse_ff(&c, &[0x10, 7, 1, 2, 3, 4, 5, 6]).is_some());
        // CAN FD: 12-byte frame, lengths count the escape byte.
        let c = fd(12);
        let mut f = [0u8; 12];
        f[0] = 0x10;
        f[1] = 8;
        assert_eq!(parse_ff(&c, &f), None);
        f[1] = 10;
        assert_eq!(parse_ff(&c, &f), None);
        f[1] = 11;
        assert_eq!(parse_ff(&c, &f).map(|h| h.ll_dl), Some(12));
        assert_eq!(parse_ff(&c, &f[..10]), None);
        // 32-bit escape with a zero length is ignored.
        assert_eq!(
            parse_ff(&Config::default(), &[0x10, 0, 0, 0, 0, 0, 1, 2]),
            None
        );
    }

    #[test]
    fn cf_and_padding() {
        let mut c = Config::default();
        let (f, n) = build_cf(&c, 17, &[1, 2, 3]);
        assert_eq!((f.payload(), n), (&[0x21, 1, 2, 3][..], 3));
        let (f, n) = build_cf(&c, 15, &[9; 20]);
        assert_eq!((f.payload(), n), (&[0x2F, 9, 9, 9, 9, 9, 9, 9][..], 7));
        c.opt.flags = CAN_ISOTP_TX_PADDING;
        let (f, _) = build_cf(&c, 1, &[1]);
        assert_eq!(f.payload(), &[0x21, 1, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]);
        // CAN FD: a last CF of 20 data bytes gets the length 24.
        let c = fd(64);
        let (f, n) = build_cf(&c, 3, &[4; 20]);
        assert_eq!((f.len, n), (24, 20));
        assert_eq!(&f.payload()[21..], &[0xCC; 3]);
        let (f, n) = build_cf(&c, 3, &[4; 200]);
        assert_eq!((f.len, n), (64, 63));
    }

    #[test]
    fn fc_build_and_parse() {
        let mut c = Config::default();
        c.rxfc.bs = 8;
        c.rxfc.stmin = 0xF3;
        let f = build_fc(&c, FS_CTS);
        assert_eq!(f.payload(), &[0x30, 8, 0xF3]);
        assert_eq!(
            parse_fc(&c, f.payload()),
            Ok(Fc {
                fs: 0,
                bs: 8,
                stmin: 0xF3
            })
        );
        assert_eq!(parse_fc(&c, &[0x30, 8]), Err(()));
        c.opt.flags = CAN_ISOTP_TX_PADDING | CAN_ISOTP_EXTEND_ADDR;
        c.opt.ext_address = 0x42;
        let f = build_fc(&c, FS_OVFLW);
        assert_eq!(f.payload(), &[0x42, 0x32, 8, 0xF3, 0xCC, 0xCC, 0xCC, 0xCC]);
        assert_eq!(parse_fc(&c, f.payload()).map(|f| f.fs), Ok(FS_OVFLW));
        assert_eq!(parse_fc(&c, &[0x42, 0x30, 8]), Err(()));
    }

    #[test]
    fn pad_checks_like_mainline() {
        let mut c = Config::default();
        let f = [0x02, 1, 2, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC];
        assert!(pad_ok(&c, &f, 3));
        // Data check without RX_PADDING: nothing to check against, fails.
        c.opt.flags = CAN_ISOTP_CHK_PAD_DATA;
        assert!(!pad_ok(&c, &f, 3));
        c.opt.flags = CAN_ISOTP_CHK_PAD_LEN;
        assert!(!pad_ok(&c, &f, 3));
        assert!(pad_ok(&c, &f[..3], 3));
        c.opt.flags = CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN | CAN_ISOTP_CHK_PAD_DATA;
        assert!(pad_ok(&c, &f, 3));
        assert!(!pad_ok(&c, &f[..3], 3));
        let mut g = f;
        g[7] = 0;
        assert!(!pad_ok(&c, &g, 3));
        c.opt.rxpad_content = 0;
        assert!(!pad_ok(&c, &f, 3));
        c.opt.flags = CAN_ISOTP_RX_PADDING | CAN_ISOTP_CHK_PAD_LEN;
        assert!(pad_ok(&c, &g, 3));
        // CAN FD optimised length: 20 protocol bytes want length 20, 21
        // want 24.
        c.opt.flags = CAN_ISOTP_CHK_PAD_LEN;
        assert!(pad_ok(&c, &[0u8; 20], 20));
        assert!(pad_ok(&c, &[0u8; 24], 21));
        assert!(!pad_ok(&c, &[0u8; 24], 20));
    }
}
