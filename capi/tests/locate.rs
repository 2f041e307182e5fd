//! `pcrnet_locate` as C calls it: on the QEMU harness's generated frame
//! (the shipped model's template on a table beside two blocks) it finds
//! the object bit for bit as the Rust API's `Int8Model::locate` does, with
//! and without the up axis; bad frames and buffers are statuses with
//! nothing written; a frame without depth is success with nothing found.
#![allow(unsafe_code)]

mod common;

use std::mem::MaybeUninit;

use common::{loaded, options_default, sentinel, shipped_blob};
use pcrnet::PcrnetStatus::*;
use pcrnet::*;
use pcrnet_core::Int8Model;
use pcrnet_core::Options;
use pcrnet_core::scene::SceneOptions;
use pcrnet_core::testing::scene as harness;

const W: usize = harness::HARNESS_WIDTH;
const H: usize = harness::HARNESS_HEIGHT;

fn scene_default() -> PcrnetSceneOptions {
    let mut o = MaybeUninit::uninit();
    unsafe {
        pcrnet_scene_options_default(o.as_mut_ptr());
        o.assume_init()
    }
}

/// The harness frame of the shipped model.
fn frame(model: &Int8Model<'_>) -> Vec<u16> {
    let mut depth = vec![0u16; W * H];
    let mut template = vec![[0f32; 3]; 1024];
    harness::harness_frame(model, &mut template, &mut depth).unwrap();
    depth
}

fn image(depth: &[u16]) -> PcrnetDepthImage {
    let k = harness::Tabletop::tof_intrinsics();
    PcrnetDepthImage {
        depth: depth.as_ptr(),
        width: W,
        height: H,
        stride: W,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        depth_scale: harness::DEPTH_SCALE,
        invalid: 0,
    }
}

/// Buffers of one call: labels, points, scratch.
struct Buffers {
    labels: Vec<u16>,
    points: Vec<[f32; 3]>,
    scratch: Vec<i8>,
}

impl Buffers {
    fn for_model(model: &Int8Model<'_>) -> Self {
        Buffers {
            labels: vec![0; pcrnet_scene_labels_len(W, H, 4)],
            points: vec![[0.0; 3]; 512],
            scratch: vec![0; model.scratch_len(1)],
        }
    }
}

/// A result filled with a pattern, to see whether a call wrote it.
fn untouched() -> PcrnetLocated {
    PcrnetLocated {
        registration: sentinel(),
        plane_normal: [7.0; 3],
        plane_offset: 7.0,
        supported: 7,
        violations: 7,
        occluded: 7,
        unobserved: 7,
        outside: 7,
        cluster: 7,
        clusters_kept: 7,
        candidates_tried: 7,
        found: true,
        reliable: true,
        verified: true,
        has_plane: true,
    }
}

/// `pcrnet_locate` with `labels_len` labels: the status and what it wrote
/// (`None`: nothing, checked against the pattern).
fn locate(
    handle: &PcrnetModel,
    image: &PcrnetDepthImage,
    scene: &PcrnetSceneOptions,
    b: &mut Buffers,
    labels_len: usize,
) -> (PcrnetStatus, Option<PcrnetLocated>) {
    let mut out = untouched();
    let options = options_default();
    let status = unsafe {
        pcrnet_locate(
            handle,
            image,
            scene,
            &options,
            b.labels.as_mut_ptr(),
            labels_len,
            b.points.as_mut_ptr() as *mut f32,
            b.points.len(),
            b.scratch.as_mut_ptr(),
            b.scratch.len(),
            &mut out,
        )
    };
    if status != PCRNET_OK {
        assert_eq!(out, untouched(), "a failed call wrote its output");
    }
    (status, (status == PCRNET_OK).then_some(out))
}

