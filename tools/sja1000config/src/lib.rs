// SPDX-License-Identifier: GPL-2.0
//! The command line of `sja1000config`, apart from the program so that
//! `rcan-mangen` builds its man page and shell completions from the same
//! definition.

use clap::{CommandFactory, Parser};

/// Show and set the bit timing and output control of an rcan SJA1000
/// interface (the thesis' sja1000config, section 5.3.6).
///
/// With only IFACE, prints the controller setup, the error state and the
/// error counters. With settings, writes them and prints the new setup.
/// Setting needs CAP_NET_ADMIN and the interface down (`ip link set IFACE
/// down`): the driver answers EPERM and EBUSY otherwise.
#[derive(Parser, Debug)]
#[command(name = "sja1000config", version, about, long_about)]
#[command(
    after_help = "Settings:\n  bitrate N        bit rate in bit/s, timing computed for the card's crystal\n  btr0 X btr1 Y    the bus timing registers (decimal or 0x hex)\n  ocr X            the output control register\n  cdr X            the clock divider register\n\nExamples:\n  sja1000config can0\n  sja1000config can0 bitrate 500000\n  sja1000config can0 btr0 0x00 btr1 0x1c"
)]
pub struct Cli {
    /// The rcan SJA1000 interface, e.g. can0.
    pub iface: String,
    /// Settings to write, as NAME VALUE pairs (see below).
    #[arg(value_name = "NAME VALUE")]
    pub settings: Vec<String>,
}

/// One setting of the command line.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Setting {
    /// `bitrate N`.
    Bitrate(u32),
    /// `btr0 X`.
    Btr0(u8),
    /// `btr1 X`.
    Btr1(u8),
    /// `ocr X`.
    Ocr(u8),
    /// `cdr X`.
    Cdr(u8),
}

fn parse_u8(s: &str) -> Result<u8, String> {
    let v = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u8::from_str_radix(h, 16),
        None => s.parse(),
    };
    v.map_err(|_| format!("not a byte value: {s:?}"))
}

impl Cli {
    /// The settings, checked: NAME VALUE pairs with known names and
    /// values in range. A usage error otherwise.
    pub fn parsed_settings(&self) -> Result<Vec<Setting>, String> {
        if !self.settings.len().is_multiple_of(2) {
            return Err(format!(
                "{} needs a value",
                self.settings.last().map_or("", |s| s.as_str())
            ));
        }
        self.settings
            .chunks(2)
            .map(|kv| {
                let (k, v) = (kv[0].as_str(), kv[1].as_str());
                Ok(match k {
                    "bitrate" => Setting::Bitrate(
                        v.parse()
                            .ok()
                            .filter(|&r| r > 0)
                            .ok_or_else(|| format!("bad bit rate {v:?}"))?,
                    ),
                    "btr0" => Setting::Btr0(parse_u8(v)?),
                    "btr1" => Setting::Btr1(parse_u8(v)?),
                    "ocr" => Setting::Ocr(parse_u8(v)?),
                    "cdr" => Setting::Cdr(parse_u8(v)?),
                    other => return Err(format!("unknown setting {other:?}")),
                })
            })
            .collect()
    }
}

/// The command definition, for man pages and completions.
pub fn command() -> clap::Command {
    Cli::command()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cli(args: &[&str]) -> Cli {
        Cli::try_parse_from(std::iter::once("sja1000config").chain(args.iter().copied())).unwrap()
    }

    #[test]
    fn settings() {
        assert_eq!(cli(&["can0"]).parsed_settings(), Ok(vec![]));
        assert_eq!(
            cli(&["can0", "bitrate", "500000", "ocr", "0xda"]).parsed_settings(),
            Ok(vec![Setting::Bitrate(500_000), Setting::Ocr(0xda)])
        );
        assert!(cli(&["can0", "btr0"]).parsed_settings().is_err());
        assert!(cli(&["can0", "btr0", "256"]).parsed_settings().is_err());
        assert!(cli(&["can0", "bitrate", "0"]).parsed_settings().is_err());
        assert!(cli(&["can0", "speed", "1"]).parsed_settings().is_err());
        command().debug_assert();
    }
}
