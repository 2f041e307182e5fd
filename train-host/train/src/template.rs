//! What a blob records about its template (format 4), built on the host:
//! the frame (how the template's units and axes map to the model frame),
//! the subsampled template points with their search grid and closest-point
//! table, the symmetry turns for flip resolution, and the template's
//! feature. One place for all of it:
//! `export`, `quantize` and `register` with a template file go through
//! [`Reference`] and [`bind`].

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use pcrnet_core::format::{
    self, F32Payload, Int8Payload, MAX_TURNS, ModelKind, NearestTable, TemplateCloud, Trailer,
    write_blob,
};
use pcrnet_core::template::{self, MAX_GRID};
use pcrnet_core::{F32Model, Frame, Int8Model, Options, Pose};

use crate::lk_solver;
use crate::shapes::frame_of;
use pcrnet_io::sampling::farthest_point_indices;

/// Model units per int16 step of stored template points: the template fills
/// `[-0.5, 0.5]^3`, and a moved source point stays representable up to
/// `+-2` (beyond that it is clamped, far outside any inlier distance).
pub const TEMPLATE_STEP: f32 = 1.0 / 16384.0;
/// Template points stored by default: 6 bytes each (3 KB of flash).
pub const DEFAULT_TEMPLATE_POINTS: usize = 512;

/// How the exporter lays out the template's closest-point table
/// ([`NearestTable`]): `across` cells over the template's widest side,
/// `margin` more cells on every side, lists longer than `max_list` left
/// to the grid search. Flash: 2 bytes per cell and per entry (`pcrnet
/// inspect` reports both).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableLayout {
    /// Cells over the template's widest side.
    pub across: u8,
    /// Cells added on every side.
    pub margin: u8,
    /// Longest list kept.
    pub max_list: usize,
}

/// The exporter's default table: 12 cells across, 4 cells of margin
/// (queries up to a third of the template's size off its box), lists of up
/// to 32 points. On the shipped template: 20 x 20 x 11 cells, 3.8 entries
/// per cell, 42.5 KB of flash. Measured on the M4F (firmware example,
/// default registration with turned starts screened on half their points
/// as then, 39.8 M instructions with this table): 16 cells
/// across with 3 of margin 39.9 M (46.7 KB), 16 and 5 38.5 M (76 KB), 24
/// and 4 39.1 M (104 KB), 8 and 5 43.2 M (38 KB); without a table 56.1 M.
pub const DEFAULT_TABLE: TableLayout = TableLayout {
    across: 12,
    margin: 4,
    max_list: 32,
};

/// Why a template cannot be recorded.
#[derive(Debug, thiserror::Error)]
pub enum TemplateError {
    /// Empty, non-finite, or all points equal.
    #[error(
        "the template has no extent (empty, non-finite, or every point equal): it cannot define a frame; give a cloud of the object's surface"
    )]
    NoExtent,
    /// The point count asked for is outside what a blob holds.
    #[error("--template-points must be between 1 and 65535 (got {0})")]
    PointCount(usize),
    /// The up axis given is zero or not finite.
    #[error("the up axis {0:?} is zero or not finite: give x, y, z, -x, -y or -z")]
    Up([f32; 3]),
    /// `pcrnet-core` refused the result.
    #[error(transparent)]
    Core(#[from] pcrnet_core::Error),
}

/// A template as a blob records it (owned bytes of a [`TemplateCloud`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    /// User units -> model frame.
    pub frame: Frame,
    /// The template as given (user units): its feature is computed from these.
    pub points: Vec<[f32; 3]>,
    point_bytes: Vec<u8>,
    normal_bytes: Vec<u8>,
    cell_bytes: Vec<u8>,
    grid: u8,
    origin: [i16; 3],
    cell: u16,
    turns: Vec<[f32; 4]>,
    table: Option<OwnedTable>,
    /// Indices into `points` of the stored points.
    stored: Vec<usize>,
    /// The template's residual floor over the points not stored
    /// ([`crate::floor::residual_floor`]; `None` when every point was).
    residual_floor: Option<f32>,
    /// The object's up axis (unit, the template's frame), when given.
    up: Option<[f32; 3]>,
}

