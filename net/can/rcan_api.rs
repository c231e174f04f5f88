// SPDX-License-Identifier: GPL-2.0

//! The interface of `rcan_pf` to the CAN protocols and drivers above and
//! below it, included (`#[path]`) by every module that uses it: the typed
//! framework of `rust/glue/can/proto.rs`, re-exported under the name the
//! modules have always used. The C ABI underneath lives in
//! `rust/glue/can/abi.rs`; nothing here is `unsafe`.
//!
//! Not every includer uses every item.
#![forbid(unsafe_code)]
#![allow(unused_imports)]

pub(crate) use crate::glue::can::proto::*;
