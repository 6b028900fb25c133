//! A [`Layer`] as binary USD (`.usdc`, USD's "crate" format, version
//! 0.8.0, what usd-core writes by default and reads back to 0.4.0): the
//! layer's specs (one per prim, property, variant set, variant and target
//! path) with their fields, over tables of tokens, strings, paths, fields
//! and field sets. The tables are compressed as the format requires (LZ4,
//! and the integer tables delta-coded first); attribute arrays are stored
//! plain, 8-byte aligned, which a reader maps without copying.
//!
//! The layout, from the format's reference implementation (OpenUSD,
//! `crateFile.cpp`, `integerCoding.cpp`): an 88-byte bootstrap (`PXR-USDC`,
//! the version, the table of contents' offset), the values, six sections
//! (TOKENS, STRINGS, FIELDS, FIELDSETS, PATHS, SPECS), the table of contents.

use std::collections::HashMap;

use super::layer::{Attribute, Body, Layer, Metadata, Prim, Property, Value};

const VERSION: [u8; 3] = [0, 8, 0];
const BOOTSTRAP_BYTES: usize = 88;

/// Value type numbers of the format (`crateDataTypes.h`).
mod ty {
    pub const BOOL: u8 = 1;
    pub const INT: u8 = 3;
    pub const FLOAT: u8 = 8;
    pub const DOUBLE: u8 = 9;
    pub const STRING: u8 = 10;
    pub const TOKEN: u8 = 11;
    pub const ASSET_PATH: u8 = 12;
    pub const VEC2F: u8 = 20;
    pub const VEC3F: u8 = 24;
    pub const DICTIONARY: u8 = 31;
    pub const TOKEN_LIST_OP: u8 = 32;
    pub const STRING_LIST_OP: u8 = 33;
    pub const PATH_LIST_OP: u8 = 34;
    pub const REFERENCE_LIST_OP: u8 = 35;
    pub const PATH_VECTOR: u8 = 40;
    pub const TOKEN_VECTOR: u8 = 41;
    pub const SPECIFIER: u8 = 42;
    pub const VARIABILITY: u8 = 44;
    pub const VARIANT_SELECTION_MAP: u8 = 45;
}

/// Spec types (`SdfSpecType`).
#[derive(Clone, Copy)]
enum SpecType {
    Attribute = 1,
    Connection = 2,
    Prim = 6,
    PseudoRoot = 7,
    Relationship = 8,
    RelationshipTarget = 9,
    Variant = 10,
    VariantSet = 11,
}

const SPECIFIER_DEF: u32 = 0;
const VARIABILITY_VARYING: u32 = 0;
const VARIABILITY_UNIFORM: u32 = 1;

/// List-op header bits: explicit items, prepended items.
const LIST_OP_EXPLICIT: u8 = 1 | 2;
const LIST_OP_PREPEND: u8 = 1 << 5;

/// One element of a scene path.
#[derive(Clone, PartialEq, Eq, Hash, Debug)]
enum Element {
    Child(String),
    /// `{set=choice}`; an empty choice names the variant set itself.
    Variant(String, String),
    Property(String),
    /// `[/absolute/path]`: a relationship's or a connection's target.
    Target(Path),
}

/// A scene path: the elements below the root.
#[derive(Clone, PartialEq, Eq, Hash, Debug, Default)]
struct Path(Vec<Element>);

impl Path {
    fn with(&self, e: Element) -> Path {
        let mut p = self.clone();
        p.0.push(e);
        p
    }
    fn child(&self, name: &str) -> Path {
        self.with(Element::Child(name.into()))
    }
    fn property(&self, name: &str) -> Path {
        self.with(Element::Property(name.into()))
    }
    /// An absolute prim or prim-property path as text (`/a/b`, `/a/b.c:d`):
    /// the targets we write.
    fn parse(text: &str) -> Path {
        let (prims, property) = match text.rsplit_once('/').and_then(|(_, last)| last.split_once('.')) {
            Some((_, prop)) => (&text[..text.len() - prop.len() - 1], Some(prop)),
            None => (text, None),
        };
        let mut p = Path::default();
        for name in prims.split('/').filter(|n| !n.is_empty()) {
            p = p.child(name);
        }
        match property {
            Some(prop) => p.property(prop),
            None => p,
        }
    }
    fn text(&self) -> String {
        let mut s = String::new();
        for e in &self.0 {
            match e {
                Element::Child(n) => {
                    if !matches!(s.chars().last(), Some('}')) {
                        s.push('/');
                    }
                    s.push_str(n);
                }
                Element::Property(n) => {
                    s.push('.');
                    s.push_str(n);
                }
                Element::Variant(set, choice) => {
                    s.push_str(&format!("{{{set}={choice}}}"));
                }
                Element::Target(t) => {
                    s.push_str(&format!("[{}]", t.text()));
                }
            }
        }
        if s.is_empty() {
            s.push('/');
        }
        s
    }
    fn parent(&self) -> Option<Path> {
        (!self.0.is_empty()).then(|| Path(self.0[..self.0.len() - 1].to_vec()))
    }
}

