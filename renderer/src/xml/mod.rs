//! Mitsuba 3 XML scene importer (docs/method.md §2.1): reads a scene file into a [`SceneDescription`].
//!
//! Loading runs in two stages, like Mitsuba's own parser:
//! 1. **read** ([`read_file`]): the XML is parsed, `$name` parameters are substituted (values
//!    from `<default>` elements, overridden by the command line's `-D name=value`), and
//!    `<include>` elements are replaced by the included file's contents. The result is a tree
//!    of [`Element`]s, each remembering its file, line and column;
//! 2. **build** ([`Builder`]): plugins are instantiated in document order; `<ref id>` is
//!    resolved against every `id` in the tree (forward references work), shapes are loaded and
//!    transformed to world space, and spectra are converted to linear sRGB.
//!
//! Every problem (unknown plugin or parameter, malformed number, wrong value type, missing
//! file, dangling reference) is a [`SceneError`] naming file, line, column and element; in
//! `lenient` mode unknown plugins and parameters become warnings instead. Nothing panics.

mod bsdfs;
mod emitters;
pub mod error;
pub mod ior;
mod media;
mod props;
mod sensors;
mod shapes;
mod textures;
pub mod transform;

pub use error::{Location, SceneError};

use crate::bsdf::{Bsdf, Diffuse};
use crate::description::{CameraDesc, EmitterDesc, IntegratorDesc, SceneDescription, ShapeDesc};
use crate::parity::upgrade;
use crate::spectrum::Rgb;
use crate::texture::{Bitmap, Texture};
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Deepest allowed `<include>` nesting (guards against include cycles).
const MAX_INCLUDE_DEPTH: usize = 16;

/// Deepest allowed element nesting within one file. Real scenes nest a handful of levels
/// (scene, shape, a few BSDFs, a texture, a transform); the tree is read and built by
/// recursion, so a file nested thousands deep would overflow the stack.
const MAX_ELEMENT_DEPTH: usize = 100;

/// Elements that hold a value in their attributes and take no child elements.
const LEAF_TAGS: &[&str] = &[
    "float",
    "integer",
    "boolean",
    "string",
    "rgb",
    "spectrum",
    "point",
    "vector",
    "lookat",
    "translate",
    "rotate",
    "scale",
    "matrix",
    "ref",
    "default",
    "path",
    "alias",
];

/// One XML element after `$name` substitution and `<include>` expansion.
#[derive(Debug, Clone)]
pub(crate) struct Element {
    /// Tag name, e.g. `bsdf`, `float`.
    pub tag: String,
    /// Attributes in file order.
    pub attrs: Vec<(String, String)>,
    /// Child elements (comments and text dropped).
    pub children: Vec<Element>,
    /// Where the element starts.
    pub location: Location,
}

impl Element {
    /// The value of attribute `name`.
    pub fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    /// The element as written, reduced to its identifying attributes: `<bsdf type="diffuse" id="white">`.
    pub fn describe(&self) -> String {
        let mut s = format!("<{}", self.tag);
        for key in ["type", "name", "id"] {
            if let Some(v) = self.attr(key) {
                s.push_str(&format!(" {key}=\"{v}\""));
            }
        }
        s.push('>');
        s
    }

    /// An error about this element.
    pub fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Element {
            location: self.location.clone(),
            element: self.describe(),
            message: message.into(),
        }
    }

    /// The directory relative paths in this element are resolved against (its file's folder).
    pub fn directory(&self) -> &Path {
        self.location.file.parent().unwrap_or(Path::new(""))
    }

    /// Resolves a file name written in this element: an absolute one as it is, a relative one
    /// in the first folder of `search` that has it — for plugins the `<path>` folders (the
    /// latest first) and then the scene file's folder, as Mitsuba's file resolver — else
    /// relative to this element's own file (which Mitsuba does not try for a file named in an
    /// `<include>`d file: kept as a last resort).
    pub fn resolve_path(&self, value: &str, search: &[PathBuf]) -> PathBuf {
        let p = Path::new(value);
        if p.is_absolute() {
            return p.to_owned();
        }
        search
            .iter()
            .map(|dir| dir.join(p))
            .find(|candidate| candidate.exists())
            .unwrap_or_else(|| self.directory().join(p))
    }

    /// Checks attributes: every attribute must be in `allowed` (unknown ones are reported
    /// through `diag`), every one in `required` must be present.
    pub fn check_attributes(
        &self,
        allowed: &[&str],
        required: &[&str],
        diag: &mut Diagnostics,
    ) -> Result<(), SceneError> {
        for (k, _) in &self.attrs {
            if !allowed.contains(&k.as_str()) {
                diag.unknown(self.error(format!("unknown attribute \"{k}\"")))?;
            }
        }
        for r in required {
            if self.attr(r).is_none() {
                return Err(self.error(format!("missing attribute \"{r}\"")));
            }
        }
        Ok(())
    }
}

