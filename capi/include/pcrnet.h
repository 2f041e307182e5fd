/* pcrnet: learned point cloud registration (PCRNet) for microcontrollers, C API.
 *
 * Generated from the pcrnet-capi crate (capi/src/) by `cargo xtask c-header`; do not edit.
 * Ownership, alignment and errors: see capi/README.md. Every function that
 * can fail returns a PcrnetStatus (0 = PCRNET_OK); pcrnet_status_message()
 * explains each one. Nothing allocates, nothing aborts. */

#ifndef PCRNET_H
#define PCRNET_H

#include <stddef.h>
#include <stdint.h>
#include <stdbool.h>

/*
 Most points per encoder pass (`pcrnet_core::MAX_TILE`); a scratch
 sized for it is the fastest.
 */
#define PCRNET_MAX_TILE 8

/*
 Storage words of a `PcrnetModel` (8 bytes each; 2,560 bytes, the
 same on every target: the Rust model takes 1,944 on 64-bit hosts and
 less on 32-bit cores, checked at compile time).
 */
#define PCRNET_MODEL_WORDS 320

/*
 Bytes of a `PcrnetModel` (`8 * PCRNET_MODEL_WORDS`), for C code to
 check its view of the type:
 `_Static_assert(sizeof(PcrnetModel) == PCRNET_MODEL_SIZE, "...")`.
 */
#define PCRNET_MODEL_SIZE 2560

/*
 Storage words of a `PcrnetPrepared` (8 bytes each; 64 bytes on every
 target, checked at compile time).
 */
#define PCRNET_PREPARED_WORDS 8

/*
 Bytes of a `PcrnetPrepared` (`8 * PCRNET_PREPARED_WORDS`), for C code
 to check its view of the type with `_Static_assert`.
 */
#define PCRNET_PREPARED_SIZE 64

/*
 `pcrnet_track`'s outcome: refined from the previous pose, reliable: the
 track is kept (the network did not run).
 */
#define PCRNET_TRACK_KEPT 0

/*
 `pcrnet_track`'s outcome: the previous pose did not hold; the full
 registration in the same call found a reliable pose.
 */
#define PCRNET_TRACK_RECOVERED 1

/*
 `pcrnet_track`'s outcome: no reliable pose either way (the result is
 the registration's, `reliable` false): track the next frame from the
 last reliable pose (its step falls back to a registration again).
 */
#define PCRNET_TRACK_LOST 2

/*
 `PcrnetOptions::metric`: point-to-point ICP.
 */
#define PCRNET_METRIC_POINT_TO_POINT 0

/*
 `PcrnetOptions::metric`: point-to-plane ICP (the default).
 */
#define PCRNET_METRIC_POINT_TO_PLANE 1

/*
 `PcrnetRegistration::degenerate`: the source determines a pose.
 */
#define PCRNET_DEGENERATE_NONE 0

/*
 `PcrnetRegistration::degenerate`: all points (nearly) coincide.
 */
#define PCRNET_DEGENERATE_POINT 1

/*
 `PcrnetRegistration::degenerate`: the points (nearly) lie on a line.
 */
#define PCRNET_DEGENERATE_LINE 2

/*
 Floats of the image buffer `pcrnet_register_view` and
 `pcrnet_check_view` are best given: 32 x 32
 pixels (4 KB), enough for sources of up to about 500 points at full
 resolution; at least 64 (8 x 8), a smaller buffer gives coarser pixels.
 */
#define PCRNET_VIEW_BUFFER_LEN 1024

/*
 Status of a call: `PCRNET_OK` (0) or what went wrong (negative).
 */
enum PcrnetStatus
#if defined(__cplusplus) || __STDC_VERSION__ >= 202311L
  : int32_t
