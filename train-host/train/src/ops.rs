//! Batched layer primitives with hand-written backward passes.
//!
//! Matrices are row-major `f32` slices. Every matrix product goes through
//! [`gemm`] (ndarray's safe front end to `matrixmultiply`'s sgemm, with
//! `matrixmultiply`'s own threading). `matrixmultiply` splits the work
//! between threads over blocks of *output* rows and columns and never over
//! the summed dimension, so every output element is summed in the same order
//! whatever the thread count: the products are deterministic. Every other
//! reduction here (bias gradients, max-pool) is a plain sequential loop.

use ndarray::linalg::general_mat_mul;
use ndarray::{ArrayView2, ArrayViewMut2};

/// A row-major matrix view of `s` (`rows x cols`).
fn view(s: &[f32], rows: usize, cols: usize) -> ArrayView2<'_, f32> {
    ArrayView2::from_shape((rows, cols), s).expect("matrix size matches its slice")
}

fn view_mut(s: &mut [f32], rows: usize, cols: usize) -> ArrayViewMut2<'_, f32> {
    ArrayViewMut2::from_shape((rows, cols), s).expect("matrix size matches its slice")
}

/// Whether an operand of [`gemm`] is used as stored or transposed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Op {
    /// As stored.
    N,
    /// Transposed.
    T,
}

/// `C (m x n) = A' B' + beta C` where `A' = op_a(A)` is `m x k` and
/// `B' = op_b(B)` is `k x n`; `A` and `B` are stored row-major in their
/// untransposed shapes (`A` is `k x m` when `op_a` is [`Op::T`]).
#[allow(clippy::too_many_arguments)]
pub fn gemm(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    op_a: Op,
    b: &[f32],
    op_b: Op,
    beta: f32,
    c: &mut [f32],
) {
    let av = match op_a {
        Op::N => view(a, m, k),
        Op::T => view(a, k, m).reversed_axes(),
    };
    let bv = match op_b {
        Op::N => view(b, k, n),
        Op::T => view(b, n, k).reversed_axes(),
    };
    let mut cv = view_mut(c, m, n);
    general_mat_mul(1.0, &av, &bv, beta, &mut cv);
}

/// Dense layer forward over `rows` inputs: `y = x W^T + b`
/// (`x`: rows x in, `w`: out x in, `y`: rows x out). No activation.
pub fn dense_forward(x: &[f32], w: &[f32], b: &[f32], rows: usize, y: &mut [f32]) {
    let out = b.len();
    let inp = w.len() / out;
    debug_assert_eq!(x.len(), rows * inp);
    debug_assert_eq!(y.len(), rows * out);
    for r in y.chunks_exact_mut(out) {
        r.copy_from_slice(b);
    }
    gemm(rows, inp, out, x, Op::N, w, Op::T, 1.0, y);
}

/// Rows per block of the parallel weight-gradient sum in [`dense_backward`].
pub const ROW_BLOCK: usize = 8192;

/// Dense layer backward: accumulates `dw += dy^T x` and `db += sum_rows dy`,
/// and writes `dx = dy W` when asked.
pub fn dense_backward(
    x: &[f32],
    w: &[f32],
    dy: &[f32],
    rows: usize,
    dw: &mut [f32],
    db: &mut [f32],
    dx: Option<&mut [f32]>,
) {
    use rayon::prelude::*;
    let out = db.len();
    let inp = w.len() / out;
    debug_assert_eq!(dy.len(), rows * out);
    if rows > ROW_BLOCK {
        // A long sum over rows with a small output: matrixmultiply would run
        // it on one thread. Fixed row blocks in parallel, partial sums added
        // in block order: deterministic whatever the thread count.
        let partials: Vec<Vec<f32>> = (0..rows.div_ceil(ROW_BLOCK))
            .into_par_iter()
            .map(|k| {
                let (r0, r1) = (k * ROW_BLOCK, ((k + 1) * ROW_BLOCK).min(rows));
                let mut p = vec![0.0; out * inp];
                gemm(
                    out,
                    r1 - r0,
                    inp,
                    &dy[r0 * out..r1 * out],
                    Op::T,
                    &x[r0 * inp..r1 * inp],
                    Op::N,
                    0.0,
                    &mut p,
                );
                p
            })
            .collect();
        for p in partials {
            for (d, v) in dw.iter_mut().zip(p) {
                *d += v;
            }
        }
    } else {
        gemm(out, rows, inp, dy, Op::T, x, Op::N, 1.0, dw);
    }
    for r in dy.chunks_exact(out) {
        for (d, g) in db.iter_mut().zip(r) {
            *d += g;
        }
    }
    if let Some(dx) = dx {
        gemm(rows, out, inp, dy, Op::N, w, Op::N, 0.0, dx);
    }
}

/// ReLU in place.
pub fn relu(y: &mut [f32]) {
    for v in y {
        if *v < 0.0 {
            *v = 0.0;
        }
    }
}

/// ReLU backward from the activation's *output* `y`: zeroes `dy` where
/// `y <= 0` (the derivative at 0 is taken as 0).
pub fn relu_backward(y: &[f32], dy: &mut [f32]) {
    for (d, &v) in dy.iter_mut().zip(y) {
        if v <= 0.0 {
            *d = 0.0;
        }
    }
}

