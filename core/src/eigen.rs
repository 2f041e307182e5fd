//! Small dense linear algebra for refinement: eigen-decomposition of small
//! symmetric matrices (3x3, 4x4) by cyclic Jacobi rotations, and a damped
//! Cholesky solve of symmetric positive semi-definite systems (6x6 for
//! point-to-plane ICP). Both in f32 with `libm::sqrtf` and single IEEE-754
//! operations in a fixed order, so the result is bit-identical on every
//! target. Used by ICP (Horn's quaternion, 4x4) and by the degeneracy check
//! of a source (its covariance, 3x3).
//!
//! Each rotation zeroes one off-diagonal entry (Golub & Van Loan,
//! *Matrix Computations*, 8.5: the stable choice of `t = tan(theta)` with
//! `|theta| <= pi/4`); sweeps stop when every off-diagonal entry is zero
//! or after [`MAX_SWEEPS`]. Jacobi converges quadratically: 4x4 matrices
//! reach f32 precision in 4-6 sweeps.

// Matrix code indexes rows and columns by name (p, q, k), as the textbook
// algorithm does; iterator forms would hide which entry is which.
#![allow(clippy::needless_range_loop)]

/// Most sweeps over all off-diagonal entries.
pub const MAX_SWEEPS: usize = 12;

