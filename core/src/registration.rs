//! The main job as one call: points -> network -> pose -> check and refine,
//! returning a [`Registration`] that says how far to trust the pose.
//!
//! ```text
//! source (user units)
//!   -> frame (blob)         p_model = scale (p - centre)
//!   -> network passes       PCRNet: 1; i-PCRNet: up to `passes`, composed
//!   -> LK steps             PointNetLK: up to `lk_iterations`, composed (blobs with a solver)
//!   -> hypotheses           the network's pose, then it followed by each template turn
//!   -> ICP                  point-to-point against the template's points, each hypothesis
//!   -> residuals            lowest point-to-point residual wins; the
//!                           plane residual judges reliability; fitness,
//!                           RMSE, degeneracy, saturation
//!   -> pose (user units)    p_template = R p_source + t
//! ```
//!
//! The same code runs on the device and on the host ([`crate::Int8Model::register`],
//! [`crate::F32Model::register`]); with the int8 network, every value is
//! bit-identical between them.

use crate::ambiguity::{self, Ambiguity};
use crate::error::{Error, Result};
use crate::format::Frame;
use crate::pose::{self, Centring, PointMap, Pose};
use crate::refine::{self, Degeneracy, Guide, IcpSettings, Metric, Resolved, Subset, Unguided};
use crate::scene::visible::Placing;
use crate::template::Template;

/// The default [`Options::network_points`], and [`network_points`] for a
/// blob with a head (PCRNet, i-PCRNet): at most this many points of a
/// cloud are max-pooled into a feature. Exported template features are
/// pooled over the same sample of the template's points
/// ([`Options::network_sample`]), and [`crate::Int8Model::feature_distance`]
/// samples the source so, so that both sides of a comparison pool over as
/// many points, as in training.
///
/// Measured on the `trust` experiment, 1,000 pairs a set, device pipeline
/// K = 10 (poses more than 5 degrees off at 128 / 256 points): ModelNet10
/// 1 / 1, resampled 15 / 15, airplanes 12 / 9, held-out classes 22 / 25;
/// AUC 0.9974 / 0.9973, 0.9899 / 0.9903, 0.9905 / 0.9931, 0.9780 /
/// 0.9756. The network's share of the default registration halves.
pub const NETWORK_POINTS: usize = 128;

/// [`network_points`] for a blob without a head (PointNetLK): the LK step
/// reads small differences of the feature, which a smaller sample blurs
/// (unseen ModelNet10 classes, device int8 LK alone: 8.7 degrees mean on
/// 128 points against 5.6 on 256, docs/kernels.md).
pub const LK_NETWORK_POINTS: usize = 256;

/// How many points a blob's network passes and LK steps encode, and its
/// template feature was pooled over at export: [`NETWORK_POINTS`] with a
/// head, [`LK_NETWORK_POINTS`] without (what [`Options::trained`] sets).
pub const fn network_points(head: bool) -> usize {
    if head {
        NETWORK_POINTS
    } else {
        LK_NETWORK_POINTS
    }
}