/// Max over the `n` points of each of `clouds` clouds (`x`: clouds*n x c).
/// Returns the maxima (clouds x c) and the winning point of each
/// (the first one on ties).
pub fn maxpool_forward(x: &[f32], clouds: usize, n: usize, c: usize) -> (Vec<f32>, Vec<u32>) {
    let mut vals = vec![f32::NEG_INFINITY; clouds * c];
    let mut arg = vec![0u32; clouds * c];
    for b in 0..clouds {
        maxpool_into(
            &x[b * n * c..(b + 1) * n * c],
            c,
            &mut vals[b * c..(b + 1) * c],
            &mut arg[b * c..(b + 1) * c],
        );
    }
    (vals, arg)
}

/// Max-pool of one cloud (`x`: n x c) into `vals`, `arg` (length c).
fn maxpool_into(x: &[f32], c: usize, vals: &mut [f32], arg: &mut [u32]) {
    vals.fill(f32::NEG_INFINITY);
    arg.fill(0);
    for (p, row) in x.chunks_exact(c).enumerate() {
        for ((v, a), &y) in vals.iter_mut().zip(arg.iter_mut()).zip(row) {
            if y > *v {
                *v = y;
                *a = p as u32;
            }
        }
    }
}

/// Max-pool backward: the gradient of each maximum goes to its winning point
/// only (`dx`: clouds*n x c, zero elsewhere).
pub fn maxpool_backward(arg: &[u32], dvals: &[f32], clouds: usize, n: usize, c: usize) -> Vec<f32> {
    let mut dx = vec![0.0; clouds * n * c];
    for b in 0..clouds {
        for ch in 0..c {
            let p = arg[b * c + ch] as usize;
            dx[(b * n + p) * c + ch] += dvals[b * c + ch];
        }
    }
    dx
}

/// The encoder's last layer fused with the max-pool: for each cloud,
/// `max over points of (x W^T + b)` (before ReLU; ReLU commutes with max).
/// Computed `chunk` clouds at a time so the `n x out` activations of the
/// whole batch are never stored. Returns the maxima and winning points.
pub fn dense_maxpool_forward(
    x: &[f32],
    w: &[f32],
    b: &[f32],
    clouds: usize,
    n: usize,
    chunk: usize,
) -> (Vec<f32>, Vec<u32>) {
    use rayon::prelude::*;
    let out = b.len();
    let inp = w.len() / out;
    let chunk = chunk.max(1);
    let mut vals = vec![0.0; clouds * out];
    let mut arg = vec![0u32; clouds * out];
    let mut y = vec![0.0; chunk.min(clouds) * n * out];
    let mut start = 0;
    while start < clouds {
        let k = chunk.min(clouds - start);
        let y = &mut y[..k * n * out];
        // No bias here: max(y + b) = max(y) + b (rounding is monotonic), so
        // the bias is added to the maxima only, saving a pass over `y`.
        let xs = &x[start * n * inp..(start + k) * n * inp];
        gemm(k * n, inp, out, xs, Op::N, w, Op::T, 0.0, y);
        vals[start * out..(start + k) * out]
            .par_chunks_mut(out)
            .zip(arg[start * out..(start + k) * out].par_chunks_mut(out))
            .zip(y.par_chunks(n * out))
            .for_each(|((v, a), yc)| maxpool_into(yc, out, v, a));
        start += k;
    }
    for v in vals.chunks_exact_mut(out) {
        for (x, bias) in v.iter_mut().zip(b) {
            *x += bias;
        }
    }
    (vals, arg)
}

/// Backward of [`dense_maxpool_forward`]: only the winning points receive
/// gradient, so this costs `clouds x out x in` instead of a full GEMM.
/// Accumulates into `dw`, `db`; writes `dx` (clouds*n x in) when asked.
#[allow(clippy::too_many_arguments)]
pub fn dense_maxpool_backward(
    x: &[f32],
    w: &[f32],
    arg: &[u32],
    dpre: &[f32],
    clouds: usize,
    n: usize,
    dw: &mut [f32],
    db: &mut [f32],
    dx: Option<&mut [f32]>,
) {
    use rayon::prelude::*;
    let out = db.len();
    let inp = w.len() / out;
    // dW row by row in parallel; each row sums over clouds in order.
    dw.par_chunks_mut(inp)
        .zip(db.par_iter_mut())
        .enumerate()
        .for_each(|(o, (row, bias))| {
            for cl in 0..clouds {
                let g = dpre[cl * out + o];
                if g == 0.0 {
                    continue;
                }
                *bias += g;
                let p = arg[cl * out + o] as usize;
                let xr = &x[(cl * n + p) * inp..(cl * n + p + 1) * inp];
                for (d, &xv) in row.iter_mut().zip(xr) {
                    *d += g * xv;
                }
            }
        });
    if let Some(dx) = dx {
        // dX cloud by cloud in parallel; each cloud's rows sum over outputs in order.
        dx.par_chunks_mut(n * inp)
            .enumerate()
            .for_each(|(cl, dxc)| {
                dxc.fill(0.0);
                for o in 0..out {
                    let g = dpre[cl * out + o];
                    if g == 0.0 {
                        continue;
                    }
                    let p = arg[cl * out + o] as usize;
                    let wr = &w[o * inp..(o + 1) * inp];
                    for (d, &wv) in dxc[p * inp..(p + 1) * inp].iter_mut().zip(wr) {
                        *d += g * wv;
                    }
                }
            });
    }
}
