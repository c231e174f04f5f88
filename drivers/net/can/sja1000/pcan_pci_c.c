// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_pcan_pci: bit timing module parameters (6.12's Rust
 * module! macro has none) and the module's private copy of the helpers.
 * Defaults are the thesis' Kconfig values (CONFIG_SJA1000_BTR0/1: 500
 * kbit/s with the card's 16 MHz clock).
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

static unsigned char btr0 = 0x01;
static unsigned char btr1 = 0x14;
module_param(btr0, byte, 0444);
MODULE_PARM_DESC(btr0, "SJA1000 bus timing register 0 (default 0x01)");
module_param(btr1, byte, 0444);
MODULE_PARM_DESC(btr1, "SJA1000 bus timing register 1 (default 0x14: 500 kbit/s)");

/* Parameter numbers: the SJA1000 core's BTR0/BTR1 (sja1000.rs). */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(btr0);
	case 1: return READ_ONCE(btr1);
	default: return 0;
	}
}
