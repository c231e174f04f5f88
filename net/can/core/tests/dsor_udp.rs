// SPDX-License-Identifier: GPL-2.0
//! Tests of the `canip` UDP/IPv4 codec (`dsor_udp`): checksums checked by
//! an independent re-computation, round trips, malformed packets.

use proptest::prelude::*;
use rcan_core::dsor_udp::*;

/// Reference ones'-complement sum (RFC 1071), written differently from the
/// codec's: a u64 accumulator folded once at the end.
fn ref_sum(parts: &[&[u8]]) -> u16 {
    let mut bytes = Vec::new();
    for p in parts {
        bytes.extend_from_slice(p);
    }
    if bytes.len() % 2 == 1 {
        bytes.push(0);
    }
    let mut s: u64 = 0;
    for i in (0..bytes.len()).step_by(2) {
        s += (bytes[i] as u64) << 8 | bytes[i + 1] as u64;
    }
    while s >> 16 != 0 {
        s = (s & 0xffff) + (s >> 16);
    }
    s as u16
}

fn packet(saddr: u32, daddr: u32, sport: u16, dport: u16, id: u16, payload: &[u8]) -> Vec<u8> {
    let mut hdr = [0u8; HDR_LEN];
    build_inbound(&mut hdr, saddr, daddr, sport, dport, id, payload);
    let mut p = hdr.to_vec();
    p.extend_from_slice(payload);
    p
}

/// The pseudo header + UDP header + payload must sum to 0xffff, and the
/// IPv4 header alone too.
fn checksums_ok(p: &[u8]) -> bool {
    let udp_len = &p[24..26];
    let pseudo = [&p[12..20], &[0, 17][..], udp_len];
    let ip_ok = ref_sum(&[&p[..20]]) == 0xffff;
    let udp_ok = ref_sum(&[pseudo[0], pseudo[1], pseudo[2], &p[20..]]) == 0xffff;
    ip_ok && udp_ok && p[26..28] != [0, 0]
}

#[test]
fn known_packet_fields() {
    let p = packet(0x0a00_0001, 0xc0a8_0102, 1234, 5000, 0x4242, b"hello");
    assert_eq!(p.len(), 33);
    assert_eq!(p[0], 0x45);
    assert_eq!(&p[2..4], &[0, 33]);
    assert_eq!(&p[4..6], &[0x42, 0x42]);
    assert_eq!(&p[6..8], &[0x40, 0]); // DF
    assert_eq!(p[8], 64);
    assert_eq!(p[9], 17);
    assert_eq!(&p[12..16], &[10, 0, 0, 1]);
    assert_eq!(&p[16..20], &[192, 168, 1, 2]);
    assert_eq!(&p[20..22], &1234u16.to_be_bytes());
    assert_eq!(&p[22..24], &5000u16.to_be_bytes());
    assert_eq!(&p[24..26], &[0, 13]);
    assert!(checksums_ok(&p));
    // Header checksum of this header computed by hand-checkable reference.
    let mut h = p[..20].to_vec();
    h[10] = 0;
    h[11] = 0;
    assert_eq!(u16::from_be_bytes([p[10], p[11]]), !ref_sum(&[&h]));
}

#[test]
fn published_example_header() {
    // The textbook IPv4 header example (Wikipedia, "Internet checksum"):
    // 4500 0073 0000 4000 4011 b861 c0a8 0001 c0a8 00c7, checksum 0xb861.
    let mut p = vec![
        0x45, 0x00, 0x00, 0x73, 0x00, 0x00, 0x40, 0x00, 0x40, 0x11, 0x00, 0x00, 0xc0, 0xa8, 0x00,
        0x01, 0xc0, 0xa8, 0x00, 0xc7,
    ];
    assert_eq!(!ref_sum(&[&p]), 0xb861);
    // Our builder writes the same header for the same fields.
    let payload = vec![0u8; 0x73 - HDR_LEN];
    let mut hdr = [0u8; HDR_LEN];
    build_inbound(&mut hdr, 0xc0a8_0001, 0xc0a8_00c7, 1, 2, 0, &payload);
    assert_eq!(&hdr[10..12], &[0xb8, 0x61]);
    p[10] = 0xb8;
    p[11] = 0x61;
    assert_eq!(&hdr[..20], &p[..]);
    p.extend_from_slice(&[0x04, 0xd2, 0x13, 0x88, 0x00, 0x5f, 0x00, 0x00]);
    p.extend_from_slice(&payload);
    assert_eq!(
        parse_outbound(&p, 100),
        Ok(UdpOut {
            daddr: 0xc0a8_00c7,
            dport: 5000,
            payload_off: 28,
            payload_len: 0x73 - 28
        })
    );
    p[11] ^= 1;
    assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadHeader));
}

