//! The model's entry points for a sensor's world: a view standing on a
//! plane ([`Int8Model::register_on_plane`]), a raw frame
//! ([`Int8Model::locate`], [`Int8Model::follow`]) and a cut single view
//! seen from a known viewpoint ([`Int8Model::register_view`],
//! [`Int8Model::track_view`], [`Int8Model::check_view`]). Each is the
//! pipeline of [`crate::registration`] with what the scene or the view
//! adds; the network passes are [`Int8Model`]'s own.

use super::{Int8Model, Ready};
use crate::error::Result;
use crate::locate::Start;
use crate::pose::Pose;
use crate::registration::{self, Options, Registration};
use crate::track::Tracking;

impl<'a> Int8Model<'a> {
    /// Registers `source`, a view of the object standing on `sweep`'s plane
    /// with the template's up axis along the plane's normal, by the yaw
    /// sweep of [`crate::sweep`] (no network pass, no scratch): the
    /// registration for one-sided views in any yaw, which the network's
    /// hypotheses do not cover. The starts stand where [`crate::sweep`]
    /// puts them: without the sensor's position they are not placed by
    /// what it sees, as [`Self::locate`]'s are (the sensor at the frame's
    /// origin, [`crate::locate::SENSOR`]).
    #[inline(never)]
    pub fn register_on_plane(
        &self,
        source: &[[f32; 3]],
        sweep: &crate::sweep::Sweep,
        options: &Options,
    ) -> Result<Registration> {
        registration::run_swept(&self.p.frame, &self.template, source, options, sweep, None)
    }

    /// Finds the template's object in a sensor frame and registers it
    /// (see [`crate::locate`]): the scene stages over `frame` with `scene`
    /// (start from [`crate::scene::SceneOptions::for_object`] with
    /// [`Self::object_radius`]), then up to `candidates` of the largest kept
    /// clusters registered, each from at most `points.len()` of its points:
    /// by the yaw sweep with its starts placed by what the sensor sees when
    /// the scene has an up axis and a plane, else as [`Self::register`] does. `labels` needs
    /// [`crate::scene::labels_len`] elements; the scratch is the registration's.
    ///
    /// When candidates are checked against the frame (the scene options'
    /// `verify` and a frame with intrinsics), a candidate's residual bound
    /// is the larger of `options.max_residual` and the check's
    /// [`crate::scene::VerifySettings::max_residual`], and each registration
    /// runs with it: its verdict and the turn it reports
    /// ([`crate::ambiguity`]: a rival fitting within the bound) are judged
    /// at the bound the candidate's verdict uses. Measured on the `scene`
    /// experiment (seed 1, 50 frames a camera, default options: the
    /// check's 0.025 against 0.015; session 53, this change alone): of the
    /// reliable poses more than 5 degrees off with the sweep, those whose
    /// reported turn explains the error 3 -> 7 (ToF) and 4 -> 4 (RGB-D),
    /// success 68 -> 70% and 68 -> 68%; the network's hypotheses (no up
    /// axis) 34 -> 46% and 20 -> 30%, their turns settled by the frame.
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub fn locate<F: crate::scene::Organised>(
        &self,
        frame: &F,
        scene: &crate::scene::SceneOptions,
        candidates: usize,
        options: &Options,
        labels: &mut [u16],
        points: &mut [[f32; 3]],
        scratch: &mut [i8],
    ) -> Result<crate::locate::Located> {
        self.locate_from(
            frame, scene, candidates, None, options, labels, points, scratch,
        )
    }

    /// Follows the object into the next frame of a stream (see
    /// [`crate::follow`]): with `previous` the pose of the last frame (user
    /// units, as a registration returns it) and `plane` the plane that
    /// frame's segmentation found (`located.segmentation.plane`), the
    /// cluster in the box about where `previous` puts the object
    /// ([`crate::follow::near`]) nearest that place is registered by ICP
    /// from `previous` and checked against the frame. Buffers as
    /// [`Self::locate`]'s. Act on the result only when its best candidate is
    /// reliable; otherwise (or on an error) locate the object afresh. A
    /// followed registration reports no turn (it has no other start to
    /// compare with): keep the turn the last `locate` reported, which still
    /// holds for a symmetric object.
    ///
    /// # Errors
    /// A non-finite `previous` or one whose rotation is not a unit
    /// quaternion is [`crate::Error::InvalidPose`]; else as
    /// [`Self::locate`].
    #[inline(never)]
    #[allow(clippy::too_many_arguments)]
    pub fn follow<F: crate::scene::Organised>(
        &self,
        frame: &F,
        scene: &crate::scene::SceneOptions,
        previous: &Pose,
        plane: Option<crate::scene::Plane>,
        options: &Options,
        labels: &mut [u16],
        points: &mut [[f32; 3]],
        scratch: &mut [i8],
    ) -> Result<crate::locate::Located> {
        let previous = previous.checked_unit()?;
        let radius = self.object_radius();
        let near = crate::follow::near(scene, &self.p.frame, &previous, plane, radius);
        let prior = crate::locate::Prior {
            pose: &previous,
            centre: crate::follow::centre(&self.p.frame, &previous),
        };
        self.locate_from(
            frame,
            &near,
            1,
            Some(prior),
            options,
            labels,
            points,
            scratch,
        )
    }

