//! `pcrnet_check_view` as C calls it: the same counts as the Rust API's
//! `Int8Model::check_view`, a fragment of the view failing where the whole
//! passes, and a status with nothing written for bad input.
#![allow(unsafe_code)]

mod common;

use common::{loaded, options_default, sentinel, shipped_blob};
use pcrnet::*;
use pcrnet_core::{Int8Model, Options};

/// `pcrnet_check_view` of `points` seen from `viewpoint` at `pose`.
fn check(
    model: &PcrnetModel,
    points: &[[f32; 3]],
    viewpoint: &[f32; 3],
    pose: *const f32,
    buffer: &mut [f32],
) -> (PcrnetStatus, PcrnetViewCheck) {
    let mut out = PcrnetViewCheck {
        supported: u32::MAX,
        ..PcrnetViewCheck::default()
    };
    let status = unsafe {
        pcrnet_check_view(
            model,
            points.as_ptr() as *const f32,
            points.len(),
            viewpoint.as_ptr(),
            pose,
            buffer.as_mut_ptr(),
            buffer.len(),
            &mut out,
        )
    };
    (status, out)
}

/// The points of `cloud` a camera far along +z sees (an orthographic
/// z-buffer on an 8 x 8 grid over the cloud: in each cell, the points
/// within a cell's width of its nearest), and a viewpoint three radii from
/// the centroid along +z.
fn near_side(cloud: &[[f32; 3]]) -> (Vec<[f32; 3]>, [f32; 3]) {
    let n = cloud.len() as f32;
    let c: [f32; 3] = std::array::from_fn(|k| cloud.iter().map(|p| p[k]).sum::<f32>() / n);
    let radius = cloud
        .iter()
        .map(|p| (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f32>().sqrt())
        .fold(0f32, f32::max);
    let cell = 2.0 * radius / 8.0;
    let at = |p: &[f32; 3]| {
        let i = |k: usize| (((p[k] - c[k] + radius) / cell) as usize).min(7);
        i(1) * 8 + i(0)
    };
    let mut top = [f32::MIN; 64];
    for p in cloud {
        top[at(p)] = top[at(p)].max(p[2]);
    }
    let seen = cloud
        .iter()
        .copied()
        .filter(|p| p[2] >= top[at(p)] - cell)
        .collect();
    (seen, [c[0], c[1], c[2] + 3.0 * radius])
}

/// The model's template's near side from +z, as a sensor there would see
/// it, and where that sensor stands ([`near_side`]).
fn shipped_view(model: &Int8Model<'_>) -> (Vec<[f32; 3]>, [f32; 3]) {
    let template: Vec<[f32; 3]> = (0..model.template().len())
        .map(|i| model.template().user_point(i, model.frame()))
        .collect();
    near_side(&template)
}

#[test]
fn the_view_check_through_the_c_api_matches_the_rust_api() {
    let blob = shipped_blob();
    let handle = loaded(&blob);
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let (view, eye) = shipped_view(&rust);
    let mut scratch = vec![0i8; rust.scratch_len(1)];
    let r = rust
        .register(&view, &Options::default(), &mut scratch)
        .unwrap();
    // The pose as C gets it from `pcrnet_register`.
    let mut registered = sentinel();
    let status = unsafe {
        pcrnet_register(
            &*handle,
            view.as_ptr() as *const f32,
            view.len(),
            &options_default(),
            scratch.as_mut_ptr(),
            scratch.len(),
            &mut registered,
        )
    };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    let pose = {
        let (q, t) = (registered.rotation, registered.translation);
        [q[0], q[1], q[2], q[3], t[0], t[1], t[2]]
    };
    assert_eq!(pose[..4], r.pose.rotation);
    let mut buffer = vec![0f32; PCRNET_VIEW_BUFFER_LEN];
    let want = rust.check_view(&view, eye, &r.pose, &mut buffer).unwrap();
    let (status, got) = check(&handle, &view, &eye, pose.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(
        [got.supported, got.violations, got.occluded, got.unobserved],
        [
            want.supported,
            want.violations,
            want.occluded,
            want.unobserved
        ]
    );
    assert!(got.passed && want.passed, "{got:?}");
    // A third of the view, at the same pose: the rest of the near side
    // would be where the sensor saw nothing.
    let third: Vec<[f32; 3]> = view.iter().copied().filter(|p| p[0] > 0.1).collect();
    assert!(
        third.len() < view.len() / 2,
        "{} of {}",
        third.len(),
        view.len()
    );
    let (status, got) = check(&handle, &third, &eye, pose.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert!(!got.passed && got.violations > 0, "{got:?}");

    // Nothing written on a bad call.
    let untouched = |c: &PcrnetViewCheck| c.supported == u32::MAX;
    let (status, got) = check(&handle, &view, &eye, std::ptr::null(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NULL_POINTER);
    assert!(untouched(&got));
    let nan = [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let (status, got) = check(&handle, &view, &eye, nan.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_POSE);
    assert!(untouched(&got));
    // Not a unit quaternion.
    let stretched = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let (status, got) = check(&handle, &view, &eye, stretched.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_POSE);
    assert!(untouched(&got));
    // Far away: another frame's coordinates.
    let far = [eye[0] + 1e6, eye[1], eye[2]];
    let (status, got) = check(&handle, &view, &far, pose.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_OPTION);
    assert!(untouched(&got));
    let inside = view[0];
    let (status, got) = check(&handle, &view, &inside, pose.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_OPTION);
    assert!(untouched(&got));
    let (status, _) = check(&handle, &view, &eye, pose.as_ptr(), &mut buffer[..63]);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_OPTION);
    let (status, _) = check(&handle, &[], &eye, pose.as_ptr(), &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_EMPTY_CLOUD);
}

#[test]
fn the_viewed_registration_through_the_c_api_matches_the_rust_api() {
    let blob = shipped_blob();
    let handle = loaded(&blob);
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let (view, eye) = shipped_view(&rust);
    let mut scratch = vec![0i8; rust.scratch_len(1)];
    let mut buffer = vec![0f32; PCRNET_VIEW_BUFFER_LEN];
    let want = rust
        .register_view(&view, eye, &Options::default(), &mut scratch, &mut buffer)
        .unwrap();
    let call = |viewpoint: *const f32,
                out_view: *mut PcrnetViewCheck,
                scratch: &mut [i8],
                buffer: &mut [f32]| {
        let mut out = sentinel();
        let status = unsafe {
            pcrnet_register_view(
                &*handle,
                view.as_ptr() as *const f32,
                view.len(),
                viewpoint,
                &options_default(),
                scratch.as_mut_ptr(),
                scratch.len(),
                buffer.as_mut_ptr(),
                buffer.len(),
                &mut out,
                out_view,
            )
        };
        (status, out)
    };
    let mut seen = PcrnetViewCheck {
        supported: u32::MAX,
        ..PcrnetViewCheck::default()
    };
    let (status, out) = call(eye.as_ptr(), &mut seen, &mut scratch, &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    assert_eq!(out.rotation, want.registration.pose.rotation);
    assert_eq!(out.translation, want.registration.pose.translation);
    assert_eq!(out.reliable, want.reliable);
    assert_eq!(
        want.reliable,
        want.registration.reliable && want.view.passed
    );
    let w = want.view;
    assert_eq!(
        [
            seen.supported,
            seen.violations,
            seen.occluded,
            seen.unobserved
        ],
        [w.supported, w.violations, w.occluded, w.unobserved]
    );
    assert_eq!(seen.passed, w.passed);
    // Nothing written without a viewpoint or with a bad one.
    let mut untouched = PcrnetViewCheck {
        supported: u32::MAX,
        ..PcrnetViewCheck::default()
    };
    let (status, out) = call(std::ptr::null(), &mut untouched, &mut scratch, &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NULL_POINTER);
    assert_eq!(
        (untouched.supported, out.rotation),
        (u32::MAX, sentinel().rotation)
    );
    let inside = view[0];
    let (status, out) = call(inside.as_ptr(), &mut untouched, &mut scratch, &mut buffer);
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_INVALID_OPTION);
    assert_eq!(
        (untouched.supported, out.rotation),
        (u32::MAX, sentinel().rotation)
    );
    let (status, _) = call(
        eye.as_ptr(),
        std::ptr::null_mut(),
        &mut scratch,
        &mut buffer,
    );
    assert_eq!(status, PcrnetStatus::PCRNET_ERROR_NULL_POINTER);
}

#[test]
fn the_viewed_tracking_step_through_the_c_api_matches_the_rust_api() {
    let blob = shipped_blob();
    let handle = loaded(&blob);
    let rust = Int8Model::from_bytes(&blob).unwrap();
    let (view, eye) = shipped_view(&rust);
    let mut scratch = vec![0i8; rust.scratch_len(1)];
    let mut buffer = vec![0f32; PCRNET_VIEW_BUFFER_LEN];
    let options = Options::default();
    let found = rust
        .register_view(&view, eye, &options, &mut scratch, &mut buffer)
        .unwrap()
        .registration
        .pose;
    // From the found pose (kept) and from a half turn away (falls back).
    let away = pcrnet_core::Pose {
        rotation: [0.0, 0.0, 1.0, 0.0],
        translation: [0.0; 3],
    };
    for (previous, code) in [
        (found, PCRNET_TRACK_KEPT),
        (found.then(&away), PCRNET_TRACK_RECOVERED),
    ] {
        let want = rust
            .track_view(&view, &previous, eye, &options, &mut scratch, &mut buffer)
            .unwrap();
        let pose: Vec<f32> = previous
            .rotation
            .iter()
            .chain(&previous.translation)
            .copied()
            .collect();
        let (mut out, mut outcome) = (sentinel(), u32::MAX);
        let status = unsafe {
            pcrnet_track_view(
                &*handle,
                view.as_ptr() as *const f32,
                view.len(),
                pose.as_ptr(),
                eye.as_ptr(),
                &options_default(),
                scratch.as_mut_ptr(),
                scratch.len(),
                buffer.as_mut_ptr(),
                buffer.len(),
                &mut out,
                &mut outcome,
            )
        };
        assert_eq!(status, PcrnetStatus::PCRNET_OK);
        assert_eq!(outcome, code);
        assert_eq!(out.rotation, want.registration.pose.rotation);
        assert_eq!(out.translation, want.registration.pose.translation);
        assert_eq!(out.reliable, want.registration.reliable);
        // A missing or refused viewpoint: a status, nothing written.
        for viewpoint in [std::ptr::null(), view[0].as_ptr()] {
            let (mut out, mut outcome) = (sentinel(), u32::MAX);
            let status = unsafe {
                pcrnet_track_view(
                    &*handle,
                    view.as_ptr() as *const f32,
                    view.len(),
                    pose.as_ptr(),
                    viewpoint,
                    &options_default(),
                    scratch.as_mut_ptr(),
                    scratch.len(),
                    buffer.as_mut_ptr(),
                    buffer.len(),
                    &mut out,
                    &mut outcome,
                )
            };
            assert_ne!(status, PcrnetStatus::PCRNET_OK);
            assert_eq!((out.rotation, outcome), (sentinel().rotation, u32::MAX));
        }
    }
}
