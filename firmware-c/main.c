/* pcrnet C example: a C firmware that links libpcrnet.a (the C API of
 * pcrnet-core), loads the model blob in place from flash, and registers a
 * stored source cloud against the model's template, with all working
 * memory in statics. Prints each result and its instruction count over
 * semihosting, and acts on the confidence: a pose that is not reliable is
 * retried from every starting pose the blob stores.
 *
 * Lines starting with "@ " repeat every result as the bits of each value,
 * for the QEMU harness to compare with the host (`cargo xtask c-example`). */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "board.h"
#include "pcrnet.h"

/* data.S: the blob and the source (x, y, z floats per point). */
extern const uint8_t model_blob[], model_blob_end[];
extern const float source_points[];
extern const uint8_t source_points_end[];

/* data.S: a depth frame, 224 x 172 pixels row by row, millimetres (the
 * frame `pcrnet frame` draws: the template on a table beside two blocks). */
extern const uint16_t depth_frame[];
extern const uint8_t depth_frame_end[];
#define FRAME_WIDTH 224
#define FRAME_HEIGHT 172
#define FRAME_STEP 4
#define FRAME_POINTS 512

/* Working memory, all static: the model handle, the encoder's scratch, and
 * a RAM copy of the cloud (a sensor driver would fill it on a device); for
 * the frame, the scene stages' labels (pcrnet_scene_labels_len) and the
 * points of one candidate. */
#define MAX_POINTS 4096
#define SCRATCH_BYTES 16384
static PcrnetModel model;
static int8_t scratch[SCRATCH_BYTES];
static float cloud[3 * MAX_POINTS];
static uint16_t labels[2 * ((FRAME_WIDTH + FRAME_STEP - 1) / FRAME_STEP) *
                       ((FRAME_HEIGHT + FRAME_STEP - 1) / FRAME_STEP)];
static float frame_points[3 * FRAME_POINTS];

/* A 64-bit count in decimal (nano printf has no %llu). */
static void print_count(uint64_t v) {
    if (v >= 1000000000u) {
        printf("%lu%09lu", (unsigned long)(v / 1000000000u), (unsigned long)(v % 1000000000u));
    } else {
        printf("%lu", (unsigned long)v);
    }
}

static uint32_t bits(float v) {
    uint32_t u;
    memcpy(&u, &v, sizeof u);
    return u;
}

static void print_bits(const float *v, size_t n) {
    for (size_t i = 0; i < n; i++) {
        printf(" %08lx", (unsigned long)bits(v[i]));
    }
}

/* Every value of a registration as bits (after a "@ reg" or "@ locate"
 * line's head), in the order the host formats them. */
static void print_registration_bits(const PcrnetRegistration *r) {
    print_bits(r->rotation, 4);
    print_bits(r->translation, 3);
    const float scores[6] = {r->residual, r->relative_residual, r->plane_residual,
                             r->relative_plane_residual, r->fitness, r->inlier_rmse};
    print_bits(scores, 6);
    printf(" %lu %lu %lu %lu %lu %lu %lu %d %d", (unsigned long)r->hypothesis, (unsigned long)r->passes,
           (unsigned long)r->lk_iterations, (unsigned long)r->icp_iterations, (unsigned long)r->saturated, (unsigned long)r->out_of_range,
           (unsigned long)r->degenerate, r->reliable ? 1 : 0, r->has_free_axis ? 1 : 0);
    const float axis[7] = {r->free_axis[0],       r->free_axis[1],       r->free_axis[2],
                           r->free_axis_point[0], r->free_axis_point[1], r->free_axis_point[2],
                           r->free_axis_stiffness};
    print_bits(axis, 7);
    printf(" %d", r->has_turn ? 1 : 0);
    const float turn[9] = {r->turn_rotation[0],    r->turn_rotation[1],    r->turn_rotation[2],
                           r->turn_rotation[3],    r->turn_translation[0], r->turn_translation[1],
                           r->turn_translation[2], r->turn_degrees,        r->turn_relative_plane_residual};
    print_bits(turn, 9);
}

