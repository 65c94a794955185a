//! What a CDR value's bytes mean: the [`Format`] of a type, traced from its `Deserialize`
//! implementation.
//!
//! A value does not show every shape its type can take (an enum shows one variant, an
//! `Option` may be empty), so the format is not inferred from values: [`trace`] runs the
//! type's own `Deserialize` against a deserializer that records every request it makes —
//! "a struct with these fields", "an enum with these variants", "a `u64`" — answering each
//! with a placeholder. An enum is answered with one variant at a time, and the type is read
//! again until every variant of every enum was seen. Every shape serde can describe without
//! looking at the data is found this way; a type that must look at the data
//! (`deserialize_any`: untagged or internally tagged enums, flattened fields) cannot be traced.

use serde::de::{self, DeserializeOwned, DeserializeSeed, IntoDeserializer, Visitor};
use serde::{Deserialize, Serialize};

/// A field, a variant: a name and what it holds.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Named<T> {
    pub name: String,
    pub value: T,
}

/// The shape of a value in serde's data model, which is also the layout of its CDR bytes.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    Unit,
    Bool,
    I8,
    I16,
    I32,
    I64,
    U8,
    U16,
    U32,
    U64,
    F32,
    F64,
    Char,
    Str,
    Bytes,
    Option(Box<Format>),
    Seq(Box<Format>),
    Map {
        key: Box<Format>,
        value: Box<Format>,
    },
    /// A fixed number of values of different formats.
    Tuple(Vec<Format>),
    /// A fixed number of values of one format (a Rust array, a matrix).
    Array {
        element: Box<Format>,
        len: usize,
    },
    Struct {
        name: String,
        fields: Vec<Named<Format>>,
    },
    TupleStruct {
        name: String,
        elements: Vec<Format>,
    },
    /// A struct with one unnamed field: written as that field.
    Newtype {
        name: String,
        inner: Box<Format>,
    },
    UnitStruct {
        name: String,
    },
    /// Variants in declaration order: the index written in front of the fields.
    Enum {
        name: String,
        variants: Vec<Named<Variant>>,
    },
}

/// What an enum variant holds.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Variant {
    Unit,
    Newtype(Format),
    Tuple(Vec<Format>),
    Struct(Vec<Named<Format>>),
}

/// Why a type could not be traced.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct TraceError(String);

impl de::Error for TraceError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        TraceError(msg.to_string())
    }
}

/// How deep formats may nest: a type that nests deeper is taken for a recursive one, which a
/// CDR schema cannot describe.
const MAX_DEPTH: usize = 64;
/// Reads of the type while enums still have unseen variants: each read sees at least one new
/// variant, so this bounds the number of variants, not the size of the type.
const MAX_PASSES: usize = 4096;

thread_local! {
    static TRACING: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Whether a trace is running on this thread: a `Deserialize` implementation that looks
/// values up elsewhere (a [`crate::Shared`] reference) answers with a [`placeholder`] instead,
/// since the trace reads placeholders, not data.
pub fn is_tracing() -> bool {
    TRACING.with(|t| t.get() > 0)
}

/// The format of `T`'s values, from its `Deserialize` implementation.
pub fn trace<T: DeserializeOwned>() -> Result<Format, TraceError> {
    TRACING.with(|t| t.set(t.get() + 1));
    let result = trace_passes::<T>();
    TRACING.with(|t| t.set(t.get() - 1));
    result
}

fn trace_passes<T: DeserializeOwned>() -> Result<Format, TraceError> {
    let mut root = Node::Unknown;
    for _ in 0..MAX_PASSES {
        T::deserialize(Tracer { node: &mut root, depth: 0 })?;
        if root.complete() {
            return root.into_format();
        }
    }
    Err(TraceError(format!("more than {MAX_PASSES} enum variants")))
}

/// A value of `T` made of placeholders (zeros, empty texts and sequences, first variants), as
/// a trace reads it.
pub fn placeholder<T: DeserializeOwned>() -> Result<T, TraceError> {
    T::deserialize(Tracer { node: &mut Node::Unknown, depth: 0 })
}

/// [`trace`], remembered per type for the life of the process (a log traces each package
/// type once, whatever the number of channels that carry it).
pub fn format_of<T: DeserializeOwned + 'static>() -> Result<Format, TraceError> {
    use std::any::TypeId;
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock, PoisonError};
    type Cache = Mutex<HashMap<TypeId, Result<Format, TraceError>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(known) =
        cache.lock().unwrap_or_else(PoisonError::into_inner).get(&TypeId::of::<T>())
    {
        return known.clone();
    }
    let traced = trace::<T>();
    cache.lock().unwrap_or_else(PoisonError::into_inner).insert(TypeId::of::<T>(), traced.clone());
    traced
}

