// SPDX-License-Identifier: GPL-2.0
//! The J1939 fuzz check, shared by the cargo-fuzz target
//! (`fuzz_targets/j1939.rs`, coverage-guided) and the host test
//! `tests/j1939_fuzz_replay.rs` (its seeds and proptest inputs, run by
//! `make check`): one local node with a transport sender, a transport
//! receiver and the address claim table, driven the way the module
//! drives them, gets arbitrary frames from peers (malformed control
//! frames included), echoes, sends, timer expiries (due and early),
//! device refusals and cancellations; nothing may panic, and the
//! invariants below must hold after every event.
//!
//! Input: 4 configuration bytes (our `block` limit, the packet delay in
//! 100 µs, the receive buffer size choice, our address), then records
//! `op | ...`, `op % 8`:
//! 0: a frame `kind | sa | da | len | bytes` (kind % 6 picks TP.CM,
//! TP.DT, ETP.CM, ETP.DT, Address Claimed or Request; da with bit 0 of
//! kind set is our address); 1: the echo of our sender's last data
//! packet; 2: time passes by `dt` (below 200: x 1 ms, else (`dt` - 199)
//! x 100 ms) and due timers fire; 3: a send of `len_hi | len_lo` bytes
//! (`len_hi` & 0x0F: up to 4095, x 3 when `op` bit 3 is set) to the
//! last peer (bit 4: broadcast);
//! 4: early timer calls; 5: the device refuses the last frame of the
//! sender (bit 3: of the receiver) with jitter `op >> 4`; 6: both
//! sessions are cancelled (socket close, interface down); 7: a bind and
//! a send by NAME through the claim table.

use rcan_core::j1939::*;
use rcan_core::j1939_ac::AcTable;
use rcan_core::j1939_tp::*;
use rcan_core::j1939_tp_rx::RxSession;
use rcan_core::j1939_tp_tx::TxSession;

const BUF_LENS: [usize; 6] = [0, 9, 100, 1785, 2000, 70_000];

const TX_ERRNOS: [i32; 9] = [
    EALREADY,
    EMSGSIZE,
    EHOSTUNREACH,
    EBADMSG,
    ENOTRECOVERABLE,
    ENOTCONN,
    EILSEQ,
    EPROTO,
    ENETUNREACH,
];

struct Sim {
    p: Params,
    us: u8,
    peer: u8,
    now: u64,
    ac: AcTable,
    sessions: Sessions<4>,
    tx: Option<(TxSession, usize)>,
    rx: Option<(RxSession, usize)>,
    msg: Vec<u8>,
    buf: Vec<u8>,
    last_dat: Option<Frame>,
}

impl Sim {
    fn frame_ok(&self, f: &Frame) {
        assert_eq!(f.len, 8, "{f:?}");
        assert!(matches!(
            f.id.pgn,
            TP_PGN_CTL | TP_PGN_DAT | ETP_PGN_CTL | ETP_PGN_DAT
        ));
        assert_eq!(f.id.sa, self.us, "{f:?}");
        assert!(f.id.prio <= 7);
    }

    fn done(&self, o: Outcome) {
        match o {
            Outcome::Sent => {}
            Outcome::Delivered(n) => assert!(n <= self.buf.len()),
            Outcome::Aborted { errno, .. } => {
                assert!(
                    TX_ERRNOS.contains(&errno) || errno == ESHUTDOWN,
                    "errno {errno}"
                )
            }
        }
    }

    fn tx_step(&mut self, s: Step) {
        if let TimerCmd::Arm(at) = s.timer {
            assert!(at >= self.now);
        }
        if let Some(f) = s.frame {
            self.frame_ok(&f);
            if f.id.pgn == TP_PGN_DAT || f.id.pgn == ETP_PGN_DAT {
                self.last_dat = Some(f);
            }
        }
        if let Some(o) = s.done {
            self.done(o);
            let (t, slot) = self.tx.take().expect("a step of a live sender");
            assert!(t.is_done());
            self.sessions.deactivate(slot);
        }
    }

    fn rx_step(&mut self, s: Step) {
        if let TimerCmd::Arm(at) = s.timer {
            assert!(at >= self.now);
        }
        if let Some(f) = s.frame {
            self.frame_ok(&f);
        }
        if let Some(o) = s.done {
            self.done(o);
            let (r, slot) = self.rx.take().expect("a step of a live receiver");
            assert!(r.is_done());
            assert!(r.received() <= r.size());
            self.sessions.deactivate(slot);
        }
        if let Some((r, _)) = &self.rx {
            assert!(r.received() <= r.size() && r.size() <= self.buf.len());
        }
    }

