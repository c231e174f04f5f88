/* SPDX-License-Identifier: GPL-2.0 */
/* empty: shim.h has KILO */
