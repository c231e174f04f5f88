// SPDX-License-Identifier: GPL-2.0
//! The ISO-TP fuzz check, shared by the cargo-fuzz target
//! (`fuzz_targets/isotp.rs`, coverage-guided) and the host test
//! `tests/isotp_fuzz_replay.rs` (proptest inputs, run by `make check`):
//! a socket configured from the input through the option parser, then
//! arbitrary frames, echoes, sends, timer expiries (due and early) and
//! aborts into its sender and receiver; nothing may panic, and the
//! invariants below must hold after every event.
//!
//! Input: 12 configuration bytes (`CAN_ISOTP_OPTS` image, then the
//! link-layer choice, `CAN_ISOTP_RECV_FC` bs/stmin and the receive
//! buffer size), then records `op | ...`:
//! `op % 6` 0: a frame `len | bytes` (classic or, with op bit 3, FD);
//! 1: the echo of the last frame sent; 2: time passes by `dt` (below
//! 200: x 100 µs, else (`dt` - 199) x 100 ms) and due timers fire; 3: `sendmsg` of `len_hi | len_lo` bytes;
//! 4: early timer callbacks; 5: both sides abort.

use rcan_core::isotp::*;
use rcan_core::isotp_pci::{parse_fc, sf_max, LlFrame};
use rcan_core::isotp_rx::{Rx, RxEvent, RxStep};
use rcan_core::isotp_tx::{Tx, TxStep};

const FD_LENS: [u8; 8] = [8, 12, 16, 20, 24, 32, 48, 64];

fn check_frame(cfg: &Config, f: &LlFrame, max: usize) {
    let n = usize::from(f.len);
    assert!(n <= max, "frame of {n} bytes, TX_DL {max}");
    assert!(
        n <= 8 || FD_LENS.contains(&f.len),
        "invalid CAN FD length {n}"
    );
    assert!(f.data[n..].iter().all(|&b| b == 0), "bytes behind len");
    assert!(n > cfg.ae(), "no N_PCI");
    if cfg.ae() == 1 {
        assert_eq!(f.data[0], cfg.opt.ext_address);
    }
}

struct Sim {
    cfg: Config,
    tx: Tx,
    rx: Rx,
    buf: Vec<u8>,
    pdu: Vec<u8>,
    now: u64,
    echo_wanted: bool,
}

impl Sim {
    fn tx_step(&mut self, st: TxStep) {
        if let Some(f) = &st.frame {
            check_frame(&self.cfg, f, usize::from(self.cfg.ll.tx_dl));
            self.echo_wanted = st.wants_echo;
        }
        if let TimerCmd::Arm(at) = st.timer {
            assert!(at >= self.now);
        }
        if let Some(Err(e)) = st.done {
            assert!([ECOMM, EBADMSG, EMSGSIZE, 22].contains(&e), "tx errno {e}");
        }
        if st.done.is_some() {
            assert!(self.tx.is_idle());
        }
        if self.tx.is_idle() {
            assert_eq!(self.tx.deadline(), None);
        }
        assert!(self.tx.sent() <= self.pdu.len());
    }

    fn rx_step(&mut self, st: RxStep) {
        if let Some(f) = &st.frame {
            // Our FCs: 3 bytes (+ address) or 8 padded, well formed.
            check_frame(&self.cfg, f, 8);
            let fc = parse_fc(
                &Config {
                    opt: IsotpOptions {
                        flags: self.cfg.opt.flags & CAN_ISOTP_EXTEND_ADDR,
                        ..self.cfg.opt
                    },
                    ..self.cfg
                },
                f.payload(),
            );
            assert!(fc.is_ok());
        }
        if let TimerCmd::Arm(at) = st.timer {
            assert!(at >= self.now);
        }
        match st.event {
            Some(RxEvent::Deliver(n)) => assert!(n > 0 && n <= self.buf.len()),
            Some(RxEvent::Error(e)) => {
                assert!([ETIMEDOUT, EILSEQ, EBADMSG].contains(&e), "rx errno {e}")
            }
            None => {}
        }
        if self.rx.is_idle() {
            assert_eq!(self.rx.deadline(), None);
        }
        assert!(self.rx.received() <= self.buf.len());
    }
}

