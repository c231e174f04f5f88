// SPDX-License-Identifier: GPL-2.0
//! The simulated bus's round (`rcan_chips::sim_bus::round`), which the
//! three simulated cards share: who sends, who is asked, what the others
//! receive, fairness, acknowledgement, a frame waiting while a receiver
//! is not ready for it; with toy nodes that record what
//! the bus did to them. (The chip models on it: the VM tests of the
//! simulated cards.)

use proptest::prelude::*;
use rcan_chips::sim_bus::{round, Attempt, BusNode, Outcome};

/// A node that sends its queued frames (numbers) one per attempt, fails
/// the attempts `fail` says, and takes at most `room` frames.
#[derive(Default, Debug)]
struct Toy {
    queue: Vec<u32>,
    listen_only: bool,
    /// Attempts to fail before the next success.
    fail: usize,
    room: usize,
    /// Its host has not read its receive buffer: a new frame would
    /// overwrite one ([`BusNode::not_ready_for`]).
    unread: bool,
    got: Vec<u32>,
    attempts: usize,
    /// The `acked` of each attempt.
    acked: Vec<bool>,
}

impl BusNode for Toy {
    type Frame = u32;
    /// Whether the bus wants an acknowledgement at all.
    type Fault = bool;

    fn tx_pending(&self) -> bool {
        !self.queue.is_empty()
    }

    fn acks(&self) -> bool {
        !self.listen_only
    }

    fn attempt(&mut self, need_ack: bool, acked: bool) -> Attempt<u32> {
        self.attempts += 1;
        self.acked.push(acked);
        if self.listen_only {
            return Attempt::Idle;
        }
        if self.fail > 0 || (need_ack && !acked) {
            self.fail = self.fail.saturating_sub(1);
            return Attempt::Failed;
        }
        Attempt::Sent(self.queue.remove(0))
    }

    fn deliver(&mut self, f: &u32) -> bool {
        if self.got.len() >= self.room {
            return false;
        }
        self.got.push(*f);
        true
    }

    fn next_frame(&self) -> Option<u32> {
        self.queue.first().copied()
    }

    fn not_ready_for(&self, _f: &u32) -> bool {
        self.unread
    }
}

fn toy(queue: &[u32], room: usize) -> Toy {
    Toy {
        queue: queue.to_vec(),
        room,
        ..Toy::default()
    }
}

#[test]
fn idle_bus_asks_nobody() {
    let mut nodes = [toy(&[], 8), toy(&[], 8), toy(&[], 8)];
    let mut next = 1;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Idle);
    assert_eq!(next, 1);
    assert!(nodes.iter().all(|n| n.attempts == 0));
}

#[test]
fn a_frame_reaches_every_other_node_once() {
    let mut nodes = [toy(&[], 8), toy(&[7], 8), toy(&[], 8)];
    let mut next = 0;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(1, 7));
    assert_eq!(next, 2);
    assert_eq!(nodes[0].got, [7]);
    assert!(
        nodes[1].got.is_empty(),
        "the sender does not receive its own frame"
    );
    assert_eq!(nodes[2].got, [7]);
}

#[test]
fn copies_stop_when_a_receiver_is_full() {
    let mut nodes = [toy(&[5], 8), toy(&[], 3), toy(&[], 100)];
    let mut next = 0;
    assert!(round(&mut nodes, &mut next, false, 10).moved());
    assert_eq!(nodes[1].got, [5, 5, 5]);
    assert_eq!(nodes[2].got.len(), 10);
}

#[test]
fn zero_copies_is_one() {
    let mut nodes = [toy(&[5], 8), toy(&[], 8)];
    let mut next = 0;
    round(&mut nodes, &mut next, false, 0);
    assert_eq!(nodes[1].got, [5]);
}

#[test]
fn a_failed_attempt_moves_the_turn_on() {
    let mut nodes = [toy(&[1], 8), toy(&[2], 8)];
    nodes[0].fail = 1;
    let mut next = 0;
    let out = round(&mut nodes, &mut next, false, 1);
    assert_eq!(out, Outcome::Failed(0));
    assert!(out.failed() && !out.moved());
    assert_eq!(next, 1);
    assert!(nodes[1].got.is_empty());
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(1, 2));
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(0, 1));
}

#[test]
fn a_node_that_answers_idle_is_passed_over_in_the_same_round() {
    let mut nodes = [toy(&[1], 8), toy(&[2], 8)];
    nodes[0].listen_only = true;
    let mut next = 0;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(1, 2));
    assert_eq!(nodes[0].attempts, 1);
    assert_eq!(next, 0);
}

#[test]
fn a_lone_transmitter_is_not_acknowledged() {
    // The only other node listens only: nobody acknowledges.
    let mut nodes = [toy(&[1], 8), toy(&[], 8)];
    nodes[1].listen_only = true;
    let mut next = 0;
    assert_eq!(round(&mut nodes, &mut next, true, 1), Outcome::Failed(0));
    assert_eq!(nodes[0].acked, [false]);
    nodes[1].listen_only = false;
    assert_eq!(round(&mut nodes, &mut next, true, 1), Outcome::Sent(0, 1));
    assert_eq!(nodes[0].acked, [false, true]);
}