#[test]
fn zero_checksum_sent_as_ffff() {
    // Search a payload whose UDP checksum computes to 0: the two payload
    // bytes are chosen so the total sum is 0xffff before complementing.
    let (sa, da, sp, dp) = (0x0102_0304, 0x0506_0708, 1, 2);
    let mut hdr = [0u8; HDR_LEN];
    build_inbound(&mut hdr, sa, da, sp, dp, 0, &[0, 0]);
    // Sum without payload, with the checksum field zero.
    let base = ref_sum(&[&hdr[12..20], &[0, 17], &hdr[24..26], &hdr[20..26]]);
    let fill = !base; // base + fill = 0xffff -> checksum !0xffff = 0
    let payload = fill.to_be_bytes();
    build_inbound(&mut hdr, sa, da, sp, dp, 0, &payload);
    assert_eq!(&hdr[26..28], &[0xff, 0xff]);
    let mut p = hdr.to_vec();
    p.extend_from_slice(&payload);
    assert!(checksums_ok(&p));
}

#[test]
fn round_trip_and_max_payload() {
    let payload: Vec<u8> = (0..1000u32).map(|i| (i * 7) as u8).collect();
    let p = packet(1, 0xe000_0001, 9, 65535, 7, &payload);
    let out = parse_outbound(&p, 65535).unwrap();
    assert_eq!(out.daddr, 0xe000_0001);
    assert_eq!(out.dport, 65535);
    assert_eq!(
        &p[out.payload_off..out.payload_off + out.payload_len],
        &payload[..]
    );
    assert_eq!(parse_outbound(&p, 999), Err(UdpDrop::TooLong));
    assert!(parse_outbound(&p, 1000).is_ok());
    let big = vec![0xabu8; MAX_PAYLOAD];
    let p = packet(1, 2, 3, 4, 5, &big);
    assert!(checksums_ok(&p));
    assert_eq!(
        parse_outbound(&p, MAX_PAYLOAD).unwrap().payload_len,
        MAX_PAYLOAD
    );
}

fn fix_ip_csum(p: &mut [u8]) {
    let ihl = (p[0] & 15) as usize * 4;
    p[10] = 0;
    p[11] = 0;
    let c = !ref_sum(&[&p[..ihl]]);
    p[10..12].copy_from_slice(&c.to_be_bytes());
}

#[test]
fn malformed_rejected() {
    let good = packet(1, 2, 3, 4, 5, b"abcdef");
    assert!(parse_outbound(&good, 100).is_ok());
    assert_eq!(parse_outbound(&[], 100), Err(UdpDrop::NotIpv4));
    // IPv6 version nibble.
    let mut p = good.clone();
    p[0] = 0x65;
    assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::NotIpv4));
    // Truncated anywhere.
    for n in 1..good.len() {
        assert!(parse_outbound(&good[..n], 100).is_err(), "truncated to {n}");
    }
    // IHL < 5.
    for ihl in 0..5u8 {
        let mut p = good.clone();
        p[0] = 0x40 | ihl;
        assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadHeader));
    }
    // Total length mismatch (longer and shorter than the packet).
    for tl in [good.len() - 1, good.len() + 1] {
        let mut p = good.clone();
        p[2..4].copy_from_slice(&(tl as u16).to_be_bytes());
        fix_ip_csum(&mut p);
        assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadHeader));
    }
    // Trailing garbage after the datagram.
    let mut p = good.clone();
    p.push(0);
    assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadHeader));
    // Fragments: MF, and a non-zero offset.
    for frag in [0x2000u16, 0x0001, 0x4001, 0x3fff] {
        let mut p = good.clone();
        p[6..8].copy_from_slice(&frag.to_be_bytes());
        fix_ip_csum(&mut p);
        assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::Fragment), "{frag:#x}");
    }
    // DF alone and no flags are fine.
    let mut p = good.clone();
    p[6..8].copy_from_slice(&[0, 0]);
    fix_ip_csum(&mut p);
    assert!(parse_outbound(&p, 100).is_ok());
    // Not UDP (TCP, ICMP).
    for proto in [6u8, 1] {
        let mut p = good.clone();
        p[9] = proto;
        fix_ip_csum(&mut p);
        assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::NotUdp));
    }
    // UDP length field disagreeing with the IP length.
    for ul in [0u16, 7, 13, 15] {
        let mut p = good.clone();
        p[24..26].copy_from_slice(&ul.to_be_bytes());
        assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadLength), "{ul}");
    }
    // IP header without room for a UDP header.
    let mut p = good[..24].to_vec();
    p[2..4].copy_from_slice(&24u16.to_be_bytes());
    fix_ip_csum(&mut p);
    assert_eq!(parse_outbound(&p, 100), Err(UdpDrop::BadLength));
}

