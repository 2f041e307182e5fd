//! The network shape, shared by the f32 reference path and the int8 path.
//!
//! ```text
//! points (n x 3) --[encoder: per-point dense + ReLU, widths e1..ek]--> (n x ek)
//!                --[max over points]--> source feature (F = ek)
//! [template feature (F) | source feature (F)] (2F)
//!                --[head: dense + ReLU, widths h1..hm]--> --[dense, no ReLU]--> 7
//! ```
//!
//! The 7 outputs are `[qw, qx, qy, qz, tx, ty, tz]`: a quaternion (scalar
//! first, normalised after the network, see [`crate::pose`]) and a translation.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Dimension of an input point (x, y, z).
pub const INPUT_DIM: usize = 3;
/// Number of head outputs: quaternion (4) then translation (3).
pub const POSE_DIM: usize = 7;
/// Most layers the encoder or the head may have.
pub const MAX_LAYERS: usize = 8;
/// Most points the int8 encoder pushes through the layers together (see [`crate::int8`]).
pub const MAX_TILE: usize = 8;
/// Points the int8 encoder's host block kernel (x86-64, aarch64) pushes
/// through the layers together, given [`Arch::host_block_len`] more bytes
/// of scratch (see [`crate::Int8Model::host_scratch_len`]): four vectors
/// of sixteen points with AVX-512, sixteen accumulators with four rows at
/// a time; 1,024 points make 16 whole blocks. 64 points ran 14% faster than 48 (A/B, best
/// rounds, Xeon with AVX-512 VNNI; 7-9% on its AVX2 route).
pub const HOST_BLOCK: usize = 64;
/// Points the f32 encoder's host kernel pushes through the layers together
/// (see [`crate::float::F32Network::tiled_scratch_len`]).
pub const F32_TILE: usize = 16;

/// Encoder widths of the paper (PointNet 64-64-64-128-1024).
pub const PAPER_ENCODER: &[u16] = &[64, 64, 64, 128, 1024];
/// Head widths of the paper's single-pass PCRNet (then 7 outputs).
pub const PCRNET_HEAD: &[u16] = &[1024, 1024, 512, 512, 256];
/// Head widths of the paper's iterative i-PCRNet (then 7 outputs).
pub const IPCRNET_HEAD: &[u16] = &[1024, 512, 256];

/// Layer widths of a PCRNet: the encoder's and the head's hidden layers.
///
/// The input (3) and the output (7) are fixed and not listed. Every encoder
/// layer and every hidden head layer is followed by ReLU; the output layer is
/// linear.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Arch {
    /// Encoder output widths, first to last; the last one is the feature size.
    pub encoder: heapless::Vec<u16, MAX_LAYERS>,
    /// Hidden head widths, first to last (may be empty).
    pub head: heapless::Vec<u16, MAX_LAYERS>,
}

/// One dense layer of the network, as seen by both paths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LayerShape {
    /// Input width.
    pub inputs: usize,
    /// Output width.
    pub outputs: usize,
    /// Whether ReLU follows.
    pub relu: bool,
}

impl LayerShape {
    /// Multiply-accumulates per evaluation (per point for the encoder).
    pub const fn macs(&self) -> usize {
        self.inputs * self.outputs
    }
    /// Words of its weights as int16 pairs, each row padded to an even
    /// length (the x86-64 host block kernel's copy).
    pub(crate) const fn pair_words(&self) -> usize {
        self.outputs * self.inputs.div_ceil(2)
    }
    /// Number of weights plus biases.
    pub const fn parameters(&self) -> usize {
        self.inputs * self.outputs + self.outputs
    }
}

