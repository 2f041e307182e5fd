//! From a sensor frame to candidate objects: the scene stages.
//!
//! Data flows **frame -> grid -> plane -> clusters -> points**, each stage
//! its own module, all `no_std`, allocation-free and deterministic:
//!
//! | stage | where | what |
//! |---|---|---|
//! | frame | [`depth`] | a borrowed depth image ([`DepthImage`]) or organised cloud ([`OrganisedPoints`]), read pixel by pixel |
//! | grid | [`grid`] | every `step`-th pixel, inside an optional region of interest ([`Region`]) |
//! | plane | [`plane`] | the dominant plane by seeded RANSAC and a refit, or one the caller gives |
//! | clusters | [`cluster`] | connected components of what is off the plane, kept when their extent fits the object |
//! | points | [`cluster::gather`] | one cluster's points at full resolution, for registration |
//! | verify | [`verify`] | a pose against the frame: the template's points seen where they should be, none in free space |
//! | view | [`view`] | a cut single view rendered from its sensor's viewpoint, for the same check when there is no frame |
//! | visible | [`visible`] | the template's points a sensor sees at a pose, and a start placed so a one-sided source's centroid meets theirs |
//!
//! Working memory is one caller-owned `u16` slice of [`labels_len`]
//! elements (4 bytes a grid cell: 9.6 KB for a 224 x 172 frame at step 4).

pub mod cluster;
pub mod depth;
pub mod grid;
pub mod plane;
pub mod verify;
pub mod view;
pub mod visible;

pub use cluster::{Cluster, ClusterSearch, Clusters};
pub use depth::{DepthImage, Intrinsics, Organised, OrganisedPoints};
pub use grid::{Grid, Region};
pub use plane::{FoundPlane, Plane, PlaneSearch};
pub use verify::{Verification, VerifySettings};
pub use view::View;

use crate::error::Result;

/// Elements of the label slice [`segment`] needs for a `width x height`
/// frame sampled every `step` pixels (two `u16` a cell).
pub const fn labels_len(width: usize, height: usize, step: usize) -> usize {
    if step == 0 {
        return 0;
    }
    2 * width.div_ceil(step) * height.div_ceil(step)
}

/// Which plane to take out of the frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlaneChoice {
    /// Find the dominant plane ([`plane::find`]); none found is not an error.
    Find(PlaneSearch),
    /// The caller knows it (a fixed camera over a table).
    Given(Plane),
    /// Keep every point.
    None,
}

/// How to segment a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SceneOptions {
    /// Pixels between grid samples.
    pub step: usize,
    /// Only points in this box take part (sensor frame, user units).
    pub roi: Option<Region>,
    /// The plane the objects stand on.
    pub plane: PlaneChoice,
    /// How clusters form and which are kept.
    pub clusters: ClusterSearch,
    /// How a candidate's pose is checked against the frame (`None`: not
    /// checked; also unchecked when the frame's intrinsics are unknown).
    pub verify: Option<VerifySettings>,
    /// The template's up axis (template frame: the axis pointing away from
    /// the surface the object rests on). With a plane found or given, each
    /// candidate is registered by the yaw sweep about the plane's normal
    /// ([`crate::sweep`]) instead of the network's hypotheses.
    pub up: Option<[f32; 3]>,
    /// Yaw starts of the sweep.
    pub yaws: usize,
}

/// Yaw starts of a sweep unless asked otherwise ([`SceneOptions::yaws`],
/// `Sweep::new`): 30 degrees apart.
pub const DEFAULT_YAWS: usize = 12;

impl SceneOptions {
    /// Settings for an object of `radius` user units (the largest distance
    /// of its points from their mean): a 4-pixel grid; the plane within 2%
    /// of the object's diameter (RANSAC, 64 trials, at least 10% of the
    /// valid cells, seed 0); neighbouring cells join within 5% of the
    /// diameter (plus the pixels' own spacing, [`cluster`]); clusters of at
    /// least 8 cells whose radius is 35% to 160% of the object's (a view
    /// from one side sees part of it, around a centre of its own); poses
    /// verified against the frame ([`VerifySettings::for_object`]).
    pub fn for_object(radius: f32) -> Self {
        let size = 2.0 * radius;
        let plane_distance = 0.02 * size;
        SceneOptions {
            step: 4,
            roi: None,
            plane: PlaneChoice::Find(PlaneSearch {
                iterations: 64,
                distance: plane_distance,
                min_share: 0.1,
                seed: 0,
            }),
            clusters: ClusterSearch {
                max_gap: 0.05 * size,
                plane_distance,
                min_cells: 8,
                radius: [0.35 * radius, 1.6 * radius],
            },
            verify: Some(VerifySettings::for_object(radius)),
            up: None,
            yaws: DEFAULT_YAWS,
        }
    }
}

/// What [`segment`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// The grid it sampled.
    pub grid: Grid,
    /// The plane taken out: found (with its support) or given.
    pub plane: Option<Plane>,
    /// Grid cells on the plane when it was found (0 otherwise).
    pub plane_cells: u32,
    /// Grid cells holding a point in the region of interest.
    pub valid_cells: u32,
    /// The clusters, and why others were dropped.
    pub clusters: Clusters,
}

/// Runs the grid, plane and cluster stages over `frame`; `labels` (at
/// least [`labels_len`] elements) then holds every cell's cluster label
/// for [`Segmentation::gather`].
///
/// # Errors
/// [`crate::Error::InvalidFrame`] for a step of 0 or a grid of more than
/// [`grid::MAX_CELLS`] cells or a bad region of interest;
/// [`crate::Error::BufferTooSmall`] when `labels` is too short.
pub fn segment<F: Organised>(
    frame: &F,
    options: &SceneOptions,
    labels: &mut [u16],
) -> Result<Segmentation> {
    let grid = Grid::over(frame, options.step, options.roi)?;
    let (plane, plane_cells, valid_cells) = match options.plane {
        PlaneChoice::Find(search) => match plane::find(frame, &grid, &search) {
            Some(found) => (Some(found.plane), found.inliers, found.valid),
            None => (None, 0, grid.count(frame, |_| true)),
        },
        PlaneChoice::Given(p) => (Some(p), 0, grid.count(frame, |_| true)),
        PlaneChoice::None => (None, 0, grid.count(frame, |_| true)),
    };
    let clusters = cluster::label(frame, &grid, plane.as_ref(), &options.clusters, labels)?;
    Ok(Segmentation {
        grid,
        plane,
        plane_cells,
        valid_cells,
        clusters,
    })
}

impl Segmentation {
    /// Writes the points of `cluster` at full resolution into `out`
    /// ([`cluster::gather`]); `labels` as [`segment`] left it. Returns how
    /// many were written.
    pub fn gather<F: Organised>(
        &self,
        frame: &F,
        options: &SceneOptions,
        labels: &[u16],
        cluster: &Cluster,
        out: &mut [[f32; 3]],
    ) -> usize {
        cluster::gather(
            frame,
            &self.grid,
            self.plane.as_ref(),
            &options.clusters,
            labels,
            cluster,
            out,
        )
    }
}
