//! glTF 2.0 exemplars (`.glb`, and `.gltf` with external or embedded buffers
//! and images), through the `gltf` crate's document and accessor readers.
//!
//! Read: every triangle primitive of the default scene (else the first) with
//! its nodes' transforms; triangle lists, strips and fans; the base colour as
//! the specification defines it, `baseColorFactor x COLOR_0 x
//! baseColorTexture` in linear light, the texture through its texture
//! coordinate set and sampler wrap modes. Refused with a clear error:
//! compressed or quantised geometry (Draco, meshopt, KHR_mesh_quantization).
//! Points and lines are left out with a warning.
//!
//! Bounds before trust: every buffer must hold the bytes it declares, every
//! accessor must fit in its view with a stride of at least its element, the
//! node graph is walked with a depth limit and a cap on instances, and images
//! decode under size limits.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use base64::Engine;
use glam::{Mat4, Vec2, Vec3};

use crate::io::mesh_data::{Mesh, MeshColours, Texture, Wrap, NO_IMAGE};

/// Extensions whose data the reader cannot decode.
const UNSUPPORTED: &[(&str, &str)] = &[
    ("KHR_draco_mesh_compression", "Draco-compressed geometry"),
    ("EXT_meshopt_compression", "meshopt-compressed buffers"),
    ("KHR_mesh_quantization", "quantised vertex attributes"),
];

/// Deepest node hierarchy walked, and most primitive instances (a node graph
/// reused many times over multiplies its triangles).
const MAX_DEPTH: usize = 64;
const MAX_INSTANCES: usize = 100_000;
/// Most triangles read (a GLB of a billion triangles is not an exemplar).
const MAX_TRIANGLES: usize = 50_000_000;
/// Largest texture side and decoding allocation.
const MAX_IMAGE_SIDE: u32 = 16384;
const MAX_IMAGE_BYTES: u64 = 1 << 30;

/// [`read`], with a panic of the readers below (none known) as an error.
pub fn read_bytes(bytes: &[u8], dir: &Path, name: &str) -> Result<Mesh, String> {
    std::panic::catch_unwind(|| read(bytes, dir, name)).map_err(|_| "the glTF reader failed on this file (damaged)".to_string())?
}

