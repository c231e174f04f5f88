// SPDX-License-Identifier: GPL-2.0
/* C side of rcan_j1939: its private copy of the helpers. */
#include "../../rust/helpers/rcan_helpers.c"
