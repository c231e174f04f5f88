// SPDX-License-Identifier: GPL-2.0
//! UDP/IPv4 codec of the `canip` network device (thesis 5.3.3, DSOR UDP/IP
//! messages).
//!
//! `canip` carries UDP datagrams over DSOR: on transmit it takes the IPv4
//! packet the stack hands it, keeps only the destination address, the
//! destination port and the UDP payload, and sends them as a DSOR UDP/IP
//! message (header DLC 8). On receive it rebuilds an IPv4 + UDP header in
//! front of the DSOR message's payload. This file is that codec; it has no
//! state. Addresses are numbers: `a.b.c.d` is `a << 24 | b << 16 | c << 8 | d`,
//! which is also the order of the bytes on the wire.

/// Bytes of the IPv4 (20, no options) plus UDP (8) header [`build_inbound`] writes.
pub const HDR_LEN: usize = 28;
/// Largest payload an IPv4 packet can carry in one UDP datagram without IP
/// options (total length is a 16-bit field).
pub const MAX_PAYLOAD: usize = 65535 - HDR_LEN;
/// IP protocol number of UDP.
pub const IPPROTO_UDP: u8 = 17;

const IPV4_MIN_HDR: usize = 20;
const UDP_HDR: usize = 8;
const TTL: u8 = 64;
const FLAG_DF: u16 = 0x4000;
const FLAG_MF: u16 = 0x2000;
const FRAG_OFFSET_MASK: u16 = 0x1fff;

/// What `canip` sends for one outbound UDP datagram.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct UdpOut {
    /// Destination IPv4 address (`a.b.c.d` = `a << 24 | ...`).
    pub daddr: u32,
    /// Destination UDP port.
    pub dport: u16,
    /// Offset of the UDP payload in the packet.
    pub payload_off: usize,
    /// Length of the UDP payload.
    pub payload_len: usize,
}

/// Why an outbound packet cannot be sent as a DSOR UDP/IP message.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum UdpDrop {
    /// Empty, or the version field is not 4.
    NotIpv4,
    /// IHL below 5, header longer than the packet, total length different
    /// from the packet length, or a wrong header checksum.
    BadHeader,
    /// A fragment (MF set or a non-zero fragment offset): DSOR carries whole
    /// datagrams only.
    Fragment,
    /// Not UDP.
    NotUdp,
    /// UDP header truncated, or its length field disagrees with the IP
    /// total length.
    BadLength,
    /// The UDP payload is longer than `max_payload`.
    TooLong,
}

fn be16(b: &[u8], at: usize) -> u16 {
    u16::from_be_bytes([b[at], b[at + 1]])
}

