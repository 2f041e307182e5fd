//! A cut single view registered with its view: every start placed by what
//! the sensor would see of the template there ([`crate::scene::visible`]),
//! the turned starts judged by the check against the view from the
//! sensor's viewpoint ([`crate::scene::view`]), and the result checked
//! against it.
//! Above both [`crate::registration`] and [`crate::scene`], as
//! [`crate::locate`] is.

use crate::error::Result;
use crate::format::Frame;
use crate::pose::{Centring, PointMap, Pose};
use crate::refine::{Guide, Subset};
use crate::registration::{self, Options, PassCounts, Registration, Sample, Step};
use crate::scene::view::{View, settings_for};
use crate::scene::visible::Placing;
use crate::scene::{Verification, VerifySettings};
use crate::template::Template;
use crate::track::Tracking;

/// A registration of a cut single view made and checked from its
/// viewpoint (`Int8Model::register_view`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Viewed {
    /// The registration: its starts chosen with the view (see
    /// `Int8Model::register_view`), its `reliable` the residual's verdict.
    pub registration: Registration,
    /// Its pose checked against the view.
    pub view: Verification,
    /// Both verdicts: the registration is reliable and the view's check passed.
    pub reliable: bool,
}

/// Registers `source` as [`crate::registration`] does (`pass` the model's
/// network step), guided by the view from `viewpoint` ([`ViewGuide`]),
/// and checks the result against it.
#[allow(clippy::too_many_arguments)]
pub(crate) fn register(
    model: &Frame,
    centring: Centring,
    template: &Template<'_>,
    source: &[[f32; 3]],
    viewpoint: [f32; 3],
    options: &Options,
    buffer: &mut [f32],
    pass: impl FnMut(Sample<'_>, &PointMap, Step) -> Result<(Pose, PassCounts)>,
) -> Result<Viewed> {
    let checked = registration::check(model, template, source, options)?;
    let view = View::render(source, viewpoint, buffer)?;
    let mut guide = ViewGuide::new(template, model, &view, &checked.subset, viewpoint);
    let registration = registration::run_checked(
        model, centring, template, &checked, options, pass, &mut guide,
    )?;
    let view = guide.judge(&registration.pose);
    Ok(Viewed {
        registration,
        view,
        reliable: registration.reliable && view.passed,
    })
}

/// One tracking step ([`crate::track`]) of a cut single view seen from
/// `viewpoint`: `previous` refined by ICP and kept when reliable, else the
/// registration in the same call guided by the view as in [`register`].
/// The options and the source are checked first (their errors as
/// `register`'s), then the view is rendered into `buffer`, so a viewpoint
/// it refuses is an error whether or not the step falls back.
#[allow(clippy::too_many_arguments)]
pub(crate) fn track(
    model: &Frame,
    centring: Centring,
    template: &Template<'_>,
    source: &[[f32; 3]],
    previous: &Pose,
    viewpoint: [f32; 3],
    options: &Options,
    buffer: &mut [f32],
    pass: impl FnMut(Sample<'_>, &PointMap, Step) -> Result<(Pose, PassCounts)>,
) -> Result<Tracking> {
    // The source's errors first, as `register` gives them.
    registration::check_input(source, options)?;
    let view = View::render(source, viewpoint, buffer)?;
    crate::track::step(
        model,
        centring,
        template,
        source,
        previous,
        options,
        |subset| ViewGuide::new(template, model, &view, subset, viewpoint),
        pass,
    )
}

/// What a view from a known viewpoint adds to flip resolution
/// ([`crate::refine::resolve`]): each start placed so that the source's
/// centroid meets the centroid of the template points the sensor sees at
/// that start ([`crate::scene::visible::place`]), and the screened turned
/// starts judged by the check against the view ([`View::check`]).
struct ViewGuide<'a, 't, 'b> {
    placing: Placing<'a, 't>,
    template: &'a Template<'t>,
    model: &'a Frame,
    view: &'a View<'b>,
    settings: VerifySettings,
}

impl<'a, 't, 'b> ViewGuide<'a, 't, 'b> {
    /// The guide of `view` for the used points of `subset`, seen from
    /// `viewpoint` (the source's frame, user units).
    fn new(
        template: &'a Template<'t>,
        model: &'a Frame,
        view: &'a View<'b>,
        subset: &Subset<'_>,
        viewpoint: [f32; 3],
    ) -> Self {
        ViewGuide {
            placing: Placing::new(template, subset, viewpoint, None),
            template,
            model,
            view,
            settings: settings_for(template, model),
        }
    }

    /// `pose` (user units) checked against the view.
    fn judge(&self, pose: &Pose) -> Verification {
        self.view
            .check(self.template, self.model, pose, &self.settings)
    }
}

impl Guide for ViewGuide<'_, '_, '_> {
    fn place(&mut self, start: Pose) -> Pose {
        self.placing.place(start)
    }

    fn accept(&mut self, pose: &Pose) -> bool {
        self.judge(&self.model.pose_to_user(pose)).passed
    }

    fn may_refuse(&self) -> bool {
        true
    }
}