pub fn read(bytes: &[u8], dir: &Path, name: &str) -> Result<Mesh, String> {
    let invalid = |e: ::gltf::Error| format!("not a valid glTF 2.0 file: {e}");
    // Extensions first: compressed primitives have no buffer views to validate.
    let unchecked = ::gltf::Gltf::from_slice_without_validation(bytes).map_err(invalid)?;
    for ext in unchecked.document.extensions_required() {
        if let Some((_, what)) = UNSUPPORTED.iter().find(|(n, _)| *n == ext) {
            return Err(format!("uses {what} ({ext}), which shapeshifter cannot read: export it uncompressed"));
        }
    }
    drop(unchecked);
    let gltf = ::gltf::Gltf::from_slice(bytes).map_err(invalid)?;
    let doc = &gltf.document;
    if doc.extensions_used().any(|e| e == "KHR_texture_transform") {
        log::warn!("{name}: KHR_texture_transform is not applied: textures may be placed wrongly");
    }
    let buffers = load_buffers(doc, gltf.blob.as_deref(), dir)?;
    check_accessors(doc, &buffers)?;

    let scene = doc.default_scene().or_else(|| doc.scenes().next()).ok_or("has no scene")?;
    let mut instances = Vec::new();
    for node in scene.nodes() {
        walk(&node, Mat4::IDENTITY, 0, &mut instances)?;
    }

    let mut images: HashMap<usize, Option<(image::RgbImage, [Wrap; 2])>> = HashMap::new();
    let mut out = Builder::default();
    let mut skipped = 0usize;
    for (mesh, matrix) in &instances {
        for prim in mesh.primitives() {
            let mode = prim.mode();
            use ::gltf::mesh::Mode;
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                skipped += 1;
                continue;
            }
            check_types(&prim)?;
            let reader = prim.reader(|b| buffers.get(b.index()).map(|v| v.as_slice()));
            let positions: Vec<Vec3> = reader.read_positions().ok_or("a primitive has no POSITION")?.map(Vec3::from).collect();
            let n = positions.len();
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= n) {
                return Err(format!("a primitive's index {bad} is past its {n} vertices"));
            }
            let triangles = assemble(&indices, mode);
            let material = prim.material();
            let pbr = material.pbr_metallic_roughness();
            let factor = Vec3::from_slice(&pbr.base_color_factor()[..3]);
            let vertex_colour: Option<Vec<Vec3>> = reader.read_colors(0).map(|c| c.into_rgb_f32().map(Vec3::from).collect());
            if vertex_colour.as_ref().is_some_and(|c| c.len() != n) {
                return Err("a primitive's COLOR_0 and POSITION counts differ".into());
            }
            let texture = pbr.base_color_texture();
            let mut uvs: Option<Vec<Vec2>> = None;
            let mut image_slot = NO_IMAGE;
            if let Some(info) = &texture {
                match reader.read_tex_coords(info.tex_coord()) {
                    Some(t) => {
                        // glTF's v runs down the image; ours (OBJ's) up.
                        let t: Vec<Vec2> = t.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect();
                        if t.len() != n {
                            return Err(format!("a primitive's TEXCOORD_{} and POSITION counts differ", info.tex_coord()));
                        }
                        let tex = info.texture();
                        let index = tex.source().index();
                        let slot = images.entry(index).or_insert_with(|| {
                            let sampler = tex.sampler();
                            let wrap = [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())];
                            match load_image(&tex.source(), &buffers, dir) {
                                Ok(img) => Some((img, wrap)),
                                Err(e) => {
                                    log::warn!("{name}: texture image {index} cannot be read ({e}); using the base colour");
                                    None
                                }
                            }
                        });
                        if let Some(image) = slot {
                            image_slot = out.image_slot(index, image);
                            uvs = Some(t);
                        }
                    }
                    None => log::warn!("{name}: a material's texture uses TEXCOORD_{}, which its primitive lacks", info.tex_coord()),
                }
            }
            let m = *matrix;
            let flip = m.determinant() < 0.0;
            let base = out.positions.len() as u32;
            for p in &positions {
                out.positions.push(m.transform_point3(*p));
            }
            for t in triangles {
                let t = if flip { [t[0], t[2], t[1]] } else { t };
                out.triangles.push(t.map(|i| base + i));
                for &i in &t {
                    let c = vertex_colour.as_ref().map_or(Vec3::ONE, |c| c[i as usize]) * factor;
                    out.colours.push(Vec3::new(
                        crate::geom::colour::linear_to_srgb(c.x),
                        crate::geom::colour::linear_to_srgb(c.y),
                        crate::geom::colour::linear_to_srgb(c.z),
                    ));
                    out.uvs.push(uvs.as_ref().map_or(Vec2::ZERO, |u| u[i as usize]));
                }
                out.triangle_image.push(image_slot);
                if out.triangles.len() > MAX_TRIANGLES {
                    return Err(format!("has more than {MAX_TRIANGLES} triangles"));
                }
            }
            out.coloured |= vertex_colour.is_some() || factor != Vec3::ONE || texture.is_some();
        }
    }
    if skipped > 0 {
        log::warn!("{name}: left out {skipped} primitives of points or lines");
    }
    if out.triangles.is_empty() {
        return Err("has no triangles in its scene".into());
    }
    Ok(weld(out.finish(name)))
}

#[derive(Default)]
struct Builder {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// Per corner: factor x COLOR_0, sRGB.
    colours: Vec<Vec3>,
    uvs: Vec<Vec2>,
    triangle_image: Vec<u32>,
    /// glTF image index -> slot (0-based) in `images`.
    slots: HashMap<usize, u32>,
    images: Vec<(image::RgbImage, [Wrap; 2])>,
    coloured: bool,
}

impl Builder {
    /// The slot of glTF image `index`, copied in on first use only.
    fn image_slot(&mut self, index: usize, image: &(image::RgbImage, [Wrap; 2])) -> u32 {
        if let Some(&s) = self.slots.get(&index) {
            return s;
        }
        let s = self.images.len() as u32;
        self.images.push(image.clone());
        self.slots.insert(index, s);
        s
    }

    fn finish(self, name: &str) -> Mesh {
        let colours = if self.coloured { MeshColours::PerCorner(self.colours) } else { MeshColours::None };
        let texture = (!self.images.is_empty()).then(|| {
            let mut images = self.images.into_iter();
            let (image, wrap) = images.next().unwrap();
            Texture { uvs: self.uvs, image, wrap, more: images.collect(), triangle_image: self.triangle_image, tinted: true }
        });
        Mesh { name: name.to_string(), positions: self.positions, triangles: self.triangles, colours, texture }
    }
}

fn wrap(w: ::gltf::texture::WrappingMode) -> Wrap {
    match w {
        ::gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
        ::gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        ::gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
    }
}