/// What reading a scene keeps besides its tree: warnings (and whether unknown plugins and
/// parameters are fatal), the files read, the parameters used and the `<path>` folders.
#[derive(Debug, Default)]
pub(crate) struct Diagnostics {
    /// Turn unknown plugins, parameters and attributes into warnings.
    pub lenient: bool,
    /// Non-fatal messages, each prefixed with its location.
    pub warnings: Vec<String>,
    /// Every XML file read so far (the scene file, then its includes in reading order).
    pub files_read: Vec<PathBuf>,
    /// Every parameter some `$name` has been replaced by.
    pub params_used: std::collections::HashSet<String>,
    /// Where relative file names are looked up, in order: the folders `<path>` elements named
    /// so far (the latest first), then the scene file's folder (Mitsuba's file resolver; the
    /// folder of the file naming them comes last, [`Element::resolve_path`]).
    pub search_paths: Vec<PathBuf>,
}

impl Diagnostics {
    /// Reports something unknown: an error, or in lenient mode a warning (`Ok`).
    pub fn unknown(&mut self, err: SceneError) -> Result<(), SceneError> {
        if self.lenient {
            self.warnings.push(format!("{err} (ignored: lenient mode)"));
            Ok(())
        } else {
            Err(err)
        }
    }

    /// Records a warning about `el`.
    pub fn warn(&mut self, el: &Element, message: impl std::fmt::Display) {
        self.warnings
            .push(format!("{}: {}: {message}", el.location, el.describe()));
    }
}

/// A [`load_scene`] error as a command line reports it: with the scene's name in front unless
/// the message already starts with it (`nope.xml: No such file or directory`, not `loading
/// nope.xml: nope.xml: …`); an error in an `<include>`d file keeps the scene that included it.
pub fn load_error(error: SceneError, scene: &Path) -> anyhow::Error {
    let names_scene = error.to_string().starts_with(&scene.display().to_string());
    let error = anyhow::Error::new(error);
    if names_scene {
        error
    } else {
        error.context(format!("loading {}", scene.display()))
    }
}

/// Parses one `-D NAME=VALUE` command-line override of a scene `<default>` (for [`load_scene`]).
pub fn parse_define(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() => Ok((k.trim().to_string(), v.to_string())),
        _ => Err(format!("expected NAME=VALUE, got '{s}'")),
    }
}

/// The folder of scene file `path`, where its relative file names are looked up.
fn scene_folder(path: &Path) -> PathBuf {
    path.parent().unwrap_or(Path::new("")).to_owned()
}

/// Loads a Mitsuba 3 XML scene.
///
/// `defaults` are `name=value` parameters from the command line (`-D`); they override the
/// file's `<default>` values. With `lenient`, unknown plugins, parameters and attributes are
/// skipped with a warning in [`SceneDescription::warnings`] instead of failing.
pub fn load_scene(
    path: &Path,
    defaults: &[(String, String)],
    lenient: bool,
) -> Result<SceneDescription, SceneError> {
    let mut diag = Diagnostics {
        lenient,
        search_paths: vec![scene_folder(path)],
        ..Diagnostics::default()
    };
    let mut params: HashMap<String, String> = defaults.iter().cloned().collect();
    let root = read_file(path, &mut params, 0, &mut diag)?;
    // A `-D` the scene never reads changes nothing: most likely a misspelt name (`-D rez=64`).
    for (name, value) in defaults {
        if !diag.params_used.contains(name) {
            diag.warnings.push(format!(
                "-D {name}={value}: no file of the scene uses ${name}; the define changes nothing"
            ));
        }
    }
    if root.tag != "scene" {
        return Err(root.error("the root element must be <scene>"));
    }
    root.check_attributes(&["version"], &["version"], &mut diag)?;
    let version = root.attr("version").unwrap_or_default();
    let valid_version =
        version.split('.').count() == 3 && version.split('.').all(|p| p.parse::<u32>().is_ok());
    if !valid_version {
        return Err(root.error(format!(
            "invalid version \"{version}\" (expected e.g. \"3.0.0\")"
        )));
    }
    let mut builder = Builder::new(&root, diag)?;
    builder.build_scene(&root)?;
    builder.finish(&root)
}