/// Runs the check on one input.
pub fn check(input: &[u8]) {
    let Some((head, mut rest)) = input.split_first_chunk::<12>() else {
        return;
    };
    let mut cfg = Config::default();
    // The option parser sees the raw image; with both broadcast flags it
    // stores SF_BROADCAST and answers EINVAL.
    let r = cfg.setsockopt(SOL_CAN_ISOTP, CAN_ISOTP_OPTS, &head[..12], false);
    assert!(r.is_ok() || r == Err(22));
    let fd = head[8] & 0x80 != 0;
    let ll = [
        if fd { 72 } else { 16 },
        FD_LENS[usize::from(head[8] & 7)],
        head[8] >> 3 & 1,
    ];
    if cfg
        .setsockopt(SOL_CAN_ISOTP, CAN_ISOTP_LL_OPTS, &ll, false)
        .is_err()
    {
        assert!(!fd && (ll[1] != 8 || ll[2] != 0));
    }
    cfg.setsockopt(
        SOL_CAN_ISOTP,
        CAN_ISOTP_RECV_FC,
        &[head[9], head[10], 0],
        false,
    )
    .unwrap();
    cfg.setsockopt(
        SOL_CAN_ISOTP,
        CAN_ISOTP_RX_STMIN,
        &(u32::from(head[10]) * 10_000).to_ne_bytes(),
        false,
    )
    .unwrap();
    cfg.setsockopt(
        SOL_CAN_ISOTP,
        CAN_ISOTP_TX_STMIN,
        &(u32::from(head[9]) * 10_000).to_ne_bytes(),
        false,
    )
    .unwrap();
    let buflen = [0usize, 7, 62, 100, 4095, 8300][usize::from(head[11] % 6)];
    let mut s = Sim {
        cfg,
        tx: Tx::new(),
        rx: Rx::new(),
        buf: vec![0; buflen],
        pdu: vec![],
        now: 0,
        echo_wanted: false,
    };
    while let Some((&op, r)) = rest.split_first() {
        rest = r;
        match op % 6 {
            0 => {
                let Some((&len, r)) = rest.split_first() else {
                    break;
                };
                let frame_fd = op & 8 != 0;
                let len = usize::from(len) % if frame_fd { 65 } else { 9 };
                let data = &r[..len.min(r.len())];
                rest = &r[data.len()..];
                match route(&s.cfg, frame_fd, data, s.tx.is_idle(), s.rx.is_idle()) {
                    Route::Drop => {}
                    Route::Tx => {
                        let st = s.tx.on_fc(&s.cfg, data, &s.pdu, s.now);
                        s.tx_step(st);
                    }
                    Route::Rx => {
                        let st = s.rx.on_frame(&s.cfg, data, &mut s.buf, s.now);
                        s.rx_step(st);
                    }
                }
            }
            1 => {
                if s.echo_wanted {
                    s.echo_wanted = false;
                    let st = s.tx.on_echo(&s.cfg, &s.pdu, s.now);
                    s.tx_step(st);
                }
            }
            2 => {
                let Some((&dt, r)) = rest.split_first() else {
                    break;
                };
                rest = r;
                s.now += if dt < 200 {
                    u64::from(dt) * 100_000
                } else {
                    u64::from(dt - 199) * 100_000_000
                };
                if s.tx.deadline().is_some_and(|d| d <= s.now) {
                    let st = s.tx.on_timer(&s.cfg, &s.pdu, s.now);
                    s.tx_step(st);
                }
                if s.rx.deadline().is_some_and(|d| d <= s.now) {
                    let st = s.rx.on_timer(s.now);
                    s.rx_step(st);
                }
            }
            3 => {
                let Some((&[hi, lo], r)) = rest.split_first_chunk::<2>() else {
                    break;
                };
                rest = r;
                let len = usize::from(u16::from_be_bytes([hi, lo]));
                if s.cfg.check_send_len(len, DEFAULT_MAX_PDU_SIZE).is_err() {
                    continue;
                }
                if !s.tx.is_idle() {
                    assert_eq!(s.tx.start(&s.cfg, &[1], s.now), Err(EAGAIN));
                    continue;
                }
                s.pdu = (0..len).map(|i| i as u8).collect();
                let st = s.tx.start(&s.cfg, &s.pdu, s.now).unwrap();
                assert!(st.frame.is_some());
                // Only a PDU that fits a single frame is sent at once.
                assert!(!s.tx.is_idle());
                assert_eq!(s.tx.sent() == len, len <= sf_max(&s.cfg));
                s.tx_step(st);
            }
            4 => {
                let (tx_before, rx_before) = (s.tx, s.rx);
                if let Some(d) = s.tx.deadline().filter(|&d| d > s.now) {
                    assert_eq!(s.tx.on_timer(&s.cfg, &s.pdu, d - 1).frame, None);
                }
                if let Some(d) = s.rx.deadline().filter(|&d| d > s.now) {
                    assert_eq!(s.rx.on_timer(d - 1).event, None);
                }
                assert_eq!((s.tx, s.rx), (tx_before, rx_before));
            }
            _ => {
                s.tx.abort();
                s.rx.abort();
                assert_eq!((s.tx.deadline(), s.rx.deadline()), (None, None));
                s.echo_wanted = false;
            }
        }
    }
}
