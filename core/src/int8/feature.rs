//! A check in the network's feature space: how far the source, moved by a
//! pose, lies from the template as the encoder sees them
//! ([`Int8Model::feature_distance`]). PointNetLK minimises this quantity;
//! here it is measured beside the plane residual (issue 36, item 3), not
//! yet used by the verdict.

use super::{Int8Model, Ready};
use crate::error::{Error, Result};
use crate::pose::{PointMap, Pose};
use crate::registration::{self, Sample};

impl Int8Model<'_> {
    /// The relative feature distance of `source` moved by `pose` (user
    /// units, as a [`crate::Registration`] returns it: `p_template = R
    /// p_source + t`): `||f(pose . source) - f(template)|| / ||f(template)||`,
    /// both features dequantized with the last encoder layer's scale (the
    /// zero point cancels in the difference), sums of squares in f32 in
    /// feature order, one `libm::sqrtf` each. The source is not centred:
    /// the pose already places it on the template. The encoder sees the
    /// sample the blob's network passes and LK steps take
    /// ([`crate::registration::network_points`] points at most, every
    /// k-th), as the template's feature was pooled: one encoder pass over it (the
    /// network's cost without its head); bit-exact on every target.
    ///
    /// Errors as [`Self::encode`]; [`Error::NonFiniteResult`] for a pose
    /// that is not finite or a template feature of zero norm.
    pub fn feature_distance(
        &self,
        source: &[[f32; 3]],
        pose: &Pose,
        scratch: &mut [i8],
    ) -> Result<f32> {
        if !pose.is_finite() {
            return Err(Error::NonFiniteResult);
        }
        // The encoder sees a sample: every point is checked here.
        registration::all_finite(source)?;
        let tile = self.tile_for(scratch.len())?;
        let map = PointMap::new(self.p.frame, &self.p.frame.pose_to_model(pose));
        let sample = Sample::new(source, registration::network_points(self.has_head()));
        let (feature, _) = self.encode_mapped(sample, &map, tile, scratch, Ready::default())?;
        let (zero, scale) = self
            .p
            .encoder
            .last()
            .map_or((0, 1.0), |l| (l.out_zero_point as i32, l.out_scale));
        let (mut apart, mut norm) = (0f32, 0f32);
        for (&s, &t) in feature.iter().zip(self.p.template_feature) {
            let (s, t) = (s as i32, t as i8 as i32);
            let d = (s - t) as f32 * scale;
            let v = (t - zero) as f32 * scale;
            apart += d * d;
            norm += v * v;
        }
        let relative = libm::sqrtf(apart) / libm::sqrtf(norm);
        if relative.is_finite() {
            Ok(relative)
        } else {
            Err(Error::NonFiniteResult)
        }
    }
}
