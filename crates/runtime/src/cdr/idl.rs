//! A [`Format`] as an OMG IDL schema (MCAP schema encoding `omgidl`), for the tools that read
//! CDR — Foxglove among them — to decode logged values without Strata.
//!
//! Every type goes into one module, `strata`, declared before it is used. Enums become unions
//! switched by the variant index (`unsigned long`), with an empty struct for variants without
//! fields, so a reader shows the variant by name. Where IDL needs a name that Rust does not
//! give (a tuple, a map entry, a sequence of sequences), a small struct holds the part: a
//! struct's bytes are its members' bytes, so the encoding does not change.

use std::collections::{HashMap, HashSet};

use super::format::{Format, Named, Variant};

/// An IDL schema: the text, and the name of the message type in it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Schema {
    /// The scoped name of the message type (`strata::WorldState`): an MCAP schema's name.
    pub name: String,
    pub text: String,
}

/// A format IDL cannot describe.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct IdlError(String);

const MODULE: &str = "strata";

/// The IDL schema of values of `format`; `type_name` (the Rust type's name) names the message
/// type when the format does not (a tuple, a number).
pub fn idl_schema(format: &Format, type_name: &str) -> Result<Schema, IdlError> {
    let mut generator = Generator::default();
    // Reserved first, so that a Rust type of that name gets another.
    generator.taken.insert("empty".to_owned());
    let root = match format {
        Format::Struct { .. } => generator.aggregate(format)?,
        _ => generator.aggregate(&Format::Struct {
            name: root_name(type_name),
            fields: vec![Named { name: "value".to_owned(), value: format.clone() }],
        })?,
    };
    let mut text = format!("module {MODULE} {{\n");
    if generator.empty {
        text.push_str("struct Empty {};\n");
    }
    for decl in &generator.decls {
        text.push_str(decl);
    }
    text.push_str("};\n");
    Ok(Schema { name: format!("{MODULE}::{root}"), text })
}

/// The last path segment of a Rust type name, without generics: `a::b::Pose<c::D>` -> `Pose`.
fn root_name(type_name: &str) -> String {
    let plain = type_name.split('<').next().unwrap_or(type_name);
    let last = plain.rsplit("::").next().unwrap_or(plain);
    let name = identifier(last);
    if name.trim_start_matches('_').is_empty() { "Message".to_owned() } else { name }
}

#[derive(Default)]
struct Generator {
    /// Declarations, each after the ones it uses.
    decls: Vec<String>,
    /// The type already declared for an aggregate format.
    declared: HashMap<Format, String>,
    /// Type names in use, lowercased: IDL names that differ only in case collide.
    taken: HashSet<String>,
    /// Whether `Empty` is used.
    empty: bool,
}

impl Generator {
    fn unique(&mut self, name: &str) -> String {
        let base = identifier(name);
        let mut candidate = base.clone();
        let mut k = 2;
        while !self.taken.insert(candidate.to_lowercase()) {
            candidate = format!("{base}_{k}");
            k += 1;
        }
        candidate
    }

