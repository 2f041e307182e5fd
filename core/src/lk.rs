//! PointNetLK's update on the device (Aoki et al., *PointNetLK: Robust &
//! Efficient Point Cloud Registration using PointNet*, CVPR 2019): the
//! Lucas-Kanade step in feature space, with the template's side computed
//! once on the host.
//!
//! For the template `T` and the encoder's global feature `phi` (`F` values),
//! the exporter computes the Jacobian of `phi` with respect to a twist
//! `xi = (omega, v)` (rotation vector, radians; translation, model units)
//! by finite differences about the template (f32:
//! `J[:, k] = (phi(exp(d e_k) T) - phi(T)) / d` as in training; int8:
//! central differences of a larger step, see `pcrnet_train::lk_solver`),
//! and stores its damped
//! pseudo-inverse `P = (J^T J + lambda I)^-1 J^T` (`6 x F`) in the blob
//! ([`crate::format::LkSolver`]). Each LK step then costs one encoder pass
//! of the source moved by the pose so far `G`, and:
//! - the feature residual `r = phi(G S) - phi(T)`;
//! - the twist `dxi = P r`: six dot products of `F` terms, f32, summed in
//!   feature order (so every core gets the same bits);
//! - the update `G <- exp(dxi)^-1 G` (inverse compositional), so that
//!   `G S` moves onto `T`.
//!
//! In an int8 blob the residual is taken on the int8 features,
//! `r_j = q_S[j] - q_T[j]` (exact integers; the zero point cancels), and
//! `J` in the same int8 steps, computed by the int8 encoder itself, so the
//! feature's scale cancels between them (the damping is relative to
//! `J^T J`'s trace). In an f32 blob both are f32.
//!
//! `exp` uses `libm` explicitly (the quaternion's `cos`/`sin` of half the
//! angle, the translation's left Jacobian of SO(3)), with the Taylor series
//! of its coefficients below [`SERIES_BELOW`] radians where the closed form
//! cancels in f32.

use crate::error::{Error, Result};
use crate::format::{LkSolver, expect_len, le_f32s};
use crate::pose::Pose;

/// Twist dimension: rotation vector then translation.
pub const TWIST_DIM: usize = 6;

/// Rotation angle (radians) below which `exp` takes the Taylor series of
/// its coefficients: there the closed forms `(1 - cos t) / t^2` and
/// `(t - sin t) / t^3` lose most of their bits in f32, and the series'
/// first omitted terms are below `t^4 / 720 < 2e-7`.
pub const SERIES_BELOW: f32 = 0.1;

/// The stored pseudo-inverse `P` (`6 x F` f32 little-endian, row-major by
/// twist component), checked: the right length, every entry finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solver<'a> {
    stored: LkSolver<'a>,
    rows: &'a [u8],
    features: usize,
}

impl<'a> Solver<'a> {
    /// Checks a stored solver for features of `features` entries.
    pub fn new(stored: LkSolver<'a>, features: usize) -> Result<Self> {
        let rows = stored.rows;
        let entries = features
            .checked_mul(TWIST_DIM)
            .ok_or(Error::InconsistentDimensions {
                what: "LK solver size",
            })?;
        expect_len(rows, entries, 4, "LK solver (6 x feature f32)")?;
        if le_f32s(rows).any(|v| !v.is_finite()) {
            return Err(Error::InvalidParameter {
                what: "LK solver entry not finite",
            });
        }
        Ok(Solver {
            stored,
            rows,
            features,
        })
    }

    /// The blob's record of this solver.
    pub fn stored(&self) -> LkSolver<'a> {
        self.stored
    }

    /// Feature entries per row (`F`).
    pub fn features(&self) -> usize {
        self.features
    }

    /// `dxi = P r` for the residual `residual(j)`, `j = 0..F`: each
    /// component an f32 sum in feature order.
    pub fn twist(&self, residual: impl Fn(usize) -> f32) -> [f32; TWIST_DIM] {
        let mut dxi = [0f32; TWIST_DIM];
        // `new` checked that the rows hold 6 x F values: each split succeeds.
        let width = 4 * self.features;
        let mut rest = self.rows;
        for d in dxi.iter_mut() {
            let Some((row, tail)) = rest.split_at_checked(width) else {
                break;
            };
            rest = tail;
            let mut acc = 0f32;
            for (j, p) in le_f32s(row).enumerate() {
                acc += p * residual(j);
            }
            *d = acc;
        }
        dxi
    }

    /// The step's pose, `exp(dxi)^-1`, for the residual `residual(j)`
    /// ([`Error::NonFiniteResult`] if the twist is not finite).
    pub fn step(&self, residual: impl Fn(usize) -> f32) -> Result<Pose> {
        let dxi = self.twist(residual);
        if dxi.iter().all(|v| v.is_finite()) {
            Ok(exp(&dxi).inverse())
        } else {
            Err(Error::NonFiniteResult)
        }
    }
}

/// A blob's solver, checked for features of `features` entries (none
/// when the blob has none); a blob without a `head` must have one
/// ([`Error::InconsistentDimensions`] otherwise). Not inlined: the
/// loaders' frames stay as they were (their stack counts on a 16 KiB
/// device).
#[inline(never)]
pub fn solver(
    stored: Option<LkSolver<'_>>,
    features: usize,
    head: bool,
) -> Result<Option<Solver<'_>>> {
    match stored {
        Some(s) => Solver::new(s, features).map(Some),
        None if head => Ok(None),
        None => Err(Error::InconsistentDimensions {
            what: "a blob without a head needs PointNetLK's solver",
        }),
    }
}