#[test]
fn the_harness_frame_is_located_as_the_rust_api_locates_it() {
    let blob = shipped_blob();
    let (handle, rust) = (loaded(&blob), Int8Model::from_bytes(&blob).unwrap());
    let depth = frame(&rust);
    let image = image(&depth);
    for up in [None, Some(harness::HARNESS_UP)] {
        let scene = PcrnetSceneOptions {
            has_up: up.is_some(),
            up: up.unwrap_or([0.0; 3]),
            ..scene_default()
        };
        let mut b = Buffers::for_model(&rust);
        let len = b.labels.len();
        let (status, found) = locate(&handle, &image, &scene, &mut b, len);
        assert_eq!(status, PCRNET_OK);
        let found = found.unwrap();

        let mut r = Buffers::for_model(&rust);
        let frame = harness::harness_image(&depth).unwrap();
        let options = SceneOptions {
            up,
            ..SceneOptions::for_object(rust.object_radius())
        };
        let located = rust
            .locate(
                &frame,
                &options,
                3,
                &Options::default(),
                &mut r.labels,
                &mut r.points,
                &mut r.scratch,
            )
            .unwrap();
        let best = located.best.expect("the harness frame holds the object");
        assert!(found.found && found.has_plane && found.verified);
        assert_eq!(
            found.registration,
            PcrnetRegistration::from(&best.registration)
        );
        assert_eq!(found.reliable, best.reliable);
        assert_eq!(found.cluster as usize, best.cluster);
        assert_eq!(found.candidates_tried as usize, located.tried.len());
        let v = best.verification.unwrap();
        assert_eq!(
            [
                found.supported,
                found.violations,
                found.occluded,
                found.unobserved,
                found.outside
            ],
            [
                v.supported,
                v.violations,
                v.occluded,
                v.unobserved,
                v.outside
            ]
        );
        let plane = located.segmentation.plane.unwrap();
        assert_eq!(
            (found.plane_normal, found.plane_offset),
            (plane.normal, plane.offset)
        );
    }
}

#[test]
fn the_sweep_finds_the_object_reliable_in_the_harness_frame() {
    let blob = shipped_blob();
    let (handle, rust) = (loaded(&blob), Int8Model::from_bytes(&blob).unwrap());
    let depth = frame(&rust);
    let scene = PcrnetSceneOptions {
        has_up: true,
        up: harness::HARNESS_UP,
        ..scene_default()
    };
    let mut b = Buffers::for_model(&rust);
    let len = b.labels.len();
    let (_, found) = locate(&handle, &image(&depth), &scene, &mut b, len);
    let found = found.unwrap();
    assert!(found.found && found.reliable, "{found:?}");
}

