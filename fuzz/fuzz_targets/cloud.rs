//! Arbitrary clouds (any f32 bit patterns, 0 to 300 points) and options
//! through the shipped int8 model: a typed error or a finite result; and
//! the same cloud's rest seen from its first point (`register_view`,
//! `check_view`): a typed error or counts of every template point.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pcrnet_core::Int8Model;

fuzz_target!(|data: &[u8]| {
    let Some((options, points)) = data.split_first_chunk::<16>() else {
        return;
    };
    let Ok(model) = Int8Model::from_bytes(pcrnet_fuzz::SHIPPED) else {
        panic!("the shipped model loads");
    };
    let cloud = pcrnet_fuzz::cloud_from(points, 300);
    let mut scratch = vec![0i8; model.scratch_len(8)];
    let options = pcrnet_fuzz::options_from(options);
    if let Ok(r) = model.register(&cloud, &options, &mut scratch) {
        pcrnet_fuzz::check(&r);
    }
    let Some((viewpoint, seen)) = cloud.split_first() else {
        return;
    };
    let mut view = vec![0f32; pcrnet_core::scene::view::buffer_len(16)];
    let counted = |v: &pcrnet_core::scene::Verification| {
        let total = v.supported + v.violations + v.occluded + v.unobserved + v.outside;
        assert_eq!(total as usize, model.template().len(), "{v:?}");
    };
    if let Ok(v) = model.register_view(seen, *viewpoint, &options, &mut scratch, &mut view) {
        pcrnet_fuzz::check(&v.registration);
        counted(&v.view);
        assert_eq!(v.reliable, v.registration.reliable && v.view.passed);
    }
    if let Ok(v) = model.check_view(seen, *viewpoint, &pcrnet_core::Pose::IDENTITY, &mut view) {
        counted(&v);
    }
});
