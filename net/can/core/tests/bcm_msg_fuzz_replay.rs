// SPDX-License-Identifier: GPL-2.0
//! The cargo-fuzz check of the BCM message parser (`fuzz/bcm_msg_check.rs`)
//! on proptest inputs, so that `make check` runs it too (cargo-fuzz needs a
//! nightly compiler; see bcm.rst, "Testing"). Not coverage-guided: random
//! byte strings, and well-formed messages (a valid opcode, plausible flags,
//! intervals and frame counts) that reach the operations.

#[path = "../fuzz/bcm_msg_check.rs"]
mod bcm_msg_check;

use proptest::prelude::*;
use rcan_core::bcm::{BcmTimeval, MsgHead, CAN_FD_FRAME, MHSIZ};

fn well_formed() -> impl Strategy<Value = Vec<u8>> {
    (
        1u32..=7,
        0u32..0x1000,
        0u32..5,
        0u64..3000,
        0u64..3000,
        0u32..6,
        prop::collection::vec(any::<[u8; 16]>(), 0..6),
    )
        .prop_map(|(opcode, flags, count, i1, i2, nframes, frames)| {
            let head = MsgHead {
                opcode,
                flags,
                count,
                ival1: BcmTimeval::from_us(i1),
                ival2: BcmTimeval::from_us(i2),
                can_id: 0x123,
                nframes,
            };
            let mut m = head.to_bytes().to_vec();
            let fd = flags & CAN_FD_FRAME != 0;
            for mut f in frames {
                if fd {
                    // A 72-byte frame: the 16 bytes and 56 more, len 0..=65.
                    f[4] %= 66;
                    m.extend_from_slice(&f);
                    m.extend((0..56u8).map(|i| f[usize::from(i) % 16] ^ i));
                } else {
                    f[4] %= 10;
                    m.extend_from_slice(&f);
                }
            }
            m
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes(input in prop::collection::vec(any::<u8>(), 0..300)) {
        bcm_msg_check::check(&input);
    }

    #[test]
    fn well_formed_messages(m in well_formed()) {
        assert!(m.len() >= MHSIZ);
        bcm_msg_check::check(&m);
    }
}