/// A value's 8-byte representation: type, array and inlined bits, and a
/// 48-bit payload (the value itself where it fits in 4 bytes, else its
/// offset in the file).
fn rep(ty: u8, inlined: bool, array: bool, payload: u64) -> u64 {
    (u64::from(array) << 63) | (u64::from(inlined) << 62) | (u64::from(ty) << 48) | (payload & ((1 << 48) - 1))
}

struct Writer {
    /// The file: bootstrap placeholder, then values as specs are packed.
    out: Vec<u8>,
    tokens: Vec<String>,
    token_index: HashMap<String, u32>,
    /// Strings are tokens, listed apart.
    strings: Vec<u32>,
    string_index: HashMap<String, u32>,
    paths: Vec<Path>,
    path_index: HashMap<Path, u32>,
    fields: Vec<(u32, u64)>,
    field_sets: Vec<u32>,
    specs: Vec<[u32; 3]>,
}

/// The layer's bytes.
pub fn encode(layer: &Layer) -> Vec<u8> {
    let mut w = Writer {
        out: vec![0; BOOTSTRAP_BYTES],
        tokens: Vec::new(),
        token_index: HashMap::new(),
        strings: Vec::new(),
        string_index: HashMap::new(),
        paths: Vec::new(),
        path_index: HashMap::new(),
        fields: Vec::new(),
        field_sets: Vec::new(),
        specs: Vec::new(),
    };
    // Token 0 is never a property name: a property's token index is stored
    // negated, and -0 would read as a prim's.
    w.token("");
    w.pseudo_root(layer);
    w.finish()
}

impl Writer {
    fn token(&mut self, t: &str) -> u32 {
        if let Some(&i) = self.token_index.get(t) {
            return i;
        }
        let i = self.tokens.len() as u32;
        self.tokens.push(t.to_string());
        self.token_index.insert(t.to_string(), i);
        i
    }

    fn string(&mut self, s: &str) -> u32 {
        if let Some(&i) = self.string_index.get(s) {
            return i;
        }
        let t = self.token(s);
        let i = self.strings.len() as u32;
        self.strings.push(t);
        self.string_index.insert(s.to_string(), i);
        i
    }

    /// The path's index, its parents' (and a target's own path) added first.
    fn path(&mut self, p: &Path) -> u32 {
        if let Some(&i) = self.path_index.get(p) {
            return i;
        }
        if let Some(Element::Target(t)) = p.0.last() {
            self.path(t);
        }
        if let Some(parent) = p.parent() {
            self.path(&parent);
        }
        match p.0.last() {
            Some(Element::Child(n)) | Some(Element::Property(n)) => self.token(n),
            Some(Element::Variant(s, c)) => self.token(&format!("{{{s}={c}}}")),
            Some(Element::Target(t)) => self.token(&format!("[{}]", t.text())),
            None => 0,
        };
        let i = self.paths.len() as u32;
        self.paths.push(p.clone());
        self.path_index.insert(p.clone(), i);
        i
    }

    fn put_u32(&mut self, x: u32) {
        self.out.extend_from_slice(&x.to_le_bytes());
    }
    fn put_u64(&mut self, x: u64) {
        self.out.extend_from_slice(&x.to_le_bytes());
    }
    fn align8(&mut self) {
        while self.out.len() % 8 != 0 {
            self.out.push(0);
        }
    }

    /// `uint64 count` then each item's index.
    fn put_indices(&mut self, items: &[u32]) {
        self.put_u64(items.len() as u64);
        for &i in items {
            self.put_u32(i);
        }
    }

    fn token_vector(&mut self, names: &[&str]) -> u64 {
        let ids: Vec<u32> = names.iter().map(|n| self.token(n)).collect();
        let at = self.out.len() as u64;
        self.put_indices(&ids);
        rep(ty::TOKEN_VECTOR, false, false, at)
    }

    fn path_vector(&mut self, paths: &[Path]) -> u64 {
        let ids: Vec<u32> = paths.iter().map(|p| self.path(p)).collect();
        let at = self.out.len() as u64;
        self.put_indices(&ids);
        rep(ty::PATH_VECTOR, false, false, at)
    }

