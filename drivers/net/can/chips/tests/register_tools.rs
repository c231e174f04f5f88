// SPDX-License-Identifier: GPL-2.0
//! The chips' bit-timing searches and decoders (`sja1000::timing_for`,
//! `sja1000::bitrate`, `i82527::timing_for`, `i82527::bitrate`), which the
//! register tools use, against the functions as they were before they went
//! through `rcan_core::bittiming`.

/// `sja1000config`'s and `i82527config`'s searches and decoders now go
/// through `to_btr`/`from_btr`; their answers must not change. The
/// references are the functions as they were before (commit 5b51aec).
#[test]
fn register_tools_unchanged() {
    fn old_sja_bitrate(btr0: u8, btr1: u8, xtal_hz: u32) -> u32 {
        let brp = u32::from(btr0 & 0x3F) + 1;
        let tseg1 = u32::from(btr1 & 0x0F) + 1;
        let tseg2 = u32::from((btr1 >> 4) & 0x07) + 1;
        xtal_hz / (2 * brp * (1 + tseg1 + tseg2))
    }
    fn old_sja_timing_for(bitrate: u32, xtal_hz: u32) -> Option<(u8, u8)> {
        if bitrate == 0 {
            return None;
        }
        let mut best: Option<(u32, u32, u8, u8)> = None;
        for tq in (8u32..=25).rev() {
            let div = 2 * tq * bitrate;
            if !xtal_hz.is_multiple_of(div) {
                continue;
            }
            let brp = xtal_hz / div;
            if brp == 0 || brp > 64 {
                continue;
            }
            for tseg2 in 1u32..=8 {
                let Some(tseg1) = (tq - 1).checked_sub(tseg2) else {
                    continue;
                };
                if !(1..=16).contains(&tseg1) {
                    continue;
                }
                let sp = (1 + tseg1) * 1000 / tq;
                let err = sp.abs_diff(875);
                let better = match best {
                    None => true,
                    Some((btq, berr, _, _)) => tq > btq || (tq == btq && err < berr),
                };
                if better {
                    best = Some((
                        tq,
                        err,
                        (brp - 1) as u8,
                        (((tseg2 - 1) << 4) | (tseg1 - 1)) as u8,
                    ));
                }
            }
            if best.is_some() {
                break;
            }
        }
        best.map(|(_, _, b0, b1)| (b0, b1))
    }
    fn old_i82527_bitrate(bt0: u8, bt1: u8, cpu_if: u8, xtal_hz: u32) -> u32 {
        let sys = xtal_hz / if cpu_if & 0x40 != 0 { 2 } else { 1 };
        let brp = u32::from(bt0 & 0x3F) + 1;
        sys / (brp * (3 + u32::from(bt1 & 0x0F) + u32::from((bt1 >> 4) & 0x07)))
    }
    fn old_i82527_timing_for(bitrate: u32, sys_hz: u32) -> Option<(u8, u8)> {
        if bitrate == 0 {
            return None;
        }
        for tq in (8u32..=25).rev() {
            let div = tq * bitrate;
            if !sys_hz.is_multiple_of(div) {
                continue;
            }
            let brp = sys_hz / div;
            if brp == 0 || brp > 64 {
                continue;
            }
            let mut best: Option<(u32, u8)> = None;
            for tseg2 in 1u32..=7 {
                let Some(tseg1) = (tq - 3).checked_sub(tseg2) else {
                    continue;
                };
                if !(2..=15).contains(&tseg1) {
                    continue;
                }
                let err = ((2 + tseg1) * 1000 / tq).abs_diff(875);
                if best.is_none_or(|(e, _)| err < e) {
                    best = Some((err, ((tseg2 << 4) | tseg1) as u8));
                }
            }
            if let Some((_, bt1)) = best {
                return Some(((brp - 1) as u8, bt1));
            }
        }
        None
    }
    use rcan_chips::{i82527, sja1000};
    for clock in [
        4_000_000, 8_000_000, 10_000_000, 12_000_000, 16_000_000, 24_000_000,
    ] {
        for rate in (1_000..=1_000_000)
            .step_by(1_000)
            .chain([33_333, 83_333, 666_666])
        {
            assert_eq!(
                sja1000::timing_for(rate, clock),
                old_sja_timing_for(rate, clock)
            );
            assert_eq!(
                i82527::timing_for(rate, clock),
                old_i82527_timing_for(rate, clock)
            );
        }
    }
    for b0 in 0..=255u8 {
        for b1 in 0..=255u8 {
            for xtal in [8_000_000, 16_000_000, 24_000_000] {
                assert_eq!(
                    sja1000::bitrate(b0, b1, xtal),
                    old_sja_bitrate(b0, b1, xtal)
                );
                for cpu_if in [0, 0x40] {
                    assert_eq!(
                        i82527::bitrate(b0, b1, cpu_if, xtal),
                        old_i82527_bitrate(b0, b1, cpu_if, xtal)
                    );
                }
            }
        }
    }
}
