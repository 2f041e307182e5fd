//! Fixed test sets: seeded registration pairs saved to disk, so every
//! method is scored on exactly the same pairs and a rerun gives the same
//! numbers.
//!
//! A [`PairSet`] file (JSON) holds the recipe ([`PairSetSpec`]: where the
//! shapes come from, how they are preprocessed, how sources are made) and,
//! per pair, the template's file name and index, the pair's seed (which
//! fixes the transform, the crop plane, the thinned subset and the noise;
//! see [`pcrnet_train::data::make_pair`]) and the true pose. Loading
//! re-creates every source from its seed and checks that the template's
//! file and the true pose are still what was saved, so a changed data
//! folder or pair generator is an error, not a silent change of the test.
//!
//! Sources are **not** centred: the true pose maps the source as made onto
//! the template, and it is the pose every method must return.

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use pcrnet_train::data::{self, PairConfig, Sampling};
use pcrnet_train::dataset::{DataError, Dataset, Split};
use pcrnet_train::geometry::Mat3;

/// Version of the pair-set file layout.
pub const FORMAT: u32 = 1;

/// Where the shapes of a pair set come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Shapes {
    /// A ModelNet-style folder (`<root>/<class>/<split>/*`, or
    /// `<root>/<split>/*` for one class), see [`Dataset::load_modelnet`].
    Folder {
        /// The data root as given.
        root: PathBuf,
        /// `true`: the test split; `false`: the training split.
        test_split: bool,
        /// Only these classes, when given.
        classes: Option<Vec<String>>,
    },
    /// Generated shapes ([`Dataset::generated`]); needs no files.
    Generated {
        /// How many shapes.
        count: usize,
    },
    /// Generated shapes with a symmetry ([`Dataset::symmetric`]: cylinders,
    /// cones, boxes); needs no files.
    Symmetric {
        /// How many shapes.
        count: usize,
    },
    /// One object of one's own ([`Dataset::object`]): every pair is a pose
    /// of it.
    Object {
        /// The cloud or OFF mesh as given.
        path: PathBuf,
    },
}

/// The recipe of a pair set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairSetSpec {
    /// Where the shapes come from.
    pub shapes: Shapes,
    /// Points per cloud after preprocessing.
    pub points: usize,
    /// How clouds are reduced to `points`.
    pub sampling: Sampling,
    /// How sources are made (`centre` is always off in a pair set).
    pub pairs: PairConfig,
    /// Number of pairs (0: one per shape, in order). Otherwise templates
    /// are a seeded shuffle of the shapes, repeated as needed.
    pub count: usize,
    /// Make each source from the shape's other points ([`Dataset::rest`]),
    /// not the template's: template and source then share no point, as
    /// with a real sensor. The transform, crop, thinning and noise are the
    /// same as without.
    #[serde(default)]
    pub resample: bool,
    /// Seed of the preprocessing, the template order and every pair.
    pub seed: u64,
}

/// One saved pair.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairRecord {
    /// Index of the template in the loaded shapes.
    pub template: usize,
    /// The template's file below the data root (or `generated/...`).
    pub name: String,
    /// The template's class.
    pub label: String,
    /// The pair's seed (transform, crop, subset and noise).
    pub seed: u64,
    /// True rotation, source onto template (row-major).
    pub rotation: Mat3,
    /// True translation, source onto template.
    pub translation: [f32; 3],
}

/// A saved, seeded test set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairSet {
    /// [`FORMAT`].
    pub format: u32,
    /// How the pairs were made.
    pub spec: PairSetSpec,
    /// The pairs.
    pub pairs: Vec<PairRecord>,
}

/// One pair ready to register.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    /// The template cloud (preprocessed).
    pub template: Vec<[f32; 3]>,
    /// The source cloud.
    pub source: Vec<[f32; 3]>,
    /// True rotation, source onto template.
    pub r_gt: Mat3,
    /// True translation, source onto template.
    pub t_gt: [f32; 3],
    /// The template's class.
    pub label: String,
    /// A single-view source's viewpoint (source frame,
    /// [`pcrnet_train::data::MadePair::viewpoint`]).
    pub viewpoint: Option<[f32; 3]>,
}

/// Why a pair set could not be made, read or used.
#[derive(Debug, thiserror::Error)]
pub enum PairSetError {
    /// Reading or writing the file failed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// The file is not a pair set.
    #[error("{}: not a pair set: {error}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The parse error.
        error: serde_json::Error,
    },
    /// The file has another layout version.
    #[error("pair set format {found}, this build reads {FORMAT}")]
    Format {
        /// The version found.
        found: u32,
    },
    /// The shapes could not be loaded.
    #[error(transparent)]
    Data(#[from] DataError),
    /// A re-created pair differs from the saved one.
    #[error("pair {index}: {what} differs from the saved set (data folder or generator changed)")]
    Mismatch {
        /// Pair index.
        index: usize,
        /// What differs.
        what: &'static str,
    },
}

