// SPDX-License-Identifier: GPL-2.0
//! The cargo-fuzz check of the ISO-TP core (`fuzz/isotp_check.rs`) on
//! proptest inputs, so that `make check` runs it too (cargo-fuzz needs a
//! nightly compiler). Not coverage-guided: random byte strings, and byte
//! strings built from plausible records (frames whose first byte is a
//! likely N_PCI, sends, echoes and time steps) that reach the deeper
//! states of both machines.

#[path = "../fuzz/isotp_check.rs"]
mod isotp_check;

use proptest::prelude::*;

/// One record of the check's input format, aimed at the interesting
/// states: frames start with an SF/FF/CF/FC N_PCI (or, with extended
/// addressing, an address byte first).
fn record() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        4 => (any::<bool>(), 0u8..4, any::<u8>(), prop::collection::vec(any::<u8>(), 0..64))
            .prop_map(|(fd, kind, low, mut data)| {
                let mut r = vec![if fd { 8 } else { 0 }];
                if let Some(b) = data.first_mut() {
                    *b = kind << 4 | (low & 0x0F);
                }
                // FF_DL mostly small, so that CFs can complete it.
                if kind == 1 && data.len() > 1 {
                    data[0] &= 0xF0;
                    data[1] = low % 100;
                }
                r.push(data.len() as u8);
                r.extend_from_slice(&data);
                r
            }),
        2 => Just(vec![1u8]),
        2 => prop_oneof![0u8..40, 200u8..=255].prop_map(|dt| vec![2, dt]),
        // A whole classic multi-frame PDU (FF and CFs with the right
        // sequence numbers), sometimes with one CF's number wrong.
        1 => (7u8..60, any::<Option<u8>>()).prop_map(|(len, bad)| {
            let mut r = vec![0, 8, 0x10, len, 1, 2, 3, 4, 5, 6];
            let ncf = (usize::from(len) - 6).div_ceil(7);
            for k in 1..=ncf {
                let sn = if bad.is_some_and(|b| usize::from(b) % ncf == k - 1) { k + 3 } else { k };
                r.extend_from_slice(&[0, 8, 0x20 | (sn as u8 & 0x0F), 9, 9, 9, 9, 9, 9, 9]);
            }
            r
        }),
        1 => (0u16..300).prop_map(|l| { let b = l.to_be_bytes(); vec![3, b[0], b[1]] }),
        1 => Just(vec![4u8]),
        1 => Just(vec![5u8]),
    ]
}

fn head() -> impl Strategy<Value = Vec<u8>> {
    (any::<[u8; 12]>(), any::<u16>()).prop_map(|(mut h, flags)| {
        // Mostly without extended addressing and pad checks, which
        // the frames above do not satisfy.
        let f = u32::from(flags) & if flags & 1 == 0 { 0x3FC5 } else { 0x3FFF };
        h[..4].copy_from_slice(&f.to_ne_bytes());
        h.to_vec()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes(input in prop::collection::vec(any::<u8>(), 0..600)) {
        isotp_check::check(&input);
    }

    #[test]
    fn plausible_records(h in head(), recs in prop::collection::vec(record(), 0..150)) {
        let mut input = h;
        input.extend(recs.concat());
        isotp_check::check(&input);
    }
}
