// SPDX-License-Identifier: GPL-2.0
//! Fuzz the BCM message parser and the operations it sets up
//! (coverage-guided); the check itself is in `../bcm_msg_check.rs`, which
//! the host test `tests/bcm_msg_fuzz_replay.rs` also runs.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../bcm_msg_check.rs"]
mod bcm_msg_check;

fuzz_target!(|input: &[u8]| bcm_msg_check::check(input));
