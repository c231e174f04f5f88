// SPDX-License-Identifier: GPL-2.0
//! The J1939 address claim table of one interface (SAE J1939-81; mainline
//! `net/can/j1939/address-claim.c` and `bus.c`, rewritten): which NAME
//! holds which address, learnt from the ADDRESS_CLAIMED frames on the bus
//! (our own included: they come back as echoes), and the decisions a
//! send needs (a NAME's address, or `EADDRNOTAVAIL`).
//!
//! One [`AcTable`] exists per interface on which a J1939 socket is
//! bound. Claiming itself is user space's (`j1939acd`): the table only
//! watches. A claim becomes usable [`AC_WINDOW_NS`] (250 ms) after its
//! last contending-free ADDRESS_CLAIMED frame: until then the NAME has no
//! address ([`AcTable::name_to_addr`] says [`J1939_IDLE_ADDR`]) and a send
//! by that NAME fails with `EADDRNOTAVAIL`, as on mainline.
//!
//! Fixed size, no allocation: 256 address entries and [`ECU_SLOTS`] ECU
//! entries (a NAME seen claiming, or bound by a local socket). The caller
//! serializes all calls (the module: one spinlock per interface, taken in
//! process context with bottom halves off and in softirq context) and
//! arms one timer for [`AcTable::next_deadline`]; times are absolute ns.
//!
//! Where we differ from mainline (j1939.rst, "Address claiming"):
//!
//! - Mainline starts a 250 ms timer per claim and maps the ECU when it
//!   expires, skipping the mapping if another ECU got the address in the
//!   meantime, whatever the NAMEs. Here at most one claim per address is
//!   pending or mapped at any time, and the standard's priority rule
//!   (the lower NAME wins, J1939-81 4.5.3) decides between a new claim
//!   and a pending one as well as a mapped one.
//! - Mainline ignores an ADDRESS_CLAIMED frame whose NAME and address are
//!   those the table already has for that ECU, even when the ECU is no
//!   longer mapped (it lost its address or the interface went down): it
//!   then never gets its address back. Here only a claim that is mapped
//!   or pending is left alone (mainline's intent: no restart of the 250
//!   ms window on a repeated claim); any other starts a new window.
//! - When the table is full a new NAME is ignored (mainline: `-ENOMEM`
//!   on allocation, same effect); a bind with a new NAME then fails with
//!   `ENOMEM`.

use super::j1939::{
    addr_is_unicast, EADDRNOTAVAIL, ENODEV, EPROTO, J1939_IDLE_ADDR, J1939_NO_ADDR, J1939_NO_NAME,
    J1939_PGN_ADDRESS_CLAIMED, J1939_PGN_REQUEST,
};

/// The claim window: a claimed address is used from 250 ms after the
/// claim on (J1939-81 4.4.2.3, ISO 11783-5 4.5.2 d), mainline's timer).
pub const AC_WINDOW_NS: u64 = 250_000_000;

/// ECU entries per table.
pub const ECU_SLOTS: usize = 512;

/// `ENOMEM`: no free ECU entry.
pub const ENOMEM: i32 = 12;

const NONE: u16 = u16::MAX;

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Ecu {
    /// 0: the entry is free.
    name: u64,
    /// The last address this NAME claimed ([`J1939_IDLE_ADDR`]: none).
    addr: u8,
    /// The claim of `addr` becomes valid then (pending), if set.
    claim_at: Option<u64>,
    /// Local sockets bound with this NAME.
    local_users: u32,
}

const FREE: Ecu = Ecu {
    name: 0,
    addr: J1939_IDLE_ADDR,
    claim_at: None,
    local_users: 0,
};

/// What an ADDRESS_CLAIMED frame did to the table ([`AcTable::on_claim`]).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum ClaimResult {
    /// Not a valid claim (length not 8, NAME 0, source 0xFF), or the
    /// table is full: nothing changed.
    Ignored,
    /// The NAME already holds (or is claiming) this address: nothing
    /// changed, the window is not restarted.
    Repeated,
    /// The claim is pending; it becomes valid at this time unless a
    /// lower NAME claims the address first.
    Pending(u64),
    /// A lower NAME holds or claims the address: this NAME has none now.
    Lost,
    /// "Cannot claim" (source 0xFE): the NAME has no address now.
    Released,
}

