// SPDX-License-Identifier: GPL-2.0
/*
 * Runs mainline's unmodified calc_bittiming.c and bittiming.c (copied from
 * the kernel source by ../bittiming-table.py) in user space: each input
 * line is "clock tseg1_min tseg1_max tseg2_min tseg2_max sjw_max brp_min
 * brp_max brp_inc bitrate sample_point tq prop_seg phase_seg1 phase_seg2
 * sjw"; for each, can_get_bittiming()'s errno and extended-ack text, and
 * the timing it set.
 */
#include "shim.h"
#include "calc_bittiming.c"
#include "bittiming.c"
int main(void)
{
	struct can_bittiming_const c = { "x" };
	unsigned clk;
	struct can_bittiming bt;
	while (scanf("%u %u %u %u %u %u %u %u %u %u %u %u %u %u %u %u", &clk,
		     &c.tseg1_min, &c.tseg1_max, &c.tseg2_min, &c.tseg2_max, &c.sjw_max,
		     &c.brp_min, &c.brp_max, &c.brp_inc, &bt.bitrate, &bt.sample_point,
		     &bt.tq, &bt.prop_seg, &bt.phase_seg1, &bt.phase_seg2, &bt.sjw) == 16) {
		struct net_device dev = { { { clk } } };
		struct netlink_ext_ack ack = { "" };
		bt.brp = 0;
		int err = can_get_bittiming(&dev, &bt, &c, NULL, 0, &ack);
		printf("RC %d MSG %s\n", err, ack.msg);
		if (!err)
			printf("BT %u %u %u %u %u %u %u %u\n", bt.bitrate, bt.sample_point, bt.tq,
			       bt.prop_seg, bt.phase_seg1, bt.phase_seg2, bt.sjw, bt.brp);
	}
	return 0;
}