/// How to register. Distances are in **model units**: the template spans
/// `[-0.5, 0.5]` along its longest axis, so 0.05 is 5% of its size, and
/// the settings carry over between objects of any size or unit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Options {
    /// Network passes (1: PCRNet; more: i-PCRNet, composing the estimates;
    /// 0 for a PointNetLK blob, which has no head: [`Error::NoHead`] otherwise).
    pub passes: usize,
    /// PointNetLK steps after the network's passes ([`crate::lk`]): each an
    /// encoder pass and the Lucas-Kanade update, composed (0: none). Needs a
    /// blob with an LK solver ([`Error::NoLkSolver`] otherwise): blobs of
    /// models trained as PointNetLK have one, `pcrnet export --lk` adds one
    /// to any model. Refine by ICP: 0 (the default); by LK: `icp_iterations`
    /// 0 and one hypothesis; LK then ICP: both.
    pub lk_iterations: usize,
    /// Most source points each network pass and LK step encodes: every
    /// k-th point from the first, as for `max_points` (at least 1; at 128,
    /// a cloud of 129 to 256 points gives `ceil(n / 2)`). The encoder's cost
    /// is linear in its points: 128 of 512 is a quarter of the network's
    /// instructions with the `trust` accuracy of 256 (docs/kernels.md). Centring uses
    /// every point; scoring and ICP their own `max_points`. The template's
    /// stored feature is pooled over [`network_points`] of its points at
    /// export ([`NETWORK_POINTS`] with a head, [`LK_NETWORK_POINTS`]
    /// without) whatever this says (blobs exported before that, such as
    /// the shipped ones, over all of them): other values pool the two
    /// inputs of the head over different counts. [`Options::trained`]
    /// (`trained_options`) sets the blob's own.
    pub network_points: usize,
    /// Network passes and LK steps stop once a step's `||dT - I||_F` is
    /// below this (0: never).
    pub tolerance: f32,
    /// Starting poses tried by flip resolution: 1 (the network's pose only)
    /// up to 1 + the turns stored in the blob (clamped).
    pub hypotheses: usize,
    /// ICP iterations every hypothesis gets before the network's own and
    /// the best turned one go on to `icp_iterations`; a turned one far
    /// above the best after [`crate::refine::SCREEN_CHECK`] of them is
    /// dropped (see [`crate::refine::resolve`]).
    pub screen_iterations: usize,
    /// Most ICP iterations in all for a finalist (0: no refinement).
    pub icp_iterations: usize,
    /// What ICP minimises: point-to-plane (default) or point-to-point.
    pub metric: Metric,
    /// ICP stops once an update's `||dT - I||_F` is below this.
    pub icp_tolerance: f32,
    /// ICP leaves out pairs farther apart than this (model units).
    pub icp_distance: f32,
    /// The residual counts a point at most this far from the template
    /// (model units), and the fitness counts points within it.
    pub inlier_distance: f32,
    /// Most source points scored and refined (every k-th point is used).
    pub max_points: usize,
    /// A pose is [`Registration::reliable`] when its relative plane
    /// residual ([`Registration::relative_plane_residual`]) is at most this.
    pub max_residual: f32,
}

/// What [`max_residual_for`] allows above a template's residual floor for
/// the sensor's noise, a share of the template's size: the mean distance
/// of Gaussian noise of sigma 0.01 per coordinate from a plane,
/// `0.01 sqrt(2 / pi)`, the noise of the `trust` and `tracking`
/// experiments. (The default threshold, 0.015, is this plus a floor of
/// 0.007.)
pub const NOISE_ALLOWANCE: f32 = 0.008;

/// The verdict threshold ([`Options::max_residual`]) for a template whose
/// residual floor is `floor` ([`crate::format::Trailer::residual_floor`]):
/// the floor plus [`NOISE_ALLOWANCE`], never below `default`. A right pose
/// scores the noise plus what the template's stored points cannot
/// represent of the object (edges between sparse samples, inner surfaces,
/// normals estimated across a fold); with the default threshold, templates
/// whose floor is near 0.015 have their right poses marked not reliable.
/// Measured on the `tracking` experiment (RESULTS.md, docs/tracking.md):
/// the frames lost fall from 18-20% to 0.8-2.2%, and more reliable frames
/// are off by more than 5 degrees: at 30 frames a second 5-12 degrees (a
/// template that represents its object coarsely also aligns it coarsely),
/// at 10 a box-like dresser tracked 90 degrees turned.
///
/// At most [`MAX_CALIBRATED`]: a floor that high says the template file
/// was noisy or cluttered, not that the object is hard to represent.
pub fn max_residual_for(floor: f32, default: f32) -> f32 {
    let calibrated = (floor + NOISE_ALLOWANCE).min(MAX_CALIBRATED);
    if calibrated > default {
        calibrated
    } else {
        default
    }
}

