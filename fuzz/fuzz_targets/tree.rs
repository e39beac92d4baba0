//! Whole importers over an in-memory file tree (what the browser builds from a dropped folder).
//! Unlike `zip`, file contents are not behind CRCs, so mutations reach the manifest, npz,
//! CSV and JSON readers and the importers' cross-file logic. Input: files as
//! `@@@ <path>\n<content>` segments, each starting a line.
#![no_main]

use egoexo_session::align::{AlignOptions, align};
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::{FileTree, Limits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Segments start at "\n@@@ " (the input's start counts as a line start).
    const MARK: &[u8] = b"\n@@@ ";
    let buf = [b"\n", data].concat();
    let starts: Vec<usize> = buf.windows(MARK.len()).enumerate().filter(|(_, w)| *w == MARK).map(|(i, _)| i).collect();
    let mut files = Vec::new();
    for (k, &start) in starts.iter().enumerate() {
        let end = starts.get(k + 1).copied().unwrap_or(buf.len());
        let segment = &buf[start + MARK.len()..end];
        let (name, content) = match segment.iter().position(|&b| b == b'\n') {
            Some(i) => (&segment[..i], &segment[i + 1..]),
            None => (segment, &[][..]),
        };
        files.push((String::from_utf8_lossy(name).into_owned(), content.to_vec()));
    }
    let limits = Limits { max_entries: 200, max_file_bytes: 4 << 20 };
    let Ok(tree) = FileTree::from_files("fuzz", files, limits) else { return };
    if let Ok(imported) = import_session(&tree, &ImportOptions::default()) {
        let _ = align(&imported.session, &AlignOptions { max_frames: 100_000, ..AlignOptions::default() });
        let _ = egoexo_session::format::write_egoexo_zip(&imported.session);
    }
});
