//! Shape sets: the clouds training and evaluation draw their pairs from,
//! loaded from ModelNet-style folders, from one object file, or generated
//! ([`crate::shapes`]), each preprocessed once at load as
//! [`super::data`] describes, with the points the reduction did not keep
//! for resampled sources.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::data::{
    PairConfig, Sampling, make_pair_with_centroid, mix_seed, normalise_together, preprocess_split,
    reduce,
};
use super::model::Batch;
use crate::shapes::{self, Shape};
use pcrnet_io::{self as io, ReadError};

/// Which split of a ModelNet-style folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    /// `<class>/train`.
    Train,
    /// `<class>/test`.
    Test,
}

impl Split {
    fn dir(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
        }
    }
}

/// Why a data set could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A folder could not be listed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The folder.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A cloud file could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// Nothing matched (no class folder, no file, or an empty cloud).
    #[error("no usable cloud found: {0}")]
    Empty(String),
    /// The folder holds data roots (folders of classes), not classes: its
    /// classes would be a mix of whichever roots happen to hold the split.
    #[error(
        "{} holds data roots, not classes ({} has class folders of its own): pass one root, e.g. {}",
        root.display(),
        inner.display(),
        inner.display()
    )]
    NestedRoot {
        /// The folder given.
        root: PathBuf,
        /// A data root inside it.
        inner: PathBuf,
    },
}

/// A class name, a file name and its preprocessed cloud.
type Labelled = (String, String, Vec<[f32; 3]>, Vec<[f32; 3]>);

/// A set of preprocessed shapes, all with the same number of points.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The clouds, each `points` long, centred and in the unit box.
    pub clouds: Vec<Vec<[f32; 3]>>,
    /// For each cloud, the shape's other points: those of the file the
    /// reduction did not keep (or, for generated shapes, a second sampling
    /// of the surface), in the cloud's own frame. Sources resampled from
    /// these share no point with the template, as a sensor's would not.
    pub rest: Vec<Vec<[f32; 3]>>,
    /// Class name of each cloud.
    pub labels: Vec<String>,
    /// Where each cloud came from: its path below the data root
    /// (`chair/test/chair_0890.pcd`), or `generated/<kind>/<index>`.
    pub names: Vec<String>,
    /// Points per cloud.
    pub points: usize,
}

/// Whether a folder inside `dir` holds `split` (`<dir>/<class>/<split>/`):
/// `dir` is then a data root, not a class.
fn holds_classes(dir: &Path, split: Split) -> bool {
    list_dir(dir).is_ok_and(|subs| subs.iter().any(|c| c.join(split.dir()).is_dir()))
}

