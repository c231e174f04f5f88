// SPDX-License-Identifier: GPL-2.0
//! Fuzz the ISO-TP sender and receiver (coverage-guided); the check
//! itself is in `../isotp_check.rs`, which the host test
//! `tests/isotp_fuzz_replay.rs` also runs.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../isotp_check.rs"]
mod isotp_check;

fuzz_target!(|input: &[u8]| isotp_check::check(input));
