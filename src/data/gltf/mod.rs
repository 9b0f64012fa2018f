//! glTF 2.0 binary (`.glb`) export of any tracks file: one node per animal, a small bird mesh (or
//! none), and one animation whose channels move every node (translation), turn it (rotation) and
//! show it only while it is tracked (scale 1, or 0 outside its frames; STEP).
//!
//! Coordinates: glTF is y up, right-handed, metres, and a model faces +Z. herdfit's 3D tracks
//! are z up, so a point (x, y, z) becomes (x, z, −y) (a −90° turn about x, keeping handedness).
//! 2D tracks lie on the ground plane: (x, y) in `m`/`BL` (y up) becomes (x, 0, −y), and (x, y) in
//! `px` (y down) becomes (x, 0, y). Everything is multiplied by `scale` (glTF metres per track
//! unit). Key times are the tracks' times less the first one, in seconds.
//!
//! Orientations follow Lin's thesis §3.6: the heading starts as the first displacement and then
//! moves by the factor `turn_rate` (0.1) towards each new displacement, o ← N((1 − α) o + α N(Δb)),
//! which keeps tracking noise from spinning the birds; the rotation turns +Z to o with no roll
//! (yaw about y, then pitch).
//!
//! The document is built with `gltf-json`; the file carries `asset.extras.schema =
//! "herdfit.gltf/1"` and the source's units and provenance.

use crate::data::tracks::{Tracks, Units};
use crate::error::{Error, Result};
use gj::validation::Checked::Valid;
use gj::validation::USize64;
use gltf_json as gj;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag in `asset.extras` of exported files.
pub const GLTF_SCHEMA: &str = "herdfit.gltf/1";

/// Export settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GltfConfig {
    /// glTF metres per track unit.
    pub scale: f64,
    /// Length of the bird mesh in glTF metres; by default 0.35 for tracks in metres, 1 track
    /// unit (× scale) for body lengths, 10 px (× scale) for pixels.
    pub body_length: Option<f64>,
    /// A bird mesh on every node; off: empty nodes (for rigs of one's own).
    pub mesh: bool,
    /// α of the orientation smoothing (thesis §3.6).
    pub turn_rate: f64,
}

impl Default for GltfConfig {
    fn default() -> Self {
        GltfConfig {
            scale: 1.0,
            body_length: None,
            mesh: true,
            turn_rate: 0.1,
        }
    }
}

impl GltfConfig {
    /// Checks ranges; errors name the key.
    pub fn check(&self) -> Result<()> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(Error::invalid(format!(
                "scale = {} must be > 0",
                self.scale
            )));
        }
        // glTF positions are f32 metres: within ±MAX_COORD after scaling (issue #47: --scale
        // 1e300 wrote infinities).
        use crate::limits::{within, MAX_COORD};
        within("scale", self.scale, 0.0, MAX_COORD)?;
        if let Some(b) = self.body_length {
            if !(b.is_finite() && b > 0.0) {
                return Err(Error::invalid(format!("body_length = {b} must be > 0")));
            }
            within("body_length", b, 0.0, MAX_COORD)?;
        }
        if !(self.turn_rate > 0.0 && self.turn_rate <= 1.0) {
            return Err(Error::invalid(format!(
                "turn_rate = {} must be in (0, 1]",
                self.turn_rate
            )));
        }
        Ok(())
    }
}

/// What an export wrote.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GltfSummary {
    pub nodes: usize,
    pub keyframes: usize,
    /// Seconds from the first key to the last.
    pub duration: f64,
    pub bytes: usize,
}

type V3 = [f64; 3];

mod orient;
mod read;
pub use orient::{bird_mesh, heading_quaternion, rotate, smoothed_headings, to_gltf};
pub use read::{read_glb, Glb, NodePose};