/// The host block kernel's scratch ([`Arch::host_block_len`]), in words.
pub(crate) struct HostBlockWords {
    /// The encoder's weights as int16 pairs ([`LayerShape::pair_words`]),
    /// each row padded to an even length (a pooled layer that runs on
    /// bytes copies its own only for blocks the byte kernel declines).
    pub weights: usize,
    /// The rows' weight sums of every layer after the first (one per
    /// output), for the byte kernels.
    pub sums: usize,
    /// A pooled layer on bytes: the list of its input quads that take the
    /// AVX2 kernel's high-bit pass.
    pub quads: usize,
    /// The pooled layer's largest accumulators over the blocks so far (one
    /// per output).
    pub maxima: usize,
    /// One activation buffer: [`HOST_BLOCK`] points x the widest layer
    /// input in int16 pairs (the coordinates count as four), or x the
    /// pooled layer's input as two sets of byte quads if that is more.
    pub buffer: usize,
}

impl Arch {
    /// Builds an architecture from width lists, checking the limits
    /// (1..=`MAX_LAYERS` encoder layers, 0..=`MAX_LAYERS` head layers, widths >= 1).
    pub fn new(encoder: &[u16], head: &[u16]) -> Result<Self> {
        let too_many = Error::InconsistentDimensions {
            what: "more layers than MAX_LAYERS",
        };
        let arch = Arch {
            encoder: heapless::Vec::from_slice(encoder).map_err(|_| too_many)?,
            head: heapless::Vec::from_slice(head).map_err(|_| too_many)?,
        };
        arch.validate()?;
        Ok(arch)
    }

    /// The paper's PCRNet: encoder 64-64-64-128-1024, head 1024-1024-512-512-256.
    pub fn paper_pcrnet() -> Self {
        Self::new(PAPER_ENCODER, PCRNET_HEAD).unwrap_or_else(|_| unreachable!())
    }

    /// Checks the limits an [`Arch`] read from a blob must respect.
    pub fn validate(&self) -> Result<()> {
        if self.encoder.is_empty() {
            return Err(Error::InconsistentDimensions {
                what: "encoder has no layer",
            });
        }
        if self.encoder.iter().chain(self.head.iter()).any(|&w| w == 0) {
            return Err(Error::InconsistentDimensions {
                what: "layer of width 0",
            });
        }
        Ok(())
    }

    /// Size of the global feature (last encoder width).
    pub fn feature_dim(&self) -> usize {
        self.encoder.last().map_or(0, |&w| w as usize)
    }

