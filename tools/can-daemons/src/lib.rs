// SPDX-License-Identifier: GPL-2.0
//! The vehicle's CAN daemons (thesis 3.3) on today's CAN_RAW API:
//!
//! - `canzlogd`: every frame of one or more interfaces, kernel
//!   timestamps and error frames included, into rotating gzip files in
//!   can-utils' `candump -l` format (the vehicle's black box);
//! - `cantcpd`: a CAN-over-TCP server speaking the socketcand protocol
//!   (BCM and raw mode), so python-can's `socketcand` interface and other
//!   socketcand clients connect unchanged;
//! - `powerd`: waits for the CAN frame that commands a shutdown, then
//!   signals the log writers, syncs and unmounts the log partition;
//! - `logd`: logs DSOR segmented messages, one timestamped line each.
//!
//! The pure parts (line formats, the socketcand parser, the rotating
//! writer) are here and host-tested; `src/bin/` holds the event loops.
//! The crate has no `unsafe`: sockets go through `socketcan` and `nix`.

#![forbid(unsafe_code)]

pub mod bcm;
pub mod canrx;
pub mod cli;
pub mod frame;
pub mod logd;
pub mod powerd;
pub mod signals;
pub mod socketcand;
pub mod zlog;