/// Eigenvalues and eigenvectors of the symmetric matrix `a` (only its upper
/// triangle is read): returns `(values, vectors)` with `vectors[k]` the unit
/// eigenvector of `values[k]`, sorted by descending value.
pub fn symmetric<const N: usize>(mut a: [[f32; N]; N]) -> ([f32; N], [[f32; N]; N]) {
    for i in 0..N {
        for j in 0..i {
            a[i][j] = a[j][i];
        }
    }
    // v's columns are the eigenvectors.
    let mut v = [[0f32; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _ in 0..MAX_SWEEPS {
        let mut off = 0f32;
        for i in 0..N {
            for j in i + 1..N {
                off += libm::fabsf(a[i][j]);
            }
        }
        if off == 0.0 || !off.is_finite() {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                rotate(&mut a, &mut v, p, q);
            }
        }
    }
    let mut values = [0f32; N];
    let mut vectors = [[0f32; N]; N];
    for (k, (value, vector)) in values.iter_mut().zip(vectors.iter_mut()).enumerate() {
        *value = a[k][k];
        for (x, row) in vector.iter_mut().zip(&v) {
            *x = row[k];
        }
    }
    // Selection sort by descending value (stable: first index wins ties),
    // moving each vector with its value.
    for i in 0..N {
        let mut best = i;
        for j in i + 1..N {
            if values[j] > values[best] {
                best = j;
            }
        }
        values.swap(i, best);
        vectors.swap(i, best);
    }
    (values, vectors)
}

/// Solves `(A + lambda I) x = b` for a symmetric positive semi-definite `A`
/// (upper triangle read) by Cholesky, with `lambda = damping x trace(A) / N`
/// so that the factorisation exists even when the data leave directions
/// unconstrained (a planar source's in-plane motion, say): there `b`, a sum
/// of `J r` while `A` is the sum of `J J^T`, has no component either, so the
/// step along them is zero instead of undefined. Returns
/// `None` if `A` is zero or the factorisation fails (non-finite input).
pub fn solve_damped<const N: usize>(
    a: &[[f32; N]; N],
    b: &[f32; N],
    damping: f32,
) -> Option<[f32; N]> {
    let mut trace = 0f32;
    for i in 0..N {
        trace += a[i][i];
    }
    let lambda = damping * trace / N as f32;
    if !(lambda.is_finite() && lambda > 0.0) {
        return None;
    }
    // Lower-triangular L with L L^T = A + lambda I.
    let mut l = [[0f32; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let mut sum = if i == j { a[j][i] + lambda } else { a[j][i] };
            for k in 0..j {
                sum -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(sum > 0.0 && sum.is_finite()) {
                    return None;
                }
                l[i][i] = libm::sqrtf(sum);
            } else {
                l[i][j] = sum / l[j][j];
            }
        }
    }
    // L y = b, then L^T x = y.
    let mut y = [0f32; N];
    for i in 0..N {
        let mut sum = b[i];
        for k in 0..i {
            sum -= l[i][k] * y[k];
        }
        y[i] = sum / l[i][i];
    }
    let mut x = [0f32; N];
    for i in (0..N).rev() {
        let mut sum = y[i];
        for k in i + 1..N {
            sum -= l[k][i] * x[k];
        }
        x[i] = sum / l[i][i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// One Jacobi rotation in the (p, q) plane zeroing `a[p][q]`.
fn rotate<const N: usize>(a: &mut [[f32; N]; N], v: &mut [[f32; N]; N], p: usize, q: usize) {
    let apq = a[p][q];
    if apq == 0.0 {
        return;
    }
    let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
    // t = sign(theta) / (|theta| + sqrt(theta^2 + 1)); for huge theta,
    // theta^2 overflows and t ~ 1 / (2 theta).
    let t = if libm::fabsf(theta) > 1e18 {
        0.5 / theta
    } else {
        let t = 1.0 / (libm::fabsf(theta) + libm::sqrtf(theta * theta + 1.0));
        if theta < 0.0 { -t } else { t }
    };
    let c = 1.0 / libm::sqrtf(t * t + 1.0);
    let s = t * c;
    for k in 0..N {
        let (akp, akq) = (a[k][p], a[k][q]);
        a[k][p] = c * akp - s * akq;
        a[k][q] = s * akp + c * akq;
    }
    for k in 0..N {
        let (apk, aqk) = (a[p][k], a[q][k]);
        a[p][k] = c * apk - s * aqk;
        a[q][k] = s * apk + c * aqk;
    }
    a[p][q] = 0.0;
    a[q][p] = 0.0;
    for row in v.iter_mut() {
        let (vp, vq) = (row[p], row[q]);
        row[p] = c * vp - s * vq;
        row[q] = s * vp + c * vq;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diagonalises_a_symmetric_matrix() {
        let a = [
            [4.0f32, 1.0, -2.0, 0.5],
            [0.0, 3.0, 0.25, 1.0],
            [0.0, 0.0, -1.0, 2.0],
            [0.0, 0.0, 0.0, 0.5],
        ];
        let full = {
            let mut f = a;
            for i in 0..4 {
                for j in 0..i {
                    f[i][j] = f[j][i];
                }
            }
            f
        };
        let (values, vectors) = symmetric(a);
        assert!(values.windows(2).all(|w| w[0] >= w[1]));
        for k in 0..4 {
            let v = vectors[k];
            let n: f32 = v.iter().map(|x| x * x).sum();
            assert!((n - 1.0).abs() < 1e-5);
            for i in 0..4 {
                let av: f32 = (0..4).map(|j| full[i][j] * v[j]).sum();
                assert!((av - values[k] * v[i]).abs() < 1e-4, "{k} {i}");
            }
        }
        let trace: f32 = values.iter().sum();
        assert!((trace - 6.5).abs() < 1e-4);
    }

    #[test]
    fn damped_cholesky_solves_and_refuses_zero() {
        let a = [[4.0f32, 1.0, 0.0], [0.0, 3.0, 0.5], [0.0, 0.0, 2.0]];
        let b = [1.0f32, 2.0, 3.0];
        let x = solve_damped(&a, &b, 1e-9).unwrap();
        let full = [[4.0f32, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]];
        for i in 0..3 {
            let ax: f32 = (0..3).map(|j| full[i][j] * x[j]).sum();
            assert!((ax - b[i]).abs() < 1e-5);
        }
        assert_eq!(solve_damped(&[[0f32; 3]; 3], &b, 1e-3), None);
        // A direction A does not constrain (b, a sum of J r with A the sum of
        // J J^T, has no component there either) gets no step.
        let x = solve_damped(&[[1.0f32, 0.0], [0.0, 0.0]], &[2.0, 0.0], 1e-3).unwrap();
        assert!((x[0] - 2.0).abs() < 1e-2 && x[1] == 0.0);
    }

    #[test]
    fn diagonal_and_zero_matrices() {
        let (values, vectors) = symmetric([[1.0f32, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 2.0]]);
        assert_eq!(values, [3.0, 2.0, 1.0]);
        assert_eq!(vectors[0], [0.0, 1.0, 0.0]);
        let (values, _) = symmetric([[0f32; 3]; 3]);
        assert_eq!(values, [0.0; 3]);
    }
}