/// The binary buffer and the JSON objects that describe it.
#[derive(Default)]
struct Builder {
    root: gj::Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends f32 data as one buffer view + accessor (min/max recorded when `bounds`).
    fn floats(
        &mut self,
        data: &[f32],
        ty: gj::accessor::Type,
        width: usize,
        bounds: bool,
        target: Option<gj::buffer::Target>,
    ) -> gj::Index<gj::Accessor> {
        while self.bin.len() % 4 != 0 {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        for v in data {
            self.bin.extend_from_slice(&v.to_le_bytes());
        }
        let view = self.root.push(gj::buffer::View {
            buffer: gj::Index::new(0),
            byte_length: USize64::from(data.len() * 4),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        });
        let (min, max) = if bounds {
            let mut lo = vec![f32::INFINITY; width];
            let mut hi = vec![f32::NEG_INFINITY; width];
            for (k, v) in data.iter().enumerate() {
                lo[k % width] = lo[k % width].min(*v);
                hi[k % width] = hi[k % width].max(*v);
            }
            (Some(serde_json::json!(lo)), Some(serde_json::json!(hi)))
        } else {
            (None, None)
        };
        self.root.push(gj::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(data.len() / width),
            component_type: Valid(gj::accessor::GenericComponentType(
                gj::accessor::ComponentType::F32,
            )),
            extensions: None,
            extras: Default::default(),
            type_: Valid(ty),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    #[allow(clippy::too_many_arguments)] // one glTF sampler's fields, each a different kind
    fn sampler(
        &mut self,
        anim: &mut gj::Animation,
        node: gj::Index<gj::Node>,
        path: gj::animation::Property,
        times: &[f32],
        values: &[f32],
        ty: gj::accessor::Type,
        width: usize,
        interpolation: gj::animation::Interpolation,
    ) {
        let input = self.floats(times, gj::accessor::Type::Scalar, 1, true, None);
        let output = self.floats(values, ty, width, false, None);
        let sampler = gj::Index::push(
            &mut anim.samplers,
            gj::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Valid(interpolation),
                output,
            },
        );
        anim.channels.push(gj::animation::Channel {
            sampler,
            target: gj::animation::Target {
                extensions: None,
                extras: Default::default(),
                node,
                path: Valid(path),
            },
            extensions: None,
            extras: Default::default(),
        });
    }
}

fn f32s(v: impl IntoIterator<Item = f64>) -> Vec<f32> {
    v.into_iter().map(|x| x as f32).collect()
}

fn default_body_length(units: Units) -> f64 {
    match units {
        Units::Metres => 0.35,
        Units::BodyLengths => 1.0,
        Units::Pixels => 10.0,
    }
}

/// The mesh of every node: the bird, with a dark matte double-sided material.
fn add_mesh(b: &mut Builder, length: f64) -> gj::Index<gj::Mesh> {
    let (pos, nor) = bird_mesh(length);
    let p = b.floats(
        &f32s(pos.iter().flatten().copied()),
        gj::accessor::Type::Vec3,
        3,
        true,
        Some(gj::buffer::Target::ArrayBuffer),
    );
    let n = b.floats(
        &f32s(nor.iter().flatten().copied()),
        gj::accessor::Type::Vec3,
        3,
        false,
        Some(gj::buffer::Target::ArrayBuffer),
    );
    let material = b.root.push(gj::Material {
        double_sided: true,
        name: Some("bird".into()),
        pbr_metallic_roughness: gj::material::PbrMetallicRoughness {
            base_color_factor: gj::material::PbrBaseColorFactor([0.12, 0.12, 0.14, 1.0]),
            metallic_factor: gj::material::StrengthFactor(0.0),
            roughness_factor: gj::material::StrengthFactor(0.8),
            ..Default::default()
        },
        ..Default::default()
    });
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(Valid(gj::mesh::Semantic::Positions), p);
    attributes.insert(Valid(gj::mesh::Semantic::Normals), n);
    b.root.push(gj::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("bird".into()),
        primitives: vec![gj::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: None,
            material: Some(material),
            mode: Valid(gj::mesh::Mode::Triangles),
            targets: None,
        }],
        weights: None,
    })
}

