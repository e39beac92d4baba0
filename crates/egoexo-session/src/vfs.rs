//! A read-only file tree that every importer works on: in-memory `name → bytes` (what the
//! browser hands its worker for a dropped folder), a zip archive in memory (a dropped `.zip` or
//! `.egoexo`), or — natively only — a directory or zip file on disk.
//!
//! Paths are relative, `/`-separated and normalised (`a/./b` → `a/b`). Entries whose path is
//! absolute, contains `..`, a drive letter or a NUL byte are rejected, never skipped. Reads
//! are capped by [`Limits`]: nothing is allocated from a size an archive declares without
//! checking it first, and a zip entry that inflates past the cap is an error.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::{Cursor, Read};
use std::sync::Arc;

use zip::ZipArchive;

use crate::error::{ImportError, ImportErrorKind, Location};

/// Safety caps for untrusted input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Most files a tree may hold.
    pub max_entries: usize,
    /// Largest single file, bytes (after decompression).
    pub max_file_bytes: u64,
}

impl Default for Limits {
    /// 100 000 files, 1 GiB per file (an hour of 1 kHz Aria trajectory is ~1 GB of CSV).
    fn default() -> Self {
        Self { max_entries: 100_000, max_file_bytes: 1 << 30 }
    }
}

/// Largest initial buffer reserved for one file before its bytes have been seen.
const MAX_PREALLOCATION: u64 = 16 << 20;

#[derive(Debug)]
enum Backend {
    Memory(BTreeMap<String, Vec<u8>>),
    Zip {
        archive: ZipArchive<Cursor<Arc<[u8]>>>,
        /// Normalised path → (entry index, declared uncompressed size).
        index: BTreeMap<String, (usize, u64)>,
    },
    #[cfg(not(target_arch = "wasm32"))]
    Directory {
        root: std::path::PathBuf,
        /// Normalised path → size on disk.
        files: BTreeMap<String, u64>,
    },
}

impl Backend {
    fn contains(&self, path: &str) -> bool {
        match self {
            Backend::Memory(files) => files.contains_key(path),
            Backend::Zip { index, .. } => index.contains_key(path),
            #[cfg(not(target_arch = "wasm32"))]
            Backend::Directory { files, .. } => files.contains_key(path),
        }
    }

    fn paths(&self) -> Box<dyn Iterator<Item = &str> + '_> {
        match self {
            Backend::Memory(files) => Box::new(files.keys().map(String::as_str)),
            Backend::Zip { index, .. } => Box::new(index.keys().map(String::as_str)),
            #[cfg(not(target_arch = "wasm32"))]
            Backend::Directory { files, .. } => Box::new(files.keys().map(String::as_str)),
        }
    }
}

/// A read-only tree of files (see the module docs). Cheap to clone; [`FileTree::view`]
/// narrows it to a sub-folder without copying.
#[derive(Clone, Debug)]
pub struct FileTree {
    name: String,
    backend: Arc<Backend>,
    /// `""` or `"dir/"`: the folder this view is rooted at.
    prefix: String,
    limits: Limits,
}

/// Normalises an entry path; `None` if it is unsafe (absolute, `..`, drive letter, NUL, empty).
pub fn normalize_path(raw: &str) -> Option<String> {
    if raw.contains('\0') {
        return None;
    }
    let unified = raw.replace('\\', "/");
    if unified.starts_with('/') {
        return None;
    }
    let mut parts = Vec::new();
    for (i, part) in unified.split('/').enumerate() {
        match part {
            "" | "." => continue,
            ".." => return None,
            p if i == 0 && p.len() >= 2 && p.as_bytes()[1] == b':' => return None,
            p => parts.push(p),
        }
    }
    if parts.is_empty() { None } else { Some(parts.join("/")) }
}

