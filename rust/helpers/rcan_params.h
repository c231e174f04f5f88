/* SPDX-License-Identifier: GPL-2.0 */
/*
 * The one way Rust reads a module's parameters (rust/glue/params.rs):
 * every module with parameters defines these in its C shim (*_c.c).
 *
 * rcan_module_param: defined for EVERY which/idx (an unknown parameter or
 * an index past an array's length reads 0); reads with READ_ONCE; no side
 * effect, no lock, any context. Signed values are returned sign-extended.
 *
 * rcan_module_param_str: writes at most len bytes into buf, NUL-terminated
 * when len > 0 and NUL-padded; returns the parameter's full length (0 for
 * NULL or an unknown which). Only modules with string parameters define it.
 */
#ifndef _RCAN_PARAMS_H
#define _RCAN_PARAMS_H

#include <linux/types.h>

u64 rcan_module_param(unsigned int which, unsigned int idx);
size_t rcan_module_param_str(unsigned int which, char *buf, size_t len);

#endif /* _RCAN_PARAMS_H */