/// One animal's keys: times, glTF positions, rotations and visibility changes.
struct Keys {
    id: u64,
    times: Vec<f64>,
    pos: Vec<V3>,
    rot: Vec<[f64; 4]>,
    /// (time, visible) at every change, starting at 0.
    shown: Vec<(f64, bool)>,
}

fn keys_of(tracks: &Tracks, cfg: &GltfConfig) -> Result<Vec<Keys>> {
    let t0 = tracks.rows.first().map_or(0.0, |r| r.time);
    let dt = 1.0 / tracks.meta.fps;
    let mut out = Vec::new();
    for (id, rows) in tracks.by_id() {
        let r: Vec<_> = rows.iter().map(|&i| &tracks.rows[i]).collect();
        let pos: Vec<V3> = r
            .iter()
            .map(|x| {
                to_gltf(tracks.meta.units, tracks.meta.dimension, x.pos).map(|c| c * cfg.scale)
            })
            .collect();
        // Headings per segment (a gap restarts the smoothing).
        let mut rot = Vec::with_capacity(r.len());
        let mut shown = vec![(0.0, false)];
        let mut start = 0;
        for k in 1..=r.len() {
            if k == r.len() || r[k].frame != r[k - 1].frame + 1 {
                let heads = smoothed_headings(&pos[start..k], cfg.turn_rate);
                let mut prev: Option<[f64; 4]> = rot.last().copied();
                for h in heads {
                    let mut q = heading_quaternion(h);
                    if let Some(p) = prev {
                        if p.iter().zip(&q).map(|(a, b)| a * b).sum::<f64>() < 0.0 {
                            q = q.map(|c| -c);
                        }
                    }
                    prev = Some(q);
                    rot.push(q);
                }
                let (on, off) = (r[start].time - t0, r[k - 1].time - t0 + dt);
                if on == 0.0 {
                    shown[0].1 = true;
                } else {
                    shown.push((on, true));
                }
                shown.push((off, false));
                start = k;
            }
        }
        let times: Vec<f64> = r.iter().map(|x| x.time - t0).collect();
        for w in times.windows(2).chain(
            shown
                .iter()
                .map(|s| s.0)
                .collect::<Vec<_>>()
                .windows(2)
                .collect::<Vec<_>>(),
        ) {
            if (w[1] as f32) <= (w[0] as f32) {
                return Err(Error::invalid(format!(
                    "id {id}: key times {} and {} are not increasing in 32-bit floats",
                    w[0], w[1]
                )));
            }
        }
        out.push(Keys {
            id,
            times,
            pos,
            rot,
            shown,
        });
    }
    Ok(out)
}

