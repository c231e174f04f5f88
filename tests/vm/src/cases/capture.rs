// SPDX-License-Identifier: GPL-2.0
//! Packet-socket visibility: tcpdump (Debian's, unchanged) captures CAN
//! frames on can0 into a pcap file, reads it back, and the file holds the
//! frames sent, as LINKTYPE_CAN_SOCKETCAN records.

use std::fs;

use super::{portable_table, raw1};
use crate::canraw::{self, ext, rtr_std, show, show_wire, std, wire, CAN_MTU, CAN_RTR_FLAG};
use crate::check::{ensure, OrFail, TestResult};
use crate::ctx::Ctx;
use crate::tools::{self, TempDir, TOOL_LIMIT};
use crate::Test;

pub const TESTS: &[Test] = portable_table![canutils_tcpdump_pcap];

/// LINKTYPE_CAN_SOCKETCAN.
const LINKTYPE_CAN_SOCKETCAN: u32 = 227;

/// The link type and the records of a pcap file (microsecond or nanosecond
/// timestamps, this machine's byte order, as tcpdump -w writes it).
fn parse_pcap(b: &[u8]) -> Result<(u32, Vec<Vec<u8>>), String> {
    let u32_at = |i: usize| -> Result<u32, String> {
        b.get(i..i + 4)
            .map(|s| u32::from_ne_bytes(s.try_into().unwrap()))
            .ok_or_else(|| format!("pcap file of {} bytes is cut short at {i}", b.len()))
    };
    let magic = u32_at(0)?;
    ensure!(
        magic == 0xA1B2_C3D4 || magic == 0xA1B2_3C4D,
        "not a pcap file in this byte order (magic {magic:#010x})"
    );
    let linktype = u32_at(20)?;
    let mut recs = Vec::new();
    let mut at = 24;
    while at < b.len() {
        let incl = u32_at(at + 8)? as usize;
        let data = b
            .get(at + 16..at + 16 + incl)
            .ok_or_else(|| format!("pcap record at {at} of {incl} bytes is cut short"))?;
        recs.push(data.to_vec());
        at += 16 + incl;
    }
    Ok((linktype, recs))
}

/// The packets of `tcpdump -r` output: a line per packet (tcpdump 4.99 has
/// no CAN dissector: `TIME UNSUPPORTED`), then its bytes in hex lines like
/// `\t0x0000:  0000 0123 0400 0000 dead beef 0000 0000  ...#....`.
fn parse_tcpdump_hex(out: &str) -> Result<Vec<Vec<u8>>, String> {
    let mut packets: Vec<Vec<u8>> = Vec::new();
    for line in out.lines().filter(|l| !l.trim().is_empty()) {
        if !line.starts_with(char::is_whitespace) {
            packets.push(Vec::new());
            continue;
        }
        let bad = || format!("unexpected tcpdump line {line:?}");
        let (_, rest) = line.split_once(':').ok_or_else(bad)?;
        // Groups of 4 hex digits, single-spaced; two spaces start the ASCII.
        let hex = rest.trim_start().split("  ").next().unwrap_or("");
        let packet = packets.last_mut().ok_or_else(bad)?;
        for group in hex.split(' ') {
            ensure!(group.len() % 2 == 0, "{}", bad());
            for i in (0..group.len()).step_by(2) {
                packet.push(u8::from_str_radix(&group[i..i + 2], 16).map_err(|_| bad())?);
            }
        }
    }
    Ok(packets)
}

