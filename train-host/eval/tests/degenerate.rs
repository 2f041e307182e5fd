//! Degenerate templates and sources in every registration method (issue
//! 10, item 6: PointNetLK on a one-point template returned a translation of
//! about 3e5 for a 1-unit source). A template with no extent is an error;
//! a source whose points do not determine a rotation gives a pose flagged
//! `degenerate` by the device's own rule, whatever the method.

use std::path::PathBuf;

use pcrnet_core::Degeneracy;
use pcrnet_eval::methods::{self, Method, MethodError, MethodKind};
use pcrnet_io::read_cloud;

const KINDS: [MethodKind; 5] = [
    MethodKind::Device,
    MethodKind::Pcrnet,
    MethodKind::Ipcrnet,
    MethodKind::Pointnetlk,
    MethodKind::Icp,
];

fn models() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../models")
}

/// The blob each method takes: PointNetLK the f32 one.
fn blob(kind: MethodKind) -> Vec<u8> {
    let name = match kind {
        MethodKind::Pointnetlk => "embedded-default-f32.pcrn",
        _ => "embedded-default-int8.pcrn",
    };
    std::fs::read(models().join(name)).unwrap()
}

#[test]
fn a_template_without_extent_is_an_error_in_every_method() {
    let source = read_cloud(&models().join("embedded-default-source.xyz")).unwrap();
    for template in [vec![[0.1, 0.2, 0.3]], vec![[0.1, 0.2, 0.3]; 50]] {
        for kind in KINDS {
            let r = methods::run(
                &Method::new(kind),
                Some(&blob(kind)),
                Some(&template),
                &source,
                None,
            );
            assert!(
                matches!(r, Err(MethodError::Model(_))),
                "{kind:?}, {} points: {:?}",
                template.len(),
                r.map(|o| o.pose)
            );
        }
    }
}

#[test]
fn a_degenerate_source_is_flagged_in_every_method() {
    let template = read_cloud(&models().join("embedded-default-template.xyz")).unwrap();
    let point = vec![[0.01, -0.02, 0.03]; 50];
    let line: Vec<[f32; 3]> = (0..50).map(|i| [0.01 * i as f32, 0.0, 0.0]).collect();
    let surface = read_cloud(&models().join("embedded-default-source.xyz")).unwrap();
    for kind in KINDS {
        let blob = blob(kind);
        for (source, want) in [
            (&point, Some(Degeneracy::Point)),
            (&line, Some(Degeneracy::Line)),
            (&surface, None),
        ] {
            // With the template as a cloud, and (network methods) with the
            // blob's own template.
            let mut templates = vec![Some(&template[..])];
            if kind != MethodKind::Icp {
                templates.push(None);
            }
            for t in templates {
                let out = methods::run(&Method::new(kind), Some(&blob), t, source, None)
                    .unwrap_or_else(|e| panic!("{kind:?}: {e}"));
                assert_eq!(
                    out.degenerate,
                    want,
                    "{kind:?}, template given: {}",
                    t.is_some()
                );
                assert!(out.pose.is_finite(), "{kind:?}");
                if let Some(c) = out.check {
                    assert_eq!(c.degenerate, want);
                    assert!(want.is_none() || !c.reliable);
                }
            }
        }
    }
}
