// SPDX-License-Identifier: GPL-2.0
//! One round of a simulated CAN bus, the same for every chip model: the
//! nodes with something to send try in turn (fairness: the search starts
//! after the last node that tried), one attempt per round, and a frame
//! that went out is offered to every other node. The simulated cards
//! (`rcan_sja1000_sim`, `rcan_i82527_sim`, `rcan_ctucanfd_sim`) run it
//! under their bus lock from their bus timer; the host tests drive it
//! with the same models. Pure: no allocation, no locking, no `unsafe`.
//!
//! A node whose model can tell which frame it sends next
//! ([`BusNode::next_frame`]) waits while another node is not ready for
//! it ([`BusNode::not_ready_for`]: its host has not read its receive
//! buffers yet, and taking the frame would overwrite one or have the host
//! read them out of bus order): the round passes over it, and if no node
//! can go, the bus stays idle ([`Outcome::Held`]) until a host reads. A
//! real bus has no such flow control (a receiver acknowledges a frame
//! whatever its buffers hold, and an unread buffer is overrun), but on a
//! real bus the pace is the bit rate and a host that reads within a frame
//! time never loses a frame. A simulated bus runs from a timer on one
//! virtual CPU of a guest while the receiving host may run on another
//! that the machine below does not schedule for many frame times; the
//! wait stands for the real host that would have kept up. Overruns are
//! still made on request (`copies` > 1, the cards' `fault=overrun`).

/// What one transmit attempt of a node did.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Attempt<F> {
    /// Nothing to send (or not allowed to: off the bus, listen-only).
    Idle,
    /// The frame went out: the bus offers it to the other nodes.
    Sent(F),
    /// The attempt failed (bus error, arbitration lost, no
    /// acknowledgement); the chip retries by itself.
    Failed,
}

impl<F> Attempt<F> {
    /// The frame sent, if one was.
    pub fn sent(self) -> Option<F> {
        match self {
            Attempt::Sent(f) => Some(f),
            _ => None,
        }
    }
}

/// A chip model as the bus sees it.
pub trait BusNode {
    /// A frame on the bus.
    type Frame;
    /// The bus condition an attempt runs under (fault injection).
    type Fault: Copy;

    /// Whether the node has a frame waiting to go out. The round asks
    /// only nodes that say so to [`BusNode::attempt`].
    fn tx_pending(&self) -> bool;

    /// Whether the node acknowledges frames on the bus now (on the bus,
    /// not listen-only).
    fn acks(&self) -> bool;

    /// One transmit attempt under `fault`; `acked`: another node on the
    /// bus acknowledges (a lone transmitter gets no ACK).
    fn attempt(&mut self, fault: Self::Fault, acked: bool) -> Attempt<Self::Frame>;

    /// A frame another node sent. Returns false if offering the same
    /// frame again is pointless (it was not taken, or the receive buffer
    /// is full): [`round`] then stops offering copies of it.
    fn deliver(&mut self, f: &Self::Frame) -> bool;

    /// The frame the node's next attempt would send, if its model can
    /// tell; such a node waits while another is not ready for the frame.
    /// By default `None`: the node's frames never wait.
    fn next_frame(&self) -> Option<Self::Frame> {
        None
    }

    /// Whether receiving `f` now would overwrite a frame this node's host
    /// has not read yet (a receive overrun), or make the host read its
    /// frames out of bus order. By default `false`.
    fn not_ready_for(&self, _f: &Self::Frame) -> bool {
        false
    }
}

/// What a [`round`] did.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Outcome<F> {
    /// No node tried to send.
    Idle,
    /// Node `.0` sent frame `.1`.
    Sent(usize, F),
    /// Node `.0` tried and failed.
    Failed(usize),
    /// Nobody sent: node `.0` (the first in turn) and any other node with
    /// a frame pending wait until a receiver's host has read what is in
    /// the way of theirs ([`BusNode::not_ready_for`]).
    Held(usize),
}

impl<F> Outcome<F> {
    /// A frame went out.
    pub fn moved(&self) -> bool {
        matches!(self, Outcome::Sent(..))
    }

    /// An attempt failed (the chip retries it by itself).
    pub fn failed(&self) -> bool {
        matches!(self, Outcome::Failed(_))
    }

    /// A frame waits for a receiver's host to read (nothing else moved).
    pub fn held(&self) -> bool {
        matches!(self, Outcome::Held(_))
    }
}

/// One round on the bus of `nodes`: the first node from `*next` on (in
/// turn, wrapping) that has a frame pending, whose frame every other node
/// is ready for ([`BusNode::not_ready_for`] of its [`BusNode::next_frame`]),
/// and that does not answer [`Attempt::Idle`] makes one attempt under
/// `fault`. A frame that went out is offered `copies` times (1 normally,
/// more to overrun the receivers) to every other node, in bus order;
/// `*next` moves past the node that tried. `copies` 0 is taken as 1. If
/// every node with a frame pending had to wait, the round is
/// [`Outcome::Held`] and `*next` stays.
pub fn round<N: BusNode>(
    nodes: &mut [N],
    next: &mut usize,
    fault: N::Fault,
    copies: usize,
) -> Outcome<N::Frame> {
    let n = nodes.len();
    let mut held = None;
    for k in 0..n {
        let i = (*next + k) % n;
        if !nodes[i].tx_pending() {
            continue;
        }
        if let Some(f) = nodes[i].next_frame() {
            if (0..n).any(|j| j != i && nodes[j].not_ready_for(&f)) {
                held.get_or_insert(i);
                continue;
            }
        }
        let acked = (0..n).any(|j| j != i && nodes[j].acks());
        let outcome = match nodes[i].attempt(fault, acked) {
            Attempt::Idle => continue,
            Attempt::Failed => Outcome::Failed(i),
            Attempt::Sent(f) => {
                for j in (0..n).filter(|&j| j != i) {
                    for _ in 0..copies.max(1) {
                        if !nodes[j].deliver(&f) {
                            break;
                        }
                    }
                }
                Outcome::Sent(i, f)
            }
        };
        *next = (i + 1) % n;
        return outcome;
    }
    match held {
        Some(i) => Outcome::Held(i),
        None => Outcome::Idle,
    }
}
