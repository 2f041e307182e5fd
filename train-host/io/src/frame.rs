//! Poses given back in the files' frame.
//!
//! Clouds far from their file's origin (map coordinates: easting about
//! 500,000 m, northing about 5,400,000 m) lose their shape when rounded to
//! `f32` (the spacing of `f32` at 5.4e6 is 0.5 m). `pcrnet register`
//! therefore reads both clouds in `f64` and moves them by one shared local
//! origin, the template's coordinate-wise median
//! ([`crate::read_cloud_local`]), before rounding; the methods run in
//! that local frame, and [`FilePose`] turns their pose back into the
//! files' frame in `f64`.
//!
//! With the local pose `q = R p + t` between local points
//! (`p = p_file - origin`, `q = q_file - origin`), the file-frame pose is
//! `q_file = R p_file + (t + origin - R origin)`. Its translation carries
//! the lever arm of the rotation about the file's origin: a rotation
//! error of 1e-7 rad moves it by 0.5 m at 5.4e6 m, while every point near
//! the object still lands within the local pose's accuracy. That is why
//! the local translation is reported beside it.

use pcrnet_core::Pose;

/// A rigid transform in the files' frame, in `f64`: `q = R p + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilePose {
    /// The local pose's rotation matrix (row-major), widened: the very
    /// rotation the method applied.
    pub rotation_matrix: [[f64; 3]; 3],
    /// Translation in file units, in the files' frame.
    pub translation: [f64; 3],
    /// The shared local origin the methods ran about (file units).
    pub origin: [f64; 3],
    /// The translation about `origin`, as the method computed it.
    pub local_translation: [f64; 3],
}

impl FilePose {
    /// The file-frame pose of `local`, a pose between clouds moved by
    /// `-origin` (see the module docs).
    pub fn from_local(local: &Pose, origin: [f64; 3]) -> FilePose {
        let rotation_matrix = local.rotation_matrix().map(|row| row.map(f64::from));
        let local_translation = local.translation.map(f64::from);
        let r_origin = rotate(&rotation_matrix, origin);
        let translation = [0, 1, 2].map(|k| local_translation[k] + origin[k] - r_origin[k]);
        FilePose {
            rotation_matrix,
            translation,
            origin,
            local_translation,
        }
    }

    /// The 4 x 4 homogeneous matrix, row-major.
    pub fn matrix(&self) -> [[f64; 4]; 4] {
        let r = self.rotation_matrix;
        let t = self.translation;
        [
            [r[0][0], r[0][1], r[0][2], t[0]],
            [r[1][0], r[1][1], r[1][2], t[1]],
            [r[2][0], r[2][1], r[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// `R p + t` for a point `p` in the files' frame.
    pub fn transform_point(&self, p: [f64; 3]) -> [f64; 3] {
        let rp = rotate(&self.rotation_matrix, p);
        [0, 1, 2].map(|k| rp[k] + self.translation[k])
    }
}

fn rotate(r: &[[f64; 3]; 3], p: [f64; 3]) -> [f64; 3] {
    r.map(|row| row[0] * p[0] + row[1] * p[1] + row[2] * p[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origin_zero_is_the_local_pose() {
        let local = Pose {
            rotation: [0.8, 0.6, 0.0, 0.0],
            translation: [1.0, -2.0, 0.5],
        };
        let f = FilePose::from_local(&local, [0.0; 3]);
        assert_eq!(f.translation, [1.0, -2.0, 0.5]);
        let m32 = local.matrix();
        for (row, row32) in f.matrix().iter().zip(m32) {
            assert_eq!(*row, row32.map(f64::from));
        }
    }

    #[test]
    fn file_pose_maps_file_points_like_the_local_pose_maps_local_points() {
        let local = Pose {
            rotation: [0.5, 0.5, -0.5, 0.5],
            translation: [0.25, -0.5, 0.125],
        };
        let origin = [500_000.25, 5_400_000.5, 120.0];
        let f = FilePose::from_local(&local, origin);
        let p_local = [0.3f32, -0.2, 0.7];
        let q_local = local.transform_point(p_local);
        let p_file = [0, 1, 2].map(|k| origin[k] + f64::from(p_local[k]));
        let q_file = f.transform_point(p_file);
        for k in 0..3 {
            let expected = origin[k] + f64::from(q_local[k]);
            assert!((q_file[k] - expected).abs() < 1e-6, "{q_file:?}");
        }
        assert_eq!(f.local_translation, [0.25, -0.5, 0.125]);
    }
}
