//! Registering two clouds from files with a model blob (the `register`
//! command): points -> normalise -> the network (int8 or f32) -> pose in
//! the user's coordinates.

use pcrnet_core::{F32Model, Int8Model, MAX_TILE, Pose};

use crate::eval::pointnetlk::{LkResult, PointNetLk};
use crate::net::F32Params;
use crate::shapes::Normalisation;

/// Which network ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// `pcrnet-core`'s int8 path (bit-identical to the device).
    Int8,
    /// The f32 reference path.
    F32,
}

/// The paper's stop rule of iterative registration: `||dT - I||_F` below
/// this. In practice no pass gets there (int8 or f32), so all passes run;
/// a device may prefer a looser tolerance (see the README).
pub const ITERATIVE_TOLERANCE: f32 = 1e-7;

/// What a registration produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Registration {
    /// Pose mapping the source onto the template, in the input coordinates.
    pub pose: Pose,
    /// Which network ran.
    pub precision: Precision,
    /// Network passes run (1 for PCRNet).
    pub passes: usize,
}

/// Registers `source` onto `template` with a model blob of either kind, in
/// up to `passes` passes (1: PCRNet; more: i-PCRNet, stopping early once a
/// pass's `||dT - I||_F` is below `tolerance`, the paper's being
/// [`ITERATIVE_TOLERANCE`]).
///
/// Both clouds are normalised with the template's normalisation (centroid,
/// scale into the unit box), as in training, so their relative pose is
/// kept; the template's feature is computed by the model's own encoder
/// (replacing the one stored in the blob). The returned pose is in the
/// input coordinates: `p_template = R p_source + t`.
pub fn register(
    blob: &[u8],
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    passes: usize,
    tolerance: f32,
) -> Result<Registration, pcrnet_core::Error> {
    let norm = Normalisation::of(template);
    let (mut t, mut s) = (template.to_vec(), source.to_vec());
    norm.apply(&mut t);
    norm.apply(&mut s);
    let ((pose, passes), precision) = match Int8Model::from_bytes(blob) {
        Ok(model) => (
            register_int8(&model, &t, &s, passes, tolerance)?,
            Precision::Int8,
        ),
        Err(pcrnet_core::Error::WrongKind { .. }) => (
            register_f32(&F32Model::from_bytes(blob)?, &t, &s, passes, tolerance)?,
            Precision::F32,
        ),
        Err(e) => return Err(e),
    };
    Ok(Registration {
        pose: denormalise(&pose, &norm),
        precision,
        passes,
    })
}

/// Registers `source` onto `template` with PointNetLK on the encoder of an
/// **f32** blob (Jacobian by finite differences on the template, up to
/// `iterations` Lucas-Kanade steps), with the same normalisation as
/// [`register`]. The pose and its trajectory are in the input coordinates.
pub fn register_pointnetlk(
    blob: &[u8],
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    iterations: usize,
) -> Result<LkResult, pcrnet_core::Error> {
    let params = F32Params::from_network(&F32Model::from_bytes(blob)?);
    let norm = Normalisation::of(template);
    let (mut t, mut s) = (template.to_vec(), source.to_vec());
    norm.apply(&mut t);
    norm.apply(&mut s);
    let lk = PointNetLk::new(&params, &t, 1e-2)?;
    let result = lk.register(&s, iterations, 1e-7)?;
    Ok(LkResult {
        pose: denormalise(&result.pose, &norm),
        iterations: result.iterations,
        trajectory: result
            .trajectory
            .iter()
            .map(|p| denormalise(p, &norm))
            .collect(),
    })
}

fn register_int8(
    model: &Int8Model<'_>,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    passes: usize,
    tolerance: f32,
) -> Result<(Pose, usize), pcrnet_core::Error> {
    let mut scratch = vec![0i8; model.scratch_len(MAX_TILE)];
    let feature: Vec<u8> = model
        .encode(template, &mut scratch)?
        .iter()
        .map(|&v| v as u8)
        .collect();
    let payload = pcrnet_core::format::Int8Payload {
        template_feature: &feature,
        ..model.payload().clone()
    };
    Int8Model::from_payload(payload)?.register_iterative(source, passes, tolerance, &mut scratch)
}