fn be32(b: &[u8], at: usize) -> u32 {
    u32::from_be_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Adds `data` to a ones'-complement running sum as big-endian 16-bit
/// words, an odd last byte padded with zero (RFC 1071).
fn sum16(mut acc: u32, data: &[u8]) -> u32 {
    let mut words = data.chunks_exact(2);
    for w in &mut words {
        acc += u32::from(u16::from_be_bytes([w[0], w[1]]));
        // Fold early so that 64 KiB of payload cannot overflow.
        acc = (acc & 0xffff) + (acc >> 16);
    }
    if let [last] = words.remainder() {
        acc += u32::from(*last) << 8;
        acc = (acc & 0xffff) + (acc >> 16);
    }
    acc
}

fn fold(mut acc: u32) -> u16 {
    while acc > 0xffff {
        acc = (acc & 0xffff) + (acc >> 16);
    }
    acc as u16
}

/// Parses an outbound IPv4 packet handed to `canip`'s transmit (the packet
/// starts at the IPv4 header). IP options are allowed and skipped; the UDP
/// checksum is not checked (the local stack made it, the receiving `canip`
/// computes a new one).
pub fn parse_outbound(pkt: &[u8], max_payload: usize) -> Result<UdpOut, UdpDrop> {
    let Some(&vihl) = pkt.first() else {
        return Err(UdpDrop::NotIpv4);
    };
    if vihl >> 4 != 4 {
        return Err(UdpDrop::NotIpv4);
    }
    let ihl = usize::from(vihl & 0x0f) * 4;
    if ihl < IPV4_MIN_HDR || pkt.len() < ihl {
        return Err(UdpDrop::BadHeader);
    }
    let total = usize::from(be16(pkt, 2));
    if total != pkt.len() {
        return Err(UdpDrop::BadHeader);
    }
    if fold(sum16(0, &pkt[..ihl])) != 0xffff {
        return Err(UdpDrop::BadHeader);
    }
    let frag = be16(pkt, 6);
    if frag & FLAG_MF != 0 || frag & FRAG_OFFSET_MASK != 0 {
        return Err(UdpDrop::Fragment);
    }
    if pkt[9] != IPPROTO_UDP {
        return Err(UdpDrop::NotUdp);
    }
    let udp = &pkt[ihl..];
    if udp.len() < UDP_HDR || usize::from(be16(udp, 4)) != udp.len() {
        return Err(UdpDrop::BadLength);
    }
    let payload_len = udp.len() - UDP_HDR;
    if payload_len > max_payload {
        return Err(UdpDrop::TooLong);
    }
    Ok(UdpOut {
        daddr: be32(pkt, 16),
        dport: be16(udp, 2),
        payload_off: ihl + UDP_HDR,
        payload_len,
    })
}

/// Writes an IPv4 header (20 bytes, no options, TTL 64, DF set, the given
/// identification) and a UDP header in front of `payload` into `hdr`, with
/// a correct IPv4 header checksum and UDP checksum (a computed 0 is sent as
/// 0xffff, RFC 768).
///
/// `payload.len()` must not exceed [`MAX_PAYLOAD`]: the caller refuses
/// longer DSOR messages (status TOO_LONG). A longer payload is a caller bug;
/// the length fields are then truncated to 16 bits (no panic).
pub fn build_inbound(
    hdr: &mut [u8; HDR_LEN],
    saddr: u32,
    daddr: u32,
    sport: u16,
    dport: u16,
    ip_id: u16,
    payload: &[u8],
) {
    let udp_len = (UDP_HDR + payload.len()) as u16;
    let total = (HDR_LEN + payload.len()) as u16;
    hdr[0] = 0x45;
    hdr[1] = 0;
    hdr[2..4].copy_from_slice(&total.to_be_bytes());
    hdr[4..6].copy_from_slice(&ip_id.to_be_bytes());
    hdr[6..8].copy_from_slice(&FLAG_DF.to_be_bytes());
    hdr[8] = TTL;
    hdr[9] = IPPROTO_UDP;
    hdr[10..12].copy_from_slice(&[0, 0]);
    hdr[12..16].copy_from_slice(&saddr.to_be_bytes());
    hdr[16..20].copy_from_slice(&daddr.to_be_bytes());
    let ip_csum = !fold(sum16(0, &hdr[..IPV4_MIN_HDR]));
    hdr[10..12].copy_from_slice(&ip_csum.to_be_bytes());

    hdr[20..22].copy_from_slice(&sport.to_be_bytes());
    hdr[22..24].copy_from_slice(&dport.to_be_bytes());
    hdr[24..26].copy_from_slice(&udp_len.to_be_bytes());
    hdr[26..28].copy_from_slice(&[0, 0]);
    // Pseudo header: source, destination, zero, protocol, UDP length.
    let mut acc = sum16(0, &hdr[12..20]);
    acc = sum16(acc, &[0, IPPROTO_UDP]);
    acc = sum16(acc, &udp_len.to_be_bytes());
    acc = sum16(acc, &hdr[20..28]);
    acc = sum16(acc, payload);
    let udp_csum = match !fold(acc) {
        0 => 0xffff,
        c => c,
    };
    hdr[26..28].copy_from_slice(&udp_csum.to_be_bytes());
}

/// Parses a dotted-quad IPv4 address `a.b.c.d` (a module parameter):
/// exactly four decimal fields 0..=255 of one to three digits, no leading
/// zeros (so `010` cannot mean octal 8 as in `inet_aton`), no signs or
/// spaces. One trailing newline is accepted (sysfs writes end in one).
pub fn parse_ipv4_addr(s: &[u8]) -> Option<u32> {
    let s = match s {
        [rest @ .., b'\n'] => rest,
        _ => s,
    };
    let mut addr = 0u32;
    let mut fields = 0;
    for field in s.split(|&c| c == b'.') {
        if field.is_empty() || field.len() > 3 || (field.len() > 1 && field[0] == b'0') {
            return None;
        }
        let mut v = 0u32;
        for &c in field {
            if !c.is_ascii_digit() {
                return None;
            }
            v = v * 10 + u32::from(c - b'0');
        }
        if v > 255 {
            return None;
        }
        fields += 1;
        if fields > 4 {
            return None;
        }
        addr = addr << 8 | v;
    }
    if fields == 4 {
        Some(addr)
    } else {
        None
    }
}
