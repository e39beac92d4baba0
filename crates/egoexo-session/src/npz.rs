//! NumPy `.npz` archives (a zip of `.npy` arrays) in sessions: a checked reader for untrusted
//! files. (The one writer is `egoexo_motion_io::npz::NpzWriter`.)
//!
//! The `.npy` reader is this crate's own (~150 lines): it parses the header dictionary
//! strictly (`descr`, `fortran_order`, `shape`), checks the shape's element count with
//! overflow-checked arithmetic against the bytes actually present *before* allocating, and
//! supports little/big-endian bool, integer and float dtypes. (npyz, used for writing,
//! multiplies an untrusted shape unchecked when reading.) Object/pickled and structured
//! dtypes are rejected. Errors name the archive and the array.

use crate::error::{ImportError, ImportErrorKind, Location};
use crate::vfs::{FileTree, Limits};

/// The element data of an array, widened to one of three types.
#[derive(Clone, Debug, PartialEq)]
pub enum NpyData {
    F32(Vec<f32>),
    F64(Vec<f64>),
    /// Every integer and bool dtype (u64 values above `i64::MAX` are rejected).
    Int(Vec<i64>),
}

/// A decoded array in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    pub shape: Vec<usize>,
    pub data: NpyData,
}

impl NpyArray {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match &self.data {
            NpyData::F32(v) => v.len(),
            NpyData::F64(v) => v.len(),
            NpyData::Int(v) => v.len(),
        }
    }

    /// No elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Element `i` as f64 (`None` out of range).
    pub fn f64_at(&self, i: usize) -> Option<f64> {
        match &self.data {
            NpyData::F32(v) => v.get(i).map(|&x| f64::from(x)),
            NpyData::F64(v) => v.get(i).copied(),
            NpyData::Int(v) => v.get(i).map(|&x| x as f64),
        }
    }

    /// Element `i` as an integer; `None` out of range or for a float dtype.
    pub fn i64_at(&self, i: usize) -> Option<i64> {
        match &self.data {
            NpyData::Int(v) => v.get(i).copied(),
            _ => None,
        }
    }

    /// Whether the dtype is an integer (or bool) type.
    pub fn is_int(&self) -> bool {
        matches!(self.data, NpyData::Int(_))
    }
}

/// An opened `.npz`: arrays are decoded on request.
#[derive(Clone, Debug)]
pub struct Npz {
    file: String,
    tree: FileTree,
}

impl Npz {
    /// Opens the archive `bytes`; `file` names it in errors.
    pub fn open(file: &str, bytes: Vec<u8>, limits: Limits) -> Result<Self, ImportError> {
        let tree = FileTree::from_zip(file, bytes, limits)?;
        Ok(Self { file: file.to_owned(), tree })
    }

    /// Array names (without `.npy`).
    pub fn names(&self) -> Vec<String> {
        self.tree.paths().into_iter().filter_map(|p| p.strip_suffix(".npy").map(str::to_owned)).collect()
    }

    /// Whether the array exists.
    pub fn contains(&self, name: &str) -> bool {
        self.tree.contains(&format!("{name}.npy"))
    }

    /// Decodes an array. Errors name the archive and the array.
    pub fn array(&self, name: &str) -> Result<NpyArray, ImportError> {
        let entry = format!("{name}.npy");
        if !self.tree.contains(&entry) {
            return Err(ImportError::invalid(
                &self.file,
                Location::Field(name.into()),
                format!("an array `{name}`"),
                format!("none (arrays: {})", self.names().join(", ")),
            ));
        }
        let bytes = self.tree.read(&entry).map_err(|mut e| {
            e.file = self.file.clone();
            e.location = Location::Field(name.into());
            e
        })?;
        parse_npy(&bytes)
            .map_err(|msg| ImportError::new(&self.file, Location::Field(name.into()), ImportErrorKind::Npy(msg)))
    }