/// The attributes read have the types the readers decode (a POSITION of
/// bytes would be read as floats past its data).
fn check_types(prim: &::gltf::Primitive) -> Result<(), String> {
    use ::gltf::accessor::{DataType as D, Dimensions as N};
    use ::gltf::Semantic as S;
    for (semantic, a) in prim.attributes() {
        let (d, t) = (a.dimensions(), a.data_type());
        let ok = match &semantic {
            S::Positions => d == N::Vec3 && t == D::F32,
            S::TexCoords(_) => d == N::Vec2 && matches!(t, D::F32 | D::U8 | D::U16),
            S::Colors(_) => matches!(d, N::Vec3 | N::Vec4) && matches!(t, D::F32 | D::U8 | D::U16),
            _ => true,
        };
        if !ok {
            return Err(format!("attribute {semantic:?} has type {d:?} of {t:?}, which the specification does not allow"));
        }
    }
    if let Some(i) = prim.indices() {
        if i.dimensions() != N::Scalar || !matches!(i.data_type(), D::U8 | D::U16 | D::U32) {
            return Err(format!("indices have type {:?} of {:?}, not unsigned integers", i.dimensions(), i.data_type()));
        }
    }
    Ok(())
}

/// Triangles of a list, strip or fan (degenerate ones left for the mesh checks).
fn assemble(indices: &[u32], mode: ::gltf::mesh::Mode) -> Vec<[u32; 3]> {
    use ::gltf::mesh::Mode;
    match mode {
        Mode::TriangleStrip => (2..indices.len())
            .map(|i| if i % 2 == 0 { [indices[i - 2], indices[i - 1], indices[i]] } else { [indices[i - 1], indices[i - 2], indices[i]] })
            .collect(),
        Mode::TriangleFan => (2..indices.len()).map(|i| [indices[0], indices[i - 1], indices[i]]).collect(),
        _ => indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
    }
}

/// Every node below `node` with a mesh, with its world matrix.
fn walk<'a>(node: &::gltf::Node<'a>, parent: Mat4, depth: usize, out: &mut Vec<(::gltf::Mesh<'a>, Mat4)>) -> Result<(), String> {
    if depth > MAX_DEPTH {
        return Err(format!("its node hierarchy is deeper than {MAX_DEPTH} (or has a cycle)"));
    }
    let local = Mat4::from_cols_array_2d(&node.transform().matrix());
    let m = parent * local;
    if !m.is_finite() {
        return Err(format!("node {} has a NaN or infinite transform", node.index()));
    }
    if let Some(mesh) = node.mesh() {
        out.push((mesh, m));
        if out.len() > MAX_INSTANCES {
            return Err(format!("its scene instances more than {MAX_INSTANCES} meshes"));
        }
    }
    for child in node.children() {
        walk(&child, m, depth + 1, out)?;
    }
    Ok(())
}

/// The bytes of a `data:` URI, or None for another URI.
fn data_uri(uri: &str) -> Option<Result<Vec<u8>, String>> {
    let rest = uri.strip_prefix("data:")?;
    let (head, payload) = rest.split_once(',')?;
    Some(if head.ends_with(";base64") {
        base64::engine::general_purpose::STANDARD.decode(payload.trim()).map_err(|e| format!("a data URI is not valid base64: {e}"))
    } else {
        Err("a data URI is not base64".into())
    })
}

/// A relative URI of a file beside the glTF (percent-escapes decoded).
fn external(uri: &str, dir: &Path) -> Result<PathBuf, String> {
    if uri.contains("://") {
        return Err(format!("refers to '{}', which is not a file beside it", crate::error::one_line(uri)));
    }
    let mut bytes = Vec::new();
    let raw = uri.as_bytes();
    let mut i = 0;
    while i < raw.len() {
        if raw[i] == b'%' && i + 2 < raw.len() {
            if let Some(b) = std::str::from_utf8(&raw[i + 1..i + 3]).ok().and_then(|h| u8::from_str_radix(h, 16).ok()) {
                bytes.push(b);
                i += 3;
                continue;
            }
        }
        bytes.push(raw[i]);
        i += 1;
    }
    Ok(dir.join(String::from_utf8_lossy(&bytes).as_ref()))
}

fn read_external(uri: &str, dir: &Path, limit: u64) -> Result<Vec<u8>, String> {
    let path = external(uri, dir)?;
    let len = std::fs::metadata(&path).map_err(|e| format!("{}: {e}", path.display()))?.len();
    if len > limit {
        return Err(format!("{} is {len} bytes, more than the {limit} expected", path.display()));
    }
    std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))
}

