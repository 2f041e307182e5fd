//! Generated tabletop depth frames with ground truth: boxes standing on a
//! table, seen by a pinhole depth camera pitched down at it, ray cast
//! pixel by pixel (no mesh, no allocation), so tests on the host and the
//! QEMU harness on a device make the same frame.

use crate::error::{Error, Result};
use crate::pose::Pose;
use crate::random::SplitMix64;
use crate::scene::depth::{Intrinsics, project};
use crate::scene::plane::{Plane, dot, sub};

/// A box standing on the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Block {
    /// Where its base's centre is on the table: along the table's x axis
    /// (the camera's x) and along its forward axis, metres from where the
    /// optical axis meets the table.
    pub at: [f32; 2],
    /// Width, depth (on the table) and height, metres.
    pub size: [f32; 3],
    /// Turn about the table's normal, radians.
    pub yaw: f32,
}

/// A point cloud placed in the camera's frame, drawn as discs (splats)
/// of `splat` radius with a z-buffer, as the host's z-buffer views are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed<'a> {
    /// The cloud in its own frame.
    pub points: &'a [[f32; 3]],
    /// Its pose: camera-frame point = `pose.transform_point(p)`.
    pub pose: Pose,
    /// Disc radius, the cloud's units (about its points' spacing).
    pub splat: f32,
}

/// A camera over a table with blocks and point clouds on it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tabletop<'a> {
    /// The camera's intrinsics.
    pub intrinsics: Intrinsics,
    /// Metres from the camera to where its optical axis meets the table.
    pub distance: f32,
    /// The camera's pitch below the horizontal, radians (0 < pitch <= pi/2).
    pub pitch: f32,
    /// The blocks.
    pub blocks: &'a [Block],
    /// Point clouds, drawn over the table and the blocks.
    pub clouds: &'a [Placed<'a>],
    /// Depth noise: uniform in +- this share of the depth squared (metres;
    /// 0.003 is about a consumer time-of-flight camera's at 1 m).
    pub noise: f32,
    /// Seed of the noise.
    pub seed: u64,
}

/// Raw depth units: millimetres.
pub const DEPTH_SCALE: f32 = 0.001;

