//! USD layers: one per variant (its mesh, its finest level's points, its
//! level files as volumes) and one asset layer with a variant set over them,
//! for pipelines that hand assets around as USD (Houdini's Solaris, usdview,
//! Omniverse, Maya, Blender). Each is described once ([`layer::Layer`]) and
//! written as text (`.usda`, [`usda`]) or binary (`.usdc`, [`usdc`]: a
//! fraction of the text's size, read without parsing).
//!
//! Every asset path is relative to the layer that names it (`./...`), so a
//! run folder can be moved or copied whole. Positions are the exemplar's own
//! frame and units, as in every other file we write.
//!
//! Prims of a variant layer (default prim `/variant`):
//! - `mesh` (`UsdGeomMesh`): points, face counts and indices, vertex normals,
//!   `primvars:displayColor` per vertex, and with a baked texture
//!   `primvars:st` and a `UsdPreviewSurface` material in `Looks`;
//! - `points` (`UsdGeomPoints`): the finest level's surface points, normals,
//!   one width (a voxel), `primvars:displayColor`;
//! - `volume` (`UsdVolVolume`) with a variant set `level` (one variant per
//!   level file, the finest selected) whose `OpenVDBAsset` fields point at
//!   that level's grids.

pub mod layer;
pub mod usda;
pub mod usdc;

use std::borrow::Cow;

use glam::{Vec2, Vec3};

use crate::grid::transform::Up;
use layer::{Attribute, Body, Layer, Metadata, Prim, Property, Value, VariantSet};

/// The encoding of the layers a run writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum UsdFormat {
    /// Text: readable, diffable.
    #[default]
    Usda,
    /// Binary ("crate"): smaller, opened faster.
    Usdc,
}

impl UsdFormat {
    /// The file extension (`usda`, `usdc`).
    pub fn extension(self) -> &'static str {
        match self {
            UsdFormat::Usda => "usda",
            UsdFormat::Usdc => "usdc",
        }
    }
    /// The layer's bytes in this encoding.
    pub fn encode(self, layer: &Layer) -> Vec<u8> {
        match self {
            UsdFormat::Usda => usda::encode(layer).into_bytes(),
            UsdFormat::Usdc => usdc::encode(layer),
        }
    }
}

/// Stage metadata every layer states.
#[derive(Clone, Debug)]
pub struct StageMetadata {
    pub up: Up,
    /// Metres per unit of the exemplar's coordinates.
    pub meters_per_unit: f64,
    /// One line for the layer's `doc` (who wrote it, from what).
    pub doc: String,
}

/// A triangle mesh for a `UsdGeomMesh`.
pub struct MeshPrim<'a> {
    pub positions: &'a [Vec3],
    pub triangles: &'a [[u32; 3]],
    /// Unit vertex normals, one per position.
    pub normals: &'a [Vec3],
    /// sRGB in [0,1], one per position (USD's displayColor is a display value).
    pub colours: Option<&'a [Vec3]>,
    /// A baked base-colour texture: one UV per triangle corner, in
    /// `triangles` order (v = 0 the image's bottom row, USD's convention as
    /// OBJ's), and the image's path relative to the layer.
    pub texture: Option<(&'a [Vec2], String)>,
}

/// Coloured oriented points for a `UsdGeomPoints`.
pub struct PointsPrim<'a> {
    pub positions: &'a [Vec3],
    pub normals: &'a [Vec3],
    pub colours: &'a [Vec3],
    /// Point diameter, world units (a voxel edge).
    pub width: f32,
}

/// One level file, a variant of the volume's `level` set.
#[derive(Clone, Debug)]
pub struct LevelVolume {
    pub index: usize,
    /// `level_K.vdb`, relative to the layer.
    pub file: String,
    /// World-unit bounds of its voxels.
    pub bounds: (Vec3, Vec3),
}

/// The OpenVDB grids of a level file a volume names as fields, with their
/// VDB grid class: the fog volume renderers draw first, then the attributes.
const LEVEL_FIELDS: &[(&str, &str)] =
    &[("density", "fogVolume"), ("Cd", "unknown"), ("N", "unknown"), ("P", "unknown"), ("mask", "unknown")];