/// `tcpdump -i can0 -Q out -c 3 -w FILE` captures a standard, an extended
/// and a remote frame sent by a CAN_RAW socket; `tcpdump -r FILE` reads
/// three packets of link type CAN_SOCKETCAN with the bytes the file holds;
/// the records are the frames, with the identifier in network byte order
/// (LINKTYPE_CAN_SOCKETCAN).
///
/// `-Q out`: the outgoing copy is the one every CAN device shows exactly
/// once. Mainline's vcan also hands its echo to packet sockets as an
/// incoming packet, devices whose echo is marked PACKET_LOOPBACK (real
/// controllers) do not.
fn canutils_tcpdump_pcap(ctx: &mut Ctx) -> TestResult {
    let idx = raw1(ctx)?;
    let tx = canraw::open(idx)?;
    let dir = TempDir::new("tcpdump")?;
    let pcap = dir.path().join("can0.pcap");
    let pcap_s = pcap.to_string_lossy().into_owned();
    let frames = [
        std(0x123, &[0xDE, 0xAD, 0xBE, 0xEF]),
        ext(0x1234_5678, &[1, 2, 3, 4, 5, 6, 7, 8]),
        rtr_std(0x7FF, 2),
    ];
    let count = frames.len().to_string();
    // -Z root: Debian's tcpdump may drop to its own user before writing.
    let mut cap = tools::spawn(
        "tcpdump",
        &[
            "-i", "can0", "-Q", "out", "-n", "-c", &count, "-Z", "root", "-w", &pcap_s,
        ],
        None,
    )?;
    cap.wait_stderr("listening on")?;
    for f in &frames {
        canraw::send(&tx, f)?;
    }
    let out = cap.finish(TOOL_LIMIT)?;
    ensure!(
        out.status.success(),
        "tcpdump -w: {}: {}",
        out.status,
        out.stderr.trim()
    );

    let rd = tools::run_ok("tcpdump", &["-r", &pcap_s, "-n"])?;
    ensure!(
        rd.stderr.contains("CAN_SOCKETCAN"),
        "tcpdump -r does not report link type CAN_SOCKETCAN: {:?}",
        rd.stderr.trim()
    );
    let dumped = parse_tcpdump_hex(&rd.stdout)?;
    ensure!(
        dumped.len() == frames.len(),
        "tcpdump -r listed {} packets, expected {}: {:?}",
        dumped.len(),
        frames.len(),
        rd.stdout
    );

    let bytes = fs::read(&pcap).or_fail(pcap.display())?;
    let (linktype, recs) = parse_pcap(&bytes)?;
    ensure!(
        linktype == LINKTYPE_CAN_SOCKETCAN,
        "pcap link type {linktype}, expected {LINKTYPE_CAN_SOCKETCAN}"
    );
    ensure!(
        recs.len() == frames.len(),
        "pcap has {} records, expected {}",
        recs.len(),
        frames.len()
    );
    ensure!(
        dumped == recs,
        "tcpdump -r shows other bytes than the file holds: {dumped:02X?} vs {recs:02X?}"
    );
    for (i, (r, f)) in recs.iter().zip(&frames).enumerate() {
        let w = wire(f);
        let mut host = r.clone();
        if host.len() >= 4 {
            // LINKTYPE_CAN_SOCKETCAN has the identifier big-endian.
            let id = u32::from_be_bytes(host[..4].try_into().unwrap());
            host[..4].copy_from_slice(&id.to_ne_bytes());
        }
        let c: &libc::can_frame = f.as_ref();
        // A remote frame's data bytes are not compared: there are none.
        let data_len = if c.can_id & CAN_RTR_FLAG != 0 {
            0
        } else {
            usize::from(c.can_dlc)
        };
        ensure!(
            host.len() == CAN_MTU
                && host[..5] == w[..5]
                && host[8..8 + data_len] == w[8..8 + data_len],
            "pcap record {i}: {} (bytes {:02X?}), expected {}",
            show_wire(&host),
            r,
            show(f)
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcap_records() {
        let mut b = Vec::new();
        for w in [0xA1B2_C3D4u32, 0x0004_0002, 0, 0, 262_144, 227] {
            b.extend(w.to_ne_bytes());
        }
        for w in [1u32, 2, 3, 3] {
            b.extend(w.to_ne_bytes());
        }
        b.extend([7, 8, 9]);
        let out = "19:34:31.702000 UNSUPPORTED\n\t0x0000:  0000 0123 0400 0000 dead beef 0000 0000  ...#............\n19:34:31.703619 UNSUPPORTED\n\t0x0000:  4000 07ff 02  @....\n";
        let p = parse_tcpdump_hex(out).unwrap();
        assert_eq!(p.len(), 2);
        assert_eq!(&p[0][..8], &[0, 0, 1, 0x23, 4, 0, 0, 0]);
        assert_eq!(p[1], vec![0x40, 0, 7, 0xFF, 2]);
        assert!(parse_tcpdump_hex("\t0x0000:  00").is_err());
        let (lt, recs) = parse_pcap(&b).unwrap();
        assert_eq!(lt, 227);
        assert_eq!(recs, vec![vec![7, 8, 9]]);
        b.pop();
        assert!(parse_pcap(&b).is_err());
    }
}
