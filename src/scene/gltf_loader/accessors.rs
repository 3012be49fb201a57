//! Buffers and their accessors: the buffers' bytes loaded (from the GLB's
//! binary chunk, a `data:` URI or a file next to the scene), and accessor
//! elements decoded with bounds-checked code (glTF §3.6), sparse
//! substitutions and `KHR_mesh_quantization`'s integer vertex attributes
//! included.

use super::files::{confined_uri_file, read_regular_file};
use super::Res;
use glam::Vec3;
use gltf::accessor::{DataType, Dimensions};
use std::path::Path;

/// Accessors without a buffer view are all zeros and cost no file bytes, so
/// their `count` is the only thing bounding the allocation: cap it.
const MAX_VIEWLESS_BYTES: usize = 1 << 28;

/// The most the scene's meshes (every node's instance) and animation
/// channels may decode to, in bytes. Each accessor is bounded by its file
/// bytes, or by [`MAX_VIEWLESS_BYTES`], but one accessor may be named by
/// many primitives, meshes by many nodes: a 3 KB file naming a 256 MiB
/// accessor of zeros from 64 primitives asked for 32 GiB.
const MAX_DECODED_BYTES: u64 = 1 << 32;

/// Refuses a file whose meshes and animations would decode to more than
/// [`MAX_DECODED_BYTES`], from the accessors' declared counts, before any
/// is decoded: for each triangle primitive of each node's mesh, its
/// positions and normals (given or computed, `Vec3`), its indices (or
/// `0..n`, `u32`) and its triangles (three `u32` corners and a material
/// id); for each channel of a scene node the loader reads, its keys.
/// Points, lines and morph-target weights, which the loader skips, do not
/// count, nor do skins' inverse bind matrices: one is read for each skin
/// (`mesh::first_inverse_bind`), however many its accessor holds.
pub(super) fn check_decoded_bytes(
    gnodes: &[gltf::Node],
    document: &gltf::Document,
    in_scene: impl Fn(usize) -> bool,
) -> Res<()> {
    use gltf::mesh::Mode;
    let mut total = 0u64;
    let mut add = |count: u64, per: u64| total = total.saturating_add(count.saturating_mul(per));
    for mesh in gnodes.iter().filter_map(|n| n.mesh()) {
        for prim in mesh.primitives() {
            let n = (prim.get(&gltf::mesh::Semantic::Positions)).map_or(0, |a| a.count() as u64);
            let indices = prim.indices().map_or(n, |a| a.count() as u64);
            let triangles = match prim.mode() {
                Mode::Triangles => indices / 3,
                Mode::TriangleStrip | Mode::TriangleFan => indices.saturating_sub(2),
                _ => continue,
            };
            add(n, 2 * 12);
            add(indices, 4);
            add(triangles, 16);
        }
    }
    for animation in document.animations() {
        for channel in animation.channels() {
            let target = channel.target();
            let weights = target.property() == gltf::animation::Property::MorphTargetWeights;
            if weights || !in_scene(target.node().index()) {
                continue;
            }
            let sampler = channel.sampler();
            add(sampler.input().count() as u64, 4);
            add(sampler.output().count() as u64, 16);
        }
    }
    if total > MAX_DECODED_BYTES {
        return Err(format!(
            "the meshes (each node's instance) and animations would decode to {:.1} GiB, \
             over the {} GiB a scene may take",
            total as f64 / (1u64 << 30) as f64,
            MAX_DECODED_BYTES >> 30
        ));
    }
    Ok(())
}

