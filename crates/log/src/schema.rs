//! JSON Schemas for logged types, inferred from a sample value.
//!
//! Serde gives no schema at run time, and deriving one would put a dependency on every message
//! type of every crate. A schema inferred from the first message of a type is enough for what
//! generic tools use it for (listing fields to plot) and never rejects a later message: no
//! field is `required`, extra fields are allowed, and a `null` sample constrains nothing (an
//! `Option` that is `None` now may hold a value later).

use serde_json::{Map, Value, json};

/// A permissive JSON Schema describing `sample`, titled `type_name` (the Rust type).
pub fn infer_json_schema(type_name: &str, sample: &Value) -> Value {
    let mut schema = infer(sample, 0);
    if let Value::Object(map) = &mut schema {
        map.insert("title".to_owned(), Value::String(type_name.to_owned()));
        map.insert(
            "$schema".to_owned(),
            Value::String("https://json-schema.org/draft/2020-12/schema".to_owned()),
        );
    }
    schema
}

/// Deep structures are described down to this depth; below it anything is accepted.
const MAX_DEPTH: usize = 8;

fn infer(sample: &Value, depth: usize) -> Value {
    if depth >= MAX_DEPTH {
        return json!({});
    }
    match sample {
        Value::Null => json!({}),
        Value::Bool(_) => json!({ "type": "boolean" }),
        // Integer-valued floats serialize as e.g. `1.0`, but a counter may later exceed what a
        // sample shows; "number" covers both.
        Value::Number(_) => json!({ "type": "number" }),
        Value::String(_) => json!({ "type": "string" }),
        Value::Array(items) => match items.first() {
            // Tuples and fixed arrays put different types at different positions: describe
            // items only when the sample's items agree.
            Some(first) if items.iter().all(|i| same_kind(i, first)) => {
                json!({ "type": "array", "items": infer(first, depth + 1) })
            }
            _ => json!({ "type": "array" }),
        },
        Value::Object(fields) => {
            let properties: Map<String, Value> =
                fields.iter().map(|(k, v)| (k.clone(), infer(v, depth + 1))).collect();
            json!({ "type": "object", "properties": properties })
        }
    }
}

fn same_kind(a: &Value, b: &Value) -> bool {
    std::mem::discriminant(a) == std::mem::discriminant(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn objects_get_properties_and_null_constrains_nothing() {
        let schema = infer_json_schema(
            "demo::Pose",
            &json!({ "x": 1.0, "name": "a", "tag": null, "list": [1, 2], "tuple": [1, "a"] }),
        );
        assert_eq!(schema["title"], "demo::Pose");
        assert_eq!(schema["type"], "object");
        assert_eq!(schema["properties"]["x"]["type"], "number");
        assert_eq!(schema["properties"]["tag"], json!({}));
        assert_eq!(schema["properties"]["list"]["items"]["type"], "number");
        assert!(schema["properties"]["tuple"].get("items").is_none());
        assert!(schema.get("required").is_none());
    }

    #[test]
    fn scalars_are_described_too() {
        assert_eq!(infer_json_schema("f64", &json!(9.81))["type"], "number");
    }
}