#endif // defined(__cplusplus) || __STDC_VERSION__ >= 202311L
 {
  /*
   Success; outputs were written.
   */
  PCRNET_OK = 0,
  /*
   A required pointer is null.
   */
  PCRNET_ERROR_NULL_POINTER = -1,
  /*
   An array is not aligned for its type (points: 4 bytes; depth
   values and labels: 2).
   */
  PCRNET_ERROR_MISALIGNED = -2,
  /*
   The model handle was not filled by a successful `pcrnet_model_load`.
   */
  PCRNET_ERROR_NOT_LOADED = -3,
  /*
   The prepared handle was not filled by a successful `pcrnet_prepare`.
   */
  PCRNET_ERROR_NOT_PREPARED = -4,
  /*
   The blob does not start with the magic bytes `PCRN`.
   */
  PCRNET_ERROR_BAD_MAGIC = -10,
  /*
   The blob's format version is not one this build reads.
   */
  PCRNET_ERROR_UNSUPPORTED_VERSION = -11,
  /*
   The blob holds another kind of model (the C API loads int8 blobs).
   */
  PCRNET_ERROR_WRONG_KIND = -12,
  /*
   The blob is shorter than its header says.
   */
  PCRNET_ERROR_TRUNCATED = -13,
  /*
   Bytes follow the blob's CRC.
   */
  PCRNET_ERROR_TRAILING_DATA = -14,
  /*
   The blob's CRC does not match its contents.
   */
  PCRNET_ERROR_BAD_CRC = -15,
  /*
   The payload does not decode.
   */
  PCRNET_ERROR_MALFORMED = -16,
  /*
   Layer sizes disagree.
   */
  PCRNET_ERROR_INCONSISTENT_DIMENSIONS = -17,
  /*
   A model parameter is outside its range.
   */
  PCRNET_ERROR_INVALID_PARAMETER = -18,
  /*
   The scratch buffer is smaller than `pcrnet_model_scratch_len(model, 1)`.
   */
  PCRNET_ERROR_SCRATCH_TOO_SMALL = -20,
  /*
   An output buffer is too small.
   */
  PCRNET_ERROR_BUFFER_TOO_SMALL = -21,
  /*
   The cloud has no points.
   */
  PCRNET_ERROR_EMPTY_CLOUD = -30,
  /*
   A coordinate is NaN or infinite.
   */
  PCRNET_ERROR_NON_FINITE_COORDINATE = -31,
  /*
   Every point is outside the model's input range (points outside it
   are left out and counted in `out_of_range`; with none left there is
   no pose).
   */
  PCRNET_ERROR_NO_POINT_IN_RANGE = -32,
  /*
   The network produced a zero quaternion.
   */
  PCRNET_ERROR_DEGENERATE_POSE = -33,
  /*
   The pose or a residual came out non-finite.
   */
  PCRNET_ERROR_NON_FINITE_RESULT = -34,
  /*
   A registration option is out of range.
   */
  PCRNET_ERROR_INVALID_OPTION = -40,
  /*
   The previous pose of `pcrnet_track` is not finite or its quaternion
   is not of unit length.
   */
  PCRNET_ERROR_INVALID_POSE = -41,
  /*
   A depth frame or a scene setting cannot be used: a zero size or
   stride, a buffer too short for the frame, intrinsics or a depth
   scale not finite and positive, a grid step of 0 or one of more cells
   than its labels can number.
   */
  PCRNET_ERROR_INVALID_FRAME = -42,
  /*
   A network pass was asked of a blob without a head (a model trained
   as PointNetLK): set `passes` to 0 and `lk_iterations` to its
   trained count.
   */
  PCRNET_ERROR_NO_HEAD = -43,
  /*
   `lk_iterations` was set for a blob without PointNetLK's solver:
   export the model with `pcrnet export --lk`, or set it to 0.
   */
  PCRNET_ERROR_NO_LK_SOLVER = -44,
  /*
   An error this version of the C API has no code for (a newer core).
   */
  PCRNET_ERROR_OTHER = -99,
};
#ifndef __cplusplus
#if __STDC_VERSION__ >= 202311L
typedef enum PcrnetStatus PcrnetStatus;
#else
typedef int32_t PcrnetStatus;
#endif // __STDC_VERSION__ >= 202311L
#endif // __cplusplus

/*
 A loaded model: storage the caller owns, filled by `pcrnet_model_load`.
 Its contents are private; its size and 8-byte alignment are fixed on
 every target.
 */
typedef struct {
  uint64_t storage[PCRNET_MODEL_WORDS];
} PcrnetModel;

/*
 How to register (`pcrnet_core::Options`; distances in model units,
 i.e. shares of the template's size). Start from
 `pcrnet_options_default` and change what you need.
 */
