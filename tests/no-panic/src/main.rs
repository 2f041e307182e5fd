//! Link-time proof that no panic is reachable from the device entry points.
//!
//! This image calls every public inference entry point of `pcrnet-core`
//! (load and parse, `register`, `track`, `locate` on a depth image and an
//! organised cloud, the network alone, `infer`, `encode`,
//! `head`, `pose`, the f32 reference) and every function of the C API, on
//! a blob, a cloud, options, tiles and scratch lengths the optimiser cannot
//! see (they pass through [`black_box`]), so every branch that some input
//! could take is kept. Its panic handler (the C API's, with the feature
//! `prove-no-panic`) calls a function that exists nowhere: if any panic path survives optimisation (a bounds check, an
//! `unwrap`, an overflow check, a formatting call), linking fails with
//! `undefined reference to pcrnet_core_can_panic`.
//!
//! `cargo xtask no-panic` builds it with the firmware's optimisation
//! (release, LTO, one codegen unit) for thumbv7em-none-eabihf and
//! thumbv6m-none-eabi, and on failure lists where the panics come from.
//! The image is linked, never run.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use pcrnet as capi;
use pcrnet_core::{F32Model, Int8Model, Options, Pose};

/// Bytes that stand for a blob, a cloud and C handles: zeros the optimiser
/// cannot see through once they pass through `black_box`.
static BLOB: [u8; 4096] = [0; 4096];
static CLOUD: [[f32; 3]; 64] = [[0.0; 3]; 64];

#[entry]
fn main() -> ! {
    static mut SCRATCH: [i8; 8192] = [0; 8192];
    static mut F32_SCRATCH: [f32; 2048] = [0.0; 2048];
    static mut FEATURE: [f32; 1024] = [0.0; 1024];
    static mut MODEL: capi::PcrnetModel = capi::PcrnetModel::new();
    let (scratch, f32_scratch, feature) = (SCRATCH, F32_SCRATCH, FEATURE);
    loop {
        rust_api(scratch, f32_scratch, feature);
        c_api(MODEL, scratch);
    }
}

/// Everything a Rust firmware calls.
fn rust_api(scratch: &mut [i8], f32_scratch: &mut [f32], feature: &mut [f32]) {
    let blob: &[u8] = black_box(&BLOB[..]);
    let source: &[[f32; 3]] = black_box(&CLOUD[..]);
    let options: Options = black_box(Options::default());
    let tile: usize = black_box(8);
    let passes: usize = black_box(1);
    let tolerance: f32 = black_box(0.0);
    let scratch = black_box(scratch);

    let _ = black_box(Int8Model::from_bytes(blob).is_ok());
    if let Ok(model) = Int8Model::load(blob, scratch) {
        let _ = black_box(model.register(source, &options, scratch));
        let previous: Pose = black_box(Pose::IDENTITY);
        let _ = black_box(model.track(source, &previous, &options, scratch));
        let _ = black_box(model.network_pose(source, passes, tolerance, scratch));
        if let Ok(inference) = model.infer_tiled(source, tile, scratch) {
            let (head, centring) = (inference.head, inference.centring);
            model.dequantize_feature(inference.feature, feature);
            let _ = black_box(model.pose(&head).map(|p| centring.then(&p).matrix()));
        }
        let _ = black_box(model.infer(source, scratch).map(|i| i.head));
        let _ = black_box(model.encode(source, scratch).map(|f| f.len()));
        let _ = black_box(model.encode_tiled(source, tile, scratch).map(|f| f.len()));
        let (source_feature, work) = scratch.split_at_mut(black_box(256).min(scratch.len()));
        let _ = black_box(model.head(source_feature, work));
        let _ = black_box(model.scratch_len(tile));
        scene(&model, &options, scratch);
    }
    if let Ok(model) = F32Model::from_bytes(blob) {
        let f32_scratch = black_box(f32_scratch);
        let _ = black_box(model.register(source, &options, f32_scratch));
        let previous: Pose = black_box(Pose::IDENTITY);
        let _ = black_box(model.track(source, &previous, &options, f32_scratch));
        let _ = black_box(model.network_pose(source, passes, tolerance, f32_scratch));
        let network = model.network();
        let _ = black_box(network.infer(source, f32_scratch));
        let (source_feature, work) =
            f32_scratch.split_at_mut(black_box(1024).min(f32_scratch.len()));
        let _ = black_box(network.head(source_feature, work));
    }
}