/// A closest-point table's shape and owned bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedTable {
    shape: template::TableShape,
    offsets: Vec<u8>,
    candidates: Vec<u8>,
}

impl OwnedTable {
    /// The table of `layout` for a stored template.
    pub fn build(t: &template::Template<'_>, layout: TableLayout) -> Result<Self, TemplateError> {
        let shape = template::TableShape::around(t, layout.across, layout.margin)?;
        let mut work = vec![0u16; template::table_work_len(t.len())];
        let (no, nc) = template::table_len(t, &shape, layout.max_list, &mut work)?;
        let (mut offsets, mut candidates) = (vec![0u8; no], vec![0u8; nc]);
        template::build_table(
            t,
            &shape,
            layout.max_list,
            &mut work,
            &mut offsets,
            &mut candidates,
        )?;
        Ok(OwnedTable {
            shape,
            offsets,
            candidates,
        })
    }

    /// The view a blob stores.
    pub fn view(&self) -> NearestTable<'_> {
        NearestTable {
            origin: self.shape.origin,
            edge: self.shape.edge,
            dims: self.shape.dims,
            offsets: &self.offsets,
            candidates: &self.candidates,
        }
    }
}

impl Reference {
    /// Records `template` (user units): its frame, `stored` of its points
    /// (farthest-point subsampled in the model frame, from point 0) on the
    /// int16 grid with a search grid of about 2 points per cell, and the
    /// half and quarter turns about its principal axes, and the
    /// [`DEFAULT_TABLE`] closest-point table.
    pub fn new(template: &[[f32; 3]], stored: usize) -> Result<Self, TemplateError> {
        Self::with_table(template, stored, Some(DEFAULT_TABLE))
    }

    /// [`Self::new`] with the closest-point table laid out by `table`, or
    /// none.
    pub fn with_table(
        template: &[[f32; 3]],
        stored: usize,
        table: Option<TableLayout>,
    ) -> Result<Self, TemplateError> {
        if !(1..=template::MAX_POINTS).contains(&stored) {
            return Err(TemplateError::PointCount(stored));
        }
        let frame = frame_of(template).ok_or(TemplateError::NoExtent)?;
        let model: Vec<[f32; 3]> = template.iter().map(|&p| frame.to_model(p)).collect();
        let stored = farthest_point_indices(&model, stored, 0, None);
        let kept: Vec<[f32; 3]> = stored.iter().map(|&i| model[i]).collect();
        let quantized: Vec<[i16; 3]> = kept
            .iter()
            .map(|p| p.map(|x| (x / TEMPLATE_STEP).round().clamp(-32767.0, 32767.0) as i16))
            .collect();
        let grid = ((kept.len() as f64 / 2.0).cbrt().round() as u8).clamp(1, MAX_GRID);
        let turns = principal_turns(&model);
        let normals = normals(&model, &kept);
        let (np, nn, nc) = template::build_len(quantized.len(), grid);
        let (mut point_bytes, mut normal_bytes, mut cell_bytes) =
            (vec![0u8; np], vec![0u8; nn], vec![0u8; nc]);
        let (origin, cell) = {
            let out = template::BuildOut {
                points: &mut point_bytes,
                normals: &mut normal_bytes,
                cells: &mut cell_bytes,
            };
            let c = template::build(&quantized, &normals, TEMPLATE_STEP, grid, &turns, out)?;
            (c.origin, c.cell)
        };
        let mut reference = Reference {
            frame,
            points: template.to_vec(),
            point_bytes,
            normal_bytes,
            cell_bytes,
            grid,
            origin,
            cell,
            turns,
            table: None,
            stored,
            residual_floor: None,
            up: None,
        };
        if let Some(layout) = table {
            let t = template::Template::new(reference.cloud(), None)?;
            reference.table = Some(OwnedTable::build(&t, layout)?);
        }
        reference.residual_floor = reference.floor_of(&reference.points)?;
        Ok(reference)
    }

