// SPDX-License-Identifier: GPL-2.0
//! Fuzz the J1939 transport sessions and address claim table
//! (coverage-guided); the check itself is in `../j1939_check.rs`, which
//! the host test `tests/j1939_fuzz_replay.rs` also runs.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[path = "../j1939_check.rs"]
mod j1939_check;

fuzz_target!(|input: &[u8]| j1939_check::check(input));
