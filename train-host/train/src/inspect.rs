//! Human-readable description of a model blob: layers, parameters, memory, MACs.

use std::fmt::Write;

use pcrnet_core::format::le_i32s;
use pcrnet_core::{Arch, F32Model, Int8Model, MAX_TILE};

/// Describes a blob of either kind; errors if it is neither.
pub fn describe(blob: &[u8]) -> Result<String, pcrnet_core::Error> {
    match Int8Model::from_bytes(blob) {
        Ok(m) => Ok(describe_int8(&m, blob.len())),
        Err(pcrnet_core::Error::WrongKind { .. }) => {
            let m = F32Model::from_bytes(blob)?;
            Ok(describe_f32(&m, blob.len()))
        }
        Err(e) => Err(e),
    }
}

/// The layer shapes; without a head (PointNetLK), the encoder's alone.
fn shape_table(arch: &Arch, head: bool, out: &mut String) {
    let _ = writeln!(
        out,
        "  {:<10} {:>7} {:>7} {:>10} {:>10}",
        "layer", "in", "out", "params", "MACs"
    );
    for (i, l) in arch.encoder_layers().enumerate() {
        let _ = writeln!(
            out,
            "  {:<10} {:>7} {:>7} {:>10} {:>10}",
            format!("enc{i}"),
            l.inputs,
            l.outputs,
            l.parameters(),
            format!("{}/pt", l.macs())
        );
    }
    if !head {
        let encoder: usize = arch.encoder_layers().map(|l| l.parameters()).sum();
        let _ = writeln!(
            out,
            "  parameters {encoder}; encoder {} MACs/point; no head",
            arch.encoder_macs_per_point()
        );
        return;
    }
    for (i, l) in arch.head_layers().enumerate() {
        let _ = writeln!(
            out,
            "  {:<10} {:>7} {:>7} {:>10} {:>10}",
            if l.relu {
                format!("head{i}")
            } else {
                "output".into()
            },
            l.inputs,
            l.outputs,
            l.parameters(),
            l.macs()
        );
    }
    let _ = writeln!(
        out,
        "  parameters {}; encoder {} MACs/point; head {} MACs",
        arch.parameters(),
        arch.encoder_macs_per_point(),
        arch.head_macs()
    );
}

fn widths(arch: &Arch, head: bool) -> String {
    if head {
        format!(
            "encoder {:?}, head {:?} -> 7",
            &arch.encoder[..],
            &arch.head[..]
        )
    } else {
        format!("encoder {:?}, no head (PointNetLK)", &arch.encoder[..])
    }
}

fn describe_int8(m: &Int8Model<'_>, flash: usize) -> String {
    let arch = m.arch();
    let p = m.payload();
    let mut s = String::new();
    let _ = writeln!(s, "int8 model: {}", widths(arch, m.has_head()));
    shape_table(arch, m.has_head(), &mut s);
    let _ = writeln!(
        s,
        "  input: int16, scale {:.3e} (range +-{:.3})",
        p.input_scale,
        p.input_scale * 32767.0
    );
    let layers = p
        .encoder
        .iter()
        .map(|l| ("enc", l))
        .chain(p.head.iter().map(|l| ("head", l)));
    for (i, (kind, l)) in layers.enumerate() {
        let ms: Vec<i32> = le_i32s(l.multiplier).collect();
        let (mmin, mmax) = (
            ms.iter().min().copied().unwrap_or(0),
            ms.iter().max().copied().unwrap_or(0),
        );
        let (smin, smax) = (
            l.shift.iter().map(|&v| v as i8).min().unwrap_or(0),
            l.shift.iter().map(|&v| v as i8).max().unwrap_or(0),
        );
        let _ = writeln!(
            s,
            "  {kind:<4} #{i}: out scale {:.3e} zero point {}; multiplier {mmin}..{mmax}, shift {smin}..{smax}",
            l.out_scale, l.out_zero_point
        );
    }
    let method = Method {
        passes: m.trained_passes(),
        head: m.has_head(),
        lk: m.lk_solver(),
        floor: m.residual_floor(),
        up: m.up_axis(),
    };
    template_lines(&method, m.centres_source(), m.frame(), m.template(), &mut s);
    let _ = writeln!(s, "flash (blob, weights used in place): {flash} bytes");
    let _ = writeln!(
        s,
        "scratch RAM: {} bytes at tile 1, {} bytes at tile {MAX_TILE}",
        m.scratch_len(1),
        m.scratch_len(MAX_TILE)
    );
    s
}

