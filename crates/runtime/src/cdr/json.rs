//! CDR bytes as JSON, read with their [`Format`] instead of their Rust type: what `strata log
//! cat`, the viewer and replay's differences show. The JSON is the one `serde_json` writes for
//! the value (structs as objects, enums externally tagged, options as `null` or the value), so
//! a value reads the same whichever encoding it was logged in.

use serde_json::{Map, Number, Value};

use super::de::{Reader, invalid};
use super::{CdrError, Format, Named, Variant, payload};

/// The value `bytes` (header included) holds, as JSON.
pub fn to_json(format: &Format, bytes: &[u8]) -> Result<Value, CdrError> {
    let mut reader = Reader::new(payload(bytes)?);
    let value = read(format, &mut reader)?;
    reader.finish()?;
    Ok(value)
}

fn float(value: f64) -> Value {
    // As serde_json: numbers that JSON cannot hold (NaN, infinities) become null.
    Number::from_f64(value).map_or(Value::Null, Value::Number)
}

fn read(format: &Format, r: &mut Reader<'_>) -> Result<Value, CdrError> {
    Ok(match format {
        Format::Unit | Format::UnitStruct { .. } => Value::Null,
        Format::Bool => Value::Bool(r.bool()?),
        Format::I8 => r.i8()?.into(),
        Format::I16 => r.i16()?.into(),
        Format::I32 => r.i32()?.into(),
        Format::I64 => r.i64()?.into(),
        Format::U8 => r.u8()?.into(),
        Format::U16 => r.u16()?.into(),
        Format::U32 => r.u32()?.into(),
        Format::U64 => r.u64()?.into(),
        Format::F32 => float(f64::from(r.f32()?)),
        Format::F64 => float(r.f64()?),
        Format::Char => Value::String(r.char()?.to_string()),
        Format::Str => Value::String(r.str()?.to_owned()),
        Format::Bytes => Value::Array(r.bytes()?.iter().map(|b| Value::from(*b)).collect()),
        Format::Option(inner) => {
            if r.option()? {
                read(inner, r)?
            } else {
                Value::Null
            }
        }
        Format::Seq(element) => {
            let count = r.count()?;
            let mut out = Vec::with_capacity(count);
            for _ in 0..count {
                out.push(read(element, r)?);
            }
            Value::Array(out)
        }
        Format::Map { key, value } => {
            let at = r.position();
            let count = r.count()?;
            let mut out = Map::new();
            for _ in 0..count {
                let key = match read(key, r)? {
                    Value::String(text) => text,
                    // serde_json writes number and boolean keys as their text.
                    key @ (Value::Number(_) | Value::Bool(_)) => key.to_string(),
                    other => {
                        return Err(invalid(at, format!("a map key JSON cannot hold: {other}")));
                    }
                };
                out.insert(key, read(value, r)?);
            }
            Value::Object(out)
        }
        Format::Tuple(elements) | Format::TupleStruct { elements, .. } => {
            Value::Array(elements.iter().map(|e| read(e, r)).collect::<Result<_, _>>()?)
        }
        Format::Array { element, len } => {
            let mut out = Vec::with_capacity(*len);
            for _ in 0..*len {
                out.push(read(element, r)?);
            }
            Value::Array(out)
        }
        Format::Struct { fields, .. } => read_fields(fields, r)?,
        Format::Newtype { inner, .. } => read(inner, r)?,
        Format::Enum { name, variants } => {
            let at = r.position();
            let index = r.u32()?;
            let Some(Named { name: variant, value }) = variants.get(index as usize) else {
                return Err(invalid(at, format!("{name} has no variant {index}")));
            };
            let content = match value {
                Variant::Unit => return Ok(Value::String(variant.clone())),
                Variant::Newtype(inner) => read(inner, r)?,
                Variant::Tuple(elements) => {
                    Value::Array(elements.iter().map(|e| read(e, r)).collect::<Result<_, _>>()?)
                }
                Variant::Struct(fields) => read_fields(fields, r)?,
            };
            let mut tagged = Map::new();
            tagged.insert(variant.clone(), content);
            Value::Object(tagged)
        }
    })
}

fn read_fields(fields: &[Named<Format>], r: &mut Reader<'_>) -> Result<Value, CdrError> {
    let mut out = Map::new();
    for field in fields {
        out.insert(field.name.clone(), read(&field.value, r)?);
    }
    Ok(Value::Object(out))
}