/// The scene path: `locate` on a depth image and on an organised cloud of
/// sizes, intrinsics, depth scale, settings and buffers the optimiser
/// cannot see.
fn scene(model: &Int8Model, options: &Options, scratch: &mut [i8]) {
    use pcrnet_core::scene::{DepthImage, Intrinsics, OrganisedPoints, SceneOptions};
    static DEPTH: [u16; 1024] = [0; 1024];
    static mut LABELS: [u16; 512] = [0; 512];
    static mut POINTS: [[f32; 3]; 128] = [[0.0; 3]; 128];
    // SAFETY: `scene` runs on one thread, one call at a time, and is the
    // only code naming these buffers.
    let (labels, points) = unsafe {
        (
            &mut *core::ptr::addr_of_mut!(LABELS),
            &mut *core::ptr::addr_of_mut!(POINTS),
        )
    };
    let labels: &mut [u16] = black_box(labels);
    let points: &mut [[f32; 3]] = black_box(points);
    let depth: &[u16] = black_box(&DEPTH[..]);
    let k: Intrinsics = black_box(Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 16.0,
        cy: 16.0,
    });
    let (width, height, stride) = (black_box(32), black_box(32), black_box(32));
    let scene_options: SceneOptions = black_box(SceneOptions::for_object(black_box(1.0)));
    let candidates = black_box(3);
    if let Ok(image) = DepthImage::new(depth, width, height, stride, k, black_box(1e-3), 0) {
        let located = model.locate(
            &image,
            &scene_options,
            candidates,
            options,
            labels,
            points,
            scratch,
        );
        let _ = black_box(located.map(|l| l.best.is_some()));
    }
    if let Ok(cloud) = OrganisedPoints::new(black_box(&CLOUD[..]), black_box(8)) {
        let cloud = match cloud.estimate_intrinsics() {
            Some(k) => cloud.with_intrinsics(k),
            None => cloud,
        };
        let located = model.locate(
            &cloud,
            &scene_options,
            candidates,
            options,
            labels,
            points,
            scratch,
        );
        let _ = black_box(located.map(|l| l.best.is_some()));
    }
}

/// Everything a C firmware calls, with pointers and lengths the optimiser
/// cannot see.
fn c_api(model: &mut capi::PcrnetModel, scratch: &mut [i8]) {
    let blob = black_box(BLOB.as_ptr());
    let blob_len = black_box(BLOB.len());
    let points = black_box(CLOUD.as_ptr()) as *const f32;
    let n_points = black_box(CLOUD.len());
    let model: *mut capi::PcrnetModel = black_box(model);
    let scratch_len = black_box(scratch.len());
    let scratch = black_box(scratch.as_mut_ptr());
    let mut options = core::mem::MaybeUninit::<capi::PcrnetOptions>::uninit();
    let mut out = core::mem::MaybeUninit::<capi::PcrnetRegistration>::uninit();
    let mut pose = [0f32; 7];
    let mut passes_run = 0u32;
    let mut prepared = capi::PcrnetPrepared::new();
    // SAFETY: every pointer is to live storage of the right size; the C
    // API checks null, alignment and lengths itself.
    unsafe {
        black_box(capi::pcrnet_model_load(blob, blob_len, model));
        black_box(capi::pcrnet_model_scratch_len(model, black_box(8)));
        black_box(capi::pcrnet_model_trained_passes(model));
        black_box(capi::pcrnet_model_residual_floor(model));
        capi::pcrnet_options_default(black_box(options.as_mut_ptr()));
        capi::pcrnet_options_network_only(black_box(options.as_mut_ptr()));
        black_box(capi::pcrnet_options_for_model(
            model,
            black_box(options.as_mut_ptr()),
        ));
        black_box(capi::pcrnet_register(
            model,
            points,
            n_points,
            black_box(options.as_ptr()),
            scratch,
            scratch_len,
            black_box(out.as_mut_ptr()),
        ));
        black_box(capi::pcrnet_network_pose(
            model,
            points,
            n_points,
            black_box(1),
            black_box(0.0),
            scratch,
            scratch_len,
            black_box(pose.as_mut_ptr()),
            black_box(&mut passes_run),
        ));
        let mut outcome = 0u32;
        black_box(capi::pcrnet_track(
            model,
            points,
            n_points,
            black_box(pose.as_ptr()),
            black_box(options.as_ptr()),
            scratch,
            scratch_len,
            black_box(out.as_mut_ptr()),
            black_box(&mut outcome),
        ));
        let prepared: *mut capi::PcrnetPrepared = black_box(&mut prepared);
        black_box(capi::pcrnet_prepare(model, scratch, scratch_len, prepared));
        black_box(capi::pcrnet_prepared_register(
            prepared,
            points,
            n_points,
            black_box(options.as_ptr()),
            black_box(out.as_mut_ptr()),
        ));
        black_box(capi::pcrnet_prepared_network_pose(
            prepared,
            points,
            n_points,
            black_box(1),
            black_box(0.0),
            black_box(pose.as_mut_ptr()),
            black_box(&mut passes_run),
        ));
        black_box(capi::pcrnet_feature_distance(
            model,
            points,
            n_points,
            black_box(pose.as_ptr()),
            scratch,
            scratch_len,
            black_box(&mut 0f32),
        ));
        let mut view = [0f32; 64];
        let mut seen = core::mem::MaybeUninit::<capi::PcrnetViewCheck>::uninit();
        black_box(capi::pcrnet_check_view(
            model,
            points,
            n_points,
            black_box([0f32, 0.0, 3.0].as_ptr()),
            black_box(pose.as_ptr()),
            black_box(view.as_mut_ptr()),
            black_box(view.len()),
            black_box(seen.as_mut_ptr()),
        ));
        black_box(capi::pcrnet_register_view(
            model,
            points,
            n_points,
            black_box([0f32, 0.0, 3.0].as_ptr()),
            black_box(options.as_ptr()),
            scratch,
            scratch_len,
            black_box(view.as_mut_ptr()),
            black_box(view.len()),
            black_box(out.as_mut_ptr()),
            black_box(seen.as_mut_ptr()),
        ));
        black_box(capi::pcrnet_track_view(
            model,
            points,
            n_points,
            black_box(pose.as_ptr()),
            black_box([0f32, 0.0, 3.0].as_ptr()),
            black_box(options.as_ptr()),
            scratch,
            scratch_len,
            black_box(view.as_mut_ptr()),
            black_box(view.len()),
            black_box(out.as_mut_ptr()),
            black_box(&mut outcome),
        ));
        black_box(capi::pcrnet_status_message(black_box(-3)));
        c_locate(model, scratch, scratch_len);
    }
}

