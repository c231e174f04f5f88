// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_ctucanfd_sim: its module parameters (6.12's Rust module!
 * macro has none; read through rust/glue/params.rs) and the module's
 * private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>
#include <linux/string.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"
#include "../../../../rust/helpers/rcan_simcard.h"

static unsigned int cards = 2;
module_param(cards, uint, 0444);
MODULE_PARM_DESC(cards, "Number of simulated CTU CAN FD cores on the bus (1..8, default 2)");

/*
 * Fault injection, writable at run time through
 * /sys/module/rcan_ctucanfd_sim/parameters/ (see ctucanfd.rst); a fixed
 * buffer, see rcan_simcard.h.
 */
static char fault[RCAN_SIMCARD_FAULT_LEN] = "none";
module_param_string(fault, fault, sizeof(fault), 0644);
MODULE_PARM_DESC(fault, "Bus fault: none, noack, biterr, arblost, overrun (default none)");

static int fault_capt = -1;
module_param(fault_capt, int, 0644);
MODULE_PARM_DESC(fault_capt, "ERR_CAPT byte (ERR_TYPE << 5 | ERR_POS) of the biterr fault's bus errors (0..255; default -1: 0x03, bit error in the data field)");

static unsigned int fault_bit = 5;
module_param(fault_bit, uint, 0644);
MODULE_PARM_DESC(fault_bit, "Bit position (ALC_BIT) at which the arblost fault loses arbitration (0..31, default 5)");

/* Parameter numbers shared with sim.rs: 0 cards, 1 fault_capt, 2 fault_bit. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(cards);
	case 1: return (u64)(s64)READ_ONCE(fault_capt);
	case 2: return READ_ONCE(fault_bit);
	default: return 0;
	}
}

/* String parameter 3: fault. Any context. */
size_t rcan_module_param_str(unsigned int which, char *buf, size_t len)
{
	return rcan_simcard_fault_str(fault, which == 3, buf, len);
}
