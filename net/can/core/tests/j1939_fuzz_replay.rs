// SPDX-License-Identifier: GPL-2.0
//! The cargo-fuzz check of the J1939 core (`fuzz/j1939_check.rs`) on its
//! seeds and on proptest inputs, so that `make check` runs it too
//! (cargo-fuzz needs a nightly compiler). Not coverage-guided: the seeds
//! below walk each protocol path once (a whole TP reception, an ETP send
//! with DPO and a retransmit, BAM both ways, holds, malformed control
//! frames, address claims), then random byte strings and byte strings
//! built from plausible records (control frames with real commands and
//! the session's PGN, data packets with nearby sequence numbers, echoes,
//! time steps, sends) reach the deeper states.

#[path = "../fuzz/j1939_check.rs"]
mod j1939_check;

use proptest::prelude::*;

const US: u8 = 0x20;
const PEER: u8 = 0x42;
/// The check's send PGN (0xEF00), little endian, as control frames carry it.
const PGN: [u8; 3] = [0x00, 0xEF, 0x00];

/// `kind` 0 TP.CM, 1 TP.DT, 2 ETP.CM, 3 ETP.DT, 4 AC, 5 request; to us.
fn frame(kind: u8, d: &[u8]) -> Vec<u8> {
    let mut r = vec![0, 0x80 | 6 << 5 & 0x60 | kind, PEER, US, d.len() as u8];
    r.extend_from_slice(d);
    r
}

fn ctl(cmd: [u8; 5]) -> Vec<u8> {
    let mut d = cmd.to_vec();
    d.extend_from_slice(&PGN);
    frame(0, &d)
}

fn etp_ctl(cmd: [u8; 5]) -> Vec<u8> {
    let mut d = cmd.to_vec();
    d.extend_from_slice(&PGN);
    frame(2, &d)
}

fn dt(kind: u8, seq: u8) -> Vec<u8> {
    frame(kind, &[seq, 1, 2, 3, 4, 5, 6, 7])
}

fn time(dt: u8) -> Vec<u8> {
    vec![2, dt]
}

/// A send of `n` bytes to the last peer (seen in an earlier frame).
fn send(n: u16) -> Vec<u8> {
    let b = n.to_be_bytes();
    vec![3, b[0], b[1]]
}