#[test]
fn a_frame_waits_while_a_receiver_is_not_ready() {
    let mut nodes = [toy(&[1, 2], 8), toy(&[], 8), toy(&[], 8)];
    nodes[2].unread = true;
    let mut next = 0;
    let out = round(&mut nodes, &mut next, false, 1);
    assert_eq!(out, Outcome::Held(0));
    assert!(out.held() && !out.moved() && !out.failed());
    assert_eq!(next, 0, "the held node keeps its turn");
    assert_eq!(nodes[0].attempts, 0, "a held frame is not attempted");
    assert!(nodes[1].got.is_empty() && nodes[2].got.is_empty());
    // The host reads: the frame goes, then the next, in order.
    nodes[2].unread = false;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(0, 1));
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(0, 2));
    assert_eq!(nodes[1].got, [1, 2]);
    assert_eq!(nodes[2].got, [1, 2]);
}

#[test]
fn a_held_node_lets_the_others_go() {
    // Node 0's frame would be lost by node 2; node 2's own frame is lost
    // by nobody and goes; the sender's own buffer does not hold it back.
    let mut nodes = [toy(&[1], 8), toy(&[], 8), toy(&[3], 8)];
    nodes[2].unread = true;
    let mut next = 0;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(2, 3));
    assert_eq!(next, 0);
    assert_eq!(nodes[0].got, [3]);
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Held(0));
    nodes[2].unread = false;
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Sent(0, 1));
    assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Idle);
}

#[test]
fn nodes_that_cannot_tell_their_frame_never_wait() {
    // A model without next_frame (the default) is never held back.
    struct Blind(Vec<u32>, Vec<u32>);
    impl BusNode for Blind {
        type Frame = u32;
        type Fault = ();
        fn tx_pending(&self) -> bool {
            !self.0.is_empty()
        }
        fn acks(&self) -> bool {
            true
        }
        fn attempt(&mut self, _: (), _: bool) -> Attempt<u32> {
            Attempt::Sent(self.0.remove(0))
        }
        fn deliver(&mut self, f: &u32) -> bool {
            self.1.push(*f);
            true
        }
        fn not_ready_for(&self, _f: &u32) -> bool {
            true
        }
    }
    let mut nodes = [Blind(vec![4], vec![]), Blind(vec![], vec![])];
    let mut next = 0;
    assert_eq!(round(&mut nodes, &mut next, (), 1), Outcome::Sent(0, 4));
    assert_eq!(nodes[1].1, [4]);
}

proptest! {
    /// Every queued frame goes out exactly once, each node's in its own
    /// order; every other node receives each one, the sender never its
    /// own; the nodes with frames take turns.
    #[test]
    fn fair_and_complete(
        queues in prop::collection::vec(prop::collection::vec(any::<u16>(), 0..6), 1..5),
        start in 0usize..8,
    ) {
        let n = queues.len();
        let mut nodes: Vec<Toy> = queues
            .iter()
            .enumerate()
            .map(|(i, q)| toy(&q.iter().map(|&v| (i as u32) << 16 | u32::from(v)).collect::<Vec<_>>(), 1000))
            .collect();
        let total: usize = queues.iter().map(Vec::len).sum();
        let mut next = start % n;
        let mut senders = Vec::new();
        for _ in 0..total {
            match round(&mut nodes, &mut next, false, 1) {
                Outcome::Sent(i, f) => {
                    prop_assert_eq!((f >> 16) as usize, i);
                    senders.push(i);
                }
                o => prop_assert!(false, "{:?} with frames left", o),
            }
        }
        prop_assert_eq!(round(&mut nodes, &mut next, false, 1), Outcome::Idle);
        for (i, node) in nodes.iter().enumerate() {
            for (j, q) in queues.iter().enumerate() {
                let from_j: Vec<u32> = node.got.iter().copied().filter(|f| (f >> 16) as usize == j).collect();
                let want: Vec<u32> = if j == i {
                    Vec::new()
                } else {
                    q.iter().map(|&v| (j as u32) << 16 | u32::from(v)).collect()
                };
                prop_assert_eq!(from_j, want, "node {} from node {}", i, j);
            }
        }
        // Fairness: each round's sender is the first node after the
        // previous sender (from `start` at first) that still had frames.
        let mut left: Vec<usize> = queues.iter().map(Vec::len).collect();
        let mut from = start % n;
        for &i in &senders {
            let want = (0..n).map(|k| (from + k) % n).find(|&j| left[j] > 0);
            prop_assert_eq!(Some(i), want);
            left[i] -= 1;
            from = (i + 1) % n;
        }
    }
}
