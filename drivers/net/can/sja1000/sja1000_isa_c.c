// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_sja1000_isa: module parameters (6.12's Rust module!
 * macro has none) and the module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"

#define RCAN_ISA_MAX_BOARDS 8

static unsigned long iomem[RCAN_ISA_MAX_BOARDS];
static unsigned int n_iomem;
module_param_hw_array(iomem, ulong, iomem, &n_iomem, 0444);
MODULE_PARM_DESC(iomem, "Physical addresses of the cards' SJA1000s (up to 8)");

static int irq[RCAN_ISA_MAX_BOARDS];
static unsigned int n_irq;
module_param_hw_array(irq, int, irq, &n_irq, 0444);
MODULE_PARM_DESC(irq, "Interrupt line of each card (0 or missing: autoprobe)");

static unsigned char btr0 = 0x01;
static unsigned char btr1 = 0x14;
module_param(btr0, byte, 0444);
MODULE_PARM_DESC(btr0, "SJA1000 bus timing register 0 (default 0x01)");
module_param(btr1, byte, 0444);
MODULE_PARM_DESC(btr1, "SJA1000 bus timing register 1 (default 0x14: 500 kbit/s)");

/* Number of boards given with iomem=. */
unsigned int rcan_isa_boards(void);
unsigned int rcan_isa_boards(void)
{
	return min_t(unsigned int, READ_ONCE(n_iomem), RCAN_ISA_MAX_BOARDS);
}

/* Board i's address and configured interrupt line (0: autoprobe). */
void rcan_isa_board(unsigned int i, unsigned long *addr, int *line);
void rcan_isa_board(unsigned int i, unsigned long *addr, int *line)
{
	*addr = i < RCAN_ISA_MAX_BOARDS ? READ_ONCE(iomem[i]) : 0;
	*line = i < READ_ONCE(n_irq) && i < RCAN_ISA_MAX_BOARDS ? READ_ONCE(irq[i]) : 0;
}

u8 rcan_isa_btr(int which);
u8 rcan_isa_btr(int which)
{
	return which ? READ_ONCE(btr1) : READ_ONCE(btr0);
}
