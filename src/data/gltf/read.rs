//! Reading an exported GLB back (tests, the preview render): its document, binary chunk and the
//! animation sampled at a time.

use crate::error::{Error, Result};
use gj::validation::Checked::Valid;
use gltf_json as gj;
use std::path::Path;

type V3 = [f64; 3];

/// A node's name, translation, rotation (x, y, z, w) and scale at one time.
pub type NodePose = (String, V3, [f64; 4], V3);

/// A GLB read back: its JSON document and binary chunk.
pub struct Glb {
    pub root: gj::Root,
    pub bin: Vec<u8>,
}

/// Reads a GLB written by [`super::export_glb`] (or any GLB with one embedded buffer).
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
        let raw = (acc.count.0 as usize)
            .checked_mul(4 * width)
            .and_then(|len| self.bin.get(start..start.checked_add(len)?))
            .ok_or_else(|| Error::invalid("accessor beyond the buffer"))?;
        let v: Vec<f32> = raw
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("four bytes")))
            .collect();
        if v.iter().any(|x| !x.is_finite()) {
            return Err(Error::invalid("an accessor holds a non-finite value"));
        }
        Ok(v)
    }

    /// Every node's (name, translation, rotation, scale) at time `t` of the first animation
    /// (linear translation, normalised-linear rotation, step scale).
    pub fn sample(&self, t: f64) -> Result<Vec<NodePose>> {
        let mut out: Vec<NodePose> = self
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
            let s = anim
                .samplers
                .get(ch.sampler.value())
                .ok_or_else(|| Error::invalid("a channel's sampler index is out of range"))?;
            let times = self.floats(s.input)?;
            let vals = self.floats(s.output)?;
            if times.is_empty() || times.windows(2).any(|p| p[1] <= p[0]) {
                return Err(Error::invalid(
                    "a sampler's times are empty or do not increase",
                ));
            }
            let w = match ch.target.path {
                Valid(gj::animation::Property::Rotation) => 4,
                _ => 3,
            };
            if vals.len() != times.len() * w {
                return Err(Error::invalid(format!(
                    "a sampler has {} values for {} times of width {w}",
                    vals.len(),
                    times.len()
                )));
            }
            if ch.target.node.value() >= out.len() {
                return Err(Error::invalid("a channel's node index is out of range"));
            }
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