impl FileTree {
    /// A tree from in-memory files (a dropped folder). Paths are normalised and checked.
    pub fn from_files(
        name: impl Into<String>,
        files: impl IntoIterator<Item = (String, Vec<u8>)>,
        limits: Limits,
    ) -> Result<Self, ImportError> {
        let name = name.into();
        let mut map = BTreeMap::new();
        for (raw, bytes) in files {
            let Some(path) = normalize_path(&raw) else {
                return Err(ImportError::new(&name, Location::File, ImportErrorKind::UnsafePath { path: raw }));
            };
            if bytes.len() as u64 > limits.max_file_bytes {
                return Err(too_large(&path, bytes.len() as u64, limits.max_file_bytes));
            }
            if map.insert(path.clone(), bytes).is_some() {
                return Err(ImportError::invalid(&name, Location::Field(path), "unique file paths", "a duplicate"));
            }
            if map.len() > limits.max_entries {
                return Err(too_many_entries(&name, map.len() as u64, limits));
            }
        }
        Ok(Self { name, backend: Arc::new(Backend::Memory(map)), prefix: String::new(), limits })
    }

    /// A tree from the bytes of a zip archive (`.zip` or `.egoexo`). Only the central
    /// directory is read here; entries inflate on [`FileTree::read`].
    pub fn from_zip(name: impl Into<String>, bytes: impl Into<Arc<[u8]>>, limits: Limits) -> Result<Self, ImportError> {
        let name = name.into();
        let bytes: Arc<[u8]> = bytes.into();
        if bytes.is_empty() {
            return Err(ImportError::new(
                &name,
                Location::File,
                ImportErrorKind::Empty { expected: "a zip archive".into() },
            ));
        }
        let mut archive = ZipArchive::new(Cursor::new(bytes))
            .map_err(|e| ImportError::new(&name, Location::File, ImportErrorKind::Zip(e.to_string())))?;
        if archive.len() > limits.max_entries {
            return Err(too_many_entries(&name, archive.len() as u64, limits));
        }
        let mut index = BTreeMap::new();
        for i in 0..archive.len() {
            let entry = archive
                .by_index_raw(i)
                .map_err(|e| ImportError::new(&name, Location::File, ImportErrorKind::Zip(e.to_string())))?;
            let raw = String::from_utf8_lossy(entry.name_raw()).into_owned();
            if entry.is_dir() {
                if !raw.trim_matches('/').is_empty() && normalize_path(&raw).is_none() {
                    return Err(ImportError::new(&name, Location::File, ImportErrorKind::UnsafePath { path: raw }));
                }
                continue;
            }
            let Some(path) = normalize_path(&raw) else {
                return Err(ImportError::new(&name, Location::File, ImportErrorKind::UnsafePath { path: raw }));
            };
            if index.insert(path.clone(), (i, entry.size())).is_some() {
                return Err(ImportError::invalid(&name, Location::Field(path), "unique entry names", "a duplicate"));
            }
        }
        Ok(Self { name, backend: Arc::new(Backend::Zip { archive, index }), prefix: String::new(), limits })
    }

    /// The input's name (folder or file name), for messages.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The limits reads are checked against.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// The same tree narrowed to the folder `dir` (relative to this view).
    pub fn view(&self, dir: &str) -> Self {
        let dir = dir.trim_matches('/');
        let prefix = if dir.is_empty() { self.prefix.clone() } else { format!("{}{dir}/", self.prefix) };
        Self { name: self.name.clone(), backend: self.backend.clone(), prefix, limits: self.limits }
    }

    /// The folder this view is rooted at, relative to the tree's root (`""` or `"dir/"`).
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// A path relative to this view, as a path relative to the input's root (for messages).
    pub fn display_path(&self, path: &str) -> String {
        format!("{}{path}", self.prefix)
    }

    /// Whether the file exists (relative to this view).
    pub fn contains(&self, path: &str) -> bool {
        self.backend.contains(&self.display_path(path))
    }

    /// Whether the folder `dir` holds any file (relative to this view).
    pub fn contains_dir(&self, dir: &str) -> bool {
        let full = format!("{}{}/", self.prefix, dir.trim_matches('/'));
        self.backend.paths().any(|p| p.starts_with(&full))
    }

    /// Every file path in this view, relative to it, sorted.
    pub fn paths(&self) -> Vec<String> {
        self.backend.paths().filter_map(|p| p.strip_prefix(&self.prefix)).map(str::to_owned).collect()
    }