fn seeds() -> Vec<Vec<u8>> {
    let head = |buf: u8| vec![255, 0, buf, US];
    let mut v = vec![];
    // A TP reception of 20 bytes, then a duplicate RTS after it.
    let mut s = head(2);
    s.extend(ctl([0x10, 20, 0, 3, 255]));
    s.extend((1..=3).flat_map(|q| dt(1, q)));
    s.extend(ctl([0x10, 20, 0, 3, 255]));
    s.extend(time(250));
    v.push(s);
    // A TP send with CTS, echo, retransmit, hold, EOMA.
    let mut s = head(2);
    s.extend(ctl([0xFF, 3, 0xFF, 0xFF, 0xFF]));
    s.extend(send(30));
    s.extend(ctl([0x11, 2, 1, 0xFF, 0xFF]));
    s.push(1);
    s.extend(ctl([0x11, 0, 3, 0xFF, 0xFF]));
    s.extend(time(100));
    s.extend(ctl([0x11, 0, 3, 0xFF, 0xFF]));
    s.extend(ctl([0x11, 3, 2, 0xFF, 0xFF]));
    s.push(1);
    s.extend(ctl([0x13, 30, 0, 5, 0xFF]));
    v.push(s);
    // An ETP send: CTS, DPO and data, a refusal and a retry, a timeout.
    let mut s = head(0);
    s.extend(ctl([0xFF, 3, 0xFF, 0xFF, 0xFF]));
    s.extend(vec![3 | 8, 0x02, 0x58]);
    s.extend(etp_ctl([0x15, 10, 1, 0, 0]));
    s.extend([5, 4]);
    s.extend(time(20));
    s.push(1);
    s.extend(time(255));
    v.push(s);
    // An ETP reception with good and bad DPOs.
    let mut s = head(4);
    s.extend(etp_ctl([0x14, 0xD0, 7, 0, 0]));
    s.extend(etp_ctl([0x16, 255, 0, 0, 0]));
    s.extend((1..=255).flat_map(|q| dt(3, q)));
    s.extend(etp_ctl([0x16, 5, 9, 0, 0]));
    v.push(s);
    // BAM out and in; a BAM to unicast.
    let mut s = head(1);
    s.extend(ctl([0xFF, 3, 0xFF, 0xFF, 0xFF]));
    s.extend(vec![3 | 16, 0, 12]);
    s.extend(time(50));
    s.extend(time(50));
    s.push(1);
    let mut bam = vec![0, 6 << 5, PEER, 0xFF, 8, 0x20, 9, 0, 2, 0xFF];
    bam.extend_from_slice(&PGN);
    s.extend(bam);
    s.extend([0, 1, PEER, 0xFF, 8, 1, 1, 1, 1, 1, 1, 1, 1]);
    s.extend(ctl([0x20, 9, 0, 2, 0xFF]));
    v.push(s);
    // Address claims and sends by NAME.
    let mut s = head(0);
    s.extend(frame(4, &7u64.to_le_bytes()));
    s.extend([7, 7]);
    s.extend(time(250));
    s.extend([7, 7]);
    s.extend(frame(4, &3u64.to_le_bytes()));
    s.extend([6, 7 | 8, 7]);
    v.push(s);
    // Malformed control frames: short, unknown commands, zero counts.
    let mut s = head(3);
    s.extend(frame(0, &[0x10, 20]));
    s.extend(ctl([0x10, 0, 0, 0, 0]));
    s.extend(ctl([0x10, 20, 0, 3, 0]));
    s.extend(ctl([0x42, 0, 0, 0, 0]));
    s.extend(etp_ctl([0x14, 0xFF, 0xFF, 0xFF, 0xFF]));
    s.extend(ctl([0x11, 0, 0, 0, 0]));
    s.extend(dt(1, 0));
    s.extend(frame(1, &[1, 2]));
    v.push(s);
    v
}

#[test]
fn seeds_pass() {
    for s in seeds() {
        j1939_check::check(&s);
    }
}

fn record() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        // Control frames with a real command, mostly the check's PGN.
        4 => (prop::sample::select(vec![0x10u8, 0x11, 0x13, 0x20, 0x14, 0x15, 0x16, 0x17, 0xFF]),
              any::<[u8; 4]>(), any::<bool>(), any::<bool>())
            .prop_map(|(cmd, b, etp, other_pgn)| {
                let mut d = vec![cmd, b[0] % 40, b[1] % 4, b[2] % 8, b[3]];
                d.extend_from_slice(if other_pgn { &[0, 0xEE, 0] } else { &PGN });
                frame(if etp { 2 } else { 0 }, &d)
            }),
        4 => (1u8..12, any::<bool>()).prop_map(|(q, etp)| dt(if etp { 3 } else { 1 }, q)),
        2 => Just(vec![1u8]),
        2 => prop_oneof![0u8..60, 200u8..=212].prop_map(time),
        1 => (9u16..300).prop_map(send),
        1 => Just(vec![3 | 16, 0, 20]),
        1 => Just(vec![4u8]),
        1 => (0u8..16).prop_map(|j| vec![5 | (j & 1) << 3 | j << 4]),
        1 => Just(vec![6u8]),
        1 => (1u8..5).prop_map(|n| {
            let mut r = frame(4, &u64::from(n).to_le_bytes());
            r.extend([7, n]);
            r
        }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn random_bytes(input in prop::collection::vec(any::<u8>(), 0..600)) {
        j1939_check::check(&input);
    }

}

proptest! {
    // Fewer cases: each is longer (about 6 ms in a debug build).
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn plausible_records(buf in 0u8..6, block in 1u8..=255, delay in 0u8..3,
                         recs in prop::collection::vec(record(), 0..120)) {
        let mut input = vec![block, delay, buf, US];
        input.extend(ctl([0xFF, 3, 0xFF, 0xFF, 0xFF]));
        input.extend(recs.concat());
        j1939_check::check(&input);
    }
}