/// The GLB bytes of `tracks` (see the module docs).
pub fn to_glb(tracks: &Tracks, cfg: &GltfConfig) -> Result<(Vec<u8>, GltfSummary)> {
    cfg.check()?;
    tracks.check()?;
    // Every scaled coordinate within the limit, so that no f32 of the file overflows.
    let reach = tracks
        .rows
        .iter()
        .flat_map(|r| r.pos)
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if reach * cfg.scale > crate::limits::MAX_COORD {
        return Err(Error::invalid(format!(
            "scale = {}: the tracks reach {} units, {} glTF metres; at most {} fit",
            crate::limits::show(cfg.scale),
            crate::limits::show(reach),
            crate::limits::show(reach * cfg.scale),
            crate::limits::show(crate::limits::MAX_COORD)
        )));
    }
    let keys = keys_of(tracks, cfg)?;
    let mut b = Builder::default();
    let length = cfg
        .body_length
        .unwrap_or_else(|| default_body_length(tracks.meta.units) * cfg.scale);
    let mesh = cfg.mesh.then(|| add_mesh(&mut b, length));
    let mut anim = gj::Animation {
        extensions: None,
        extras: Default::default(),
        channels: Vec::new(),
        name: Some("flight".into()),
        samplers: Vec::new(),
    };
    let mut nodes = Vec::new();
    let (mut nkeys, mut last) = (0, 0.0f64);
    for k in &keys {
        let visible0 = k.shown[0].1;
        let node = b.root.push(gj::Node {
            mesh,
            name: Some(format!("bird {}", k.id)),
            translation: Some(f32s(k.pos[0]).try_into().expect("three")),
            rotation: Some(gj::scene::UnitQuaternion(
                f32s(k.rot[0]).try_into().expect("four"),
            )),
            scale: Some(if visible0 { [1.0; 3] } else { [0.0; 3] }),
            ..Default::default()
        });
        nodes.push(node);
        let times = f32s(k.times.iter().copied());
        use gj::accessor::Type::{Vec3, Vec4};
        use gj::animation::{Interpolation as I, Property as P};
        let pos = f32s(k.pos.iter().flatten().copied());
        b.sampler(
            &mut anim,
            node,
            P::Translation,
            &times,
            &pos,
            Vec3,
            3,
            I::Linear,
        );
        let rot = f32s(k.rot.iter().flatten().copied());
        b.sampler(
            &mut anim,
            node,
            P::Rotation,
            &times,
            &rot,
            Vec4,
            4,
            I::Linear,
        );
        let st = f32s(k.shown.iter().map(|s| s.0));
        let sv = f32s(
            k.shown
                .iter()
                .flat_map(|s| [if s.1 { 1.0 } else { 0.0 }; 3]),
        );
        b.sampler(&mut anim, node, P::Scale, &st, &sv, Vec3, 3, I::Step);
        nkeys += k.times.len();
        last = last.max(k.shown.last().map_or(0.0, |s| s.0));
    }
    b.root.animations.push(anim);
    let scene = b.root.push(gj::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("flock".into()),
        nodes,
    });
    b.root.scene = Some(scene);
    while b.bin.len() % 4 != 0 {
        b.bin.push(0);
    }
    b.root.push(gj::Buffer {
        byte_length: USize64::from(b.bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let extras = serde_json::json!({
        "schema": GLTF_SCHEMA,
        "source_units": tracks.meta.units.as_str(),
        "source_dimension": tracks.meta.dimension,
        "scale": cfg.scale,
        "up": "+y (tracks z, or the ground plane's normal in 2D)",
        "provenance": tracks.meta.provenance,
    });
    b.root.asset = gj::Asset {
        copyright: None,
        extensions: None,
        extras: Some(
            serde_json::value::to_raw_value(&extras)
                .map_err(|e| Error::Internal(format!("glTF extras: {e}")))?,
        ),
        generator: Some(format!("herdfit {}", env!("CARGO_PKG_VERSION"))),
        min_version: None,
        version: "2.0".into(),
    };
    let json = b
        .root
        .to_vec()
        .map_err(|e| Error::Internal(format!("glTF JSON: {e}")))?;
    let bytes = glb_container(json, &b.bin);
    let summary = GltfSummary {
        nodes: keys.len(),
        keyframes: nkeys,
        duration: last,
        bytes: bytes.len(),
    };
    Ok((bytes, summary))
}

/// The GLB container: 12-byte header, JSON chunk (space-padded), BIN chunk (zero-padded).
fn glb_container(mut json: Vec<u8>, bin: &[u8]) -> Vec<u8> {
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(&0x4654_6C67u32.to_le_bytes());
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x4E4F_534Au32.to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(&0x004E_4942u32.to_le_bytes());
    out.extend_from_slice(bin);
    out
}

/// Writes the GLB of `tracks` to `path` atomically.
pub fn export_glb(tracks: &Tracks, cfg: &GltfConfig, path: &Path) -> Result<GltfSummary> {
    let (bytes, summary) = to_glb(tracks, cfg)?;
    crate::data::atomic::write_atomic(path, &bytes)?;
    Ok(summary)
}
