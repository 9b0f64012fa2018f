//! Learning a crowd model (§4–§5): state–action samples from tracks, one action model per labelled
//! behaviour (weighted states → PCA → kd-tree), the behaviour machine's statistics, and the model
//! file `herdfit.crowd-model/1`.

use super::action::{ActionConfig, ActionModel, ActionSamples, NO_NEXT};
use super::behaviour::{self, FsmStats, LabelConfig, INTERACTION, LOCOMOTION};
use super::features::{
    alignment, exit_intent, formation, headings, intent_at, pivot_parts, to_local, unit,
    FeatureConfig, FeatureWeights, IntentWindow, Scene, StateParts, V2,
};
use super::pca::Pca;
use crate::data::tracks::{Tracks, Units};
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of model files.
pub const MODEL_SCHEMA: &str = "herdfit.crowd-model/1";

/// A pivot object (§4): position and orientation in world coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pivot {
    pub position: V2,
    /// Degrees counter-clockwise from +x.
    pub orientation_deg: f64,
}

impl Pivot {
    /// Unit orientation vector.
    pub fn dir(&self) -> V2 {
        let a = self.orientation_deg.to_radians();
        [a.cos(), a.sin()]
    }
}

/// One behaviour to learn: which labelled samples, its weights and optional pivot (Table 1 rows).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BehaviourSpec {
    /// `locomotion`, `interaction` (samples by label) or any name (all samples).
    pub name: String,
    /// Weights replacing `features.weights` for this behaviour.
    #[serde(default)]
    pub weights: Option<FeatureWeights>,
    /// A pivot the states are taken relative to (formation sectors in its frame).
    #[serde(default)]
    pub pivot: Option<Pivot>,
}

/// Settings of `crowd learn`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LearnConfig {
    pub features: FeatureConfig,
    pub action: ActionConfig,
    /// PCA dimensions kept (§4: 8–12).
    pub pca_dims: usize,
    /// σ (frames) of the Gaussian smoothing of tracks before sampling (§3); 0: none.
    pub smoothing: f64,
    /// At most this many samples per behaviour (an even stride through them beyond).
    pub max_samples: usize,
    /// A behaviour with fewer samples is not learnt (its agents use locomotion).
    pub min_samples: usize,
    /// Frame rate of ETH/UCY text inputs (`.txt`).
    pub eth_fps: f64,
    pub labels: LabelConfig,
    pub behaviours: Vec<BehaviourSpec>,
}

impl Default for LearnConfig {
    fn default() -> Self {
        LearnConfig {
            features: FeatureConfig::default(),
            action: ActionConfig::default(),
            pca_dims: 10,
            smoothing: 1.0,
            max_samples: 20_000,
            min_samples: 200,
            eth_fps: 2.5,
            labels: LabelConfig::default(),
            behaviours: vec![
                BehaviourSpec {
                    name: LOCOMOTION.into(),
                    weights: None,
                    pivot: None,
                },
                // Table 1's "Chat" row.
                BehaviourSpec {
                    name: INTERACTION.into(),
                    weights: Some(FeatureWeights {
                        speed: 1.0,
                        formation: 100.0,
                        pivot: 0.0,
                        direction: 0.0,
                        alignment: 0.0,
                    }),
                    pivot: None,
                },
            ],
        }
    }
}

