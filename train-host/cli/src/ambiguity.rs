//! How `register` and `register --scene` report a pose's ambiguity
//! ([`pcrnet_core::ambiguity`]): lines for a person and a JSON object, in
//! the files' frame (the local origin added back).

use pcrnet_core::Ambiguity;
use pcrnet_core::ambiguity::FREE_AXIS_STIFFNESS;
use pcrnet_io::frame::FilePose;

/// The ambiguity as lines for a person.
pub(crate) fn lines(a: &Ambiguity, origin: [f64; 3]) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(x) = a.axis {
        out.push(format!(
            "ambiguous: a rotation about the axis {:?} through {:?} (template frame) barely changes the fit (stiffness {:.3}, free below {FREE_AXIS_STIFFNESS}): the angle about it is arbitrary (a surface of revolution?)",
            x.direction,
            point(x.point, origin),
            x.stiffness
        ));
    }
    if let Some(t) = a.turn {
        let [_, x, y, z] = t.motion.rotation;
        let n = (x * x + y * y + z * z).sqrt().max(f32::MIN_POSITIVE);
        out.push(format!(
            "ambiguous: the pose turned by {:.1} deg about {:?} (template frame) fits about as well (plane residual {:.4} of the size): the object may be turned by it (a symmetric shape?)",
            t.degrees,
            [x / n, y / n, z / n],
            t.relative_plane_residual
        ));
    }
    if out.is_empty() {
        out.push(
            "ambiguity: none found (no free rotation axis; no other start fits about as well)"
                .into(),
        );
    }
    out
}

/// The ambiguity as JSON: `free_axis` (`direction`, `point`,
/// `stiffness`) and `turn` (`quaternion_wxyz`, `translation`, `matrix`,
/// `degrees`, `relative_plane_residual`), each `null` when not found. The
/// turn is a motion of the template's frame: the other pose is the turn
/// applied after the pose.
pub(crate) fn json(a: &Ambiguity, origin: [f64; 3]) -> serde_json::Value {
    serde_json::json!({
        "ambiguous": a.is_ambiguous(),
        "free_axis": a.axis.map(|x| serde_json::json!({
            "direction": x.direction,
            "point": point(x.point, origin),
            "stiffness": x.stiffness,
        })),
        "turn": a.turn.map(|t| {
            let file = FilePose::from_local(&t.motion, origin);
            serde_json::json!({
                "quaternion_wxyz": t.motion.rotation,
                "translation": file.translation,
                "matrix": file.matrix(),
                "degrees": t.degrees,
                "relative_plane_residual": t.relative_plane_residual,
            })
        }),
    })
}

/// A point about the local origin, in the files' frame.
fn point(p: [f32; 3], origin: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| f64::from(p[k]) + origin[k])
}
