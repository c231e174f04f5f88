/* SPDX-License-Identifier: GPL-2.0 WITH Linux-syscall-note */
/*
 * rcan Intel 82527 driver family (thesis 5.3.10): device-private ioctls on
 * any socket, with struct ifreq naming the interface and ifr_data pointing
 * to the structure below.
 *
 *   SIOCRCANI82527GET     read struct rcan_i82527_setup
 *   SIOCRCANI82527ANSWER  publish (flags bit 0 set) or withdraw (clear)
 *                         the data frame remote-answer slot `slot` (0..11,
 *                         message object 2 + slot) answers remote frames
 *                         for its identifier with, automatically, without
 *                         waking the host; CAP_NET_ADMIN (EPERM), ERANGE
 *                         for a bad slot, EINVAL for a remote or error
 *                         frame. Works up or down; kept across down/up.
 *
 * A standard answer object is compared under the global standard mask,
 * which the driver opens as far as the bound sockets' filters need (see
 * Documentation/networking/rcan/i82527.rst): std_answers_exact tells
 * whether standard answers currently match their own identifier only.
 * Extended answers are always exact.
 */
#ifndef _UAPI_LINUX_CAN_RCAN_I82527_H
#define _UAPI_LINUX_CAN_RCAN_I82527_H

#include <linux/types.h>
#include <linux/sockios.h>
#include <linux/can.h>

#define SIOCRCANI82527GET	(SIOCDEVPRIVATE + 0)
#define SIOCRCANI82527ANSWER	(SIOCDEVPRIVATE + 2)

#define RCAN_I82527_ANSWERS	12

struct rcan_i82527_setup {
	__u8	cpu_if;		/* CPU interface register (DSC, DMC, CEN) */
	__u8	clkout;		/* clock out register */
	__u8	bus_cfg;	/* bus configuration register */
	__u8	bt0;		/* bit timing 0: SJW, BRP */
	__u8	bt1;		/* bit timing 1: SPL, TSEG2, TSEG1 */
	__u8	state;		/* 0 active, 1 warning, 3 bus-off */
	__u8	std_answers_exact;
	__u8	pad;
	__u32	restarts;	/* automatic restarts after bus-off */
};

#define RCAN_I82527_PUBLISH	0x1

struct rcan_i82527_answer {
	__u32	slot;		/* 0 .. RCAN_I82527_ANSWERS - 1 */
	__u32	flags;		/* RCAN_I82527_PUBLISH: publish, else withdraw */
	struct can_frame frame;	/* data frame (no RTR/ERR flag) */
};

#endif /* _UAPI_LINUX_CAN_RCAN_I82527_H */