impl LearnConfig {
    /// The settings for imitating real pedestrians (`crowd learn --preset pedestrians`; the
    /// split-in-time check of `crowd holdout`, RESULTS): raw tracks (no smoothing: the measured
    /// turning is of the raw steps, and smoothing takes it away), the exit intent
    /// ([`IntentWindow::Exit`]) weighted 10 beside speed 1 and formation 1 within r = 1 m, one
    /// behaviour learnt from every sample (standing people included: a simulated stander needs
    /// standing samples), the output a real step drawn from the k = 100 nearest samples
    /// ([`super::action::ActionOutput::Sample`]) rather than eq. 3's average of them, and the
    /// next step of the agent's last sample's own track taken when it is the nearest sample
    /// ([`super::action::ActionConfig::continuation`] 1).
    pub fn pedestrians() -> LearnConfig {
        let mut c = LearnConfig {
            smoothing: 0.0,
            behaviours: vec![BehaviourSpec {
                name: LOCOMOTION.into(),
                weights: None,
                pivot: None,
            }],
            ..LearnConfig::default()
        };
        c.features.radius = 1.0;
        c.features.intent = IntentWindow::Exit;
        c.features.weights = FeatureWeights {
            speed: 1.0,
            formation: 1.0,
            pivot: 0.0,
            direction: 10.0,
            alignment: 0.0,
        };
        c.action.clusters = 1;
        c.action.choice = super::action::ClusterChoice::Nearest;
        c.action.output = super::action::ActionOutput::Sample;
        // Chosen on the split-in-time tuning scenes (RESULTS, crowds from tracks).
        c.action.continuation = 1;
        c
    }

    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.features.check()?;
        self.action.check()?;
        self.labels.check()?;
        // The smallest state any behaviour can have (no pivot, no alignment).
        let bare = FeatureWeights {
            alignment: 0.0,
            ..FeatureWeights::default()
        };
        let max_dims = FeatureConfig::dims(false, &bare).min(super::knn::MAX_DIMS);
        if self.pca_dims == 0 || self.pca_dims > max_dims {
            return Err(Error::invalid(format!(
                "pca_dims = {} must be in 1..={max_dims}",
                self.pca_dims
            )));
        }
        if !(self.smoothing.is_finite() && self.smoothing >= 0.0) {
            return Err(Error::invalid(format!(
                "smoothing = {} must be ≥ 0",
                self.smoothing
            )));
        }
        // σ in frames: its kernel spans 8σ frames (issue #47: 1e300 overflowed its length).
        crate::limits::within("smoothing", self.smoothing, 0.0, 1e4)?;
        let (lo, hi) = crate::limits::FPS_RANGE;
        crate::limits::within("eth_fps", self.eth_fps, lo, hi)?;
        crate::limits::check_count("max_samples", self.max_samples, 100_000_000)
            .map_err(|e| Error::invalid(e.to_string().replacen(": ", " = ", 1)))?;
        if self.max_samples < 2 {
            return Err(Error::invalid("max_samples must be ≥ 2"));
        }
        if !(self.eth_fps.is_finite() && self.eth_fps > 0.0) {
            return Err(Error::invalid(format!(
                "eth_fps = {} must be > 0",
                self.eth_fps
            )));
        }
        if self.behaviours.is_empty() || self.behaviours[0].name != LOCOMOTION {
            return Err(Error::invalid(
                "behaviours must start with 'locomotion' (the fallback of every agent)",
            ));
        }
        for (i, b) in self.behaviours.iter().enumerate() {
            if self.behaviours[..i].iter().any(|o| o.name == b.name) {
                return Err(Error::invalid(format!(
                    "behaviours[{i}]: '{}' is given twice",
                    b.name
                )));
            }
        }
        Ok(())
    }
}

/// One learnt behaviour as stored in the model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BehaviourFile {
    pub name: String,
    pub weights: FeatureWeights,
    pub pivot: Option<Pivot>,
    pub pca: Pca,
    pub samples: ActionSamples,
}

/// The model file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    pub schema: String,
    pub units: Units,
    /// Seconds per step (the training tracks' frame interval).
    pub dt: f64,
    pub config: LearnConfig,
    pub behaviours: Vec<BehaviourFile>,
    pub fsm: FsmStats,
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// A learnt behaviour ready to query.
pub struct Behaviour {
    pub name: String,
    pub weights: FeatureWeights,
    pub pivot: Option<Pivot>,
    pub pca: Pca,
    pub model: ActionModel,
}