typedef struct {
  /*
   Network passes (1: PCRNet; more: i-PCRNet; 0 for a blob without a
   head, a model trained as PointNetLK).
   */
  uint32_t passes;
  /*
   Passes and LK steps stop once one moves the pose by less than this (0: never).
   */
  float tolerance;
  /*
   Starting poses of flip resolution, 1 up to 1 + the blob's turns.
   */
  uint32_t hypotheses;
  /*
   ICP iterations every start gets before the two best continue (a
   turned start far above the best after 3 of them is dropped).
   */
  uint32_t screen_iterations;
  /*
   Most ICP iterations in all (0: no refinement).
   */
  uint32_t icp_iterations;
  /*
   `PCRNET_METRIC_POINT_TO_PLANE` or `PCRNET_METRIC_POINT_TO_POINT`.
   */
  uint32_t metric;
  /*
   ICP stops once an update moves the pose by less than this.
   */
  float icp_tolerance;
  /*
   ICP leaves out pairs farther apart than this.
   */
  float icp_distance;
  /*
   Residuals count a point at most this far; fitness counts points within it.
   */
  float inlier_distance;
  /*
   Most source points scored and refined (every k-th point is used).
   */
  uint32_t max_points;
  /*
   `reliable` when the relative plane residual is at most this.
   */
  float max_residual;
  /*
   PointNetLK steps after the network's passes (0: none; needs a blob
   with PointNetLK's solver). Refine by LK: this with `icp_iterations`
   0 and one hypothesis; LK then ICP: both.
   */
  uint32_t lk_iterations;
  /*
   Most source points each network pass and LK step encodes (every
   k-th point; at least 1). The default 128 (a blob with a head; 256
   for a PointNetLK blob, which `pcrnet_options_for_model` sets) is a
   quarter of the network's cost at 512 points with the same accuracy;
   exported template features are pooled over that many of the
   template's points, so other values pool the two compared features
   over different counts.
   */
  uint32_t network_points;
} PcrnetOptions;

/*
 What a registration found and how far to trust it
 (`pcrnet_core::Registration`): `p_template = R p_source + t`, in the
 source's units.
 */
typedef struct {
  /*
   Unit quaternion `[w, x, y, z]`, `w >= 0`.
   */
  float rotation[4];
  /*
   Translation `[x, y, z]`, source units.
   */
  float translation[3];
  /*
   Mean distance to the nearest template point (capped), source units.
   */
  float residual;
  /*
   The same as a share of the template's size.
   */
  float relative_residual;
  /*
   Mean distance to the tangent plane at the nearest template point (capped), source units.
   */
  float plane_residual;
  /*
   The same as a share of the template's size: what `reliable` is judged on.
   */
  float relative_plane_residual;
  /*
   Share of used source points within the inlier distance.
   */
  float fitness;
  /*
   RMS distance of those inliers, source units.
   */
  float inlier_rmse;
  /*
   Winning start: 0 the network's pose, `k` it followed by turn `k - 1`.
   */
  uint32_t hypothesis;
  /*
   Network passes run.
   */
  uint32_t passes;
  /*
   PointNetLK steps run after them.
   */
  uint32_t lk_iterations;
  /*
   ICP iterations from the winning start.
   */
  uint32_t icp_iterations;
  /*
   int8 values that reached the top of their range.
   */
  uint32_t saturated;
  /*
   Points of the network's sample (`network_points`) left out of it:
   outside the model's input range (stray points far from the object).
   */
  uint32_t out_of_range;
  /*
   `PCRNET_DEGENERATE_NONE`, `_POINT` or `_LINE`.
   */
  uint32_t degenerate;
  /*
   With `has_free_axis`: the unit direction (sign arbitrary) of an
   axis, template frame, about which a rotation barely changes the fit:
   the pose's angle about it is arbitrary (a continuous symmetry).
   */
  float free_axis[3];
  /*
   With `has_free_axis`: the axis's point nearest the template's
   centroid, template frame, source units.
   */
  float free_axis_point[3];
  /*
   With `has_free_axis`: how stiff the fit is to a rotation about it
   (below 0.12; 0 is perfectly free).
   */
  float free_axis_stiffness;
  /*
   With `has_turn`: the rotation (unit quaternion `[w, x, y, z]`) of
   the rigid motion of the template's frame taking the pose to another
   that fits about as well (`other = turn after pose`; a discrete symmetry).
   */
  float turn_rotation[4];
  /*
   With `has_turn`: that motion's translation, source units.
   */
  float turn_translation[3];
  /*
   With `has_turn`: the turn's angle, degrees (0..=180).
   */
  float turn_degrees;
  /*
   With `has_turn`: the other pose's relative plane residual.
   */
  float turn_relative_plane_residual;
  /*
   Not degenerate and the relative plane residual within `max_residual`.
   */
  bool reliable;
  /*
   A free rotation axis was found (`free_axis`, `free_axis_point`,
   `free_axis_stiffness`; zero without one).
   */
  bool has_free_axis;
  /*
   A turn to another pose that fits about as well was found
   (`turn_rotation`, `turn_translation`, `turn_degrees`,
   `turn_relative_plane_residual`; zero without one).
   */
  bool has_turn;
} PcrnetRegistration;

/*
 How to look for the object (`pcrnet_scene_options_default` fills the
 defaults); the rest of the scene settings follow from the model's
 object radius (`pcrnet_core::scene::SceneOptions::for_object`).
 */
