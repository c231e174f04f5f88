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

use rcan_core::arb::CAN_EFF_FLAG;
use rcan_core::frame::CanFrame;
use rcan_core::i82527::{bitrate, AnswerReq, Setup, ANSWERS, ANSWER_LEN, SETUP_LEN};
use std::process::ExitCode;

use rcan_uapi::{dev_ioctl, SIOCDEVPRIVATE};

const SIOCRCANI82527GET: libc::c_ulong = SIOCDEVPRIVATE;
const SIOCRCANI82527ANSWER: libc::c_ulong = SIOCDEVPRIVATE + 2;

/// Crystal assumed when showing the bit rate.
const XTAL_HZ: u32 = 16_000_000;

/// Parses `ID#DATA` (cansend syntax, data frames only).
fn parse_frame(s: &str) -> Result<CanFrame, String> {
    let (id, data) = s.split_once('#').ok_or("frame must be ID#DATA")?;
    let can_id = u32::from_str_radix(id, 16).map_err(|e| format!("identifier {id}: {e}"))?;
    let can_id = match id.len() {
        3 if can_id <= 0x7FF => can_id,
        8 if can_id <= 0x1FFF_FFFF => can_id | CAN_EFF_FLAG,
        _ => return Err(format!("identifier {id}: 3 or 8 hex digits")),
    };
    let data = data.replace('.', "");
    if data.len() % 2 != 0 || data.len() > 16 {
        return Err(format!("data {data}: up to 8 bytes in hex"));
    }
    let mut f = CanFrame {
        can_id,
        len: (data.len() / 2) as u8,
        ..CanFrame::default()
    };
    for i in 0..data.len() / 2 {
        f.data[i] = u8::from_str_radix(&data[2 * i..2 * i + 2], 16)
            .map_err(|e| format!("data {data}: {e}"))?;
    }
    Ok(f)
}

fn parse_slot(s: &str) -> Result<u32, String> {
    match s.parse::<u32>() {
        Ok(v) if (v as usize) < ANSWERS => Ok(v),
        _ => Err(format!("slot {s}: 0..{}", ANSWERS - 1)),
    }
}

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

fn run(args: &[String]) -> Result<(), String> {
    match args {
        [iface] => show(iface),
        [iface, cmd, slot, frame] if cmd == "answer" => {
            set_answer(iface, parse_slot(slot)?, Some(parse_frame(frame)?))
        }
        [iface, cmd, slot] if cmd == "withdraw" => set_answer(iface, parse_slot(slot)?, None),
        _ => Err("usage: i82527config IFACE [answer SLOT ID#DATA | withdraw SLOT]".into()),
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("i82527config: {e}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_and_slots() {
        let f = parse_frame("123#DEAD").unwrap();
        assert_eq!(
            (f.can_id, f.len, &f.data[..2]),
            (0x123, 2, &[0xDE, 0xAD][..])
        );
        let f = parse_frame("1ABCDEF0#").unwrap();
        assert_eq!((f.can_id, f.len), (0x1ABC_DEF0 | CAN_EFF_FLAG, 0));
        assert!(parse_frame("800#").is_err());
        assert!(parse_frame("123#112233445566778899").is_err());
        assert!(parse_frame("123").is_err());
        assert_eq!(parse_slot("11"), Ok(11));
        assert!(parse_slot("12").is_err());
    }
}