    /// Decodes an array and checks its shape: `None` entries match any length.
    pub fn array_with_shape(&self, name: &str, shape: &[Option<usize>]) -> Result<NpyArray, ImportError> {
        let array = self.array(name)?;
        let ok =
            array.shape.len() == shape.len() && array.shape.iter().zip(shape).all(|(&a, e)| e.is_none_or(|e| e == a));
        if !ok {
            let expected: Vec<String> = shape.iter().map(|d| d.map_or("N".into(), |d| d.to_string())).collect();
            return Err(ImportError::invalid(
                &self.file,
                Location::Field(name.into()),
                format!("shape ({})", expected.join(", ")),
                format!("shape {:?}", array.shape),
            ));
        }
        Ok(array)
    }
}

/// Parses one `.npy` file.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || !bytes.starts_with(MAGIC) {
        return Err("missing the \\x93NUMPY magic; expected an .npy array".into());
    }
    let major = bytes[6];
    let (header_len, header_start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("truncated header".into());
            }
            (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12)
        }
        v => return Err(format!("unsupported .npy format version {v}; expected 1, 2 or 3")),
    };
    let header_end = header_start.checked_add(header_len).filter(|&e| e <= bytes.len()).ok_or("truncated header")?;
    let header = std::str::from_utf8(&bytes[header_start..header_end]).map_err(|_| "header is not text")?;
    let dict = HeaderParser { s: header.as_bytes(), i: 0 }.dict()?;
    let descr = dict.descr.ok_or("header lacks `descr`")?;
    let fortran = dict.fortran_order.ok_or("header lacks `fortran_order`")?;
    let shape = dict.shape.ok_or("header lacks `shape`")?;
    let (kind, size, big_endian) = parse_descr(&descr)?;
    let data = &bytes[header_end..];
    let count = shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .ok_or_else(|| format!("shape {shape:?} overflows"))?;
    let needed = count.checked_mul(size).ok_or_else(|| format!("shape {shape:?} overflows"))?;
    if needed != data.len() {
        return Err(format!("shape {shape:?} of `{descr}` needs {needed} data bytes, the file has {}", data.len()));
    }
    let word = |chunk: &[u8]| -> u64 {
        let mut buf = [0u8; 8];
        if big_endian {
            buf[8 - size..].copy_from_slice(chunk);
            u64::from_be_bytes(buf)
        } else {
            buf[..size].copy_from_slice(chunk);
            u64::from_le_bytes(buf)
        }
    };
    let chunks = data.chunks_exact(size.max(1));
    let data = match (kind, size) {
        (b'f', 4) => NpyData::F32(chunks.map(|c| f32::from_bits(word(c) as u32)).collect()),
        (b'f', 8) => NpyData::F64(chunks.map(|c| f64::from_bits(word(c))).collect()),
        (b'i', 1 | 2 | 4 | 8) => {
            let shift = 64 - 8 * size as u32;
            NpyData::Int(chunks.map(|c| ((word(c) << shift) as i64) >> shift).collect())
        }
        (b'u' | b'b', 1 | 2 | 4 | 8) => NpyData::Int(
            chunks
                .map(|c| i64::try_from(word(c)).map_err(|_| "an unsigned value exceeds i64::MAX".to_owned()))
                .collect::<Result<_, _>>()?,
        ),
        _ => return Err(format!("unsupported dtype `{descr}`; expected bool, integer, float32 or float64")),
    };
    let mut array = NpyArray { shape, data };
    if fortran && array.shape.len() > 1 {
        array = fortran_to_c(array);
    }
    Ok(array)
}

/// `(kind, item size, big endian)` of a simple dtype string like `<f8`.
fn parse_descr(descr: &str) -> Result<(u8, usize, bool), String> {
    let b = descr.as_bytes();
    let unsupported = || format!("unsupported dtype `{descr}`; expected bool, integer, float32 or float64");
    if b.len() < 2 {
        return Err(unsupported());
    }
    let (order, rest) = match b[0] {
        b'<' | b'>' | b'|' | b'=' => (b[0], &b[1..]),
        _ => (b'=', b),
    };
    let kind = *rest.first().ok_or_else(unsupported)?;
    let size: usize = std::str::from_utf8(&rest[1..]).ok().and_then(|s| s.parse().ok()).ok_or_else(unsupported)?;
    if !matches!(size, 1 | 2 | 4 | 8) || !matches!(kind, b'f' | b'i' | b'u' | b'b') {
        return Err(unsupported());
    }
    Ok((kind, size, order == b'>'))
}