    /// The type of a member holding `format`, and the dimensions of its declarator.
    fn member(&mut self, format: &Format) -> Result<(String, Vec<usize>), IdlError> {
        let primitive = |name: &str| Ok((name.to_owned(), Vec::new()));
        match format {
            Format::Unit | Format::UnitStruct { .. } => {
                self.empty = true;
                primitive("Empty")
            }
            Format::Bool => primitive("boolean"),
            Format::I8 => primitive("int8"),
            Format::I16 => primitive("short"),
            Format::I32 => primitive("long"),
            Format::I64 => primitive("long long"),
            Format::U8 => primitive("octet"),
            Format::U16 => primitive("unsigned short"),
            Format::U32 | Format::Char => primitive("unsigned long"),
            Format::U64 => primitive("unsigned long long"),
            Format::F32 => primitive("float"),
            Format::F64 => primitive("double"),
            Format::Str => primitive("string"),
            Format::Bytes => primitive("sequence<octet>"),
            Format::Option(inner) => Ok((format!("sequence<{}, 1>", self.element(inner)?), vec![])),
            Format::Seq(inner) => Ok((format!("sequence<{}>", self.element(inner)?), vec![])),
            Format::Map { key, value } => {
                let entry = Format::Struct {
                    name: "Entry".to_owned(),
                    fields: vec![
                        Named { name: "key".to_owned(), value: (**key).clone() },
                        Named { name: "value".to_owned(), value: (**value).clone() },
                    ],
                };
                Ok((format!("sequence<{}>", self.aggregate(&entry)?), vec![]))
            }
            Format::Array { element, len } => {
                // IDL arrays of sequences do not parse everywhere: such elements get a struct.
                let (base, mut dims) = match **element {
                    Format::Option(_) | Format::Seq(_) | Format::Map { .. } | Format::Bytes => {
                        (self.wrapped(element)?, Vec::new())
                    }
                    _ => self.member(element)?,
                };
                dims.insert(0, *len);
                Ok((base, dims))
            }
            Format::Newtype { inner, .. } => self.member(inner),
            Format::Tuple(_)
            | Format::TupleStruct { .. }
            | Format::Struct { .. }
            | Format::Enum { .. } => Ok((self.aggregate(format)?, Vec::new())),
        }
    }

    /// A type that can stand inside `sequence<...>`: no dimensions, no sequence (readers do
    /// not take sequences of sequences or of arrays), so those are held by a struct.
    fn element(&mut self, format: &Format) -> Result<String, IdlError> {
        let mut inner = format;
        while let Format::Newtype { inner: wrapped, .. } = inner {
            inner = wrapped;
        }
        match inner {
            Format::Option(_)
            | Format::Seq(_)
            | Format::Map { .. }
            | Format::Bytes
            | Format::Array { .. } => self.wrapped(inner),
            _ => Ok(self.member(inner)?.0),
        }
    }

    /// A struct with one member, `value`, holding `format`.
    fn wrapped(&mut self, format: &Format) -> Result<String, IdlError> {
        self.aggregate(&Format::Struct {
            name: "Element".to_owned(),
            fields: vec![Named { name: "value".to_owned(), value: format.clone() }],
        })
    }

    /// Declares a struct or union for `format` (once) and returns its name.
    fn aggregate(&mut self, format: &Format) -> Result<String, IdlError> {
        if let Some(name) = self.declared.get(format) {
            return Ok(name.clone());
        }
        let positional = |elements: &[Format]| {
            elements
                .iter()
                .enumerate()
                .map(|(i, f)| Named { name: format!("_{i}"), value: f.clone() })
                .collect::<Vec<_>>()
        };
        let (name, body) = match format {
            Format::Struct { name, fields } => (name.clone(), self.struct_body(fields)?),
            Format::TupleStruct { name, elements } => {
                (name.clone(), self.struct_body(&positional(elements))?)
            }
            Format::Tuple(elements) => {
                ("Tuple".to_owned(), self.struct_body(&positional(elements))?)
            }
            Format::Enum { name, variants } => (name.clone(), self.union_body(name, variants)?),
            other => return Err(IdlError(format!("no IDL aggregate for {other:?}"))),
        };
        let name = self.unique(&name);
        let keyword = if matches!(format, Format::Enum { .. }) { "union" } else { "struct" };
        let switch = if keyword == "union" { " switch (unsigned long)" } else { "" };
        self.decls.push(format!("{keyword} {name}{switch} {{\n{body}}};\n"));
        self.declared.insert(format.clone(), name.clone());
        Ok(name)
    }

    fn struct_body(&mut self, fields: &[Named<Format>]) -> Result<String, IdlError> {
        let mut body = String::new();
        let mut names = HashSet::new();
        for field in fields {
            let (ty, dims) = self.member(&field.value)?;
            let name = distinct(&mut names, &field.name);
            body.push_str(&format!("  {ty} {name}{};\n", dimensions(&dims)));
        }
        Ok(body)
    }