/// The most [`max_residual_for`] raises the verdict to: 0.0375, two and a
/// half times the default. The highest any template of the `tracking`
/// experiment needed was 0.0364 (a night stand, floor 0.028). Each point's
/// plane offset is capped at the inlier distance (0.05) in the residual,
/// so a threshold near it accepts almost any pose: a template file with
/// 3,000 stray points beside an 8,192-point object measured a floor of
/// 0.034, and a wrong object then passed at 0.042.
pub const MAX_CALIBRATED: f32 = 0.0375;

/// Checks a blob's residual floor: finite and at least 0.
pub(crate) fn checked_floor(floor: Option<f32>) -> Result<Option<f32>> {
    match floor {
        Some(f) if !(f.is_finite() && f >= 0.0) => Err(Error::InconsistentDimensions {
            what: "the template's residual floor must be finite and at least 0",
        }),
        f => Ok(f),
    }
}

impl Default for Options {
    /// The recommended device pipeline (see the README for the measurements
    /// behind each number).
    fn default() -> Self {
        Options {
            passes: 1,
            lk_iterations: 0,
            network_points: NETWORK_POINTS,
            tolerance: 0.0,
            hypotheses: 10,
            screen_iterations: 10,
            icp_iterations: 50,
            metric: Metric::PointToPlane,
            icp_tolerance: 1e-3,
            icp_distance: 0.3,
            inlier_distance: 0.05,
            max_points: 256,
            max_residual: 0.015,
        }
    }
}

impl Options {
    /// [`Options::default`] with the steps a blob was trained for: its
    /// `trained` passes when it has a head (PCRNet 1, i-PCRNet its count),
    /// else (PointNetLK) no network pass and `trained` LK steps; and the
    /// blob's [`network_points`] (256 without a head). What
    /// `Int8Model::trained_options` and `F32Model::trained_options` give.
    ///
    /// With the template's `residual_floor` (a blob of format 6 whose
    /// exporter measured one), the verdict's threshold is calibrated for
    /// the template ([`max_residual_for`]).
    pub fn trained(trained: usize, head: bool, residual_floor: Option<f32>) -> Self {
        let (passes, lk_iterations) = if head { (trained, 0) } else { (0, trained) };
        let defaults = Options::default();
        Options {
            passes,
            lk_iterations,
            network_points: network_points(head),
            max_residual: residual_floor.map_or(defaults.max_residual, |floor| {
                max_residual_for(floor, defaults.max_residual)
            }),
            ..defaults
        }
    }

    /// The network alone (no turns, no ICP), still scored.
    pub fn network_only() -> Self {
        Options {
            hypotheses: 1,
            icp_iterations: 0,
            ..Options::default()
        }
    }

    /// The points of `cloud` each network pass and LK step encodes under
    /// these options: every k-th from the first, at most
    /// [`Self::network_points`]. A template's feature is encoded from the
    /// same sample of its points at the blob's [`network_points`] (the
    /// exporter does so: 128 with a head, 256 for PointNetLK), so that both
    /// max-pools run over as many points, as in training.
    pub fn network_sample<'c>(
        &self,
        cloud: &'c [[f32; 3]],
    ) -> impl Iterator<Item = &'c [f32; 3]> + 'c {
        Sample::new(cloud, self.network_points)
            .iter()
            .map(|(_, p)| p)
    }

    /// The ICP settings these options give.
    pub(crate) fn icp_settings(&self) -> IcpSettings {
        IcpSettings {
            metric: self.metric,
            iterations: self.icp_iterations,
            tolerance: self.icp_tolerance,
            max_distance: self.icp_distance,
        }
    }

    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what| Err(Error::InvalidOption { what });
        if self.passes == 0 && self.lk_iterations == 0 {
            return bad("passes and lk_iterations cannot both be 0");
        }
        if self.hypotheses == 0 {
            return bad("hypotheses must be at least 1");
        }
        if self.max_points == 0 || self.network_points == 0 {
            return bad("max_points and network_points must be at least 1");
        }
        let non_negative = |v: f32| v.is_finite() && v >= 0.0;
        if !non_negative(self.tolerance) || !non_negative(self.icp_tolerance) {
            return bad("tolerances must be finite and >= 0");
        }
        let positive = |v: f32| v.is_finite() && v > 0.0;
        if !positive(self.icp_distance) || !positive(self.inlier_distance) {
            return bad("distances must be finite and > 0");
        }
        if !self.max_residual.is_finite() {
            return bad("max_residual must be finite");
        }
        Ok(())
    }
}