/// The baked material's prim path in a variant layer.
const MATERIAL: &str = "/variant/Looks/baked";

/// A variant's layer: `mesh`, `points` and `volume` under the default prim
/// `variant` (each optional: a variant without a mesh still has its levels).
pub struct VariantLayer<'a> {
    pub mesh: Option<MeshPrim<'a>>,
    pub points: Option<PointsPrim<'a>>,
    pub levels: Vec<LevelVolume>,
}

/// `name` as a USD identifier: letters, digits and `_`, not starting with a
/// digit (the prim name of an asset comes from a file name).
pub fn identifier(name: &str) -> String {
    let mut s: String = name.chars().map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }).collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    s
}

/// The bounding box of `points` (min, max).
pub fn bounds_of(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &p| (lo.min(p), hi.max(p)))
}

fn empty_layer<'a>(meta: &StageMetadata, default_prim: &str) -> Layer<'a> {
    Layer {
        default_prim: default_prim.into(),
        doc: meta.doc.clone(),
        meters_per_unit: meta.meters_per_unit,
        up_axis: match meta.up {
            Up::Y => "Y",
            Up::Z => "Z",
        },
        prims: Vec::new(),
    }
}

fn prim<'a>(name: &str, type_name: &'static str, body: Body<'a>) -> Prim<'a> {
    Prim { name: name.into(), type_name, body }
}

fn extent<'a>(lo: Vec3, hi: Vec3) -> Property<'a> {
    Attribute::new("extent", "float3[]", Some(Value::Vec3s(Cow::Owned(vec![lo, hi])))).into()
}

/// A variant's layer.
pub fn variant_layer<'a>(layer: &VariantLayer<'a>, meta: &StageMetadata) -> Layer<'a> {
    let mut children = Vec::new();
    if let Some(m) = &layer.mesh {
        children.push(mesh_prim(m));
    }
    if let Some(p) = &layer.points {
        children.push(points_prim(p));
    }
    if !layer.levels.is_empty() {
        children.push(volume_prim(&layer.levels));
    }
    if let Some((_, image)) = layer.mesh.as_ref().and_then(|m| m.texture.as_ref()) {
        children.push(material_scope(image));
    }
    let mut out = empty_layer(meta, "variant");
    out.prims.push(prim("variant", "Xform", Body { meta: Metadata { kind: Some("component"), ..Default::default() }, children, ..Default::default() }));
    out
}

fn mesh_prim<'a>(m: &MeshPrim<'a>) -> Prim<'a> {
    let (lo, hi) = bounds_of(m.positions);
    let textured = m.texture.is_some();
    let mut properties = vec![
        extent(lo, hi),
        Attribute::new("faceVertexCounts", "int[]", Some(Value::Ints(Cow::Owned(vec![3; m.triangles.len()])))).into(),
        Attribute::new("faceVertexIndices", "int[]", Some(Value::Ints(Cow::Owned(m.triangles.iter().flatten().map(|&i| i as i32).collect())))).into(),
    ];
    if textured {
        properties.push(Property::Relationship { name: "material:binding".into(), target: MATERIAL.into() });
    }
    properties.push(Attribute::new("normals", "normal3f[]", Some(Value::Vec3s(Cow::Borrowed(m.normals)))).interpolation("vertex").into());
    properties.push(Attribute::new("points", "point3f[]", Some(Value::Vec3s(Cow::Borrowed(m.positions)))).into());
    if let Some(c) = m.colours {
        properties.push(Attribute::new("primvars:displayColor", "color3f[]", Some(Value::Vec3s(Cow::Borrowed(c)))).interpolation("vertex").into());
    }
    if let Some((uvs, _)) = &m.texture {
        properties.push(Attribute::new("primvars:st", "texCoord2f[]", Some(Value::Vec2s(Cow::Borrowed(uvs)))).interpolation("faceVarying").into());
    }
    properties.push(Attribute::new("subdivisionScheme", "token", Some(Value::Token("none"))).uniform().into());
    let api_schemas = if textured { vec!["MaterialBindingAPI"] } else { Vec::new() };
    prim("mesh", "Mesh", Body { meta: Metadata { api_schemas, ..Default::default() }, properties, ..Default::default() })
}