typedef struct {
  /*
   Pixels between grid samples (4).
   */
  uint32_t step;
  /*
   Candidates registered, largest clusters first (3; at most 8).
   */
  uint32_t candidates;
  /*
   With `has_up`: the template's up axis (template frame: the axis
   pointing away from the surface it rests on). Each candidate is then
   registered by a yaw sweep about the plane's normal, for a view from
   one side in any yaw.
   */
  float up[3];
  /*
   Yaw starts of that sweep (12: 30 degrees apart).
   */
  uint32_t yaws;
  /*
   With `has_plane`: the plane the objects stand on, unit normal
   towards the sensor (sensor frame) ...
   */
  float plane_normal[3];
  /*
   ... and the sensor's distance from it, user units. Without
   `has_plane` the dominant plane is found (seeded RANSAC).
   */
  float plane_offset;
  /*
   `up` is given.
   */
  bool has_up;
  /*
   `plane_normal` and `plane_offset` are given.
   */
  bool has_plane;
  /*
   Check each candidate's pose against the frame (true): a pose is
   reliable only if the template's points that should be visible are
   seen where it puts them, and none lies in front of what the sensor saw.
   */
  bool verify;
} PcrnetSceneOptions;

/*
 A 16-bit depth image the caller owns: `height` rows of `stride`
 pixels (`width` of them used), row-major, from the top-left pixel.
 The sensor frame is x right, y down, z forward (the usual pinhole
 camera), in `depth_scale` user units per count.
 */
typedef struct {
  /*
   `height * stride` depth values, 2-byte aligned.
   */
  const uint16_t *depth;
  /*
   Pixels a row.
   */
  size_t width;
  /*
   Rows.
   */
  size_t height;
  /*
   Pixels from one row's start to the next's (at least `width`).
   */
  size_t stride;
  /*
   Focal length along a row, pixels.
   */
  float fx;
  /*
   Focal length along a column, pixels.
   */
  float fy;
  /*
   Principal point, column.
   */
  float cx;
  /*
   Principal point, row.
   */
  float cy;
  /*
   User units per depth count (0.001 turns millimetres into metres);
   the template's units, as for `pcrnet_register`'s points.
   */
  float depth_scale;
  /*
   The value of a pixel the sensor has no depth for (usually 0).
   */
  uint16_t invalid;
} PcrnetDepthImage;

/*
 What `pcrnet_locate` found.
 */
typedef struct {
  /*
   With `found`: the winner's registration, its pose mapping the
   sensor frame onto the template (user units), its `reliable` the
   registration's own verdict (see `reliable` below for the frame's).
   */
  PcrnetRegistration registration;
  /*
   With `has_plane`: the plane taken out (unit normal towards the
   sensor) ...
   */
  float plane_normal[3];
  /*
   ... and the sensor's distance from it, user units.
   */
  float plane_offset;
  /*
   With `verified`: the winner's template points seen at their place ...
   */
  uint32_t supported;
  /*
   ... in front of what the sensor saw (free space) or beneath the
   plane ...
   */
  uint32_t violations;
  /*
   ... behind it ...
   */
  uint32_t occluded;
  /*
   ... and at a pixel without depth (for those outside the frame see
   `outside`, the last field).
   */
  uint32_t unobserved;
  /*
   The winner's place among the kept clusters (largest first).
   */
  uint32_t cluster;
  /*
   Clusters kept by their size.
   */
  uint32_t clusters_kept;
  /*
   Candidates registered.
   */
  uint32_t candidates_tried;
  /*
   A candidate was registered (a kept cluster exists).
   */
  bool found;
  /*
   The winner's verdict: checked against the frame when `verified`,
   else its registration's.
   */
  bool reliable;
  /*
   The winner was checked against the frame.
   */
  bool verified;
  /*
   A plane was found or given.
   */
  bool has_plane;
  /*
   With `verified`: the winner's template points outside the frame or
   behind the sensor (a winner with more than 5% of its points there
   is not reliable: out of view). Last, so that the fields before it
   keep the places they had before it was added.
   */
  uint32_t outside;
} PcrnetLocated;

/*
 A model handle and a scratch made ready by `pcrnet_prepare`: storage
 the caller owns. Its contents are private; its size and 8-byte
 alignment are fixed on every target.
 */
typedef struct {
  uint64_t storage[PCRNET_PREPARED_WORDS];
} PcrnetPrepared;

/*
 What `pcrnet_check_view` found: the stored template points, moved by the
 pose into the view, counted by what the view says of each.
 */
