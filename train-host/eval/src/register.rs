//! Registering clouds with a model blob on the host.
//!
//! - [`pipeline`]: the device pipeline, `pcrnet-core`'s
//!   [`register`](pcrnet_core::Int8Model::register) (network, flip
//!   hypotheses, ICP against the template's points, residual), with the
//!   blob's own template or another one bound in its place ([`bind`]).
//!   With an int8 blob and no other template, every value is bit-identical
//!   to what a device computes.
//! - [`network`]: the network alone (PCRNet / i-PCRNet), as in the paper.
//! - [`register_pointnetlk`]: PointNetLK on an f32 blob's encoder.
//!
//! All take and return user units: the frame is the blob's (or the bound
//! template's), `p_template = R p_source + t`.

use pcrnet_core::pose;
use pcrnet_core::viewed::Viewed;
use pcrnet_core::{F32Model, Int8Model, Options, Pose, Registration};

use crate::pointnetlk::{LkResult, PointNetLk};
use pcrnet_train::net::F32Params;
use pcrnet_train::template::{DEFAULT_TEMPLATE_POINTS, TemplateError, bind};

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

/// A template cloud (user units) to bind in place of a blob's own, and how
/// many of its points the bound blob stores for checking and refining poses
/// (see [`bind`]).
#[derive(Debug, Clone, Copy)]
pub struct Bound<'a> {
    /// The template cloud.
    pub cloud: &'a [[f32; 3]],
    /// Points stored (farthest-point subsampled; all of them when the
    /// cloud has fewer).
    pub stored: usize,
}

impl<'a> Bound<'a> {
    /// `cloud` with the default [`DEFAULT_TEMPLATE_POINTS`] stored.
    pub fn new(cloud: &'a [[f32; 3]]) -> Self {
        Bound {
            cloud,
            stored: DEFAULT_TEMPLATE_POINTS,
        }
    }
}

/// The blob to run: `blob` itself, or with `template` bound in place of its
/// own (see [`bind`]).
fn model_for(blob: &[u8], template: Option<Bound<'_>>) -> Result<Vec<u8>, TemplateError> {
    match template {
        Some(t) => bind(blob, t.cloud, t.stored),
        None => Ok(blob.to_vec()),
    }
}

/// `options` with each count left at 0 (passes, LK steps, network points)
/// taken from the blob's `trained` options (`trained_options`: for a blob
/// without a head, PointNetLK, no network pass, its trained LK steps and
/// its larger network sample).
pub fn or_trained(options: &Options, trained: Options) -> Options {
    let pick = |asked: usize, trained: usize| if asked == 0 { trained } else { asked };
    Options {
        passes: pick(options.passes, trained.passes),
        lk_iterations: pick(options.lk_iterations, trained.lk_iterations),
        network_points: pick(options.network_points, trained.network_points),
        ..*options
    }
}

/// The device pipeline on the host: see the module docs. A count of 0 in
/// `options` (passes, LK steps, network points) means the blob's own
/// ([`or_trained`]).
pub fn pipeline(
    blob: &[u8],
    template: Option<Bound<'_>>,
    source: &[[f32; 3]],
    options: &Options,
) -> Result<(Registration, Precision), TemplateError> {
    let blob = model_for(blob, template)?;
    on_either(
        &blob,
        options,
        |m, o, scratch| m.register(source, o, scratch),
        |m, o, scratch| m.register(source, o, scratch),
    )
}

/// Pixels a side of the view [`pipeline_viewed`] renders: 32, enough for
/// sources of up to about 500 points at full resolution.
pub const VIEW_SIDE: usize = 32;

/// [`pipeline`] for a cut single view seen from `viewpoint` (the source's
/// frame): `register_view` of either kind of blob, its starts chosen with
/// the view and its pose checked against it.
pub fn pipeline_viewed(
    blob: &[u8],
    source: &[[f32; 3]],
    viewpoint: [f32; 3],
    options: &Options,
) -> Result<(Viewed, Precision), TemplateError> {
    // One of the two runs: each takes its own buffer.
    let buffer = || vec![0f32; pcrnet_core::scene::view::buffer_len(VIEW_SIDE)];
    on_either(
        blob,
        options,
        |m, o, scratch| m.register_view(source, viewpoint, o, scratch, &mut buffer()),
        |m, o, scratch| m.register_view(source, viewpoint, o, scratch, &mut buffer()),
    )
}