fn points_prim<'a>(p: &PointsPrim<'a>) -> Prim<'a> {
    let (lo, hi) = bounds_of(p.positions);
    let r = Vec3::splat(p.width * 0.5);
    let mut properties = vec![
        extent(lo - r, hi + r),
        Attribute::new("normals", "normal3f[]", Some(Value::Vec3s(Cow::Borrowed(p.normals)))).into(),
        Attribute::new("points", "point3f[]", Some(Value::Vec3s(Cow::Borrowed(p.positions)))).into(),
    ];
    if !p.colours.is_empty() {
        properties.push(Attribute::new("primvars:displayColor", "color3f[]", Some(Value::Vec3s(Cow::Borrowed(p.colours)))).interpolation("vertex").into());
    }
    properties.push(Attribute::new("widths", "float[]", Some(Value::Floats(Cow::Owned(vec![p.width])))).interpolation("constant").into());
    prim("points", "Points", Body { properties, ..Default::default() })
}

fn volume_prim<'a>(levels: &[LevelVolume]) -> Prim<'a> {
    let finest = &levels[levels.len() - 1];
    let variants = levels
        .iter()
        .map(|l| {
            let mut properties = vec![extent(l.bounds.0, l.bounds.1)];
            for (field, _) in LEVEL_FIELDS {
                properties.push(Property::Relationship { name: format!("field:{field}"), target: format!("/variant/volume/{field}") });
            }
            let children = LEVEL_FIELDS
                .iter()
                .map(|(field, class)| {
                    let properties = vec![
                        Attribute::new("fieldClass", "token", Some(Value::Token(class))).into(),
                        Attribute::new("fieldName", "token", Some(Value::Token(field))).into(),
                        Attribute::new("filePath", "asset", Some(Value::Asset(l.file.clone()))).into(),
                    ];
                    prim(field, "OpenVDBAsset", Body { properties, ..Default::default() })
                })
                .collect();
            (format!("level_{}", l.index), Body { properties, children, ..Default::default() })
        })
        .collect();
    let meta = Metadata { variant_selection: vec![("level".into(), format!("level_{}", finest.index))], ..Default::default() };
    prim("volume", "Volume", Body { meta, variant_sets: vec![VariantSet { name: "level".into(), variants }], ..Default::default() })
}

fn material_scope<'a>(image: &str) -> Prim<'a> {
    let m = MATERIAL;
    let shader = |name: &str, id: &'static str, mut properties: Vec<Property<'a>>| {
        properties.insert(0, Attribute::new("info:id", "token", Some(Value::Token(id))).uniform().into());
        prim(name, "Shader", Body { properties, ..Default::default() })
    };
    let surface = shader(
        "surface",
        "UsdPreviewSurface",
        vec![
            Attribute::new("inputs:diffuseColor", "color3f", None).connect(format!("{m}/texture.outputs:rgb")).into(),
            Attribute::new("inputs:metallic", "float", Some(Value::Float(0.0))).into(),
            Attribute::new("inputs:roughness", "float", Some(Value::Float(0.8))).into(),
            Attribute::new("outputs:surface", "token", None).into(),
        ],
    );
    let texture = shader(
        "texture",
        "UsdUVTexture",
        vec![
            Attribute::new("inputs:file", "asset", Some(Value::Asset(image.into()))).into(),
            Attribute::new("inputs:sourceColorSpace", "token", Some(Value::Token("sRGB"))).into(),
            Attribute::new("inputs:st", "float2", None).connect(format!("{m}/st.outputs:result")).into(),
            Attribute::new("inputs:wrapS", "token", Some(Value::Token("clamp"))).into(),
            Attribute::new("inputs:wrapT", "token", Some(Value::Token("clamp"))).into(),
            Attribute::new("outputs:rgb", "float3", None).into(),
        ],
    );
    let st = shader(
        "st",
        "UsdPrimvarReader_float2",
        vec![
            Attribute::new("inputs:varname", "string", Some(Value::String("st".into()))).into(),
            Attribute::new("outputs:result", "float2", None).into(),
        ],
    );
    let material = prim(
        "baked",
        "Material",
        Body {
            properties: vec![Attribute::new("outputs:surface", "token", None).connect(format!("{m}/surface.outputs:surface")).into()],
            children: vec![surface, texture, st],
            ..Default::default()
        },
    );
    prim("Looks", "Scope", Body { children: vec![material], ..Default::default() })
}

