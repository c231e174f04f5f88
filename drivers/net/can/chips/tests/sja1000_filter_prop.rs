// SPDX-License-Identifier: GPL-2.0
//! Soundness of the SJA1000 hardware acceptance filter derived from the
//! bound filters (DESIGN decision 7, thesis 5.3.4/5.3.6): for any set of
//! receive filters (mainline and thesis forms) and any frame, if some
//! filter wants the frame, the programmed chip filter (evaluated by the
//! datasheet model `HwFilter::accepts`) lets it through. Also: the
//! per-format cubes (`Wanted::of`) contain every frame their filter wants.

mod common;

use common::filters::{can_id, filter};
use proptest::prelude::*;
use rcan_chips::sja1000::{hw_filter, Wanted};
use rcan_core::arb::*;
use rcan_core::frame::CanFrame;
use rcan_core::rxtable::{frame_key, CanFilterKind, Filter};

fn frame(can_id: u32, len: u8, data: [u8; 8]) -> CanFrame {
    let mut f = CanFrame {
        can_id,
        len,
        data,
        ..CanFrame::default()
    };
    if can_id & CAN_RTR_FLAG != 0 {
        f.data = [0; 8];
    } else {
        for b in f.data[len as usize..].iter_mut() {
            *b = 0;
        }
    }
    f
}

/// QEMU's acceptance filter (hw/net/can/can_sja1000.c,
/// can_sja_accept_filter, as of QEMU 7-9), bugs included: in single mode a
/// standard frame's mask takes AMR1 shifted left, so identifier bits 2..0
/// are always compared. Written from reading that code.
fn qemu_accepts(hw: &rcan_chips::sja1000::HwFilter, f: &CanFrame) -> bool {
    let (acr, amr) = (hw.acr, hw.amr);
    let id = f.can_id;
    let eff = id & CAN_EFF_FLAG != 0;
    let rtr = id & CAN_RTR_FLAG != 0;
    let matches = |fid: u32, fmask: u32| (id & fmask) == (fid & fmask);
    if hw.single {
        if eff {
            let mut fid = u32::from(acr[0]) << 21
                | u32::from(acr[1]) << 13
                | u32::from(acr[2]) << 5
                | u32::from(acr[3]) >> 3;
            if acr[3] & 4 != 0 {
                fid |= CAN_RTR_FLAG;
            }
            let m = u32::from(amr[0]) << 21
                | u32::from(amr[1]) << 13
                | u32::from(amr[2]) << 5
                | u32::from(amr[3]) >> 3;
            let mut fmask = !m & CAN_EFF_MASK;
            if amr[3] & 4 == 0 {
                fmask |= CAN_RTR_FLAG;
            }
            matches(fid, fmask)
        } else {
            let mut fid = u32::from(acr[0]) << 3 | u32::from(acr[1]) >> 5;
            if acr[1] & 0x10 != 0 {
                fid |= CAN_RTR_FLAG;
            }
            let m = u32::from(amr[0]) << 3 | u32::from(amr[1]) << 5;
            let mut fmask = !m & CAN_SFF_MASK;
            if amr[1] & 0x10 == 0 {
                fmask |= CAN_RTR_FLAG;
            }
            if !matches(fid, fmask) {
                return false;
            }
            if rtr || f.len == 0 {
                return true;
            }
            if f.data[0] & !amr[2] != acr[2] & !amr[2] {
                return false;
            }
            f.len < 2 || f.data[1] & !amr[3] == acr[3] & !amr[3]
        }
    } else if eff {
        [(0usize, 4usize), (2, 6)].iter().any(|&(c, m)| {
            let code = [
                acr[0], acr[1], acr[2], acr[3], amr[0], amr[1], amr[2], amr[3],
            ];
            let fid = u32::from(code[c]) << 21 | u32::from(code[c + 1]) << 13;
            let mm = u32::from(code[m]) << 21 | u32::from(code[m + 1]) << 13;
            matches(fid, !mm & CAN_EFF_MASK & !0x1fff)
        })
    } else {
        let code = [
            acr[0], acr[1], acr[2], acr[3], amr[0], amr[1], amr[2], amr[3],
        ];
        let sff = |c: usize, m: usize| {
            let mut fid = u32::from(code[c]) << 3 | u32::from(code[c + 1]) >> 5;
            if code[c + 1] & 0x10 != 0 {
                fid |= CAN_RTR_FLAG;
            }
            let mm = u32::from(code[m]) << 3 | u32::from(code[m + 1]) >> 5;
            let mut fmask = !mm & CAN_SFF_MASK;
            if code[m + 1] & 0x10 == 0 {
                fmask |= CAN_RTR_FLAG;
            }
            matches(fid, fmask)
        };
        if sff(0, 4) {
            let expect = (code[1] << 4) | (code[3] & 0x0f);
            let mask = !((code[5] << 4) | (code[7] & 0x0f));
            if f.data[0] & mask == expect & mask {
                return true;
            }
        }
        sff(2, 6)
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn hw_filter_never_drops_a_wanted_frame(
        filters in prop::collection::vec(filter(), 0..20),
        frames in prop::collection::vec((can_id(), 0u8..=8, any::<[u8; 8]>()), 1..20),
    ) {
        let wanted: Vec<Wanted> = filters.iter().map(Wanted::of).collect();
        let hw = hw_filter(&wanted, false);
        // Frames built from the filters' own patterns are the likeliest to
        // expose a lost bit; add them to the random ones.
        for (id, len, data) in frames {
            let f = frame(id, len, data);
            let key = frame_key(id);
            if filters.iter().any(|flt| flt.matches(key)) {
                prop_assert!(hw.accepts(&f), "wanted {:#x} dropped by {:?} (filters {:?})", id, hw, filters);
                prop_assert!(qemu_accepts(&hw, &f), "QEMU drops wanted {:#x} with {:?} (filters {:?})", id, hw, filters);
            }
        }
    }

    #[test]
    fn wanted_cubes_contain_their_frames(f in filter(), id in can_id()) {
        let w = Wanted::of(&f);
        let key = frame_key(id);
        if f.matches(key) {
            let rtr = u32::from(id & CAN_RTR_FLAG != 0);
            let (cube, bits) = if id & CAN_EFF_FLAG != 0 {
                (w.eff, ((id & CAN_EFF_MASK) << 1) | rtr)
            } else {
                (w.sff, ((id & CAN_SFF_MASK) << 1) | rtr)
            };
            let c = cube.expect("filter wants a frame of a format its cube excludes");
            prop_assert_eq!((bits ^ c.value) & c.care, 0);
        }
    }

    /// Single identifiers are passed exactly (up to dual mode's 16-bit
    /// extended comparison): with one or two exact standard ids wanted, no
    /// other standard data frame gets through.
    #[test]
    fn exact_standard_ids_are_tight(a in 0u32..0x800, b in 0u32..0x800, other in 0u32..0x800) {
        let exact = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;
        let fs: Vec<Filter> = [a, b].iter().map(|&id| match Filter::from_can_filter(id, exact) {
            CanFilterKind::Frames(f) => f,
            CanFilterKind::Errors(_) => unreachable!(),
        }).collect();
        let wanted: Vec<Wanted> = fs.iter().map(Wanted::of).collect();
        let hw = hw_filter(&wanted, false);
        let f = frame(other, 0, [0; 8]);
        prop_assert_eq!(hw.accepts(&f), other == a || other == b);
        prop_assert_eq!(qemu_accepts(&hw, &f), other == a || other == b);
    }
}