    /// Measures the template's residual floor on `cloud` (user units: the
    /// object's points, the template's own or a denser scan of it), its
    /// points other than the stored ones ([`Self::unstored_of`]), and keeps
    /// it for the blob; no floor unless there are at least as many of
    /// them as stored points. Farthest point sampling leaves out the points
    /// nearest the stored ones, so a cloud barely larger than the stored
    /// count gives a floor biased low (a night stand, 512 stored: 576
    /// points in the file gave 0.0095, 768 0.0267, 1,024 0.0296, against
    /// 0.0284 from independent points).
    pub fn measure_floor(&mut self, cloud: &[[f32; 3]]) -> Result<(), TemplateError> {
        self.residual_floor = self.floor_of(cloud)?;
        Ok(())
    }

    /// The floor [`Self::measure_floor`] keeps.
    fn floor_of(&self, cloud: &[[f32; 3]]) -> Result<Option<f32>, TemplateError> {
        let unstored = self.unstored_of(cloud);
        if unstored.len() < self.stored.len() {
            return Ok(None);
        }
        let t = template::Template::new(self.cloud(), self.table())?;
        Ok(crate::floor::residual_floor(
            &t,
            &self.frame,
            &unstored,
            Options::default().inlier_distance,
        ))
    }

    /// The template's points (user units) that were not stored, leaving
    /// out copies of stored points (a file may repeat a point): what
    /// [`crate::floor::residual_floor`] scores. Empty when every point was
    /// stored.
    pub fn unstored(&self) -> Vec<[f32; 3]> {
        self.unstored_of(&self.points)
    }

    /// The points of `cloud` (user units) that are not stored points of
    /// the template (compared bit for bit).
    pub fn unstored_of(&self, cloud: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let bits = |p: &[f32; 3]| p.map(f32::to_bits);
        let stored: std::collections::HashSet<[u32; 3]> = self
            .stored
            .iter()
            .filter_map(|&i| self.points.get(i).map(bits))
            .collect();
        cloud
            .iter()
            .filter(|p| !stored.contains(&bits(p)))
            .copied()
            .collect()
    }

    /// The template's residual floor, measured on the points not stored
    /// with the default inlier distance ([`crate::floor`]): what a blob
    /// of this template carries. `None` unless the cloud holds at least
    /// as many points again as were stored (fewer leave only the points
    /// nearest the stored ones, and a floor biased low).
    pub fn residual_floor(&self) -> Option<f32> {
        self.residual_floor
    }

    /// Records the object's up axis (the template's frame: the axis pointing
    /// away from the surface the object rests on, any length) for the blob
    /// (format 7), scaled to unit length.
    ///
    /// # Errors
    /// [`TemplateError::Up`] for an axis that is zero or not finite.
    pub fn set_up(&mut self, up: [f32; 3]) -> Result<(), TemplateError> {
        let length = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
        if !(length.is_finite() && length > 0.0) {
            return Err(TemplateError::Up(up));
        }
        self.up = Some(up.map(|v| v / length));
        Ok(())
    }

    /// The up axis a blob of this template carries ([`Self::set_up`]).
    pub fn up(&self) -> Option<[f32; 3]> {
        self.up
    }

    /// The closest-point table a blob stores beside the cloud, if any.
    pub fn table(&self) -> Option<NearestTable<'_>> {
        self.table.as_ref().map(OwnedTable::view)
    }

    /// The view a payload stores.
    pub fn cloud(&self) -> TemplateCloud<'_> {
        TemplateCloud {
            step: TEMPLATE_STEP,
            points: &self.point_bytes,
            normals: &self.normal_bytes,
            grid: self.grid,
            origin: self.origin,
            cell: self.cell,
            cells: &self.cell_bytes,
            turns: heapless::Vec::from_slice(&self.turns).unwrap_or_default(),
        }
    }

    /// The template in the model frame (`frame.to_model` of every point,
    /// exactly as `pcrnet-core` moves a source).
    pub fn normalised(&self) -> Vec<[f32; 3]> {
        self.points
            .iter()
            .map(|&p| self.frame.to_model(p))
            .collect()
    }
}