/// The address claim table of one interface. `Copy`, so that the module
/// can copy an empty one from a `static` into its allocation without
/// building it on the kernel stack (18 KiB).
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub struct AcTable {
    ecus: [Ecu; ECU_SLOTS],
    /// The ECU holding each address (index into `ecus`), or `NONE`.
    map: [u16; 256],
    /// The ECU with a pending claim of each address, or `NONE`.
    pending: [u16; 256],
    /// Local sockets bound to each address directly (not by NAME).
    bound: [u32; 256],
    /// No pending claim becomes valid before this time, if set: the
    /// earliest deadline, or earlier (a claim pending when it was noted
    /// may have been dropped since; [`AcTable::settle`] then finds nothing
    /// due and notes the next one). Lets `settle` skip the table's scan
    /// on every frame.
    due: Option<u64>,
}

impl Default for AcTable {
    fn default() -> Self {
        Self::new()
    }
}

impl AcTable {
    /// An empty table.
    pub const fn new() -> Self {
        AcTable {
            ecus: [FREE; ECU_SLOTS],
            map: [NONE; 256],
            pending: [NONE; 256],
            bound: [0; 256],
            due: None,
        }
    }

    fn find(&self, name: u64) -> Option<usize> {
        if name == J1939_NO_NAME {
            return None;
        }
        self.ecus.iter().position(|e| e.name == name)
    }

    fn create(&mut self, name: u64) -> Option<usize> {
        let i = self.ecus.iter().position(|e| e.name == 0)?;
        self.ecus[i] = Ecu { name, ..FREE };
        Some(i)
    }

    fn slot(i: usize) -> u16 {
        i as u16
    }

    fn is_mapped(&self, i: usize) -> bool {
        let a = self.ecus[i].addr;
        addr_is_unicast(a) && usize::from(self.map[usize::from(a)]) == i
    }

    /// Drops ECU `i`'s mapping and pending claim; frees the entry when
    /// nothing refers to it any more.
    fn unmap(&mut self, i: usize) {
        self.unmap_keep(i);
        self.release_if_unused(i);
    }

    /// [`Self::unmap`], keeping the entry (its NAME is about to get a new
    /// address or to be released by the caller).
    fn unmap_keep(&mut self, i: usize) {
        let a = usize::from(self.ecus[i].addr);
        if addr_is_unicast(self.ecus[i].addr) {
            if usize::from(self.map[a]) == i {
                self.map[a] = NONE;
            }
            if usize::from(self.pending[a]) == i {
                self.pending[a] = NONE;
            }
        }
        self.ecus[i].claim_at = None;
    }

    fn release_if_unused(&mut self, i: usize) {
        let e = &self.ecus[i];
        if e.local_users == 0 && e.claim_at.is_none() && !self.is_mapped(i) {
            self.ecus[i] = FREE;
        }
    }