    fn union_body(&mut self, name: &str, variants: &[Named<Variant>]) -> Result<String, IdlError> {
        if variants.is_empty() {
            return Err(IdlError(format!("enum {name} has no variants")));
        }
        let mut body = String::new();
        let mut names = HashSet::new();
        for (index, variant) in variants.iter().enumerate() {
            let (ty, dims) = match &variant.value {
                Variant::Unit => self.member(&Format::Unit)?,
                Variant::Newtype(inner) => self.member(inner)?,
                Variant::Tuple(elements) => {
                    let fields = elements
                        .iter()
                        .enumerate()
                        .map(|(i, f)| Named { name: format!("_{i}"), value: f.clone() })
                        .collect();
                    let holder =
                        Format::Struct { name: format!("{name}_{}", variant.name), fields };
                    (self.aggregate(&holder)?, Vec::new())
                }
                Variant::Struct(fields) => {
                    let holder = Format::Struct {
                        name: format!("{name}_{}", variant.name),
                        fields: fields.clone(),
                    };
                    (self.aggregate(&holder)?, Vec::new())
                }
            };
            let member = distinct(&mut names, &variant.name);
            body.push_str(&format!("  case {index}: {ty} {member}{};\n", dimensions(&dims)));
        }
        Ok(body)
    }
}

fn dimensions(dims: &[usize]) -> String {
    dims.iter().map(|d| format!("[{d}]")).collect()
}

/// `name` as an identifier not yet in `names` (compared without case, as IDL does).
fn distinct(names: &mut HashSet<String>, name: &str) -> String {
    let base = identifier(name);
    let mut candidate = base.clone();
    let mut k = 2;
    while !names.insert(candidate.to_lowercase()) {
        candidate = format!("{base}_{k}");
        k += 1;
    }
    candidate
}

/// IDL's reserved words (IDL 4.2, 7.2.4; compared without case).
const KEYWORDS: &[&str] = &[
    "abstract",
    "any",
    "alias",
    "attribute",
    "bitfield",
    "bitmask",
    "bitset",
    "boolean",
    "case",
    "char",
    "component",
    "connector",
    "const",
    "consumes",
    "context",
    "custom",
    "default",
    "double",
    "emits",
    "enum",
    "eventtype",
    "exception",
    "factory",
    "false",
    "finder",
    "fixed",
    "float",
    "getraises",
    "getter",
    "home",
    "import",
    "in",
    "inout",
    "interface",
    "local",
    "long",
    "manages",
    "map",
    "mirrorport",
    "module",
    "multiple",
    "native",
    "object",
    "octet",
    "oneway",
    "out",
    "primarykey",
    "private",
    "port",
    "porttype",
    "provides",
    "public",
    "publishes",
    "raises",
    "readonly",
    "setraises",
    "setter",
    "sequence",
    "short",
    "string",
    "struct",
    "supports",
    "switch",
    "true",
    "truncatable",
    "typedef",
    "typeid",
    "typename",
    "typeprefix",
    "unsigned",
    "union",
    "uses",
    "valuebase",
    "valuetype",
    "void",
    "wchar",
    "wstring",
    "int8",
    "uint8",
    "int16",
    "int32",
    "int64",
    "uint16",
    "uint32",
    "uint64",
];

/// `name` as an IDL identifier: letters, digits and underscores, not starting with a digit;
/// a reserved word gets IDL's escape, a leading underscore.
fn identifier(name: &str) -> String {
    let mut out: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
    if out.is_empty() || out.starts_with(|c: char| c.is_ascii_digit()) {
        out.insert(0, '_');
    }
    if KEYWORDS.iter().any(|k| k.eq_ignore_ascii_case(&out)) {
        out.insert(0, '_');
    }
    out
}
