// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_tscan1: bit timing module parameters (6.12's Rust
 * module! macro has none) and the module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

/*
 * Optional preset of the bit timing (the thesis' CONFIG_SJA1000_BTR0/1
 * way: 0x01/0x14 is 500 kbit/s with the 16 MHz crystal). Unset (-1), the
 * device has no bit timing until `ip link set canX type can bitrate ...`
 * or sja1000config sets one, and refuses to come up before, as mainline.
 */
static short btr0 = -1;
static short btr1 = -1;
module_param(btr0, short, 0444);
MODULE_PARM_DESC(btr0, "SJA1000 bus timing register 0 preset (with btr1; default: none)");
module_param(btr1, short, 0444);
MODULE_PARM_DESC(btr1, "SJA1000 bus timing register 1 preset (with btr0; e.g. 0x14: 500 kbit/s with btr0 0x01)");

/* Parameter numbers: the SJA1000 core's BTR0/BTR1 (sja1000.rs). */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return (u64)(s64)READ_ONCE(btr0);
	case 1: return (u64)(s64)READ_ONCE(btr1);
	default: return 0;
	}
}
