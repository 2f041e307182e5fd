/* The model blob, a stored source cloud and a depth frame, linked into
 * flash from the files the Makefile names (MODEL_BLOB, SOURCE_POINTS,
 * DEPTH_FRAME: quoted paths). The blob may sit at any alignment; the
 * points are floats, so 4-aligned; the frame's pixels are uint16_t. */
    .section .rodata.pcrnet_data, "a"
    .balign 4
    .global model_blob
model_blob:
    .incbin MODEL_BLOB
    .global model_blob_end
model_blob_end:

    .balign 4
    .global source_points
source_points:
    .incbin SOURCE_POINTS
    .global source_points_end
source_points_end:

    .balign 4
    .global depth_frame
depth_frame:
    .incbin DEPTH_FRAME
    .global depth_frame_end
depth_frame_end:
