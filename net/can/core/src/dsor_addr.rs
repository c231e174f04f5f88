// SPDX-License-Identifier: GPL-2.0
//! DSOR socket addresses (thesis 5.2.6): `struct sockaddr_cansegm` and
//! `struct sockaddr_canport` of `<linux/can/rcan_dsor.h>`, told apart by
//! their length, and the rules for `bind`, `connect` and `sendto`.
//!
//! Layouts (native byte order, as every sockaddr field but the port of
//! AF_INET):
//!
//! ```text
//! sockaddr_cansegm (8 bytes): u16 family, u8 priority, u8 node, u32 id
//! sockaddr_canport (6 bytes): u16 family, u16 port, u8 priority, u8 pad
//! ```
//!
//! A port is `node << 8 | sub-port`: the high byte is a 7-bit node, the low
//! byte the software port on that node.

use super::arb::EINVAL;
use super::sockaddr::AF_CAN;

/// `sizeof(struct sockaddr_cansegm)`.
pub const SOCKADDR_CANSEGM_LEN: usize = 8;
/// `sizeof(struct sockaddr_canport)`.
pub const SOCKADDR_CANPORT_LEN: usize = 6;
/// `node` of a segmented bind that accepts every source node.
pub const DSOR_NODE_ANY: u8 = 0xff;
/// `id` of a segmented bind that accepts every message identifier.
pub const DSOR_ID_ANY: u32 = 0xffff_ffff;
/// Highest node number (7 bits).
pub const DSOR_NODE_MAX: u8 = 0x7f;
/// First sub-port handed out by automatic binding (128..=255).
pub const DSOR_EPHEMERAL_MIN: u8 = 128;

/// `EAFNOSUPPORT`.
pub const EAFNOSUPPORT: i32 = 97;

/// A decoded DSOR socket address.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DsorAddr {
    /// Segmented messages: a peer node and a 32-bit message identifier.
    Segm {
        /// Bus priority (the identifier's 8 most significant bits).
        prio: u8,
        /// Peer node, or [`DSOR_NODE_ANY`] in a bind.
        node: u8,
        /// Message identifier, or [`DSOR_ID_ANY`] in a bind.
        id: u32,
    },
    /// Port messages: node and sub-port in one 16-bit port.
    Port {
        /// Bus priority.
        prio: u8,
        /// `node << 8 | sub-port`.
        port: u16,
    },
}

impl DsorAddr {
    /// Decodes a user address; the length selects the type. `EINVAL` for
    /// a length of neither type, `EAFNOSUPPORT` for another family.
    pub fn parse(b: &[u8]) -> Result<Self, i32> {
        if b.len() < 2 {
            return Err(EINVAL);
        }
        if u16::from_ne_bytes([b[0], b[1]]) != AF_CAN {
            return Err(EAFNOSUPPORT);
        }
        match b.len() {
            SOCKADDR_CANSEGM_LEN => Ok(DsorAddr::Segm {
                prio: b[2],
                node: b[3],
                id: u32::from_ne_bytes([b[4], b[5], b[6], b[7]]),
            }),
            SOCKADDR_CANPORT_LEN => Ok(DsorAddr::Port {
                port: u16::from_ne_bytes([b[2], b[3]]),
                prio: b[4],
            }),
            _ => Err(EINVAL),
        }
    }