/* The readable report of one registration, then its "@ reg" line. */
static void report(const char *label, int32_t status, const PcrnetRegistration *r, uint64_t instructions) {
    printf("register %s: %s, ", label, pcrnet_status_message(status));
    print_count(instructions);
    printf(" instructions\n");
    if (status != PCRNET_OK) {
        printf("@ reg %s %ld\n", label, (long)status);
        return;
    }
    printf("  rotation (w x y z): %.6f %.6f %.6f %.6f\n", (double)r->rotation[0], (double)r->rotation[1],
           (double)r->rotation[2], (double)r->rotation[3]);
    printf("  translation: %.6f %.6f %.6f\n", (double)r->translation[0], (double)r->translation[1],
           (double)r->translation[2]);
    printf("  plane residual %.6f (%.4f of the template's size), fitness %.3f, hypothesis %lu, ICP iterations %lu, saturated %lu, out of range %lu\n",
           (double)r->plane_residual, (double)r->relative_plane_residual, (double)r->fitness,
           (unsigned long)r->hypothesis, (unsigned long)r->icp_iterations, (unsigned long)r->saturated,
           (unsigned long)r->out_of_range);
    printf("  reliable: %s\n", r->reliable ? "yes" : "no");
    printf("@ reg %s 0", label);
    print_registration_bits(r);
    printf("\n");
}

static int32_t run(const char *label, const float *points, size_t n, const PcrnetOptions *options,
                   PcrnetRegistration *r) {
    uint64_t start = instructions_now();
    int32_t status = pcrnet_register(&model, points, n, options, scratch, sizeof scratch, r);
    report(label, status, r, instructions_now() - start);
    return status;
}

/* The source as a cut single view from a sensor at (0, 0, 3), above the
 * object: registered with the view (of the turned starts, the lowest
 * whose pose explains the view finishes) and checked against it; then its
 * "@ view" line (the registration, then the check's counts). */
static void viewed(const float *points, size_t n, const PcrnetOptions *options) {
    static float view[PCRNET_VIEW_BUFFER_LEN];
    const float viewpoint[3] = {0.0f, 0.0f, 3.0f};
    PcrnetRegistration r;
    PcrnetViewCheck v;
    uint64_t start = instructions_now();
    int32_t status = pcrnet_register_view(&model, points, n, viewpoint, options, scratch, sizeof scratch, view,
                                          PCRNET_VIEW_BUFFER_LEN, &r, &v);
    uint64_t used = instructions_now() - start;
    printf("register seen from (0, 0, 3): %s, ", pcrnet_status_message(status));
    print_count(used);
    printf(" instructions\n");
    if (status != PCRNET_OK) {
        printf("@ view above %ld\n", (long)status);
        return;
    }
    printf("  view: %lu template points on the seen surface, %lu where the sensor saw past the object, %lu behind it; reliable with the view: %s\n",
           (unsigned long)v.supported, (unsigned long)v.violations, (unsigned long)v.occluded,
           r.reliable ? "yes" : "no");
    printf("@ view above 0");
    print_registration_bits(&r);
    printf(" %lu %lu %lu %lu %d\n", (unsigned long)v.supported, (unsigned long)v.violations,
           (unsigned long)v.occluded, (unsigned long)v.unobserved, v.passed ? 1 : 0);
}

/* The object found in the depth frame and registered (the plane taken
 * out, clusters of the object's size registered by a yaw sweep about the
 * plane's normal, each checked against the frame), then its "@ locate"
 * line. */

/* One `@ locate LABEL 0 ...` line: the counts, the plane and the
   registration's bits, for the host to compare. */
