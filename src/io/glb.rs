//! glTF 2.0 binary (`.glb`) meshes with vertex colours, for game engines and
//! DCC tools that import glTF (Blender, Godot, Unity, three.js).
//!
//! One file holds the JSON scene (one node, one mesh, one triangle primitive)
//! and one binary buffer with tightly packed views, each 4-byte aligned
//! because every component is 4 bytes:
//! 1. POSITION: float VEC3 with its min/max (glTF requires the bounds);
//! 2. NORMAL: float VEC3, unit length (area-weighted vertex normals);
//! 3. COLOR_0 (only for a coloured mesh): float VEC3, linear (see
//!    [`crate::geom::colour::srgb_to_linear`]);
//! 4. TEXCOORD_0 (only for a textured mesh): float VEC2, v = 0 the image's
//!    top row (glTF's convention), vertices split where corners' UVs differ;
//! 5. indices: unsigned int SCALAR, 3 per triangle;
//! 6. a textured mesh's image, PNG, as the material's `baseColorTexture`
//!    (then no COLOR_0: glTF would multiply the two).
//!
//! Positions are written as they are: the exemplar's own frame and units.
//! glTF says +Y is up and units are metres; an exemplar modelled Y-up (the
//! OBJ convention) therefore opens upright.

use std::borrow::Cow;

use glam::Vec3;
use gltf::json::{self, validation::Checked::Valid, validation::USize64};

use crate::error::{Error, Result};
use crate::geom::colour::srgb_to_linear;
use crate::io::mesh_data::Mesh;


/// Appends a tightly packed buffer view of `values` (little-endian 4-byte
/// words) to `bin`, and an accessor of `count` elements of `type_` over it.
fn push_view(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    words: impl Iterator<Item = [u8; 4]>,
    count: usize,
    accessor: (json::accessor::ComponentType, json::accessor::Type, json::buffer::Target),
    bounds: Option<(Vec3, Vec3)>,
) -> json::Index<json::Accessor> {
    let (component, type_, target) = accessor;
    let offset = bin.len();
    words.for_each(|w| bin.extend_from_slice(&w));
    let view = root.push(json::buffer::View {
        buffer: json::Index::new(0),
        byte_length: USize64((bin.len() - offset) as u64),
        byte_offset: Some(USize64(offset as u64)),
        byte_stride: None,
        name: None,
        target: Some(Valid(target)),
        extensions: None,
        extras: Default::default(),
    });
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64(count as u64),
        component_type: Valid(json::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(type_),
        min: bounds.map(|(lo, _)| json::Value::from(lo.to_array().to_vec())),
        max: bounds.map(|(_, hi)| json::Value::from(hi.to_array().to_vec())),
        name: None,
        normalized: false,
        sparse: None,
    })
}

/// A textured mesh's vertices split so that each (vertex, UV) pair is one
/// glTF vertex (glTF has one TEXCOORD_0 per vertex, our UVs are per corner),
/// with glTF's UV convention (v = 0 the image's top row).
fn split_at_uv_seams(mesh: &Mesh, uvs: &[glam::Vec2]) -> (Mesh, Vec<glam::Vec2>) {
    let mut index: std::collections::HashMap<(u32, u32, u32), u32> = std::collections::HashMap::new();
    let (mut positions, mut out_uvs, mut from) = (Vec::new(), Vec::new(), Vec::new());
    let triangles = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            std::array::from_fn(|k| {
                let uv = uvs[3 * t + k];
                *index.entry((tri[k], uv.x.to_bits(), uv.y.to_bits())).or_insert_with(|| {
                    positions.push(mesh.positions[tri[k] as usize]);
                    out_uvs.push(glam::Vec2::new(uv.x, 1.0 - uv.y));
                    from.push(tri[k] as usize);
                    (positions.len() - 1) as u32
                })
            })
        })
        .collect();
    let colours = match mesh.vertex_colours() {
        Some(c) => crate::io::mesh_data::MeshColours::PerVertex(from.iter().map(|&i| c[i]).collect()),
        None => crate::io::mesh_data::MeshColours::None,
    };
    (Mesh { name: mesh.name.clone(), positions, triangles, colours, texture: None }, out_uvs)
}

