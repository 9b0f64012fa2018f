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
        if let Some(b) = self.body_length {
            if !(b.is_finite() && b > 0.0) {
                return Err(Error::invalid(format!("body_length = {b} must be > 0")));
            }
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

/// A tracks position in glTF coordinates (see the module docs), before `scale`.
pub fn to_gltf(units: Units, dimension: u8, p: V3) -> V3 {
    match (dimension, units) {
        (3, _) => [p[0], p[2], -p[1]],
        (_, Units::Pixels) => [p[0], 0.0, p[1]],
        _ => [p[0], 0.0, -p[1]],
    }
}

fn unit(a: V3) -> Option<V3> {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| a.map(|c| c / n))
}

/// Headings of one track by §3.6's smoothing (`alpha` = turn rate). Frames before the first
/// displacement take the first displacement's direction (the thesis's o² = b² − b¹); a track that
/// never moves faces +Z.
pub fn smoothed_headings(points: &[V3], alpha: f64) -> Vec<V3> {
    let mut out: Vec<Option<V3>> = Vec::with_capacity(points.len());
    let mut o: Option<V3> = None;
    for (k, p) in points.iter().enumerate() {
        if k > 0 {
            let step = [0, 1, 2].map(|c| p[c] - points[k - 1][c]);
            if let Some(s) = unit(step) {
                o = match o {
                    None => Some(s),
                    Some(prev) => {
                        unit([0, 1, 2].map(|c| (1.0 - alpha) * prev[c] + alpha * s[c])).or(Some(s))
                    }
                };
            }
        }
        out.push(o);
    }
    let first = out
        .iter()
        .flatten()
        .next()
        .copied()
        .unwrap_or([0.0, 0.0, 1.0]);
    out.into_iter().map(|h| h.unwrap_or(first)).collect()
}

/// The unit quaternion `[x, y, z, w]` turning +Z to the unit vector `h` with no roll.
pub fn heading_quaternion(h: V3) -> [f64; 4] {
    let yaw = h[0].atan2(h[2]);
    let pitch = -h[1].clamp(-1.0, 1.0).asin();
    let (sy, cy) = (0.5 * yaw).sin_cos();
    let (sx, cx) = (0.5 * pitch).sin_cos();
    [cy * sx, sy * cx, -sy * sx, cy * cx]
}

/// Rotates `v` by the unit quaternion `q = [x, y, z, w]`.
pub fn rotate(q: [f64; 4], v: V3) -> V3 {
    let u = [q[0], q[1], q[2]];
    let w = q[3];
    let cross = |a: V3, b: V3| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v).map(|c| 2.0 * c);
    let ut = cross(u, t);
    [0, 1, 2].map(|c| v[c] + w * t[c] + ut[c])
}

/// Triangles of the bird mesh for body length `l`: a body along z (nose at +z) and two swept
/// wings along ±x (span 1.8 l), flat-shaded (three vertices per face, with its normal).
pub fn bird_mesh(l: f64) -> (Vec<V3>, Vec<V3>) {
    let nose = [0.0, 0.0, 0.55 * l];
    let tail = [0.0, 0.0, -0.45 * l];
    let (w, h) = (0.09 * l, 0.08 * l);
    let ring = [[w, 0.0, 0.0], [0.0, h, 0.0], [-w, 0.0, 0.0], [0.0, -h, 0.0]];
    let mut tris: Vec<[V3; 3]> = Vec::new();
    for k in 0..4 {
        let (a, b) = (ring[k], ring[(k + 1) % 4]);
        tris.push([nose, b, a]);
        tris.push([tail, a, b]);
    }
    for s in [1.0, -1.0] {
        let root_front = [0.0, 0.0, 0.15 * l];
        let root_back = [0.0, 0.0, -0.15 * l];
        let tip = [s * 0.9 * l, 0.02 * l, -0.2 * l];
        if s > 0.0 {
            tris.push([root_front, root_back, tip]);
        } else {
            tris.push([root_front, tip, root_back]);
        }
    }
    let mut pos = Vec::new();
    let mut nor = Vec::new();
    for t in &tris {
        let e1 = [0, 1, 2].map(|c| t[1][c] - t[0][c]);
        let e2 = [0, 1, 2].map(|c| t[2][c] - t[0][c]);
        let n = unit([
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ])
        .unwrap_or([0.0, 1.0, 0.0]);
        for v in t {
            pos.push(*v);
            nor.push(n);
        }
    }
    (pos, nor)
}

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
                .collect::<Vec<_>>()
                .into_iter(),
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

/// A GLB read back: its JSON document and binary chunk.
pub struct Glb {
    pub root: gj::Root,
    pub bin: Vec<u8>,
}

/// Reads a GLB written by [`export_glb`] (or any GLB with one embedded buffer).
pub fn read_glb(path: &Path) -> Result<Glb> {
    crate::data::atomic::note_input(path);
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let bad = |m: &str| Error::file(path, format!("not a GLB file: {m}"));
    let u32_at = |o: usize| -> Result<u32> {
        bytes
            .get(o..o + 4)
            .map(|s| u32::from_le_bytes(s.try_into().expect("four bytes")))
            .ok_or_else(|| bad("truncated"))
    };
    if u32_at(0)? != 0x4654_6C67 || u32_at(4)? != 2 {
        return Err(bad("no glTF 2 header"));
    }
    let jl = u32_at(12)? as usize;
    let json = bytes
        .get(20..20 + jl)
        .ok_or_else(|| bad("truncated JSON chunk"))?;
    let root = gj::Root::from_slice(json).map_err(|e| bad(&e.to_string()))?;
    let bin = match u32_at(20 + jl) {
        Ok(bl) => bytes
            .get(28 + jl..28 + jl + bl as usize)
            .ok_or_else(|| bad("truncated BIN chunk"))?
            .to_vec(),
        Err(_) => Vec::new(),
    };
    Ok(Glb { root, bin })
}

