//! Zip containers: a dropped `.zip` / `.egoexo` through recognition, every importer, npz
//! decoding and alignment.
#![no_main]

use egoexo_session::align::{AlignOptions, align};
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::npz::Npz;
use egoexo_session::{FileTree, Limits};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let limits = Limits { max_entries: 1_000, max_file_bytes: 16 << 20 };
    let Ok(tree) = FileTree::from_zip("f.zip", data.to_vec(), limits) else { return };
    if let Ok(imported) = import_session(&tree, &ImportOptions::default()) {
        let options = AlignOptions { max_frames: 100_000, ..AlignOptions::default() };
        let _ = align(&imported.session, &options);
        let _ = egoexo_session::format::write_egoexo_zip(&imported.session);
    }
    // The archive as an npz.
    if let Ok(npz) = Npz::open("f.npz", data.to_vec(), limits) {
        for name in npz.names().into_iter().take(16) {
            let _ = npz.array(&name);
        }
    }
});
