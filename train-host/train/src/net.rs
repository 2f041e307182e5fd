//! f32 parameters of a PCRNet held in owned arrays.

use pcrnet_core::Arch;
use pcrnet_core::float::{F32Network, Layer, Params};
use pcrnet_core::format::{F32Layer, F32Payload};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::template::{Reference, TemplateError, f32_blob};

/// How a network was trained, as its blobs record it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrainedFor {
    /// Sources were centred on their centroid (see `pcrnet_core::pose::centring`).
    pub centre_source: bool,
    /// Network passes per registration: 1 for PCRNet, more for i-PCRNet;
    /// PointNetLK's iterations for a model trained as PointNetLK.
    pub passes: u16,
    /// The model was trained as PointNetLK: its blobs have no head (the
    /// head's parameters were never trained) and always PointNetLK's solver.
    pub pointnetlk: bool,
    /// The blobs carry PointNetLK's solver for their template
    /// (`pcrnet export --lk`; always for a PointNetLK model).
    pub lk_solver: bool,
}

impl TrainedFor {
    /// A one-pass PCRNet.
    pub fn pcrnet(centre_source: bool) -> Self {
        TrainedFor {
            centre_source,
            passes: 1,
            pointnetlk: false,
            lk_solver: false,
        }
    }

    /// A model trained as PointNetLK with `iterations` LK iterations.
    pub fn pointnetlk(centre_source: bool, iterations: u16) -> Self {
        TrainedFor {
            centre_source,
            passes: iterations,
            pointnetlk: true,
            lk_solver: true,
        }
    }

    /// Whether the blobs carry PointNetLK's solver.
    pub fn has_lk_solver(&self) -> bool {
        self.pointnetlk || self.lk_solver
    }
}

/// Weights (`outputs x inputs`, row-major) and biases of every layer:
/// encoder layers, hidden head layers, then the output layer.
#[derive(Debug, Clone, PartialEq)]
pub struct F32Params {
    /// Network shape.
    pub arch: Arch,
    /// `(weights, bias)` per layer, in [`Arch::encoder_layers`] then
    /// [`Arch::head_layers`] order.
    pub layers: Vec<(Vec<f32>, Vec<f32>)>,
}

impl F32Params {
    /// He-uniform initial weights (`U[-sqrt(6/in), sqrt(6/in)]`) and zero
    /// biases, fixed by `seed`.
    pub fn init(arch: Arch, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let layers = arch
            .encoder_layers()
            .chain(arch.head_layers())
            .map(|s| {
                let bound = (6.0 / s.inputs as f32).sqrt();
                let w = (0..s.inputs * s.outputs)
                    .map(|_| rng.random_range(-bound..bound))
                    .collect();
                (w, vec![0.0; s.outputs])
            })
            .collect();
        F32Params { arch, layers }
    }

    /// Owned copies of a network's parameters (e.g. of an f32 blob).
    pub fn from_network<P: Params>(net: &F32Network<P>) -> Self {
        let values = |p: P| (0..p.len()).map(|i| p.get(i)).collect::<Vec<f32>>();
        F32Params {
            arch: net.arch().clone(),
            layers: net
                .layers()
                .iter()
                .map(|l| (values(l.weights), values(l.bias)))
                .collect(),
        }
    }

    /// A view for `pcrnet-core`'s f32 forward pass, with `template` as the
    /// template feature.
    pub fn network<'a>(
        &'a self,
        template: &'a [f32],
    ) -> pcrnet_core::Result<F32Network<&'a [f32]>> {
        let mut layers = heapless::Vec::new();
        for (w, b) in &self.layers {
            layers
                .push(Layer {
                    weights: &w[..],
                    bias: &b[..],
                })
                .map_err(|_| pcrnet_core::Error::InconsistentDimensions {
                    what: "too many layers",
                })?;
        }
        F32Network::new(self.arch.clone(), layers, template)
    }

    /// The parameters a blob of a model trained as `trained` holds: all of
    /// them, or for PointNetLK the encoder alone (its head was never
    /// trained), with no head in the architecture.
    pub fn for_blob(&self, trained: TrainedFor) -> F32Params {
        if !trained.pointnetlk {
            return self.clone();
        }
        let mut arch = self.arch.clone();
        arch.head.clear();
        F32Params {
            layers: self.layers[..arch.encoder.len()].to_vec(),
            arch,
        }
    }

    /// The f32 global feature of a cloud.
    pub fn encode(&self, cloud: &[[f32; 3]]) -> pcrnet_core::Result<Vec<f32>> {
        let dummy = vec![0.0; self.arch.feature_dim()];
        let net = self.network(&dummy)?;
        let mut scratch = vec![0.0; net.tiled_scratch_len()];
        Ok(net.encode(cloud, &mut scratch)?.to_vec())
    }

    /// Serialises an f32 blob whose template feature is `template`'s
    /// encoding; `centre_source` records whether the network was trained on
    /// sources centred on their centroid (see `pcrnet_core::pose::centring`).
    pub fn to_f32_blob(
        &self,
        reference: &Reference,
        trained: TrainedFor,
    ) -> Result<Vec<u8>, TemplateError> {
        let params = self.for_blob(trained);
        let bytes: Vec<(Vec<u8>, Vec<u8>)> = params
            .layers
            .iter()
            .map(|(w, b)| (le_bytes(w), le_bytes(b)))
            .collect();
        let mut layers = heapless::Vec::new();
        for (w, b) in &bytes {
            layers
                .push(F32Layer {
                    weights: w,
                    bias: b,
                })
                .map_err(|_| pcrnet_core::Error::InconsistentDimensions {
                    what: "too many layers",
                })?;
        }
        let payload = F32Payload {
            arch: params.arch.clone(),
            centre_source: trained.centre_source,
            passes: trained.passes,
            frame: reference.frame,
            template: reference.cloud(),
            layers,
            template_feature: &[],
        };
        f32_blob(&payload, reference, trained.has_lk_solver())
    }
}

/// Little-endian bytes of f32 values.
pub fn le_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}
