// SPDX-License-Identifier: GPL-2.0
//! The cargo-fuzz check of the DSOR receive path (`fuzz/dsor_rx_check.rs`)
//! on proptest inputs, so that `make check` runs it too (cargo-fuzz needs a
//! nightly compiler and is not part of CI; see dsor-wire.rst, "Testing and
//! fuzzing"). Not coverage-guided: random byte strings, and byte strings
//! built from well-formed records (headers, bodies and acks on the few
//! streams of the local node) that reach the deeper states.

#[path = "../fuzz/dsor_rx_check.rs"]
mod dsor_rx_check;

use proptest::prelude::*;

/// One record: `id | dlc | data | dt`, with the id aimed at node 1's
/// streams (bit 31 clear, see the check's id mapping: sources 0-3, any
/// channel and sequence bit), a frame type header/body/ack and a
/// plausible payload.
fn record() -> impl Strategy<Value = Vec<u8>> {
    (
        any::<u32>(),
        0u8..3,
        0usize..=8,
        prop::collection::vec(any::<u8>(), 8),
        prop_oneof![Just(0u8), 1u8..20, Just(255u8)],
    )
        .prop_map(|(raw, ftype, dlc, mut data, dt)| {
            let id = (raw & 0x7fff_ffff & !(3 << 5)) | u32::from(ftype) << 5;
            // Headers: one of the three lengths (segmented, port, UDP),
            // announcing short messages, mostly within the check's
            // max_len of 600.
            let dlc = if ftype == 0 {
                data[0] = 0;
                data[1] %= 64;
                [6, 4, 8][dlc % 3]
            } else {
                dlc
            };
            let mut r = id.to_le_bytes().to_vec();
            r.push(dlc as u8);
            r.extend_from_slice(&data[..dlc]);
            r.push(dt);
            r
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes(input in prop::collection::vec(any::<u8>(), 0..800)) {
        dsor_rx_check::check(&input);
    }

    #[test]
    fn well_formed_records(recs in prop::collection::vec(record(), 0..120)) {
        dsor_rx_check::check(&recs.concat());
    }
}