/// Every file the scene `path` reads with the `-D` overrides `defaults`, in document order
/// without repeats: the scene file, its `<include>`d files, and each file named by a
/// `filename` parameter or attribute (meshes, bitmaps, environment maps, spectrum files). These
/// are the files whose contents decide the image; resumable runs and datasets fingerprint them.
/// Only the XML is read: a named file that does not exist is listed, not reported (the scene's
/// load reports it with its line).
pub fn scene_files(path: &Path, defaults: &[(String, String)]) -> Result<Vec<PathBuf>, SceneError> {
    let mut diag = Diagnostics {
        lenient: true,
        search_paths: vec![scene_folder(path)],
        ..Diagnostics::default()
    };
    let mut params: HashMap<String, String> = defaults.iter().cloned().collect();
    let root = read_file(path, &mut params, 0, &mut diag)?;
    let mut files = std::mem::take(&mut diag.files_read);
    collect_named_files(&root, &diag.search_paths, &mut files);
    let mut seen = std::collections::HashSet::new();
    files.retain(|f| seen.insert(f.clone()));
    Ok(files)
}

/// Appends the files named in `el` and its descendants: `<string name="filename">` values and
/// `<spectrum filename>` attributes, resolved in `search` as the scene's load resolves them.
fn collect_named_files(el: &Element, search: &[PathBuf], out: &mut Vec<PathBuf>) {
    let named = match el.tag.as_str() {
        "string" if el.attr("name") == Some("filename") => el.attr("value"),
        "spectrum" => el.attr("filename"),
        _ => None,
    };
    if let Some(value) = named {
        out.push(el.resolve_path(value, search));
    }
    for child in &el.children {
        collect_named_files(child, search, out);
    }
}

/// Reads and parses one XML file, substituting parameters and expanding includes.
pub(crate) fn read_file(
    path: &Path,
    params: &mut HashMap<String, String>,
    depth: usize,
    diag: &mut Diagnostics,
) -> Result<Element, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|error| SceneError::Io {
        file: path.to_owned(),
        error,
    })?;
    diag.files_read.push(path.to_owned());
    let file: Arc<Path> = Arc::from(path);
    let options = roxmltree::ParsingOptions {
        allow_dtd: true,
        ..Default::default()
    };
    let doc = roxmltree::Document::parse_with_options(&text, options).map_err(|e| {
        let pos = e.pos();
        SceneError::Syntax {
            location: Location {
                file: file.clone(),
                line: pos.row,
                column: pos.col,
            },
            message: e.to_string(),
        }
    })?;
    let legacy = doc
        .root_element()
        .attribute("version")
        .is_some_and(upgrade::is_legacy);
    let mut reader = Reader {
        doc: &doc,
        file,
        params,
        depth,
        nesting: 0,
        legacy,
        diag,
    };
    let mut out = reader.convert(doc.root_element())?;
    match out.len() {
        1 => Ok(out.remove(0)),
        // The root itself was a <default> or <include>: not a scene file.
        _ => Err(SceneError::Element {
            location: Location {
                file: Arc::from(path),
                line: 1,
                column: 1,
            },
            element: format!("<{}>", doc.root_element().tag_name().name()),
            message: "not a valid root element".into(),
        }),
    }
}

/// State of reading one file.
struct Reader<'d, 'p> {
    doc: &'d roxmltree::Document<'d>,
    file: Arc<Path>,
    params: &'p mut HashMap<String, String>,
    /// `<include>` depth of this file.
    depth: usize,
    /// Ancestors of the element being converted, within this file.
    nesting: usize,
    /// The file is of a scene version before 2.0: its names are upgraded (`upgrade`).
    legacy: bool,
    diag: &'p mut Diagnostics,
}