typedef struct {
  /*
   On the seen surface.
   */
  uint32_t supported;
  /*
   Where the sensor saw past the object (free space).
   */
  uint32_t violations;
  /*
   Behind the seen surface (no evidence).
   */
  uint32_t occluded;
  /*
   Behind the viewpoint (none for a sound pose).
   */
  uint32_t unobserved;
  /*
   At most 10% violations among supported + violations, at least 20%
   support among those with an observation: the pose explains the view.
   */
  bool passed;
} PcrnetViewCheck;

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/*
 Validates `blob` (magic, version, CRC, sizes, every parameter) and fills
 `model`. The blob must stay valid and unchanged while `model` is used.
 On failure `model` is marked not loaded.

 # Safety
 `blob` must point to `blob_len` readable bytes (or be null), and
 `model` to writable storage of a `PcrnetModel` (or be null).
 */
PcrnetStatus pcrnet_model_load(const uint8_t *blob, size_t blob_len, PcrnetModel *model);

/*
 Bytes of scratch a call needs with `tile` points per encoder pass
 (1..=`PCRNET_MAX_TILE`; the largest is the fastest); 0 for a handle
 that is not loaded or a tile out of range.

 # Safety
 `model` must be null or point to a `PcrnetModel`.
 */
size_t pcrnet_model_scratch_len(const PcrnetModel *model, size_t tile);

/*
 Bytes of scratch with which a host build of this library on an x86-64
 CPU with AVX2, or an aarch64 one with the dot-product extension,
 encodes many points per weight pass (the block kernel, picked at run
 time; results identical bit for bit): the `PCRNET_MAX_TILE` scratch
 plus the kernel's int16 weights and activations (and the room the Rust
 API's `Int8Model::prepare` folds the head's template half into, which
 these calls leave unused). Firmware builds never use the extra bytes:
 give them `pcrnet_model_scratch_len`. 0 for a handle that is not
 loaded.

 # Safety
 `model` must be null or point to a `PcrnetModel`.
 */
size_t pcrnet_model_host_scratch_len(const PcrnetModel *model);

/*
 Network passes the model was trained for (1: PCRNet; more: i-PCRNet),
 the `passes` to register with; 0 for a handle that is not loaded.

 # Safety
 `model` must be null or point to a `PcrnetModel`.
 */
uint32_t pcrnet_model_trained_passes(const PcrnetModel *model);

/*
 The template's residual floor, a share of its size, when the blob
 carries one (format 6, measured by the exporter on the template's
 points beyond those stored); -1 when it does not or for a handle that
 is not loaded. `pcrnet_options_for_model` calibrates `max_residual`
 with it.

 # Safety
 `model` must be null or point to a `PcrnetModel`.
 */
float pcrnet_model_residual_floor(const PcrnetModel *model);

/*
 Writes the recommended options (`pcrnet_core::Options::default()`:
 one pass, 10 starts, point-to-plane ICP). Does nothing if `out` is null.

 # Safety
 `out` must be null or point to a writable `PcrnetOptions`.
 */
void pcrnet_options_default(PcrnetOptions *out);

/*
 Writes the recommended options with the steps `model` was trained for
 (`Int8Model::trained_options`): its passes (PCRNet 1, i-PCRNet more),
 or for a model trained as PointNetLK, which has no head, `passes` 0,
 its LK steps in `lk_iterations` and its larger sample in
 `network_points` (256 against 128); and `max_residual` calibrated by
 the template's residual floor when the blob carries one
 (`pcrnet_model_residual_floor`). `PCRNET_ERROR_NULL_POINTER` or
 `PCRNET_ERROR_NOT_LOADED`, writing nothing, otherwise.

 # Safety
 `model` must be null or point to a `PcrnetModel`; `out` null or point
 to a writable `PcrnetOptions`.
 */
PcrnetStatus pcrnet_options_for_model(const PcrnetModel *model, PcrnetOptions *out);

/*
 Writes the options of the network alone, scored: one start, no ICP.
 Does nothing if `out` is null.

 # Safety
 `out` must be null or point to a writable `PcrnetOptions`.
 */
void pcrnet_options_network_only(PcrnetOptions *out);

/*
 Registers `n_points` source points (`x y z` each, source units) to the
 model's template: network, flip resolution, ICP and residuals, as
 `options` say. Writes `out` on success.

 # Safety
 `model` must be null or point to a `PcrnetModel`; `points` to
 `3 * n_points` readable floats (or null); `options` to a
 `PcrnetOptions` (or null); `scratch` to `scratch_len` writable bytes
 (or null) overlapping none of the others; `out` to a writable
 `PcrnetRegistration` (or null).
 */
PcrnetStatus pcrnet_register(const PcrnetModel *model,
                             const float *points,
                             size_t n_points,
                             const PcrnetOptions *options,
                             int8_t *scratch,
                             size_t scratch_len,
                             PcrnetRegistration *out);