/// A learnt crowd model.
pub struct CrowdModel {
    pub units: Units,
    pub dt: f64,
    pub config: LearnConfig,
    pub behaviours: Vec<Behaviour>,
    pub fsm: FsmStats,
    pub provenance: serde_json::Value,
}

impl CrowdModel {
    /// The behaviour named `name`, if learnt.
    pub fn behaviour(&self, name: &str) -> Option<usize> {
        self.behaviours.iter().position(|b| b.name == name)
    }

    /// Total samples over behaviours.
    pub fn samples(&self) -> usize {
        self.behaviours.iter().map(|b| b.model.samples.len()).sum()
    }

    fn from_file(f: ModelFile) -> Result<CrowdModel> {
        if f.schema != MODEL_SCHEMA {
            return Err(Error::invalid(format!(
                "schema is '{}', expected '{MODEL_SCHEMA}'",
                f.schema
            )));
        }
        f.config.check()?;
        if !(f.dt.is_finite() && f.dt > 0.0) {
            return Err(Error::invalid(format!("dt = {} must be > 0", f.dt)));
        }
        // A step of 1/fps within the frame rates herdfit accepts (issue #47: dt = 1e300 ran).
        {
            let (lo, hi) = crate::limits::FPS_RANGE;
            crate::limits::within("dt", f.dt, 1.0 / hi, 1.0 / lo)?;
        }
        if f.behaviours.first().map(|b| b.name.as_str()) != Some(LOCOMOTION) {
            return Err(Error::invalid("behaviours[0] must be 'locomotion'"));
        }
        let mut behaviours = Vec::new();
        for (i, b) in f.behaviours.into_iter().enumerate() {
            let at = |e: Error| Error::invalid(format!("behaviours[{i}].{e}"));
            b.pca.check().map_err(at)?;
            let input = FeatureConfig::dims(b.pivot.is_some(), &b.weights);
            if b.pca.dims() != b.samples.dims || b.pca.input() != input {
                return Err(Error::invalid(format!(
                    "behaviours[{i}]: PCA {} → {} does not fit states of {} values and samples of {}",
                    b.pca.input(),
                    b.pca.dims(),
                    input,
                    b.samples.dims
                )));
            }
            behaviours.push(Behaviour {
                model: ActionModel::new(b.samples).map_err(at)?,
                name: b.name,
                weights: b.weights,
                pivot: b.pivot,
                pca: b.pca,
            });
        }
        Ok(CrowdModel {
            units: f.units,
            dt: f.dt,
            config: f.config,
            behaviours,
            fsm: f.fsm,
            provenance: f.provenance,
        })
    }

    fn to_file(&self) -> ModelFile {
        ModelFile {
            schema: MODEL_SCHEMA.into(),
            units: self.units,
            dt: self.dt,
            config: self.config.clone(),
            behaviours: self
                .behaviours
                .iter()
                .map(|b| BehaviourFile {
                    name: b.name.clone(),
                    weights: b.weights.clone(),
                    pivot: b.pivot.clone(),
                    pca: b.pca.clone(),
                    samples: b.model.samples.clone(),
                })
                .collect(),
            fsm: self.fsm.clone(),
            provenance: self.provenance.clone(),
        }
    }

    /// Writes the model file atomically (JSON, shortest round-trip floats).
    pub fn save(&self, path: &Path) -> Result<()> {
        let s = serde_json::to_string(&self.to_file())
            .map_err(|e| Error::Internal(format!("crowd model: {e}")))?;
        crate::data::atomic::write_atomic(path, format!("{s}\n").as_bytes())
    }

    /// Reads and checks a model file.
    pub fn load(path: &Path) -> Result<CrowdModel> {
        crate::data::atomic::note_input(path);
        let s = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let f: ModelFile = serde_json::from_str(&s)
            .map_err(|e| Error::file(path, format!("not a crowd model: {e}")))?;
        CrowdModel::from_file(f).map_err(|e| e.in_file(path))
    }
}

