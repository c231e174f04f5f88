// SPDX-License-Identifier: GPL-2.0
//! `sja1000config`: the thesis' user-space tool for SJA1000 bit timing
//! and controller setup (5.3.6), over the rcan driver's device ioctls
//! (`<linux/can/rcan_sja1000.h>`).
//!
//! ```text
//! sja1000config IFACE                        show setup, state, counters
//! sja1000config IFACE bitrate N              set the bit rate (bit/s)
//! sja1000config IFACE btr0 X btr1 Y          set the timing registers
//!               [ocr X] [cdr X]              ... and output control/clock
//! ```
//!
//! Setting needs CAP_NET_ADMIN and the interface down (`ip link set IFACE
//! down`): the driver answers EPERM and EBUSY otherwise.
//!
//! The bit timing is the same one `ip link set IFACE type can bitrate ...`
//! sets and `ip -details link show IFACE` shows (the driver keeps one);
//! btr0 0x00 btr1 0x00 stands for "none set yet" (the interface does not
//! come up until one is), in both directions.

use clap::error::ErrorKind;
use clap::Parser;
use rcan_chips::sja1000::{bitrate, timing_for, Setup, SETUP_LEN};
use sja1000config::{command, Cli, Setting};
use std::io;
use std::process::ExitCode;

use rcan_uapi::{dev_ioctl, SIOCDEVPRIVATE};

const SIOCRCANSJA1000GET: libc::c_ulong = SIOCDEVPRIVATE;
const SIOCRCANSJA1000SET: libc::c_ulong = SIOCDEVPRIVATE + 1;

fn get(iface: &str) -> io::Result<Setup> {
    let mut b = [0u8; SETUP_LEN];
    dev_ioctl(iface, SIOCRCANSJA1000GET, &mut b)?;
    Ok(Setup::from_bytes(&b))
}

fn show(iface: &str, s: &Setup) {
    let state = ["error-active", "error-warning", "error-passive", "bus-off"]
        .get(usize::from(s.state))
        .unwrap_or(&"?");
    let rate = if s.btr0 == 0 && s.btr1 == 0 {
        "no bit timing set".to_string()
    } else {
        format!("{} bit/s", bitrate(s.btr0, s.btr1, s.xtal_hz.max(1)))
    };
    println!(
        "{iface}: btr0 {:#04x} btr1 {:#04x} ({rate} at {} Hz) ocr {:#04x} cdr {:#04x}",
        s.btr0, s.btr1, s.xtal_hz, s.ocr, s.cdr
    );
    println!(
        "{iface}: state {state}, rxerr {}, txerr {}, restarts {}",
        s.rxerr, s.txerr, s.restarts
    );
}

fn run(cli: &Cli, settings: &[Setting]) -> Result<(), String> {
    let iface = cli.iface.as_str();
    let mut s = get(iface).map_err(|e| format!("{iface}: {e}"))?;
    if settings.is_empty() {
        show(iface, &s);
        return Ok(());
    }
    for setting in settings {
        match *setting {
            Setting::Bitrate(rate) => {
                let (b0, b1) = timing_for(rate, s.xtal_hz).ok_or_else(|| {
                    format!(
                        "{rate} bit/s cannot be set exactly with a {} Hz crystal",
                        s.xtal_hz
                    )
                })?;
                s.btr0 = b0;
                s.btr1 = b1;
            }
            Setting::Btr0(v) => s.btr0 = v,
            Setting::Btr1(v) => s.btr1 = v,
            Setting::Ocr(v) => s.ocr = v,
            Setting::Cdr(v) => s.cdr = v,
        }
    }
    let mut b = s.to_bytes();
    dev_ioctl(iface, SIOCRCANSJA1000SET, &mut b).map_err(|e| format!("{iface}: {e}"))?;
    show(iface, &get(iface).map_err(|e| format!("{iface}: {e}"))?);
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let settings = cli
        .parsed_settings()
        .unwrap_or_else(|e| command().error(ErrorKind::InvalidValue, e).exit());
    match run(&cli, &settings) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("sja1000config: {e}");
            ExitCode::FAILURE
        }
    }
}
