//! USD text layers (`.usda`): one layer per variant (its mesh, its finest
//! level's points, its level files as volumes) and one asset layer with a
//! variant set over them, for pipelines that hand assets around as USD
//! (Houdini's Solaris, usdview, Omniverse, Maya, Blender).
//!
//! Written as text, by hand, to the USD 1.0 text grammar: every name is an
//! identifier, every float a finite decimal (Rust's shortest round-trip
//! form), every asset path relative to the layer that names it (`@./...@`),
//! so a run folder can be moved or copied whole. Positions are the
//! exemplar's own frame and units, as in every other file we write.
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

use std::fmt::Write as _;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::grid::transform::Up;

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

/// A string as a USD string literal (quotes, backslashes and control
/// characters escaped; the rest UTF-8 as it is).
fn quoted(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// An asset path literal. USD has no escape inside `@...@`: a path holding
/// `@` is written between triple `@@@` delimiters.
fn asset(path: &str) -> String {
    if path.contains('@') {
        format!("@@@{path}@@@")
    } else {
        format!("@{path}@")
    }
}

/// A finite float as USD text (0 for a NaN or infinity, which no writer
/// should pass but no reader must be given).
fn num(x: f32) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        "0".into()
    }
}

fn tuple3(v: Vec3) -> String {
    format!("({}, {}, {})", num(v.x), num(v.y), num(v.z))
}

/// `[a, b, ...]` of `items` formatted in parallel chunks (a full-resolution
/// mesh has millions of numbers), one line per 8 items.
fn array<T: Sync>(items: &[T], fmt: impl Fn(&T) -> String + Sync) -> String {
    let chunks: Vec<String> = items
        .par_chunks(8192)
        .map(|chunk| {
            let mut s = String::with_capacity(chunk.len() * 24);
            for (i, item) in chunk.iter().enumerate() {
                s.push_str(&fmt(item));
                s.push_str(if i % 8 == 7 { ",\n        " } else { ", " });
            }
            s
        })
        .collect();
    let mut body = chunks.concat();
    body.truncate(body.trim_end().trim_end_matches(',').len());
    format!("[{body}]")
}

/// The bounding box of `points` (min, max).
pub fn bounds_of(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &p| (lo.min(p), hi.max(p)))
}

fn header(meta: &StageMetadata, default_prim: &str) -> String {
    let up = match meta.up {
        Up::Y => "Y",
        Up::Z => "Z",
    };
    format!(
        "#usda 1.0\n(\n    defaultPrim = {}\n    doc = {}\n    metersPerUnit = {}\n    upAxis = \"{up}\"\n)\n\n",
        quoted(default_prim),
        quoted(&meta.doc),
        meta.meters_per_unit,
    )
}

/// The text of a variant's layer.
pub fn variant_layer(layer: &VariantLayer, meta: &StageMetadata) -> String {
    let mut s = header(meta, "variant");
    s.push_str("def Xform \"variant\" (\n    kind = \"component\"\n)\n{\n");
    if let Some(m) = &layer.mesh {
        write_mesh(&mut s, m);
    }
    if let Some(p) = &layer.points {
        write_points(&mut s, p);
    }
    if !layer.levels.is_empty() {
        write_volume(&mut s, &layer.levels);
    }
    if let Some((_, image)) = layer.mesh.as_ref().and_then(|m| m.texture.as_ref()) {
        write_material(&mut s, image);
    }
    s.push_str("}\n");
    s
}