/*
 The network alone (no check, no refinement): up to `passes` passes
 (1: PCRNet; more: i-PCRNet, composing the estimates, stopping once a
 pass moves the pose by less than `tolerance`), each on at most 128
 points of the cloud (`NETWORK_POINTS`; every k-th, the sample a
 registration's pass takes). Writes the pose `[qw, qx, qy, qz, tx, ty, tz]` (source units)
 to `pose` and the passes run to `passes_run` on success.

 # Safety
 As `pcrnet_register`; `pose` must point to 7 writable floats and
 `passes_run` to a writable `uint32_t` (or be null).
 */
PcrnetStatus pcrnet_network_pose(const PcrnetModel *model,
                                 const float *points,
                                 size_t n_points,
                                 uint32_t passes,
                                 float tolerance,
                                 int8_t *scratch,
                                 size_t scratch_len,
                                 float *pose,
                                 uint32_t *passes_run);

/*
 What a status means and what to do, as a NUL-terminated string in
 static memory; an unknown value gives "unknown status".
 */
const char *pcrnet_status_message(int32_t status);

/*
 How far the points moved by `pose` `[qw, qx, qy, qz, tx, ty, tz]`
 (source units, as `PcrnetRegistration` gives it) lie from the template
 in the network's feature space: the relative distance between the
 encoder's feature of the moved points and the template's (0: the same
 feature; see `Int8Model::feature_distance`). One encoder pass over at most
 128 points (256 for a PointNetLK blob; every k-th: the sample the blob's
 registrations encode, as the template's feature was pooled). Writes it to `out` on success; a pose that is not finite is
 `PCRNET_ERROR_NON_FINITE_RESULT`.

 # Safety
 `model` as `pcrnet_register`; `points` must point to `3 * n_points`
 readable floats, `pose` to 7, `scratch` to `scratch_len` writable
 bytes, `out` to a writable float (each may be null: an error).
 */
PcrnetStatus pcrnet_feature_distance(const PcrnetModel *model,
                                     const float *points,
                                     size_t n_points,
                                     const float *pose,
                                     int8_t *scratch,
                                     size_t scratch_len,
                                     float *out);

/*
 The label elements (`uint16_t`) `pcrnet_locate` needs for a
 `width x height` frame sampled every `step` pixels (0 for a step of 0).
 */
size_t pcrnet_scene_labels_len(size_t width, size_t height, uint32_t step);

/*
 Writes the default scene options to `out` (nothing for null): a 4-pixel
 grid, 3 candidates, the plane found, no up axis, poses verified.

 # Safety
 `out` must be null or point to a writable `PcrnetSceneOptions`.
 */
void pcrnet_scene_options_default(PcrnetSceneOptions *out);

/*
 Writes the default scene options for `model`'s object to `out`: those
 of `pcrnet_scene_options_default`, with the up axis the blob was
 exported with (`pcrnet train --up`, format 7) in `up` and `has_up` set
 when it has one, so that `pcrnet_locate` sweeps the yaw about the plane
 it finds. `PCRNET_ERROR_NULL_POINTER` or `PCRNET_ERROR_NOT_LOADED`,
 writing nothing, otherwise.

 # Safety
 `model` must be null or point to a `PcrnetModel`; `out` null or point
 to a writable `PcrnetSceneOptions`.
 */
PcrnetStatus pcrnet_scene_options_for_model(const PcrnetModel *model, PcrnetSceneOptions *out);

/*
 Finds the model's object in a depth frame and registers it: the
 dominant plane (found, or given in `scene`) taken out, what stands off
 it split into clusters, those the size of the object kept, the largest
 `scene->candidates` registered as `pcrnet_register` does (each from at
 most `points_capacity` of its points) and checked against the frame,
 the best reliable one reported. A frame without a kept cluster is
 success with `found` false. Writes `out` on success.

 Buffers, all caller-owned and not overlapping: `labels`, at least
 `pcrnet_scene_labels_len(width, height, step)` elements; `points`,
 `3 * points_capacity` floats (512 points is plenty); `scratch` as for
 `pcrnet_register`. A bad frame or scene setting is
 `PCRNET_ERROR_INVALID_FRAME`.

 # Safety
 `model`, `options`, `scratch` as `pcrnet_register` says; `image` must
 point to a `PcrnetDepthImage` whose `depth` holds `height * stride`
 readable values; `scene` to a `PcrnetSceneOptions`; `labels` to
 `labels_len` writable `uint16_t`; `points` to `3 * points_capacity`
 writable floats; `out` to a writable `PcrnetLocated` (each may be null,
 which is a status).
 */