    /// Names of the immediate sub-folders of `dir` (`""` = this view's root), sorted.
    pub fn subdirs(&self, dir: &str) -> Vec<String> {
        let dir = dir.trim_matches('/');
        let full = if dir.is_empty() { self.prefix.clone() } else { format!("{}{dir}/", self.prefix) };
        let mut out: Vec<String> = self
            .backend
            .paths()
            .filter_map(|p| p.strip_prefix(&full))
            .filter_map(|rest| rest.split_once('/').map(|(first, _)| first.to_owned()))
            .collect();
        out.dedup();
        out
    }

    /// If every file lies in one top-level folder (a zipped or dropped folder), the view of
    /// that folder; otherwise this view.
    pub fn strip_single_root(&self) -> Self {
        let paths = self.paths();
        let mut top: Option<&str> = None;
        for p in &paths {
            match p.split_once('/') {
                None => return self.clone(),
                Some((first, _)) => match top {
                    None => top = Some(first),
                    Some(t) if t == first => {}
                    Some(_) => return self.clone(),
                },
            }
        }
        match top {
            Some(t) => self.view(t),
            None => self.clone(),
        }
    }

    /// The bytes of a file (relative to this view), checked against [`Limits::max_file_bytes`].
    pub fn read(&self, path: &str) -> Result<Cow<'_, [u8]>, ImportError> {
        let full = self.display_path(path);
        let limit = self.limits.max_file_bytes;
        match &*self.backend {
            Backend::Memory(files) => {
                files.get(&full).map(|b| Cow::Borrowed(b.as_slice())).ok_or_else(|| not_found(&full))
            }
            Backend::Zip { archive, index } => {
                let &(i, declared) = index.get(&full).ok_or_else(|| not_found(&full))?;
                if declared > limit {
                    return Err(too_large(&full, declared, limit));
                }
                let mut archive = archive.clone();
                let entry = archive
                    .by_index(i)
                    .map_err(|e| ImportError::new(&full, Location::File, ImportErrorKind::Zip(e.to_string())))?;
                let mut bytes = Vec::with_capacity(declared.min(MAX_PREALLOCATION) as usize);
                entry
                    .take(limit + 1)
                    .read_to_end(&mut bytes)
                    .map_err(|e| ImportError::new(&full, Location::File, ImportErrorKind::Zip(e.to_string())))?;
                if bytes.len() as u64 > limit {
                    return Err(too_large(&full, bytes.len() as u64, limit));
                }
                Ok(Cow::Owned(bytes))
            }
            #[cfg(not(target_arch = "wasm32"))]
            Backend::Directory { root, files } => {
                let &size = files.get(&full).ok_or_else(|| not_found(&full))?;
                if size > limit {
                    return Err(too_large(&full, size, limit));
                }
                let file = std::fs::File::open(root.join(&full))
                    .map_err(|e| ImportError::invalid(&full, Location::File, "a readable file", e.to_string()))?;
                let mut bytes = Vec::with_capacity(size.min(MAX_PREALLOCATION) as usize);
                file.take(limit + 1)
                    .read_to_end(&mut bytes)
                    .map_err(|e| ImportError::invalid(&full, Location::File, "a readable file", e.to_string()))?;
                if bytes.len() as u64 > limit {
                    return Err(too_large(&full, bytes.len() as u64, limit));
                }
                Ok(Cow::Owned(bytes))
            }
        }
    }

    /// The size of a file in bytes (declared size for zip entries), if it exists.
    pub fn size(&self, path: &str) -> Option<u64> {
        let full = self.display_path(path);
        match &*self.backend {
            Backend::Memory(files) => files.get(&full).map(|b| b.len() as u64),
            Backend::Zip { index, .. } => index.get(&full).map(|&(_, size)| size),
            #[cfg(not(target_arch = "wasm32"))]
            Backend::Directory { files, .. } => files.get(&full).copied(),
        }
    }

    /// A file as a stream (relative to this view), checked against [`Limits::max_file_bytes`]:
    /// files on disk are read as they are consumed, so a reader that keeps little holds
    /// little; memory and zip trees hand out their bytes.
    pub fn open_reader(&self, path: &str) -> Result<Box<dyn Read + '_>, ImportError> {
        #[cfg(not(target_arch = "wasm32"))]
        if let Backend::Directory { root, files } = &*self.backend {
            let full = self.display_path(path);
            let limit = self.limits.max_file_bytes;
            let &size = files.get(&full).ok_or_else(|| not_found(&full))?;
            if size > limit {
                return Err(too_large(&full, size, limit));
            }
            let file = std::fs::File::open(root.join(&full))
                .map_err(|e| ImportError::invalid(&full, Location::File, "a readable file", e.to_string()))?;
            return Ok(Box::new(std::io::BufReader::with_capacity(1 << 16, file.take(limit))));
        }
        Ok(Box::new(Cursor::new(self.read(path)?)))
    }

    /// Like [`FileTree::read`], as UTF-8 text.
    pub fn read_text(&self, path: &str) -> Result<Cow<'_, str>, ImportError> {
        let full = self.display_path(path);
        match self.read(path)? {
            Cow::Borrowed(b) => std::str::from_utf8(b).map(Cow::Borrowed).map_err(|e| not_utf8(&full, b, e)),
            Cow::Owned(b) => String::from_utf8(b).map(Cow::Owned).map_err(|e| {
                let err = e.utf8_error();
                not_utf8(&full, e.as_bytes(), err)
            }),
        }
    }
}

