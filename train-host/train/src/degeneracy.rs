//! The device's degeneracy verdict (`pcrnet_core::refine::degeneracy`,
//! a cloud whose points coincide or lie on a line fixes no pose) run on the
//! host: on a cloud as its own template, as `pcrnet train --object` checks
//! an object before any epoch, and on a source against a template, as
//! every evaluated method reports it.

use pcrnet_core::refine::{self, Subset};
use pcrnet_core::registration::MIN_EXTENT;
use pcrnet_core::template::Template;
use pcrnet_core::{Degeneracy, F32Model, Frame, Int8Model, Options};

use crate::template::{DEFAULT_TEMPLATE_POINTS, Reference, TemplateError};

/// The device's degeneracy verdict on `cloud` as its own template (as
/// `pcrnet train --object` would bind it): `Some` for a cloud that fixes
/// no pose (its points coincide or lie on a line), an error for one with
/// no extent at all.
pub fn self_degeneracy(cloud: &[[f32; 3]]) -> Result<Option<Degeneracy>, TemplateError> {
    let reference = Reference::new(cloud, DEFAULT_TEMPLATE_POINTS)?;
    source_degeneracy(None, Some(&reference), cloud)
}

/// The device's degeneracy verdict on `source`, against the template cloud
/// if one is given (recorded as a blob records it) or else the blob's own
/// template. A template with no extent is an error for every method.
pub fn source_degeneracy(
    blob: Option<&[u8]>,
    reference: Option<&Reference>,
    source: &[[f32; 3]],
) -> Result<Option<Degeneracy>, TemplateError> {
    let judge = |t: &Template<'_>, frame: Frame| {
        let subset = Subset::new(source, frame, Options::default().max_points);
        refine::degeneracy(t, &subset, MIN_EXTENT)
    };
    if let Some(reference) = reference {
        let t = Template::new(reference.cloud(), reference.table()).map_err(TemplateError::from)?;
        return Ok(judge(&t, reference.frame));
    }
    let Some(blob) = blob else {
        return Ok(None);
    };
    if let Ok(m) = Int8Model::from_bytes(blob) {
        Ok(judge(m.template(), *m.frame()))
    } else if let Ok(m) = F32Model::from_bytes(blob) {
        Ok(judge(m.template(), *m.frame()))
    } else {
        // The method itself reports what is wrong with the blob.
        Ok(None)
    }
}
