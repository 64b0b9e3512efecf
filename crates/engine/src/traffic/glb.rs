//! Aircraft models from glTF 2.0 binary files (`.glb`), read with the `gltf` crate, and the
//! built-in shapes written as `.glb` (so they can be opened, changed and given back).
//!
//! Every triangle primitive of the default scene (or of every root node when there is no
//! scene) is taken, placed by its nodes' transforms, with glTF's axes (`+Y` up, `+Z` forward,
//! `+X` left, metres) turned into the model's (`x` forward, `y` left, `z` up). Normals are
//! made flat from the triangles, as the built-in shapes'. Primitives whose material is named
//! `accent` are drawn in the aircraft's colour, the rest white. Only self-contained files are
//! read: buffers must be the file's own binary chunk.
//!
//! Files are outside data: at most [`MAX_GLB_BYTES`] are read, at most [`MAX_TRIANGLES`]
//! taken, every index checked against its vertices and every position finite.

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};

use super::models::ModelMesh;

/// The largest `.glb` read.
pub const MAX_GLB_BYTES: u64 = 64 << 20;
/// The most triangles a model may have.
pub const MAX_TRIANGLES: usize = 500_000;
/// Nodes nested deeper than this are not followed.
const MAX_DEPTH: usize = 64;

/// A model file that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file could not be read.
    #[error("{path}: cannot read the model: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid glTF 2.0 binary.
    #[error("{path}: not a usable glTF 2.0 binary (.glb): {reason}")]
    Gltf {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        reason: String,
    },
    /// The glTF is valid but its content cannot be drawn.
    #[error("{path}: {reason}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Reads a model from a `.glb` file.
pub fn read_glb(path: &Path) -> Result<ModelMesh, ModelError> {
    let bytes = globus_tiling::files::read_capped(path, MAX_GLB_BYTES).map_err(|source| {
        ModelError::Read {
            path: path.to_owned(),
            source,
        }
    })?;
    model_from_glb(&bytes, path)
}

/// Reads a model from `.glb` bytes; `name` is what errors call it.
pub fn model_from_glb(bytes: &[u8], name: &Path) -> Result<ModelMesh, ModelError> {
    let gltf_err = |e: gltf::Error| ModelError::Gltf {
        path: name.to_owned(),
        reason: e.to_string(),
    };
    let content = |reason: String| ModelError::Content {
        path: name.to_owned(),
        reason,
    };
    check_glb_length(bytes, name)?;
    check_position_accessors(bytes, name)?;
    let gltf = gltf::Gltf::from_slice(bytes).map_err(gltf_err)?;
    for buffer in gltf.buffers() {
        if !matches!(buffer.source(), gltf::buffer::Source::Bin) {
            return Err(content(format!(
                "buffer {} lies outside the file; only self-contained .glb files are read",
                buffer.index()
            )));
        }
    }
    let blob = gltf.blob.as_deref().unwrap_or(&[]);
    let roots: Vec<gltf::Node<'_>> = match gltf.default_scene().or_else(|| gltf.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => gltf.nodes().collect(),
    };
    // glTF (x left, y up, z forward) to the model's (x forward, y left, z up).
    let axes = |p: [f32; 3]| [p[2], p[0], p[1]];
    let mut mesh_out = ModelMesh::default();
    let mut taken = 0usize;
    let mut stack: Vec<(gltf::Node<'_>, Mat4, usize)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY, 0)).collect();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > MAX_DEPTH {
            return Err(content(format!("nodes nest deeper than {MAX_DEPTH}")));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        for child in node.children() {
            stack.push((child, world, depth + 1));
        }
        let Some(mesh) = node.mesh() else { continue };
        for primitive in mesh.primitives() {
            if primitive.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let accent = primitive
                .material()
                .name()
                .is_some_and(|n| n.eq_ignore_ascii_case("accent"));
            // The reader panics on types the specification forbids here (float indices,
            // integer positions) rather than refusing them: check first.
            use gltf::accessor::{DataType, Dimensions};
            if let Some(a) = primitive.get(&gltf::Semantic::Positions)
                && (a.data_type() != DataType::F32 || a.dimensions() != Dimensions::Vec3)
            {
                return Err(content(format!(
                    "mesh {} has positions that are not three floats",
                    mesh.index()
                )));
            }
            if let Some(a) = primitive.indices()
                && (!matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
                    || a.dimensions() != Dimensions::Scalar)
            {
                return Err(content(format!(
                    "mesh {} has indices that are not unsigned integers",
                    mesh.index()
                )));
            }
            let reader = primitive.reader(|b| (b.index() == 0).then_some(blob));
            let Some(positions) = reader.read_positions() else {
                return Err(content(format!(
                    "mesh {} has a primitive without readable positions",
                    mesh.index()
                )));
            };
            let positions: Vec<[f32; 3]> = positions
                .map(|p| world.transform_point3(Vec3::from(p)).to_array())
                .collect();
            if positions.iter().flatten().any(|v| !v.is_finite()) {
                return Err(content(format!(
                    "mesh {} has a position that is not finite",
                    mesh.index()
                )));
            }
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            for t in indices.chunks_exact(3) {
                let get = |i: u32| {
                    positions.get(i as usize).copied().ok_or_else(|| {
                        content(format!(
                            "mesh {} indexes vertex {i} of {}",
                            mesh.index(),
                            positions.len()
                        ))
                    })
                };
                mesh_out.push_triangle(
                    axes(get(t[0])?),
                    axes(get(t[1])?),
                    axes(get(t[2])?),
                    accent,
                );
                taken += 1;
                if taken > MAX_TRIANGLES {
                    return Err(content(format!("more than {MAX_TRIANGLES} triangles")));
                }
            }
        }
    }
    if mesh_out.triangles() == 0 {
        return Err(content("no triangles to draw".into()));
    }
    Ok(mesh_out)
}