fn not_utf8(file: &str, bytes: &[u8], e: std::str::Utf8Error) -> ImportError {
    let line = bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count() as u64 + 1;
    ImportError::invalid(
        file,
        Location::Line(line),
        "UTF-8 text",
        format!("an invalid byte at offset {}", e.valid_up_to()),
    )
}

fn not_found(path: &str) -> ImportError {
    ImportError::missing_file(path, "this file in the session")
}

fn too_large(path: &str, size: u64, limit: u64) -> ImportError {
    ImportError::new(
        path,
        Location::File,
        ImportErrorKind::TooLarge { what: "the file size in bytes".into(), size, limit },
    )
}

fn too_many_entries(name: &str, count: u64, limits: Limits) -> ImportError {
    ImportError::new(
        name,
        Location::File,
        ImportErrorKind::TooLarge { what: "the number of files".into(), size: count, limit: limits.max_entries as u64 },
    )
}

#[cfg(not(target_arch = "wasm32"))]
mod native {
    use std::path::Path;

    use super::*;

    impl FileTree {
        /// Opens a directory, or a zip file (`.zip`, `.egoexo`, or anything starting with the
        /// zip signature), from disk. Symbolic links inside a directory are not followed.
        pub fn open(path: &Path, limits: Limits) -> Result<Self, ImportError> {
            let name = path.display().to_string();
            let meta = std::fs::metadata(path).map_err(|e| {
                ImportError::invalid(&name, Location::File, "an existing file or folder", e.to_string())
            })?;
            if meta.is_dir() {
                return Self::open_dir(path, limits);
            }
            if meta.len() > limits.max_file_bytes.saturating_mul(4) {
                return Err(too_large(&name, meta.len(), limits.max_file_bytes.saturating_mul(4)));
            }
            let bytes = std::fs::read(path)
                .map_err(|e| ImportError::invalid(&name, Location::File, "a readable file", e.to_string()))?;
            Self::from_zip(name, bytes, limits)
        }

        fn open_dir(root: &Path, limits: Limits) -> Result<Self, ImportError> {
            let name = root.display().to_string();
            let mut files = BTreeMap::new();
            let mut stack = vec![(root.to_path_buf(), String::new())];
            while let Some((dir, rel)) = stack.pop() {
                let entries = std::fs::read_dir(&dir).map_err(|e| {
                    ImportError::invalid(dir.display().to_string(), Location::File, "a readable folder", e.to_string())
                })?;
                for entry in entries {
                    let entry = entry.map_err(|e| {
                        ImportError::invalid(
                            dir.display().to_string(),
                            Location::File,
                            "a readable folder",
                            e.to_string(),
                        )
                    })?;
                    let file_name = entry.file_name().to_string_lossy().into_owned();
                    let rel_path = if rel.is_empty() { file_name.clone() } else { format!("{rel}/{file_name}") };
                    let meta = entry.path().symlink_metadata().map_err(|e| {
                        ImportError::invalid(&rel_path, Location::File, "a readable file", e.to_string())
                    })?;
                    if meta.is_dir() {
                        stack.push((entry.path(), rel_path));
                    } else if meta.is_file() {
                        files.insert(rel_path, meta.len());
                        if files.len() > limits.max_entries {
                            return Err(too_many_entries(&name, files.len() as u64, limits));
                        }
                    }
                }
            }
            Ok(Self {
                name,
                backend: Arc::new(Backend::Directory { root: root.to_path_buf(), files }),
                prefix: String::new(),
                limits,
            })
        }
    }

