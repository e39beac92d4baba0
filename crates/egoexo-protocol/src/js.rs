//! Reading messages from JS values without copying their byte arrays (wasm32 only).
//!
//! serde's internally tagged enums (`{type: "open", …}`) first buffer every field of a
//! message, which would copy each `Uint8Array` into wasm memory and lose the JS object. So a
//! message is read in three steps: its `Uint8Array`s are taken out of a copy of the object's
//! tree (plain objects and arrays only, depth-limited) and replaced by placeholders
//! `{"$bytes": i}`; the rest is deserialised, with [`BytesSlot`] where the bytes were; then
//! each slot takes its array back, each array at most once.

use js_sys::{Array, Object, Reflect, Uint8Array};
use serde::Deserialize;
use wasm_bindgen::{JsCast, JsValue};

use crate::JsBytes;
use crate::worker::{WorkerEvent, WorkerRequest};

/// How deep a message's objects and arrays may nest.
pub const MAX_DEPTH: usize = 32;

/// Where a byte array stood in a message: its position among the arrays taken out.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
pub struct BytesSlot {
    #[serde(rename = "$bytes")]
    pub index: u32,
}

/// Why a message could not be read.
#[derive(Debug)]
pub struct ReadError(pub String);

impl std::fmt::Display for ReadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ReadError {}

/// Reads a page → worker request.
pub fn request_from_js(value: &JsValue) -> Result<WorkerRequest<JsBytes>, ReadError> {
    let (stripped, arrays) = take_byte_arrays(value)?;
    let request: WorkerRequest<BytesSlot> = deserialize(stripped)?;
    let mut arrays = Slots::new(arrays);
    request.try_map_bytes(|slot| arrays.take(slot))
}

/// Reads a worker → page event.
pub fn event_from_js(value: &JsValue) -> Result<WorkerEvent<JsBytes>, ReadError> {
    let (stripped, arrays) = take_byte_arrays(value)?;
    let event: WorkerEvent<BytesSlot> = deserialize(stripped)?;
    let mut arrays = Slots::new(arrays);
    event.try_map_bytes(|slot| arrays.take(slot))
}

fn deserialize<T: for<'de> Deserialize<'de>>(value: JsValue) -> Result<T, ReadError> {
    serde_wasm_bindgen::from_value(value).map_err(|e| ReadError(e.to_string()))
}

struct Slots(Vec<Option<Uint8Array>>);

impl Slots {
    fn new(arrays: Vec<Uint8Array>) -> Self {
        Slots(arrays.into_iter().map(Some).collect())
    }

    fn take(&mut self, slot: BytesSlot) -> Result<JsBytes, ReadError> {
        self.0
            .get_mut(slot.index as usize)
            .and_then(Option::take)
            .map(JsBytes)
            .ok_or_else(|| ReadError(format!("byte array {} is missing or named twice", slot.index)))
    }
}

/// A copy of `value`'s tree of plain objects and arrays with every `Uint8Array` replaced by a
/// placeholder `{"$bytes": i}`, and the arrays in placeholder order.
pub fn take_byte_arrays(value: &JsValue) -> Result<(JsValue, Vec<Uint8Array>), ReadError> {
    let mut arrays = Vec::new();
    let copy = strip(value, &mut arrays, 0)?;
    Ok((copy, arrays))
}

fn strip(value: &JsValue, arrays: &mut Vec<Uint8Array>, depth: usize) -> Result<JsValue, ReadError> {
    if depth > MAX_DEPTH {
        return Err(ReadError(format!("the message nests deeper than {MAX_DEPTH} levels")));
    }
    if let Some(bytes) = value.dyn_ref::<Uint8Array>() {
        let placeholder = Object::new();
        set(&placeholder, &JsValue::from_str("$bytes"), &JsValue::from(arrays.len() as u32))?;
        arrays.push(bytes.clone());
        return Ok(placeholder.into());
    }
    if Array::is_array(value) {
        let copy = Array::new();
        for item in Array::from(value).iter() {
            copy.push(&strip(&item, arrays, depth + 1)?);
        }
        return Ok(copy.into());
    }
    if let Some(object) = value.dyn_ref::<Object>().filter(|_| value.is_object() && !value.is_function()) {
        let copy = Object::new();
        for entry in Object::entries(object).iter() {
            let entry = Array::from(&entry);
            set(&copy, &entry.get(0), &strip(&entry.get(1), arrays, depth + 1)?)?;
        }
        return Ok(copy.into());
    }
    Ok(value.clone())
}

fn set(object: &Object, key: &JsValue, value: &JsValue) -> Result<(), ReadError> {
    Reflect::set(object, key, value).map(|_| ()).map_err(|e| ReadError(format!("cannot copy the message: {e:?}")))
}