/// How a model was trained to run: its passes, whether it has a head,
/// PointNetLK's solver, the template's residual floor and up axis if the
/// blob has them.
struct Method<'m, 'a> {
    passes: usize,
    head: bool,
    lk: Option<&'m pcrnet_core::lk::Solver<'a>>,
    floor: Option<f32>,
    up: Option<[f32; 3]>,
}

/// How the model runs and what it records of its template.
fn template_lines(
    method: &Method<'_, '_>,
    centred: bool,
    frame: &pcrnet_core::Frame,
    template: &pcrnet_core::template::Template<'_>,
    s: &mut String,
) {
    let passes = method.passes;
    let sources = if centred {
        "centred on their centroid"
    } else {
        "as given"
    };
    if method.head {
        let kind = if passes > 1 { "i-PCRNet" } else { "PCRNet" };
        let _ = writeln!(
            s,
            "  trained for {passes} pass(es) ({kind}), sources {sources}"
        );
    } else {
        let _ = writeln!(
            s,
            "  trained as PointNetLK for {passes} LK iterations, no head (run it with passes 0, lk_iterations {passes} or more), sources {sources}"
        );
    }
    match method.lk {
        Some(lk) => {
            let stored = lk.stored();
            let _ = writeln!(
                s,
                "  PointNetLK solver: 6 x {} f32 ({} bytes of flash), Jacobian by {} differences of step {}, damping {:e}",
                lk.features(),
                stored.rows.len(),
                if stored.central { "central" } else { "forward" },
                stored.jacobian_step,
                stored.damping
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  PointNetLK solver: none (lk_iterations needs one: `pcrnet export --lk`)"
            );
        }
    }
    let default = pcrnet_core::Options::default().max_residual;
    let _ = match method.floor {
        Some(floor) => writeln!(
            s,
            "  residual floor: {floor:.4} of the template's size (its points beyond those stored, at its own pose): recommended verdict max_residual {:.4} (default {default})",
            pcrnet_core::registration::max_residual_for(floor, default)
        ),
        None => writeln!(
            s,
            "  residual floor: not measured (the template file had fewer than twice the stored points, or a blob before format 6): the default verdict, max_residual {default}"
        ),
    };
    let _ = match method.up {
        Some(up) => writeln!(
            s,
            "  up axis: {up:?} (template frame): `register --scene` sweeps the yaw about the plane it finds"
        ),
        None => writeln!(
            s,
            "  up axis: none (export with --up AXIS, or give register --scene --up AXIS, for an object standing in any yaw)"
        ),
    };
    let _ = writeln!(
        s,
        "  frame: p_model = {:e} x (p - {:?}); the template spans about {:.4} user units",
        frame.scale,
        frame.centre,
        1.0 / frame.scale
    );
    let _ = writeln!(
        s,
        "  template: {} points with normals, {} turns (flip hypotheses up to {})",
        template.len(),
        template.turns().len(),
        1 + template.turns().len()
    );
    match template.table() {
        Some(t) => {
            let cells: usize = t.dims.iter().map(|&d| d as usize).product();
            let _ = writeln!(
                s,
                "  closest-point table: {} x {} x {} cells of {} steps, {} entries ({:.1} per cell): {} bytes of flash ({} offsets, {} entries)",
                t.dims[0],
                t.dims[1],
                t.dims[2],
                t.edge,
                t.candidates.len() / 2,
                t.candidates.len() as f64 / 2.0 / cells as f64,
                t.offsets.len() + t.candidates.len(),
                t.offsets.len(),
                t.candidates.len()
            );
        }
        None => {
            let _ = writeln!(
                s,
                "  closest-point table: none (format 3, or exported without one): every search walks the grid; `pcrnet upgrade` adds one"
            );
        }
    }
}

fn describe_f32(m: &F32Model<'_>, size: usize) -> String {
    let mut s = String::new();
    let net = m.network();
    let _ = writeln!(s, "f32 model: {}", widths(net.arch(), net.has_head()));
    shape_table(net.arch(), net.has_head(), &mut s);
    let method = Method {
        passes: m.trained_passes(),
        head: m.network().has_head(),
        lk: m.lk_solver(),
        floor: m.residual_floor(),
        up: m.up_axis(),
    };
    template_lines(&method, m.centres_source(), m.frame(), m.template(), &mut s);
    let _ = writeln!(s, "size: {size} bytes");
    let _ = writeln!(
        s,
        "scratch: {} f32 ({} bytes)",
        m.scratch_len(),
        4 * m.scratch_len()
    );
    s
}