/// `pcrnet_locate` on a frame, settings and buffers the optimiser cannot see.
///
/// # Safety
/// `model` points to a handle and `scratch` to `scratch_len` writable bytes.
unsafe fn c_locate(model: *const capi::PcrnetModel, scratch: *mut i8, scratch_len: usize) {
    static DEPTH: [u16; 1024] = [0; 1024];
    static mut LABELS: [u16; 512] = [0; 512];
    static mut POINTS: [f32; 384] = [0.0; 384];
    let image = black_box(capi::PcrnetDepthImage {
        depth: black_box(DEPTH.as_ptr()),
        width: black_box(32),
        height: black_box(32),
        stride: black_box(32),
        fx: black_box(100.0),
        fy: black_box(100.0),
        cx: black_box(16.0),
        cy: black_box(16.0),
        depth_scale: black_box(1e-3),
        invalid: black_box(0),
    });
    let mut scene = core::mem::MaybeUninit::<capi::PcrnetSceneOptions>::uninit();
    let mut options = core::mem::MaybeUninit::<capi::PcrnetOptions>::uninit();
    let mut out = core::mem::MaybeUninit::<capi::PcrnetLocated>::uninit();
    // SAFETY: every pointer is to live storage of the right size (the
    // statics are named by this function only, which runs once at a time);
    // the C API checks null, alignment and lengths itself.
    unsafe {
        capi::pcrnet_scene_options_default(black_box(scene.as_mut_ptr()));
        black_box(capi::pcrnet_scene_options_for_model(
            model,
            black_box(scene.as_mut_ptr()),
        ));
        capi::pcrnet_options_default(black_box(options.as_mut_ptr()));
        black_box(capi::pcrnet_scene_labels_len(32, 32, black_box(4)));
        black_box(capi::pcrnet_locate(
            model,
            &image,
            black_box(scene.as_ptr()),
            black_box(options.as_ptr()),
            black_box(core::ptr::addr_of_mut!(LABELS) as *mut u16),
            black_box(512),
            black_box(core::ptr::addr_of_mut!(POINTS) as *mut f32),
            black_box(128),
            scratch,
            scratch_len,
            black_box(out.as_mut_ptr()),
        ));
        let previous = black_box([1.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        black_box(capi::pcrnet_follow(
            model,
            &image,
            black_box(scene.as_ptr()),
            black_box(previous.as_ptr()),
            black_box(options.as_ptr()),
            black_box(core::ptr::addr_of_mut!(LABELS) as *mut u16),
            black_box(512),
            black_box(core::ptr::addr_of_mut!(POINTS) as *mut f32),
            black_box(128),
            scratch,
            scratch_len,
            black_box(out.as_mut_ptr()),
        ));
    }
}
