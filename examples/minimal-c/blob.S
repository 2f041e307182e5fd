/* The model blob and a stored source cloud, linked into flash from the
 * files the Makefile names (MODEL, SOURCE: quoted paths). The blob may sit
 * at any alignment; the points are floats, so 4-aligned. */
#include "model_sizes.h"

    .section .rodata.pcrnet_blob, "a"
    .global model_blob
model_blob:
    .incbin MODEL
model_blob_end:
    /* model_sizes.h must describe this blob: regenerate it if not. */
    .if model_blob_end - model_blob != PCRNET_BLOB_LEN
    .error "model_sizes.h is not MODEL's: regenerate it (pcrnet inspect MODEL --c-header)"
    .endif

    .balign 4
    .global source_points, source_points_end
source_points:
    .incbin SOURCE
source_points_end:
