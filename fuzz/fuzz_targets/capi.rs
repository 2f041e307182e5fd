//! The C API as a C caller drives it: arbitrary blob bytes through
//! `pcrnet_model_load`, then arbitrary options and clouds through
//! `pcrnet_register` and `pcrnet_network_pose` on the shipped model. Every
//! call returns a status; on `PCRNET_OK` every output is finite.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcrnet::{
    PcrnetModel, PcrnetOptions, PcrnetRegistration, PcrnetStatus, pcrnet_model_load,
    pcrnet_model_scratch_len, pcrnet_network_pose, pcrnet_options_default, pcrnet_register,
    pcrnet_status_message,
};

fuzz_target!(|data: &[u8]| {
    let Some((head, rest)) = data.split_first_chunk::<20>() else {
        return;
    };
    let blob_len = u16::from_le_bytes([head[0], head[1]]) as usize;
    let (blob, points) = rest.split_at(blob_len.min(rest.len()));
    let mut model = Box::new(PcrnetModel::new());
    // SAFETY: every pointer is to live memory of the stated length.
    unsafe {
        let status = pcrnet_model_load(blob.as_ptr(), blob.len(), &mut *model);
        assert!(!pcrnet_status_message(status as i32).is_null());
        let shipped = pcrnet_fuzz::SHIPPED;
        assert_eq!(
            pcrnet_model_load(shipped.as_ptr(), shipped.len(), &mut *model),
            PcrnetStatus::PCRNET_OK
        );
        let mut options = std::mem::MaybeUninit::<PcrnetOptions>::uninit();
        pcrnet_options_default(options.as_mut_ptr());
        let mut options = options.assume_init();
        let f = |i: usize| f32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
        options.passes = (head[2] % 3) as u32;
        options.hypotheses = head[3] as u32;
        options.icp_iterations = (head[4] % 6) as u32;
        options.metric = head[5] as u32 % 3;
        options.tolerance = f(6);
        options.icp_distance = f(10);
        options.max_points = u16::from_le_bytes([head[14], head[15]]) as u32;
        let tile = 1 + (head[16] % 8) as usize;
        let scratch_len = pcrnet_model_scratch_len(&*model, tile);
        // Sometimes a scratch too small, by up to 255 bytes.
        let scratch_len = scratch_len.saturating_sub(head[17] as usize % 4 * 85);
        let mut scratch = vec![0i8; scratch_len];
        let cloud = pcrnet_fuzz::cloud_from(points, 300);
        let mut out = std::mem::MaybeUninit::<PcrnetRegistration>::uninit();
        let status = pcrnet_register(
            &*model,
            cloud.as_ptr() as *const f32,
            cloud.len(),
            &options,
            scratch.as_mut_ptr(),
            scratch.len(),
            out.as_mut_ptr(),
        );
        if status == PcrnetStatus::PCRNET_OK {
            let r = out.assume_init();
            let all = r.rotation.iter().chain(&r.translation);
            assert!(all.chain(&[r.residual, r.fitness]).all(|v| v.is_finite()));
        }
        let mut pose = [0f32; 7];
        let mut passes = 0u32;
        let status = pcrnet_network_pose(
            &*model,
            cloud.as_ptr() as *const f32,
            cloud.len(),
            (head[18] % 4) as u32,
            f(6),
            scratch.as_mut_ptr(),
            scratch.len(),
            pose.as_mut_ptr(),
            &mut passes,
        );
        if status == PcrnetStatus::PCRNET_OK {
            assert!(pose.iter().all(|v| v.is_finite()));
        }
    }
});
