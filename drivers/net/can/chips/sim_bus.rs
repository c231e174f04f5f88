// SPDX-License-Identifier: GPL-2.0
//! One round of a simulated CAN bus, the same for every chip model: the
//! nodes with something to send try in turn (fairness: the search starts
//! after the last node that tried), one attempt per round, and a frame
//! that went out is offered to every other node. The simulated cards
//! (`rcan_sja1000_sim`, `rcan_i82527_sim`, `rcan_ctucanfd_sim`) run it
//! under their bus lock from their bus timer; the host tests drive it
//! with the same models. Pure: no allocation, no locking, no `unsafe`.

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
}

/// One round on the bus of `nodes`: the first node from `*next` on (in
/// turn, wrapping) that has a frame pending and does not answer
/// [`Attempt::Idle`] makes one attempt under `fault`. A frame that went
/// out is offered `copies` times (1 normally, more to overrun the
/// receivers) to every other node, in bus order; `*next` moves past the
/// node that tried. `copies` 0 is taken as 1.
pub fn round<N: BusNode>(
    nodes: &mut [N],
    next: &mut usize,
    fault: N::Fault,
    copies: usize,
) -> Outcome<N::Frame> {
    let n = nodes.len();
    for k in 0..n {
        let i = (*next + k) % n;
        if !nodes[i].tx_pending() {
            continue;
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
    Outcome::Idle
}