fn register_f32(
    model: &F32Model<'_>,
    template: &[[f32; 3]],
    source: &[[f32; 3]],
    passes: usize,
    tolerance: f32,
) -> Result<(Pose, usize), pcrnet_core::Error> {
    let params = F32Params::from_network(model);
    let feature = params.encode(template)?;
    let net = params
        .network(&feature)?
        .with_centring(model.centres_source());
    let mut scratch = vec![0f32; net.scratch_len()];
    net.register_iterative(source, passes, tolerance, &mut scratch)
}

/// Turns a pose between normalised clouds (`q = s (p - c)`) into one
/// between the original clouds: `R` is kept, `t = c + t'/s - R c`.
fn denormalise(pose: &Pose, norm: &Normalisation) -> Pose {
    // transform_point(c) = R c + t', so R c = rc - t'.
    let rc = pose.transform_point(norm.centre);
    let t = pose.translation;
    let translation = std::array::from_fn(|k| norm.centre[k] + t[k] / norm.scale - (rc[k] - t[k]));
    Pose {
        translation,
        ..*pose
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Shape, random_transform, sample};
    use crate::{CalibrationRule, F32Params, quantize};
    use pcrnet_core::Arch;

    #[test]
    fn denormalised_pose_commutes_with_the_normalisation() {
        let norm = Normalisation {
            centre: [3.0, -2.0, 10.0],
            scale: 0.05,
        };
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let pose = Pose::from_head_output(&[h, 0.0, h, 0.0, 0.3, -0.2, 0.1]).unwrap();
        let original = denormalise(&pose, &norm);
        for p in [[1.0f32, 2.0, 3.0], [-4.0, 0.5, 12.0]] {
            let mut lhs = [original.transform_point(p)];
            norm.apply(&mut lhs);
            let mut q = [p];
            norm.apply(&mut q);
            let rhs = pose.transform_point(q[0]);
            for k in 0..3 {
                assert!((lhs[0][k] - rhs[k]).abs() < 1e-5, "{lhs:?} vs {rhs:?}");
            }
        }
    }

    #[test]
    fn int8_and_f32_blobs_register_files_consistently() {
        let params = F32Params::init(Arch::new(&[16, 32], &[32]).unwrap(), 5);
        let template = sample(Shape::Ell, 200, 5);
        let calib: Vec<_> = (0..8)
            .map(|i| random_transform(&template, 45.0, 1.0, i))
            .collect();
        let int8 = quantize(&params, &template, &calib, CalibrationRule::default(), true).unwrap();
        let f32_blob = params.to_f32_blob(&template, true).unwrap();
        // The template in its own (scaled, shifted) coordinates.
        let world: Vec<[f32; 3]> = template
            .iter()
            .map(|p| [p[0] * 20.0 + 5.0, p[1] * 20.0, p[2] * 20.0 - 3.0])
            .collect();
        let source = random_transform(&world, 30.0, 0.0, 9);
        let r8 = register(&int8, &world, &source, 1, ITERATIVE_TOLERANCE).unwrap();
        let rf = register(&f32_blob, &world, &source, 1, ITERATIVE_TOLERANCE).unwrap();
        assert_eq!(
            (r8.precision, rf.precision),
            (Precision::Int8, Precision::F32)
        );
        assert_eq!((r8.passes, rf.passes), (1, 1));
        let (p8, pf) = (r8.pose, rf.pose);
        // Same network, same clouds: the two paths agree to quantization error.
        let dot: f32 = p8
            .rotation
            .iter()
            .zip(pf.rotation)
            .map(|(a, b)| a * b)
            .sum();
        assert!(2.0 * dot.abs().min(1.0).acos().to_degrees() < 10.0);
        assert!(matches!(
            register(&int8, &world, &[], 1, ITERATIVE_TOLERANCE),
            Err(pcrnet_core::Error::EmptyCloud)
        ));
    }
}
