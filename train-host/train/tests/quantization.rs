//! int8 against f32 on random models and generated clouds, within stated tolerances.

use pcrnet_core::{Arch, F32Model, Int8Model, MAX_TILE};
use pcrnet_train::shapes::{Shape, random_transform, sample};
use pcrnet_train::template::Reference;
use pcrnet_train::{CalibrationRule, F32Params, TrainedFor, quantize};

/// Worst and mean errors.
#[derive(Default)]
struct Errors {
    feature: f64,
    head: f64,
    rot_deg: f64,
    trans: f64,
    mean_feature: f64,
    mean_head: f64,
    mean_rot_deg: f64,
}

fn rel(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (num / den.max(1e-30)).sqrt()
}

fn angle_deg(q1: [f32; 4], q2: [f32; 4]) -> f64 {
    let d: f64 = q1
        .iter()
        .zip(q2)
        .map(|(a, b)| (*a as f64) * (b as f64))
        .sum();
    2.0 * d.abs().min(1.0).acos().to_degrees()
}

/// Worst-case errors of int8 against f32 over test clouds. `coarsen`
/// rounds the input to a grid of that step first (simulating int8 input).
fn measure(enc: &[u16], head: &[u16], seed: u64, coarsen: Option<f32>) -> Errors {
    let mut params = F32Params::init(Arch::new(enc, head).unwrap(), seed);
    // A trained head is biased towards the identity; give the random one that too,
    // so the pose is well conditioned.
    params.layers.last_mut().unwrap().1[0] = 2.0;
    let template = sample(Shape::Ell, 256, seed);
    let calib: Vec<Vec<[f32; 3]>> = (0..16)
        .map(|i| random_transform(&template, 45.0, 1.0, 1000 + i))
        .collect();
    let reference = Reference::new(&template, 256).unwrap();
    let blob = quantize(
        &params,
        &reference,
        &calib,
        CalibrationRule::default(),
        TrainedFor::pcrnet(false),
    )
    .unwrap();
    let q = Int8Model::from_bytes(&blob).unwrap();
    let fblob = params
        .to_f32_blob(&reference, TrainedFor::pcrnet(false))
        .unwrap();
    let f = F32Model::from_bytes(&fblob).unwrap();
    let mut qs = vec![0i8; q.scratch_len(MAX_TILE)];
    let mut fs = vec![0f32; f.scratch_len()];
    let mut e = Errors::default();
    for i in 0..64 {
        let src = random_transform(&template, 45.0, 1.0, 5000 + i);
        // The int8 path sees the (possibly coarsened) cloud, f32 the exact one.
        let mut qsrc = src.clone();
        if let Some(step) = coarsen {
            for p in &mut qsrc {
                for v in p.iter_mut() {
                    *v = (*v / step).round() * step;
                }
            }
        }
        let qi = q.infer(&qsrc, &mut qs).unwrap();
        let mut deq = vec![0f32; qi.feature.len()];
        q.dequantize_feature(qi.feature, &mut deq);
        let qhead = q.head_to_real(&qi.head);
        // Both poses from `network_pose`: on the sample a registration
        // encodes, over as many points as the template's stored feature.
        let (qpose, _) = q.network_pose(&qsrc, 1, 0.0, &mut qs).unwrap();
        // The template's frame is (nearly) the identity: compare in it.
        let ff = f.network().encode(&src, &mut fs).unwrap().to_vec();
        let fhead = f.network().infer(&src, &mut fs).unwrap();
        let (fpose, _) = f.network_pose(&src, 1, 0.0, &mut fs).unwrap();
        let (fe, he, re) = (
            rel(&deq, &ff),
            rel(&qhead, &fhead),
            angle_deg(qpose.rotation, fpose.rotation),
        );
        e.feature = e.feature.max(fe);
        e.head = e.head.max(he);
        e.rot_deg = e.rot_deg.max(re);
        e.mean_feature += fe / 64.0;
        e.mean_head += he / 64.0;
        e.mean_rot_deg += re / 64.0;
        e.trans = e.trans.max(rel(&qpose.translation, &fpose.translation));
    }
    e
}

#[test]
fn int8_tracks_f32_within_tolerance() {
    // Tolerances, worst case over 64 clouds and two random (untrained)
    // architectures: relative L2 error of the global feature <= 3%, of the
    // raw head output <= 6% (both on every point), rotation difference <= 6
    // degrees, relative translation difference <= 8% (the pose on the
    // network's 128-point sample, as a registration takes it: measured 3.2
    // / 5.1 degrees and 4.8% / 7.0%; on 256 points these bounds were 5
    // degrees and 6%). (A random head amplifies feature errors more than a
    // trained one; trained-model figures are in the README.)
    for (enc, head, seed) in [
        (&[32u16, 64, 128, 256][..], &[256u16, 128, 64][..], 1u64),
        (&[64, 64, 64, 128, 1024][..], &[1024, 512, 256][..], 2),
    ] {
        let e = measure(enc, head, seed, None);
        println!(
            "{enc:?}/{head:?}: feature {:.4}, head {:.4}, rotation {:.3} deg, relative translation {:.4}",
            e.feature, e.head, e.rot_deg, e.trans
        );
        assert!(e.feature <= 0.03, "feature error {}", e.feature);
        assert!(e.head <= 0.06, "head error {}", e.head);
        assert!(e.rot_deg <= 6.0, "rotation error {}", e.rot_deg);
        assert!(e.trans <= 0.08, "translation error {}", e.trans);
    }
}

#[test]
fn int16_input_beats_int8_input() {
    // int8 input over the same +-(2 x max coordinate) range has step range/127.
    let enc = [32u16, 64, 128, 256];
    let head = [256u16, 128, 64];
    let int16 = measure(&enc, &head, 3, None);
    let step = 2.0 * 2.2 / 127.0;
    let int8 = measure(&enc, &head, 3, Some(step));
    println!(
        "mean over 64 clouds: input int16: feature {:.4} head {:.4} rot {:.3} deg; input int8 grid: feature {:.4} head {:.4} rot {:.3} deg",
        int16.mean_feature,
        int16.mean_head,
        int16.mean_rot_deg,
        int8.mean_feature,
        int8.mean_head,
        int8.mean_rot_deg
    );
    assert!(int16.mean_feature < int8.mean_feature);
    assert!(int16.mean_head < int8.mean_head);
    assert!(int16.mean_rot_deg < int8.mean_rot_deg);
}