/// Runs `int8` on the blob's model if it is an int8 one, else `f32` on it
/// as an f32 one, each with `options` completed by the blob's trained
/// ones ([`or_trained`]) and the host scratch its kernels want.
fn on_either<T>(
    blob: &[u8],
    options: &Options,
    int8: impl FnOnce(&Int8Model<'_>, &Options, &mut [i8]) -> Result<T, pcrnet_core::Error>,
    f32: impl FnOnce(&F32Model<'_>, &Options, &mut [f32]) -> Result<T, pcrnet_core::Error>,
) -> Result<(T, Precision), TemplateError> {
    match Int8Model::from_bytes(blob) {
        Ok(model) => {
            let mut scratch = vec![0i8; model.host_scratch_len()];
            let options = or_trained(options, model.trained_options());
            Ok((int8(&model, &options, &mut scratch)?, Precision::Int8))
        }
        Err(pcrnet_core::Error::WrongKind { .. }) => {
            let model = F32Model::from_bytes(blob)?;
            let mut scratch = vec![0f32; model.tiled_scratch_len()];
            let options = or_trained(options, model.trained_options());
            Ok((f32(&model, &options, &mut scratch)?, Precision::F32))
        }
        Err(e) => Err(e.into()),
    }
}

/// The network passes a blob of either kind was trained for (1: PCRNet).
pub fn trained_passes(blob: &[u8]) -> Result<usize, pcrnet_core::Error> {
    either_model(blob, |m| m.trained_passes(), |m| m.trained_passes())
}

/// Turns stored with the blob's own template (the device tries at most
/// one more starting pose than this).
pub fn template_turns(blob: &[u8]) -> Result<usize, pcrnet_core::Error> {
    either_model(
        blob,
        |m| m.template().turns().len(),
        |m| m.template().turns().len(),
    )
}

/// `int8` of the blob's model if it is an int8 one, else `f32` of it as an
/// f32 one, or the error loading it gives.
fn either_model<T>(
    blob: &[u8],
    int8: impl FnOnce(&Int8Model<'_>) -> T,
    f32: impl FnOnce(&F32Model<'_>) -> T,
) -> Result<T, pcrnet_core::Error> {
    match Int8Model::from_bytes(blob) {
        Ok(m) => Ok(int8(&m)),
        Err(pcrnet_core::Error::WrongKind { .. }) => Ok(f32(&F32Model::from_bytes(blob)?)),
        Err(e) => Err(e),
    }
}

/// The network's pose alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkPose {
    /// Pose mapping the source onto the template, user units.
    pub pose: Pose,
    /// Which network ran.
    pub precision: Precision,
    /// Network passes run (1 for PCRNet).
    pub passes: usize,
}

/// The network alone, in up to `passes` passes (1: PCRNet; more: i-PCRNet,
/// stopping early once a pass's `||dT - I||_F` is below `tolerance`, the
/// paper's being [`ITERATIVE_TOLERANCE`]).
pub fn network(
    blob: &[u8],
    template: Option<&[[f32; 3]]>,
    source: &[[f32; 3]],
    passes: usize,
    tolerance: f32,
) -> Result<NetworkPose, TemplateError> {
    let blob = model_for(blob, template.map(Bound::new))?;
    let ((pose, passes), precision) = match Int8Model::from_bytes(&blob) {
        Ok(model) => {
            let mut scratch = vec![0i8; model.host_scratch_len()];
            (
                model.network_pose(source, passes, tolerance, &mut scratch)?,
                Precision::Int8,
            )
        }
        Err(pcrnet_core::Error::WrongKind { .. }) => {
            let model = F32Model::from_bytes(&blob)?;
            let mut scratch = vec![0f32; model.tiled_scratch_len()];
            (
                model.network_pose(source, passes, tolerance, &mut scratch)?,
                Precision::F32,
            )
        }
        Err(e) => return Err(e.into()),
    };
    Ok(NetworkPose {
        pose,
        precision,
        passes,
    })
}

/// Registers `source` onto `template` with PointNetLK on the encoder of an
/// **f32** blob (Jacobian by finite differences on the template, up to
/// `iterations` Lucas-Kanade steps), in the template's frame. A blob whose
/// network was trained on centred sources (every shipped and recipe model)
/// has the source centred on its centroid first, as in training and as the
/// PointNetLK reference centres both clouds; the LK poses are composed after
/// that move. The pose and its trajectory are in user units.
pub fn register_pointnetlk(
    blob: &[u8],
    template: Option<&[[f32; 3]]>,
    source: &[[f32; 3]],
    iterations: usize,
) -> Result<LkResult, TemplateError> {
    let blob = model_for(blob, template.map(Bound::new))?;
    let model = F32Model::from_bytes(&blob)?;
    let params = F32Params::from_network(model.network());
    let frame = *model.frame();
    let stored = model.template();
    // The template in the model frame: the blob's stored points.
    let t: Vec<[f32; 3]> = (0..stored.len())
        .map(|i| stored.point(i).map(|v| v as f32 * stored.step()))
        .collect();
    let start = pose::centring(source, model.network().centring(), &frame)?;
    let map = pose::PointMap::new(frame, &start);
    let s: Vec<[f32; 3]> = source.iter().map(|&p| map.apply(p)).collect();
    let lk = PointNetLk::new(&params, &t)?;
    let result = lk.register(&s, iterations, 1e-7)?;
    let to_user = |p: &Pose| frame.pose_to_user(&start.then(p));
    Ok(LkResult {
        pose: to_user(&result.pose),
        trajectory: result.trajectory.iter().map(to_user).collect(),
        ..result
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pcrnet_core::Arch;
    use pcrnet_train::geometry::{euler_to_mat, mat_vec, quat_to_mat, transpose};
    use pcrnet_train::metrics::rotation_error_deg;
    use pcrnet_train::shapes::{Shape, random_transform, sample};
    use pcrnet_train::template::Reference;
    use pcrnet_train::{CalibrationRule, F32Params, TrainedFor, quantize};

    #[test]
    fn int8_and_f32_blobs_register_files_consistently() {
        let params = F32Params::init(Arch::new(&[16, 32], &[32]).unwrap(), 5);
        let template = sample(Shape::Ell, 200, 5);
        let calib: Vec<_> = (0..8)
            .map(|i| random_transform(&template, 45.0, 1.0, i))
            .collect();
        let reference = Reference::new(&template, 128).unwrap();
        let int8 = quantize(
            &params,
            &reference,
            &calib,
            CalibrationRule::default(),
            TrainedFor::pcrnet(true),
        )
        .unwrap();
        let f32_blob = params
            .to_f32_blob(&reference, TrainedFor::pcrnet(true))
            .unwrap();
        // The template in its own (scaled, shifted) coordinates.
        let world: Vec<[f32; 3]> = template
            .iter()
            .map(|p| [p[0] * 20.0 + 5.0, p[1] * 20.0, p[2] * 20.0 - 3.0])
            .collect();
        let source = random_transform(&world, 30.0, 0.0, 9);
        let r8 = network(&int8, Some(&world), &source, 1, ITERATIVE_TOLERANCE).unwrap();
        let rf = network(&f32_blob, Some(&world), &source, 1, ITERATIVE_TOLERANCE).unwrap();
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
            network(&int8, Some(&world), &[], 1, ITERATIVE_TOLERANCE),
            Err(TemplateError::Core(pcrnet_core::Error::EmptyCloud))
        ));
        // The pipeline without refinement is the network's pose, scored.
        let (bare, _) = pipeline(
            &int8,
            Some(Bound::new(&world)),
            &source,
            &Options::network_only(),
        )
        .unwrap();
        assert_eq!(bare.pose, r8.pose);
        assert_eq!((bare.hypothesis, bare.icp_iterations), (0, 0));
    }

    /// An untrained network whose head is biased to the identity (as a
    /// trained head is, near it), quantized for `reference` with
    /// calibration poses of `unit` (the template in the model frame): the
    /// pipeline's pose then comes from the device ICP.
    pub(crate) fn identity_biased(reference: &Reference, unit: &[[f32; 3]]) -> Vec<u8> {
        let mut params = F32Params::init(Arch::new(&[16, 32], &[32]).unwrap(), 7);
        let (w, b) = params.layers.last_mut().unwrap();
        w.iter_mut().for_each(|v| *v *= 1e-3);
        b[0] = 2.0;
        let calib: Vec<_> = (0..8)
            .map(|i| random_transform(unit, 20.0, 0.1, i))
            .collect();
        quantize(
            &params,
            reference,
            &calib,
            CalibrationRule::default(),
            TrainedFor::pcrnet(true),
        )
        .unwrap()
    }

    /// A source sampled apart from the template (no shared point) is
    /// refined closer to its true pose against more stored template points:
    /// what `--template-points` buys.
    #[test]
    fn more_stored_template_points_refine_a_resampled_source_closer() {
        let template = sample(Shape::Ell, 1200, 3);
        let int8 = identity_biased(&Reference::new(&template, 64).unwrap(), &template);
        // Another sampling of the same surface, turned 10 degrees about z;
        // the true pose turns it back.
        let turn = euler_to_mat([0.0, 0.0, 10f32.to_radians()]);
        let source: Vec<[f32; 3]> = sample(Shape::Ell, 600, 11)
            .iter()
            .map(|p| mat_vec(&turn, p))
            .collect();
        let truth = transpose(&turn);
        let options = Options {
            max_points: 600,
            ..Options::default()
        };
        let error = |stored: usize| {
            let bound = Bound {
                cloud: &template,
                stored,
            };
            let (r, _) = pipeline(&int8, Some(bound), &source, &options).unwrap();
            rotation_error_deg(&quat_to_mat(r.pose.rotation), &truth)
        };
        let (sparse, dense) = (error(64), error(1200));
        assert!(dense < sparse, "64 points: {sparse} deg, 1200: {dense} deg");
        assert!(dense < 0.5, "1200 points: {dense} deg");
    }

    #[test]
    fn the_refined_pipeline_recovers_a_known_transform_in_user_units() {
        let unit = sample(Shape::Ell, 400, 3);
        // The template in millimetres, far from the origin.
        let world: Vec<[f32; 3]> = unit
            .iter()
            .map(|p| {
                [
                    p[0] * 120.0 + 2500.0,
                    p[1] * 120.0 - 800.0,
                    p[2] * 120.0 + 40.0,
                ]
            })
            .collect();
        let int8 = identity_biased(&Reference::new(&world, 400).unwrap(), &unit);
        // The source: the template turned 15 degrees about a tilted axis
        // through its centre and moved 9 mm.
        let source: Vec<[f32; 3]> = {
            let (s, c) = 15f32.to_radians().sin_cos();
            world
                .iter()
                .map(|p| {
                    let (x, y, z) = (p[0] - 2500.0, p[1] + 800.0, p[2] - 40.0);
                    [c * x - s * y + 2506.0, s * x + c * y - 797.0, z + 47.0]
                })
                .collect()
        };
        let (r, _) = pipeline(&int8, None, &source, &Options::default()).unwrap();
        let worst = source
            .iter()
            .zip(&world)
            .map(|(s, t)| {
                let p = r.pose.transform_point(*s);
                ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2)).sqrt()
            })
            .fold(0f32, f32::max);
        // 0.1 degree at 120 mm is 0.2 mm.
        assert!(worst < 0.2, "worst {worst} mm, {r:?}");
        assert!(r.reliable && r.fitness == 1.0 && r.residual < 0.05, "{r:?}");
        let (z, _) = (r.pose.rotation[3], r.pose.rotation[0]);
        assert!((2.0 * z.asin().to_degrees() + 15.0).abs() < 0.1, "{r:?}");
    }
}
