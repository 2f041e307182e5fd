//! A cut single view registered with its view: the registration's turned
//! starts judged by the check against the view from the sensor's
//! viewpoint ([`crate::scene::view`]), and the result checked against it.
//! Above both [`crate::registration`] and [`crate::scene`], as
//! [`crate::locate`] is.

use crate::error::Result;
use crate::format::Frame;
use crate::pose::{Centring, PointMap, Pose};
use crate::registration::{self, Options, PassCounts, Registration, Sample, Step};
use crate::scene::Verification;
use crate::scene::view::{View, settings_for};
use crate::template::Template;

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
/// network step), its starts resolved with the view from `viewpoint` as
/// the test a pose must pass besides its residual
/// ([`crate::refine::resolve`]), and checks the result against it.
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
    let settings = settings_for(template, model);
    let judge = |pose: &Pose| view.check(template, model, pose, &settings);
    let registration =
        registration::run_checked(model, centring, template, &checked, options, pass, |pose| {
            judge(pose).passed
        })?;
    let view = judge(&registration.pose);
    Ok(Viewed {
        registration,
        view,
        reliable: registration.reliable && view.passed,
    })
}
