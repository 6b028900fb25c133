//! A [`Layer`] as USD text (`.usda`), to the USD 1.0 text grammar: every
//! name an identifier, every float a finite decimal (Rust's shortest
//! round-trip form), every asset path between `@` (or `@@@` where it holds
//! an `@`).

use std::fmt::Write as _;

use glam::Vec3;
use rayon::prelude::*;

use super::layer::{Attribute, Body, Layer, Metadata, Prim, Property, Value};

/// The layer's text.
pub fn encode(layer: &Layer) -> String {
    let mut s = format!(
        "#usda 1.0\n(\n    defaultPrim = {}\n    doc = {}\n    metersPerUnit = {}\n    upAxis = {}\n)\n\n",
        quoted(&layer.default_prim),
        quoted(&layer.doc),
        layer.meters_per_unit,
        quoted(layer.up_axis),
    );
    for prim in &layer.prims {
        write_prim(&mut s, prim, 0);
    }
    s
}

fn indent(s: &mut String, depth: usize) {
    s.extend(std::iter::repeat_n("    ", depth));
}

fn write_prim(s: &mut String, prim: &Prim, depth: usize) {
    indent(s, depth);
    let _ = write!(s, "def {} {}", prim.type_name, quoted(&prim.name));
    write_metadata(s, &prim.body, depth);
    s.push('\n');
    indent(s, depth);
    s.push_str("{\n");
    write_body(s, &prim.body, depth + 1);
    indent(s, depth);
    s.push_str("}\n\n");
}

/// ` (\n    key = value\n)` after a prim's or a variant's name, nothing where
/// it has no metadata.
fn write_metadata(s: &mut String, body: &Body, depth: usize) {
    let Metadata { kind, api_schemas, asset_name, variant_selection, references } = &body.meta;
    let mut lines = Vec::new();
    if let Some(name) = asset_name {
        lines.push(format!("assetInfo = {{\n{i}    string name = {}\n{i}}}", quoted(name), i = "    ".repeat(depth + 1)));
    }
    if let Some(kind) = kind {
        lines.push(format!("kind = {}", quoted(kind)));
    }
    if !api_schemas.is_empty() {
        // apiSchemas takes no bare value in USD's grammar (references and
        // variantSets do): always a list.
        let names: Vec<String> = api_schemas.iter().map(|a| quoted(a)).collect();
        lines.push(format!("prepend apiSchemas = [{}]", names.join(", ")));
    }
    if !references.is_empty() {
        lines.push(format!("prepend references = {}", list(references.iter().map(|r| asset(r)))));
    }
    if !variant_selection.is_empty() {
        let mut v = String::from("variants = {\n");
        for (set, choice) in variant_selection {
            let _ = writeln!(v, "{}    string {set} = {}", "    ".repeat(depth + 1), quoted(choice));
        }
        let _ = write!(v, "{}}}", "    ".repeat(depth + 1));
        lines.push(v);
    }
    if !body.variant_sets.is_empty() {
        lines.push(format!("prepend variantSets = {}", list(body.variant_sets.iter().map(|v| quoted(&v.name)))));
    }
    if lines.is_empty() {
        return;
    }
    s.push_str(" (\n");
    for line in lines {
        indent(s, depth + 1);
        s.push_str(&line);
        s.push('\n');
    }
    indent(s, depth);
    s.push(')');
}

/// `"a"` for one item, `["a", "b"]` for more (where the field allows a bare value).
fn list(items: impl Iterator<Item = String>) -> String {
    let items: Vec<String> = items.collect();
    if items.len() == 1 {
        items.into_iter().next().unwrap_or_default()
    } else {
        format!("[{}]", items.join(", "))
    }
}

fn write_body(s: &mut String, body: &Body, depth: usize) {
    for p in &body.properties {
        write_property(s, p, depth);
    }
    if !body.properties.is_empty() && (!body.children.is_empty() || !body.variant_sets.is_empty()) {
        s.push('\n');
    }
    for child in &body.children {
        write_prim(s, child, depth);
    }
    for set in &body.variant_sets {
        indent(s, depth);
        let _ = writeln!(s, "variantSet {} = {{", quoted(&set.name));
        for (name, variant) in &set.variants {
            indent(s, depth + 1);
            s.push_str(&quoted(name));
            write_metadata(s, variant, depth + 1);
            s.push_str(" {\n");
            write_body(s, variant, depth + 2);
            indent(s, depth + 1);
            s.push_str("}\n");
        }
        indent(s, depth);
        s.push_str("}\n");
    }
}

fn write_property(s: &mut String, p: &Property, depth: usize) {
    match p {
        Property::Relationship { name, target } => {
            indent(s, depth);
            let _ = writeln!(s, "rel {name} = <{target}>");
        }
        Property::Attribute(a) => write_attribute(s, a, depth),
    }
}

fn write_attribute(s: &mut String, a: &Attribute, depth: usize) {
    let declaration = format!("{}{} {}", if a.uniform { "uniform " } else { "" }, a.type_name, a.name);
    if a.value.is_some() || a.connection.is_none() {
        indent(s, depth);
        s.push_str(&declaration);
        if let Some(v) = &a.value {
            s.push_str(" = ");
            s.push_str(&value(v));
        }
        if let Some(i) = a.interpolation {
            s.push_str(" (\n");
            indent(s, depth + 1);
            let _ = writeln!(s, "interpolation = {}", quoted(i));
            indent(s, depth);
            s.push(')');
        }
        s.push('\n');
    }
    if let Some(target) = &a.connection {
        indent(s, depth);
        let _ = writeln!(s, "{declaration}.connect = <{target}>");
    }
}

fn value(v: &Value) -> String {
    match v {
        Value::Token(t) => quoted(t),
        Value::String(t) => quoted(t),
        Value::Asset(p) => asset(p),
        Value::Float(x) => num(*x),
        Value::Ints(v) => array(v, |i| i.to_string()),
        Value::Floats(v) => array(v, |&x| num(x)),
        Value::Vec2s(v) => array(v, |uv| format!("({}, {})", num(uv.x), num(uv.y))),
        Value::Vec3s(v) => array(v, |&p| tuple3(p)),
    }
}

/// A string as a USD string literal (quotes, backslashes and control
/// characters escaped; the rest UTF-8 as it is).
pub(super) fn quoted(s: &str) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_arrays_break_lines_and_keep_every_item() {
        let v: Vec<u32> = (0..20_000).collect();
        let text = array(&v, |i| i.to_string());
        let items: Vec<u32> = text.trim_matches(|c| c == '[' || c == ']').split(',').map(|s| s.trim().parse().unwrap()).collect();
        assert_eq!(items, v);
        assert_eq!(num(f32::NAN), "0");
    }
}