impl Reader<'_, '_> {
    /// Converts one element; returns the elements that replace it (none for `<default>`, the
    /// included file's children for `<include>`).
    fn convert(&mut self, node: roxmltree::Node) -> Result<Vec<Element>, SceneError> {
        let pos = self.doc.text_pos_at(node.range().start);
        let location = Location {
            file: self.file.clone(),
            line: pos.row,
            column: pos.col,
        };
        let tag = node.tag_name().name().to_owned();
        let mut el = Element {
            tag,
            attrs: Vec::new(),
            children: Vec::new(),
            location,
        };
        // Attributes first unsubstituted, so that errors can describe the element.
        el.attrs = node
            .attributes()
            .map(|a| (a.name().to_owned(), a.value().to_owned()))
            .collect();
        let mut substituted = Vec::with_capacity(el.attrs.len());
        for (k, v) in &el.attrs {
            substituted.push((
                k.clone(),
                substitute(v, self.params, &mut self.diag.params_used).map_err(|m| el.error(m))?,
            ));
        }
        el.attrs = substituted;
        if self.legacy {
            upgrade::rename_parameter(&mut el);
        }

        let child_element = node.children().find(|c| c.is_element());
        // A `<spectrum type="…">` is a plugin with parameters, `<spectrum value="…">` a value.
        let leaf = LEAF_TAGS.contains(&el.tag.as_str())
            && !(el.tag == "spectrum" && el.attr("type").is_some());
        if let Some(child) = child_element.filter(|_| leaf) {
            let p = self.doc.text_pos_at(child.range().start);
            let err = SceneError::Element {
                location: Location {
                    file: self.file.clone(),
                    line: p.row,
                    column: p.col,
                },
                element: el.describe(),
                message: format!(
                    "<{}> takes no child elements, found <{}>",
                    el.tag,
                    child.tag_name().name()
                ),
            };
            self.diag.unknown(err)?;
        }
        if child_element.is_some() && self.nesting >= MAX_ELEMENT_DEPTH {
            return Err(el.error(format!(
                "elements nested deeper than {MAX_ELEMENT_DEPTH} levels"
            )));
        }

        match el.tag.as_str() {
            "default" => {
                el.check_attributes(&["name", "value"], &["name", "value"], self.diag)?;
                let name = el.attr("name").unwrap_or_default();
                if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                    return Err(el.error(format!("invalid parameter name \"{name}\"")));
                }
                // Command-line values (already present) win over the file's defaults.
                self.params
                    .entry(name.to_owned())
                    .or_insert_with(|| el.attr("value").unwrap_or_default().to_owned());
                Ok(Vec::new())
            }
            "path" => {
                // Mitsuba's `<path value>`: a folder where file names are looked up first.
                el.check_attributes(&["value"], &["value"], self.diag)?;
                if self.nesting != 1 {
                    return Err(el.error("<path> can only be a child of <scene>"));
                }
                let value = el.attr("value").unwrap_or_default();
                let mut dir = el.resolve_path(value, &[]);
                if !dir.is_dir() {
                    dir = el.resolve_path(value, &self.diag.search_paths);
                }
                if !dir.is_dir() {
                    return Err(el.error(format!("folder \"{}\" not found", dir.display())));
                }
                self.diag.search_paths.insert(0, dir);
                Ok(Vec::new())
            }
            "include" => {
                el.check_attributes(&["filename", "name"], &["filename"], self.diag)?;
                // Mitsuba: the including file's folder first, then the file resolver's.
                let filename = el.attr("filename").unwrap_or_default();
                let own = el.resolve_path(filename, &[]);
                let path = if own.is_file() {
                    own
                } else {
                    el.resolve_path(filename, &self.diag.search_paths)
                };
                if !path.is_file() {
                    return Err(el.error(format!("included file \"{}\" not found", path.display())));
                }
                if self.depth + 1 > MAX_INCLUDE_DEPTH {
                    return Err(el.error(format!(
                        "includes nested deeper than {MAX_INCLUDE_DEPTH} (an include cycle?)"
                    )));
                }
                let root = read_file(&path, self.params, self.depth + 1, self.diag)?;
                if root.tag == "scene" {
                    Ok(root.children)
                } else {
                    Ok(vec![root])
                }
            }
            _ => {
                for child in node.children() {
                    if child.is_element() {
                        self.nesting += 1;
                        let converted = self.convert(child);
                        self.nesting -= 1;
                        el.children.extend(converted?);
                    } else if child.is_text() && !child.text().unwrap_or_default().trim().is_empty()
                    {
                        let p = self.doc.text_pos_at(child.range().start);
                        let loc = Location {
                            file: self.file.clone(),
                            line: p.row,
                            column: p.col,
                        };
                        let err = SceneError::Element {
                            location: loc,
                            element: el.describe(),
                            message: "unexpected text content".into(),
                        };
                        self.diag.unknown(err)?;
                    }
                }
                if self.legacy {
                    upgrade::upgrade_plugin(&mut el)?;
                }
                Ok(vec![el])
            }
        }
    }
}