/// The asset layer: prim `name` (kind component, the default prim) with a
/// variant set `variant` whose variants reference the variant layers
/// (`(variant name, layer path relative to this layer)`); `default` is the
/// selection a client shows first.
pub fn asset_layer<'a>(name: &str, variants: &[(String, String)], default: &str, meta: &StageMetadata) -> Layer<'a> {
    let prim_name = identifier(name);
    let variants = variants
        .iter()
        .map(|(variant, layer)| {
            (identifier(variant), Body { meta: Metadata { references: vec![layer.clone()], ..Default::default() }, ..Default::default() })
        })
        .collect();
    let meta_ = Metadata {
        kind: Some("component"),
        asset_name: Some(name.into()),
        variant_selection: vec![("variant".into(), default.into())],
        ..Default::default()
    };
    let mut out = empty_layer(meta, &prim_name);
    out.prims.push(prim(&prim_name, "Xform", Body { meta: meta_, variant_sets: vec![VariantSet { name: "variant".into(), variants }], ..Default::default() }));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta() -> StageMetadata {
        StageMetadata { up: Up::Z, meters_per_unit: 1.0, doc: "test \"quoted\"".into() }
    }

    #[test]
    fn identifiers_are_usd_names() {
        assert_eq!(identifier("ruined tower-2"), "ruined_tower_2");
        assert_eq!(identifier("3dscan"), "_3dscan");
        assert_eq!(identifier(""), "_");
    }

    #[test]
    fn a_variant_layer_holds_counts_that_match_its_data() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let triangles = [[0, 2, 1], [0, 1, 3]];
        let normals = [Vec3::Z; 4];
        let uvs = [Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE, Vec2::X, Vec2::Y];
        let layer = VariantLayer {
            mesh: Some(MeshPrim {
                positions: &positions,
                triangles: &triangles,
                normals: &normals,
                colours: Some(&normals),
                texture: Some((&uvs, "./mesh_basecolor.png".into())),
            }),
            points: None,
            levels: vec![
                LevelVolume { index: 0, file: "./level_0.vdb".into(), bounds: (Vec3::ZERO, Vec3::ONE) },
                LevelVolume { index: 1, file: "./a@b/level_1.vdb".into(), bounds: (Vec3::ZERO, Vec3::ONE) },
            ],
        };
        let text = usda::encode(&variant_layer(&layer, &meta()));
        assert!(text.starts_with("#usda 1.0\n"));
        assert!(text.contains("upAxis = \"Z\""));
        assert!(text.contains("doc = \"test \\\"quoted\\\"\""));
        assert!(text.contains("int[] faceVertexCounts = [3, 3]"));
        assert!(text.contains("int[] faceVertexIndices = [0, 2, 1, 0, 1, 3]"));
        assert!(text.contains("string level = \"level_1\""));
        assert!(text.contains("asset filePath = @@@./a@b/level_1.vdb@@@"));
        assert!(text.contains("rel material:binding = </variant/Looks/baked>"));
        // usd-core refuses a bare value here (references take one).
        assert!(text.contains("prepend apiSchemas = [\"MaterialBindingAPI\"]"));
        assert!(text.contains("interpolation = \"faceVarying\""));
        assert_eq!(text.matches("def OpenVDBAsset").count(), 2 * LEVEL_FIELDS.len());
        // Balanced braces: every prim and variant closed.
        assert_eq!(text.matches('{').count(), text.matches('}').count());
    }

    #[test]
    fn the_asset_layer_selects_a_default_variant() {
        let text = usda::encode(&asset_layer("tower 1", &[("variant_000".into(), "./variants/variant_000/variant.usda".into())], "variant_000", &meta()));
        assert!(text.contains("defaultPrim = \"tower_1\""));
        assert!(text.contains("string variant = \"variant_000\""));
        assert!(text.contains("prepend references = @./variants/variant_000/variant.usda@"));
        assert!(text.contains("kind = \"component\""));
    }
}