    /// A list op of one list (`bits`: explicit or prepended) of indices.
    fn list_op(&mut self, ty: u8, bits: u8, ids: &[u32]) -> u64 {
        let at = self.out.len() as u64;
        self.out.push(bits);
        self.put_indices(ids);
        rep(ty, false, false, at)
    }

    fn double(&mut self, x: f64) -> u64 {
        let at = self.out.len() as u64;
        self.out.extend_from_slice(&x.to_le_bytes());
        rep(ty::DOUBLE, false, false, at)
    }

    /// An array: 8-byte aligned, `uint64 count`, the items' bytes.
    fn array(&mut self, ty: u8, count: usize, bytes: impl Iterator<Item = [u8; 4]>) -> u64 {
        if count == 0 {
            return rep(ty, false, true, 0);
        }
        self.align8();
        let at = self.out.len() as u64;
        self.put_u64(count as u64);
        self.out.reserve(count * 12);
        for b in bytes {
            self.out.extend_from_slice(&b);
        }
        rep(ty, false, true, at)
    }

    fn value(&mut self, v: &Value) -> u64 {
        match v {
            Value::Token(t) => rep(ty::TOKEN, true, false, self.token(t).into()),
            Value::String(s) => rep(ty::STRING, true, false, self.string(s).into()),
            Value::Asset(p) => rep(ty::ASSET_PATH, true, false, self.token(p).into()),
            Value::Float(x) => rep(ty::FLOAT, true, false, x.to_bits().into()),
            Value::Ints(v) => self.array(ty::INT, v.len(), v.iter().map(|i| i.to_le_bytes())),
            Value::Floats(v) => self.array(ty::FLOAT, v.len(), v.iter().map(|x| x.to_le_bytes())),
            Value::Vec2s(v) => self.array(ty::VEC2F, v.len(), v.iter().flat_map(|p| [p.x, p.y]).map(|x| x.to_le_bytes())),
            Value::Vec3s(v) => self.array(ty::VEC3F, v.len(), v.iter().flat_map(|p| [p.x, p.y, p.z]).map(|x| x.to_le_bytes())),
        }
    }

    fn spec(&mut self, path: &Path, kind: SpecType, fields: &[(&str, u64)]) {
        let p = self.path(path);
        let set = self.field_sets.len() as u32;
        for &(name, rep) in fields {
            let t = self.token(name);
            self.field_sets.push(self.fields.len() as u32);
            self.fields.push((t, rep));
        }
        self.field_sets.push(u32::MAX);
        self.specs.push([p, set, kind as u32]);
    }

    fn pseudo_root(&mut self, layer: &Layer) {
        let root = Path::default();
        let mut fields = vec![
            ("defaultPrim", rep(ty::TOKEN, true, false, self.token(&layer.default_prim).into())),
            ("documentation", rep(ty::STRING, true, false, self.string(&layer.doc).into())),
            ("metersPerUnit", self.double(layer.meters_per_unit)),
            ("upAxis", rep(ty::TOKEN, true, false, self.token(layer.up_axis).into())),
        ];
        let names: Vec<&str> = layer.prims.iter().map(|p| p.name.as_str()).collect();
        if !names.is_empty() {
            fields.push(("primChildren", self.token_vector(&names)));
        }
        self.spec(&root, SpecType::PseudoRoot, &fields);
        for prim in &layer.prims {
            self.prim(&root, prim);
        }
    }

    fn prim(&mut self, parent: &Path, prim: &Prim) {
        let path = parent.child(&prim.name);
        let mut fields = vec![
            ("specifier", rep(ty::SPECIFIER, true, false, SPECIFIER_DEF.into())),
            ("typeName", rep(ty::TOKEN, true, false, self.token(prim.type_name).into())),
        ];
        fields.extend(self.body(&path, &prim.body));
        self.spec(&path, SpecType::Prim, &fields);
    }

    /// The fields of a prim's or a variant's body; the specs below it
    /// (properties, child prims, variant sets and variants) written too.
    fn body(&mut self, path: &Path, body: &Body) -> Vec<(&'static str, u64)> {
        let mut fields = self.metadata(&body.meta);
        if !body.variant_sets.is_empty() {
            let names: Vec<u32> = body.variant_sets.iter().map(|s| self.string(&s.name)).collect();
            fields.push(("variantSetNames", self.list_op(ty::STRING_LIST_OP, LIST_OP_PREPEND, &names)));
            let names: Vec<&str> = body.variant_sets.iter().map(|s| s.name.as_str()).collect();
            fields.push(("variantSetChildren", self.token_vector(&names)));
        }
        let children: Vec<&str> = body.children.iter().map(|c| c.name.as_str()).collect();
        if !children.is_empty() {
            fields.push(("primChildren", self.token_vector(&children)));
        }
        let properties: Vec<&str> = body.properties.iter().map(|p| p.name()).collect();
        if !properties.is_empty() {
            fields.push(("properties", self.token_vector(&properties)));
        }
        for p in &body.properties {
            self.property(path, p);
        }
        for c in &body.children {
            self.prim(path, c);
        }
        for set in &body.variant_sets {
            let names: Vec<&str> = set.variants.iter().map(|(n, _)| n.as_str()).collect();
            let children = self.token_vector(&names);
            self.spec(&path.with(Element::Variant(set.name.clone(), String::new())), SpecType::VariantSet, &[("variantChildren", children)]);
            for (name, variant) in &set.variants {
                let vpath = path.with(Element::Variant(set.name.clone(), name.clone()));
                let fields = self.body(&vpath, variant);
                self.spec(&vpath, SpecType::Variant, &fields);
            }
        }
        fields
    }