fn load_buffers(doc: &::gltf::Document, blob: Option<&[u8]>, dir: &Path) -> Result<Vec<Vec<u8>>, String> {
    doc.buffers()
        .map(|b| {
            let declared = b.length();
            let data = match b.source() {
                ::gltf::buffer::Source::Bin => blob.ok_or("a buffer refers to a GLB binary chunk the file lacks")?.to_vec(),
                ::gltf::buffer::Source::Uri(uri) => match data_uri(uri) {
                    Some(d) => d?,
                    None => read_external(uri, dir, declared as u64 + 4)?,
                },
            };
            if data.len() < declared {
                return Err(format!("buffer {} declares {declared} bytes but holds {} (truncated)", b.index(), data.len()));
            }
            Ok(data)
        })
        .collect()
}

/// Every accessor within its view and every view within its buffer, with a
/// stride no shorter than the element: the readers then never index past
/// the data.
fn check_accessors(doc: &::gltf::Document, buffers: &[Vec<u8>]) -> Result<(), String> {
    for v in doc.views() {
        let end = v.offset().checked_add(v.length()).ok_or("a buffer view's end overflows")?;
        if end > buffers[v.buffer().index()].len() {
            return Err(format!("buffer view {} ends at byte {end}, past its buffer", v.index()));
        }
    }
    for a in doc.accessors() {
        let size = a.size();
        let Some(view) = a.view() else {
            if a.sparse().is_none() {
                // All zeros by the specification: nothing to read.
            }
            continue;
        };
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            return Err(format!("accessor {}'s stride {stride} is shorter than its element of {size} bytes", a.index()));
        }
        if a.count() == 0 {
            return Err(format!("accessor {} has no elements", a.index()));
        }
        let end = (a.count() - 1).checked_mul(stride).and_then(|x| x.checked_add(a.offset())).and_then(|x| x.checked_add(size));
        if end.map_or(true, |e| e > view.length()) {
            return Err(format!("accessor {} reaches past its buffer view", a.index()));
        }
        if let Some(s) = a.sparse() {
            for (v, off, each) in [(s.indices().view(), s.indices().offset(), 4usize), (s.values().view(), s.values().offset(), size)] {
                let end = s.count().checked_mul(each).and_then(|x| x.checked_add(off));
                if end.map_or(true, |e| e > v.length()) {
                    return Err(format!("accessor {}'s sparse data reaches past its buffer view", a.index()));
                }
            }
        }
    }
    Ok(())
}

fn load_image(img: &::gltf::Image, buffers: &[Vec<u8>], dir: &Path) -> Result<image::RgbImage, String> {
    // The format from the bytes, else from the MIME type or the file name
    // (a TGA has no signature to guess it by).
    let (bytes, named) = match img.source() {
        ::gltf::image::Source::View { view, mime_type } => {
            let b = &buffers[view.buffer().index()];
            (b[view.offset()..view.offset() + view.length()].to_vec(), image::ImageFormat::from_mime_type(mime_type))
        }
        ::gltf::image::Source::Uri { uri, mime_type } => {
            let named = mime_type.and_then(image::ImageFormat::from_mime_type).or_else(|| image::ImageFormat::from_path(uri).ok());
            match data_uri(uri) {
                Some(d) => (d?, named),
                None => (read_external(uri, dir, MAX_IMAGE_BYTES)?, named),
            }
        }
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes)).with_guessed_format().map_err(|e| e.to_string())?;
    if reader.format().is_none() {
        if let Some(f) = named {
            reader.set_format(f);
        }
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_IMAGE_BYTES);
    reader.limits(limits);
    Ok(reader.decode().map_err(|e| e.to_string())?.to_rgb8())
}

/// Vertices at exactly the same position made one: glTF writers split
/// vertices wherever a normal or UV changes (Blender's exporter and Assimp's
/// give flat-shaded faces their own corners), which would make those edges
/// boundaries (an open surface, meshed as one). Colours and UVs are per
/// corner here, so nothing else changes.
fn weld(mut mesh: Mesh) -> Mesh {
    let mut index: std::collections::HashMap<[u32; 3], u32> = std::collections::HashMap::new();
    let mut positions = Vec::new();
    let remap: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            let key = p.to_array().map(|v| if v == 0.0 { 0 } else { v.to_bits() });
            *index.entry(key).or_insert_with(|| {
                positions.push(*p);
                positions.len() as u32 - 1
            })
        })
        .collect();
    if let crate::io::mesh_data::MeshColours::PerVertex(c) = &mesh.colours {
        // Per-vertex colours (not what the glTF reader gives) as corners.
        let corners = mesh.triangles.iter().flat_map(|t| t.map(|i| c[i as usize])).collect();
        mesh.colours = crate::io::mesh_data::MeshColours::PerCorner(corners);
    }
    for t in &mut mesh.triangles {
        *t = t.map(|i| remap[i as usize]);
    }
    mesh.positions = positions;
    mesh
}