/// Reads tracks: ETH/UCY text (`.txt`, at `eth_fps`) or `herdfit.tracks/1` CSV.
pub fn read_tracks(path: &Path, eth_fps: f64) -> Result<Tracks> {
    if path.extension().is_some_and(|e| e == "txt") {
        crate::data::tracks::read_eth_ucy(path, eth_fps)
    } else {
        Tracks::load(path)
    }
}

/// The unweighted state of segment `k` at its index `j` (needs j ≥ 1), given every segment's
/// headings; `centred` picks the intended-direction window, `pivot` the frame of the sectors,
/// `align` whether to compute the neighbours' headings.
#[allow(clippy::too_many_arguments)]
pub fn state_at(
    scene: &Scene,
    k: usize,
    j: usize,
    heads: &[Vec<V2>],
    cfg: &FeatureConfig,
    centred: bool,
    pivot: Option<&Pivot>,
    align: bool,
) -> StateParts {
    let s = &scene.segments[k];
    let f = s.start + j;
    let (p, h) = (s.pos[j], heads[k][j]);
    let (pp, hp) = (s.pos[j - 1], heads[k][j - 1]);
    let fr = |h: V2| pivot.map_or(h, |pv| pv.dir());
    let intent = if cfg.intent == IntentWindow::Exit {
        exit_intent(&s.pos, j, scene.dt)
    } else {
        intent_at(&s.pos, j, cfg.intent_window, centred, h)
    };
    StateParts {
        speed: (p[0] - pp[0]).hypot(p[1] - pp[1]) / scene.dt,
        now: formation(p, fr(h), scene.others(f, k), cfg.radius),
        prev: formation(pp, fr(hp), scene.others(f - 1, k), cfg.radius),
        pivot: pivot.map(|pv| pivot_parts(p, h, pv.position, pv.dir())),
        intent: to_local(intent, h),
        align: align.then(|| alignment(p, h, scene.others_headed(f, k, heads), cfg.radius)),
    }
}

pub use super::samples::RawSamples;

/// Weighted state–action samples of every segment index with a previous and a next frame whose
/// label matches `want` (`None`: all).
pub fn raw_samples(
    scene: &Scene,
    labels: &[Vec<bool>],
    want: Option<bool>,
    cfg: &FeatureConfig,
    weights: &FeatureWeights,
    pivot: Option<&Pivot>,
    out: &mut RawSamples,
) {
    let centred = cfg.intent == IntentWindow::Centred;
    let align = weights.aligns();
    let heads: Vec<Vec<V2>> = scene
        .segments
        .iter()
        .map(|s| headings(&s.pos, cfg.still_speed * scene.dt))
        .collect();
    for (k, s) in scene.segments.iter().enumerate() {
        if s.pos.len() < 3 {
            continue;
        }
        // The sample this segment wrote for the frame before, if any.
        let mut before: Option<usize> = None;
        for j in 1..s.pos.len() - 1 {
            if want.is_some_and(|w| labels[k][j] != w) {
                before = None;
                continue;
            }
            let me = out.actions.len();
            if let Some(b) = before {
                out.next[b] = me as u32;
            }
            out.next.push(NO_NEXT);
            before = Some(me);
            let st = state_at(scene, k, j, &heads, cfg, centred, pivot, align);
            st.write(weights, &mut out.states);
            let v = [
                (s.pos[j + 1][0] - s.pos[j][0]) / scene.dt,
                (s.pos[j + 1][1] - s.pos[j][1]) / scene.dt,
            ];
            out.actions.push(to_local(v, heads[k][j]));
        }
    }
}

