// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_isotp: its module parameter (6.12's Rust module! macro
 * has none) and its private copy of the helpers. The value is clamped in
 * Rust (rcan_core::isotp::clamp_max_pdu_size) where it is read, at bind.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../rust/helpers/rcan_helpers.c"
#include "../../rust/helpers/rcan_params.h"

static unsigned int rcan_isotp_max_pdu_size = 8300;

module_param_named(max_pdu_size, rcan_isotp_max_pdu_size, uint, 0444);
MODULE_PARM_DESC(max_pdu_size, "maximum PDU size in bytes (4095 to 1049600, default 8300)");

/* Parameter numbers shared with isotp.rs. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(rcan_isotp_max_pdu_size);
	default: return 0;
	}
}
