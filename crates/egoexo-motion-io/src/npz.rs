//! Writing NumPy `.npz` archives: the project's one npz writer (AMASS exports, `.egoexo`
//! sessions, training shards), and the deterministic zip they are stored in.
//!
//! An `.npz` is a zip of `.npy` arrays, one per name, as `numpy.savez_compressed` writes it;
//! `numpy.load(path)` reads it without pickles. Arrays are C-order, little-endian, with
//! npyz's default dtype for the element type (`<f4`, `<f8`, `<i8`, `<u2`, …), plus 0-d unicode
//! strings ([`NpzWriter::add_str`]). Reading untrusted `.npz` files is the session importer's
//! job (`egoexo_session::npz`).

use std::collections::BTreeMap;
use std::io::{Cursor, Write};

use npyz::WriterBuilder;
use thiserror::Error;

/// Why an archive could not be written.
#[derive(Debug, Error)]
pub enum NpzWriteError {
    #[error("array `{name}`: shape {shape:?} holds {expected} values, but {got} were given")]
    ShapeMismatch { name: String, shape: Vec<u64>, expected: u64, got: usize },
    #[error("array `{name}`: {source}")]
    Encode { name: String, source: std::io::Error },
    #[error("zip: {0}")]
    Zip(#[from] zip::result::ZipError),
}

/// Builds an `.npz` archive in memory. Arrays are stored in name order, so the same arrays
/// give the same bytes whatever order they were added in.
#[derive(Debug, Default)]
pub struct NpzWriter {
    files: BTreeMap<String, Vec<u8>>,
}

impl NpzWriter {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds an array: `data` in C order, `data.len()` the product of `shape` (`&[]` for a
    /// 0-d scalar). A second array of the same name replaces the first.
    pub fn add<T>(&mut self, name: &str, shape: &[u64], data: &[T]) -> Result<(), NpzWriteError>
    where
        T: npyz::Serialize + npyz::AutoSerialize + Copy,
    {
        let expected: u64 = shape.iter().product();
        if expected != data.len() as u64 {
            return Err(NpzWriteError::ShapeMismatch {
                name: name.to_owned(),
                shape: shape.to_vec(),
                expected,
                got: data.len(),
            });
        }
        let encode = |source| NpzWriteError::Encode { name: name.to_owned(), source };
        let mut npy = Vec::with_capacity(128 + std::mem::size_of_val(data));
        let mut writer =
            npyz::WriteOptions::new().default_dtype().shape(shape).writer(&mut npy).begin_nd().map_err(encode)?;
        writer.extend(data.iter().copied()).map_err(encode)?;
        writer.finish().map_err(encode)?;
        self.files.insert(format!("{name}.npy"), npy);
        Ok(())
    }

    /// Adds a 0-d unicode string (`<U{len}`), as numpy saves `np.array("neutral")`.
    pub fn add_str(&mut self, name: &str, value: &str) -> Result<(), NpzWriteError> {
        let encode = |source| NpzWriteError::Encode { name: name.to_owned(), source };
        let len = value.chars().count().max(1);
        let dtype: npyz::TypeStr = format!("<U{len}").parse().map_err(|e| {
            encode(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("dtype <U{len}: {e}")))
        })?;
        let mut npy = Vec::new();
        let mut writer = npyz::WriteOptions::<str>::new()
            .dtype(npyz::DType::Plain(dtype))
            .shape(&[])
            .writer(&mut npy)
            .begin_nd()
            .map_err(encode)?;
        writer.push(value).map_err(encode)?;
        writer.finish().map_err(encode)?;
        self.files.insert(format!("{name}.npy"), npy);
        Ok(())
    }

    /// The archive's bytes ([`write_zip`]).
    pub fn finish(self) -> Result<Vec<u8>, NpzWriteError> {
        Ok(write_zip(&self.files)?)
    }
}

/// A deterministic zip of `files` (path → bytes): deflated entries in path order, every
/// timestamp 1980-01-01 00:00 (zip's epoch), zip64 only for entries of 4 GiB or more. The
/// container of `.npz`; `.egoexo` sessions are written with it too.
pub fn write_zip(files: &BTreeMap<String, Vec<u8>>) -> Result<Vec<u8>, zip::result::ZipError> {
    let mut writer = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .last_modified_time(zip::DateTime::default())
        .large_file(false);
    for (path, bytes) in files {
        let options = if bytes.len() as u64 >= u32::MAX as u64 { options.large_file(true) } else { options };
        writer.start_file(path.as_str(), options)?;
        writer.write_all(bytes)?;
    }
    Ok(writer.finish()?.into_inner())
}

#[cfg(test)]
mod tests {
    use std::io::Read;

    use super::*;

    fn entries(bytes: &[u8]) -> BTreeMap<String, Vec<u8>> {
        let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).unwrap();
        let mut out = BTreeMap::new();
        for i in 0..zip.len() {
            let mut entry = zip.by_index(i).unwrap();
            let mut data = Vec::new();
            entry.read_to_end(&mut data).unwrap();
            out.insert(entry.name().unwrap().to_string(), data);
        }
        out
    }

    #[test]
    fn arrays_are_npy_files_in_name_order_and_the_bytes_are_deterministic() {
        let write = |first_b: bool| {
            let mut w = NpzWriter::new();
            if first_b {
                w.add("b", &[3], &[1i64, 2, 3]).unwrap();
            }
            w.add("a", &[2, 2], &[1.0f64, 2.0, 3.0, 4.0]).unwrap();
            w.add("s", &[], &[30.0f64]).unwrap();
            w.add_str("gender", "neutral").unwrap();
            if !first_b {
                w.add("b", &[3], &[1i64, 2, 3]).unwrap();
            }
            w.finish().unwrap()
        };
        let bytes = write(true);
        assert_eq!(bytes, write(false));
        let files = entries(&bytes);
        assert_eq!(files.keys().collect::<Vec<_>>(), ["a.npy", "b.npy", "gender.npy", "s.npy"]);
        let header = |name: &str| String::from_utf8_lossy(&files[name][10..80]).into_owned();
        assert!(
            header("a.npy").contains("'descr': '<f8'") && header("a.npy").contains("'shape': (2, 2,"),
            "{}",
            header("a.npy")
        );
        assert!(header("s.npy").contains("'shape': ()"), "{}", header("s.npy"));
        assert!(header("gender.npy").contains("'<U7'"), "{}", header("gender.npy"));
    }

    #[test]
    fn a_shape_that_does_not_fit_the_data_is_an_error_naming_the_array() {
        let mut w = NpzWriter::new();
        let err = w.add("poses", &[2, 3], &[0.0f32; 5]).unwrap_err();
        assert_eq!(err.to_string(), "array `poses`: shape [2, 3] holds 6 values, but 5 were given");
    }
}