    /// Writes files under `root` (created if needed), refusing unsafe paths.
    pub fn write_dir(root: &Path, files: &BTreeMap<String, Vec<u8>>) -> std::io::Result<()> {
        for (path, bytes) in files {
            let Some(safe) = normalize_path(path) else {
                return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, format!("unsafe path `{path}`")));
            };
            let target = root.join(safe);
            if let Some(parent) = target.parent() {
                std::fs::create_dir_all(parent)?;
            }
            std::fs::write(target, bytes)?;
        }
        Ok(())
    }
}

#[cfg(not(target_arch = "wasm32"))]
pub use native::write_dir;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_reads_no_dropped_file_larger_than_an_importer_takes() {
        assert_eq!(Limits::default().max_file_bytes, egoexo_protocol::worker::MAX_DROPPED_FILE_BYTES);
    }

    fn tree(files: &[(&str, &str)]) -> FileTree {
        FileTree::from_files("t", files.iter().map(|(p, b)| (p.to_string(), b.as_bytes().to_vec())), Limits::default())
            .unwrap()
    }

    #[test]
    fn normalises_and_rejects_paths() {
        assert_eq!(normalize_path("a/./b//c").as_deref(), Some("a/b/c"));
        assert_eq!(normalize_path("a\\b").as_deref(), Some("a/b"));
        for bad in ["../x", "a/../../x", "/etc/passwd", "C:/x", "c:\\x", "", "a/\0", "./"] {
            assert_eq!(normalize_path(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn views_subdirs_and_single_root() {
        let t = tree(&[("s/wearer/a.csv", "1"), ("s/observers/o1/b.csv", "2"), ("s/observers/o2/c", "3")]);
        let s = t.strip_single_root();
        assert_eq!(s.prefix(), "s/");
        assert_eq!(s.subdirs(""), vec!["observers", "wearer"]);
        assert_eq!(s.subdirs("observers"), vec!["o1", "o2"]);
        let o1 = s.view("observers/o1");
        assert!(o1.contains("b.csv"));
        assert_eq!(o1.display_path("b.csv"), "s/observers/o1/b.csv");
        assert_eq!(&*o1.read("b.csv").unwrap(), b"2");
        assert!(o1.read("missing").unwrap_err().to_string().contains("s/observers/o1/missing"));
        assert!(s.contains_dir("wearer") && !s.contains_dir("wear"));
    }

    #[test]
    fn zip_round_trip_and_limits() {
        let mut files = BTreeMap::new();
        files.insert("dir/a.txt".to_string(), b"hello".repeat(100));
        files.insert("b.bin".to_string(), vec![1, 2, 3]);
        let bytes = egoexo_motion_io::npz::write_zip(&files).unwrap();
        let t = FileTree::from_zip("x.zip", bytes.clone(), Limits::default()).unwrap();
        assert_eq!(t.paths(), vec!["b.bin", "dir/a.txt"]);
        assert_eq!(&*t.read("dir/a.txt").unwrap(), &files["dir/a.txt"][..]);
        let small = FileTree::from_zip("x.zip", bytes, Limits { max_entries: 10, max_file_bytes: 10 }).unwrap();
        let err = small.read("dir/a.txt").unwrap_err();
        assert!(matches!(*err.kind, ImportErrorKind::TooLarge { size: 500, limit: 10, .. }), "{err}");
    }
}
