// SPDX-License-Identifier: GPL-2.0
//! `i82527config`: setup and remote-frame answers of rcan Intel 82527
//! interfaces, over the driver's device ioctls
//! (`<linux/can/rcan_i82527.h>`, Documentation/networking/rcan/i82527.rst).
//!
//! ```text
//! i82527config IFACE                       show setup, state, restarts
//! i82527config IFACE answer SLOT ID#DATA   publish the answer of slot 0..11
//! i82527config IFACE withdraw SLOT         withdraw it
//! ```
//!
//! `ID#DATA` as cansend: three hex digits for a standard identifier,
//! eight for an extended one, then up to eight data bytes in hex.
//! Publishing needs CAP_NET_ADMIN.

use clap::Parser;
use i82527config::{Cli, Cmd};
use rcan_chips::i82527::{bitrate, AnswerReq, Setup, ANSWER_LEN, SETUP_LEN};
use rcan_core::frame::CanFrame;
use std::process::ExitCode;

use rcan_uapi::{dev_ioctl, SIOCDEVPRIVATE};

const SIOCRCANI82527GET: libc::c_ulong = SIOCDEVPRIVATE;
const SIOCRCANI82527ANSWER: libc::c_ulong = SIOCDEVPRIVATE + 2;

/// Crystal assumed when showing the bit rate.
const XTAL_HZ: u32 = 16_000_000;

fn show(iface: &str) -> Result<(), String> {
    let mut b = [0u8; SETUP_LEN];
    dev_ioctl(iface, SIOCRCANI82527GET, &mut b).map_err(|e| format!("{iface}: {e}"))?;
    let s = Setup::from_bytes(&b);
    let state = match s.state {
        0 => "error active",
        1 => "error warning",
        3 => "bus-off",
        _ => "unknown",
    };
    println!(
        "{iface}: bt0 {:#04x} bt1 {:#04x} cpu_if {:#04x} ({} bit/s with a {} MHz crystal)",
        s.bt0,
        s.bt1,
        s.cpu_if,
        bitrate(s.bt0, s.bt1, s.cpu_if, XTAL_HZ),
        XTAL_HZ / 1_000_000
    );
    println!(
        "{iface}: clkout {:#04x} bus_cfg {:#04x}, {state}, {} restarts, standard answers {}",
        s.clkout,
        s.bus_cfg,
        s.restarts,
        if s.std_answers_exact != 0 {
            "exact"
        } else {
            "widened by the receive mask"
        }
    );
    Ok(())
}

fn set_answer(iface: &str, slot: u32, frame: Option<CanFrame>) -> Result<(), String> {
    let mut b: [u8; ANSWER_LEN] = AnswerReq { slot, frame }.to_bytes();
    dev_ioctl(iface, SIOCRCANI82527ANSWER, &mut b).map_err(|e| format!("{iface}: {e}"))
}

fn run(cli: &Cli) -> Result<(), String> {
    let iface = cli.iface.as_str();
    match &cli.cmd {
        None => show(iface),
        Some(Cmd::Answer { slot, frame }) => set_answer(iface, *slot, Some(*frame)),
        Some(Cmd::Withdraw { slot }) => set_answer(iface, *slot, None),
    }
}

fn main() -> ExitCode {
    match run(&Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("i82527config: {e}");
            ExitCode::FAILURE
        }
    }
}
