// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_pf: the writers' mutexes and the export table of the
 * functions defined in pf_can.rs (Rust cannot emit EXPORT_SYMBOL itself).
 * The prototypes are placeholders for the export table only; the real
 * signatures are in rcan_api.rs.
 */
#include <linux/export.h>
#include <linux/mutex.h>

#include "../../rust/helpers/rcan_helpers.c"

/*
 * The writers' mutexes, each its own lock class. Not static: the Rust side
 * (rust/glue/can/family.rs) takes their addresses as extern statics, so a
 * lock is one call to rcan_mutex_lock, not an address lookup first. Not
 * exported: only this module uses them.
 */
extern struct mutex rcan_pf_mutex;
DEFINE_MUTEX(rcan_pf_mutex);

/* The receive table's writers. */
extern struct mutex rcan_rx_mutex;
DEFINE_MUTEX(rcan_rx_mutex);

void rcan_pf_abi(void);
void rcan_proto_register(void);
void rcan_proto_unregister(void);
void rcan_rx_set(void);
void rcan_rx_reserve(void);
void rcan_rx_set_reserved(void);
void rcan_send(void);
void rcan_rx_set_kernel(void);
void rcan_rx_listen(void);
void rcan_rx_filters(void);

EXPORT_SYMBOL_GPL(rcan_pf_abi);
EXPORT_SYMBOL_GPL(rcan_proto_register);
EXPORT_SYMBOL_GPL(rcan_proto_unregister);
EXPORT_SYMBOL_GPL(rcan_rx_set);
EXPORT_SYMBOL_GPL(rcan_rx_reserve);
EXPORT_SYMBOL_GPL(rcan_rx_set_reserved);
EXPORT_SYMBOL_GPL(rcan_send);
EXPORT_SYMBOL_GPL(rcan_rx_set_kernel);
EXPORT_SYMBOL_GPL(rcan_rx_listen);
EXPORT_SYMBOL_GPL(rcan_rx_filters);