/// Learns a crowd model from tracks (§4–§6.1).
pub fn learn(
    inputs: &[Tracks],
    cfg: &LearnConfig,
    progress: &mut dyn Progress,
) -> Result<CrowdModel> {
    cfg.check()?;
    let Some(first) = inputs.first() else {
        return Err(Error::invalid("no training tracks"));
    };
    let mut scenes = Vec::new();
    for t in inputs {
        if t.meta.units != first.meta.units || (t.meta.fps - first.meta.fps).abs() > 1e-9 {
            return Err(Error::invalid(format!(
                "training tracks mix units or frame rates ({} at {} fps vs {} at {} fps)",
                t.meta.units.as_str(),
                t.meta.fps,
                first.meta.units.as_str(),
                first.meta.fps
            )));
        }
        scenes.push(Scene::from_tracks(t, cfg.smoothing)?);
    }
    let labels: Vec<Vec<Vec<bool>>> = scenes
        .iter()
        .map(|s| behaviour::label(s, &cfg.labels))
        .collect();
    let pairs: Vec<(&Scene, &[Vec<bool>])> = scenes
        .iter()
        .zip(&labels)
        .map(|(s, l)| (s, l.as_slice()))
        .collect();
    let fsm = behaviour::measure(&pairs, &cfg.labels);
    let mut behaviours = Vec::new();
    progress.start("learn", cfg.behaviours.len() as u64);
    for spec in &cfg.behaviours {
        let want = match spec.name.as_str() {
            LOCOMOTION if cfg.behaviours.iter().any(|b| b.name == INTERACTION) => Some(false),
            INTERACTION => Some(true),
            _ => None,
        };
        let weights = spec
            .weights
            .clone()
            .unwrap_or_else(|| cfg.features.weights.clone());
        let dims = FeatureConfig::dims(spec.pivot.is_some(), &weights);
        let mut raw = RawSamples {
            dims,
            states: Vec::new(),
            actions: Vec::new(),
            next: Vec::new(),
        };
        for (scene, l) in scenes.iter().zip(&labels) {
            raw_samples(
                scene,
                l,
                want,
                &cfg.features,
                &weights,
                spec.pivot.as_ref(),
                &mut raw,
            );
        }
        progress.inc(1);
        if raw.actions.len() < cfg.min_samples.max(cfg.pca_dims + 1) {
            if spec.name == LOCOMOTION {
                return Err(Error::invalid(format!(
                    "the tracks give {} locomotion samples; at least {} are needed (min_samples)",
                    raw.actions.len(),
                    cfg.min_samples.max(cfg.pca_dims + 1)
                )));
            }
            continue;
        }
        super::samples::thin(&mut raw, cfg.max_samples, cfg.action.continuation > 0);
        let pca = Pca::fit(&raw.states, dims, cfg.pca_dims)?;
        let mut states = vec![0.0; raw.actions.len() * cfg.pca_dims];
        for (row, out) in raw
            .states
            .chunks_exact(dims)
            .zip(states.chunks_exact_mut(cfg.pca_dims))
        {
            pca.project(row, out);
        }
        let model = ActionModel::new(ActionSamples {
            dims: cfg.pca_dims,
            states,
            actions: raw.actions,
            // Kept (and written) only where the simulation follows them.
            next: if cfg.action.continuation > 0 {
                raw.next
            } else {
                Vec::new()
            },
        })?;
        behaviours.push(Behaviour {
            name: spec.name.clone(),
            weights,
            pivot: spec.pivot.clone(),
            pca,
            model,
        });
    }
    progress.finish();
    Ok(CrowdModel {
        units: first.meta.units,
        dt: 1.0 / first.meta.fps,
        config: cfg.clone(),
        behaviours,
        fsm,
        provenance: serde_json::json!({
            "inputs": inputs.iter().map(|t| t.meta.provenance.clone()).collect::<Vec<_>>(),
        }),
    })
}

/// A direction of travel for an agent with no history: toward `goal` from `p`, else +x.
pub fn toward(p: V2, goal: Option<V2>) -> V2 {
    goal.and_then(|g| unit([g[0] - p[0], g[1] - p[1]]))
        .unwrap_or([1.0, 0.0])
}
