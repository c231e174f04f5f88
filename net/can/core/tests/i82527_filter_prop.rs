// SPDX-License-Identifier: GPL-2.0
//! Soundness of the 82527 masks derived from the bound filters (thesis
//! 5.3.4, 5.3.10; `rcan_core::i82527::masks_for`): for any set of receive
//! filters (mainline and thesis forms) and any data frame some filter
//! wants, a chip programmed by the driver core with those masks stores
//! the frame (checked on the register-level model, through the driver's
//! interrupt handler), and `Masks::receives` agrees with the model on
//! every frame. Remote frames are never stored by receive objects on an
//! 82527 (documented limitation), so only data frames are required.

use proptest::prelude::*;
use rcan_core::arb::*;
use rcan_core::filter::ArbFilter;
use rcan_core::frame::CanFrame;
use rcan_core::i82527::{masks_for, Chip, Config, Event, Masks};
use rcan_core::i82527_model::I82527Model;
use rcan_core::rxtable::{frame_key, CanFilterKind, Filter};
use rcan_core::sja1000::Wanted;

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

fn data_frame(can_id: u32, len: u8, data: [u8; 8]) -> CanFrame {
    let mut f = CanFrame {
        can_id: can_id & !CAN_RTR_FLAG,
        len,
        data,
        ..CanFrame::default()
    };
    for b in f.data[len as usize..].iter_mut() {
        *b = 0;
    }
    f
}

/// A sender and a receiver programmed with `m`; `f` goes over the bus;
/// returns whether the receiver's host got it.
fn delivered(m: &Masks, f: &CanFrame) -> bool {
    let mk = |m: &Masks| {
        let mut c = Chip::new(I82527Model::new(), Config::DEFAULT);
        c.probe().unwrap();
        c.init(m);
        c.start();
        c
    };
    let mut tx = mk(&Masks::OPEN);
    let mut rx = mk(m);
    tx.xmit(f).unwrap();
    let sent = tx.regs.transmit().unwrap();
    rx.regs.receive(&sent);
    let mut got = false;
    rx.irq(16, |e| {
        if e == Event::Rx(*f) {
            got = true;
        }
    });
    got
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn masks_never_drop_a_wanted_data_frame(
        filters in prop::collection::vec(filter(), 0..12),
        frames in prop::collection::vec((can_id(), 0u8..=8, any::<[u8; 8]>()), 1..12),
    ) {
        let wanted: Vec<Wanted> = filters.iter().map(Wanted::of).collect();
        let m = masks_for(&wanted, false);
        for (id, len, data) in frames {
            let f = data_frame(id, len, data);
            let model = delivered(&m, &f);
            prop_assert_eq!(m.receives(&f), model, "Masks::receives disagrees with the model for {:#x} ({:?})", f.can_id, m);
            if filters.iter().any(|flt| flt.matches(frame_key(f.can_id))) {
                prop_assert!(model, "wanted {:#x} dropped by {:?} (filters {:?})", f.can_id, m, filters);
            }
        }
    }

    #[test]
    fn masks_are_the_tightest_cube(
        filters in prop::collection::vec(filter(), 1..6),
    ) {
        // Every identifier bit the masks compare is one all wanted frames
        // of that format agree on: clearing any compared bit of a mask
        // would be looser, and setting a don't-care bit would drop a
        // frame some filter wants (checked on the filters' own cubes).
        let wanted: Vec<Wanted> = filters.iter().map(Wanted::of).collect();
        let m = masks_for(&wanted, false);
        let sff: Vec<_> = wanted.iter().filter_map(|w| w.sff).collect();
        if let Some(rx) = m.std_rx {
            for bit in 0..11 {
                let b = 1u32 << bit;
                let cared_by_all = sff.iter().all(|c| (c.care >> 1) & b != 0);
                let agree = sff.iter().all(|c| ((c.value >> 1) ^ rx) & b == 0);
                prop_assert_eq!(m.gms & b != 0, cared_by_all && agree, "bit {}", bit);
            }
        } else {
            prop_assert!(sff.is_empty());
        }
        let eff: Vec<_> = wanted.iter().filter_map(|w| w.eff).collect();
        if let Some(rx) = m.ext_rx {
            for bit in 0..29 {
                let b = 1u32 << bit;
                let cared_by_all = eff.iter().all(|c| (c.care >> 1) & b != 0);
                let agree = eff.iter().all(|c| ((c.value >> 1) ^ rx) & b == 0);
                prop_assert_eq!(m.m15 & b != 0, cared_by_all && agree, "bit {}", bit);
            }
        } else {
            prop_assert!(eff.is_empty());
        }
    }

    #[test]
    fn promiscuous_receives_every_data_frame(
        (id, len, data) in (can_id(), 0u8..=8, any::<[u8; 8]>()),
    ) {
        let f = data_frame(id, len, data);
        prop_assert!(delivered(&masks_for(&[], true), &f));
    }
}
