/* SPDX-License-Identifier: GPL-2.0 WITH Linux-syscall-note */
/*
 * rcan: the DSOR higher-layer CAN protocol socket API (thesis 5.2.6),
 * socket(PF_CAN, SOCK_DGRAM, CANPROTO_DSOR). Wire format:
 * Documentation/networking/rcan/dsor-wire.rst; socket behaviour:
 * Documentation/networking/rcan/dsor.rst.
 *
 * The address type follows the address length: a struct sockaddr_cansegm
 * (8 bytes) selects segmented messages, a struct sockaddr_canport (6 bytes)
 * port messages. All fields are in host byte order.
 */
#ifndef _UAPI_LINUX_CAN_RCAN_DSOR_H
#define _UAPI_LINUX_CAN_RCAN_DSOR_H

#include <linux/types.h>
#include <linux/socket.h>
#include <linux/can/rcan.h>

/* Segmented messages: a peer node and a 32-bit message identifier. */
struct sockaddr_cansegm {
	__kernel_sa_family_t	family;		/* AF_CAN */
	__u8			priority;	/* 8-bit bus priority */
	__u8			node;		/* 7-bit source/destination node */
	__u32			id;		/* 32-bit message identifier */
};

/* Port messages: port = node << 8 | sub-port. */
struct sockaddr_canport {
	__kernel_sa_family_t	family;		/* AF_CAN */
	__u16			port;		/* node << 8 | sub-port */
	__u8			priority;	/* 8-bit bus priority */
};

/* bind() wildcards of struct sockaddr_cansegm. */
#define DSOR_NODE_ANY		0xff
#define DSOR_ID_ANY		0xffffffffU
#define DSOR_NODE_MAX		0x7f

#define DSOR_PORT(node, sub)	((__u16)(((node) & 0x7f) << 8 | ((sub) & 0xff)))
#define DSOR_PORT_NODE(port)	((__u8)((port) >> 8))
#define DSOR_PORT_SUB(port)	((__u8)((port) & 0xff))

/* Longest message (the header's 16-bit length). */
#define DSOR_MAX_LEN		65535

#endif /* _UAPI_LINUX_CAN_RCAN_DSOR_H */