/// Replaces every `$name` in `value` by the parameter's value, noting the name in `used`; `\$`
/// is a literal `$`. A `$` not followed by a known parameter name is an error, as in Mitsuba.
fn substitute(
    value: &str,
    params: &HashMap<String, String>,
    used: &mut std::collections::HashSet<String>,
) -> Result<String, String> {
    if !value.contains('$') {
        return Ok(value.to_owned());
    }
    let mut out = String::with_capacity(value.len());
    let mut rest = value;
    while let Some(i) = rest.find('$') {
        let before = &rest[..i];
        let after = &rest[i + 1..];
        // `\$` is a literal dollar sign (Mitsuba's escape).
        if let Some(kept) = before.strip_suffix('\\') {
            out.push_str(kept);
            out.push('$');
            rest = after;
            continue;
        }
        out.push_str(before);
        let run = after
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        if run == 0 {
            return Err(format!(
                "a \"$\" must be followed by a parameter name in \"{value}\" (\\$ for a dollar sign)"
            ));
        }
        // Mitsuba replaces `$name` as a substring, longest names first: the longest parameter
        // whose name begins the run (`$spp2` with only `spp` defined is its value then "2").
        let Some(len) = (1..=run).rev().find(|&l| params.contains_key(&after[..l])) else {
            let name = &after[..run];
            return Err(format!("undefined parameter \"${name}\" (add <default name=\"{name}\" value=\"...\"/> or -D {name}=...)"));
        };
        let name = &after[..len];
        out.push_str(&params[name]);
        if !used.contains(name) {
            used.insert(name.to_owned());
        }
        rest = &after[len..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Instantiates plugins from the element tree into a [`SceneDescription`].
pub(crate) struct Builder<'a> {
    /// Warnings and the lenient flag.
    pub diag: Diagnostics,
    /// Every element with an `id`.
    ids: HashMap<String, &'a Element>,
    /// Every id some `<ref>` names.
    referenced: HashSet<String>,
    /// Already built BSDFs with an id → index into `bsdfs`.
    bsdf_ids: HashMap<String, usize>,
    /// Already built textures with an id.
    texture_ids: HashMap<String, Texture>,
    /// Already built media with an id → index into `media`.
    medium_ids: HashMap<String, u32>,
    /// Already built volumes (grids) with an id, and the boxes they cover.
    volume_ids: HashMap<String, (crate::parity::media::VolumeTexture, media::Bounds)>,
    /// Ids being built (reference cycle detection).
    building: Vec<String>,
    /// Decoded images by (path, raw).
    pub bitmaps: HashMap<(PathBuf, bool), Arc<Bitmap>>,
    /// All materials.
    pub bsdfs: Vec<Bsdf>,
    /// Indices of the default materials (diffuse 0.5; black for emitters), once needed.
    default_bsdf: [Option<usize>; 2],
    /// All shapes.
    pub shapes: Vec<ShapeDesc>,
    /// Emitters that are not area lights.
    pub emitters: Vec<EmitterDesc>,
    /// The sensor, once seen.
    pub camera: Option<CameraDesc>,
    /// Participating media.
    pub media: Vec<crate::parity::media::Medium>,
    /// The medium of the (first) sensor.
    pub camera_medium: Option<u32>,
    /// The sampler's sample count.
    pub sample_count: Option<u32>,
    /// The integrator.
    pub integrator: Option<IntegratorDesc>,
    /// While the shapes of a `shapegroup` are built for an `instance`: its `to_world` and name.
    pub instance: Option<(glam::Mat4, String)>,
    /// While a shape's BSDF and emitter are built: the shape, whose mesh attributes its
    /// `mesh_attribute` textures read.
    pub mesh_scope: Option<MeshScope<'a>>,
}

/// The shape whose BSDF and emitter are being built, for `mesh_attribute` textures.
pub(crate) struct MeshScope<'a> {
    /// The `<shape>` element (for messages).
    pub shape: &'a Element,
    /// Its mesh's attributes; `None` for analytic shapes (sphere, disk, cylinder).
    pub attributes: Option<crate::shapes::mesh_attributes::MeshAttributes>,
}

impl<'a> Builder<'a> {
    /// Indexes every `id` in the tree (duplicates are an error) and every `<alias>` (in document
    /// order, as Mitsuba), and notes the ids `<ref>`s name.
    fn new(root: &'a Element, diag: Diagnostics) -> Result<Self, SceneError> {
        let mut ids = HashMap::new();
        let mut referenced = HashSet::new();
        fn collect<'a>(
            el: &'a Element,
            ids: &mut HashMap<String, &'a Element>,
            referenced: &mut HashSet<String>,
            aliases: &mut Vec<(String, String)>,
        ) -> Result<(), SceneError> {
            if el.tag == "ref" {
                referenced.extend(el.attr("id").map(str::to_owned));
            } else if el.tag == "alias" {
                // `<alias id="a" as="b"/>`: "b" names what "a" names, from here on (Mitsuba
                // reads ids in document order, so the source must come first).
                let (Some(source), Some(alias)) = (el.attr("id"), el.attr("as")) else {
                    return Err(el.error("<alias> needs the attributes \"id\" and \"as\""));
                };
                if let Some(prev) = ids.get(alias) {
                    return Err(el.error(format!(
                        "alias \"{alias}\" already names {} at {}",
                        prev.describe(),
                        prev.location
                    )));
                }
                let Some(&target) = ids.get(source) else {
                    return Err(el.error(format!(
                        "alias source id \"{source}\" not found (before this line)"
                    )));
                };
                ids.insert(alias.to_owned(), target);
                aliases.push((
                    target.attr("id").unwrap_or_default().to_owned(),
                    alias.to_owned(),
                ));
            } else if let Some(id) = el.attr("id") {
                if let Some(prev) = ids.insert(id.to_owned(), el) {
                    return Err(el.error(format!(
                        "duplicate id \"{id}\" (first defined at {})",
                        prev.location
                    )));
                }
            }
            el.children
                .iter()
                .try_for_each(|c| collect(c, ids, referenced, aliases))
        }
        let mut aliases = Vec::new();
        collect(root, &mut ids, &mut referenced, &mut aliases)?;
        // A reference through an alias refers to the aliased element.
        for (id, alias) in aliases {
            if referenced.contains(&alias) {
                referenced.insert(id);
            }
        }
        Ok(Self {
            diag,
            ids,
            referenced,
            bsdf_ids: HashMap::new(),
            texture_ids: HashMap::new(),
            medium_ids: HashMap::new(),
            volume_ids: HashMap::new(),
            building: Vec::new(),
            bitmaps: HashMap::new(),
            bsdfs: Vec::new(),
            default_bsdf: [None; 2],
            shapes: Vec::new(),
            emitters: Vec::new(),
            camera: None,
            media: Vec::new(),
            camera_medium: None,
            sample_count: None,
            integrator: None,
            instance: None,
            mesh_scope: None,
        })
    }

    /// Whether some `<ref>` of the scene names `id`.
    pub fn is_referenced(&self, id: &str) -> bool {
        self.referenced.contains(id)
    }

    /// The element a `<ref id="…">` points to.
    pub fn resolve_ref(&mut self, r: &'a Element) -> Result<&'a Element, SceneError> {
        r.check_attributes(&["id", "name"], &["id"], &mut self.diag)?;
        let id = r.attr("id").unwrap_or_default();
        self.ids
            .get(id)
            .copied()
            .ok_or_else(|| r.error(format!("reference to unknown id \"{id}\"")))
    }

    /// Follows `el` if it is a `<ref>`, otherwise returns it.
    pub fn deref(&mut self, el: &'a Element) -> Result<&'a Element, SceneError> {
        if el.tag == "ref" {
            self.resolve_ref(el)
        } else {
            Ok(el)
        }
    }

    /// Marks `id` as under construction; errors on a reference cycle.
    fn enter(&mut self, el: &Element) -> Result<Option<String>, SceneError> {
        let Some(id) = el.attr("id") else {
            return Ok(None);
        };
        if self.building.iter().any(|b| b == id) {
            return Err(el.error(format!("reference cycle through id \"{id}\"")));
        }
        self.building.push(id.to_owned());
        Ok(Some(id.to_owned()))
    }

    fn leave(&mut self, id: Option<String>) {
        if id.is_some() {
            self.building.pop();
        }
    }

    /// Whether `el` (following references) contains a `mesh_attribute` texture: such a BSDF
    /// or texture is built anew for every shape that uses it, bound to that shape's mesh.
    fn reads_mesh_attributes(&self, el: &Element) -> bool {
        fn walk(b: &Builder, el: &Element, depth: usize) -> bool {
            // The depth bound stops reference cycles (reported when the element is built).
            if depth > 64 {
                return false;
            }
            let el = match el.tag.as_str() {
                "ref" => match el.attr("id").and_then(|id| b.ids.get(id)) {
                    Some(target) => *target,
                    None => return false,
                },
                _ => el,
            };
            (el.tag == "texture" && el.attr("type") == Some("mesh_attribute"))
                || el.children.iter().any(|c| walk(b, c, depth + 1))
        }
        walk(self, el, 0)
    }

    /// The values of mesh attribute `name` for a `mesh_attribute` texture `el`, laid out per
    /// triangle of the shape being built; an error naming the texture and the shape when that
    /// shape is not a mesh or its mesh lacks the attribute.
    pub fn bind_mesh_attribute(
        &self,
        el: &Element,
        name: &str,
    ) -> Result<Arc<crate::texture::AttributeValues>, SceneError> {
        let Some(scope) = &self.mesh_scope else {
            return Err(el.error(
                "a mesh_attribute texture can only be used by a shape's BSDF or area emitter",
            ));
        };
        let shape = format!("{} at {}", scope.shape.describe(), scope.shape.location);
        let Some(attributes) = &scope.attributes else {
            // Mitsuba 3.9.1: an error in scalar variants, silently zero in JIT variants.
            return Err(el.error(format!(
                "used by {shape}, which is not a triangle mesh: only meshes have attributes"
            )));
        };
        attributes
            .bind(name)
            .map_err(|m| el.error(format!("used by {shape}: {m}")))
    }

    /// The index in `bsdfs` of the BSDF declared by `el` (a `<bsdf>` or a `<ref>` to one);
    /// a BSDF with an id is built once, unless it reads mesh attributes (then once per shape).
    pub fn bsdf_index(&mut self, el: &'a Element) -> Result<usize, SceneError> {
        let target = self.deref(el)?;
        if target.tag != "bsdf" {
            return Err(el.error(format!(
                "expected a <bsdf>, but this refers to {}",
                target.describe()
            )));
        }
        if self.reads_mesh_attributes(target) {
            let guard = self.enter(target)?;
            let built = bsdfs::build_bsdf(self, target);
            self.leave(guard);
            self.bsdfs.push(built?);
            return Ok(self.bsdfs.len() - 1);
        }
        if let Some(id) = target.attr("id") {
            if let Some(&i) = self.bsdf_ids.get(id) {
                return Ok(i);
            }
        }
        let guard = self.enter(target)?;
        let built = bsdfs::build_bsdf(self, target);
        self.leave(guard);
        self.bsdfs.push(built?);
        let index = self.bsdfs.len() - 1;
        if let Some(id) = target.attr("id") {
            self.bsdf_ids.insert(id.to_owned(), index);
        }
        Ok(index)
    }

    /// The BSDF declared by `el` (a `<bsdf>` or a `<ref>` to one), as a value.
    pub fn bsdf_value(&mut self, el: &'a Element) -> Result<Bsdf, SceneError> {
        // An anonymous nested BSDF (e.g. inside `twosided`) is not a scene material itself.
        if el.tag == "bsdf" && el.attr("id").is_none() {
            return bsdfs::build_bsdf(self, el);
        }
        let i = self.bsdf_index(el)?;
        Ok(self.bsdfs[i].clone())
    }

    /// The default material for shapes without a BSDF, as Mitsuba 3's `Shape`: diffuse with
    /// reflectance 0.5, but 0 (black) for a shape that emits — a light without a BSDF reflects
    /// nothing.
    pub fn default_bsdf(&mut self, emits: bool) -> usize {
        let slot = usize::from(emits);
        if let Some(i) = self.default_bsdf[slot] {
            return i;
        }
        let reflectance = if emits { 0.0 } else { 0.5 };
        self.bsdfs.push(Bsdf::Diffuse(Diffuse {
            reflectance: Texture::Constant(Rgb::splat(reflectance)),
        }));
        let i = self.bsdfs.len() - 1;
        self.default_bsdf[slot] = Some(i);
        i
    }

    /// The index in `media` of the medium declared by `el` (a `<medium>` or a `<ref>` to one);
    /// a medium with an id is built once.
    pub fn medium_index(&mut self, el: &'a Element) -> Result<u32, SceneError> {
        let target = self.deref(el)?;
        if target.tag != "medium" {
            return Err(el.error(format!(
                "expected a <medium>, but this refers to {}",
                target.describe()
            )));
        }
        if let Some(&i) = target.attr("id").and_then(|id| self.medium_ids.get(id)) {
            return Ok(i);
        }
        let guard = self.enter(target)?;
        let built = media::build_medium(self, target);
        self.leave(guard);
        self.media.push(built?);
        let index = self.media.len() as u32 - 1;
        if let Some(id) = target.attr("id") {
            self.medium_ids.insert(id.to_owned(), index);
        }
        Ok(index)
    }

    /// The volume declared by `el` (a `<volume>` or a `<ref>` to one), read as `kind`; a
    /// volume with an id is built (its file read) once.
    pub fn volume_value(
        &mut self,
        el: &'a Element,
        kind: crate::spectrum::SpectrumKind,
    ) -> Result<(crate::parity::media::VolumeTexture, media::Bounds), SceneError> {
        let target = self.deref(el)?;
        if target.tag != "volume" {
            return Err(el.error(format!(
                "expected a <volume>, but this refers to {}",
                target.describe()
            )));
        }
        if let Some(v) = target.attr("id").and_then(|id| self.volume_ids.get(id)) {
            return Ok(v.clone());
        }
        let built = media::build_volume(self, target, kind)?;
        if let Some(id) = target.attr("id") {
            self.volume_ids.insert(id.to_owned(), built.clone());
        }
        Ok(built)
    }

    /// The texture declared by `el` (a `<texture>` or a `<ref>` to one); built once per id.
    pub fn texture_value(&mut self, el: &'a Element) -> Result<Texture, SceneError> {
        let target = self.deref(el)?;
        // A typed spectrum declared at the top level: Mitsuba's spectra are textures.
        let spectrum = target.tag == "spectrum" && target.attr("type").is_some();
        if !spectrum && target.tag != "texture" {
            return Err(el.error(format!(
                "expected a <texture>, but this refers to {}",
                target.describe()
            )));
        }
        let per_shape = self.reads_mesh_attributes(target);
        if let Some(t) = target.attr("id").and_then(|id| self.texture_ids.get(id)) {
            return Ok(t.clone());
        }
        let t = if spectrum {
            let Some(props::Value::Rgb(c)) = props::typed_spectrum(self, target)? else {
                return Err(el.error(format!("{} has no value to use", target.describe())));
            };
            Texture::Constant(c)
        } else {
            let guard = self.enter(target)?;
            let built = textures::build_texture(self, target);
            self.leave(guard);
            built?
        };
        if per_shape {
            return Ok(t);
        }
        if let Some(id) = target.attr("id") {
            self.texture_ids.insert(id.to_owned(), t.clone());
        }
        Ok(t)
    }

    /// Instantiates every top-level element of the scene in document order.
    fn build_scene(&mut self, root: &'a Element) -> Result<(), SceneError> {
        for el in &root.children {
            match el.tag.as_str() {
                // Reading mesh attributes: built for each shape that refers to it.
                "bsdf" | "texture" if self.reads_mesh_attributes(el) => {}
                "bsdf" => {
                    self.bsdf_index(el)?;
                }
                // A typed spectrum (Mitsuba: a texture) declared for `<ref>`s.
                "texture" | "spectrum" if el.tag == "texture" || el.attr("type").is_some() => {
                    self.texture_value(el)?;
                }
                "shape" => shapes::build_shape(self, el)?,
                "emitter" => emitters::build_emitter(self, el)?,
                // Declared for the shapes and sensors that refer to it.
                "medium" => {
                    self.medium_index(el)?;
                }
                // Declared for the media that refer to it (its file is read and checked now).
                "volume" => {
                    self.volume_value(el, crate::spectrum::SpectrumKind::Unbounded)?;
                }
                // Declared for the media that refer to it (built each time; checked now).
                "phase" => {
                    media::build_phase(self, el)?;
                }
                "sensor" => {
                    let camera = sensors::build_sensor(self, el)?;
                    if self.camera.is_some() {
                        self.diag
                            .warn(el, "more than one sensor: only the first is used");
                    } else {
                        self.camera = Some(camera);
                    }
                }
                "integrator" => self.integrator = Some(sensors::build_integrator(self, el)?),
                "film" | "sampler" | "rfilter" => sensors::build_detached(self, el)?,
                // Read with the ids (Builder::new).
                "alias" => {}
                // Mitsuba adds the referenced object to the scene once more: a shape or an
                // emitter counts twice; a BSDF or texture is a declaration either way.
                "ref" => {
                    let target = self.deref(el)?;
                    match target.tag.as_str() {
                        "shape" => shapes::build_shape(self, target)?,
                        "emitter" => emitters::build_emitter(self, target)?,
                        "bsdf" | "texture" | "spectrum" | "phase" => {}
                        "medium" => {
                            self.medium_index(target)?;
                        }
                        "volume" => {
                            self.volume_value(target, crate::spectrum::SpectrumKind::Unbounded)?;
                        }
                        _ => {
                            let err = el.error(format!(
                                "a top-level <ref> to {} is not supported (only shapes, emitters, BSDFs and textures)",
                                target.describe()
                            ));
                            self.diag.unknown(err)?;
                        }
                    }
                }
                _ => {
                    let err = el.error(format!("unexpected element <{}> in <scene>", el.tag));
                    self.diag.unknown(err)?;
                }
            }
        }
        Ok(())
    }

    /// Assembles the description; a scene without a sensor gets Mitsuba's default camera.
    fn finish(mut self, root: &Element) -> Result<SceneDescription, SceneError> {
        let camera = match self.camera.take() {
            Some(c) => c,
            None => {
                self.diag.warn(root, "no <sensor>: using a default perspective camera (fov 45°, 768x576) at the origin looking along +z");
                sensors::default_camera()
            }
        };
        Ok(SceneDescription {
            camera,
            sample_count: self.sample_count,
            integrator: self.integrator,
            bsdfs: self.bsdfs,
            shapes: self.shapes,
            emitters: self.emitters,
            warnings: self.diag.warnings,
            media: self.media,
            camera_medium: self.camera_medium,
        })
    }
}

#[cfg(test)]
mod tests;
