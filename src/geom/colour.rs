//! sRGB and linear light: glTF's colours are linear, textures and vertex
//! colours here are sRGB.

use glam::Vec3;

/// `texel` (sRGB) times `tint` (sRGB) in linear light, as sRGB: glTF's base
/// colour is the product of the factor, COLOR_0 and the texture, all linear.
pub fn tint(texel: Vec3, tint: Vec3) -> Vec3 {
    let lin = |v: Vec3| Vec3::new(srgb_to_linear(v.x), srgb_to_linear(v.y), srgb_to_linear(v.z));
    let c = lin(texel) * lin(tint);
    Vec3::new(linear_to_srgb(c.x), linear_to_srgb(c.y), linear_to_srgb(c.z))
}

/// Inverse of [`srgb_to_linear`].
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// An sRGB-encoded colour channel in [0,1] to linear light (the IEC 61966-2-1
/// curve). Our colours are display values, like the bytes of a PLY, while
/// glTF's COLOR_0 is linear: without this a viewer would show them too light.
pub fn srgb_to_linear(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
