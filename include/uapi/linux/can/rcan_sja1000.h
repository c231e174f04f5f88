/* SPDX-License-Identifier: GPL-2.0 WITH Linux-syscall-note */
/*
 * rcan SJA1000 driver family: controller setup from user space (thesis
 * 5.3.6, the sja1000config tool). Device-private ioctls on any socket, with
 * struct ifreq naming the interface and ifr_data pointing to a
 * struct rcan_sja1000_setup:
 *
 *   SIOCRCANSJA1000GET  read the setup, error state and counters
 *   SIOCRCANSJA1000SET  set btr0, btr1, ocr, cdr (the other fields are
 *                       ignored); needs CAP_NET_ADMIN (EPERM) and the
 *                       interface down (EBUSY); applied when it comes up
 */
#ifndef _UAPI_LINUX_CAN_RCAN_SJA1000_H
#define _UAPI_LINUX_CAN_RCAN_SJA1000_H

#include <linux/types.h>
#include <linux/sockios.h>

#define SIOCRCANSJA1000GET	(SIOCDEVPRIVATE + 0)
#define SIOCRCANSJA1000SET	(SIOCDEVPRIVATE + 1)

struct rcan_sja1000_setup {
	__u8	btr0;		/* bus timing 0: SJW, BRP */
	__u8	btr1;		/* bus timing 1: SAM, TSEG2, TSEG1 */
	__u8	ocr;		/* output control */
	__u8	cdr;		/* clock divider (PeliCAN bit set by the driver) */
	__u8	state;		/* 0 active, 1 warning, 2 passive, 3 bus-off */
	__u8	rxerr;		/* receive error counter */
	__u8	txerr;		/* transmit error counter */
	__u8	pad;
	__u32	restarts;	/* automatic restarts after bus-off */
	__u32	xtal_hz;	/* crystal frequency of the board */
};

#endif /* _UAPI_LINUX_CAN_RCAN_SJA1000_H */