fn list_dir(path: &Path) -> Result<Vec<PathBuf>, DataError> {
    let rd = std::fs::read_dir(path).map_err(|error| DataError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let mut out: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    out.sort();
    Ok(out)
}

impl Dataset {
    /// Loads `<root>/<class>/<split>/*` (every file [`io::read_cloud`]
    /// understands), classes in name order, files in name order, keeping
    /// only `classes` when given; a root with `<root>/<split>/` is one
    /// class named after the root folder. Preprocessing (see the module docs) is
    /// seeded per file by `seed` and the file's position.
    pub fn load_modelnet(
        root: &Path,
        split: Split,
        classes: Option<&[String]>,
        points: usize,
        sampling: Sampling,
        seed: u64,
    ) -> Result<Self, DataError> {
        let mut files = Vec::new();
        // A root that holds the split itself (`<root>/<split>/*`, as the
        // ModelNet40 airplanes) is one class named after the root.
        let single = root.join(split.dir()).is_dir();
        let class_dirs = if single {
            vec![root.to_path_buf()]
        } else {
            list_dir(root)?
        };
        // Every class folder with the split, for the message when nothing
        // matches.
        let mut found = Vec::new();
        for class_dir in class_dirs {
            if !class_dir.is_dir() {
                continue;
            }
            let name = class_dir
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            if class_dir.join(split.dir()).is_dir() {
                found.push(name.clone());
            }
            if classes.is_some_and(|c| !c.iter().any(|x| x == &name)) {
                continue;
            }
            let dir = class_dir.join(split.dir());
            if !dir.is_dir() {
                if holds_classes(&class_dir, split) {
                    return Err(DataError::NestedRoot {
                        root: root.to_path_buf(),
                        inner: class_dir,
                    });
                }
                continue;
            }
            for f in list_dir(&dir)? {
                if io::Format::from_path(&f).is_some() {
                    files.push((name.clone(), f));
                }
            }
        }
        if files.is_empty() {
            found.sort();
            let (asked, found) = (
                classes.map_or("any class".into(), |c| format!("class {}", c.join(", "))),
                match found.as_slice() {
                    [] => "it has no class folder with that split".to_string(),
                    names => format!("its classes are {}", names.join(", ")),
                },
            );
            return Err(DataError::Empty(format!(
                "{} ({} split): no cloud file of {asked}; {found}",
                root.display(),
                split.dir(),
            )));
        }
        let loaded: Vec<Result<Option<Labelled>, DataError>> = files
            .par_iter()
            .enumerate()
            .map(|(i, (label, path))| {
                let raw = io::read_cloud(path)?;
                let name = path
                    .strip_prefix(root)
                    .unwrap_or(path)
                    .to_string_lossy()
                    .into_owned();
                Ok(
                    preprocess_split(&raw, points, sampling, mix_seed(seed, 0x10AD, i as u64))
                        .map(|(c, rest)| (label.clone(), name, c, rest)),
                )
            })
            .collect();
        let mut clouds = Vec::new();
        let mut rest = Vec::new();
        let mut labels = Vec::new();
        let mut names = Vec::new();
        for r in loaded {
            if let Some((l, n, c, o)) = r? {
                labels.push(l);
                names.push(n);
                clouds.push(c);
                rest.push(o);
            }
        }
        if clouds.is_empty() {
            return Err(DataError::Empty(root.display().to_string()));
        }
        Ok(Dataset {
            clouds,
            rest,
            labels,
            names,
            points,
        })
    }

    /// `count` generated shapes (box, torus, "L" in turn, each with its own
    /// sampling and a random per-axis stretch in `[0.6, 1]`), preprocessed
    /// as loaded data. Needs no files.
    pub fn generated(count: usize, points: usize, seed: u64) -> Self {
        let kinds = [
            (Shape::Box, "box"),
            (Shape::Torus, "torus"),
            (Shape::Ell, "ell"),
        ];
        Self::generated_of(&kinds, true, count, points, seed)
    }

    /// `count` generated shapes with a symmetry (cylinder and cone, free
    /// about their axis; the box, whose half turns about its axes fit as
    /// well), in turn, not stretched (a stretch would break the cylinder's
    /// and the cone's symmetry), preprocessed as loaded data.
    pub fn symmetric(count: usize, points: usize, seed: u64) -> Self {
        let kinds = [
            (Shape::Cylinder, "cylinder"),
            (Shape::Cone, "cone"),
            (Shape::Box, "box"),
        ];
        Self::generated_of(&kinds, false, count, points, seed)
    }

    /// `count` shapes of `kinds` in turn, each with its own sampling and,
    /// with `stretch`, a random per-axis stretch in `[0.6, 1]`.
    fn generated_of(
        kinds: &[(Shape, &str)],
        stretch: bool,
        count: usize,
        points: usize,
        seed: u64,
    ) -> Self {
        let mut clouds = Vec::with_capacity(count);
        let mut rest = Vec::with_capacity(count);
        let mut labels = Vec::with_capacity(count);
        let mut names = Vec::with_capacity(count);
        for i in 0..count {
            let (kind, name) = kinds[i % kinds.len().max(1)];
            let s = mix_seed(seed, 0x6E7, i as u64);
            let mut rng = ChaCha8Rng::seed_from_u64(s);
            let drawn: [f32; 3] = std::array::from_fn(|_| rng.random_range(0.6..=1.0));
            let stretch = if stretch { drawn } else { [1.0; 3] };
            let stretched = |seed| -> Vec<[f32; 3]> {
                shapes::sample(kind, points, seed)
                    .into_iter()
                    .map(|p| std::array::from_fn(|k| p[k] * stretch[k]))
                    .collect()
            };
            let raw = stretched(s);
            if let Some(kept) = reduce(&raw, points, Sampling::Random, s) {
                // A second, independent sampling of the same surface.
                let (c, o) = normalise_together(kept, stretched(s ^ 0x5EC0));
                clouds.push(c);
                rest.push(o);
                labels.push(name.to_string());
                names.push(format!("generated/{name}/{i}"));
            }
        }
        Dataset {
            clouds,
            rest,
            labels,
            names,
            points,
        }
    }

    /// One object of one's own (`pcrnet train --object`): a cloud file, or
    /// an OFF mesh sampled by area with 8 x `points` points, preprocessed
    /// as loaded data; the points the reduction leaves are the object's
    /// `rest`, to resample sources from.
    pub fn object(
        path: &Path,
        points: usize,
        sampling: Sampling,
        seed: u64,
    ) -> Result<Self, DataError> {
        let raw = match io::Format::from_path(path) {
            Some(io::Format::Off) => io::read_off_sampled(path, points.saturating_mul(8), seed)?,
            _ => io::read_cloud(path)?,
        };
        let (cloud, rest) = preprocess_split(&raw, points, sampling, mix_seed(seed, 0x0B1E, 0))
            .ok_or_else(|| DataError::Empty(format!("{}: no finite point", path.display())))?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(Dataset {
            clouds: vec![cloud],
            rest: vec![rest],
            labels: vec!["object".to_string()],
            names: vec![name],
            points,
        })
    }

    /// Adds `other`'s shapes after these (both reduced to the same
    /// `points`: one training run's sets).
    pub fn append(&mut self, other: Dataset) {
        self.clouds.extend(other.clouds);
        self.rest.extend(other.rest);
        self.labels.extend(other.labels);
        self.names.extend(other.names);
    }

    /// Only the shape at `index` (single-model training).
    pub fn single_model(mut self, index: usize) -> Self {
        let i = index.min(self.clouds.len().saturating_sub(1));
        self.clouds = self.clouds.drain(i..=i).collect();
        self.rest = self.rest.drain(i..=i).collect();
        self.labels = self.labels.drain(i..=i).collect();
        self.names = self.names.drain(i..=i).collect();
        self
    }

    /// Number of shapes.
    pub fn len(&self) -> usize {
        self.clouds.len()
    }

    /// Whether there is no shape.
    pub fn is_empty(&self) -> bool {
        self.clouds.is_empty()
    }

    /// The points the source of a pair on shape `shape` is made from: the
    /// template itself, or with `resample` a random `points`-point subset
    /// of the shape's other points ([`Dataset::rest`], drawn with the
    /// pair's `seed`), so that template and source share no point. `None`
    /// for an index out of range, or with `resample` when the shape has no
    /// other point ([`Dataset::cannot_resample`]).
    pub fn source_points(
        &self,
        shape: usize,
        resample: bool,
        seed: u64,
    ) -> Option<Cow<'_, [[f32; 3]]>> {
        if resample {
            reduce(self.rest.get(shape)?, self.points, Sampling::Random, seed).map(Cow::Owned)
        } else {
            self.clouds.get(shape).map(|c| Cow::Borrowed(c.as_slice()))
        }
    }

    /// The first shape without other points to resample sources from
    /// (its name), if any: files with no more points than `points`.
    pub fn cannot_resample(&self) -> Option<&str> {
        self.rest
            .iter()
            .zip(&self.names)
            .find(|(rest, _)| !rest.iter().any(|p| p.iter().all(|v| v.is_finite())))
            .map(|(_, name)| name.as_str())
    }

    /// Builds the batch of pairs: shape `shapes[k]` with pair seed
    /// `seeds[k]`, in parallel (each pair depends on its seed only). With
    /// `resample`, sources come from the shapes' other points
    /// ([`Dataset::source_points`]); the caller checks
    /// [`Dataset::cannot_resample`] first (a shape without them would get
    /// its template's points).
    pub fn batch(
        &self,
        shapes: &[usize],
        seeds: &[u64],
        cfg: &PairConfig,
        resample: bool,
    ) -> Batch {
        let pairs: Vec<_> = shapes
            .par_iter()
            .zip(seeds.par_iter())
            .map(|(&s, &seed)| {
                let base = self
                    .source_points(s, resample, seed)
                    .unwrap_or(Cow::Borrowed(&self.clouds[s]));
                let (src, r, t, c) = make_pair_with_centroid(&base, cfg, seed);
                (s, src, r, t, c)
            })
            .collect();
        let mut batch = Batch {
            size: shapes.len(),
            points: self.points,
            template: Vec::with_capacity(shapes.len() * self.points),
            source: Vec::with_capacity(shapes.len() * self.points),
            r_gt: Vec::with_capacity(shapes.len()),
            t_gt: Vec::with_capacity(shapes.len()),
            centroids: Vec::with_capacity(shapes.len()),
        };
        for (s, src, r, t, c) in pairs {
            batch.template.extend_from_slice(&self.clouds[s]);
            batch.source.extend_from_slice(&src);
            batch.r_gt.push(r);
            batch.t_gt.push(t);
            batch.centroids.push(c);
        }
        batch
    }
}