PcrnetStatus pcrnet_locate(const PcrnetModel *model,
                           const PcrnetDepthImage *image,
                           const PcrnetSceneOptions *scene,
                           const PcrnetOptions *options,
                           uint16_t *labels,
                           size_t labels_len,
                           float *points,
                           size_t points_capacity,
                           int8_t *scratch,
                           size_t scratch_len,
                           PcrnetLocated *out);

/*
 Follows the model's object into the next frame of a stream
 (`Int8Model::follow`): `previous` is the pose of the last frame (7
 floats, `qw qx qy qz tx ty tz`, as `pcrnet_locate` or this call wrote it
 in `out->registration`), and `scene` should carry the plane the last
 result found (`has_plane`, `plane_normal`, `plane_offset` copied from
 it: no plane search then). The cluster nearest where `previous` put the
 object, in a box of 1.5 object radii about it, is registered by ICP
 from `previous` and checked against the frame; `out` as
 `pcrnet_locate` writes it (`candidates_tried` 1 at most; no turn
 reported: keep the last `pcrnet_locate`'s). Act on it only when the
 status is `PCRNET_OK` and `reliable`; otherwise call `pcrnet_locate`
 again (the object moved too far, left the box or is hidden). Without
 `has_plane` the plane is searched for in the box. A `previous`
 that is not finite or not a unit rotation is
 `PCRNET_ERROR_INVALID_POSE`; buffers and other statuses as
 `pcrnet_locate`.

 # Safety
 As `pcrnet_locate`; `previous` must point to 7 readable floats (or be
 null, which is a status).
 */
PcrnetStatus pcrnet_follow(const PcrnetModel *model,
                           const PcrnetDepthImage *image,
                           const PcrnetSceneOptions *scene,
                           const float *previous,
                           const PcrnetOptions *options,
                           uint16_t *labels,
                           size_t labels_len,
                           float *points,
                           size_t points_capacity,
                           int8_t *scratch,
                           size_t scratch_len,
                           PcrnetLocated *out);

/*
 Makes `scratch` ready for many calls of `model` and fills `prepared`.
 `pcrnet_model_host_scratch_len` bytes let a host prepare everything;
 at least `pcrnet_model_scratch_len(model, 1)` are needed. Until the
 last call on `prepared`, the model handle, its blob and the scratch
 must stay valid and unchanged, and the scratch must be used by no other
 call; after `pcrnet_model_load` on the same model handle, prepare
 again. On failure `prepared` is marked not prepared.

 # Safety
 `model` must be null or point to a `PcrnetModel`; `scratch` to
 `scratch_len` writable bytes (or null) overlapping nothing else;
 `prepared` to writable storage of a `PcrnetPrepared` (or be null).
 */
PcrnetStatus pcrnet_prepare(const PcrnetModel *model,
                            int8_t *scratch,
                            size_t scratch_len,
                            PcrnetPrepared *prepared);

/*
 `pcrnet_register` on a prepared handle (its model and scratch).

 # Safety
 `prepared` must be null or point to a `PcrnetPrepared` whose model
 handle and scratch are still valid (see `pcrnet_prepare`); `points`,
 `options` and `out` as `pcrnet_register` says.
 */
PcrnetStatus pcrnet_prepared_register(PcrnetPrepared *prepared,
                                      const float *points,
                                      size_t n_points,
                                      const PcrnetOptions *options,
                                      PcrnetRegistration *out);

/*
 `pcrnet_network_pose` on a prepared handle (its model and scratch).

 # Safety
 As `pcrnet_prepared_register` for `prepared` and `points`; `pose` and
 `passes_run` as `pcrnet_network_pose` says.
 */
PcrnetStatus pcrnet_prepared_network_pose(PcrnetPrepared *prepared,
                                          const float *points,
                                          size_t n_points,
                                          uint32_t passes,
                                          float tolerance,
                                          float *pose,
                                          uint32_t *passes_run);

/*
 One tracking step: refines `previous`, the last frame's pose
 `[qw, qx, qy, qz, tx, ty, tz]` (source units, as `PcrnetRegistration`
 gives it), by ICP on the points, and keeps it when reliable and within
 one step; else registers the points afresh, as `pcrnet_register` does.
 Writes the result to `out` and `PCRNET_TRACK_KEPT`, `_RECOVERED` or
 `_LOST` to `outcome` on success. A `previous` that is not finite or
 whose quaternion is not of unit length is `PCRNET_ERROR_INVALID_POSE`.

 # Safety
 As `pcrnet_register`; `previous` must point to 7 readable floats and
 `outcome` to a writable `uint32_t` (or be null).
 */