    /// Encodes the address; returns the bytes and their length.
    pub fn encode(&self) -> ([u8; SOCKADDR_CANSEGM_LEN], usize) {
        let mut o = [0u8; SOCKADDR_CANSEGM_LEN];
        o[..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        match *self {
            DsorAddr::Segm { prio, node, id } => {
                o[2] = prio;
                o[3] = node;
                o[4..8].copy_from_slice(&id.to_ne_bytes());
                (o, SOCKADDR_CANSEGM_LEN)
            }
            DsorAddr::Port { prio, port } => {
                o[2..4].copy_from_slice(&port.to_ne_bytes());
                o[4] = prio;
                (o, SOCKADDR_CANPORT_LEN)
            }
        }
    }

    /// Checks a destination (`connect`, `sendto`): a real node (no
    /// wildcard), and for segmented messages any id. `EINVAL` otherwise.
    pub fn check_dest(&self) -> Result<(), i32> {
        match *self {
            DsorAddr::Segm { node, .. } if node <= DSOR_NODE_MAX => Ok(()),
            DsorAddr::Port { port, .. } if port_node(port) <= DSOR_NODE_MAX => Ok(()),
            _ => Err(EINVAL),
        }
    }

    /// Checks a `bind` address of a host whose node is `local`: segmented
    /// binds name a peer node or [`DSOR_NODE_ANY`]; port binds name a port
    /// of this node (`EADDRNOTAVAIL` otherwise).
    pub fn check_bind(&self, local: u8) -> Result<(), i32> {
        match *self {
            DsorAddr::Segm { node, .. } if node <= DSOR_NODE_MAX || node == DSOR_NODE_ANY => Ok(()),
            DsorAddr::Segm { .. } => Err(EINVAL),
            DsorAddr::Port { port, .. } if port_node(port) == local => Ok(()),
            DsorAddr::Port { .. } => Err(EADDRNOTAVAIL),
        }
    }

    /// Whether a segmented bind `self` accepts message `id` from `src`.
    pub fn segm_accepts(&self, src: u8, msg_id: u32) -> bool {
        match *self {
            DsorAddr::Segm { node, id, .. } => {
                (node == DSOR_NODE_ANY || node == src) && (id == DSOR_ID_ANY || id == msg_id)
            }
            DsorAddr::Port { .. } => false,
        }
    }
}

/// `EADDRNOTAVAIL`.
pub const EADDRNOTAVAIL: i32 = 99;

/// The node of a port.
pub const fn port_node(port: u16) -> u8 {
    (port >> 8) as u8
}

/// The sub-port of a port.
pub const fn port_sub(port: u16) -> u8 {
    port as u8
}

/// The port of `sub` on `node`.
pub const fn make_port(node: u8, sub: u8) -> u16 {
    (node as u16) << 8 | sub as u16
}

/// The CAN node an IPv4 destination maps to on `canip`: its last octet,
/// modulo 128 (so `10.0.0.5` and `10.0.0.133` are node 5).
pub const fn udp_node(daddr: u32) -> u8 {
    (daddr & 0x7f) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    fn segm(prio: u8, node: u8, id: u32) -> [u8; 8] {
        let mut b = [0u8; 8];
        b[..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        b[2] = prio;
        b[3] = node;
        b[4..].copy_from_slice(&id.to_ne_bytes());
        b
    }

    #[test]
    fn length_selects_type() {
        let s = segm(0x40, 5, 0x1234_5678);
        assert_eq!(
            DsorAddr::parse(&s),
            Ok(DsorAddr::Segm {
                prio: 0x40,
                node: 5,
                id: 0x1234_5678
            })
        );
        let mut p = [0u8; 6];
        p[..2].copy_from_slice(&AF_CAN.to_ne_bytes());
        p[2..4].copy_from_slice(&0x0507u16.to_ne_bytes());
        p[4] = 9;
        assert_eq!(
            DsorAddr::parse(&p),
            Ok(DsorAddr::Port {
                prio: 9,
                port: 0x0507
            })
        );
        assert_eq!(DsorAddr::parse(&s[..7]), Err(EINVAL));
        assert_eq!(DsorAddr::parse(&[0u8; 16]), Err(EAFNOSUPPORT));
        assert_eq!(DsorAddr::parse(&s[..1]), Err(EINVAL));
    }

    #[test]
    fn encode_round_trips() {
        for a in [
            DsorAddr::Segm {
                prio: 1,
                node: 0x7f,
                id: 7,
            },
            DsorAddr::Port {
                prio: 0xff,
                port: 0x7fff,
            },
        ] {
            let (b, n) = a.encode();
            assert_eq!(DsorAddr::parse(&b[..n]), Ok(a));
        }
    }

    #[test]
    fn bind_and_dest_rules() {
        let any = DsorAddr::Segm {
            prio: 0,
            node: DSOR_NODE_ANY,
            id: DSOR_ID_ANY,
        };
        assert_eq!(any.check_bind(0), Ok(()));
        assert_eq!(any.check_dest(), Err(EINVAL));
        assert!(any.segm_accepts(3, 99));
        let one = DsorAddr::Segm {
            prio: 0,
            node: 3,
            id: 99,
        };
        assert!(one.segm_accepts(3, 99));
        assert!(!one.segm_accepts(4, 99));
        assert!(!one.segm_accepts(3, 98));
        assert_eq!(
            DsorAddr::Segm {
                prio: 0,
                node: 0x80,
                id: 0
            }
            .check_bind(0),
            Err(EINVAL)
        );
        let p = DsorAddr::Port {
            prio: 0,
            port: make_port(2, 7),
        };
        assert_eq!(p.check_bind(2), Ok(()));
        assert_eq!(p.check_bind(3), Err(EADDRNOTAVAIL));
        assert_eq!(
            DsorAddr::Port {
                prio: 0,
                port: 0x8001
            }
            .check_dest(),
            Err(EINVAL)
        );
        assert_eq!(udp_node(0x0a00_0085), 5);
    }
}
