// SPDX-License-Identifier: GPL-2.0
//! canarb-demo: the thesis CAN socket API (section 5.2) on one page.
//!
//! Usage: `canarb-demo [IFACE]` (default `can0`; the interface must be up;
//! `--help` for the rest).
//!
//! Opens a `socket(PF_CAN, SOCK_RAW, CANPROTO_CAN)`, binds it to IFACE with
//! a filter that accepts every frame (mask `CAN_MASK_ANY`), sends three
//! frames with `sendto()` and reads them back with `recvfrom()`. The
//! loopback driver reflects every transmitted frame into the receive path,
//! and the sender's own filter matches, so the socket sees its own frames.
//! Exits 0 if all three came back in order and unchanged.

use clap::Parser;
use rcan_samples::CanarbDemo;
use std::process::ExitCode;
use std::time::Duration;

use rcan_uapi::{arb_ext, arb_std, describe_arb, format_frame, ArbSocket, CAN_MASK_ANY};

fn main() -> ExitCode {
    let cli = CanarbDemo::parse();
    match run(&cli.iface) {
        Ok(()) => ExitCode::SUCCESS,
        Err(why) => {
            eprintln!("canarb-demo: {why}");
            ExitCode::FAILURE
        }
    }
}

fn run(iface: &str) -> Result<(), String> {
    let ifindex = rcan_uapi::ifindex(iface).map_err(|e| format!("{iface}: {e}"))?;

    let sock = ArbSocket::new().map_err(|e| format!("socket: {e}"))?;
    // Filter: every bit "don't care", so every frame on `iface` matches.
    sock.bind(0, CAN_MASK_ANY, ifindex)
        .map_err(|e| format!("bind: {e}"))?;
    sock.set_rcvtimeo(Duration::from_secs(5))
        .map_err(|e| format!("SO_RCVTIMEO: {e}"))?;

    // (arbitration field, data). A remote frame carries no data: the length
    // of the buffer is its DLC and the bytes are ignored (and received as 0).
    let frames: [(u32, &[u8]); 3] = [
        (arb_std(0x123, false), &[0xDE, 0xAD, 0xBE, 0xEF]),
        (arb_ext(0x1ABC_DEF0, false), &[0, 1, 2, 3, 4, 5, 6, 7]),
        (arb_std(0x456, true), &[0; 4]),
    ];

    for (arb, data) in frames {
        sock.send_to(data, arb, ifindex)
            .map_err(|e| format!("sendto {}: {e}", describe_arb(arb)))?;
    }

    for (arb, data) in frames {
        let mut buf = [0u8; 8];
        let (n, from) = sock
            .recv_from(&mut buf)
            .map_err(|e| format!("recvfrom (waiting for {}): {e}", describe_arb(arb)))?;
        let got = &buf[..n];
        let name = rcan_uapi::ifname(from.ifindex).unwrap_or_else(|_| from.ifindex.to_string());
        println!("{}", format_frame(&name, from.arb, got));

        if (from.arb, got, from.ifindex) != (arb, data, ifindex) {
            return Err(format!(
                "expected {} back, got a different frame",
                format_frame(iface, arb, data)
            ));
        }
    }
    println!("all 3 frames came back unchanged");
    Ok(())
}
