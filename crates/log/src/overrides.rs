//! `--set key=value`: changing parameters of a logged configuration before a replay.
//!
//! Keys are dotted paths into the configuration (`world.ball_filter.process_noise`, with
//! numbers indexing arrays: `robots.2.role`). A key must name a value that exists, and the new
//! value must have the same type (any number for a number): a typo or a wrong type is an error
//! naming the key, not a silently ignored parameter.

use serde_json::Value;

/// One `key=value` override.
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    pub key: String,
    pub value: Value,
    /// The value as written, for strings given without quotes.
    pub raw: String,
}

/// Why an override could not be parsed or applied. Every variant names the key.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OverrideError {
    #[error("`{text}` is not of the form key=value")]
    Syntax { text: String },
    #[error("--set {key}: `{missing}` does not exist in `{parent}` (it has: {available})")]
    UnknownKey { key: String, parent: String, missing: String, available: String },
    #[error("--set {key}: `{parent}` is {kind}, it has no field `{missing}`")]
    NotAContainer { key: String, parent: String, missing: String, kind: &'static str },
    #[error("--set {key}: expected {expected}, got `{raw}`")]
    WrongType { key: String, expected: &'static str, raw: String },
}

impl Override {
    /// Parses `key=value`. The value is JSON when it parses as JSON (numbers, booleans,
    /// quoted strings, arrays, objects) and a plain string otherwise.
    pub fn parse(text: &str) -> Result<Override, OverrideError> {
        let (key, raw) = text
            .split_once('=')
            .filter(|(k, _)| !k.trim().is_empty())
            .ok_or_else(|| OverrideError::Syntax { text: text.to_owned() })?;
        let raw = raw.trim();
        let value = serde_json::from_str(raw).unwrap_or_else(|_| Value::String(raw.to_owned()));
        Ok(Override { key: key.trim().to_owned(), value, raw: raw.to_owned() })
    }

    /// Sets the value in `config`.
    pub fn apply(&self, config: &mut Value) -> Result<(), OverrideError> {
        let parts: Vec<&str> = self.key.split('.').collect();
        let mut current = config;
        let mut parent = String::from("the configuration");
        for (i, part) in parts.iter().enumerate() {
            let next = match current {
                Value::Object(map) => {
                    if !map.contains_key(*part) {
                        let mut keys: Vec<&str> = map.keys().map(String::as_str).collect();
                        keys.sort_unstable();
                        return Err(OverrideError::UnknownKey {
                            key: self.key.clone(),
                            parent,
                            missing: (*part).to_owned(),
                            available: if keys.is_empty() {
                                "nothing".to_owned()
                            } else {
                                keys.join(", ")
                            },
                        });
                    }
                    map.get_mut(*part)
                }
                Value::Array(items) => {
                    let len = items.len();
                    match part.parse::<usize>() {
                        Ok(index) if index < len => items.get_mut(index),
                        _ => {
                            return Err(OverrideError::UnknownKey {
                                key: self.key.clone(),
                                parent,
                                missing: (*part).to_owned(),
                                available: format!("indices 0 to {}", len.saturating_sub(1)),
                            });
                        }
                    }
                }
                other => {
                    return Err(OverrideError::NotAContainer {
                        key: self.key.clone(),
                        parent,
                        missing: (*part).to_owned(),
                        kind: kind(other),
                    });
                }
            };
            let Some(next) = next else {
                return Err(OverrideError::UnknownKey {
                    key: self.key.clone(),
                    parent,
                    missing: (*part).to_owned(),
                    available: String::new(),
                });
            };
            current = next;
            parent = parts[..=i].join(".");
        }
        *current = self.converted(current)?;
        Ok(())
    }

    /// The new value, checked against (and where harmless converted to) the old one's type.
    fn converted(&self, old: &Value) -> Result<Value, OverrideError> {
        let wrong = |expected| OverrideError::WrongType {
            key: self.key.clone(),
            expected,
            raw: self.raw.clone(),
        };
        match (old, &self.value) {
            (Value::Null, new) => Ok(new.clone()),
            (Value::Bool(_), Value::Bool(_))
            | (Value::Number(_), Value::Number(_))
            | (Value::String(_), Value::String(_))
            | (Value::Array(_), Value::Array(_))
            | (Value::Object(_), Value::Object(_)) => Ok(self.value.clone()),
            // `--set name=42` for a string parameter means the text "42".
            (Value::String(_), _) => Ok(Value::String(self.raw.clone())),
            (old, _) => Err(wrong(kind(old))),
        }
    }
}

fn kind(value: &Value) -> &'static str {
    match value {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "a table",
    }
}

/// Parses and applies `key=value` overrides in order.
pub fn apply_overrides(config: &mut Value, overrides: &[Override]) -> Result<(), OverrideError> {
    overrides.iter().try_for_each(|o| o.apply(config))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn set(config: &mut Value, text: &str) -> Result<(), OverrideError> {
        Override::parse(text)?.apply(config)
    }

    #[test]
    fn sets_nested_values_and_array_items() {
        let mut config =
            json!({ "filter": { "gain": 0.3, "name": "a", "on": true }, "list": [1, 2] });
        set(&mut config, "filter.gain=0.5").unwrap_or_else(|e| panic!("{e}"));
        set(&mut config, "filter.name=b c").unwrap_or_else(|e| panic!("{e}"));
        set(&mut config, "filter.on=false").unwrap_or_else(|e| panic!("{e}"));
        set(&mut config, "list.1=7").unwrap_or_else(|e| panic!("{e}"));
        set(&mut config, "filter.name=42").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            config,
            json!({ "filter": { "gain": 0.5, "name": "42", "on": false }, "list": [1, 7] })
        );
    }

    #[test]
    fn errors_name_the_key() {
        let mut config = json!({ "filter": { "gain": 0.3 } });
        let error = set(&mut config, "filter.gian=1").err().map(|e| e.to_string());
        assert_eq!(
            error.as_deref(),
            Some("--set filter.gian: `gian` does not exist in `filter` (it has: gain)")
        );
        let error = set(&mut config, "filter.gain=fast").err().map(|e| e.to_string());
        assert_eq!(error.as_deref(), Some("--set filter.gain: expected a number, got `fast`"));
        let error = set(&mut config, "filter.gain.x=1").err().map(|e| e.to_string());
        assert_eq!(
            error.as_deref(),
            Some("--set filter.gain.x: `filter.gain` is a number, it has no field `x`")
        );
        assert!(matches!(Override::parse("novalue"), Err(OverrideError::Syntax { .. })));
        assert!(matches!(Override::parse("=3"), Err(OverrideError::Syntax { .. })));
    }
}