fn fortran_to_c(array: NpyArray) -> NpyArray {
    let shape = array.shape.clone();
    let n = array.len();
    // C index → Fortran offset.
    let offset = |mut c: usize| {
        let mut f = 0;
        let mut stride = 1;
        let mut idx = vec![0; shape.len()];
        for (slot, &d) in idx.iter_mut().zip(&shape).rev() {
            *slot = c % d.max(1);
            c /= d.max(1);
        }
        for (&i, &d) in idx.iter().zip(&shape) {
            f += i * stride;
            stride *= d;
        }
        f
    };
    fn permute<T: Copy>(v: &[T], n: usize, offset: impl Fn(usize) -> usize) -> Vec<T> {
        (0..n).filter_map(|c| v.get(offset(c)).copied()).collect()
    }
    let data = match &array.data {
        NpyData::F32(v) => NpyData::F32(permute(v, n, offset)),
        NpyData::F64(v) => NpyData::F64(permute(v, n, offset)),
        NpyData::Int(v) => NpyData::Int(permute(v, n, offset)),
    };
    NpyArray { shape, data }
}

#[derive(Default)]
struct HeaderDict {
    descr: Option<String>,
    fortran_order: Option<bool>,
    shape: Option<Vec<usize>>,
}

/// A strict parser for the header's Python dict literal.
struct HeaderParser<'a> {
    s: &'a [u8],
    i: usize,
}

