//! A minimal Mitsuba 3 XML writer: an element tree plus helpers for the plugin parameters the
//! generators use (`rgb`, `float`, `matrix`, `lookat`, ...). Only features the project's
//! importer supports (docs/method.md §2.1) are produced.

use glam::{Mat4, Vec3};
use std::fmt::Write;

/// One XML element with attributes (in insertion order) and child elements.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// Tag name, e.g. `shape`.
    pub tag: String,
    /// Attributes as (name, value) in output order.
    pub attrs: Vec<(String, String)>,
    /// Child elements.
    pub children: Vec<Element>,
}

/// Formats a float compactly but exactly enough to round-trip (shortest representation).
pub fn fmt_f32(v: f32) -> String {
    // `{}` on f32 prints the shortest string that parses back to the same value.
    let v = if v == 0.0 { 0.0 } else { v }; // no "-0"
    format!("{v}")
}

/// Formats a vector as Mitsuba's comma-separated `value`.
pub fn fmt_vec3(v: Vec3) -> String {
    format!("{}, {}, {}", fmt_f32(v.x), fmt_f32(v.y), fmt_f32(v.z))
}

impl Element {
    /// An element without attributes or children.
    pub fn new(tag: &str) -> Self {
        Self {
            tag: tag.to_owned(),
            attrs: Vec::new(),
            children: Vec::new(),
        }
    }

    /// A plugin element such as `<bsdf type="diffuse">`.
    pub fn plugin(tag: &str, kind: &str) -> Self {
        Self::new(tag).attr("type", kind)
    }

    /// Adds an attribute.
    pub fn attr(mut self, name: &str, value: impl Into<String>) -> Self {
        self.attrs.push((name.to_owned(), value.into()));
        self
    }

    /// Adds a child element.
    pub fn child(mut self, child: Element) -> Self {
        self.children.push(child);
        self
    }

    /// Adds a child element in place.
    pub fn push(&mut self, child: Element) {
        self.children.push(child);
    }

    /// Adds `<float name value>`.
    pub fn float(self, name: &str, v: f32) -> Self {
        self.child(
            Element::new("float")
                .attr("name", name)
                .attr("value", fmt_f32(v)),
        )
    }

    /// Adds `<integer name value>`.
    pub fn integer(self, name: &str, v: i64) -> Self {
        self.child(
            Element::new("integer")
                .attr("name", name)
                .attr("value", v.to_string()),
        )
    }

    /// Adds `<string name value>`.
    pub fn string(self, name: &str, v: &str) -> Self {
        self.child(Element::new("string").attr("name", name).attr("value", v))
    }

    /// Adds `<boolean name value>`.
    pub fn boolean(self, name: &str, v: bool) -> Self {
        self.child(
            Element::new("boolean")
                .attr("name", name)
                .attr("value", if v { "true" } else { "false" }),
        )
    }

    /// Adds `<rgb name value="r, g, b">`.
    pub fn rgb(self, name: &str, c: [f32; 3]) -> Self {
        self.child(
            Element::new("rgb")
                .attr("name", name)
                .attr("value", fmt_vec3(Vec3::from(c))),
        )
    }

    /// Adds `<point name x y z>`.
    pub fn point(self, name: &str, p: Vec3) -> Self {
        self.child(
            Element::new("point")
                .attr("name", name)
                .attr("x", fmt_f32(p.x))
                .attr("y", fmt_f32(p.y))
                .attr("z", fmt_f32(p.z)),
        )
    }

    /// Adds `<vector name x y z>`.
    pub fn vector(self, name: &str, v: Vec3) -> Self {
        self.child(
            Element::new("vector")
                .attr("name", name)
                .attr("x", fmt_f32(v.x))
                .attr("y", fmt_f32(v.y))
                .attr("z", fmt_f32(v.z)),
        )
    }

    /// Adds `<transform name><matrix value="16 numbers, row-major"/></transform>`.
    pub fn matrix(self, name: &str, m: Mat4) -> Self {
        let rows = m.transpose().to_cols_array(); // rows of m, row-major
        let value = rows
            .iter()
            .map(|v| fmt_f32(*v))
            .collect::<Vec<_>>()
            .join(" ");
        self.child(
            Element::new("transform")
                .attr("name", name)
                .child(Element::new("matrix").attr("value", value)),
        )
    }

    /// Adds `<transform name><lookat origin target up/></transform>`.
    pub fn lookat(self, name: &str, origin: Vec3, target: Vec3, up: Vec3) -> Self {
        self.child(
            Element::new("transform").attr("name", name).child(
                Element::new("lookat")
                    .attr("origin", fmt_vec3(origin))
                    .attr("target", fmt_vec3(target))
                    .attr("up", fmt_vec3(up)),
            ),
        )
    }

    /// Serialises with two-space indentation.
    pub fn write_to(&self, out: &mut String, depth: usize) {
        let pad = "    ".repeat(depth);
        let _ = write!(out, "{pad}<{}", self.tag);
        for (k, v) in &self.attrs {
            let _ = write!(out, " {k}=\"{}\"", escape(v));
        }
        if self.children.is_empty() {
            out.push_str("/>\n");
        } else {
            out.push_str(">\n");
            for c in &self.children {
                c.write_to(out, depth + 1);
            }
            let _ = writeln!(out, "{pad}</{}>", self.tag);
        }
    }
}

/// Escapes the XML special characters of an attribute value.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A whole scene document: `<scene version="3.0.0">` with the given children and a comment.
pub fn document(comment: &str, children: Vec<Element>) -> String {
    let mut out = String::new();
    out.push_str("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    let _ = writeln!(out, "<!-- {} -->", comment.replace("--", "-"));
    let mut scene = Element::new("scene").attr("version", "3.0.0");
    scene.children = children;
    scene.write_to(&mut out, 0);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serialises_nested_elements_with_escaping() {
        let e = Element::plugin("bsdf", "diffuse")
            .attr("id", "a<b")
            .rgb("reflectance", [0.5, 0.25, 1.0]);
        let mut s = String::new();
        e.write_to(&mut s, 0);
        assert_eq!(
            s,
            "<bsdf type=\"diffuse\" id=\"a&lt;b\">\n    <rgb name=\"reflectance\" value=\"0.5, 0.25, 1\"/>\n</bsdf>\n"
        );
    }

    #[test]
    fn matrix_is_written_row_major() {
        let m = Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0));
        let e = Element::new("x").matrix("to_world", m);
        let v = &e.children[0].children[0].attrs[0].1;
        assert_eq!(v, "1 0 0 1 0 1 0 2 0 0 1 3 0 0 0 1");
    }
}
