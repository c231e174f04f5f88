// SPDX-License-Identifier: GPL-2.0
//! The DSOR receive-path fuzz check, shared by the cargo-fuzz target
//! (`fuzz_targets/dsor_rx.rs`, coverage-guided) and the host test
//! `tests/dsor_rx_fuzz_replay.rs` (proptest inputs, run by `make check`):
//! arbitrary frames into a `Reassembler` (and into a sender's `on_ack`);
//! nothing may panic, and the limits and delivery invariants must hold.
//!
//! Input: records of `id (4 bytes, LE) | dlc (1 byte, low 4 bits, max 8) |
//! data (dlc bytes) | dt (1 byte, ms)`; `dt` 255 also fires the timers.

use rcan_core::dsor_rx::{Limits, Reassembler};
use rcan_core::dsor_tx::Transfer;
use rcan_core::dsor_wire::{Ack, AckStatus, DsorId, FrameType, Header, MsgKind, Timers};

const LOCAL: u8 = 1;

/// Runs one input through the receiver and a sender; panics on a broken
/// invariant.
pub fn check(input: &[u8]) {
    let tm = Timers {
        ack_timeout_ms: 10,
        max_retx: 3,
        reasm_timeout_ms: 100,
    };
    let limits = Limits {
        max_len: 600,
        max_per_peer: 2,
        max_bytes_total: 1000,
    };
    let mut rx: Reassembler<Vec<u8>, 4> = Reassembler::new(LOCAL, limits, &tm);
    let h = Header {
        len: 20,
        kind: MsgKind::Segm { id: 0 },
    };
    let msg = [0x55u8; 20];
    let mut tx = Transfer::new(LOCAL, 2, 0, 0, h, false, &tm);
    tx.start(&msg, 0);
    let mut now = 0u64;
    let mut rest = input;
    while rest.len() >= 6 {
        // Map the fuzzer's id mostly onto node LOCAL's few streams.
        let raw = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
        let id29 = if raw & 0x8000_0000 != 0 {
            raw & 0x1fff_ffff
        } else {
            (raw & 0x1fe0_007f) | (LOCAL as u32) << 14 | ((raw >> 7) & 3) << 7
        };
        let dlc = ((rest[4] & 0xf) as usize).min(8);
        if rest.len() < 5 + dlc + 1 {
            break;
        }
        let data = &rest[5..5 + dlc];
        let dt = rest[5 + dlc];
        rest = &rest[6 + dlc..];
        now += dt as u64;
        if dt == 255 {
            rx.on_timer(now);
            let _ = tx.on_timer(&msg, now);
        }
        let Some(id) = DsorId::from_can_id(id29) else {
            continue;
        };
        // The application refuses some complete messages (full queue,
        // gone), decided by the message's length; now and then it goes
        // away for the partial messages of one source (`dt` 254).
        let mut offered = None;
        let mut out = rx.on_frame_with(
            &id,
            data,
            now,
            |inc| {
                assert!(inc.header.len <= limits.max_len);
                if inc.header.len % 5 == 4 {
                    Err(AckStatus::Refused)
                } else {
                    Ok(vec![0; inc.header.len as usize])
                }
            },
            |d| {
                offered = Some(d.header.len);
                assert_eq!(d.buf.len(), d.header.len as usize);
                match d.header.len % 7 {
                    3 => Err(AckStatus::NoMemory),
                    5 => Err(AckStatus::Refused),
                    _ => Ok(()),
                }
            },
        );
        if let Some(len) = offered {
            // The last frame is acked with the application's answer.
            let a = Ack::decode(out.ack.unwrap().payload()).unwrap();
            let want = match len % 7 {
                3 => AckStatus::NoMemory,
                5 => AckStatus::Refused,
                _ => AckStatus::Ok,
            };
            assert_eq!(a.status, want);
        }
        if dt == 254 {
            rx.refuse_partial(|inc| inc.src != id.src, AckStatus::Refused);
        }
        out.delivered = None;
        if id.dst != LOCAL || id.ftype == FrameType::Ack {
            assert!(out.ack.is_none() && out.delivered.is_none());
        }
        if let Some(a) = out.ack {
            let aid = DsorId::from_can_id(a.id).unwrap();
            assert_eq!(
                (aid.src, aid.dst, aid.chan, aid.seq, aid.ftype),
                (id.dst, id.src, id.chan, id.seq, FrameType::Ack)
            );
            assert!(Ack::decode(a.payload()).is_some());
        }
        assert!(rx.bytes_in_use() <= limits.max_bytes_total);
        assert!(rx.active() <= 4);
        let _ = tx.on_ack(&id, data, &msg, now);
    }
    rx.clear();
    assert_eq!(rx.bytes_in_use(), 0);
}
