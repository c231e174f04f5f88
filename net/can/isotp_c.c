// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_isotp: its module parameters (6.12's Rust module! macro
 * has none) and its private copy of the helpers. The values are clamped
 * in Rust where they are read, at bind.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../rust/helpers/rcan_helpers.c"
#include "../../rust/helpers/rcan_params.h"

static unsigned int rcan_isotp_max_pdu_size = 8300;

module_param_named(max_pdu_size, rcan_isotp_max_pdu_size, uint, 0444);
MODULE_PARM_DESC(max_pdu_size, "maximum PDU size in bytes (4095 to 1049600, default 8300)");

/*
 * Test-only, not mainline's (its timeouts are fixed): N_Bs/N_Cr and the
 * echo wait in ms, read at bind, clamped in Rust (rcan_core::isotp::
 * Timeouts::from_ms). Writable at run time so that tests sharing the
 * loaded module set them for their own sockets only (isotp.rst).
 */
static unsigned int rcan_isotp_fc_timeout_ms = 1000;
static unsigned int rcan_isotp_echo_timeout_ms = 2000;

module_param_named(fc_timeout_ms, rcan_isotp_fc_timeout_ms, uint, 0644);
MODULE_PARM_DESC(fc_timeout_ms, "test only: N_Bs and N_Cr in ms for sockets bound afterwards (1 to 600000, default 1000 as mainline)");
module_param_named(echo_timeout_ms, rcan_isotp_echo_timeout_ms, uint, 0644);
MODULE_PARM_DESC(echo_timeout_ms, "test only: wait for a sent frame's echo in ms for sockets bound afterwards (1 to 600000, default 2000 as mainline)");

/* Parameter numbers shared with isotp.rs. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(rcan_isotp_max_pdu_size);
	case 1: return READ_ONCE(rcan_isotp_fc_timeout_ms);
	case 2: return READ_ONCE(rcan_isotp_echo_timeout_ms);
	default: return 0;
	}
}