#[test]
fn ip_options_skipped() {
    let base = packet(0x0a000001, 0x0a000002, 7, 8, 1, b"xyz");
    // Insert 4 bytes of options (NOPs... end of list): IHL 6.
    let mut p = base[..20].to_vec();
    p.extend_from_slice(&[1, 1, 1, 0]);
    p.extend_from_slice(&base[20..]);
    p[0] = 0x46;
    let tl = p.len() as u16;
    p[2..4].copy_from_slice(&tl.to_be_bytes());
    fix_ip_csum(&mut p);
    let out = parse_outbound(&p, 100).unwrap();
    assert_eq!(
        (out.daddr, out.dport, out.payload_off, out.payload_len),
        (0x0a000002, 8, 32, 3)
    );
    assert_eq!(&p[32..], b"xyz");
}

#[test]
fn ipv4_addr_strings() {
    assert_eq!(parse_ipv4_addr(b"10.0.0.1"), Some(0x0a00_0001));
    assert_eq!(parse_ipv4_addr(b"255.255.255.255"), Some(0xffff_ffff));
    assert_eq!(parse_ipv4_addr(b"0.0.0.0"), Some(0));
    assert_eq!(parse_ipv4_addr(b"192.168.1.2\n"), Some(0xc0a8_0102));
    for bad in [
        &b""[..],
        b"1.2.3",
        b"1.2.3.4.5",
        b"1.2.3.256",
        b"1..3.4",
        b"1.2.3.4.",
        b".1.2.3",
        b"01.2.3.4",
        b"1.2.3.4 ",
        b" 1.2.3.4",
        b"1.2.3.+4",
        b"1.2.3.4\n\n",
        b"1000.2.3.4",
        b"a.b.c.d",
        b"\n",
    ] {
        assert_eq!(
            parse_ipv4_addr(bad),
            None,
            "{:?}",
            String::from_utf8_lossy(bad)
        );
    }
}

proptest! {
    #[test]
    fn arbitrary_bytes_never_panic(b in proptest::collection::vec(any::<u8>(), 0..80), max in 0usize..100) {
        let _ = parse_outbound(&b, max);
        let _ = parse_ipv4_addr(&b);
    }

    #[test]
    fn ipv4_looking_bytes_never_panic(mut b in proptest::collection::vec(any::<u8>(), 20..80), ihl in 0u8..16) {
        b[0] = 0x40 | ihl;
        let tl = b.len() as u16;
        b[2..4].copy_from_slice(&tl.to_be_bytes());
        let ihl_b = (ihl as usize * 4).min(b.len());
        if ihl_b >= 20 {
            b[10] = 0;
            b[11] = 0;
            let c = !ref_sum(&[&b[..ihl_b]]);
            b[10..12].copy_from_slice(&c.to_be_bytes());
        }
        if let Ok(o) = parse_outbound(&b, 1000) {
            prop_assert!(o.payload_off + o.payload_len == b.len());
        }
    }

    #[test]
    fn build_then_parse(sa in any::<u32>(), da in any::<u32>(), sp in any::<u16>(), dp in any::<u16>(),
                        id in any::<u16>(), payload in proptest::collection::vec(any::<u8>(), 0..600)) {
        let p = packet(sa, da, sp, dp, id, &payload);
        prop_assert!(checksums_ok(&p));
        let o = parse_outbound(&p, payload.len()).unwrap();
        prop_assert_eq!(o.daddr, da);
        prop_assert_eq!(o.dport, dp);
        prop_assert_eq!(&p[o.payload_off..o.payload_off + o.payload_len], &payload[..]);
        prop_assert_eq!(u16::from_be_bytes([p[20], p[21]]), sp);
    }

    #[test]
    fn addr_round_trip(a in any::<[u8; 4]>()) {
        let s = format!("{}.{}.{}.{}", a[0], a[1], a[2], a[3]);
        prop_assert_eq!(parse_ipv4_addr(s.as_bytes()), Some(u32::from_be_bytes(a)));
    }
}
