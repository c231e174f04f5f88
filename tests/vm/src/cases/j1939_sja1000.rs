// SPDX-License-Identifier: GPL-2.0
//! CAN_J1939 between two controllers: QEMU's two Kvaser cards (SJA1000,
//! can0 and can1 on one emulated bus) under our SJA1000 driver, a J1939
//! socket on each. What the loopback device tests cannot show: the
//! transport sessions between two interface states (each side's
//! sessions see only the other's frames and their own echoes, as two
//! ECUs on a real bus) and the error queue's TX ACK of a single frame
//! coming from the driver's echo (the frame's transmit-complete
//! interrupt), not from a loopback device. Ours only (the mainline stage
//! has no SJA1000 cards of its own).

use crate::check::{ensure, TestResult};
use crate::ctx::{Ctx, Module};

use super::j1939::{jbound, NO_PGN};
use super::j1939_errqueue::{
    errqueue_sender, next_note, no_note, want_tstamp, NLA_BYTES_ACKED, TSTAMP_ACK, TSTAMP_SCHED,
};
use super::j1939_tp::{payload, recv_msg, send_to, want_msg};
use super::sja1000::{kvaser2, pin_to_cpu0};
use super::test_table;

pub static TESTS: &[crate::Test] = test_table![sja1000_j1939_between_cards];

/// 0x20 on can0 sends to 0x30 on can1, the sender with the error queue
/// on (TX SCHED, TX ACK, OPT_ID): a single frame of 3 bytes (received;
/// the sender told SCHED and ACK with key 0), a TP message of 100 bytes
/// (RTS/CTS/DT/EOMA between the two controllers; received whole; ACK
/// with key 1) and an ETP message of 2000 bytes (ACK with key 2, after
/// a SCHED at each CTS that followed data, as many bytes acknowledged as
/// it says and more each time); then
/// 0x30 answers with 1785 bytes (TP's largest) and 0x20 receives them
/// whole. Nothing else on the sender's queue.
fn sja1000_j1939_between_cards(ctx: &mut Ctx) -> TestResult {
    let (i0, i1) = kvaser2(ctx)?;
    // The sender, both cards' interrupts and so the sessions' softirqs on
    // one CPU: QEMU's bus takes no time, and the receiving card's FIFO
    // (64 bytes, four extended frames) overflowed under a block of data
    // packets sent from another CPU ([`pin_to_cpu0`]).
    let _pinned = pin_to_cpu0(&["can0", "can1"])?;
    ctx.insmod(Module::J1939, &[])?;
    let a = jbound(i0, 0x20, NO_PGN)?;
    let b = jbound(i1, 0x30, NO_PGN)?;
    errqueue_sender(&a, "0x20 on can0")?;
    for (key, size) in [(0u32, 3usize), (1, 100), (2, 2000)] {
        let msg = payload(size, key + 11);
        send_to(&a, &msg, 0x30, &format!("sendto {size} bytes on can0"))?;
        let what = format!("{size} bytes at 0x30 on can1");
        want_msg(&recv_msg(&b, &what)?, &msg, 0x20, Some(0x30), &what)?;
        if size <= 8 {
            let what = format!("the sender's SCHED of its {size}-byte message");
            want_tstamp(&next_note(&a, &what)?, TSTAMP_SCHED, key, size as u64, &what)?;
        }
        // A transport message may get a SCHED at each CTS after data
        // (ETP: 286 packets, more than one CTS's worth), each with more
        // bytes acknowledged, before its ACK.
        let mut acked = 0;
        loop {
            let what = format!("the sender's notification of its {size}-byte message");
            let n = next_note(&a, &what)?;
            if size > 8 && n.info == TSTAMP_SCHED {
                let got = n.stat(NLA_BYTES_ACKED).unwrap_or(0);
                ensure!(
                    n.data == key && got > acked && got < size as u64,
                    "{what}: {n:?}, want a SCHED with key {key} and more than {acked} \
                     of {size} bytes acknowledged"
                );
                acked = got;
                continue;
            }
            want_tstamp(&n, TSTAMP_ACK, key, size as u64, &what)?;
            break;
        }
        no_note(&a, &format!("the sender's queue after its {size}-byte message"))?;
    }
    let msg = payload(1785, 99);
    send_to(&b, &msg, 0x20, "sendto 1785 bytes on can1")?;
    let what = "1785 bytes at 0x20 on can0";
    want_msg(&recv_msg(&a, what)?, &msg, 0x30, Some(0x20), what)
}
