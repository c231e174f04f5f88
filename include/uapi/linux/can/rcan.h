/* SPDX-License-Identifier: GPL-2.0 WITH Linux-syscall-note */
/*
 * rcan: the thesis CAN socket API (CANPROTO_CAN), thesis section 5.2.
 *
 * socket(PF_CAN, SOCK_RAW, CANPROTO_CAN) opens a socket of the CAN 2.0A/B
 * data link protocol. Its address, struct sockaddr_canarb, carries the 32-bit
 * software arbitration field of thesis figure 5-5 in host byte order:
 *
 *   bit 31..21  11-bit (base) identifier
 *   bit 20..3   18-bit extended identifier (zero in standard frames)
 *   bit 2       IDE  (CAN_IDE: 1 = extended format frame)
 *   bit 1       RTR  (CAN_RTR: 1 = remote frame)
 *   bit 0       unused, must be 0
 *
 * so that bits 31..3 hold the 29-bit identifier of an extended frame as a
 * whole. In a filter mask a 1 bit means "don't care".
 *
 * The thesis calls the address struct sockaddr_can. Mainline SocketCAN's
 * <linux/can.h> already defines a different struct of that name, and both
 * stacks must be usable from one program, so ours is struct sockaddr_canarb.
 * The layout is the thesis' own.
 */
#ifndef _UAPI_LINUX_CAN_RCAN_H
#define _UAPI_LINUX_CAN_RCAN_H

#include <linux/types.h>
#include <linux/socket.h>

#ifndef AF_CAN
#define AF_CAN		29
#endif
#ifndef PF_CAN
#define PF_CAN		AF_CAN
#endif

/*
 * Protocol numbers of the rcan family. Mainline uses 1..7 (CAN_RAW = 1 is
 * served by rcan with mainline's ABI); the thesis protocols live above them.
 */
#define CANPROTO_CAN	16	/* thesis CAN 2.0 data link protocol, SOCK_RAW */
#define CANPROTO_DSOR	17	/* DSOR higher-layer protocol, SOCK_DGRAM */
#define CANPROTO_MAX	24	/* size of the pf_can protocol table */

/* Arbitration field bits (figure 5-5). */
#define CAN_IDE		0x00000004U
#define CAN_RTR		0x00000002U
#define CAN_ARB_UNUSED	0x00000001U

/* Build and take apart arbitration fields. */
#define CAN_ARB_STD(id)		(((__u32)(id) & 0x7ffU) << 21)
#define CAN_ARB_EXT(id)		((((__u32)(id) & 0x1fffffffU) << 3) | CAN_IDE)
#define CAN_ARB_STD_ID(arb)	(((__u32)(arb) >> 21) & 0x7ffU)
#define CAN_ARB_EXT_ID(arb)	(((__u32)(arb) >> 3) & 0x1fffffffU)

/* Mask that matches one identifier of one format and frame type exactly. */
#define CAN_MASK_EXACT		0x00000001U
/* Mask that accepts every frame. */
#define CAN_MASK_ANY		0xffffffffU

/* Maximum data length code (CAN 2.0). */
#define CAN_ARB_MAX_DLC		8

struct sockaddr_canarb {
	__kernel_sa_family_t	family;		/* AF_CAN */
	__u32			arb;		/* arbitration field */
	__u32			mask;		/* 1 bits = don't care */
	unsigned int		ifindex;	/* 0 = all CAN interfaces */
};

#endif /* _UAPI_LINUX_CAN_RCAN_H */