    fn metadata(&mut self, m: &Metadata) -> Vec<(&'static str, u64)> {
        let mut fields = Vec::new();
        if let Some(name) = &m.asset_name {
            // A dictionary: count, then each key (a string) and its value
            // (an offset to the value's representation, here just after it).
            let key = self.string("name");
            let value = rep(ty::STRING, true, false, self.string(name).into());
            let at = self.out.len() as u64;
            self.put_u64(1);
            self.put_u32(key);
            self.put_u64(8);
            self.put_u64(value);
            fields.push(("assetInfo", rep(ty::DICTIONARY, false, false, at)));
        }
        if let Some(kind) = m.kind {
            fields.push(("kind", rep(ty::TOKEN, true, false, self.token(kind).into())));
        }
        if !m.api_schemas.is_empty() {
            let ids: Vec<u32> = m.api_schemas.iter().map(|a| self.token(a)).collect();
            fields.push(("apiSchemas", self.list_op(ty::TOKEN_LIST_OP, LIST_OP_PREPEND, &ids)));
        }
        if !m.references.is_empty() {
            // Each reference: asset path (a string), prim path (the empty
            // path: the layer's default prim), layer offset (0, scale 1),
            // custom data (an empty dictionary).
            let refs: Vec<u32> = m.references.iter().map(|r| self.string(r)).collect();
            let empty = self.empty_path();
            let at = self.out.len() as u64;
            self.out.push(LIST_OP_PREPEND);
            self.put_u64(refs.len() as u64);
            for r in refs {
                self.put_u32(r);
                self.put_u32(empty);
                self.out.extend_from_slice(&0f64.to_le_bytes());
                self.out.extend_from_slice(&1f64.to_le_bytes());
                self.put_u64(0);
            }
            fields.push(("references", rep(ty::REFERENCE_LIST_OP, false, false, at)));
        }
        if !m.variant_selection.is_empty() {
            let pairs: Vec<(u32, u32)> = m.variant_selection.iter().map(|(s, c)| (self.string(s), self.string(c))).collect();
            let at = self.out.len() as u64;
            self.put_u64(pairs.len() as u64);
            for (s, c) in pairs {
                self.put_u32(s);
                self.put_u32(c);
            }
            fields.push(("variantSelection", rep(ty::VARIANT_SELECTION_MAP, false, false, at)));
        }
        fields
    }

    /// The empty path's index: in the path table, never in its tree (a
    /// reader leaves the entry empty).
    fn empty_path(&mut self) -> u32 {
        // Listed apart from the scene's paths: a sentinel no scene path equals.
        let empty = Path(vec![Element::Child(String::new())]);
        if let Some(&i) = self.path_index.get(&empty) {
            return i;
        }
        let i = self.paths.len() as u32;
        self.paths.push(empty.clone());
        self.path_index.insert(empty, i);
        i
    }

    fn property(&mut self, prim: &Path, p: &Property) {
        match p {
            Property::Attribute(a) => self.attribute(prim, a),
            Property::Relationship { name, target } => {
                let path = prim.property(name);
                let target = Path::parse(target);
                let t = self.path(&target);
                let fields = [
                    ("variability", rep(ty::VARIABILITY, true, false, VARIABILITY_UNIFORM.into())),
                    ("targetPaths", self.list_op(ty::PATH_LIST_OP, LIST_OP_EXPLICIT, &[t])),
                    ("targetChildren", self.path_vector(std::slice::from_ref(&target))),
                ];
                self.spec(&path, SpecType::Relationship, &fields);
                self.spec(&path.with(Element::Target(target)), SpecType::RelationshipTarget, &[]);
            }
        }
    }