fn write_mesh(s: &mut String, m: &MeshPrim) {
    let (lo, hi) = bounds_of(m.positions);
    let textured = m.texture.is_some();
    s.push_str(if textured {
        "    def Mesh \"mesh\" (\n        prepend apiSchemas = [\"MaterialBindingAPI\"]\n    )\n    {\n"
    } else {
        "    def Mesh \"mesh\"\n    {\n"
    });
    let _ = writeln!(s, "        float3[] extent = [{}, {}]", tuple3(lo), tuple3(hi));
    let _ = writeln!(s, "        int[] faceVertexCounts = {}", array(m.triangles, |_| "3".to_string()));
    let _ = writeln!(s, "        int[] faceVertexIndices = {}", array(m.triangles, |t| format!("{}, {}, {}", t[0], t[1], t[2])));
    if textured {
        s.push_str("        rel material:binding = </variant/Looks/baked>\n");
    }
    let _ = writeln!(s, "        normal3f[] normals = {} (\n            interpolation = \"vertex\"\n        )", array(m.normals, |&n| tuple3(n)));
    let _ = writeln!(s, "        point3f[] points = {}", array(m.positions, |&p| tuple3(p)));
    if let Some(c) = m.colours {
        let _ = writeln!(
            s,
            "        color3f[] primvars:displayColor = {} (\n            interpolation = \"vertex\"\n        )",
            array(c, |&c| tuple3(c))
        );
    }
    if let Some((uvs, _)) = &m.texture {
        let _ = writeln!(
            s,
            "        texCoord2f[] primvars:st = {} (\n            interpolation = \"faceVarying\"\n        )",
            array(uvs, |uv| format!("({}, {})", num(uv.x), num(uv.y)))
        );
    }
    s.push_str("        uniform token subdivisionScheme = \"none\"\n    }\n\n");
}

fn write_points(s: &mut String, p: &PointsPrim) {
    let (lo, hi) = bounds_of(p.positions);
    let r = Vec3::splat(p.width * 0.5);
    s.push_str("    def Points \"points\"\n    {\n");
    let _ = writeln!(s, "        float3[] extent = [{}, {}]", tuple3(lo - r), tuple3(hi + r));
    let _ = writeln!(s, "        normal3f[] normals = {}", array(p.normals, |&n| tuple3(n)));
    let _ = writeln!(s, "        point3f[] points = {}", array(p.positions, |&q| tuple3(q)));
    if !p.colours.is_empty() {
        let _ = writeln!(
            s,
            "        color3f[] primvars:displayColor = {} (\n            interpolation = \"vertex\"\n        )",
            array(p.colours, |&c| tuple3(c))
        );
    }
    let _ = writeln!(s, "        float[] widths = [{}] (\n            interpolation = \"constant\"\n        )", num(p.width));
    s.push_str("    }\n\n");
}

fn write_volume(s: &mut String, levels: &[LevelVolume]) {
    let finest = &levels[levels.len() - 1];
    let _ = write!(
        s,
        "    def Volume \"volume\" (\n        variants = {{\n            string level = \"level_{}\"\n        }}\n        prepend variantSets = \"level\"\n    )\n    {{\n        variantSet \"level\" = {{\n",
        finest.index
    );
    for l in levels {
        let _ = writeln!(s, "            \"level_{}\" {{", l.index);
        let _ = writeln!(s, "                float3[] extent = [{}, {}]", tuple3(l.bounds.0), tuple3(l.bounds.1));
        for (field, _) in LEVEL_FIELDS {
            let _ = writeln!(s, "                rel field:{field} = </variant/volume/{field}>");
        }
        for (field, class) in LEVEL_FIELDS {
            let _ = write!(
                s,
                "\n                def OpenVDBAsset \"{field}\"\n                {{\n                    token fieldClass = \"{class}\"\n                    token fieldName = \"{field}\"\n                    asset filePath = {}\n                }}\n",
                asset(&l.file)
            );
        }
        s.push_str("            }\n");
    }
    s.push_str("        }\n    }\n\n");
}