static void print_located(const char *label, const PcrnetLocated *l) {
    printf("@ locate %s 0 %d %d %d %d %lu %lu %lu %lu %lu %lu %lu %lu", label, l->found ? 1 : 0, l->reliable ? 1 : 0,
           l->verified ? 1 : 0, l->has_plane ? 1 : 0, (unsigned long)l->cluster, (unsigned long)l->clusters_kept,
           (unsigned long)l->candidates_tried, (unsigned long)l->supported, (unsigned long)l->violations,
           (unsigned long)l->occluded, (unsigned long)l->unobserved, (unsigned long)l->outside);
    print_bits(l->plane_normal, 3);
    print_bits(&l->plane_offset, 1);
    print_registration_bits(&l->registration);
    printf("\n");
}
static void locate(void) {
    size_t pixels = (size_t)(depth_frame_end - (const uint8_t *)depth_frame) / sizeof(uint16_t);
    if (pixels != (size_t)FRAME_WIDTH * FRAME_HEIGHT) {
        printf("the stored frame has %lu pixels; this example takes %d x %d\n", (unsigned long)pixels,
               FRAME_WIDTH, FRAME_HEIGHT);
        return;
    }
    /* The time-of-flight camera the frame was drawn with (`pcrnet frame`
     * writes it to FRAME.json). */
    const PcrnetDepthImage image = {.depth = depth_frame,
                                    .width = FRAME_WIDTH,
                                    .height = FRAME_HEIGHT,
                                    .stride = FRAME_WIDTH,
                                    .fx = 194.0f,
                                    .fy = 194.0f,
                                    .cx = 111.5f,
                                    .cy = 85.5f,
                                    .depth_scale = 0.001f,
                                    .invalid = 0};
    PcrnetSceneOptions scene;
    pcrnet_scene_options_default(&scene);
    scene.step = FRAME_STEP;
    scene.has_up = true; /* the template's z axis points away from the table */
    scene.up[0] = 0.0f;
    scene.up[1] = 0.0f;
    scene.up[2] = 1.0f;
    PcrnetOptions options;
    pcrnet_options_default(&options);
    PcrnetLocated found;
    uint64_t start = instructions_now();
    int32_t status = pcrnet_locate(&model, &image, &scene, &options, labels, sizeof labels / sizeof labels[0],
                                   frame_points, FRAME_POINTS, scratch, sizeof scratch, &found);
    uint64_t used = instructions_now() - start;
    printf("locate in a %d x %d depth frame (yaw sweep, up z): %s, ", FRAME_WIDTH, FRAME_HEIGHT,
           pcrnet_status_message(status));
    print_count(used);
    printf(" instructions\n");
    if (status != PCRNET_OK) {
        printf("@ locate sweep %ld\n", (long)status);
        return;
    }
    if (found.found) {
        const PcrnetRegistration *r = &found.registration;
        printf("  cluster %lu of %lu kept, %lu registered; plane residual %.4f of the size\n",
               (unsigned long)found.cluster, (unsigned long)found.clusters_kept,
               (unsigned long)found.candidates_tried, (double)r->relative_plane_residual);
        printf("  rotation (w x y z): %.6f %.6f %.6f %.6f, translation %.4f %.4f %.4f\n", (double)r->rotation[0],
               (double)r->rotation[1], (double)r->rotation[2], (double)r->rotation[3], (double)r->translation[0],
               (double)r->translation[1], (double)r->translation[2]);
        printf("  checked against the frame: %lu points seen, %lu in free space or beneath the plane; %s%s\n",
               (unsigned long)found.supported, (unsigned long)found.violations,
               found.reliable ? "reliable" : "not reliable",
               r->has_turn || r->has_free_axis ? " (ambiguous: a symmetric object)" : "");
    } else {
        printf("  no cluster of the object's size\n");
    }
    print_located("sweep", &found);
    if (!found.reliable) {
        return;
    }
    /* The next frame of a stream (here the same frame): followed from the
       pose and plane just found, about 40 times cheaper than locating. */
    const PcrnetRegistration *r = &found.registration;
    const float previous[7] = {r->rotation[0],    r->rotation[1],    r->rotation[2],   r->rotation[3],
                               r->translation[0], r->translation[1], r->translation[2]};
    PcrnetSceneOptions next = scene;
    next.has_plane = found.has_plane;
    next.plane_normal[0] = found.plane_normal[0];
    next.plane_normal[1] = found.plane_normal[1];
    next.plane_normal[2] = found.plane_normal[2];
    next.plane_offset = found.plane_offset;
    PcrnetLocated followed;
    start = instructions_now();
    status = pcrnet_follow(&model, &image, &next, previous, &options, labels, sizeof labels / sizeof labels[0],
                           frame_points, FRAME_POINTS, scratch, sizeof scratch, &followed);
    used = instructions_now() - start;
    printf("followed into the next frame: %s, ", pcrnet_status_message(status));
    print_count(used);
    printf(" instructions, %s\n", status == PCRNET_OK && followed.reliable ? "reliable" : "not reliable");
    if (status != PCRNET_OK) {
        printf("@ locate follow %ld\n", (long)status);
        return;
    }
    print_located("follow", &followed);
}

