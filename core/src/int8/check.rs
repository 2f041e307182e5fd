//! Loading checks: every dimension, parameter range and accumulator bound
//! an int8 blob must meet before any kernel runs on it.

use super::Int8Model;
use crate::arch::POSE_DIM;
use crate::error::{Error, Result};
use crate::fixed::{INPUT_QMAX, MAX_SHIFT, MIN_SHIFT};
use crate::format::{
    Int8Layer, Int8Payload, NearestTable, check_frame, check_passes, expect_len, le_f32s, le_i32s,
};
use crate::kernel::rows;
use crate::template::Template;

impl<'a> Int8Model<'a> {
    /// Every check of [`Self::from_payload`] but the solver's
    /// ([`crate::lk::solver`]). Returns the template.
    #[inline(never)]
    pub(super) fn validate(
        p: &Int8Payload<'a>,
        table: Option<NearestTable<'a>>,
    ) -> Result<Template<'a>> {
        let arch = &p.arch;
        arch.validate()?;
        if !(p.input_scale.is_finite() && p.input_scale > 0.0) {
            return Err(Error::InvalidParameter {
                what: "input scale",
            });
        }
        if p.encoder.len() != arch.encoder.len() || p.head.len() != arch.head.len() {
            return Err(Error::InconsistentDimensions {
                what: "layer count differs from architecture",
            });
        }
        for (i, (shape, layer)) in arch.encoder_layers().zip(p.encoder.iter()).enumerate() {
            let xmax = if i == 0 { INPUT_QMAX as i64 } else { 128 };
            check_layer(layer, shape.inputs, shape.outputs, xmax)?;
        }
        for (shape, layer) in arch.head_layers().zip(p.head.iter()) {
            check_layer(layer, shape.inputs, shape.outputs, 128)?;
        }
        if !headless(p) {
            check_output(p)?;
        }
        expect_len(
            p.template_feature,
            arch.feature_dim(),
            1,
            "template feature",
        )?;
        check_frame(&p.frame)?;
        check_passes(p.passes)?;
        Template::new(p.template.clone(), table)
    }
}

/// Whether the payload has no head: no hidden head layer and an empty
/// output layer (a model trained as PointNetLK).
pub(super) fn headless(p: &Int8Payload<'_>) -> bool {
    let out = &p.output;
    p.arch.head.is_empty() && out.weights.is_empty() && out.bias.is_empty() && out.scale.is_empty()
}

/// The output layer's sizes, scales and accumulator bound.
fn check_output(p: &Int8Payload<'_>) -> Result<()> {
    let out = &p.output;
    let out_in = p.arch.head_layers().last().map_or(0, |l| l.inputs);
    expect_len(out.weights, POSE_DIM, out_in, "output weights")?;
    expect_len(out.bias, POSE_DIM, 4, "output bias")?;
    expect_len(out.scale, POSE_DIM, 4, "output scale")?;
    if le_f32s(out.scale).any(|s| !s.is_finite()) {
        return Err(Error::InvalidParameter {
            what: "output scale",
        });
    }
    check_accumulator(out.weights, out.bias, out_in, 128)
}

fn check_layer(layer: &Int8Layer<'_>, inputs: usize, outputs: usize, xmax: i64) -> Result<()> {
    expect_len(layer.weights, outputs, inputs, "layer weights")?;
    expect_len(layer.bias, outputs, 4, "layer bias")?;
    expect_len(layer.multiplier, outputs, 4, "layer multiplier")?;
    expect_len(layer.shift, outputs, 1, "layer shift")?;
    if !(layer.out_scale.is_finite() && layer.out_scale > 0.0) {
        return Err(Error::InvalidParameter {
            what: "output scale",
        });
    }
    if le_i32s(layer.multiplier).any(|m| m < 0) {
        return Err(Error::InvalidParameter {
            what: "negative multiplier",
        });
    }
    if layer
        .shift
        .iter()
        .any(|&s| !(MIN_SHIFT..=MAX_SHIFT).contains(&(s as i8)))
    {
        return Err(Error::InvalidParameter {
            what: "shift outside -31..=31",
        });
    }
    check_accumulator(layer.weights, layer.bias, inputs, xmax)
}

/// Proves that no accumulator can leave the i32 range:
/// `|bias| + sum_i |w_i| * xmax <= i32::MAX` for every output row.
fn check_accumulator(weights: &[u8], bias: &[u8], inputs: usize, xmax: i64) -> Result<()> {
    for (row, b) in rows(weights, inputs).zip(le_i32s(bias)) {
        // |w| <= 128 and a row has at most 2 x 65,535 inputs (the head's
        // first layer), so the sum stays below 2^25: u32 lanes, which
        // vectorise, where i64 ones were most of a blob's load time.
        let sum = row.iter().fold(0u32, |s, &w| {
            s.wrapping_add((w as i8).unsigned_abs() as u32)
        });
        if (b as i64).abs() + sum as i64 * xmax > i32::MAX as i64 {
            return Err(Error::InvalidParameter {
                what: "bias and weights can overflow the i32 accumulator",
            });
        }
    }
    Ok(())
}
