// SPDX-License-Identifier: GPL-2.0
//! `dsor-peer`: a DSOR node (thesis 5.3.3) in userspace, written from the
//! DSOR wire specification alone, to test rcan's DSOR implementation
//! against an independent one.
//!
//! [`wire`] is the frame codec, [`node`] the protocol (no I/O, virtual
//! time), `main.rs` the CAN_RAW socket and the command line.

pub mod cli;
pub mod node;
pub mod wire;