    /// An ADDRESS_CLAIMED frame (ours or a peer's) from source `sa` with
    /// `data` arrived at `now` (mainline's `j1939_ac_process`). The NAME
    /// is the 8 data bytes, little endian.
    pub fn on_claim(&mut self, sa: u8, data: &[u8], now: u64) -> ClaimResult {
        let Ok(b) = <[u8; 8]>::try_from(data) else {
            return ClaimResult::Ignored;
        };
        let name = u64::from_le_bytes(b);
        if name == J1939_NO_NAME || sa == J1939_NO_ADDR {
            return ClaimResult::Ignored;
        }
        let i = match self.find(name) {
            Some(i) => i,
            None if addr_is_unicast(sa) => match self.create(name) {
                Some(i) => i,
                None => return ClaimResult::Ignored,
            },
            // An unknown NAME that cannot claim: nothing to forget.
            None => return ClaimResult::Released,
        };
        let e = self.ecus[i];
        if e.addr == sa
            && addr_is_unicast(sa)
            && (self.is_mapped(i) || usize::from(self.pending[usize::from(sa)]) == i)
        {
            return ClaimResult::Repeated;
        }
        // The previous claim of this NAME, mapped or pending, is over.
        self.unmap_keep(i);
        if !addr_is_unicast(sa) {
            self.ecus[i].addr = J1939_IDLE_ADDR;
            self.release_if_unused(i);
            return ClaimResult::Released;
        }
        self.ecus[i].addr = sa;
        let a = usize::from(sa);
        for rival in [self.map[a], self.pending[a]] {
            if rival == NONE {
                continue;
            }
            let r = usize::from(rival);
            if self.ecus[r].name < name {
                self.ecus[i].addr = J1939_IDLE_ADDR;
                self.release_if_unused(i);
                return ClaimResult::Lost;
            }
        }
        for rival in [self.map[a], self.pending[a]] {
            if rival != NONE {
                self.unmap(usize::from(rival));
            }
        }
        let at = now.saturating_add(AC_WINDOW_NS);
        self.ecus[i].claim_at = Some(at);
        self.pending[a] = Self::slot(i);
        self.due = Some(self.due.map_or(at, |d| d.min(at)));
        ClaimResult::Pending(at)
    }

    /// Feeds any received frame (source `sa`, PGN `pgn`, payload `data`)
    /// to the table: only ADDRESS_CLAIMED frames change it.
    pub fn on_frame(&mut self, sa: u8, pgn: u32, data: &[u8], now: u64) -> Option<ClaimResult> {
        (pgn == J1939_PGN_ADDRESS_CLAIMED).then(|| self.on_claim(sa, data, now))
    }

    /// The earliest time a pending claim becomes valid.
    pub fn next_deadline(&self) -> Option<u64> {
        self.pending
            .iter()
            .filter(|&&p| p != NONE)
            .filter_map(|&p| self.ecus.get(usize::from(p)).and_then(|e| e.claim_at))
            .min()
    }

    /// The timer expired at `now`: every claim whose window has passed
    /// becomes valid. Early calls do nothing.
    pub fn on_timer(&mut self, now: u64) {
        for a in 0..256 {
            let p = self.pending[a];
            if p == NONE {
                continue;
            }
            let i = usize::from(p);
            if self.ecus[i].claim_at.is_some_and(|t| t <= now) {
                self.ecus[i].claim_at = None;
                self.pending[a] = NONE;
                // A lower NAME never pends beside a mapped one (on_claim).
                if self.map[a] != NONE {
                    let old = usize::from(self.map[a]);
                    self.map[a] = NONE;
                    self.release_if_unused(old);
                }
                self.map[a] = p;
            }
        }
        self.due = self.next_deadline();
    }

    /// Brings the claims whose window has passed by `now` into force, as
    /// [`AcTable::on_timer`] at each deadline would have: for a caller
    /// with no timer, which calls this before every question it asks and
    /// every frame it feeds (the table only answers at those moments, so
    /// the answers are the same). Cheap when nothing is due (no scan).
    pub fn settle(&mut self, now: u64) {
        if self.due.is_some_and(|d| d <= now) {
            self.on_timer(now);
        }
    }

    /// The address of `name` (mainline's `j1939_name_to_addr`):
    /// [`J1939_NO_ADDR`] for no NAME, [`J1939_IDLE_ADDR`] while it holds
    /// none (unknown, lost, or inside its claim window).
    pub fn name_to_addr(&self, name: u64) -> u8 {
        if name == J1939_NO_NAME {
            return J1939_NO_ADDR;
        }
        match self.find(name) {
            Some(i) if self.is_mapped(i) => self.ecus[i].addr,
            _ => J1939_IDLE_ADDR,
        }
    }

    /// The NAME holding `addr`, or [`J1939_NO_NAME`] (mainline's
    /// `j1939_ac_recv` fills the source and destination NAMEs of a
    /// received frame from this).
    pub fn addr_to_name(&self, addr: u8) -> u64 {
        if !addr_is_unicast(addr) {
            return J1939_NO_NAME;
        }
        match self.map[usize::from(addr)] {
            NONE => J1939_NO_NAME,
            i => self
                .ecus
                .get(usize::from(i))
                .map_or(J1939_NO_NAME, |e| e.name),
        }
    }