    fn frame(&mut self, id: Id, data: &[u8]) {
        if id.pgn == J1939_PGN_ADDRESS_CLAIMED {
            self.ac.on_claim(id.sa, data, self.now);
            return;
        }
        let Some(m) = classify(&id, data) else { return };
        let for_us = id.da == self.us || id.is_broadcast();
        match m {
            Msg::Dat { etp } => {
                if let Some((r, _)) = self.rx.as_mut() {
                    if r.key() == Key::rx_of(&id, etp) {
                        let s = r.on_dat(data, &mut self.buf, self.now);
                        self.rx_step(s);
                    }
                }
            }
            Msg::Ctl {
                etp, cmd, data: d, ..
            } => {
                // A reply to our sender?
                if let Some((t, _)) = self.tx.as_mut() {
                    if !from_originator(cmd) && t.key() == Key::tx_of_reply(&id, etp) {
                        let s = t.on_ctl(&d, &self.msg, self.now);
                        self.tx_step(s);
                        return;
                    }
                }
                if !for_us {
                    return;
                }
                let key = Key::rx_of(&id, etp);
                if let Some((r, _)) = self.rx.as_mut() {
                    if r.key() == key {
                        let s = r.on_ctl(&d, self.now);
                        self.rx_step(s);
                    }
                    return;
                }
                if !matches!(cmd, TP_CMD_RTS | TP_CMD_BAM | ETP_CMD_RTS) {
                    return;
                }
                match RxSession::on_rts(&self.p, id, &d, self.buf.len(), self.now) {
                    Ok((r, s)) => {
                        assert_eq!(r.key(), key);
                        let slot = self.sessions.activate(key).expect("no rx session active");
                        self.rx = Some((r, slot));
                        self.rx_step(s);
                    }
                    Err(s) => {
                        assert!(s.done.is_none() && s.timer == TimerCmd::Keep);
                        if let Some(f) = s.frame {
                            self.frame_ok(&f);
                            assert_eq!(f.data[0], CMD_ABORT);
                        }
                    }
                }
            }
        }
    }

    fn timers(&mut self, early: bool) {
        let t = if early {
            self.now.saturating_sub(1)
        } else {
            self.now
        };
        let nothing = Step {
            frame: None,
            timer: TimerCmd::Keep,
            done: None,
            notify: None,
        };
        if let Some((tx, _)) = self.tx.as_mut() {
            let not_due = tx.deadline().is_none_or(|d| d > t);
            if early == not_due {
                let s = tx.on_timer(&self.msg, t);
                if not_due {
                    assert_eq!(s, nothing, "an early timer acted");
                }
                self.tx_step(s);
            }
        }
        if let Some((rx, _)) = self.rx.as_mut() {
            let not_due = rx.deadline().is_none_or(|d| d > t);
            if early == not_due {
                let s = rx.on_timer(t);
                if not_due {
                    assert_eq!(s, nothing, "an early timer acted");
                }
                self.rx_step(s);
            }
        }
    }
}