    fn attribute(&mut self, prim: &Path, a: &Attribute) {
        let path = prim.property(&a.name);
        let variability = if a.uniform { VARIABILITY_UNIFORM } else { VARIABILITY_VARYING };
        let mut fields = vec![
            ("custom", rep(ty::BOOL, true, false, 0)),
            ("typeName", rep(ty::TOKEN, true, false, self.token(a.type_name).into())),
            ("variability", rep(ty::VARIABILITY, true, false, variability.into())),
        ];
        if let Some(v) = &a.value {
            fields.push(("default", self.value(v)));
        }
        if let Some(i) = a.interpolation {
            fields.push(("interpolation", rep(ty::TOKEN, true, false, self.token(i).into())));
        }
        let target = a.connection.as_deref().map(Path::parse);
        if let Some(target) = &target {
            let t = self.path(target);
            fields.push(("connectionPaths", self.list_op(ty::PATH_LIST_OP, LIST_OP_EXPLICIT, &[t])));
            fields.push(("connectionChildren", self.path_vector(std::slice::from_ref(target))));
        }
        self.spec(&path, SpecType::Attribute, &fields);
        if let Some(target) = target {
            self.spec(&path.with(Element::Target(target)), SpecType::Connection, &[]);
        }
    }

    /// The sections and the table of contents after the values, then the
    /// bootstrap at the start.
    fn finish(mut self) -> Vec<u8> {
        let mut toc: Vec<(&str, u64, u64)> = Vec::new();

        let start = self.out.len();
        let mut chars = Vec::new();
        for t in &self.tokens {
            chars.extend_from_slice(t.as_bytes());
            chars.push(0);
        }
        self.put_u64(self.tokens.len() as u64);
        self.put_u64(chars.len() as u64);
        let packed = fast_compress(&chars);
        self.put_u64(packed.len() as u64);
        self.out.extend_from_slice(&packed);
        toc.push(("TOKENS", start as u64, (self.out.len() - start) as u64));

        let start = self.out.len();
        let strings = std::mem::take(&mut self.strings);
        self.put_indices(&strings);
        toc.push(("STRINGS", start as u64, (self.out.len() - start) as u64));

        let start = self.out.len();
        self.put_u64(self.fields.len() as u64);
        let tokens: Vec<u32> = self.fields.iter().map(|f| f.0).collect();
        self.put_ints(&tokens);
        let reps: Vec<u8> = self.fields.iter().flat_map(|f| f.1.to_le_bytes()).collect();
        let packed = fast_compress(&reps);
        self.put_u64(packed.len() as u64);
        self.out.extend_from_slice(&packed);
        toc.push(("FIELDS", start as u64, (self.out.len() - start) as u64));

        let start = self.out.len();
        let sets = std::mem::take(&mut self.field_sets);
        self.put_u64(sets.len() as u64);
        self.put_ints(&sets);
        toc.push(("FIELDSETS", start as u64, (self.out.len() - start) as u64));

        let start = self.out.len();
        self.write_paths();
        toc.push(("PATHS", start as u64, (self.out.len() - start) as u64));

        let start = self.out.len();
        let specs = std::mem::take(&mut self.specs);
        self.put_u64(specs.len() as u64);
        for column in 0..3 {
            let v: Vec<u32> = specs.iter().map(|s| s[column]).collect();
            self.put_ints(&v);
        }
        toc.push(("SPECS", start as u64, (self.out.len() - start) as u64));

        let toc_offset = self.out.len() as u64;
        self.put_u64(toc.len() as u64);
        for (name, start, size) in toc {
            let mut n = [0u8; 16];
            n[..name.len()].copy_from_slice(name.as_bytes());
            self.out.extend_from_slice(&n);
            self.put_u64(start);
            self.put_u64(size);
        }
        self.out[..8].copy_from_slice(b"PXR-USDC");
        self.out[8..11].copy_from_slice(&VERSION);
        self.out[16..24].copy_from_slice(&toc_offset.to_le_bytes());
        self.out
    }

    /// `uint64 size` then the integers compressed.
    fn put_ints(&mut self, ints: &[u32]) {
        let packed = fast_compress(&encode_ints(ints));
        self.put_u64(packed.len() as u64);
        self.out.extend_from_slice(&packed);
    }