/// A format while it is being traced: parts not reached yet are `Unknown`, enum variants not
/// chosen yet are `None`.
#[derive(Debug)]
enum Node {
    Unknown,
    Leaf(Format),
    Option(Box<Node>),
    Seq(Box<Node>),
    Map(Box<Node>, Box<Node>),
    Tuple(Vec<Node>),
    Struct { name: &'static str, fields: Vec<(&'static str, Node)> },
    TupleStruct { name: &'static str, elements: Vec<Node> },
    Newtype { name: &'static str, inner: Box<Node> },
    UnitStruct { name: &'static str },
    Enum { name: &'static str, variants: Vec<(&'static str, Option<VariantNode>)> },
}

#[derive(Debug)]
enum VariantNode {
    Unit,
    Newtype(Node),
    Tuple(Vec<Node>),
    Struct(Vec<(&'static str, Node)>),
}

impl VariantNode {
    fn complete(&self) -> bool {
        match self {
            VariantNode::Unit => true,
            VariantNode::Newtype(node) => node.complete(),
            VariantNode::Tuple(nodes) => nodes.iter().all(Node::complete),
            VariantNode::Struct(fields) => fields.iter().all(|(_, n)| n.complete()),
        }
    }
}

impl Node {
    fn complete(&self) -> bool {
        match self {
            Node::Unknown => false,
            Node::Leaf(_) | Node::UnitStruct { .. } => true,
            Node::Option(inner) | Node::Seq(inner) | Node::Newtype { inner, .. } => {
                inner.complete()
            }
            Node::Map(key, value) => key.complete() && value.complete(),
            Node::Tuple(elements) | Node::TupleStruct { elements, .. } => {
                elements.iter().all(Node::complete)
            }
            Node::Struct { fields, .. } => fields.iter().all(|(_, n)| n.complete()),
            Node::Enum { variants, .. } => {
                variants.iter().all(|(_, v)| v.as_ref().is_some_and(VariantNode::complete))
            }
        }
    }

    fn into_format(self) -> Result<Format, TraceError> {
        let fields = |fields: Vec<(&'static str, Node)>| {
            fields
                .into_iter()
                .map(|(name, node)| Ok(Named { name: name.to_owned(), value: node.into_format()? }))
                .collect::<Result<Vec<_>, TraceError>>()
        };
        let elements = |nodes: Vec<Node>| {
            nodes.into_iter().map(Node::into_format).collect::<Result<Vec<_>, TraceError>>()
        };
        Ok(match self {
            Node::Unknown => return Err(TraceError("a part of the type was never read".into())),
            Node::Leaf(format) => format,
            Node::Option(inner) => Format::Option(Box::new(inner.into_format()?)),
            Node::Seq(inner) => Format::Seq(Box::new(inner.into_format()?)),
            Node::Map(key, value) => Format::Map {
                key: Box::new(key.into_format()?),
                value: Box::new(value.into_format()?),
            },
            Node::Tuple(nodes) => {
                let formats = elements(nodes)?;
                match formats.first() {
                    Some(first) if formats.iter().all(|f| f == first) => {
                        Format::Array { element: Box::new(first.clone()), len: formats.len() }
                    }
                    _ => Format::Tuple(formats),
                }
            }
            Node::Struct { name, fields: f } => {
                Format::Struct { name: name.to_owned(), fields: fields(f)? }
            }
            Node::TupleStruct { name, elements: e } => {
                Format::TupleStruct { name: name.to_owned(), elements: elements(e)? }
            }
            Node::Newtype { name, inner } => {
                Format::Newtype { name: name.to_owned(), inner: Box::new(inner.into_format()?) }
            }
            Node::UnitStruct { name } => Format::UnitStruct { name: name.to_owned() },
            Node::Enum { name, variants } => Format::Enum {
                name: name.to_owned(),
                variants: variants
                    .into_iter()
                    .map(|(variant, node)| {
                        let value = match node {
                            None => return Err(TraceError(format!("{name}::{variant} unseen"))),
                            Some(VariantNode::Unit) => Variant::Unit,
                            Some(VariantNode::Newtype(node)) => {
                                Variant::Newtype(node.into_format()?)
                            }
                            Some(VariantNode::Tuple(nodes)) => Variant::Tuple(elements(nodes)?),
                            Some(VariantNode::Struct(f)) => Variant::Struct(fields(f)?),
                        };
                        Ok(Named { name: variant.to_owned(), value })
                    })
                    .collect::<Result<_, TraceError>>()?,
            },
        })
    }
}

/// A deserializer that records what it is asked for into `node`.
struct Tracer<'n> {
    node: &'n mut Node,
    depth: usize,
}

impl<'n> Tracer<'n> {
    /// Records a leaf format, checking it agrees with what an earlier read recorded.
    fn leaf(self, format: Format) -> Result<(), TraceError> {
        match self.node {
            Node::Unknown => {
                *self.node = Node::Leaf(format);
                Ok(())
            }
            Node::Leaf(known) if *known == format => Ok(()),
            other => Err(mismatch(other, &format!("{format:?}"))),
        }
    }
}

fn mismatch(known: &Node, now: &str) -> TraceError {
    TraceError(format!("the type read {known:?} once and {now} another time"))
}

macro_rules! trace_primitive {
    ($method:ident, $format:expr, $visit:ident, $value:expr) => {
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, TraceError> {
            self.leaf($format)?;
            visitor.$visit($value)
        }
    };
}

impl<'de, 'n> de::Deserializer<'de> for Tracer<'n> {
    type Error = TraceError;

    fn is_human_readable(&self) -> bool {
        false
    }

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, TraceError> {
        Err(TraceError(
            "the type reads itself through deserialize_any (an untagged or internally tagged \
             enum, or flattened fields): its layout depends on the data"
                .into(),
        ))
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, TraceError> {
        Err(TraceError("the type skips a value it does not know".into()))
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, _: V) -> Result<V::Value, TraceError> {
        Err(TraceError("the type reads field names".into()))
    }

    trace_primitive!(deserialize_bool, Format::Bool, visit_bool, false);
    trace_primitive!(deserialize_i8, Format::I8, visit_i8, 0);
    trace_primitive!(deserialize_i16, Format::I16, visit_i16, 0);
    trace_primitive!(deserialize_i32, Format::I32, visit_i32, 0);
    trace_primitive!(deserialize_i64, Format::I64, visit_i64, 0);
    trace_primitive!(deserialize_u8, Format::U8, visit_u8, 0);
    trace_primitive!(deserialize_u16, Format::U16, visit_u16, 0);
    trace_primitive!(deserialize_u32, Format::U32, visit_u32, 0);
    trace_primitive!(deserialize_u64, Format::U64, visit_u64, 0);
    trace_primitive!(deserialize_f32, Format::F32, visit_f32, 0.0);
    trace_primitive!(deserialize_f64, Format::F64, visit_f64, 0.0);
    trace_primitive!(deserialize_char, Format::Char, visit_char, '\0');
    trace_primitive!(deserialize_str, Format::Str, visit_str, "");
    trace_primitive!(deserialize_string, Format::Str, visit_str, "");
    trace_primitive!(deserialize_bytes, Format::Bytes, visit_bytes, &[]);
    trace_primitive!(deserialize_byte_buf, Format::Bytes, visit_bytes, &[]);

    fn deserialize_unit<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, TraceError> {
        self.leaf(Format::Unit)?;
        visitor.visit_unit()
    }

    fn deserialize_i128<V: Visitor<'de>>(self, _: V) -> Result<V::Value, TraceError> {
        Err(TraceError("128-bit integers have no CDR type".into()))
    }

    fn deserialize_u128<V: Visitor<'de>>(self, _: V) -> Result<V::Value, TraceError> {
        Err(TraceError("128-bit integers have no CDR type".into()))
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node = Node::Option(Box::new(Node::Unknown));
        }
        let Node::Option(inner) = self.node else { return Err(mismatch(self.node, "an option")) };
        let depth = self.depth;
        visitor.visit_some(nested(inner, depth)?)
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        match self.node {
            Node::Unknown => *self.node = Node::UnitStruct { name },
            Node::UnitStruct { .. } => {}
            other => return Err(mismatch(other, "a unit struct")),
        }
        visitor.visit_unit()
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node = Node::Newtype { name, inner: Box::new(Node::Unknown) };
        }
        let depth = self.depth;
        let Node::Newtype { inner, .. } = self.node else {
            return Err(mismatch(self.node, "a newtype struct"));
        };
        visitor.visit_newtype_struct(nested(inner, depth)?)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node = Node::Seq(Box::new(Node::Unknown));
        }
        let depth = self.depth;
        let Node::Seq(inner) = self.node else { return Err(mismatch(self.node, "a sequence")) };
        visitor.visit_seq(Elements { nodes: std::slice::from_mut(&mut **inner).iter_mut(), depth })
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node = Node::Tuple((0..len).map(|_| Node::Unknown).collect());
        }
        let depth = self.depth;
        match self.node {
            Node::Tuple(nodes) if nodes.len() == len => {
                visitor.visit_seq(Elements { nodes: nodes.iter_mut(), depth })
            }
            other => Err(mismatch(other, &format!("a tuple of {len}"))),
        }
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node =
                Node::TupleStruct { name, elements: (0..len).map(|_| Node::Unknown).collect() };
        }
        let depth = self.depth;
        match self.node {
            Node::TupleStruct { elements, .. } if elements.len() == len => {
                visitor.visit_seq(Elements { nodes: elements.iter_mut(), depth })
            }
            other => Err(mismatch(other, &format!("a tuple struct of {len}"))),
        }
    }

    fn deserialize_map<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node = Node::Map(Box::new(Node::Unknown), Box::new(Node::Unknown));
        }
        let depth = self.depth;
        let Node::Map(key, value) = self.node else { return Err(mismatch(self.node, "a map")) };
        visitor.visit_map(OneEntry { key: Some(key), value: Some(value), depth })
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node =
                Node::Struct { name, fields: fields.iter().map(|f| (*f, Node::Unknown)).collect() };
        }
        let depth = self.depth;
        match self.node {
            Node::Struct { fields: known, .. } if known.len() == fields.len() => {
                visitor.visit_seq(Elements {
                    nodes: known.iter_mut().map(|(_, n)| n).collect::<Vec<_>>().into_iter(),
                    depth,
                })
            }
            other => Err(mismatch(other, &format!("struct {name}"))),
        }
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if let Node::Unknown = self.node {
            *self.node =
                Node::Enum { name, variants: variants.iter().map(|v| (*v, None)).collect() };
        }
        let depth = self.depth;
        let Node::Enum { variants: known, .. } = self.node else {
            return Err(mismatch(self.node, &format!("enum {name}")));
        };
        if known.is_empty() {
            return Err(TraceError(format!("enum {name} has no variants")));
        }
        // A variant not seen yet, or one with unseen parts; once all are complete, any.
        let choice = known
            .iter()
            .position(|(_, v)| !v.as_ref().is_some_and(VariantNode::complete))
            .unwrap_or(0);
        visitor.visit_enum(Choice { slot: &mut known[choice].1, index: choice, depth })
    }
}