    /// The encoder layers in order.
    pub fn encoder_layers(&self) -> impl Iterator<Item = LayerShape> + '_ {
        chain_layers(INPUT_DIM, &self.encoder, true)
    }

    /// The head layers in order, the linear 7-wide output layer last.
    pub fn head_layers(&self) -> impl Iterator<Item = LayerShape> + '_ {
        let hidden = chain_layers(2 * self.feature_dim(), &self.head, true);
        let last_in = self
            .head
            .last()
            .map_or(2 * self.feature_dim(), |&w| w as usize);
        hidden.chain(core::iter::once(LayerShape {
            inputs: last_in,
            outputs: POSE_DIM,
            relu: false,
        }))
    }

    /// Encoder multiply-accumulates per point.
    pub fn encoder_macs_per_point(&self) -> usize {
        self.encoder_layers().map(|l| l.macs()).sum()
    }

    /// Head multiply-accumulates per registration.
    pub fn head_macs(&self) -> usize {
        self.head_layers().map(|l| l.macs()).sum()
    }

    /// Weights plus biases of the whole network.
    pub fn parameters(&self) -> usize {
        self.encoder_layers()
            .chain(self.head_layers())
            .map(|l| l.parameters())
            .sum()
    }

    /// Width of the widest hidden encoder layer (the last one feeds the
    /// max-pool and needs no buffer); 0 with a single encoder layer.
    pub fn widest_hidden_encoder(&self) -> usize {
        max_of(&self.encoder, true)
    }

    /// Width of the widest hidden head layer (0 without hidden layers).
    pub fn widest_hidden_head(&self) -> usize {
        max_of(&self.head, false)
    }

    /// Bytes of int8 scratch the int8 path needs with `tile` points per pass.
    pub fn int8_scratch_len(&self, tile: usize) -> usize {
        int8_scratch_len(&self.encoder, &self.head, tile)
    }

    /// Bytes of scratch the int8 encoder's host block kernel uses past
    /// [`Self::int8_scratch_len`]: the encoder's weights as int16 (each
    /// row padded to an even length); one word per output of every layer
    /// after the first, and when the pooled layer's input is an int8
    /// activation one per four of its inputs, for the byte kernels; one per
    /// output of the pooled layer, for its running maxima; and two buffers
    /// of [`HOST_BLOCK`] points x the widest layer input as int16 (the
    /// coordinates count as four), plus 3 for alignment.
    pub fn host_block_len(&self) -> usize {
        let w = self.host_block_words();
        4 * (w.weights + w.sums + w.quads + w.maxima + 2 * w.buffer) + 3
    }

    /// The host block kernel's scratch in words.
    pub(crate) fn host_block_words(&self) -> HostBlockWords {
        let last = self.encoder_layers().last();
        // The pooled layer runs on bytes when its input is an int8
        // activation, not the int16 coordinates.
        let pooled = last.filter(|_| self.encoder.len() > 1);
        let weights = self.encoder_layers().map(|l| l.pair_words()).sum();
        let pairs = self.encoder_layers().map(|l| l.inputs.div_ceil(2));
        // Bytes: the block's low bits and high bits, each a word per point
        // and quad of inputs.
        let bytes = pooled.map_or(0, |l| 2 * l.inputs.div_ceil(4));
        HostBlockWords {
            weights,
            sums: self.encoder_layers().skip(1).map(|l| l.outputs).sum(),
            quads: pooled.map_or(0, |l| l.inputs.div_ceil(4)),
            maxima: last.map_or(0, |l| l.outputs),
            buffer: HOST_BLOCK * pairs.chain([bytes]).max().unwrap_or(0),
        }
    }

    /// Elements of f32 scratch the f32 path needs.
    pub fn f32_scratch_len(&self) -> usize {
        f32_scratch_len(&self.encoder, &self.head)
    }
}

/// Splits `work` into two ping-pong buffers of `half` elements each, or
/// reports how much scratch was missing.
pub(crate) fn ping_pong<T>(work: &mut [T], half: usize) -> Result<(&mut [T], &mut [T])> {
    let available = work.len();
    let needed = half.saturating_mul(2);
    let (a, rest) = work
        .split_at_mut_checked(half)
        .ok_or(Error::ScratchTooSmall { needed, available })?;
    let b = rest
        .get_mut(..half)
        .ok_or(Error::ScratchTooSmall { needed, available })?;
    Ok((a, b))
}

/// The first `n` elements of a working buffer. Buffers are sized from the
/// validated architecture, so the error is unreachable; it stands where a
/// slice index would leave a panic path for the compiler to keep.
pub(crate) fn prefix<T>(s: &[T], n: usize) -> Result<&[T]> {
    s.get(..n).ok_or(Error::InconsistentDimensions {
        what: "layer input wider than its buffer",
    })
}

fn chain_layers(
    first_in: usize,
    widths: &[u16],
    relu: bool,
) -> impl Iterator<Item = LayerShape> + '_ {
    let mut inputs = first_in;
    widths.iter().map(move |&w| {
        let l = LayerShape {
            inputs,
            outputs: w as usize,
            relu,
        };
        inputs = w as usize;
        l
    })
}

const fn max_of(widths: &[u16], skip_last: bool) -> usize {
    // Slice patterns, not indices: no bounds check to leave behind.
    let mut rest = match widths {
        [init @ .., _] if skip_last => init,
        _ => widths,
    };
    let mut m = 0;
    while let [w, tail @ ..] = rest {
        if *w as usize > m {
            m = *w as usize;
        }
        rest = tail;
    }
    m
}