impl Tabletop<'_> {
    /// The intrinsics of a 224 x 172 time-of-flight camera (about 60 x 48
    /// degrees).
    pub fn tof_intrinsics() -> Intrinsics {
        Intrinsics {
            fx: 194.0,
            fy: 194.0,
            cx: 111.5,
            cy: 85.5,
        }
    }

    /// The table's up axis in the camera frame (x right, y down, z forward).
    pub fn up(&self) -> [f32; 3] {
        let (s, c) = (libm::sinf(self.pitch), libm::cosf(self.pitch));
        [0.0, -c, -s]
    }

    /// The table's forward axis (on the table, away from the camera).
    fn forward(&self) -> [f32; 3] {
        let (s, c) = (libm::sinf(self.pitch), libm::cosf(self.pitch));
        [0.0, -s, c]
    }

    /// The table, as the scene stages report a plane (normal towards the camera).
    pub fn table(&self) -> Plane {
        let up = self.up();
        Plane {
            normal: up,
            offset: self.distance * libm::sinf(self.pitch),
        }
    }

    /// A block's base centre and its two axes on the table, camera frame.
    pub fn placement(&self, block: &Block) -> ([f32; 3], [f32; 3], [f32; 3]) {
        let f = self.forward();
        let origin = [0.0, 0.0, self.distance];
        let centre = [
            origin[0] + block.at[0],
            origin[1] + block.at[1] * f[1],
            origin[2] + block.at[1] * f[2],
        ];
        let (s, c) = (libm::sinf(block.yaw), libm::cosf(block.yaw));
        let a = [c, s * f[1], s * f[2]];
        let b = [-s, c * f[1], c * f[2]];
        (centre, a, b)
    }

    /// The camera-frame pose of an object standing on the table: its
    /// template-frame `up` axis (unit) along the table's normal, turned
    /// `yaw` about it, its lowest level along `up` (over `points`) on the
    /// table, its origin over `at` (as [`Block::at`]).
    pub fn stand(&self, points: &[[f32; 3]], up: [f32; 3], at: [f32; 2], yaw: f32) -> Pose {
        let table_up = self.up();
        // The shortest turn of `up` onto the table's normal, then the yaw.
        let w = 1.0 + dot(up, table_up);
        let c = cross(up, table_up);
        let align = if w > 1e-6 {
            [w, c[0], c[1], c[2]]
        } else {
            [0.0, 1.0, 0.0, 0.0]
        };
        let n = libm::sqrtf(align.iter().map(|v| v * v).sum::<f32>());
        let align = Pose {
            rotation: align.map(|v| v / n),
            translation: [0.0; 3],
        };
        let (s, c) = (libm::sinf(yaw / 2.0), libm::cosf(yaw / 2.0));
        let turn = Pose {
            rotation: [c, s * table_up[0], s * table_up[1], s * table_up[2]],
            translation: [0.0; 3],
        };
        let rotation = align.then(&turn);
        let base = points
            .iter()
            .map(|&p| dot(rotation.transform_point(p), table_up))
            .fold(f32::INFINITY, f32::min);
        let (centre, _, _) = self.placement(&Block {
            at,
            size: [0.0; 3],
            yaw: 0.0,
        });
        // The origin over `at`, then lifted so the base is on the table.
        let lift = -base;
        Pose {
            translation: [0, 1, 2].map(|i| centre[i] + table_up[i] * lift),
            ..rotation
        }
    }

    /// Renders the frame into `depth` (`width * height` millimetre values,
    /// row order, 0 where the ray meets nothing within 10 m).
    ///
    /// # Errors
    /// [`Error::BufferTooSmall`] when `depth` is shorter than `width * height`.
    pub fn render(&self, width: usize, height: usize, depth: &mut [u16]) -> Result<()> {
        let needed = width * height;
        if depth.len() < needed {
            return Err(Error::BufferTooSmall {
                needed: needed * 2,
                available: depth.len() * 2,
            });
        }
        let k = self.intrinsics;
        let table = self.table();
        let mut random = SplitMix64(self.seed);
        for v in 0..height {
            for u in 0..width {
                let ray = [(u as f32 - k.cx) / k.fx, (v as f32 - k.cy) / k.fy, 1.0];
                let mut nearest = f32::INFINITY;
                let toward = dot(table.normal, ray);
                if toward < 0.0 {
                    nearest = -table.offset / toward;
                }
                for block in self.blocks {
                    if let Some(t) = self.hit(block, ray) {
                        nearest = nearest.min(t);
                    }
                }
                depth[v * width + u] = to_raw(nearest);
            }
        }
        for cloud in self.clouds {
            self.splat(cloud, width, height, depth);
        }
        for d in depth[..needed].iter_mut() {
            let z = *d as f32 * DEPTH_SCALE;
            let noise = self.noise * z * z * (2.0 * random.unit() - 1.0);
            *d = if *d == 0 { 0 } else { to_raw(z + noise) };
        }
        Ok(())
    }

    /// Draws `cloud` into `depth` where it is nearer than what is there.
    fn splat(&self, cloud: &Placed, width: usize, height: usize, depth: &mut [u16]) {
        let k = &self.intrinsics;
        for &p in cloud.points {
            let Some(([pu, pv], z)) = project(k, cloud.pose.transform_point(p)) else {
                continue;
            };
            let raw = to_raw(z);
            let r = cloud.splat * k.fx / z;
            let (u0, u1) = (libm::floorf(pu - r), libm::ceilf(pu + r));
            let (v0, v1) = (libm::floorf(pv - r), libm::ceilf(pv + r));
            for v in (v0.max(0.0) as usize)..=(v1.max(0.0) as usize).min(height - 1) {
                for u in (u0.max(0.0) as usize)..=(u1.max(0.0) as usize).min(width - 1) {
                    let (du, dv) = (u as f32 - pu, v as f32 - pv);
                    let d = &mut depth[v * width + u];
                    if du * du + dv * dv <= r * r && (*d == 0 || raw < *d) {
                        *d = raw;
                    }
                }
            }
        }
    }

    /// Where the ray `t * ray` first enters `block` (its `t`, which is the
    /// depth since `ray.z = 1`): the slab test in the block's frame.
    fn hit(&self, block: &Block, ray: [f32; 3]) -> Option<f32> {
        let (centre, a, b) = self.placement(block);
        let up = self.up();
        let axes = [a, up, b];
        let lo = [-block.size[0] / 2.0, 0.0, -block.size[1] / 2.0];
        let hi = [block.size[0] / 2.0, block.size[2], block.size[1] / 2.0];
        let origin = sub([0.0; 3], centre);
        let (mut enter, mut leave) = (0f32, f32::INFINITY);
        for i in 0..3 {
            let o = dot(axes[i], origin);
            let d = dot(axes[i], ray);
            if libm::fabsf(d) < 1e-9 {
                if o < lo[i] || o > hi[i] {
                    return None;
                }
                continue;
            }
            let (t0, t1) = ((lo[i] - o) / d, (hi[i] - o) / d);
            enter = enter.max(t0.min(t1));
            leave = leave.min(t0.max(t1));
        }
        (enter <= leave && enter > 0.0).then_some(enter)
    }
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Millimetres of a depth in metres (0, no point, beyond 10 m or for a
/// non-finite depth).
fn to_raw(z: f32) -> u16 {
    if z.is_finite() && z > 0.0 && z < 10.0 {
        libm::roundf(z / DEPTH_SCALE) as u16
    } else {
        0
    }
}

/// Where the harness's `follow` run starts: the winner's pose and the
/// plane of `located` (the sweep's), or the identity and no plane when it
/// found nothing.
pub fn follow_start(located: &crate::locate::Located) -> (Pose, Option<Plane>) {
    (
        located.best.map_or(Pose::IDENTITY, |b| b.registration.pose),
        located.segmentation.plane,
    )
}

/// The QEMU harness's frame: 224 x 172 pixels (the time-of-flight camera).
pub const HARNESS_WIDTH: usize = 224;
/// Rows of the harness's frame.
pub const HARNESS_HEIGHT: usize = 172;
/// Candidates the harness registers.
pub const HARNESS_CANDIDATES: usize = 3;
/// The template axis the harness's object stands on (and the sweep's up axis).
pub const HARNESS_UP: [f32; 3] = [0.0, 0.0, 1.0];

/// Renders the harness's frame for `model` into `depth` (at least
/// [`HARNESS_WIDTH`] x [`HARNESS_HEIGHT`]): the model's stored template
/// points (user units, as many as `template` holds) standing on their z
/// axis ([`HARNESS_UP`]) on a table 4.3 object radii from a camera pitched
/// 55 degrees down, turned 200 degrees about the table's normal, beside two
/// blocks of about the object's size; noise 0.2% of depth squared. The same
/// frame on every target: single f32 operations and `libm`.
///
/// Returns the object's pose (template frame -> camera frame); a
/// registration should return its inverse (or a turn about a symmetry of
/// the template).
///
/// # Errors
/// [`Error::BufferTooSmall`] when `depth` is too short.
pub fn harness_frame(
    model: &crate::Int8Model,
    template: &mut [[f32; 3]],
    depth: &mut [u16],
) -> Result<Pose> {
    let t = model.template();
    let n = t.len().min(template.len());
    for (i, p) in template.iter_mut().enumerate().take(n) {
        *p = t.user_point(i, model.frame());
    }
    let points = &template[..n];
    let r = model.object_radius();
    let distance = 4.3 * r;
    let table = Tabletop {
        intrinsics: Tabletop::tof_intrinsics(),
        distance,
        pitch: 55f32.to_radians(),
        blocks: &[],
        clouds: &[],
        noise: 0.002,
        seed: 3,
    };
    // Standing on its z axis, turned 200 degrees: outside the network's range.
    let pose = table.stand(
        points,
        HARNESS_UP,
        [0.1 * r, -0.05 * r],
        200f32.to_radians(),
    );
    let blocks = [
        Block {
            at: [1.55 * r, 0.5 * r],
            size: [0.5 * r, 0.85 * r, 0.7 * r],
            yaw: 0.4,
        },
        Block {
            at: [1.05 * r, -1.05 * r],
            size: [0.85 * r, 0.85 * r, 0.85 * r],
            yaw: 0.0,
        },
    ];
    let clouds = [Placed {
        points,
        pose,
        splat: 0.05 * r,
    }];
    Tabletop {
        blocks: &blocks,
        clouds: &clouds,
        ..table
    }
    .render(HARNESS_WIDTH, HARNESS_HEIGHT, depth)?;
    Ok(pose)
}

/// The harness frame as the depth image the scene stages read.
///
/// # Errors
/// As [`crate::scene::DepthImage::new`].
pub fn harness_image(depth: &[u16]) -> Result<crate::scene::DepthImage<'_>> {
    crate::scene::DepthImage::new(
        depth,
        HARNESS_WIDTH,
        HARNESS_HEIGHT,
        HARNESS_WIDTH,
        Tabletop::tof_intrinsics(),
        DEPTH_SCALE,
        0,
    )
}