#[test]
fn bad_frames_and_buffers_are_statuses_with_nothing_written() {
    let blob = shipped_blob();
    let (handle, rust) = (loaded(&blob), Int8Model::from_bytes(&blob).unwrap());
    let depth = frame(&rust);
    let scene = scene_default();
    let mut b = Buffers::for_model(&rust);
    let len = b.labels.len();
    // Labels too short for the grid.
    let (status, out) = locate(&handle, &image(&depth), &scene, &mut b, len / 2);
    assert_eq!((status, out), (PCRNET_ERROR_BUFFER_TOO_SMALL, None));
    // No width; a stride below the width; a non-finite focal length; a step of 0.
    for bad in [
        PcrnetDepthImage {
            width: 0,
            ..image(&depth)
        },
        PcrnetDepthImage {
            stride: W - 1,
            ..image(&depth)
        },
        PcrnetDepthImage {
            fx: f32::NAN,
            ..image(&depth)
        },
    ] {
        let (status, out) = locate(&handle, &bad, &scene, &mut b, len);
        assert_eq!((status, out), (PCRNET_ERROR_INVALID_FRAME, None));
    }
    let step0 = PcrnetSceneOptions { step: 0, ..scene };
    let (status, _) = locate(&handle, &image(&depth), &step0, &mut b, len);
    assert_eq!(status, PCRNET_ERROR_INVALID_FRAME);
    // Null depth with pixels; misaligned labels.
    let null = PcrnetDepthImage {
        depth: std::ptr::null(),
        ..image(&depth)
    };
    assert_eq!(
        locate(&handle, &null, &scene, &mut b, len).0,
        PCRNET_ERROR_NULL_POINTER
    );
    let mut out = MaybeUninit::<PcrnetLocated>::zeroed();
    let options = options_default();
    let bytes = b.labels.as_mut_ptr() as *mut u8;
    let status = unsafe {
        pcrnet_locate(
            &*handle,
            &image(&depth),
            &scene,
            &options,
            bytes.add(1) as *mut u16,
            len - 1,
            b.points.as_mut_ptr() as *mut f32,
            b.points.len(),
            b.scratch.as_mut_ptr(),
            b.scratch.len(),
            out.as_mut_ptr(),
        )
    };
    assert_eq!(status, PCRNET_ERROR_MISALIGNED);
    // Null options, scene, image or output.
    let status = unsafe {
        pcrnet_locate(
            &*handle,
            &image(&depth),
            std::ptr::null(),
            &options,
            b.labels.as_mut_ptr(),
            len,
            b.points.as_mut_ptr() as *mut f32,
            b.points.len(),
            b.scratch.as_mut_ptr(),
            b.scratch.len(),
            out.as_mut_ptr(),
        )
    };
    assert_eq!(status, PCRNET_ERROR_NULL_POINTER);
}

#[test]
fn a_frame_without_depth_is_success_with_nothing_found() {
    let blob = shipped_blob();
    let (handle, rust) = (loaded(&blob), Int8Model::from_bytes(&blob).unwrap());
    let empty = vec![0u16; W * H];
    let mut b = Buffers::for_model(&rust);
    let len = b.labels.len();
    let (status, out) = locate(&handle, &image(&empty), &scene_default(), &mut b, len);
    assert_eq!(status, PCRNET_OK);
    let out = out.unwrap();
    assert!(!out.found && !out.reliable && !out.has_plane, "{out:?}");
    assert_eq!((out.clusters_kept, out.candidates_tried), (0, 0));
}

/// A blob exported with an up axis (format 7): the scene options for the
/// model carry it (the Rust scene options they give are
/// `Int8Model::scene_options`); the shipped blob has none, and a null
/// handle or output is a status.
#[test]
fn the_blobs_up_axis_reaches_the_scene_options_for_the_model() {
    use pcrnet_core::format::{self, ModelKind, Trailer};
    let shipped = shipped_blob();
    let rust = Int8Model::from_bytes(&shipped).unwrap();
    let trailer = Trailer {
        table: rust.template().table(),
        up: Some([0.0, 0.0, -1.0]),
        ..Trailer::default()
    };
    let mut blob = vec![0u8; format::blob_len(rust.payload(), &trailer).unwrap()];
    format::write_blob(ModelKind::Int8, rust.payload(), &trailer, &mut blob).unwrap();
    let model = loaded(&blob);
    let mut scene = scene_default();
    let status = unsafe { pcrnet_scene_options_for_model(&*model, &mut scene) };
    assert_eq!(status, PCRNET_OK);
    assert!(scene.has_up);
    assert_eq!(scene.up, [0.0, 0.0, -1.0]);
    assert_eq!(
        PcrnetSceneOptions {
            up: [0.0, 0.0, 1.0],
            has_up: false,
            ..scene
        },
        scene_default()
    );
    let plain = loaded(&shipped);
    let status = unsafe { pcrnet_scene_options_for_model(&*plain, &mut scene) };
    assert_eq!(status, PCRNET_OK);
    assert_eq!(scene, scene_default());
    let with_up = Int8Model::from_bytes(&blob).unwrap();
    let scene_rust = with_up.scene_options();
    let c_scene = {
        let mut s = scene_default();
        unsafe { pcrnet_scene_options_for_model(&*model, &mut s) };
        s
    };
    assert_eq!(c_scene.scene_options(with_up.object_radius()), scene_rust);
    assert_eq!(
        unsafe { pcrnet_scene_options_for_model(std::ptr::null(), &mut scene) },
        PCRNET_ERROR_NULL_POINTER
    );
    assert_eq!(
        unsafe { pcrnet_scene_options_for_model(&*model, std::ptr::null_mut()) },
        PCRNET_ERROR_NULL_POINTER
    );
}