/// What a registration found, and how far to trust it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Registration {
    /// Pose mapping the source onto the template, user units:
    /// `p_template = R p_source + t`.
    pub pose: Pose,
    /// Mean distance from the moved source's points to the template's
    /// nearest point, each capped at the inlier distance: user units.
    pub residual: f32,
    /// The same as a share of the template's size (model units): compare
    /// it across objects. 0 is a perfect fit; the inlier distance is the worst.
    pub relative_residual: f32,
    /// Share of the used source points within the inlier distance (0..=1).
    pub fitness: f32,
    /// RMS distance of those inliers, user units.
    pub inlier_rmse: f32,
    /// Mean distance from the moved source's points to the tangent plane
    /// at their nearest template point (`|n . (p - q)|`), each capped at
    /// the inlier distance: user units. Unlike [`Registration::residual`],
    /// it does not grow with how far apart the source's and the template's
    /// samples lie along the surface, so a right pose scores about the
    /// sensor noise whether or not the source shares points with the template.
    pub plane_residual: f32,
    /// The same as a share of the template's size (model units): what
    /// [`Registration::reliable`] is judged on.
    pub relative_plane_residual: f32,
    /// The starting pose that won: 0 the network's, `k` the network's followed by turn `k - 1`.
    pub hypothesis: usize,
    /// Network passes run.
    pub passes: usize,
    /// PointNetLK steps run after them.
    pub lk_iterations: usize,
    /// ICP iterations run from the winning start.
    pub icp_iterations: usize,
    /// int8 values that reached the top of their range (feature entries and
    /// head activations, summed over passes): clipping that costs accuracy.
    /// Always 0 on the f32 path.
    pub saturated: u32,
    /// Points of the network's sample ([`Options::network_points`]) it
    /// left out because they lie outside the model's input range (the
    /// most over its passes): stray points far from the object. They still count in the residual and the fitness
    /// (capped at the inlier distance). Always 0 on the f32 path.
    pub out_of_range: u32,
    /// The source's shape does not determine a pose.
    pub degenerate: Option<Degeneracy>,
    /// Poses the fit cannot tell apart from this one: a free rotation axis
    /// or a turn to another pose that fits about as well ([`crate::ambiguity`]).
    /// Reported beside the verdict, which it does not change.
    pub ambiguity: Ambiguity,
    /// Not degenerate, and the relative plane residual is at most the
    /// option's `max_residual`.
    pub reliable: bool,
}

/// What a model's step closure runs on the moved source: a network pass
/// (the head's estimate) or a PointNetLK step ([`crate::lk`]). Either
/// returns the step's pose in the model frame, composed onto the pose so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Step {
    /// Encoder and head.
    Network,
    /// Encoder and the Lucas-Kanade update.
    Lk,
}

/// What the pose stage ran and counted, for [`Registration`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Stage {
    /// Network passes run.
    pub passes: usize,
    /// LK steps run.
    pub lk_iterations: usize,
    /// What their encoder passes counted.
    pub counts: PassCounts,
}

