/* SPDX-License-Identifier: GPL-2.0 */
/*
 * The SJA1000 core's module parameters btr0/btr1, shared by every
 * SJA1000 front-end's C shim (issue 19: once, not in each shim).
 *
 * An optional preset of the bit timing (the thesis' CONFIG_SJA1000_BTR0/1
 * way: 0x01/0x14 is 500 kbit/s with the 16 MHz crystal). Unset (-1), the
 * device has no bit timing until `ip link set canX type can bitrate ...`
 * or sja1000config sets one, and refuses to come up before, as mainline.
 *
 * They are parameters 0 and 1 of the shim's rcan_module_param (sja1000.rs:
 * BTR0, BTR1): the shim's switch starts with RCAN_SJA1000_BTR_CASES.
 * Included once, by the shim, after <linux/moduleparam.h>.
 */
#ifndef _RCAN_SJA1000_BTR_PARAMS_H
#define _RCAN_SJA1000_BTR_PARAMS_H

static short btr0 = -1;
static short btr1 = -1;
module_param(btr0, short, 0444);
MODULE_PARM_DESC(btr0, "SJA1000 bus timing register 0 preset (with btr1; default: none)");
module_param(btr1, short, 0444);
MODULE_PARM_DESC(btr1, "SJA1000 bus timing register 1 preset (with btr0; e.g. 0x14: 500 kbit/s with btr0 0x01)");

#define RCAN_SJA1000_BTR_CASES \
	case 0: return (u64)(s64)READ_ONCE(btr0); \
	case 1: return (u64)(s64)READ_ONCE(btr1)

#endif /* _RCAN_SJA1000_BTR_PARAMS_H */