    /// Whether a local socket sends from `addr` (bound to it, or bound to
    /// the NAME holding it): the transport protocol acts for local
    /// addresses only (mainline's `J1939_ECU_LOCAL_SRC/DST`).
    pub fn is_local(&self, addr: u8) -> bool {
        if !addr_is_unicast(addr) {
            return false;
        }
        let a = usize::from(addr);
        self.bound[a] > 0
            || (self.map[a] != NONE
                && self
                    .ecus
                    .get(usize::from(self.map[a]))
                    .is_some_and(|e| e.local_users > 0))
    }

    /// A socket binds with `name` and `sa` (mainline's
    /// `j1939_local_ecu_get`). `ENOMEM` when a new NAME finds no entry.
    pub fn local_get(&mut self, name: u64, sa: u8) -> Result<(), i32> {
        if name != J1939_NO_NAME {
            let i = match self.find(name) {
                Some(i) => i,
                None => self.create(name).ok_or(ENOMEM)?,
            };
            self.ecus[i].local_users = self.ecus[i].local_users.saturating_add(1);
        }
        if addr_is_unicast(sa) {
            let b = &mut self.bound[usize::from(sa)];
            *b = b.saturating_add(1);
        }
        Ok(())
    }

    /// The socket of a [`AcTable::local_get`] unbinds (same arguments).
    /// Unbalanced calls are ignored.
    pub fn local_put(&mut self, name: u64, sa: u8) {
        if addr_is_unicast(sa) {
            let b = &mut self.bound[usize::from(sa)];
            *b = b.saturating_sub(1);
        }
        if let Some(i) = self.find(name) {
            self.ecus[i].local_users = self.ecus[i].local_users.saturating_sub(1);
            self.release_if_unused(i);
        }
    }

    /// The interface went down (mainline's `j1939_ecu_unmap_all`): every
    /// address and pending claim is forgotten; bound sockets stay.
    pub fn unmap_all(&mut self) {
        for i in 0..ECU_SLOTS {
            if self.ecus[i].name != 0 {
                self.unmap(i);
            }
        }
    }

    /// Number of ECU entries in use.
    pub fn ecus_in_use(&self) -> usize {
        self.ecus.iter().filter(|e| e.name != 0).count()
    }

