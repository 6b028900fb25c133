//! `[mesh]`: how `run` and `stage mesh` mesh each variant.

use serde::{Deserialize, Serialize};

/// How `run` and `stage mesh` write each variant's mesh.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshConfig {
    /// Triangle budget of mesh.ply (quadric decimation, sharp features and
    /// colours kept); 0 keeps every triangle of the reconstruction.
    pub faces: usize,
    /// Also write mesh.glb (glTF binary with vertex colours) beside mesh.ply.
    pub glb: bool,
    /// Base-colour texture of a light mesh (`faces` > 0), texels across: a
    /// UV atlas and a texture baked from the level's points, written as
    /// mesh.obj + mesh.mtl + mesh_basecolor.png and as mesh.glb (mesh.ply
    /// keeps vertex colours); 0: no texture. Left out of recorded
    /// configurations at its default, so older run folders keep their digests.
    #[serde(default = "default_texture", skip_serializing_if = "is_default_texture")]
    pub texture: u32,
}

/// [`MeshConfig::texture`]'s default, texels across.
pub const DEFAULT_TEXTURE: u32 = 2048;

fn default_texture() -> u32 {
    DEFAULT_TEXTURE
}
fn is_default_texture(v: &u32) -> bool {
    *v == DEFAULT_TEXTURE
}

impl Default for MeshConfig {
    fn default() -> Self {
        MeshConfig { faces: 0, glb: false, texture: DEFAULT_TEXTURE }
    }
}

impl MeshConfig {
    /// The texture size a light mesh is baked at, if any.
    pub fn texture_size(&self) -> Option<u32> {
        (self.faces > 0 && self.texture > 0).then_some(self.texture)
    }
}
