//! Templates built from generated clouds, shared by the tests that refine
//! against them (refine, ambiguity).

use pcrnet_core::template::{self, Template};

/// The int16 step of the generated templates (model units).
const STEP: f32 = 1.0 / 16384.0;

/// Unit normals by PCA of the 10 nearest points (brute force), times 127.
pub fn normals(cloud: &[[f32; 3]]) -> Vec<[i8; 3]> {
    cloud
        .iter()
        .map(|p| {
            let mut near: Vec<(f32, [f32; 3])> = cloud
                .iter()
                .map(|q| ((0..3).map(|k| (p[k] - q[k]).powi(2)).sum(), *q))
                .collect();
            near.sort_by(|a, b| a.0.total_cmp(&b.0));
            let near: Vec<[f32; 3]> = near[..10].iter().map(|x| x.1).collect();
            let c: [f32; 3] =
                std::array::from_fn(|k| near.iter().map(|q| q[k]).sum::<f32>() / 10.0);
            let mut m = [[0f32; 3]; 3];
            for q in &near {
                for i in 0..3 {
                    for j in 0..3 {
                        m[i][j] += (q[i] - c[i]) * (q[j] - c[j]);
                    }
                }
            }
            let (_, v) = pcrnet_core::eigen::symmetric(m);
            v[2].map(|x| (127.0 * x).round() as i8)
        })
        .collect()
}

pub fn template_of(cloud: &[[f32; 3]], turns: &[[f32; 4]]) -> Template<'static> {
    let q: Vec<[i16; 3]> = cloud
        .iter()
        .map(|p| p.map(|x| (x / STEP).round() as i16))
        .collect();
    let (np, nn, nc) = template::build_len(q.len(), 6);
    // Leaked for a 'static view, in tests only.
    let out = template::BuildOut {
        points: Box::leak(vec![0u8; np].into_boxed_slice()),
        normals: Box::leak(vec![0u8; nn].into_boxed_slice()),
        cells: Box::leak(vec![0u8; nc].into_boxed_slice()),
    };
    let cloud = template::build(&q, &normals(cloud), STEP, 6, turns, out).unwrap();
    Template::new(cloud, None).unwrap()
}