    /// The path table as a tree in depth-first order: each node's path
    /// index, its element's token (negated for a prim's property), and a
    /// jump: -2 a leaf with no next sibling, -1 its first child follows
    /// and no sibling, 0 its next sibling follows, else its first child
    /// follows and its next sibling is that many entries on.
    fn write_paths(&mut self) {
        let empty = self.path_index.get(&Path(vec![Element::Child(String::new())])).copied();
        let mut children: HashMap<Option<Path>, Vec<u32>> = HashMap::new();
        for (i, p) in self.paths.iter().enumerate() {
            if Some(i as u32) != empty {
                children.entry(p.parent()).or_default().push(i as u32);
            }
        }
        let mut indices = Vec::new();
        let mut tokens = Vec::new();
        let mut jumps = Vec::new();
        self.tree(&children, None, &mut indices, &mut tokens, &mut jumps);
        self.put_u64(self.paths.len() as u64);
        self.put_u64(indices.len() as u64);
        self.put_ints(&indices);
        let tokens: Vec<u32> = tokens.iter().map(|&t: &i32| t as u32).collect();
        self.put_ints(&tokens);
        let jumps: Vec<u32> = jumps.iter().map(|&j: &i32| j as u32).collect();
        self.put_ints(&jumps);
    }

    fn tree(&self, children: &HashMap<Option<Path>, Vec<u32>>, parent: Option<Path>, indices: &mut Vec<u32>, tokens: &mut Vec<i32>, jumps: &mut Vec<i32>) {
        let Some(siblings) = children.get(&parent) else { return };
        for (k, &i) in siblings.iter().enumerate() {
            let p = &self.paths[i as usize];
            let token = match p.0.last() {
                None => 0,
                Some(Element::Property(n)) => -(self.token_index[n] as i32),
                Some(Element::Child(n)) => self.token_index[n] as i32,
                Some(Element::Variant(s, c)) => self.token_index[&format!("{{{s}={c}}}")] as i32,
                Some(Element::Target(t)) => self.token_index[&format!("[{}]", t.text())] as i32,
            };
            let at = indices.len();
            indices.push(i);
            tokens.push(token);
            jumps.push(0);
            let has_child = children.contains_key(&Some(p.clone()));
            let has_sibling = k + 1 < siblings.len();
            if has_child {
                self.tree(children, Some(p.clone()), indices, tokens, jumps);
            }
            jumps[at] = match (has_child, has_sibling) {
                (true, true) => (indices.len() - at) as i32,
                (false, true) => 0,
                (true, false) => -1,
                (false, false) => -2,
            };
        }
    }
}

/// The format's integer coding (before LZ4): the most common difference
/// between neighbours, then a 2-bit code per integer (0 that difference, 1
/// an 8-bit, 2 a 16-bit, 3 a 32-bit difference following), then the
/// differences that are not the common one.
fn encode_ints(ints: &[u32]) -> Vec<u8> {
    if ints.is_empty() {
        return Vec::new();
    }
    let deltas: Vec<i32> = ints.iter().scan(0i32, |prev, &x| {
        let d = (x as i32).wrapping_sub(*prev);
        *prev = x as i32;
        Some(d)
    }).collect();
    let mut counts: HashMap<i32, usize> = HashMap::new();
    for &d in &deltas {
        *counts.entry(d).or_default() += 1;
    }
    let common = counts.iter().max_by_key(|&(&d, &n)| (n, d)).map(|(&d, _)| d).unwrap_or(0);
    let mut codes = vec![0u8; (ints.len() * 2).div_ceil(8)];
    let mut vints = Vec::new();
    for (i, &d) in deltas.iter().enumerate() {
        let code: u8 = if d == common {
            0
        } else if let Ok(b) = i8::try_from(d) {
            vints.extend_from_slice(&b.to_le_bytes());
            1
        } else if let Ok(h) = i16::try_from(d) {
            vints.extend_from_slice(&h.to_le_bytes());
            2
        } else {
            vints.extend_from_slice(&d.to_le_bytes());
            3
        };
        codes[i / 4] |= code << (2 * (i % 4));
    }
    let mut out = common.to_le_bytes().to_vec();
    out.extend_from_slice(&codes);
    out.extend_from_slice(&vints);
    out
}