PcrnetStatus pcrnet_track(const PcrnetModel *model,
                          const float *points,
                          size_t n_points,
                          const float *previous,
                          const PcrnetOptions *options,
                          int8_t *scratch,
                          size_t scratch_len,
                          PcrnetRegistration *out,
                          uint32_t *outcome);

/*
 One tracking step of a cut single view seen from `viewpoint` `[x, y,
 z]` (the sensor's position in the source's frame, source units: 0, 0, 0
 for points in the camera's own frame), as `pcrnet_track` does, its
 fallback registration guided by the view as `pcrnet_register_view`'s
 is (starts placed by what the sensor sees, the turned ones judged by
 the view rendered into `buffer`, `buffer_len` floats, see
 `PCRNET_VIEW_BUFFER_LEN`). `out->reliable` is the residual's verdict,
 as `pcrnet_track`'s; `pcrnet_check_view` checks the pose against the
 view. Errors as `pcrnet_track` and `pcrnet_check_view` (the view is
 rendered first: a viewpoint it refuses is an error even when the track
 holds); nothing is written on one.

 # Safety
 As `pcrnet_track`; `viewpoint` must point to 3 readable floats and
 `buffer` to `buffer_len` writable floats overlapping nothing else
 (each may be null: an error).
 */
PcrnetStatus pcrnet_track_view(const PcrnetModel *model,
                               const float *points,
                               size_t n_points,
                               const float *previous,
                               const float *viewpoint,
                               const PcrnetOptions *options,
                               int8_t *scratch,
                               size_t scratch_len,
                               float *buffer,
                               size_t buffer_len,
                               PcrnetRegistration *out,
                               uint32_t *outcome);

/*
 Registers `n_points` source points, a cut single view seen from
 `viewpoint` `[x, y, z]` (the sensor's position in the source's frame,
 source units), as `pcrnet_register` does, with the view rendered into
 `buffer` (`buffer_len` floats, see `PCRNET_VIEW_BUFFER_LEN`) as a test
 the turned starts must pass besides their residual (the lowest-residual
 one that explains the view finishes), every start first placed so that
 the view's centroid meets the centroid of what the sensor would see of
 the template there (`Int8Model::register_view`).
 Writes the registration to `out` and its check against the view to
 `out_view` on success; `out->reliable` is both verdicts (the residual's
 and `out_view->passed`): act on the pose only when it is set. Errors as
 `pcrnet_register` and `pcrnet_check_view`; nothing is written on one.

 # Safety
 As `pcrnet_register`; `viewpoint` must point to 3 readable floats,
 `buffer` to `buffer_len` writable floats overlapping nothing else,
 `out_view` to a writable `PcrnetViewCheck` (each may be null: an error).
 */
PcrnetStatus pcrnet_register_view(const PcrnetModel *model,
                                  const float *points,
                                  size_t n_points,
                                  const float *viewpoint,
                                  const PcrnetOptions *options,
                                  int8_t *scratch,
                                  size_t scratch_len,
                                  float *buffer,
                                  size_t buffer_len,
                                  PcrnetRegistration *out,
                                  PcrnetViewCheck *out_view);

/*
 Checks `pose` `[qw, qx, qy, qz, tx, ty, tz]` (a registration of the
 `n_points` source points, as `PcrnetRegistration` gives it) against the
 source seen as a cut single view from `viewpoint` `[x, y, z]` (the
 sensor's position in the source's frame, source units; 0, 0, 0 for
 points in the camera's own frame): the source splatted into a small
 depth image in `buffer` (`buffer_len` floats, see
 `PCRNET_VIEW_BUFFER_LEN`), the template's points judged on it (see
 `pcrnet_core::scene::view`). Act on a registration only when it is
 reliable and the check passed. Writes `out` on success; a viewpoint
 that is not finite, among or beside the points or more than 10,000
 source radii away, or a buffer under 64 floats, is
 `PCRNET_ERROR_INVALID_OPTION`; no finite point,
 `PCRNET_ERROR_EMPTY_CLOUD`; a pose that is not finite or whose
 quaternion is not of unit length, `PCRNET_ERROR_INVALID_POSE`.

 # Safety
 `model` as `pcrnet_register`; `points` must point to `3 * n_points`
 readable floats, `viewpoint` to 3 and `pose` to 7, `buffer` to
 `buffer_len` writable floats, `out` to a writable `PcrnetViewCheck`
 (each may be null: an error).
 */
PcrnetStatus pcrnet_check_view(const PcrnetModel *model,
                               const float *points,
                               size_t n_points,
                               const float *viewpoint,
                               const float *pose,
                               float *buffer,
                               size_t buffer_len,
                               PcrnetViewCheck *out);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* PCRNET_H */
