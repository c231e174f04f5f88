/* SPDX-License-Identifier: GPL-2.0 */
/*
 * Minimal user-space stand-ins for the kernel definitions that mainline's
 * drivers/net/can/dev/calc_bittiming.c and bittiming.c use, so that those
 * two files compile unmodified on the host (see harness.c). Each macro
 * behaves as the kernel's does for the types these files pass: abs() of an
 * unsigned int takes it as a signed int, do_div() divides a u64 in place.
 */
#ifndef SHIM_H
#define SHIM_H
#include <stdio.h>
#include <stdint.h>
#include <limits.h>
#include <errno.h>
#include <string.h>
#include <stdarg.h>
typedef uint64_t u64; typedef uint32_t u32; typedef uint16_t u16; typedef uint8_t u8;
#define KILO 1000UL
#define NSEC_PER_SEC 1000000000L
#define CAN_SYNC_SEG 1
#define EXPORT_SYMBOL_GPL(x)
#define max(a,b) ({ typeof(a) _a=(a); typeof(b) _b=(b); _a>_b?_a:_b; })
#define min(a,b) ({ typeof(a) _a=(a); typeof(b) _b=(b); _a<_b?_a:_b; })
#define clamp(v,lo,hi) min((typeof(v))max(v,lo),hi)
#define abs(x) ({ int __x = (int)(x); __x < 0 ? -__x : __x; })
#define do_div(n,base) ({ u32 __r = (n) % (base); (n) /= (base); __r; })
#define mul_u32_u32(a,b) ((u64)(a)*(u64)(b))
#define DIV_U64_ROUND_CLOSEST(d, div) ({ u32 _t = (div); ((d) + _t/2) / _t; })
struct can_bittiming { u32 bitrate, sample_point, tq, prop_seg, phase_seg1, phase_seg2, sjw, brp; };
struct can_bittiming_const { char name[16]; u32 tseg1_min, tseg1_max, tseg2_min, tseg2_max, sjw_max, brp_min, brp_max, brp_inc; };
struct can_clock { u32 freq; };
struct can_priv { struct can_clock clock; };
struct net_device { struct can_priv priv; };
struct netlink_ext_ack { char msg[128]; };
struct can_tdc { u32 tdcv, tdco, tdcf; }; struct can_tdc_const { u32 tdcv_min, tdcv_max, tdco_min, tdco_max, tdcf_min, tdcf_max; };
#define CAN_CTRLMODE_TDC_AUTO 0x200
#define CAN_CTRLMODE_TDC_MASK 0x600
static inline void *netdev_priv(const struct net_device *d) { return (void *)&d->priv; }
#define NL_SET_ERR_MSG_FMT(ack, fmt, ...) snprintf((ack)->msg, sizeof((ack)->msg), fmt, ##__VA_ARGS__)
static inline unsigned int can_bit_time(const struct can_bittiming *bt)
{ return CAN_SYNC_SEG + bt->prop_seg + bt->phase_seg1 + bt->phase_seg2; }
void can_sjw_set_default(struct can_bittiming *bt);
int can_sjw_check(const struct net_device *dev, const struct can_bittiming *bt,
		  const struct can_bittiming_const *btc, struct netlink_ext_ack *extack);
#endif