/// A tracer for a part of a format at `depth` (its parent's depth): one level deeper.
fn nested(node: &mut Node, depth: usize) -> Result<Tracer<'_>, TraceError> {
    if depth >= MAX_DEPTH {
        return Err(TraceError(format!(
            "formats nested deeper than {MAX_DEPTH} levels (a recursive type?)"
        )));
    }
    Ok(Tracer { node, depth: depth + 1 })
}

/// The elements of a sequence (one), tuple or struct, each traced into its node.
struct Elements<I> {
    nodes: I,
    depth: usize,
}

impl<'de, 'n, I: Iterator<Item = &'n mut Node>> de::SeqAccess<'de> for Elements<I> {
    type Error = TraceError;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, TraceError> {
        match self.nodes.next() {
            Some(node) => seed.deserialize(nested(node, self.depth)?).map(Some),
            None => Ok(None),
        }
    }
}

/// A map of one entry.
struct OneEntry<'n> {
    key: Option<&'n mut Node>,
    value: Option<&'n mut Node>,
    depth: usize,
}

impl<'de> de::MapAccess<'de> for OneEntry<'_> {
    type Error = TraceError;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, TraceError> {
        match self.key.take() {
            Some(node) => seed.deserialize(nested(node, self.depth)?).map(Some),
            None => Ok(None),
        }
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> Result<V::Value, TraceError> {
        let node = self.value.take().ok_or_else(|| TraceError("a map value without key".into()))?;
        seed.deserialize(nested(node, self.depth)?)
    }
}