/// The mesh as the bytes of a `.glb` file. Errors: no triangles, or a mesh
/// too large for glTF's 32-bit lengths.
pub fn to_bytes(mesh: &Mesh) -> Result<Vec<u8>> {
    use json::accessor::{ComponentType, Type};
    use json::buffer::Target;
    if mesh.triangles.is_empty() {
        return Err(Error::Invalid("a mesh without triangles cannot be written as glTF".into()));
    }
    // A texture (one image: what baking makes) becomes baseColorTexture, with
    // COLOR_0 only where it tints the image (glTF multiplies the two).
    let split;
    let (mesh, texture, uvs) = match &mesh.texture {
        Some(t) if t.more.is_empty() && t.image.width() > 0 => {
            let (m, uvs) = split_at_uv_seams(mesh, &t.uvs);
            split = m;
            (&split, Some(t), uvs)
        }
        _ => (mesh, None, Vec::new()),
    };
    let colours = mesh.vertex_colours().filter(|_| texture.is_none_or(|t| t.tinted));
    // Bytes per vertex (position, normal, colour) and per triangle.
    let image_bytes = texture.map_or(0, |t| 3 * t.image.width() as usize * t.image.height() as usize);
    let size = mesh.positions.len() * if colours.is_some() { 36 } else { 24 } + uvs.len() * 8 + mesh.triangles.len() * 12 + image_bytes;
    if size > u32::MAX as usize - 4096 {
        return Err(Error::Invalid(format!("{} MB of mesh data exceed a .glb file's 4 GiB", size >> 20)));
    }
    let vec3_words = |v: &[Vec3]| v.iter().flat_map(|p| p.to_array()).map(f32::to_le_bytes).collect::<Vec<_>>();
    let mut root = json::Root {
        asset: json::Asset { generator: Some(crate::io::vdb::CREATOR.into()), ..Default::default() },
        ..Default::default()
    };
    let mut bin = Vec::with_capacity(size);
    let n = mesh.positions.len();
    let vertex = (ComponentType::F32, Type::Vec3, Target::ArrayBuffer);
    let position =
        push_view(&mut root, &mut bin, vec3_words(&mesh.positions).into_iter(), n, vertex, Some(mesh.bounds()));
    let normal = push_view(&mut root, &mut bin, vec3_words(&mesh.vertex_normals()).into_iter(), n, vertex, None);
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), position);
    attributes.insert(Valid(json::mesh::Semantic::Normals), normal);
    if let Some(c) = colours {
        let linear: Vec<Vec3> = c.iter().map(|c| Vec3::from_array(c.to_array().map(srgb_to_linear))).collect();
        let colour = push_view(&mut root, &mut bin, vec3_words(&linear).into_iter(), n, vertex, None);
        attributes.insert(Valid(json::mesh::Semantic::Colors(0)), colour);
    }
    if !uvs.is_empty() {
        let words = uvs.iter().flat_map(|p| p.to_array()).map(f32::to_le_bytes).collect::<Vec<_>>();
        let uv = push_view(&mut root, &mut bin, words.into_iter(), n, (ComponentType::F32, Type::Vec2, Target::ArrayBuffer), None);
        attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), uv);
    }
    let indices = push_view(
        &mut root,
        &mut bin,
        mesh.triangles.iter().flatten().map(|i| i.to_le_bytes()),
        3 * mesh.triangles.len(),
        (ComponentType::U32, Type::Scalar, Target::ElementArrayBuffer),
        None,
    );
    // The image: a PNG in the binary buffer (views of images take no target).
    let base_colour_texture = match texture {
        Some(t) => {
            let mut png = std::io::Cursor::new(Vec::new());
            t.image.write_to(&mut png, image::ImageFormat::Png).map_err(|e| Error::Invalid(format!("texture PNG: {e}")))?;
            let png = png.into_inner();
            let offset = bin.len();
            bin.extend_from_slice(&png);
            while bin.len() % 4 != 0 {
                bin.push(0);
            }
            let view = root.push(json::buffer::View {
                buffer: json::Index::new(0),
                byte_length: USize64(png.len() as u64),
                byte_offset: Some(USize64(offset as u64)),
                byte_stride: None,
                name: None,
                target: None,
                extensions: None,
                extras: Default::default(),
            });
            let image = root.push(json::Image {
                buffer_view: Some(view),
                mime_type: Some(json::image::MimeType("image/png".into())),
                name: Some("base colour".into()),
                uri: None,
                extensions: None,
                extras: Default::default(),
            });
            let sampler = root.push(json::texture::Sampler {
                mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
                min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
                wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
                wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
                name: None,
                extensions: None,
                extras: Default::default(),
            });
            let tex = root.push(json::Texture {
                sampler: Some(sampler),
                source: image,
                name: None,
                extensions: None,
                extras: Default::default(),
            });
            Some(json::texture::Info { index: tex, tex_coord: 0, extensions: None, extras: Default::default() })
        }
        None => None,
    };
    root.push(json::Buffer {
        byte_length: USize64(bin.len() as u64),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    // Matte and not metallic, as the previews render it: glTF's default
    // material is fully metallic, which shows vertex colours nearly black.
    let material = root.push(json::Material {
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(1.0),
            base_color_texture: base_colour_texture.clone(),
            ..Default::default()
        },
        name: Some(if base_colour_texture.is_some() { "baked texture" } else { "vertex colours" }.into()),
        ..Default::default()
    });
    let name = if mesh.name.is_empty() { "mesh".to_string() } else { mesh.name.clone() };
    let gltf_mesh = root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some(name.clone()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: None,
        }],
        weights: None,
    });
    let node = root.push(json::Node { mesh: Some(gltf_mesh), name: Some(name), ..Default::default() });
    let scene = root.push(json::Scene { extensions: None, extras: Default::default(), name: None, nodes: vec![node] });
    root.scene = Some(scene);

    let json = root.to_vec().map_err(|e| Error::Invalid(format!("glTF JSON: {e}")))?;
    let glb = gltf::binary::Glb {
        // to_vec computes the total length itself.
        header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(bin)),
    };
    glb.to_vec().map_err(|e| Error::Invalid(format!("glTF binary: {e}")))
}