impl PairSetSpec {
    /// Loads and preprocesses the shapes.
    pub fn load_shapes(&self) -> Result<Dataset, PairSetError> {
        Ok(match &self.shapes {
            Shapes::Folder {
                root,
                test_split,
                classes,
            } => Dataset::load_modelnet(
                root,
                if *test_split {
                    Split::Test
                } else {
                    Split::Train
                },
                classes.as_deref(),
                self.points,
                self.sampling,
                self.seed,
            )?,
            Shapes::Generated { count } => Dataset::generated(*count, self.points, self.seed),
            Shapes::Symmetric { count } => Dataset::symmetric(*count, self.points, self.seed),
            Shapes::Object { path } => {
                Dataset::object(path, self.points, self.sampling, self.seed)?
            }
        })
    }

    fn pair_config(&self) -> PairConfig {
        PairConfig {
            centre: false,
            ..self.pairs
        }
    }
}

impl PairSet {
    /// Makes the pairs of `spec` from its loaded `shapes`
    /// ([`PairSetSpec::load_shapes`]).
    pub fn generate(spec: PairSetSpec, shapes: &Dataset) -> PairSet {
        let n = shapes.len();
        let order: Vec<usize> = if spec.count == 0 {
            (0..n).collect()
        } else {
            let mut all: Vec<usize> = (0..n).collect();
            all.shuffle(&mut ChaCha8Rng::seed_from_u64(data::mix_seed(
                spec.seed, 0x0DE5, 0,
            )));
            (0..spec.count).map(|k| all[k % n.max(1)]).collect()
        };
        let cfg = spec.pair_config();
        let pairs = order
            .iter()
            .enumerate()
            .map(|(k, &i)| {
                let seed = data::mix_seed(spec.seed, 0xE7A1, k as u64);
                // The transform is drawn first: it does not depend on the points.
                let (_, rotation, translation) = data::make_pair(&shapes.clouds[i], &cfg, seed);
                PairRecord {
                    template: i,
                    name: shapes.names[i].clone(),
                    label: shapes.labels[i].clone(),
                    seed,
                    rotation,
                    translation,
                }
            })
            .collect();
        PairSet {
            format: FORMAT,
            spec,
            pairs,
        }
    }