    /// [`Self::locate`], with a `prior` each candidate registered from its
    /// pose by ICP alone, the clusters nearest its centre first
    /// ([`crate::follow`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn locate_from<F: crate::scene::Organised>(
        &self,
        frame: &F,
        scene: &crate::scene::SceneOptions,
        candidates: usize,
        prior: Option<crate::locate::Prior<'_>>,
        options: &Options,
        labels: &mut [u16],
        points: &mut [[f32; 3]],
        scratch: &mut [i8],
    ) -> Result<crate::locate::Located> {
        let tile = self.tile_for(scratch.len())?;
        // Checked against the frame, a candidate is judged at the looser of
        // the two residual bounds, and so is the turn its registration
        // reports (a rival within that bound is one the frame has to settle).
        let check = scene.verify.zip(frame.intrinsics());
        let bound = crate::locate::checked_bound(frame, scene, options);
        let checked;
        let options = match bound {
            Some(max_residual) => {
                checked = Options {
                    max_residual,
                    ..*options
                };
                &checked
            }
            None => options,
        };
        let verify = |frame: &F, r: &Registration, surface: Option<crate::scene::Plane>| {
            let ((settings, k), bound) = check.zip(bound)?;
            let (template, model) = (&self.template, &self.p.frame);
            let v = crate::scene::verify::verify(
                frame, &k, template, model, &r.pose, &settings, surface,
            );
            Some((v, bound))
        };
        crate::locate::locate(
            frame,
            scene,
            candidates,
            prior,
            labels,
            points,
            |source, start| match start {
                Start::Sweep(sweep) => registration::run_swept(
                    &self.p.frame,
                    &self.template,
                    source,
                    options,
                    sweep,
                    Some(crate::locate::SENSOR),
                ),
                Start::Network => {
                    self.register_ready(source, options, tile, scratch, Ready::default())
                }
                Start::Pose(pose) => {
                    registration::run_from(&self.p.frame, &self.template, source, pose, options)
                }
            },
            verify,
        )
    }

    /// Registers a cut single view `source` (one object as a depth sensor
    /// saw it from `viewpoint`, the sensor's position in the source's
    /// frame, user units; everything else cut away) as [`Self::register`]
    /// does, guided by the view: every start (the network's pose and each
    /// turned one) is first placed so that the source's centroid meets the
    /// centroid of the template points the sensor would see at that start
    /// ([`crate::scene::visible::place`]), and the view, rendered into
    /// `buffer` ([`crate::scene::view::buffer_len`]), is a test the turned
    /// starts must pass besides their residual: screening finishes the
    /// lowest-residual turned start whose pose explains the view
    /// ([`crate::refine::resolve`]). The result carries the registration, its
    /// check against the view ([`Self::check_view`]) and both verdicts.
    ///
    /// # Errors
    /// As [`Self::register`] and [`crate::scene::View::render`].
    #[inline(never)]
    pub fn register_view(
        &self,
        source: &[[f32; 3]],
        viewpoint: [f32; 3],
        options: &Options,
        scratch: &mut [i8],
        buffer: &mut [f32],
    ) -> Result<crate::viewed::Viewed> {
        let tile = self.tile_for(scratch.len())?;
        crate::viewed::register(
            &self.p.frame,
            self.centring(),
            &self.template,
            source,
            viewpoint,
            options,
            buffer,
            |sample, map, step| self.pass(sample, map, step, tile, scratch, Ready::default()),
        )
    }

    /// One tracking step ([`Self::track`]) of a cut single view seen from
    /// `viewpoint` (the sensor's position in the source's frame, user
    /// units: the origin for points in the sensor's own frame): `previous`
    /// refined by ICP and kept when reliable, else registered afresh in the
    /// same call as [`Self::register_view`] registers (its starts placed by
    /// what the sensor sees and judged by the view rendered into `buffer`).
    /// The result's verdict is the residual's, as [`Self::track`]'s; check
    /// the pose against the view with [`Self::check_view`] when acting on
    /// it must also explain the view.
    ///
    /// # Errors
    /// As [`Self::track`] and [`crate::scene::View::render`] (the view is
    /// rendered first, whether or not the step falls back).
    #[inline(never)]
    pub fn track_view(
        &self,
        source: &[[f32; 3]],
        previous: &Pose,
        viewpoint: [f32; 3],
        options: &Options,
        scratch: &mut [i8],
        buffer: &mut [f32],
    ) -> Result<Tracking> {
        let tile = self.tile_for(scratch.len())?;
        crate::viewed::track(
            &self.p.frame,
            self.centring(),
            &self.template,
            source,
            previous,
            viewpoint,
            options,
            buffer,
            |sample, map, step| self.pass(sample, map, step, tile, scratch, Ready::default()),
        )
    }

    /// Checks `pose` (a registration of `source`, user units) against the
    /// cut single view `source` seen from `viewpoint` (the sensor's
    /// position in the source's frame, user units): the view rendered into
    /// `buffer` ([`crate::scene::view::buffer_len`]) and judged with
    /// [`crate::scene::VerifySettings::for_object`] of
    /// [`Self::object_radius`] (see [`crate::scene::view`]). A pose that
    /// passes explains the view both ways; combine it with the
    /// registration's own verdict.
    ///
    /// # Errors
    /// As [`crate::scene::View::render`]; a pose that is not finite or
    /// whose rotation is not a unit quaternion is [`crate::Error::InvalidPose`].
    pub fn check_view(
        &self,
        source: &[[f32; 3]],
        viewpoint: [f32; 3],
        pose: &Pose,
        buffer: &mut [f32],
    ) -> Result<crate::scene::Verification> {
        crate::scene::view::check_model(
            &self.template,
            &self.p.frame,
            source,
            viewpoint,
            pose,
            buffer,
        )
    }
}
