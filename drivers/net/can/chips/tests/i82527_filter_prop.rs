// SPDX-License-Identifier: GPL-2.0
//! Soundness of the 82527 masks derived from the bound filters (thesis
//! 5.3.4, 5.3.10; `rcan_chips::i82527::masks_for`): for any set of receive
//! filters (mainline and thesis forms) and any data frame some filter
//! wants, a chip programmed by the driver core with those masks stores
//! the frame (checked on the register-level model, through the driver's
//! interrupt handler), and `Masks::receives` agrees with the model on
//! every frame. Remote frames are never stored by receive objects on an
//! 82527 (documented limitation), so only data frames are required.

mod common;

use common::filters::{can_id, filter};
use proptest::prelude::*;
use rcan_chips::i82527::{masks_for, Chip, Config, Event, Masks};
use rcan_chips::i82527_model::I82527Model;
use rcan_chips::sja1000::Wanted;
use rcan_core::arb::*;
use rcan_core::frame::CanFrame;
use rcan_core::rxtable::frame_key;

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
