// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_i82527_sim: the `cards` module parameter (6.12's Rust
 * module! macro has none; read through rust/glue/params.rs) and the
 * module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>
#include <linux/string.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"
#include "../../../../rust/helpers/rcan_simcard.h"

static unsigned int cards = 2;
module_param(cards, uint, 0444);
MODULE_PARM_DESC(cards, "Number of simulated 82527 cards on the bus (1..8, default 2)");

/*
 * Fault injection, writable at run time through
 * /sys/module/rcan_i82527_sim/parameters/ (see i82527.rst); a fixed
 * buffer, see rcan_simcard.h.
 */
static char fault[RCAN_SIMCARD_FAULT_LEN] = "none";
module_param_string(fault, fault, sizeof(fault), 0644);
MODULE_PARM_DESC(fault, "Bus fault: none, noack, biterr (default none)");

/* Parameter numbers shared with sim.rs: 0 cards, string 1 fault. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	return which == 0 ? READ_ONCE(cards) : 0;
}

/* String parameter 1: fault. Any context. */
size_t rcan_module_param_str(unsigned int which, char *buf, size_t len)
{
	return rcan_simcard_fault_str(fault, which == 1, buf, len);
}
