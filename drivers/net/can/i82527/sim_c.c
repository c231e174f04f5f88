// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_i82527_sim: the `cards` module parameter (6.12's Rust
 * module! macro has none; read through rust/glue/params.rs) and the
 * module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

static unsigned int cards = 2;
module_param(cards, uint, 0444);
MODULE_PARM_DESC(cards, "Number of simulated 82527 cards on the bus (1..8, default 2)");

/* Parameter numbers shared with sim.rs: 0 cards. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	return which == 0 ? READ_ONCE(cards) : 0;
}