/// Runs the check on one input.
pub fn check(input: &[u8]) {
    let Some((head, mut rest)) = input.split_first_chunk::<4>() else {
        return;
    };
    let mut s = Sim {
        p: Params {
            block: head[0].max(1),
            packet_delay_ns: u64::from(head[1]) * 100_000,
            max_size: MAX_ETP_SIZE,
        },
        us: head[3] % 0xFE,
        peer: 0x42,
        now: 0,
        ac: AcTable::new(),
        sessions: Sessions::new(),
        tx: None,
        rx: None,
        msg: vec![],
        buf: vec![0; BUF_LENS[usize::from(head[2] % 6)]],
        last_dat: None,
    };
    let byte = |rest: &mut &[u8]| -> Option<u8> {
        let (&b, r) = rest.split_first()?;
        *rest = r;
        Some(b)
    };
    while let Some(op) = byte(&mut rest) {
        match op % 8 {
            0 => {
                let (Some(kind), Some(sa), Some(da), Some(len)) = (
                    byte(&mut rest),
                    byte(&mut rest),
                    byte(&mut rest),
                    byte(&mut rest),
                ) else {
                    break;
                };
                let n = usize::from(len % 9).min(rest.len());
                let (data, r) = rest.split_at(n);
                rest = r;
                let pgn = [
                    TP_PGN_CTL,
                    TP_PGN_DAT,
                    ETP_PGN_CTL,
                    ETP_PGN_DAT,
                    J1939_PGN_ADDRESS_CLAIMED,
                    J1939_PGN_REQUEST,
                ][usize::from(kind % 6)];
                let da = if kind & 0x80 != 0 { s.us } else { da };
                let Some(id) = Id::from_can_id(
                    Id {
                        prio: kind >> 5 & 7,
                        pgn,
                        sa,
                        da,
                    }
                    .to_can_id(),
                ) else {
                    continue;
                };
                if sa != s.us {
                    s.peer = sa;
                }
                s.frame(id, data);
            }
            1 => {
                if let (Some((tx, _)), Some(f)) = (s.tx.as_mut(), s.last_dat) {
                    let st = tx.on_echo(&f.data, s.now);
                    s.tx_step(st);
                }
            }
            2 => {
                let Some(dt) = byte(&mut rest) else { break };
                s.now += if dt < 200 {
                    u64::from(dt) * 1_000_000
                } else {
                    u64::from(dt - 199) * 100_000_000
                };
                // A burst re-arms at "now": fire until nothing is due.
                for _ in 0..300 {
                    let due = |d: Option<u64>| d.is_some_and(|d| d <= s.now);
                    if !due(s.tx.as_ref().and_then(|t| t.0.deadline()))
                        && !due(s.rx.as_ref().and_then(|r| r.0.deadline()))
                    {
                        break;
                    }
                    s.timers(false);
                }
            }
            3 => {
                let (Some(hi), Some(lo)) = (byte(&mut rest), byte(&mut rest)) else {
                    break;
                };
                let mut n = usize::from(u16::from_be_bytes([hi & 0x0F, lo]));
                if op & 8 != 0 {
                    n *= 3;
                }
                let da = if op & 16 != 0 { J1939_NO_ADDR } else { s.peer };
                if s.tx.is_some() {
                    continue;
                }
                let msg: Vec<u8> = (0..n).map(|i| i as u8).collect();
                let id = Id {
                    prio: 6,
                    pgn: 0xEF00,
                    sa: s.us,
                    da,
                };
                match TxSession::start(&s.p, id, &msg, s.now) {
                    Ok((t, st)) => {
                        let Ok(slot) = s.sessions.activate(t.key()) else {
                            continue;
                        };
                        s.msg = msg;
                        s.tx = Some((t, slot));
                        s.tx_step(st);
                    }
                    Err(e) => assert!([22, EMSGSIZE, EDESTADDRREQ].contains(&e), "{e}"),
                }
            }
            4 => s.timers(true),
            5 => {
                let (now, j) = (s.now, op >> 4);
                if op & 8 == 0 {
                    if let Some((t, _)) = s.tx.as_mut() {
                        let st = t.on_refused(now, j);
                        s.tx_step(st);
                    }
                } else if let Some((r, _)) = s.rx.as_mut() {
                    let st = r.on_refused(now, j);
                    s.rx_step(st);
                }
            }
            6 => {
                if let Some((t, _)) = s.tx.as_mut() {
                    let st = t.cancel(ESHUTDOWN, None);
                    s.tx_step(st);
                }
                if let Some((r, _)) = s.rx.as_mut() {
                    let st = r.cancel(ESHUTDOWN, Some(abort::OTHER));
                    s.rx_step(st);
                }
            }
            _ => {
                let Some(name) = byte(&mut rest) else { break };
                let name = u64::from(name);
                if s.ac.local_get(name, J1939_NO_ADDR).is_ok() {
                    let r =
                        s.ac.fixup_send(name, J1939_NO_ADDR, 0, s.peer, 0xEF00, &[1, 2, 3]);
                    match r {
                        Ok((sa, da)) => {
                            if name == J1939_NO_NAME {
                                assert_eq!(sa, J1939_NO_ADDR);
                            } else {
                                assert!(sa <= J1939_MAX_UNICAST_ADDR);
                                assert_eq!(s.ac.name_to_addr(name), sa);
                            }
                            assert_eq!(da, s.peer);
                        }
                        Err(e) => assert_eq!(e, EADDRNOTAVAIL),
                    }
                    if op & 8 != 0 {
                        s.ac.local_put(name, J1939_NO_ADDR);
                    }
                }
                s.ac.on_timer(s.now);
            }
        }
        assert!(s.sessions.active() <= 2);
    }
    // The claim table: one holder per address, and it holds that one.
    for a in 0..=J1939_MAX_UNICAST_ADDR {
        let n = s.ac.addr_to_name(a);
        if n != 0 {
            assert_eq!(s.ac.name_to_addr(n), a);
        }
    }
}