    /// Source and destination addresses of a message a socket sends
    /// (mainline's `j1939_ac_fixup`): `src_name`/`sa` of the socket,
    /// `dst_name`/`da` of the destination, the PGN and payload.
    ///
    /// - An ADDRESS_CLAIMED message must be 8 bytes carrying the
    ///   socket's NAME, from a source other than 0xFF, to broadcast
    ///   (`EPROTO` otherwise); its NAME must be known (`ENODEV`); if it
    ///   claims another address than the NAME holds, the NAME loses the
    ///   old one at once (traffic waits for the new claim).
    /// - Otherwise a NAME's address replaces `sa`: `EADDRNOTAVAIL` when
    ///   it has none, except for a Request for Address Claimed, which
    ///   goes out from 0xFE.
    /// - A destination NAME must hold an address (`EADDRNOTAVAIL`).
    pub fn fixup_send(
        &mut self,
        src_name: u64,
        sa: u8,
        dst_name: u64,
        da: u8,
        pgn: u32,
        data: &[u8],
    ) -> Result<(u8, u8), i32> {
        let mut sa = sa;
        let mut da = da;
        if pgn == J1939_PGN_ADDRESS_CLAIMED {
            let ok_len = data.len() == 8;
            let carried = <[u8; 8]>::try_from(data).map(u64::from_le_bytes).ok();
            if !ok_len
                || carried != Some(src_name)
                || sa == J1939_NO_ADDR
                || dst_name != J1939_NO_NAME
                || da != J1939_NO_ADDR
            {
                return Err(EPROTO);
            }
            let i = self.find(src_name).ok_or(ENODEV)?;
            if self.ecus[i].addr != sa {
                self.unmap(i);
            }
        } else if src_name != J1939_NO_NAME {
            let a = self.name_to_addr(src_name);
            let request_for_ac = pgn == J1939_PGN_REQUEST
                && data.len() >= 3
                && u32::from_le_bytes([data[0], data[1], data[2], 0]) == J1939_PGN_ADDRESS_CLAIMED;
            if !addr_is_unicast(a) && !request_for_ac {
                return Err(EADDRNOTAVAIL);
            }
            sa = a;
        }
        if dst_name != J1939_NO_NAME {
            let a = self.name_to_addr(dst_name);
            if !addr_is_unicast(a) {
                return Err(EADDRNOTAVAIL);
            }
            da = a;
        }
        Ok((sa, da))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn claim(t: &mut AcTable, name: u64, sa: u8, now: u64) -> ClaimResult {
        t.on_claim(sa, &name.to_le_bytes(), now)
    }

    #[test]
    fn a_claim_is_usable_after_the_window() {
        let mut t = AcTable::new();
        assert_eq!(
            claim(&mut t, 0x100, 0x20, 0),
            ClaimResult::Pending(250 * MS)
        );
        assert_eq!(t.next_deadline(), Some(250 * MS));
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        assert_eq!(t.addr_to_name(0x20), 0);
        t.on_timer(249 * MS);
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        t.on_timer(250 * MS);
        assert_eq!(t.name_to_addr(0x100), 0x20);
        assert_eq!(t.addr_to_name(0x20), 0x100);
        assert_eq!(t.next_deadline(), None);
        // A repeated claim neither restarts the window nor unmaps.
        assert_eq!(claim(&mut t, 0x100, 0x20, 300 * MS), ClaimResult::Repeated);
        assert_eq!(t.name_to_addr(0x100), 0x20);
        assert_eq!(t.next_deadline(), None);
    }

    #[test]
    fn settle_brings_claims_into_force_at_their_deadline() {
        let mut t = AcTable::new();
        t.settle(0);
        claim(&mut t, 0x100, 0x20, 0);
        claim(&mut t, 0x200, 0x21, 100 * MS);
        t.settle(249 * MS);
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        t.settle(250 * MS);
        assert_eq!(t.name_to_addr(0x100), 0x20);
        assert_eq!(t.name_to_addr(0x200), J1939_IDLE_ADDR);
        t.settle(349 * MS);
        assert_eq!(t.name_to_addr(0x200), J1939_IDLE_ADDR);
        t.settle(350 * MS);
        assert_eq!(t.name_to_addr(0x200), 0x21);
        // A pending claim that lost its address before its deadline
        // leaves a stale `due`: settling then changes nothing.
        claim(&mut t, 0x900, 0x30, 400 * MS);
        claim(&mut t, 0x800, 0x30, 500 * MS);
        t.settle(650 * MS);
        assert_eq!(t.addr_to_name(0x30), 0);
        t.settle(750 * MS);
        assert_eq!(t.addr_to_name(0x30), 0x800);
    }

    #[test]
    fn repeated_claim_inside_the_window_keeps_its_deadline() {
        let mut t = AcTable::new();
        claim(&mut t, 0x100, 0x20, 0);
        assert_eq!(claim(&mut t, 0x100, 0x20, 100 * MS), ClaimResult::Repeated);
        assert_eq!(t.next_deadline(), Some(250 * MS));
    }

    #[test]
    fn lower_name_wins() {
        let mut t = AcTable::new();
        claim(&mut t, 0x500, 0x20, 0);
        t.on_timer(250 * MS);
        // A lower NAME takes the address: the old holder loses it at once.
        assert_eq!(
            claim(&mut t, 0x300, 0x20, 300 * MS),
            ClaimResult::Pending(550 * MS)
        );
        assert_eq!(t.name_to_addr(0x500), J1939_IDLE_ADDR);
        assert_eq!(t.addr_to_name(0x20), 0);
        // The old holder re-claiming loses.
        assert_eq!(claim(&mut t, 0x500, 0x20, 310 * MS), ClaimResult::Lost);
        t.on_timer(550 * MS);
        assert_eq!(t.name_to_addr(0x300), 0x20);
        assert_eq!(t.name_to_addr(0x500), J1939_IDLE_ADDR);
        // A higher NAME against a mapped one loses.
        assert_eq!(claim(&mut t, 0x900, 0x20, 600 * MS), ClaimResult::Lost);
        assert_eq!(t.name_to_addr(0x300), 0x20);
    }

    #[test]
    fn priority_decides_between_pending_claims() {
        // Mainline would map whichever timer expires first (0x700 here).
        let mut t = AcTable::new();
        claim(&mut t, 0x700, 0x30, 0);
        assert_eq!(
            claim(&mut t, 0x200, 0x30, 100 * MS),
            ClaimResult::Pending(350 * MS)
        );
        t.on_timer(250 * MS);
        assert_eq!(t.addr_to_name(0x30), 0);
        t.on_timer(350 * MS);
        assert_eq!(t.addr_to_name(0x30), 0x200);
        assert_eq!(t.name_to_addr(0x700), J1939_IDLE_ADDR);
    }

    #[test]
    fn moving_and_releasing() {
        let mut t = AcTable::new();
        claim(&mut t, 0x100, 0x20, 0);
        t.on_timer(250 * MS);
        // A claim of another address drops the old one at once.
        assert_eq!(
            claim(&mut t, 0x100, 0x21, 300 * MS),
            ClaimResult::Pending(550 * MS)
        );
        assert_eq!(t.addr_to_name(0x20), 0);
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        t.on_timer(550 * MS);
        assert_eq!(t.name_to_addr(0x100), 0x21);
        // Cannot claim (0xFE): no address.
        assert_eq!(claim(&mut t, 0x100, 0xFE, 600 * MS), ClaimResult::Released);
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        assert_eq!(t.ecus_in_use(), 0);
        // Re-claiming the old address works again (mainline: ignored).
        assert_eq!(
            claim(&mut t, 0x100, 0x21, 700 * MS),
            ClaimResult::Pending(950 * MS)
        );
    }

    #[test]
    fn reclaim_after_ifdown_maps_again() {
        let mut t = AcTable::new();
        t.local_get(0x100, J1939_NO_ADDR).unwrap();
        claim(&mut t, 0x100, 0x20, 0);
        t.on_timer(250 * MS);
        t.unmap_all();
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
        assert_eq!(
            claim(&mut t, 0x100, 0x20, 1000 * MS),
            ClaimResult::Pending(1250 * MS)
        );
        t.on_timer(1250 * MS);
        assert_eq!(t.name_to_addr(0x100), 0x20);
    }

    #[test]
    fn invalid_claims_are_ignored() {
        let mut t = AcTable::new();
        assert_eq!(t.on_claim(0x20, &[1, 2, 3], 0), ClaimResult::Ignored);
        assert_eq!(claim(&mut t, 0, 0x20, 0), ClaimResult::Ignored);
        assert_eq!(claim(&mut t, 5, 0xFF, 0), ClaimResult::Ignored);
        assert_eq!(claim(&mut t, 5, 0xFE, 0), ClaimResult::Released);
        assert_eq!(t.ecus_in_use(), 0);
        assert_eq!(t.on_frame(0x20, 0xEA00, &5u64.to_le_bytes(), 0), None);
        assert!(t
            .on_frame(0x20, J1939_PGN_ADDRESS_CLAIMED, &5u64.to_le_bytes(), 0)
            .is_some());
    }

    #[test]
    fn table_full_ignores_new_names() {
        let mut t = AcTable::new();
        for n in 0..ECU_SLOTS as u64 {
            t.local_get(n + 1, J1939_NO_ADDR).unwrap();
        }
        assert_eq!(claim(&mut t, 0xFFFF, 0x10, 0), ClaimResult::Ignored);
        assert_eq!(t.local_get(0xFFFF, 0x10), Err(ENOMEM));
        // Known NAMEs still claim.
        assert_eq!(claim(&mut t, 1, 0x10, 0), ClaimResult::Pending(250 * MS));
    }

    #[test]
    fn local_users() {
        let mut t = AcTable::new();
        assert!(!t.is_local(0x20));
        t.local_get(J1939_NO_NAME, 0x20).unwrap();
        assert!(t.is_local(0x20));
        t.local_put(J1939_NO_NAME, 0x20);
        assert!(!t.is_local(0x20));
        t.local_get(0x100, J1939_NO_ADDR).unwrap();
        claim(&mut t, 0x100, 0x40, 0);
        assert!(!t.is_local(0x40));
        t.on_timer(250 * MS);
        assert!(t.is_local(0x40));
        t.local_put(0x100, J1939_NO_ADDR);
        assert!(!t.is_local(0x40));
        // Still mapped: a peer's claim keeps the entry.
        assert_eq!(t.name_to_addr(0x100), 0x40);
        t.local_put(0x100, J1939_NO_ADDR);
        t.local_put(J1939_NO_NAME, 0x77);
    }

    #[test]
    fn send_fixups() {
        let mut t = AcTable::new();
        let pgn = 0xEF00;
        // By address: untouched.
        assert_eq!(t.fixup_send(0, 0x20, 0, 0x30, pgn, &[1]), Ok((0x20, 0x30)));
        // By NAME without a claim: EADDRNOTAVAIL, also inside the window.
        t.local_get(0x100, J1939_NO_ADDR).unwrap();
        assert_eq!(
            t.fixup_send(0x100, 0xFF, 0, 0x30, pgn, &[1]),
            Err(EADDRNOTAVAIL)
        );
        claim(&mut t, 0x100, 0x20, 0);
        assert_eq!(
            t.fixup_send(0x100, 0xFF, 0, 0x30, pgn, &[1]),
            Err(EADDRNOTAVAIL)
        );
        // A request for address claimed goes out from 0xFE.
        let req = [0x00, 0xEE, 0x00];
        assert_eq!(
            t.fixup_send(0x100, 0xFF, 0, 0xFF, J1939_PGN_REQUEST, &req),
            Ok((0xFE, 0xFF))
        );
        t.on_timer(250 * MS);
        assert_eq!(
            t.fixup_send(0x100, 0xFF, 0, 0x30, pgn, &[1]),
            Ok((0x20, 0x30))
        );
        // Destination by NAME.
        assert_eq!(
            t.fixup_send(0x100, 0xFF, 0x999, 0xFF, pgn, &[1]),
            Err(EADDRNOTAVAIL)
        );
        assert_eq!(
            t.fixup_send(0, 0x21, 0x100, 0xFF, pgn, &[1]),
            Ok((0x21, 0x20))
        );
    }

    #[test]
    fn sending_address_claims() {
        let mut t = AcTable::new();
        let ac = J1939_PGN_ADDRESS_CLAIMED;
        let n = 0x100u64.to_le_bytes();
        assert_eq!(t.fixup_send(0x100, 0x20, 0, 0xFF, ac, &n[..7]), Err(EPROTO));
        assert_eq!(t.fixup_send(0x101, 0x20, 0, 0xFF, ac, &n), Err(EPROTO));
        assert_eq!(t.fixup_send(0x100, 0xFF, 0, 0xFF, ac, &n), Err(EPROTO));
        assert_eq!(t.fixup_send(0x100, 0x20, 0, 0x30, ac, &n), Err(EPROTO));
        assert_eq!(t.fixup_send(0x100, 0x20, 5, 0xFF, ac, &n), Err(EPROTO));
        assert_eq!(t.fixup_send(0x100, 0x20, 0, 0xFF, ac, &n), Err(ENODEV));
        t.local_get(0x100, J1939_NO_ADDR).unwrap();
        assert_eq!(t.fixup_send(0x100, 0x20, 0, 0xFF, ac, &n), Ok((0x20, 0xFF)));
        claim(&mut t, 0x100, 0x20, 0);
        t.on_timer(250 * MS);
        // Claiming another address: the old one is dropped at once.
        assert_eq!(t.fixup_send(0x100, 0x21, 0, 0xFF, ac, &n), Ok((0x21, 0xFF)));
        assert_eq!(t.name_to_addr(0x100), J1939_IDLE_ADDR);
    }
}