/// Bytes of int8 scratch needed by an architecture, usable in a `const`
/// to size a `static` buffer:
///
/// ```
/// const SCRATCH: usize = pcrnet_core::int8_scratch_len(&[32, 64, 256], &[128, 64], 4);
/// static mut BUF: [i8; SCRATCH] = [0; SCRATCH];
/// // The feature, then the head's area (larger than the encoder's 1,027 B).
/// # assert_eq!(SCRATCH, 256 + 2 * 128 + (2 * 512 + 3));
/// ```
///
/// Layout: the source feature (F bytes), then an area used first by the
/// encoder (two ping-pong tiles of `tile` x widest hidden encoder layer `H`;
/// the last encoder layer feeds the max-pool directly and needs no buffer;
/// with `tile >= 4`, also the int16 copy of the activations of every full
/// group of four points that the Cortex-M4/M7 kernel reads, `2 x (tile / 4
/// x 4) x H` bytes plus 3 for alignment; the same on every target, so one
/// figure sizes a buffer for any core) and then by the head (two ping-pong
/// vectors of the widest hidden head layer `W`, and the int16 copy of a
/// layer's input vector for the Cortex-M4/M7 kernel, `2 x max(2F, W)`
/// bytes plus 3; the first layer's input is the template feature, read
/// from the blob, and the source feature).
pub const fn int8_scratch_len(encoder: &[u16], head: &[u16], tile: usize) -> usize {
    let feature = last_or_zero(encoder);
    let hidden = max_of(encoder, true);
    let enc = 2 * tile * hidden + expanded_len(hidden, tile);
    let head_hidden = max_of(head, false);
    let head_input = if 2 * feature > head_hidden {
        2 * feature
    } else {
        head_hidden
    };
    let hd = 2 * head_hidden + 2 * head_input + 3;
    feature + if enc > hd { enc } else { hd }
}

/// Bytes of the encoder's int16 activation copy for `tile` points of width
/// `hidden` (see [`int8_scratch_len`]).
pub(crate) const fn expanded_len(hidden: usize, tile: usize) -> usize {
    let quads = tile / 4;
    if quads == 0 || hidden == 0 {
        0
    } else {
        2 * quads * 4 * hidden + 3
    }
}

/// Elements of f32 scratch needed by an architecture (the f32 path runs one
/// point at a time; same layout as [`int8_scratch_len`] with tile 1).
pub const fn f32_scratch_len(encoder: &[u16], head: &[u16]) -> usize {
    int8_scratch_len(encoder, head, 1)
}

const fn last_or_zero(widths: &[u16]) -> usize {
    match widths.last() {
        Some(&w) => w as usize,
        None => 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_figures() {
        let a = Arch::paper_pcrnet();
        assert_eq!(a.feature_dim(), 1024);
        // 3*64 + 64*64*2 + 64*128 + 128*1024
        assert_eq!(a.encoder_macs_per_point(), 192 + 8192 + 8192 + 131072);
        let head: usize = 2048 * 1024 + 1024 * 1024 + 1024 * 512 + 512 * 512 + 512 * 256 + 256 * 7;
        assert_eq!(a.head_macs(), head);
        // The head's area (ping-pong of 1024, int16 copy of the 2048
        // inputs) is larger than the encoder's (4,099 B).
        assert_eq!(a.int8_scratch_len(8), 1024 + 2 * 1024 + (2 * 2048 + 3));
    }

    #[test]
    fn rejects_bad_shapes() {
        assert!(Arch::new(&[], &[4]).is_err());
        assert!(Arch::new(&[4, 0], &[4]).is_err());
        assert!(Arch::new(&[1; 9], &[]).is_err());
        let a = Arch::new(&[8], &[]).unwrap();
        assert_eq!(a.head_layers().count(), 1);
        assert_eq!(a.head_layers().next().unwrap().inputs, 16);
        // The feature, then the int16 copy of the head's 16 inputs.
        assert_eq!(a.int8_scratch_len(4), 8 + (2 * 16 + 3));
    }
}
