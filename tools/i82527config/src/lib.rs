// SPDX-License-Identifier: GPL-2.0
//! The command line of `i82527config`, apart from the program so that
//! `rcan-mangen` builds its man page and shell completions from the same
//! definition.

use clap::{CommandFactory, Parser, Subcommand};
use rcan_chips::i82527::ANSWERS;
use rcan_core::arb::CAN_EFF_FLAG;
use rcan_core::frame::CanFrame;

/// Show the setup of an rcan Intel 82527 interface and publish the
/// answers its message objects give to remote frames
/// (Documentation/networking/rcan/i82527.rst).
///
/// With only IFACE, prints the bit timing, the bus configuration, the
/// error state and the restarts. Publishing and withdrawing need
/// CAP_NET_ADMIN.
#[derive(Parser, Debug)]
#[command(name = "i82527config", version, about, long_about)]
#[command(
    after_help = "Examples:\n  i82527config can1\n  i82527config can1 answer 0 123#DEADBEEF\n  i82527config can1 withdraw 0"
)]
pub struct Cli {
    /// The rcan 82527 interface, e.g. can1.
    pub iface: String,
    /// What to change; nothing shows the setup.
    #[command(subcommand)]
    pub cmd: Option<Cmd>,
}

/// What `i82527config` changes.
#[derive(Subcommand, Debug)]
pub enum Cmd {
    /// Publish the data frame answer slot SLOT gives to a remote frame
    /// with its identifier.
    Answer {
        /// The answer slot, 0 to 11.
        #[arg(value_parser = parse_slot)]
        slot: u32,
        /// The answer as cansend writes it: ID#DATA, three hex digits for
        /// a standard identifier or eight for an extended one, then up to
        /// eight data bytes in hex.
        #[arg(value_name = "ID#DATA", value_parser = parse_frame)]
        frame: CanFrame,
    },
    /// Withdraw the answer of slot SLOT.
    Withdraw {
        /// The answer slot, 0 to 11.
        #[arg(value_parser = parse_slot)]
        slot: u32,
    },
}

/// The command definition, for man pages and completions.
pub fn command() -> clap::Command {
    Cli::command()
}

/// Parses `ID#DATA` (cansend syntax, data frames only).
pub fn parse_frame(s: &str) -> Result<CanFrame, String> {
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

/// Parses an answer slot number, 0 to 11.
pub fn parse_slot(s: &str) -> Result<u32, String> {
    match s.parse::<u32>() {
        Ok(v) if (v as usize) < ANSWERS => Ok(v),
        _ => Err(format!("slot {s}: 0..{}", ANSWERS - 1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

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
        command().debug_assert();
        let parse = |a: &[&str]| {
            Cli::try_parse_from(std::iter::once("i82527config").chain(a.iter().copied()))
        };
        assert!(parse(&["can1"]).unwrap().cmd.is_none());
        assert!(matches!(
            parse(&["can1", "withdraw", "3"]).unwrap().cmd,
            Some(Cmd::Withdraw { slot: 3 })
        ));
        assert!(parse(&["can1", "answer", "12", "123#"]).is_err());
        assert!(parse(&["can1", "answer", "1"]).is_err());
    }
}