/// Neighbours whose covariance gives a point's normal.
const NORMAL_NEIGHBOURS: usize = 12;

/// The unit normal (times 127, sign arbitrary) at each of `kept`: the
/// direction of least spread of its [`NORMAL_NEIGHBOURS`] nearest points of
/// `model` (principal component analysis, as PCL and Open3D estimate
/// normals). A point whose neighbourhood has no such direction (all
/// neighbours equal) gets `+x`.
fn normals(model: &[[f32; 3]], kept: &[[f32; 3]]) -> Vec<[i8; 3]> {
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(
        &model
            .iter()
            .map(|p| p.map(|v| v as f64))
            .collect::<Vec<_>>(),
    );
    let k = NORMAL_NEIGHBOURS.min(model.len()).max(1);
    kept.iter()
        .map(|p| {
            let q = p.map(|v| v as f64);
            let near = tree.nearest_n::<SquaredEuclidean>(
                &q,
                std::num::NonZero::new(k).unwrap_or(std::num::NonZero::<usize>::MIN),
            );
            let pts: Vec<Vector3<f64>> = near
                .iter()
                .map(|n| {
                    let m = model[n.item as usize];
                    Vector3::new(m[0] as f64, m[1] as f64, m[2] as f64)
                })
                .collect();
            let c = pts.iter().sum::<Vector3<f64>>() / pts.len() as f64;
            let cov = pts
                .iter()
                .fold(Matrix3::zeros(), |a, v| a + (v - c) * (v - c).transpose());
            let eig = SymmetricEigen::new(cov);
            let (mut best, mut value) = (0usize, f64::INFINITY);
            for i in 0..3 {
                if eig.eigenvalues[i] < value {
                    (best, value) = (i, eig.eigenvalues[i]);
                }
            }
            let n = eig.eigenvectors.column(best);
            let len = n.norm();
            if len > 0.0 && eig.eigenvalues.iter().any(|&v| v > 0.0) {
                [0, 1, 2].map(|i| (127.0 * n[i] / len).round() as i8)
            } else {
                [127, 0, 0]
            }
        })
        .collect()
}

/// Turns a template recorded here carries (`principal_turns`): a half
/// turn and two quarter turns about each principal axis. The device tries
/// at most `1 + PRINCIPAL_TURNS` starting poses with it.
pub const PRINCIPAL_TURNS: usize = 9;

/// Half turns then quarter turns (+-90 degrees) about the principal axes
/// of `model` (the template in the model frame, centroid at the origin),
/// largest variance first: unit quaternions `[w, x, y, z]`
/// ([`PRINCIPAL_TURNS`] of them).
fn principal_turns(model: &[[f32; 3]]) -> Vec<[f32; 4]> {
    let n = model.len().max(1) as f64;
    let mut c = Matrix3::<f64>::zeros();
    for p in model {
        for i in 0..3 {
            for j in 0..3 {
                c[(i, j)] += p[i] as f64 * p[j] as f64 / n;
            }
        }
    }
    let eig = SymmetricEigen::new(c);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let axes: Vec<[f32; 3]> = order
        .iter()
        .map(|&k| {
            let v = eig.eigenvectors.column(k);
            [v[0] as f32, v[1] as f32, v[2] as f32]
        })
        .collect();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let mut turns: Vec<[f32; 4]> = axes.iter().map(|a| [0.0, a[0], a[1], a[2]]).collect();
    for a in &axes {
        turns.push([h, h * a[0], h * a[1], h * a[2]]);
        turns.push([h, -h * a[0], -h * a[1], -h * a[2]]);
    }
    turns.truncate(PRINCIPAL_TURNS.min(MAX_TURNS));
    turns
}

