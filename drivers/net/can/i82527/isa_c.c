// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_i82527_isa (thesis 5.3.11): the iomem/irq and bit timing
 * module parameters (6.12's Rust module! macro has none; read through
 * rust/glue/params.rs) and the module's private copy of the helpers. The
 * window is claimed and mapped by the glue's IoWindow (rust/glue/isa.rs).
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

static unsigned long iomem;
module_param(iomem, ulong, 0444);
MODULE_PARM_DESC(iomem, "Physical address of the memory-mapped 82527 (required)");
static int irq;
module_param(irq, int, 0444);
MODULE_PARM_DESC(irq, "Interrupt line of the card (required)");
static unsigned char bt0 = 0x00;
module_param(bt0, byte, 0444);
MODULE_PARM_DESC(bt0, "82527 bit timing register 0 (default 0x00)");
static unsigned char bt1 = 0x2b;
module_param(bt1, byte, 0444);
MODULE_PARM_DESC(bt1, "82527 bit timing register 1 (default 0x2b: 500 kbit/s at 16 MHz, DSC)");
static unsigned char cpu_if = 0x40;
module_param(cpu_if, byte, 0444);
MODULE_PARM_DESC(cpu_if, "82527 CPU interface register: DSC 0x40, DMC 0x20, CEN 0x01 (default 0x40)");
static unsigned char clkout;
module_param(clkout, byte, 0444);
MODULE_PARM_DESC(clkout, "82527 clock out register: slew rate, divider (default 0)");
static unsigned char bus_cfg = 0x40;
module_param(bus_cfg, byte, 0444);
MODULE_PARM_DESC(bus_cfg, "82527 bus configuration register (default 0x40: comparator bypass)");

/* Parameter numbers shared with isa.rs. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(iomem);
	case 1: return (u64)(s64)READ_ONCE(irq);
	case 2: return READ_ONCE(bt0);
	case 3: return READ_ONCE(bt1);
	case 4: return READ_ONCE(cpu_if);
	case 5: return READ_ONCE(clkout);
	case 6: return READ_ONCE(bus_cfg);
	default: return 0;
	}
}