int main(void) {
    instructions_start();
    size_t blob_len = (size_t)(model_blob_end - model_blob);
    size_t n = (size_t)(source_points_end - (const uint8_t *)source_points) / (3 * sizeof(float));
    printf("pcrnet C example\n");

    int32_t status = pcrnet_model_load(model_blob, blob_len, &model);
    if (status != PCRNET_OK) {
        printf("model rejected: %s\n", pcrnet_status_message(status));
        return 1;
    }
    size_t tile = PCRNET_MAX_TILE;
    while (tile > 1 && pcrnet_model_scratch_len(&model, tile) > sizeof scratch) {
        tile--;
    }
    printf("model: %lu bytes, trained passes %lu, scratch %lu of %lu bytes (tile %lu)\n",
           (unsigned long)blob_len, (unsigned long)pcrnet_model_trained_passes(&model),
           (unsigned long)pcrnet_model_scratch_len(&model, tile), (unsigned long)sizeof scratch,
           (unsigned long)tile);
    if (n == 0 || n > MAX_POINTS) {
        printf("the stored source has %lu points; this example takes 1 to %d\n", (unsigned long)n,
               MAX_POINTS);
        return 1;
    }
    printf("points: %lu\n", (unsigned long)n);

    /* The recommended pipeline: network, flip resolution, ICP, residual. */
    PcrnetOptions options;
    pcrnet_options_default(&options);
    PcrnetRegistration r;
    status = run("default", source_points, n, &options, &r);
    if (status == PCRNET_OK && !r.reliable) {
        printf("not reliable: retrying from every starting pose\n");
        PcrnetOptions every = options;
        every.hypotheses = UINT32_MAX;
        status = run("every-start", source_points, n, &every, &r);
    }
    if (status == PCRNET_OK) {
        printf(r.reliable ? "pose reliable: acting on it\n" : "no reliable pose: keeping the last good one\n");
    }

    /* The network alone, scored; then three i-PCRNet passes, unscored. */
    PcrnetOptions network;
    pcrnet_options_network_only(&network);
    PcrnetRegistration rn;
    run("network", source_points, n, &network, &rn);
    float pose[7];
    uint32_t passes = 0;
    uint64_t start = instructions_now();
    status = pcrnet_network_pose(&model, source_points, n, 3, 0.0f, scratch, sizeof scratch, pose, &passes);
    uint64_t used = instructions_now() - start;
    printf("network pose, 3 passes: %s, ", pcrnet_status_message(status));
    print_count(used);
    printf(" instructions\n");
    printf("@ pose iterated %ld", (long)status);
    if (status == PCRNET_OK) {
        printf(" %lu", (unsigned long)passes);
        print_bits(pose, 7);
    }
    printf("\n");

    /* A cut single view from a known place, then a raw depth frame. */
    viewed(source_points, n, &options);
    locate();

    /* Bad input is a status with a message, never a crash. */
    memcpy(cloud, source_points, 3 * n * sizeof(float));
    cloud[0] = 0.0f / 0.0f;
    run("nan", cloud, n, &options, &r);
    printf("@ done\n");
    return 0;
}