fn write_material(s: &mut String, image: &str) {
    let m = "/variant/Looks/baked";
    let _ = write!(
        s,
        "    def Scope \"Looks\"\n    {{\n        def Material \"baked\"\n        {{\n            token outputs:surface.connect = <{m}/surface.outputs:surface>\n\n\
        \x20           def Shader \"surface\"\n            {{\n                uniform token info:id = \"UsdPreviewSurface\"\n\
        \x20               color3f inputs:diffuseColor.connect = <{m}/texture.outputs:rgb>\n\
        \x20               float inputs:metallic = 0\n                float inputs:roughness = 0.8\n                token outputs:surface\n            }}\n\n\
        \x20           def Shader \"texture\"\n            {{\n                uniform token info:id = \"UsdUVTexture\"\n\
        \x20               asset inputs:file = {}\n                token inputs:sourceColorSpace = \"sRGB\"\n\
        \x20               float2 inputs:st.connect = <{m}/st.outputs:result>\n\
        \x20               token inputs:wrapS = \"clamp\"\n                token inputs:wrapT = \"clamp\"\n                float3 outputs:rgb\n            }}\n\n\
        \x20           def Shader \"st\"\n            {{\n                uniform token info:id = \"UsdPrimvarReader_float2\"\n\
        \x20               string inputs:varname = \"st\"\n                float2 outputs:result\n            }}\n        }}\n    }}\n",
        asset(image)
    );
}

/// The text of the asset layer: prim `name` (kind component, the default
/// prim) with a variant set `variant` whose variants reference the variant
/// layers (`(variant name, layer path relative to this layer)`); `default`
/// is the selection a client shows first.
pub fn asset_layer(name: &str, variants: &[(String, String)], default: &str, meta: &StageMetadata) -> String {
    let prim = identifier(name);
    let mut s = header(meta, &prim);
    let _ = write!(
        s,
        "def Xform {} (\n    assetInfo = {{\n        string name = {}\n    }}\n    kind = \"component\"\n    variants = {{\n        string variant = {}\n    }}\n    prepend variantSets = \"variant\"\n)\n{{\n    variantSet \"variant\" = {{\n",
        quoted(&prim),
        quoted(name),
        quoted(default)
    );
    for (variant, layer) in variants {
        let _ = write!(
            s,
            "        {} (\n            prepend references = {}\n        ) {{\n        }}\n",
            quoted(&identifier(variant)),
            asset(layer)
        );
    }
    s.push_str("    }\n}\n");
    s
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
        let text = variant_layer(&layer, &meta());
        assert!(text.starts_with("#usda 1.0\n"));
        assert!(text.contains("upAxis = \"Z\""));
        assert!(text.contains("doc = \"test \\\"quoted\\\"\""));
        assert!(text.contains("int[] faceVertexCounts = [3, 3]"));
        assert!(text.contains("int[] faceVertexIndices = [0, 2, 1, 0, 1, 3]"));
        assert!(text.contains("string level = \"level_1\""));
        assert!(text.contains("asset filePath = @@@./a@b/level_1.vdb@@@"));
        assert!(text.contains("rel material:binding = </variant/Looks/baked>"));
        assert!(text.contains("interpolation = \"faceVarying\""));
        assert_eq!(text.matches("def OpenVDBAsset").count(), 2 * LEVEL_FIELDS.len());
        // Balanced braces: every prim and variant closed.
        assert_eq!(text.matches('{').count(), text.matches('}').count());
    }

    #[test]
    fn long_arrays_break_lines_and_keep_every_item() {
        let v: Vec<u32> = (0..20_000).collect();
        let text = array(&v, |i| i.to_string());
        let items: Vec<u32> = text.trim_matches(|c| c == '[' || c == ']').split(',').map(|s| s.trim().parse().unwrap()).collect();
        assert_eq!(items, v);
        assert_eq!(num(f32::NAN), "0");
    }

    #[test]
    fn the_asset_layer_selects_a_default_variant() {
        let text = asset_layer("tower 1", &[("variant_000".into(), "./variants/variant_000/variant.usda".into())], "variant_000", &meta());
        assert!(text.contains("defaultPrim = \"tower_1\""));
        assert!(text.contains("string variant = \"variant_000\""));
        assert!(text.contains("prepend references = @./variants/variant_000/variant.usda@"));
        assert!(text.contains("kind = \"component\""));
    }
}
