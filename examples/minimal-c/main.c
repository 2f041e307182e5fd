/* The smallest pcrnet C firmware (Cortex-M4F; QEMU's mps2-an386 board):
 * use the int8 model blob in place from flash, register one point cloud
 * against the template stored in the blob, print the pose and whether to
 * trust it over semihosting, and exit. `make run` builds and runs it.
 *
 * To start your own: copy this folder, set MODEL (and regenerate
 * model_sizes.h), make read_sensor() read your sensor, and change link.ld
 * for your chip. */
#include <stdio.h>

#include "model_sizes.h" /* PCRNET_BLOB_LEN, PCRNET_BLOB_SCRATCH_LEN */
#include "pcrnet.h"

/* The header and the library agree on the handle's size. */
_Static_assert(sizeof(PcrnetModel) == PCRNET_MODEL_SIZE, "pcrnet.h does not match libpcrnet.a");

/* blob.S: the model blob (any alignment) and a stored cloud (x, y, z floats). */
extern const uint8_t model_blob[PCRNET_BLOB_LEN];
extern const float source_points[];
extern const uint8_t source_points_end[];

/* All working memory is static (in .bss): the loaded model's handle and
 * the scratch, sized for PCRNET_MAX_TILE points per encoder pass. */
static PcrnetModel model;
static int8_t scratch[PCRNET_BLOB_SCRATCH_LEN];

/* The points to register (x, y, z per point): here the stored cloud; on a
 * device, what the sensor driver just measured. Returns the point count. */
static size_t read_sensor(const float **points) {
    *points = source_points;
    return (size_t)(source_points_end - (const uint8_t *)source_points) / (3 * sizeof(float));
}

int main(void) {
    /* Checks the blob (magic, version, CRC, every size) and fills the handle. */
    int32_t status = pcrnet_model_load(model_blob, sizeof model_blob, &model);
    if (status != PCRNET_OK) {
        printf("model rejected: %s\n", pcrnet_status_message(status));
        return 1;
    }
    /* The recommended pipeline: the network, flip resolution, ICP against
     * the template's points, the residual and its verdict. */
    PcrnetOptions options;
    pcrnet_options_default(&options);
    const float *points;
    size_t n = read_sensor(&points);
    PcrnetRegistration r;
    status = pcrnet_register(&model, points, n, &options, scratch, sizeof scratch, &r);
    if (status != PCRNET_OK) {
        printf("registration failed: %s\n", pcrnet_status_message(status));
        return 1;
    }
    /* The pose moves the source onto the template: p' = R(rotation) p + t. */
    printf("rotation (w, x, y, z): %.6f %.6f %.6f %.6f\n", (double)r.rotation[0], (double)r.rotation[1],
           (double)r.rotation[2], (double)r.rotation[3]);
    printf("translation: %.6f %.6f %.6f\n", (double)r.translation[0], (double)r.translation[1],
           (double)r.translation[2]);
    printf("residual: %g\n", (double)r.residual);
    /* Act on the pose only if reliable (a low residual, a source that is
     * not degenerate); otherwise keep the last good pose. */
    printf("reliable: %s\n", r.reliable ? "true" : "false");
    return 0;
}