impl HeaderParser<'_> {
    fn skip_ws(&mut self) {
        while self.s.get(self.i).is_some_and(|c| c.is_ascii_whitespace()) {
            self.i += 1;
        }
    }

    fn eat(&mut self, c: u8) -> bool {
        self.skip_ws();
        if self.s.get(self.i) == Some(&c) {
            self.i += 1;
            true
        } else {
            false
        }
    }

    fn expect(&mut self, c: u8) -> Result<(), String> {
        if self.eat(c) { Ok(()) } else { Err(format!("malformed header: expected `{}` at byte {}", c as char, self.i)) }
    }

    fn string(&mut self) -> Result<String, String> {
        self.skip_ws();
        let quote = match self.s.get(self.i) {
            Some(&q @ (b'\'' | b'"')) => q,
            _ => return Err(format!("malformed header: expected a string at byte {}", self.i)),
        };
        self.i += 1;
        let start = self.i;
        while self.s.get(self.i).is_some_and(|&c| c != quote) {
            self.i += 1;
        }
        if self.i >= self.s.len() {
            return Err("malformed header: unterminated string".into());
        }
        let out = String::from_utf8_lossy(&self.s[start..self.i]).into_owned();
        self.i += 1;
        Ok(out)
    }

    fn word(&mut self) -> &[u8] {
        self.skip_ws();
        let start = self.i;
        while self.s.get(self.i).is_some_and(|c| c.is_ascii_alphanumeric()) {
            self.i += 1;
        }
        &self.s[start..self.i]
    }

    fn shape(&mut self) -> Result<Vec<usize>, String> {
        self.expect(b'(')?;
        let mut dims = Vec::new();
        loop {
            if self.eat(b')') {
                return Ok(dims);
            }
            let w = self.word();
            let d: usize =
                std::str::from_utf8(w).ok().map(|s| s.trim_end_matches('L')).and_then(|s| s.parse().ok()).ok_or(
                    "malformed header: `shape` holds something other than a non-negative integer that fits in memory",
                )?;
            if dims.len() >= 32 {
                return Err("malformed header: `shape` has more than 32 dimensions".into());
            }
            dims.push(d);
            if !self.eat(b',') {
                self.expect(b')')?;
                return Ok(dims);
            }
        }
    }

    fn dict(mut self) -> Result<HeaderDict, String> {
        let mut out = HeaderDict::default();
        self.expect(b'{')?;
        loop {
            if self.eat(b'}') {
                break;
            }
            let key = self.string()?;
            self.expect(b':')?;
            match key.as_str() {
                "descr" => {
                    self.skip_ws();
                    if self.s.get(self.i) == Some(&b'[') {
                        return Err("structured dtypes are not supported; expected a plain numeric dtype".into());
                    }
                    out.descr = Some(self.string()?);
                }
                "fortran_order" => {
                    out.fortran_order = Some(match self.word() {
                        b"True" => true,
                        b"False" => false,
                        _ => return Err("malformed header: `fortran_order` is not True/False".into()),
                    })
                }
                "shape" => out.shape = Some(self.shape()?),
                other => return Err(format!("malformed header: unexpected key `{other}`")),
            }
            if !self.eat(b',') {
                self.expect(b'}')?;
                break;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use egoexo_motion_io::npz::NpzWriter;

    use super::*;

    #[test]
    fn write_then_read() {
        let mut w = NpzWriter::new();
        w.add("a", &[2, 3], &[1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        w.add("t", &[3], &[-1i64, 0, i64::MAX]).unwrap();
        w.add("m", &[2], &[7u16, 65535]).unwrap();
        let bytes = w.finish().unwrap();
        let npz = Npz::open("x.npz", bytes, Limits::default()).unwrap();
        assert_eq!(npz.names(), vec!["a", "m", "t"]);
        let a = npz.array_with_shape("a", &[None, Some(3)]).unwrap();
        assert_eq!(a.data, NpyData::F32(vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        assert_eq!(npz.array("t").unwrap().data, NpyData::Int(vec![-1, 0, i64::MAX]));
        assert_eq!(npz.array("m").unwrap().data, NpyData::Int(vec![7, 65535]));
        let err = npz.array_with_shape("a", &[Some(3), Some(2)]).unwrap_err().to_string();
        assert_eq!(err, "x.npz, field `a`: expected shape (3, 2), got shape [2, 3]");
        assert!(npz.array("zz").unwrap_err().to_string().contains("expected an array `zz`"));
    }

    fn npy(header: &str, data: &[u8]) -> Vec<u8> {
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn big_endian_fortran_and_malformed_headers() {
        let data: Vec<u8> = [1.0f64, 2.0, 3.0, 4.0, 5.0, 6.0].iter().flat_map(|x| x.to_be_bytes()).collect();
        let a = parse_npy(&npy("{'descr': '>f8', 'fortran_order': True, 'shape': (2, 3), }", &data)).unwrap();
        // Fortran order: column-major [[1, 3, 5], [2, 4, 6]].
        assert_eq!(a.data, NpyData::F64(vec![1.0, 3.0, 5.0, 2.0, 4.0, 6.0]));
        let i8s = parse_npy(&npy("{'descr': '|i1', 'fortran_order': False, 'shape': (2,), }", &[0xff, 3])).unwrap();
        assert_eq!(i8s.data, NpyData::Int(vec![-1, 3]));
        for (header, data, needle) in [
            ("{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296, 16), }", &[][..], "overflows"),
            ("{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000,), }", &[0u8; 8][..], "needs"),
            ("{'descr': '|O', 'fortran_order': False, 'shape': (1,), }", &[0u8; 8][..], "unsupported dtype"),
            ("{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (1,), }", &[0u8; 4][..], "structured"),
            ("{'descr': '<f4', 'shape': (1,), }", &[0u8; 4][..], "fortran_order"),
            ("{'descr': '<f4', 'fortran_order': False, 'shape': (x,), }", &[0u8; 4][..], "non-negative integer"),
        ] {
            let err = parse_npy(&npy(header, data)).unwrap_err();
            assert!(err.contains(needle), "{header}: {err}");
        }
        assert!(parse_npy(b"garbage").unwrap_err().contains("magic"));
    }
}