/// The source points a network pass or an LK step encodes: every
/// `stride`-th point from the first, at most [`Options::network_points`]
/// of them (the rule of [`Subset`]'s `max_points`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sample<'s> {
    points: &'s [[f32; 3]],
    stride: usize,
}

impl<'s> Sample<'s> {
    /// At most `most` of `points`, evenly strided.
    pub fn new(points: &'s [[f32; 3]], most: usize) -> Self {
        Sample {
            points,
            stride: refine::stride_for(points.len(), most),
        }
    }

    /// Every point.
    pub fn all(points: &'s [[f32; 3]]) -> Self {
        Sample { points, stride: 1 }
    }

    /// The sampled points with their indices in the whole cloud.
    pub fn iter(self) -> impl Iterator<Item = (usize, &'s [f32; 3])> + 's {
        self.points.iter().enumerate().step_by(self.stride.max(1))
    }

    /// How many points [`Self::iter`] yields (the host block kernel's
    /// test of whether a block can fill).
    #[cfg(all(any(target_arch = "x86_64", target_arch = "aarch64"), feature = "std"))]
    pub fn len(&self) -> usize {
        self.points.len().div_ceil(self.stride.max(1))
    }

    /// Whether there is no point to encode.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// What one network pass counted (the int8 path; the f32 path has no range).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct PassCounts {
    /// int8 values at the top of their range.
    pub saturated: u32,
    /// Source points outside the input range, left out of the encoder.
    pub out_of_range: u32,
}

/// Standard deviation (model units) below which a source counts as one
/// point (see [`refine::degeneracy`]).
pub const MIN_EXTENT: f32 = 1e-3;

/// What a registration and a tracking step check and derive first: valid
/// options, a non-empty source, the points refinement and scoring use, and
/// whether their shape determines a pose.
pub(crate) struct Checked<'s> {
    /// The used points ([`Options::max_points`] of them at most).
    pub subset: Subset<'s>,
    /// The degeneracy of those points ([`refine::degeneracy`]).
    pub degenerate: Option<Degeneracy>,
}

/// Checks `options` and `source` (every point finite: the network passes
/// see a sample, scoring and ICP a subset) and derives the [`Checked`]
/// parts.
pub(crate) fn check<'s>(
    frame: &Frame,
    template: &Template<'_>,
    source: &'s [[f32; 3]],
    options: &Options,
) -> Result<Checked<'s>> {
    check_input(source, options)?;
    let subset = Subset::new(source, *frame, options.max_points);
    let degenerate = refine::degeneracy(template, &subset, MIN_EXTENT);
    Ok(Checked { subset, degenerate })
}