/// The se(3) exponential of a twist `(omega, v)`: the rotation by the
/// angle `|omega|` about `omega`, and the translation `J_l(omega) v` with
/// `J_l = I + a [omega]x + b [omega]x^2`, `a = (1 - cos t) / t^2`,
/// `b = (t - sin t) / t^3`.
pub fn exp(xi: &[f32; TWIST_DIM]) -> Pose {
    let [wx, wy, wz, vx, vy, vz] = *xi;
    let t2 = wx * wx + wy * wy + wz * wz;
    let t = libm::sqrtf(t2);
    // sin(t / 2) / t, a, b.
    let (half, a, b) = if t < SERIES_BELOW {
        (0.5 - t2 / 48.0, 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        (
            libm::sinf(0.5 * t) / t,
            (1.0 - libm::cosf(t)) / t2,
            (t - libm::sinf(t)) / (t2 * t),
        )
    };
    let c = if t < SERIES_BELOW {
        1.0 - t2 / 8.0
    } else {
        libm::cosf(0.5 * t)
    };
    // [omega]x v and [omega]x ([omega]x v).
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let w = [wx, wy, wz];
    let wv = cross(w, [vx, vy, vz]);
    let wwv = cross(w, wv);
    let rotation = [c, half * wx, half * wy, half * wz];
    Pose {
        rotation: if c < 0.0 {
            rotation.map(|v| -v)
        } else {
            rotation
        },
        translation: [
            vx + a * wv[0] + b * wwv[0],
            vy + a * wv[1] + b * wwv[1],
            vz + a * wv[2] + b * wwv[2],
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stored(rows: &[u8]) -> LkSolver<'_> {
        LkSolver {
            jacobian_step: 0.01,
            central: false,
            damping: 1e-6,
            rows,
        }
    }

    fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    /// A pure rotation about z by 0.5 rad, and a pure translation.
    #[test]
    fn exp_of_simple_twists() {
        let r = exp(&[0.0, 0.0, 0.5, 0.0, 0.0, 0.0]);
        let p = r.transform_point([1.0, 0.0, 0.0]);
        assert!(close(p, [0.5f32.cos(), 0.5f32.sin(), 0.0], 1e-6), "{p:?}");
        let t = exp(&[0.0, 0.0, 0.0, 0.1, -0.2, 0.3]);
        assert_eq!(t.rotation, [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(t.translation, [0.1, -0.2, 0.3]);
    }

    /// The series and the closed form meet at the switch, and the screw
    /// motion's translation follows the rotation (a twist about z with
    /// v along x moves the origin on the circle's chord).
    #[test]
    fn series_and_closed_form_agree() {
        let below = exp(&[0.0, 0.0, SERIES_BELOW * 0.99999, 1.0, 0.0, 0.0]);
        let above = exp(&[0.0, 0.0, SERIES_BELOW * 1.00001, 1.0, 0.0, 0.0]);
        assert!(close(below.translation, above.translation, 1e-5));
        assert!((below.rotation[0] - above.rotation[0]).abs() < 1e-5);
        // Rotation by t about z with v = (1, 0, 0): t = (sin t, 1 - cos t, 0) / t.
        let th = 1.2f32;
        let s = exp(&[0.0, 0.0, th, 1.0, 0.0, 0.0]);
        let want = [th.sin() / th, (1.0 - th.cos()) / th, 0.0];
        assert!(close(s.translation, want, 1e-6), "{:?}", s.translation);
    }

    /// A linear feature model, `phi(exp(xi) T) = phi(T) + J xi`, is solved
    /// in one step by the pseudo-inverse: a row-wise `P` that picks each
    /// component recovers the twist, and the step is its inverse.
    #[test]
    fn step_inverts_the_twist() {
        // F = 6, P = I (row k picks feature k).
        let mut bytes = [0u8; 6 * 6 * 4];
        for k in 0..6 {
            bytes[4 * (6 * k + k)..][..4].copy_from_slice(&1f32.to_le_bytes());
        }
        let solver = Solver::new(stored(&bytes), 6).unwrap();
        let xi = [0.02, -0.01, 0.03, 0.05, 0.0, -0.02];
        assert_eq!(solver.twist(|j| xi[j]), xi);
        let step = solver.step(|j| xi[j]).unwrap();
        let id = exp(&xi).then(&step);
        assert!(id.distance_to_identity_squared() < 1e-12);
    }

    #[test]
    fn rejects_bad_solvers() {
        assert!(matches!(
            Solver::new(stored(&[0u8; 20]), 1),
            Err(Error::InconsistentDimensions { .. })
        ));
        let mut nan = [0u8; 24];
        nan[..4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(
            Solver::new(stored(&nan), 1),
            Err(Error::InvalidParameter { .. })
        ));
        let huge = f32::MAX.to_le_bytes().repeat(6);
        let s = Solver::new(stored(&huge), 1).unwrap();
        assert_eq!(s.step(|_| 10.0), Err(Error::NonFiniteResult));
    }
}