/// Writes an int8 blob from `payload` with `reference` as its template:
/// frame, template points and the template feature (computed by the int8
/// encoder itself, as the device would), and with `lk` PointNetLK's
/// solver for it ([`crate::lk_solver`]).
pub fn int8_blob(
    payload: &Int8Payload<'_>,
    reference: &Reference,
    lk: bool,
) -> Result<Vec<u8>, TemplateError> {
    let zeros = vec![0u8; payload.arch.feature_dim()];
    let draft = Int8Payload {
        frame: reference.frame,
        template: reference.cloud(),
        template_feature: &zeros,
        ..payload.clone()
    };
    // A placeholder solver of zeros lets a headless draft load.
    let zero_rows = lk.then(|| lk_solver::placeholder_rows(payload.arch.feature_dim()));
    let draft_trailer =
        lk_solver::trailer(ModelKind::Int8, reference.table(), zero_rows.as_deref());
    let model = Int8Model::from_payload(draft.clone(), draft_trailer)?;
    // The feature a registration compares a source with: centred on the
    // whole template, pooled over the network's sample of it.
    let rows = lk
        .then(|| lk_solver::int8_rows(&model, &reference.points))
        .transpose()?;
    let mut scratch = vec![0i8; model.host_scratch_len()];
    let feature: Vec<u8> = model
        .encode_moved(&reference.points, &Pose::IDENTITY, &mut scratch)?
        .iter()
        .map(|&v| v as u8)
        .collect();
    let done = Int8Payload {
        template_feature: &feature,
        ..draft
    };
    let trailer = Trailer {
        residual_floor: reference.residual_floor(),
        up: reference.up(),
        ..lk_solver::trailer(ModelKind::Int8, reference.table(), rows.as_deref())
    };
    let mut out = vec![0u8; format::blob_len(&done, &trailer)?];
    write_blob(ModelKind::Int8, &done, &trailer, &mut out)?;
    Int8Model::from_bytes(&out)?;
    Ok(out)
}

/// Writes an f32 blob from `payload` with `reference` as its template (as [`int8_blob`]).
pub fn f32_blob(
    payload: &F32Payload<'_>,
    reference: &Reference,
    lk: bool,
) -> Result<Vec<u8>, TemplateError> {
    let zeros = vec![0u8; 4 * payload.arch.feature_dim()];
    let draft = F32Payload {
        frame: reference.frame,
        template: reference.cloud(),
        template_feature: &zeros,
        ..payload.clone()
    };
    let zero_rows = lk.then(|| lk_solver::placeholder_rows(payload.arch.feature_dim()));
    let draft_trailer = lk_solver::trailer(ModelKind::F32, reference.table(), zero_rows.as_deref());
    let model = F32Model::from_payload(draft.clone(), draft_trailer)?;
    let normalised = reference.normalised();
    let rows = lk
        .then(|| lk_solver::f32_rows(&model, &normalised))
        .transpose()?;
    let mut scratch = vec![0f32; model.tiled_scratch_len()];
    let feature: Vec<u8> = model
        .network()
        .encode_moved(&normalised, &Pose::IDENTITY, &mut scratch)?
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let done = F32Payload {
        template_feature: &feature,
        ..draft
    };
    let trailer = Trailer {
        residual_floor: reference.residual_floor(),
        up: reference.up(),
        ..lk_solver::trailer(ModelKind::F32, reference.table(), rows.as_deref())
    };
    let mut out = vec![0u8; format::blob_len(&done, &trailer)?];
    write_blob(ModelKind::F32, &done, &trailer, &mut out)?;
    F32Model::from_bytes(&out)?;
    Ok(out)
}