/// Writes what [`crate::Int8Model::locate`] found as words (f32 as hex
/// bits), so the harness compares device and host bit for bit: the plane,
/// the cell counts, every kept cluster, every candidate's registration
/// and verification, and the winner.
pub fn describe(
    located: &crate::locate::Located,
    out: &mut impl core::fmt::Write,
) -> core::fmt::Result {
    let s = &located.segmentation;
    match s.plane {
        Some(p) => {
            write!(out, "plane")?;
            for v in p.normal.iter().chain([&p.offset]) {
                write!(out, " {:08x}", v.to_bits())?;
            }
        }
        None => write!(out, "plane none")?,
    }
    let c = &s.clusters;
    write!(
        out,
        " cells {} {} {} clusters {} {} {} {}",
        s.valid_cells,
        s.plane_cells,
        c.foreground,
        c.too_few_cells,
        c.wrong_radius,
        c.unmeasured,
        c.kept.len()
    )?;
    for k in &c.kept {
        write!(out, " c {} {}", k.label, k.cells)?;
        for v in k.centroid.iter().chain([&k.radius]) {
            write!(out, " {:08x}", v.to_bits())?;
        }
    }
    for t in &located.tried {
        let r = &t.registration;
        write!(out, " t {} {}", t.cluster, t.points)?;
        for v in r.pose.rotation.iter().chain(&r.pose.translation) {
            write!(out, " {:08x}", v.to_bits())?;
        }
        write!(
            out,
            " {:08x} {:08x} {} {} {}",
            r.relative_plane_residual.to_bits(),
            r.fitness.to_bits(),
            r.hypothesis,
            r.icp_iterations,
            r.reliable
        )?;
        match t.verification {
            Some(v) => write!(
                out,
                " v {} {} {} {} {} {}",
                v.supported, v.violations, v.occluded, v.unobserved, v.outside, v.passed
            )?,
            None => write!(out, " v none")?,
        }
        write!(out, " {} ", t.reliable)?;
        super::describe_ambiguity(&r.ambiguity, out)?;
    }
    match located.best {
        Some(b) => write!(out, " best {}", b.cluster),
        None => write!(out, " best none"),
    }
}