/// Refuses a primitive whose `POSITION` names an accessor the file does not have: the
/// `gltf` crate's validation (gltf-json 1.4) indexes that accessor before checking it, and
/// panics (found by this crate's fuzzer). JSON that does not parse is left to the full
/// reader, which says why.
/// The length a GLB header declares must hold the header and a chunk header and fit in the
/// file: the `gltf` crate (1.4) subtracts the header's size from it unchecked.
fn check_glb_length(bytes: &[u8], name: &Path) -> Result<(), ModelError> {
    let Some((b"glTF", rest)) = bytes.split_first_chunk::<4>() else {
        return Ok(());
    };
    let Some(length) = rest
        .get(4..8)
        .and_then(|b| <[u8; 4]>::try_from(b).ok())
        .map(u32::from_le_bytes)
    else {
        return Ok(());
    };
    if (20..=bytes.len() as u64).contains(&u64::from(length)) {
        return Ok(());
    }
    Err(ModelError::Gltf {
        path: name.to_owned(),
        reason: format!(
            "the header declares {length} bytes, the file has {}",
            bytes.len()
        ),
    })
}

fn check_position_accessors(bytes: &[u8], name: &Path) -> Result<(), ModelError> {
    let Ok(glb) = gltf::Glb::from_slice(bytes) else {
        return Ok(());
    };
    let Ok(root) = gltf::json::Root::from_slice(&glb.json) else {
        return Ok(());
    };
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let position = gltf::json::validation::Checked::Valid(gltf::Semantic::Positions);
            if let Some(i) = primitive.attributes.get(&position)
                && i.value() >= accessors
            {
                return Err(ModelError::Gltf {
                    path: name.to_owned(),
                    reason: format!(
                        "mesh {m} primitive {p}: POSITION is accessor {} of {accessors}",
                        i.value()
                    ),
                });
            }
        }
    }
    Ok(())
}

/// A model as `.glb` bytes: one node, one mesh with a primitive per paint (materials
/// `airframe` and `accent`), positions and flat normals in glTF's axes.
pub fn write_glb(mesh: &ModelMesh) -> Vec<u8> {
    // The model's (x forward, y left, z up) to glTF's (x left, y up, z forward).
    let axes = |p: [f32; 3]| [p[1], p[2], p[0]];
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut primitives = Vec::new();
    for (material, paint) in [(0, 0u8), (1, 1u8)] {
        let picked: Vec<usize> = (0..mesh.positions.len())
            .filter(|&i| mesh.accents.get(i).copied().unwrap_or(0) == paint)
            .collect();
        if picked.is_empty() {
            continue;
        }
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let first = accessors.len();
        for (data, bounds) in [(&mesh.positions, true), (&mesh.normals, false)] {
            let offset = bin.len();
            for &i in &picked {
                let v = axes(data[i]);
                if bounds {
                    for k in 0..3 {
                        lo[k] = lo[k].min(v[k]);
                        hi[k] = hi[k].max(v[k]);
                    }
                }
                for c in v {
                    bin.extend_from_slice(&c.to_le_bytes());
                }
            }
            views.push(format!(
                r#"{{"buffer":0,"byteOffset":{offset},"byteLength":{},"target":34962}}"#,
                bin.len() - offset
            ));
            let minmax = if bounds {
                format!(
                    r#","min":[{},{},{}],"max":[{},{},{}]"#,
                    lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
                )
            } else {
                String::new()
            };
            accessors.push(format!(
                r#"{{"bufferView":{},"componentType":5126,"count":{},"type":"VEC3"{minmax}}}"#,
                views.len() - 1,
                picked.len()
            ));
        }
        primitives.push(format!(
            r#"{{"attributes":{{"POSITION":{first},"NORMAL":{}}},"material":{material},"mode":4}}"#,
            first + 1
        ));
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0","generator":"Globus"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{}]}}],"materials":[{{"name":"airframe","pbrMetallicRoughness":{{"baseColorFactor":[0.8,0.82,0.85,1]}}}},{{"name":"accent","pbrMetallicRoughness":{{"baseColorFactor":[0.2,0.4,0.9,1]}}}}],"buffers":[{{"byteLength":{}}}],"bufferViews":[{}],"accessors":[{}]}}"#,
        primitives.join(","),
        bin.len(),
        views.join(","),
        accessors.join(",")
    );
    pack_glb(json.into_bytes(), bin)
}

/// A GLB container: the header, the JSON chunk (padded with spaces) and the binary chunk
/// (padded with zeros).
pub(crate) fn pack_glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

#[cfg(test)]
mod tests;