/// Runs the pipeline with `pass`, one [`Step`] on the source moved by a
/// [`PointMap`], returning the step's pose (model frame) and its counts.
pub(crate) fn run(
    frame: &Frame,
    centring: Centring,
    template: &Template<'_>,
    source: &[[f32; 3]],
    options: &Options,
    pass: impl FnMut(Sample<'_>, &PointMap, Step) -> Result<(Pose, PassCounts)>,
) -> Result<Registration> {
    let checked = check(frame, template, source, options)?;
    run_checked(
        frame,
        centring,
        template,
        &checked,
        options,
        pass,
        &mut Unguided,
    )
}

/// [`run`] on a source [`check`] has passed (its subset's cloud), the
/// starts resolved with `guide` ([`refine::resolve`]; model frame).
pub(crate) fn run_checked(
    frame: &Frame,
    centring: Centring,
    template: &Template<'_>,
    checked: &Checked<'_>,
    options: &Options,
    mut pass: impl FnMut(Sample<'_>, &PointMap, Step) -> Result<(Pose, PassCounts)>,
    guide: &mut impl Guide,
) -> Result<Registration> {
    let source = checked.subset.source;
    let sample = Sample::new(source, options.network_points);
    let mut counts = PassCounts::default();
    let (network, passes, lk_iterations) = pose_steps(
        frame,
        centring,
        source,
        (options.passes, options.lk_iterations),
        options.tolerance,
        |map, step| {
            let (delta, c) = pass(sample, map, step)?;
            counts.saturated = counts.saturated.saturating_add(c.saturated);
            counts.out_of_range = counts.out_of_range.max(c.out_of_range);
            Ok(delta)
        },
    )?;
    let r = refine::resolve(
        template,
        &checked.subset,
        network,
        options.hypotheses,
        options.screen_iterations,
        &options.icp_settings(),
        options.inlier_distance,
        guide,
    )?;
    let stage = Stage {
        passes,
        lk_iterations,
        counts,
    };
    conclude(frame, template, checked, &r, stage, options)
}

/// What [`check`] refuses first: invalid options, an empty source, a
/// point that is not finite.
pub(crate) fn check_input(source: &[[f32; 3]], options: &Options) -> Result<()> {
    options.validate()?;
    if source.is_empty() {
        return Err(Error::EmptyCloud);
    }
    all_finite(source)
}

/// [`Error::NonFiniteCoordinate`] for the first point with a NaN or
/// infinite coordinate.
pub(crate) fn all_finite(source: &[[f32; 3]]) -> Result<()> {
    match source.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        Some(index) => Err(Error::NonFiniteCoordinate { index }),
        None => Ok(()),
    }
}

/// Registers `source` standing on `sweep`'s plane: the sweep's starts
/// ([`crate::sweep`]) screened and the best refined, no network pass. With
/// `seen_from` (the sensor's position in the source's frame, user units:
/// the source is one side of the object as seen from there) each start is
/// placed by what the sensor sees ([`Placing`]), along the plane only (its
/// base stays on the plane).
pub(crate) fn run_swept(
    frame: &Frame,
    template: &Template<'_>,
    source: &[[f32; 3]],
    options: &Options,
    sweep: &crate::sweep::Sweep,
    seen_from: Option<[f32; 3]>,
) -> Result<Registration> {
    sweep.validate()?;
    let checked = check(frame, template, source, options)?;
    let starts = crate::sweep::starts(frame, template, &checked.subset, sweep);
    let up = crate::sweep::unit_up(sweep);
    let mut guide = seen_from.map(|eye| Placing::new(template, &checked.subset, eye, Some(up)));
    let r = refine::resolve_starts(
        template,
        &checked.subset,
        starts,
        options.screen_iterations,
        &options.icp_settings(),
        options.inlier_distance,
        &mut guide,
    )?;
    conclude(frame, template, &checked, &r, Stage::default(), options)
}

/// Registers `source` from `start` (user units): ICP from it against the
/// template's points and the verdict, no network pass and no other start
/// (how [`crate::locate`] checks the turn a registration reports).
pub(crate) fn run_from(
    frame: &Frame,
    template: &Template<'_>,
    source: &[[f32; 3]],
    start: &Pose,
    options: &Options,
) -> Result<Registration> {
    let checked = check(frame, template, source, options)?;
    if !start.is_finite() {
        return Err(Error::InvalidPose);
    }
    let start = frame.pose_to_model(&start.normalised());
    refine_from(frame, template, &checked, start, options).1
}

/// ICP from `start` (model frame) on the checked points, scored and
/// concluded: the refined pose (model frame) and its registration (an
/// error when it is not finite).
pub(crate) fn refine_from(
    frame: &Frame,
    template: &Template<'_>,
    checked: &Checked<'_>,
    start: Pose,
    options: &Options,
) -> (Pose, Result<Registration>) {
    let (pose, icp_iterations) =
        refine::icp(template, &checked.subset, start, &options.icp_settings());
    let fit = refine::score(template, &checked.subset, &pose, options.inlier_distance);
    let refined = Resolved {
        pose,
        fit,
        hypothesis: 0,
        icp_iterations,
        rival: None,
    };
    let registration = conclude(
        frame,
        template,
        checked,
        &refined,
        Stage::default(),
        options,
    );
    (pose, registration)
}

/// The [`Registration`] of a refined and scored pose (model frame) of the
/// checked points: the pose and distances in user units, the verdict, the
/// ambiguity. A non-finite pose or distance is an error.
pub(crate) fn conclude(
    frame: &Frame,
    template: &Template<'_>,
    checked: &Checked<'_>,
    r: &Resolved,
    stage: Stage,
    options: &Options,
) -> Result<Registration> {
    let degenerate = checked.degenerate;
    let pose = frame.pose_to_user(&r.pose);
    let residual = r.fit.residual / frame.scale;
    let inlier_rmse = r.fit.inlier_rmse / frame.scale;
    let plane_residual = r.fit.plane_residual / frame.scale;
    let finite = residual.is_finite() && inlier_rmse.is_finite() && plane_residual.is_finite();
    if !(pose.is_finite() && finite) {
        return Err(Error::NonFiniteResult);
    }
    Ok(Registration {
        pose,
        residual,
        relative_residual: r.fit.residual,
        fitness: r.fit.fitness,
        inlier_rmse,
        plane_residual,
        relative_plane_residual: r.fit.plane_residual,
        hypothesis: r.hypothesis,
        passes: stage.passes,
        lk_iterations: stage.lk_iterations,
        icp_iterations: r.icp_iterations,
        saturated: stage.counts.saturated,
        out_of_range: stage.counts.out_of_range,
        degenerate,
        ambiguity: ambiguity::assess(
            frame,
            template,
            &checked.subset,
            r,
            options.inlier_distance,
            options.max_residual,
        ),
        reliable: degenerate.is_none() && r.fit.plane_residual <= options.max_residual,
    })
}

/// The pose stage from where registration starts ([`pose::centring`]):
/// `counts.0` network passes, then `counts.1` LK steps, each on the source
/// moved by the pose so far ([`pose::iterate`]; each run stops on
/// `tolerance`): the pose in the model frame, the passes and the LK steps
/// run. A non-finite pose is an error.
fn pose_steps(
    frame: &Frame,
    centring: Centring,
    source: &[[f32; 3]],
    counts: (usize, usize),
    tolerance: f32,
    mut pass: impl FnMut(&PointMap, Step) -> Result<Pose>,
) -> Result<(Pose, usize, usize)> {
    let start = pose::centring(source, centring, frame)?;
    let (network, passes) = pose::iterate(start, counts.0, tolerance, |current| {
        pass(&PointMap::new(*frame, current), Step::Network)
    })?;
    let (pose, lk) = pose::iterate(network, counts.1, tolerance, |current| {
        pass(&PointMap::new(*frame, current), Step::Lk)
    })?;
    if pose.is_finite() {
        Ok((pose, passes, lk))
    } else {
        Err(Error::NonFiniteResult)
    }
}

/// The network's passes alone ([`pose_steps`] without LK) on the default
/// sample of [`NETWORK_POINTS`] (every point checked for NaN first), with
/// the pose in user units, as `Int8Model::network_pose` and
/// `F32Model::network_pose` give it.
pub(crate) fn network_pose(
    frame: &Frame,
    centring: Centring,
    source: &[[f32; 3]],
    passes: usize,
    tolerance: f32,
    mut pass: impl FnMut(Sample<'_>, &PointMap) -> Result<Pose>,
) -> Result<(Pose, usize)> {
    all_finite(source)?;
    let sample = Sample::new(source, NETWORK_POINTS);
    let (pose, n, _) = pose_steps(frame, centring, source, (passes, 0), tolerance, |map, _| {
        pass(sample, map)
    })?;
    let pose = frame.pose_to_user(&pose);
    if pose.is_finite() {
        Ok((pose, n))
    } else {
        Err(Error::NonFiniteResult)
    }
}
