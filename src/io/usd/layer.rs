//! A USD layer as the scene description it holds (USD's own data model,
//! reduced to what we write): prims with their metadata, attributes and
//! relationships, variant sets. One description, two encodings: text
//! (`.usda`, [`super::usda`]) and binary (`.usdc`, [`super::usdc`]), so the
//! two files of a layer hold the same scene by construction.

use std::borrow::Cow;

use glam::{Vec2, Vec3};

/// A layer: its metadata and its root prims.
pub struct Layer<'a> {
    pub default_prim: String,
    /// The layer's `doc` (who wrote it, from what).
    pub doc: String,
    pub meters_per_unit: f64,
    /// `"Y"` or `"Z"`.
    pub up_axis: &'static str,
    pub prims: Vec<Prim<'a>>,
}

/// A defined prim (`def TYPE "name"`).
pub struct Prim<'a> {
    pub name: String,
    /// The schema type (`Mesh`, `Xform`, ...).
    pub type_name: &'static str,
    pub body: Body<'a>,
}

/// What a prim and a variant both hold: metadata, properties, child prims
/// and variant sets (a variant is a prim's body chosen by name).
#[derive(Default)]
pub struct Body<'a> {
    pub meta: Metadata,
    pub properties: Vec<Property<'a>>,
    pub children: Vec<Prim<'a>>,
    pub variant_sets: Vec<VariantSet<'a>>,
}

/// The prim metadata we write.
#[derive(Default)]
pub struct Metadata {
    pub kind: Option<&'static str>,
    /// `prepend apiSchemas`.
    pub api_schemas: Vec<&'static str>,
    /// `assetInfo = { string name = ... }`.
    pub asset_name: Option<String>,
    /// `variants = { string SET = "CHOICE" }`, the selection shown first.
    pub variant_selection: Vec<(String, String)>,
    /// `prepend references`: layers (paths relative to this one) whose
    /// default prim this prim or variant is.
    pub references: Vec<String>,
}

/// A named set of alternative bodies (`variantSet "name" = { ... }`); the
/// owning prim also lists it in `prepend variantSets`.
pub struct VariantSet<'a> {
    pub name: String,
    pub variants: Vec<(String, Body<'a>)>,
}

pub enum Property<'a> {
    Attribute(Attribute<'a>),
    /// `rel NAME = <TARGET>`: one target, an absolute prim path.
    Relationship { name: String, target: String },
}

/// `[uniform] TYPE NAME [= VALUE] [(interpolation = ...)]`, and its
/// connection (`NAME.connect = <PATH>`, an absolute property path) where
/// there is one.
pub struct Attribute<'a> {
    pub name: String,
    /// The USD value type name (`point3f[]`, `token`, ...): the value's
    /// role, the encodings store [`Value`]s by their plain type.
    pub type_name: &'static str,
    pub uniform: bool,
    pub value: Option<Value<'a>>,
    pub interpolation: Option<&'static str>,
    pub connection: Option<String>,
}

impl<'a> Attribute<'a> {
    pub fn new(name: &str, type_name: &'static str, value: Option<Value<'a>>) -> Self {
        Attribute { name: name.into(), type_name, uniform: false, value, interpolation: None, connection: None }
    }
    pub fn uniform(mut self) -> Self {
        self.uniform = true;
        self
    }
    pub fn interpolation(mut self, i: &'static str) -> Self {
        self.interpolation = Some(i);
        self
    }
    pub fn connect(mut self, path: String) -> Self {
        self.connection = Some(path);
        self
    }
}

impl<'a> From<Attribute<'a>> for Property<'a> {
    fn from(a: Attribute<'a>) -> Self {
        Property::Attribute(a)
    }
}

/// An attribute's value. Arrays borrow the caller's data where it has the
/// stored layout (a full-resolution mesh holds millions of numbers).
pub enum Value<'a> {
    Token(&'static str),
    String(String),
    /// A path relative to the layer.
    Asset(String),
    Float(f32),
    Ints(Cow<'a, [i32]>),
    Floats(Cow<'a, [f32]>),
    Vec2s(Cow<'a, [Vec2]>),
    Vec3s(Cow<'a, [Vec3]>),
}

impl Property<'_> {
    pub fn name(&self) -> &str {
        match self {
            Property::Attribute(a) => &a.name,
            Property::Relationship { name, .. } => name,
        }
    }
}
