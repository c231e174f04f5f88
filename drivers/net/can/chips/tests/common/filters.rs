// SPDX-License-Identifier: GPL-2.0
//! proptest strategies for receive filters and CAN identifiers, shared by
//! the hardware-filter soundness tests of the SJA1000 and the 82527.

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::filter::ArbFilter;
use rcan_core::rxtable::{CanFilterKind, Filter};

pub fn can_id() -> impl Strategy<Value = u32> {
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

pub fn filter() -> impl Strategy<Value = Filter> {
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
