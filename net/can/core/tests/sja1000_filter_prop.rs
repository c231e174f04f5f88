// SPDX-License-Identifier: GPL-2.0
//! Soundness of the SJA1000 hardware acceptance filter derived from the
//! bound filters (DESIGN decision 7, thesis 5.3.4/5.3.6): for any set of
//! receive filters (mainline and thesis forms) and any frame, if some
//! filter wants the frame, the programmed chip filter (evaluated by the
//! datasheet model `HwFilter::accepts`) lets it through. Also: the
//! per-format cubes (`Wanted::of`) contain every frame their filter wants.

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::filter::ArbFilter;
use rcan_core::frame::CanFrame;
use rcan_core::rxtable::{frame_key, CanFilterKind, Filter};
use rcan_core::sja1000::{hw_filter, Wanted};

/// Ids drawn near a few values so that filters and frames collide often.
fn can_id() -> impl Strategy<Value = u32> {
    let id = prop_oneof![
        0u32..8,
        0x120u32..0x128,
        0x7F0u32..0x800,
        0u32..=CAN_EFF_MASK
    ];
    (id, any::<bool>(), any::<bool>(), any::<u32>()).prop_map(|(id, eff, rtr, noise)| {
        let mut c = if eff {
            // Extended ids near standard ones shifted into the base id.
            if noise & 1 == 0 {
                ((id & CAN_SFF_MASK) << 18 | (noise >> 14 & 0x3FFFF)) | CAN_EFF_FLAG
            } else {
                id | CAN_EFF_FLAG
            }
        } else {
            id & CAN_SFF_MASK
        };
        if rtr {
            c |= CAN_RTR_FLAG;
        }
        c
    })
}

fn filter() -> impl Strategy<Value = Filter> {
    let masks = prop::sample::select(vec![
        0,
        CAN_SFF_MASK,
        CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
        CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG,
        0x7F0,
        CAN_EFF_FLAG,
        0x1FFF_0000 | CAN_EFF_FLAG,
    ]);
    let mainline = (
        can_id(),
        prop_oneof![masks, any::<u32>()],
        prop::bool::weighted(0.1),
    )
        .prop_map(|(id, mask, inv)| {
            let id = if inv { id | 0x2000_0000 } else { id };
            match Filter::from_can_filter(id, mask & !CAN_ERR_FLAG) {
                CanFilterKind::Frames(f) => f,
                CanFilterKind::Errors(_) => unreachable!(),
            }
        });
    let thesis = (
        can_id(),
        prop_oneof![
            prop::sample::select(vec![1u32, 3, 5, 7, 0x00FF_FFFF, 0x001F_FFFF, u32::MAX]),
            any::<u32>()
        ],
    )
        .prop_map(|(id, mask)| {
            let arb = Arb::from_can_id(id).unwrap().raw();
            Filter::Arb(ArbFilter::new(arb, mask).unwrap())
        });
    prop_oneof![mainline, thesis]
}

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
    }
}
