//! Reading untrusted JSON values with errors that name the file, line and field path.

use serde_json::Value;

use crate::error::{ImportError, ImportErrorKind, Location, quote};

/// Where values come from: a file and, for JSON-lines files, a line.
#[derive(Clone, Copy, Debug)]
pub(crate) struct JsonCtx<'a> {
    pub file: &'a str,
    pub line: Option<u64>,
}

impl<'a> JsonCtx<'a> {
    pub fn file(file: &'a str) -> Self {
        Self { file, line: None }
    }

    pub fn line(file: &'a str, line: u64) -> Self {
        Self { file, line: Some(line) }
    }

    pub fn at(&self, path: &str) -> Location {
        match (self.line, path.is_empty()) {
            (Some(line), true) => Location::Line(line),
            (Some(line), false) => Location::LineField { line, field: path.to_owned() },
            (None, true) => Location::File,
            (None, false) => Location::Field(path.to_owned()),
        }
    }

    pub fn invalid(&self, path: &str, expected: impl Into<String>, got: &Value) -> ImportError {
        ImportError::invalid(self.file, self.at(path), expected, describe(got))
    }

    pub fn error(&self, path: &str, kind: ImportErrorKind) -> ImportError {
        ImportError::new(self.file, self.at(path), kind)
    }

    /// Parses one JSON document.
    pub fn parse(&self, text: &str) -> Result<Value, ImportError> {
        serde_json::from_str(text).map_err(|e| {
            let location = match self.line {
                Some(line) => Location::Line(line),
                None => Location::Line(e.line() as u64),
            };
            ImportError::new(self.file, location, ImportErrorKind::Json(e.to_string()))
        })
    }

    /// A required object member.
    pub fn field<'v>(&self, v: &'v Value, path: &str, key: &str) -> Result<&'v Value, ImportError> {
        let full = join(path, key);
        match v {
            Value::Object(map) => map
                .get(key)
                .ok_or_else(|| ImportError::invalid(self.file, self.at(&full), "this field to be present", "nothing")),
            other => Err(self.invalid(path, "a JSON object", other)),
        }
    }

    /// An optional object member (`null` counts as absent).
    pub fn optional<'v>(&self, v: &'v Value, path: &str, key: &str) -> Result<Option<&'v Value>, ImportError> {
        match v {
            Value::Object(map) => Ok(map.get(key).filter(|v| !v.is_null())),
            other => Err(self.invalid(path, "a JSON object", other)),
        }
    }

    pub fn f64(&self, v: &Value, path: &str) -> Result<f64, ImportError> {
        match v.as_f64() {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(self.invalid(path, "a finite number", v)),
        }
    }

    /// A finite number that also fits `f32`.
    pub fn f32(&self, v: &Value, path: &str) -> Result<f32, ImportError> {
        let x = self.f64(v, path)?;
        let y = x as f32;
        if y.is_finite() { Ok(y) } else { Err(self.invalid(path, "a number within the f32 range", v)) }
    }

    pub fn i64(&self, v: &Value, path: &str) -> Result<i64, ImportError> {
        v.as_i64().ok_or_else(|| self.invalid(path, "an integer (64-bit)", v))
    }

    pub fn u64(&self, v: &Value, path: &str) -> Result<u64, ImportError> {
        v.as_u64().ok_or_else(|| self.invalid(path, "a non-negative integer", v))
    }

    pub fn str<'v>(&self, v: &'v Value, path: &str) -> Result<&'v str, ImportError> {
        v.as_str().ok_or_else(|| self.invalid(path, "a string", v))
    }

    pub fn array<'v>(&self, v: &'v Value, path: &str) -> Result<&'v [Value], ImportError> {
        v.as_array().map(Vec::as_slice).ok_or_else(|| self.invalid(path, "an array", v))
    }

    /// An array of exactly `N` finite numbers (f32).
    pub fn f32_array<const N: usize>(&self, v: &Value, path: &str) -> Result<[f32; N], ImportError> {
        let items = self.array(v, path)?;
        if items.len() != N {
            return Err(self.invalid(path, format!("an array of {N} numbers"), v));
        }
        let mut out = [0f32; N];
        for (i, (slot, item)) in out.iter_mut().zip(items).enumerate() {
            *slot = self.f32(item, &format!("{path}[{i}]"))?;
        }
        Ok(out)
    }
}

/// `a.b` (or `b` at the root).
pub(crate) fn join(path: &str, key: &str) -> String {
    if path.is_empty() { key.to_owned() } else { format!("{path}.{key}") }
}

/// A short description of a JSON value for "got …" in messages.
pub(crate) fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".into(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) => format!("the string {}", quote(s, 40)),
        Value::Array(a) => format!("an array of {} items", a.len()),
        Value::Object(o) => format!("an object with {} fields", o.len()),
    }
}