/// Buffer contents, indexed like the document's buffers; the files their
/// URIs name are read inside `root` only, when given.
pub(super) fn load_buffers(
    document: &gltf::Document,
    base: &Path,
    root: Option<&Path>,
    mut blob: Option<Vec<u8>>,
) -> Res<Vec<Vec<u8>>> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let source = buffer.source();
        let data = match source {
            // Read here, not by the crate: its errors do not name the file,
            // and it reads whatever the URI names to its end (a device, a
            // FIFO).
            gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => {
                let file =
                    confined_uri_file(base, uri, root).map_err(|e| format!("buffer {i}: {e}"))?;
                read_regular_file(&file, Some(buffer.length() as u64)).map_err(|e| {
                    let e = if e == "file not found" {
                        "missing buffer file".into()
                    } else {
                        e
                    };
                    format!("{e} '{}' (buffer {i})", file.display())
                })?
            }
            _ => {
                // glTF §4.4.3.2: the binary chunk is buffer 0's alone.
                if i > 0 && matches!(source, gltf::buffer::Source::Bin) {
                    return Err(format!(
                        "buffer {i} has no URI: only the first buffer (buffer 0) may be the GLB \
                         binary chunk, and every other buffer needs a URI"
                    ));
                }
                gltf::buffer::Data::from_source_and_blob(source, Some(base), &mut blob)
                    .map_err(|e| match e {
                        gltf::Error::MissingBlob => format!(
                            "buffer {i} refers to the GLB binary chunk, which is missing (truncated GLB?)"
                        ),
                        gltf::Error::Base64(e) => {
                            format!("buffer {i}: its data: URI is not valid base64 ({e})")
                        }
                        e => format!("cannot load buffer {i}: {e}"),
                    })?
                    .0
            }
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {i} is truncated: it declares {} bytes but has {}",
                buffer.length(),
                data.len()
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// Bounds-checked accessor decoding (see the loader's module comment for
/// why the crate's readers are not used).
pub(super) struct Buffers {
    pub(super) data: Vec<Vec<u8>>,
    /// Whether the file uses `KHR_mesh_quantization`: vertex attributes
    /// may then be integers.
    pub(super) quantized: bool,
}

impl Buffers {
    fn view_bytes(&self, view: &gltf::buffer::View) -> Res<&[u8]> {
        let buffer = self
            .data
            .get(view.buffer().index())
            .ok_or_else(|| format!("buffer view {} names a missing buffer", view.index()))?;
        view.offset()
            .checked_add(view.length())
            .and_then(|end| buffer.get(view.offset()..end))
            .ok_or_else(|| {
                format!(
                    "buffer view {} is out of range of buffer {} ({} bytes)",
                    view.index(),
                    view.buffer().index(),
                    buffer.len()
                )
            })
    }

    /// Where the accessor's elements lie, once checked to fit: its buffer
    /// view's bytes and their stride (`None`: it has no buffer view, and
    /// holds zeros). Nothing is decoded.
    fn located(&self, acc: &gltf::Accessor, what: &str) -> Res<Option<(&[u8], usize)>> {
        let i = acc.index();
        let out_of_range = || format!("accessor {i} ({what}) is out of range of its buffer view");
        let count = acc.count();
        let elem = element_size(acc);
        if count == 0 {
            return Err(format!("accessor {i} ({what}) is empty"));
        }
        // glTF's `sparse.count` is 1 or more: a sparse object that
        // substitutes nothing is malformed, not a choice of its writer.
        if acc.sparse().is_some_and(|s| s.count() == 0) {
            return Err(format!(
                "accessor {i} ({what}): its sparse count is 0; glTF requires 1 or more"
            ));
        }
        count.checked_mul(elem).ok_or_else(out_of_range)?;
        let Some(view) = acc.view() else {
            return Ok(None);
        };
        let bytes = self.view_bytes(&view)?;
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(format!(
                "accessor {i} ({what}): byte stride {stride} is smaller than an element ({elem} bytes)"
            ));
        }
        let last = stride
            .checked_mul(count - 1)
            .and_then(|x| x.checked_add(acc.offset()))
            .ok_or_else(out_of_range)?;
        if last.checked_add(elem).is_none_or(|end| end > bytes.len()) {
            return Err(out_of_range());
        }
        Ok(Some((bytes, stride)))
    }

    /// Checks that the accessor's elements lie inside its buffer view, as
    /// decoding it would, without decoding it: for attributes the loader
    /// does not read.
    pub(super) fn check_layout(&self, acc: &gltf::Accessor, what: &str) -> Res<()> {
        self.located(acc, what).map(drop)
    }

    /// The accessor's elements packed tightly (`count × element size`
    /// bytes), with sparse substitutions applied.
    fn elements(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<u8>> {
        self.leading_elements(acc, what, acc.count())
    }

    /// The first `take` (at most `count`) of the accessor's elements, as
    /// [`Self::elements`] gives them all: a reader that uses one element of
    /// a large accessor decodes only that one.
    fn leading_elements(&self, acc: &gltf::Accessor, what: &str, take: usize) -> Res<Vec<u8>> {
        let i = acc.index();
        let located = self.located(acc, what)?;
        let elem = element_size(acc);
        let take = take.min(acc.count());
        let mut out = match located {
            Some((bytes, stride)) => {
                let mut out = Vec::with_capacity(take * elem);
                for k in 0..take {
                    let start = acc.offset() + k * stride;
                    out.extend_from_slice(&bytes[start..start + elem]);
                }
                out
            }
            None if take * elem <= MAX_VIEWLESS_BYTES => vec![0; take * elem],
            None => return Err(format!("accessor {i} ({what}) is too large")),
        };
        if let Some(sparse) = acc.sparse() {
            self.apply_sparse(&sparse, &mut out, acc.count(), elem)
                .map_err(|e| format!("accessor {i} ({what}): sparse {e}"))?;
        }
        Ok(out)
    }

    fn apply_sparse(
        &self,
        sparse: &gltf::accessor::sparse::Sparse,
        out: &mut [u8],
        count: usize,
        elem: usize,
    ) -> Res<()> {
        let n = sparse.count();
        let (indices, values) = (sparse.indices(), sparse.values());
        let index_size = indices.index_type().size();
        let slice = |bytes: &'_ [u8], offset: usize, len: Option<usize>| -> Res<Vec<u8>> {
            len.and_then(|len| bytes.get(offset..offset.checked_add(len)?))
                .map(<[u8]>::to_vec)
                .ok_or_else(|| "data is out of range of its buffer view".to_string())
        };
        let index_bytes = slice(
            self.view_bytes(&indices.view())?,
            indices.offset(),
            n.checked_mul(index_size),
        )?;
        let value_bytes = slice(
            self.view_bytes(&values.view())?,
            values.offset(),
            n.checked_mul(elem),
        )?;
        for (k, raw) in index_bytes.chunks_exact(index_size).enumerate() {
            let target = read_uint(raw) as usize;
            if target >= count {
                return Err(format!("index {target} is out of range ({count} elements)"));
            }
            // `out` may hold only the leading elements.
            if let Some(element) = out.get_mut(target * elem..(target + 1) * elem) {
                element.copy_from_slice(&value_bytes[k * elem..(k + 1) * elem]);
            }
        }
        Ok(())
    }

    /// Float values of an accessor of the given type, flattened; integer
    /// components are converted (normalised ones to \[0, 1\] or \[−1, 1\]).
    pub(super) fn floats(
        &self,
        acc: &gltf::Accessor,
        dims: Dimensions,
        what: &str,
    ) -> Res<Vec<f32>> {
        self.leading_floats(acc, dims, what, acc.count())
    }

    /// [`Self::floats`] of the accessor's first element only.
    pub(super) fn first_floats(
        &self,
        acc: &gltf::Accessor,
        dims: Dimensions,
        what: &str,
    ) -> Res<Vec<f32>> {
        self.leading_floats(acc, dims, what, 1)
    }

    fn leading_floats(
        &self,
        acc: &gltf::Accessor,
        dims: Dimensions,
        what: &str,
        take: usize,
    ) -> Res<Vec<f32>> {
        if acc.dimensions() != dims {
            return Err(format!(
                "accessor {} ({what}) has type {:?}, expected {dims:?}",
                acc.index(),
                acc.dimensions()
            ));
        }
        let ty = acc.data_type();
        let bytes = self.leading_elements(acc, what, take)?;
        Ok(bytes
            .chunks_exact(ty.size())
            .map(|c| component(c, ty, acc.normalized()))
            .collect())
    }

    /// glTF 2.0 keeps vertex positions and normals in floats (§3.7.2.1);
    /// `KHR_mesh_quantization` also allows 8- and 16-bit integers.
    pub(super) fn check_vertex_type(&self, acc: &gltf::Accessor, what: &str) -> Res<()> {
        let ty = acc.data_type();
        let allowed = match ty {
            DataType::F32 => true,
            DataType::U32 => false,
            _ => self.quantized,
        };
        if allowed {
            return Ok(());
        }
        let why = if self.quantized {
            "integers of 8 or 16 bits at most"
        } else {
            "FLOAT unless the file uses KHR_mesh_quantization"
        };
        Err(format!(
            "accessor {} ({what}) holds {ty:?} components; glTF allows {why}",
            acc.index()
        ))
    }

    pub(super) fn vec3s(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<Vec3>> {
        let flat = self.floats(acc, Dimensions::Vec3, what)?;
        Ok(flat.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    pub(super) fn indices(&self, acc: &gltf::Accessor, what: &str) -> Res<Vec<u32>> {
        let ty = acc.data_type();
        if acc.dimensions() != Dimensions::Scalar
            || !matches!(ty, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(format!(
                "accessor {} ({what}) must be unsigned integer scalars for indices",
                acc.index()
            ));
        }
        // glTF lets only vertex attributes' buffer views have a stride
        // (other data "MUST NOT define byteStride"): other tools read
        // such indices packed, or refuse them.
        if let Some((view, stride)) = acc.view().and_then(|v| Some((v.index(), v.stride()?))) {
            return Err(format!(
                "accessor {} ({what}): its buffer view {view} has a byteStride ({stride}), which \
                 glTF forbids for indices",
                acc.index()
            ));
        }
        let bytes = self.elements(acc, what)?;
        Ok(bytes.chunks_exact(ty.size()).map(read_uint).collect())
    }
}

/// Bytes of one element of `acc`.
fn element_size(acc: &gltf::Accessor) -> usize {
    acc.data_type().size() * acc.dimensions().multiplicity()
}

/// Little-endian unsigned integer of 1, 2 or 4 bytes.
fn read_uint(raw: &[u8]) -> u32 {
    raw.iter().rev().fold(0u32, |acc, &b| (acc << 8) | b as u32)
}

/// One component as f32 (glTF §3.11 normalisation for integer types).
fn component(raw: &[u8], ty: DataType, normalized: bool) -> f32 {
    let (value, scale) = match ty {
        DataType::F32 => return f32::from_le_bytes([raw[0], raw[1], raw[2], raw[3]]),
        DataType::I8 => (raw[0] as i8 as f32, 127.0),
        DataType::U8 => (raw[0] as f32, 255.0),
        DataType::I16 => (i16::from_le_bytes([raw[0], raw[1]]) as f32, 32767.0),
        DataType::U16 => (u16::from_le_bytes([raw[0], raw[1]]) as f32, 65535.0),
        DataType::U32 => (read_uint(raw) as f32, 1.0),
    };
    if normalized {
        (value / scale).max(-1.0)
    } else {
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalised_components() {
        assert_eq!(component(&[255], DataType::U8, true), 1.0);
        assert_eq!(component(&[0x80], DataType::I8, true), -1.0);
        assert_eq!(component(&[0xff, 0x7f], DataType::I16, true), 1.0);
        assert_eq!(component(&[7, 0], DataType::U16, false), 7.0);
        assert_eq!(read_uint(&[1, 2, 0, 0]), 0x0201);
    }
}