/// `pcrnet_follow` from the sweep's result (its pose, and its plane copied
/// into the scene options) finds what the Rust API's `Int8Model::follow`
/// finds, bit for bit, reliable; a null or non-unit pose is a status with
/// nothing written.
#[test]
fn the_next_frame_is_followed_as_the_rust_api_follows_it() {
    let blob = shipped_blob();
    let (handle, rust) = (loaded(&blob), Int8Model::from_bytes(&blob).unwrap());
    let depth = frame(&rust);
    let image = image(&depth);
    let swept = PcrnetSceneOptions {
        has_up: true,
        up: harness::HARNESS_UP,
        ..scene_default()
    };
    let mut b = Buffers::for_model(&rust);
    let len = b.labels.len();
    let (status, found) = locate(&handle, &image, &swept, &mut b, len);
    assert_eq!(status, PCRNET_OK);
    let found = found.unwrap();
    assert!(found.reliable && found.has_plane);
    let r = &found.registration;
    let previous = [
        r.rotation[0],
        r.rotation[1],
        r.rotation[2],
        r.rotation[3],
        r.translation[0],
        r.translation[1],
        r.translation[2],
    ];
    let scene = PcrnetSceneOptions {
        has_plane: true,
        plane_normal: found.plane_normal,
        plane_offset: found.plane_offset,
        ..scene_default()
    };
    let follow = |previous: *const f32, b: &mut Buffers| {
        let mut out = untouched();
        let options = options_default();
        let status = unsafe {
            pcrnet_follow(
                &*handle,
                &image,
                &scene,
                previous,
                &options,
                b.labels.as_mut_ptr(),
                b.labels.len(),
                b.points.as_mut_ptr() as *mut f32,
                b.points.len(),
                b.scratch.as_mut_ptr(),
                b.scratch.len(),
                &mut out,
            )
        };
        (status, out)
    };
    let (status, followed) = follow(previous.as_ptr(), &mut b);
    assert_eq!(status, PCRNET_OK);
    assert!(followed.reliable && followed.found, "{followed:?}");
    assert_eq!(followed.candidates_tried, 1);
    // The Rust API from the same pose and plane.
    let frame = harness::harness_image(&depth).unwrap();
    let pose = pcrnet_core::Pose {
        rotation: [previous[0], previous[1], previous[2], previous[3]],
        translation: [previous[4], previous[5], previous[6]],
    };
    let plane = pcrnet_core::scene::Plane {
        normal: found.plane_normal,
        offset: found.plane_offset,
    };
    let mut rb = Buffers::for_model(&rust);
    let want = rust
        .follow(
            &frame,
            &SceneOptions::for_object(rust.object_radius()),
            &pose,
            Some(plane),
            &Options::default(),
            &mut rb.labels,
            &mut rb.points,
            &mut rb.scratch,
        )
        .unwrap();
    assert_eq!(followed, PcrnetLocated::from(&want));
    // Bad poses: nothing written.
    let (status, out) = follow(std::ptr::null(), &mut b);
    assert_eq!((status, out), (PCRNET_ERROR_NULL_POINTER, untouched()));
    let skewed = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0f32];
    let (status, out) = follow(skewed.as_ptr(), &mut b);
    assert_eq!((status, out), (PCRNET_ERROR_INVALID_POSE, untouched()));
}
