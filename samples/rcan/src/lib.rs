// SPDX-License-Identifier: GPL-2.0
//! The command lines of the sample programs, apart from the programs so
//! that `rcan-mangen` builds their man pages and shell completions from
//! the same definitions.

use clap::Parser;

/// The thesis CAN socket API (section 5.2) on one page.
///
/// Opens a socket(PF_CAN, SOCK_RAW, CANPROTO_CAN), binds it to IFACE with
/// a filter that accepts every frame, sends three frames with sendto()
/// and reads them back with recvfrom(): the device's echo brings the
/// socket its own frames. Exits 0 if all three came back in order and
/// unchanged, 1 otherwise. Needs the rcan stack loaded and IFACE up.
#[derive(Parser, Debug)]
#[command(name = "canarb-demo", version, about, long_about)]
pub struct CanarbDemo {
    /// The CAN interface (up, with echo: canloop or a controller).
    #[arg(default_value = "can0")]
    pub iface: String,
}

/// The command definition of `canarb-demo`, for man pages and completions.
pub fn canarb_demo_command() -> clap::Command {
    <CanarbDemo as clap::CommandFactory>::command()
}