/// The variant chosen for this read of an enum, recorded into `slot`.
struct Choice<'n> {
    slot: &'n mut Option<VariantNode>,
    index: usize,
    depth: usize,
}

impl<'de, 'n> de::EnumAccess<'de> for Choice<'n> {
    type Error = TraceError;
    type Variant = Self;

    fn variant_seed<V: DeserializeSeed<'de>>(
        self,
        seed: V,
    ) -> Result<(V::Value, Self), TraceError> {
        let index =
            u32::try_from(self.index).map_err(|_| TraceError("too many variants".into()))?;
        let value = seed.deserialize(IntoDeserializer::<TraceError>::into_deserializer(index))?;
        Ok((value, self))
    }
}

impl<'de, 'n> de::VariantAccess<'de> for Choice<'n> {
    type Error = TraceError;

    fn unit_variant(self) -> Result<(), TraceError> {
        match self.slot {
            None => *self.slot = Some(VariantNode::Unit),
            Some(VariantNode::Unit) => {}
            Some(other) => return Err(TraceError(format!("variant read as unit and {other:?}"))),
        }
        Ok(())
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(
        self,
        seed: T,
    ) -> Result<T::Value, TraceError> {
        if self.slot.is_none() {
            *self.slot = Some(VariantNode::Newtype(Node::Unknown));
        }
        let Some(VariantNode::Newtype(node)) = self.slot else {
            return Err(TraceError(format!("variant read as newtype and {:?}", self.slot)));
        };
        seed.deserialize(nested(node, self.depth)?)
    }

    fn tuple_variant<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if self.slot.is_none() {
            *self.slot = Some(VariantNode::Tuple((0..len).map(|_| Node::Unknown).collect()));
        }
        match self.slot {
            Some(VariantNode::Tuple(nodes)) if nodes.len() == len => {
                visitor.visit_seq(Elements { nodes: nodes.iter_mut(), depth: self.depth })
            }
            other => Err(TraceError(format!("variant read as a tuple of {len} and {other:?}"))),
        }
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, TraceError> {
        if self.slot.is_none() {
            *self.slot =
                Some(VariantNode::Struct(fields.iter().map(|f| (*f, Node::Unknown)).collect()));
        }
        match self.slot {
            Some(VariantNode::Struct(known)) if known.len() == fields.len() => {
                visitor.visit_seq(Elements {
                    nodes: known.iter_mut().map(|(_, n)| n).collect::<Vec<_>>().into_iter(),
                    depth: self.depth,
                })
            }
            other => Err(TraceError(format!("variant read as struct and {other:?}"))),
        }
    }
}

impl Format {
    /// The name of a named format (struct, enum, …); `None` for the others.
    pub fn name(&self) -> Option<&str> {
        match self {
            Format::Struct { name, .. }
            | Format::TupleStruct { name, .. }
            | Format::Newtype { name, .. }
            | Format::UnitStruct { name }
            | Format::Enum { name, .. } => Some(name),
            _ => None,
        }
    }
}
