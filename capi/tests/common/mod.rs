//! What the C API tests share: the shipped model and source, a loaded
//! handle, the default options and a result filled with a pattern.
#![allow(unsafe_code)]

use std::mem::MaybeUninit;
use std::path::PathBuf;

use pcrnet::*;

/// The repository's `models/` folder.
pub fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models")
}

pub fn shipped_blob() -> Vec<u8> {
    std::fs::read(models().join("embedded-default-int8.pcrn")).expect("shipped int8 model")
}

#[allow(
    dead_code,
    reason = "each test binary compiles this module; locate.rs renders its frames instead"
)]
pub fn shipped_source() -> Vec<[f32; 3]> {
    let text = std::fs::read_to_string(models().join("embedded-default-source.xyz"))
        .expect("shipped source");
    text.lines()
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// A handle in a box (the C caller's static storage), loaded from `blob`.
pub fn loaded(blob: &[u8]) -> Box<PcrnetModel> {
    let mut model: Box<MaybeUninit<PcrnetModel>> = Box::new(MaybeUninit::zeroed());
    let status = unsafe { pcrnet_model_load(blob.as_ptr(), blob.len(), model.as_mut_ptr()) };
    assert_eq!(status, PcrnetStatus::PCRNET_OK);
    unsafe { model.assume_init() }
}

pub fn options_default() -> PcrnetOptions {
    let mut o = MaybeUninit::uninit();
    unsafe {
        pcrnet_options_default(o.as_mut_ptr());
        o.assume_init()
    }
}

/// A registration filled with a pattern, to see whether a call wrote it.
pub fn sentinel() -> PcrnetRegistration {
    PcrnetRegistration {
        rotation: [7.0; 4],
        translation: [7.0; 3],
        residual: 7.0,
        relative_residual: 7.0,
        plane_residual: 7.0,
        relative_plane_residual: 7.0,
        fitness: 7.0,
        inlier_rmse: 7.0,
        hypothesis: 7,
        passes: 7,
        lk_iterations: 7,
        icp_iterations: 7,
        saturated: 7,
        out_of_range: 7,
        degenerate: 7,
        free_axis: [7.0; 3],
        free_axis_point: [7.0; 3],
        free_axis_stiffness: 7.0,
        turn_rotation: [7.0; 4],
        turn_translation: [7.0; 3],
        turn_degrees: 7.0,
        turn_relative_plane_residual: 7.0,
        reliable: true,
        has_free_axis: true,
        has_turn: true,
    }
}