    /// Writes the set as JSON.
    pub fn save(&self, path: &Path) -> Result<(), PairSetError> {
        let io = |error| PairSetError::Io {
            path: path.to_path_buf(),
            error,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let json = serde_json::to_string_pretty(self).map_err(|error| PairSetError::Json {
            path: path.to_path_buf(),
            error,
        })?;
        std::fs::write(path, json).map_err(io)
    }

    /// Reads a set written by [`PairSet::save`].
    pub fn load(path: &Path) -> Result<PairSet, PairSetError> {
        let text = std::fs::read_to_string(path).map_err(|error| PairSetError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let set: PairSet = serde_json::from_str(&text).map_err(|error| PairSetError::Json {
            path: path.to_path_buf(),
            error,
        })?;
        if set.format != FORMAT {
            return Err(PairSetError::Format { found: set.format });
        }
        Ok(set)
    }

    /// Re-creates every pair from `shapes` (loaded by the set's own
    /// [`PairSetSpec::load_shapes`]), checking the template files and the
    /// true poses against the saved ones.
    pub fn materialise(&self, shapes: &Dataset) -> Result<Vec<Pair>, PairSetError> {
        let cfg = self.spec.pair_config();
        self.pairs
            .iter()
            .enumerate()
            .map(|(index, rec)| {
                let template = shapes
                    .clouds
                    .get(rec.template)
                    .filter(|_| shapes.names.get(rec.template) == Some(&rec.name))
                    .ok_or(PairSetError::Mismatch {
                        index,
                        what: "template file",
                    })?;
                let base = shapes
                    .source_points(rec.template, self.spec.resample, rec.seed)
                    .ok_or(PairSetError::Mismatch {
                        index,
                        what: "the shape's other points (--resample needs shapes with more points than --points)",
                    })?;
                let made = data::make_pair_seen(&base, &cfg, rec.seed);
                let (source, r_gt, t_gt) = (made.source, made.r_gt, made.t_gt);
                if r_gt != rec.rotation || t_gt != rec.translation {
                    return Err(PairSetError::Mismatch {
                        index,
                        what: "true pose",
                    });
                }
                Ok(Pair {
                    template: template.clone(),
                    source,
                    r_gt,
                    t_gt,
                    label: rec.label.clone(),
                    viewpoint: made.viewpoint,
                })
            })
            .collect()
    }

    /// The same pairs (templates and seeds) with sources made by `pairs`
    /// instead: a sweep over noise, crop or thinning keeps everything else.
    /// `shapes` must be the set's own ([`PairSetSpec::load_shapes`]).
    pub fn with_sources(&self, pairs: PairConfig, shapes: &Dataset) -> PairSet {
        let spec = PairSetSpec {
            pairs,
            ..self.spec.clone()
        };
        // Same count and seed: same template order and pair seeds.
        PairSet::generate(spec, shapes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcrnet_train::geometry::apply;

    fn spec(count: usize) -> PairSetSpec {
        PairSetSpec {
            shapes: Shapes::Generated { count: 5 },
            points: 64,
            sampling: Sampling::Random,
            pairs: PairConfig::default(),
            count,
            seed: 3,
            resample: false,
        }
    }

    #[test]
    fn resampled_sources_share_no_point_but_the_pose() {
        let plain = spec(6);
        let shapes = plain.load_shapes().unwrap();
        let resampled = PairSetSpec {
            resample: true,
            ..plain.clone()
        };
        let a = PairSet::generate(plain, &shapes)
            .materialise(&shapes)
            .unwrap();
        let b = PairSet::generate(resampled, &shapes)
            .materialise(&shapes)
            .unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!((x.r_gt, x.t_gt), (y.r_gt, y.t_gt));
            assert_eq!(y.source.len(), y.template.len());
            // Moved back onto the template, no source point lands on a template point...
            let back: Vec<[f32; 3]> = y
                .source
                .iter()
                .map(|s| apply(&y.r_gt, &y.t_gt, s))
                .collect();
            let nearest = |q: &[f32; 3]| {
                y.template
                    .iter()
                    .map(|t| (0..3).map(|k| (q[k] - t[k]).powi(2)).sum::<f32>().sqrt())
                    .fold(f32::INFINITY, f32::min)
            };
            assert!(back.iter().all(|q| nearest(q) > 1e-4));
            // ...but all lie on the same surface, near the template.
            let mean = back.iter().map(nearest).sum::<f32>() / back.len() as f32;
            assert!(
                mean < 0.15,
                "mean distance {mean} (64-point clouds: spacing about 0.2)"
            );
        }
    }

    #[test]
    fn saved_sets_reload_to_the_same_pairs() {
        let s = spec(12);
        let shapes = s.load_shapes().unwrap();
        let set = PairSet::generate(s, &shapes);
        assert_eq!(set.pairs.len(), 12);
        let dir = std::env::temp_dir().join(format!("pcrnet-pairs-{}", std::process::id()));
        let path = dir.join("set.json");
        set.save(&path).unwrap();
        let back = PairSet::load(&path).unwrap();
        assert_eq!(back, set);
        let pairs = back.materialise(&back.spec.load_shapes().unwrap()).unwrap();
        // Clean pairs: the true pose maps the (uncentred) source onto the template.
        for p in &pairs {
            for (s, t) in p.source.iter().zip(&p.template) {
                let q = apply(&p.r_gt, &p.t_gt, s);
                assert!((0..3).all(|k| (q[k] - t[k]).abs() < 1e-4), "{q:?} {t:?}");
            }
        }
        // Every shape is used before any repeats.
        let mut first: Vec<usize> = set.pairs[..5].iter().map(|p| p.template).collect();
        first.sort();
        assert_eq!(first, vec![0, 1, 2, 3, 4]);
        // A tampered file is refused.
        let mut bad = back.clone();
        bad.pairs[3].translation[0] += 1e-3;
        assert!(matches!(
            bad.materialise(&shapes),
            Err(PairSetError::Mismatch { index: 3, .. })
        ));
        bad = back.clone();
        bad.pairs[1].name = "elsewhere.pcd".into();
        assert!(matches!(
            bad.materialise(&shapes),
            Err(PairSetError::Mismatch { index: 1, .. })
        ));
        std::fs::write(&path, "{}").unwrap();
        assert!(matches!(
            PairSet::load(&path),
            Err(PairSetError::Json { .. })
        ));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn sweeps_keep_templates_and_transforms() {
        let s = spec(0);
        let shapes = s.load_shapes().unwrap();
        let clean = PairSet::generate(s, &shapes);
        assert_eq!(clean.pairs.len(), 5);
        let noisy = clean.with_sources(
            PairConfig {
                noise: Some([0.02, 0.02]),
                ..PairConfig::default()
            },
            &shapes,
        );
        let (a, b) = (
            clean.materialise(&shapes).unwrap(),
            noisy.materialise(&shapes).unwrap(),
        );
        for (x, y) in a.iter().zip(&b) {
            assert_eq!((x.r_gt, x.t_gt), (y.r_gt, y.t_gt));
            assert_ne!(x.source, y.source);
        }
    }
}