/// The same model with another template (user units): for registering
/// against any cloud with a trained blob of either kind. A blob with
/// PointNetLK's solver gets one for the new template. The new template has
/// no up axis (that of [`bind_reference`]'s reference, if set).
pub fn bind(blob: &[u8], template: &[[f32; 3]], stored: usize) -> Result<Vec<u8>, TemplateError> {
    bind_reference(blob, &Reference::new(template, stored)?)
}

/// [`bind`] with the template's [`Reference`] already built (for callers
/// that also use it otherwise: building one subsamples the cloud and
/// estimates normals, several milliseconds at 512 stored points).
pub fn bind_reference(blob: &[u8], reference: &Reference) -> Result<Vec<u8>, TemplateError> {
    match Int8Model::from_bytes(blob) {
        Ok(m) => int8_blob(m.payload(), reference, m.lk_solver().is_some()),
        Err(pcrnet_core::Error::WrongKind { .. }) => {
            let (payload, trailer): (F32Payload<'_>, _) =
                format::decode_model(blob, ModelKind::F32)?;
            f32_blob(&payload, reference, trailer.lk.is_some())
        }
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shapes::{Shape, sample};

    #[test]
    fn records_frame_points_and_turns() {
        let unit = sample(Shape::Ell, 600, 2);
        let metres: Vec<[f32; 3]> = unit
            .iter()
            .map(|p| [p[0] * 3.0 + 100.0, p[1] * 3.0 - 50.0, p[2] * 3.0 + 7.0])
            .collect();
        let r = Reference::new(&metres, 256).unwrap();
        assert!((r.frame.scale - 1.0 / 3.0).abs() < 1e-3, "{:?}", r.frame);
        let t = template::Template::new(r.cloud(), r.table()).unwrap();
        assert!(t.table().is_some());
        assert_eq!(t.len(), 256);
        // The points not stored are the rest of the cloud, none of them a
        // stored one; 344 >= 256 of them give a residual floor.
        let unstored = r.unstored();
        assert_eq!(unstored.len(), 600 - 256);
        assert!(unstored.iter().all(|p| metres.contains(p)));
        assert!(r.stored.iter().all(|&i| !unstored.contains(&metres[i])));
        assert!(r.residual_floor().is_some());
        // A file repeating its points has none left: no floor, not 0.
        let twice: Vec<[f32; 3]> = metres
            .iter()
            .take(256)
            .chain(metres.iter().take(256))
            .copied()
            .collect();
        let r2 = Reference::new(&twice, 256).unwrap();
        assert!(r2.unstored().is_empty());
        assert_eq!(r2.residual_floor(), None);
        // Fewer unstored points than stored: no floor (it would be biased low).
        let mut r3 = Reference::new(&metres, 400).unwrap();
        assert_eq!(r3.residual_floor(), None);
        // A denser scan of the same object gives one; the stored points
        // alone give none again.
        let denser: Vec<[f32; 3]> = sample(Shape::Ell, 1200, 5)
            .iter()
            .map(|p| [p[0] * 3.0 + 100.0, p[1] * 3.0 - 50.0, p[2] * 3.0 + 7.0])
            .collect();
        r3.measure_floor(&denser).unwrap();
        assert!(
            r3.residual_floor()
                .is_some_and(|f| f.is_finite() && f >= 0.0)
        );
        let stored: Vec<[f32; 3]> = r3.stored.iter().map(|&i| r3.points[i]).collect();
        r3.measure_floor(&stored).unwrap();
        assert_eq!(r3.residual_floor(), None);
        assert_eq!(t.turns().len(), PRINCIPAL_TURNS);
        // Stored points lie in the unit box of the model frame.
        for i in 0..t.len() {
            assert!(
                t.point(i)
                    .iter()
                    .all(|&v| (v as f32 * TEMPLATE_STEP).abs() <= 0.5001)
            );
        }
        assert!(matches!(
            Reference::new(&[[0.1, 0.1, 0.1]; 3], 16),
            Err(TemplateError::NoExtent)
        ));
        assert!(matches!(
            Reference::new(&metres, 0),
            Err(TemplateError::PointCount(0))
        ));
    }
}