/// The format's fast compression: a chunk count byte (0: one chunk), then
/// an LZ4 block. Our tables are far below LZ4's 2 GB chunk limit.
fn fast_compress(bytes: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8];
    out.extend_from_slice(&lz4_flex::block::compress(bytes));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The decoder of the format's integer coding, as its reader does it.
    fn decode_ints(bytes: &[u8], n: usize) -> Vec<u32> {
        let common = i32::from_le_bytes(bytes[..4].try_into().unwrap());
        let codes = &bytes[4..4 + (n * 2).div_ceil(8)];
        let mut v = &bytes[4 + codes.len()..];
        let mut prev = 0i32;
        (0..n)
            .map(|i| {
                let d = match (codes[i / 4] >> (2 * (i % 4))) & 3 {
                    0 => common,
                    1 => {
                        let x = v[0] as i8 as i32;
                        v = &v[1..];
                        x
                    }
                    2 => {
                        let x = i16::from_le_bytes([v[0], v[1]]) as i32;
                        v = &v[2..];
                        x
                    }
                    _ => {
                        let x = i32::from_le_bytes(v[..4].try_into().unwrap());
                        v = &v[4..];
                        x
                    }
                };
                prev = prev.wrapping_add(d);
                prev as u32
            })
            .collect()
    }

    #[test]
    fn integers_round_trip_through_the_coding() {
        let ints: Vec<u32> = vec![0, 1, 2, 3, 4, 5, 300, 301, 70_000, 5, u32::MAX, 0, (-2i32) as u32, 7, 7, 7, 8];
        for n in [1, 2, 3, 4, 5, ints.len()] {
            assert_eq!(decode_ints(&encode_ints(&ints[..n]), n), ints[..n]);
        }
        let packed = fast_compress(&encode_ints(&ints));
        assert_eq!(packed[0], 0);
        let raw = lz4_flex::block::decompress(&packed[1..], 4 + 5 + 4 * ints.len()).unwrap();
        assert_eq!(decode_ints(&raw, ints.len()), ints);
    }

    /// A reader of what [`encode`] writes, after the format's reference
    /// reader: the table of contents, the tokens, the path tree, the specs
    /// and their fields.
    struct Decoded {
        tokens: Vec<String>,
        paths: Vec<String>,
        /// (path, spec type, [(field name, value rep)]).
        specs: Vec<(String, u32, Vec<(String, u64)>)>,
    }

    fn decode(b: &[u8]) -> Decoded {
        let u64_at = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
        assert_eq!(&b[..8], b"PXR-USDC");
        assert_eq!(&b[8..11], &VERSION);
        let toc = u64_at(16) as usize;
        let sections: HashMap<String, usize> = (0..u64_at(toc) as usize)
            .map(|k| {
                let at = toc + 8 + 32 * k;
                (String::from_utf8(b[at..at + 16].iter().take_while(|&&c| c != 0).copied().collect()).unwrap(), u64_at(at + 16) as usize)
            })
            .collect();
        let lz4 = |at: usize, size: usize, max: usize| {
            assert_eq!(b[at], 0);
            lz4_flex::block::decompress(&b[at + 1..at + size], max).unwrap()
        };
        // `n` compressed integers at `*at` (their size first).
        let ints = |at: &mut usize, n: usize| {
            let size = u64_at(*at) as usize;
            let raw = lz4(*at + 8, size, 4 + n.div_ceil(4) + 4 * n);
            *at += 8 + size;
            decode_ints(&raw, n)
        };
        let t = sections["TOKENS"];
        let chars = lz4(t + 24, u64_at(t + 16) as usize, u64_at(t + 8) as usize);
        let tokens: Vec<String> = chars.split(|&c| c == 0).take(u64_at(t) as usize).map(|s| String::from_utf8(s.to_vec()).unwrap()).collect();

        let mut at = sections["PATHS"];
        let mut paths = vec![String::new(); u64_at(at) as usize];
        let n = u64_at(at + 8) as usize;
        at += 16;
        let (index, element, jump) = (ints(&mut at, n), ints(&mut at, n), ints(&mut at, n));
        // Depth first: a stack of (parent text, next entry) for siblings.
        let mut pending = vec![(String::new(), 0usize)];
        while let Some((parent, mut k)) = pending.pop() {
            let mut parent = parent;
            loop {
                let e = element[k] as i32;
                let text = if k == 0 {
                    "/".to_string()
                } else if e < 0 {
                    format!("{parent}.{}", tokens[(-e) as usize])
                } else {
                    let name = &tokens[e as usize];
                    let sep = if parent == "/" || name.starts_with(['{', '[']) || parent.ends_with('}') { "" } else { "/" };
                    format!("{parent}{sep}{name}")
                };
                paths[index[k] as usize] = text.clone();
                let j = jump[k] as i32;
                if j > 0 {
                    pending.push((parent.clone(), k + j as usize));
                }
                if j == -2 {
                    break;
                }
                if j != 0 {
                    parent = text;
                }
                k += 1;
            }
        }

        let mut at = sections["FIELDS"];
        let n = u64_at(at) as usize;
        at += 8;
        let field_tokens = ints(&mut at, n);
        let reps = lz4(at + 8, u64_at(at) as usize, 8 * n);
        let fields: Vec<(String, u64)> =
            (0..n).map(|k| (tokens[field_tokens[k] as usize].clone(), u64::from_le_bytes(reps[8 * k..8 * k + 8].try_into().unwrap()))).collect();
        let mut at = sections["FIELDSETS"];
        let n = u64_at(at) as usize;
        at += 8;
        let sets = ints(&mut at, n);
        let mut at = sections["SPECS"];
        let n = u64_at(at) as usize;
        at += 8;
        let (path, set, kind) = (ints(&mut at, n), ints(&mut at, n), ints(&mut at, n));
        let specs = (0..n)
            .map(|k| {
                let fs = sets[set[k] as usize..].iter().take_while(|&&f| f != u32::MAX).map(|&f| fields[f as usize].clone()).collect();
                (paths[path[k] as usize].clone(), kind[k], fs)
            })
            .collect();
        Decoded { tokens, paths, specs }
    }

    #[test]
    fn a_layer_decodes_to_its_specs_fields_and_arrays() {
        use crate::io::usd::{variant_layer, LevelVolume, MeshPrim, StageMetadata, VariantLayer};
        use glam::{Vec2, Vec3};
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(0.5, -2.0, 1e-3)];
        let triangles = [[0, 2, 1], [0, 1, 3]];
        let normals = [Vec3::Z; 4];
        let uvs = [Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE, Vec2::X, Vec2::Y];
        let layer = VariantLayer {
            mesh: Some(MeshPrim { positions: &positions, triangles: &triangles, normals: &normals, colours: Some(&normals), texture: Some((&uvs, "./t.png".into())) }),
            points: None,
            levels: vec![
                LevelVolume { index: 0, file: "./level_0.vdb".into(), bounds: (Vec3::ZERO, Vec3::ONE) },
                LevelVolume { index: 1, file: "./level_1.vdb".into(), bounds: (Vec3::ZERO, Vec3::ONE) },
            ],
        };
        let meta = StageMetadata { up: crate::grid::transform::Up::Z, meters_per_unit: 0.01, doc: "d".into() };
        let bytes = encode(&variant_layer(&layer, &meta));
        let d = decode(&bytes);
        let spec = |p: &str| d.specs.iter().find(|s| s.0 == p).unwrap_or_else(|| panic!("no spec {p} in {:?}", d.paths));
        // One spec per prim, property, variant set, variant and target.
        assert_eq!(spec("/").1, SpecType::PseudoRoot as u32);
        assert_eq!(spec("/variant/mesh").1, SpecType::Prim as u32);
        assert_eq!(spec("/variant/mesh.points").1, SpecType::Attribute as u32);
        assert_eq!(spec("/variant/mesh.material:binding[/variant/Looks/baked]").1, SpecType::RelationshipTarget as u32);
        assert_eq!(spec("/variant/volume{level=}").1, SpecType::VariantSet as u32);
        assert_eq!(spec("/variant/volume{level=level_1}").1, SpecType::Variant as u32);
        assert_eq!(spec("/variant/volume{level=level_1}density.filePath").1, SpecType::Attribute as u32);
        assert_eq!(spec("/variant/volume{level=level_1}.field:Cd").1, SpecType::Relationship as u32);
        assert_eq!(spec("/variant/Looks/baked.outputs:surface[/variant/Looks/baked/surface.outputs:surface]").1, SpecType::Connection as u32);
        assert_eq!(d.specs.len(), d.specs.iter().map(|s| &s.0).collect::<std::collections::HashSet<_>>().len(), "a path with two specs");
        // Values: the points array as written, the selection, the units.
        let field = |p: &str, f: &str| spec(p).2.iter().find(|x| x.0 == f).unwrap_or_else(|| panic!("{p} has no {f}")).1;
        let points = field("/variant/mesh.points", "default");
        assert_eq!(points >> 63, 1, "an array");
        assert_eq!((points >> 48) & 0xff, ty::VEC3F as u64);
        let at = (points & ((1 << 48) - 1)) as usize;
        assert_eq!(at % 8, 0, "arrays are 8-byte aligned");
        assert_eq!(u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()), 4);
        let read: Vec<f32> = bytes[at + 8..at + 8 + 48].chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(read, positions.iter().flat_map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>());
        let mpu = field("/", "metersPerUnit") & ((1 << 48) - 1);
        assert_eq!(f64::from_le_bytes(bytes[mpu as usize..mpu as usize + 8].try_into().unwrap()), 0.01);
        let kind = field("/variant", "kind");
        assert_eq!(d.tokens[(kind & 0xffff_ffff) as usize], "component");
    }

    #[test]
    fn paths_parse_and_print() {
        for text in ["/variant/Looks/baked", "/variant/Looks/baked/surface.outputs:surface", "/a"] {
            assert_eq!(Path::parse(text).text(), text);
        }
        let v = Path::parse("/variant/volume").with(Element::Variant("level".into(), "level_2".into())).child("density");
        assert_eq!(v.text(), "/variant/volume{level=level_2}density");
        assert_eq!(Path::default().text(), "/");
    }
}