impl Glb {
    /// The f32 values of accessor `a` (tightly packed float accessors only).
    pub fn floats(&self, a: gj::Index<gj::Accessor>) -> Result<Vec<f32>> {
        let acc = self
            .root
            .get(a)
            .ok_or_else(|| Error::invalid("accessor index out of range"))?;
        let view = acc
            .buffer_view
            .and_then(|v| self.root.get(v))
            .ok_or_else(|| Error::invalid("accessor without a buffer view"))?;
        let width = match acc.type_ {
            Valid(gj::accessor::Type::Scalar) => 1,
            Valid(gj::accessor::Type::Vec3) => 3,
            Valid(gj::accessor::Type::Vec4) => 4,
            _ => return Err(Error::invalid("unsupported accessor type")),
        };
        let start = view.byte_offset.map_or(0, |o| o.0 as usize)
            + acc.byte_offset.map_or(0, |o| o.0 as usize);
        let n = acc.count.0 as usize * width;
        let raw = self
            .bin
            .get(start..start + 4 * n)
            .ok_or_else(|| Error::invalid("accessor beyond the buffer"))?;
        Ok(raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("four bytes")))
            .collect())
    }

    /// Every node's (name, translation, rotation, scale) at time `t` of the first animation
    /// (linear translation, normalised-linear rotation, step scale).
    pub fn sample(&self, t: f64) -> Result<Vec<(String, V3, [f64; 4], V3)>> {
        let mut out: Vec<(String, V3, [f64; 4], V3)> = self
            .root
            .nodes
            .iter()
            .map(|n| {
                (
                    n.name.clone().unwrap_or_default(),
                    n.translation.map_or([0.0; 3], |v| v.map(f64::from)),
                    n.rotation
                        .map_or([0.0, 0.0, 0.0, 1.0], |q| q.0.map(f64::from)),
                    n.scale.map_or([1.0; 3], |v| v.map(f64::from)),
                )
            })
            .collect();
        let Some(anim) = self.root.animations.first() else {
            return Ok(out);
        };
        for ch in &anim.channels {
            let s = &anim.samplers[ch.sampler.value()];
            let times = self.floats(s.input)?;
            let vals = self.floats(s.output)?;
            let w = vals.len() / times.len().max(1);
            let k = times.partition_point(|&x| f64::from(x) <= t);
            let step = matches!(s.interpolation, Valid(gj::animation::Interpolation::Step));
            let value: Vec<f64> = if k == 0 {
                vals[..w].iter().map(|&v| v.into()).collect()
            } else if k == times.len() || step {
                vals[(k - 1) * w..k * w].iter().map(|&v| v.into()).collect()
            } else {
                let (t0, t1) = (f64::from(times[k - 1]), f64::from(times[k]));
                let a = (t - t0) / (t1 - t0);
                (0..w)
                    .map(|c| {
                        (1.0 - a) * f64::from(vals[(k - 1) * w + c])
                            + a * f64::from(vals[k * w + c])
                    })
                    .collect()
            };
            let node = &mut out[ch.target.node.value()];
            match ch.target.path {
                Valid(gj::animation::Property::Translation) => {
                    node.1 = [value[0], value[1], value[2]]
                }
                Valid(gj::animation::Property::Rotation) => {
                    let n = value.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
                    node.2 = [value[0] / n, value[1] / n, value[2] / n, value[3] / n];
                }
                Valid(gj::animation::Property::Scale) => node.3 = [value[0], value[1], value[2]],
                _ => {}
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heading_quaternion_turns_plus_z_onto_the_heading() {
        for h in [
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.6, 0.0, 0.8],
            [0.3, 0.5, -0.81],
            [0.0, 1.0, 0.0],
        ] {
            let h = unit(h).unwrap();
            let q = heading_quaternion(h);
            let r = rotate(q, [0.0, 0.0, 1.0]);
            for c in 0..3 {
                assert!((r[c] - h[c]).abs() < 1e-9, "{h:?} → {r:?}");
            }
            // No roll: the wing axis (+x) stays horizontal.
            assert!(rotate(q, [1.0, 0.0, 0.0])[1].abs() < 1e-9);
        }
    }

    #[test]
    fn headings_follow_section_3_6() {
        let pts: Vec<V3> = (0..5)
            .map(|k| [0.0, 0.0, k as f64])
            .chain([[1.0, 0.0, 4.0]])
            .collect();
        let h = smoothed_headings(&pts, 0.1);
        assert_eq!(h[0], [0.0, 0.0, 1.0]);
        assert_eq!(h[4], [0.0, 0.0, 1.0]);
        // A sharp turn to +x moves the heading by about a tenth of the way.
        let want = unit([0.1, 0.0, 0.9]).unwrap();
        for c in 0..3 {
            assert!((h[5][c] - want[c]).abs() < 1e-12);
        }
    }
}
