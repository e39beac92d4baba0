//! The web app's build: both wasm modules (`+simd128` from `.cargo/config.toml`) with the
//! shipped profile `wasm-dist` (LTO, size-optimised, function names stripped) or the tests'
//! `wasm-release`, wasm-bindgen `--target web`, wasm-opt on request, and `dist/` assembled from
//! `web/`, `public/`, the models and the generated `pkg/`.

use std::hash::{DefaultHasher, Hash, Hasher};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

use crate::{cmd, tools};

/// The Cargo profile of the tests' browser modules (release without debug info; see
/// Cargo.toml). The worker's wasm tests build with it too, so they reuse the compiled
/// dependencies.
pub const WASM_PROFILE: &str = "wasm-release";
/// The Cargo profile of the shipped browser modules (LTO, dependencies at opt-level `z`).
pub const WASM_DIST_PROFILE: &str = "wasm-dist";

/// Which build of the modules `dist/` gets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WasmBuild {
    /// What users download: [`WASM_DIST_PROFILE`], the name section stripped.
    Shipped,
    /// What the tests run: [`WASM_PROFILE`] (function names kept for stack traces), built
    /// here, each module with its own crate's features.
    Tests,
    /// [`WASM_PROFILE`]'s modules as the wasm test build left them (`cargo xtask test` builds
    /// every wasm test in one invocation, which builds both modules too, with the features of
    /// all those tests together): nothing is compiled here.
    BuiltByWasmTests,
}

impl WasmBuild {
    pub fn profile(self) -> &'static str {
        match self {
            Self::Shipped => WASM_DIST_PROFILE,
            Self::Tests | Self::BuiltByWasmTests => WASM_PROFILE,
        }
    }
}
pub const WASM_TARGET: &str = "wasm32-unknown-unknown";

/// The browser crates: (package, library name). Each is its own wasm module.
pub const MODULES: &[(&str, &str)] = &[("egoexo-web-worker", "egoexo_web_worker"), ("egoexo-viewer", "egoexo_viewer")];

/// Where the models come from, in order: `--models`, `EGOEXO_MODELS`, `models/`.
pub fn models_dir(root: &Path, given: Option<&Path>) -> Result<PathBuf> {
    let (dir, how) = match (given, std::env::var_os("EGOEXO_MODELS")) {
        (Some(dir), _) => (dir.to_path_buf(), "--models"),
        (None, Some(dir)) => (PathBuf::from(dir), "EGOEXO_MODELS"),
        (None, None) => (root.join("models"), "the default"),
    };
    if !dir.join("manifest.json").is_file() {
        bail!(
            "{}/manifest.json not found ({how}): the app needs the trained models (manifest.json + \
             ONNX files, committed to models/). For development, point at another models folder with \
             --models DIR or EGOEXO_MODELS=DIR, e.g. the untrained fixture \
             crates/egoexo-infer/tests/fixtures/models",
            dir.display()
        );
    }
    Ok(dir)
}

/// Whether to run wasm-opt (off by default: on the LTO build its output is smaller raw but
/// larger gzipped, see docs/performance.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WasmOpt {
    /// When a current wasm-opt is found (npm `binaryen` in tests/node_modules, or on PATH).
    IfAvailable,
    Off,
}

/// Size of one built module.
#[derive(Clone, Debug)]
pub struct ModuleSize {
    pub file: String,
    pub raw: u64,
    pub gzipped: u64,
    pub optimised: bool,
}

/// Builds both modules and assembles `dist/`. Returns the module sizes.
pub fn build_dist(root: &Path, models: &Path, build: WasmBuild, wasm_opt: WasmOpt) -> Result<Vec<ModuleSize>> {
    let wasm_bindgen = tools::ensure_wasm_bindgen(root)?;
    let wasm_opt = match wasm_opt {
        WasmOpt::IfAvailable => find_wasm_opt(root),
        WasmOpt::Off => None,
    };
    if wasm_opt.is_none() && build != WasmBuild::Shipped {
        eprintln!("note: the tests' build of the wasm modules (profile {WASM_PROFILE}), not the shipped one");
    }
    let pkg = root.join("target").join("web").join("pkg");
    std::fs::create_dir_all(&pkg)?;
    let mut sizes = Vec::new();
    for (package, lib) in MODULES {
        let wasm = if build == WasmBuild::BuiltByWasmTests {
            let wasm = module_built_by_tests(root, lib);
            if !wasm.is_file() {
                bail!("{} is missing: the wasm test build did not make it", wasm.display());
            }
            wasm
        } else {
            build_module(package, build.profile())?;
            root.join("target").join(WASM_TARGET).join(build.profile()).join(format!("{lib}.wasm"))
        };
        cmd::run(
            Command::new(&wasm_bindgen).arg(&wasm).args(["--target", "web", "--no-typescript", "--out-dir"]).arg(&pkg),
        )?;
        let module = pkg.join(format!("{lib}_bg.wasm"));
        if build == WasmBuild::Shipped {
            let bytes = std::fs::read(&module).with_context(|| format!("reading {}", module.display()))?;
            let stripped = strip_custom_sections(&bytes, STRIPPED_SECTIONS)
                .with_context(|| format!("stripping {}", module.display()))?;
            std::fs::write(&module, stripped)?;
        }
        let optimised = match &wasm_opt {
            Some(tool) => {
                optimise(root, tool, &module)?;
                true
            }
            None => false,
        };
        let bytes = std::fs::read(&module).with_context(|| format!("reading {}", module.display()))?;
        sizes.push(ModuleSize {
            file: format!("pkg/{lib}_bg.wasm"),
            raw: bytes.len() as u64,
            gzipped: gzipped_len(&bytes)?,
            optimised,
        });
    }
    assemble(root, models, &pkg)?;
    // The models the page downloads (every file the manifest lists), for the same table.
    let manifest = std::fs::read(models.join("manifest.json"))?;
    for file in model_files(&manifest)? {
        let bytes = std::fs::read(models.join(&file)).with_context(|| format!("reading models/{file}"))?;
        sizes.push(ModuleSize {
            file: format!("models/{file}"),
            raw: bytes.len() as u64,
            gzipped: gzipped_len(&bytes)?,
            optimised: false,
        });
    }
    Ok(sizes)
}

/// Where a test build leaves the module `lib` (a `cdylib` built as the library of an
/// integration test is not copied up from `deps/`, as `cargo build` does).
pub fn module_built_by_tests(root: &Path, lib: &str) -> PathBuf {
    root.join("target").join(WASM_TARGET).join(WASM_PROFILE).join("deps").join(format!("{lib}.wasm"))
}

/// `cargo build` of one browser crate (one invocation per crate, so each crate's dependency
/// features are the same as in its own test build and nothing is rebuilt between them).
pub fn build_module(package: &str, profile: &str) -> Result<()> {
    cmd::run(Command::new("cargo").args(["build", "--profile", profile, "--target", WASM_TARGET, "-p", package]))
}

/// Custom sections the shipped modules drop: function names (a sixth of the worker's bytes;
/// panics still say file and line) and the toolchain list.
const STRIPPED_SECTIONS: &[&str] = &["name", "producers"];

/// `module` without the custom sections named in `names` (everything else byte for byte).
pub fn strip_custom_sections(module: &[u8], names: &[&str]) -> Result<Vec<u8>> {
    fn leb128(bytes: &[u8], at: &mut usize) -> Result<usize> {
        let mut value = 0usize;
        for shift in (0..35).step_by(7) {
            let byte = *bytes.get(*at).context("a LEB128 number runs past the end")?;
            *at += 1;
            value |= usize::from(byte & 0x7f) << shift;
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        bail!("a LEB128 number is longer than 5 bytes")
    }
    if module.get(..4) != Some(&b"\0asm"[..]) || module.len() < 8 {
        bail!("not a wasm module (no \\0asm header)");
    }
    let mut out = module[..8].to_vec();
    let mut at = 8;
    while at < module.len() {
        let start = at;
        let id = module[at];
        at += 1;
        let size = leb128(module, &mut at)?;
        let end = at.checked_add(size).filter(|&e| e <= module.len()).context("a section runs past the end")?;
        let drop = id == 0 && {
            let mut name_at = at;
            let len = leb128(module, &mut name_at)?;
            module.get(name_at..name_at + len).is_some_and(|n| names.iter().any(|w| w.as_bytes() == n))
        };
        if !drop {
            out.extend_from_slice(&module[start..end]);
        }
        at = end;
    }
    Ok(out)
}

/// wasm-opt's flags: size-optimised, with the wasm features rustc emits for wasm32 today
/// (Debian's old binaryen breaks reference types; npm `binaryen` is current).
const WASM_OPT_FLAGS: &[&str] = &[
    "-O3",
    "--enable-simd",
    "--enable-reference-types",
    "--enable-bulk-memory",
    "--enable-nontrapping-float-to-int",
    "--enable-sign-ext",
    "--enable-mutable-globals",
    "--enable-multivalue",
];

/// A wasm-opt from npm `binaryen` (tests/node_modules) or PATH, version 116 or later.
fn find_wasm_opt(root: &Path) -> Option<PathBuf> {
    let npm = root.join("tests").join("node_modules").join(".bin").join("wasm-opt");
    [Some(npm), tools::find_on_path("wasm-opt")].into_iter().flatten().find(|tool| {
        let version = cmd::output(Command::new(tool).arg("--version")).unwrap_or_default();
        // "wasm-opt version 123 (version_123)"
        let number = version.split_whitespace().nth(2).and_then(|v| v.parse::<u32>().ok());
        number.is_some_and(|n| n >= 116)
    })
}

/// Runs wasm-opt on `module` in place; the result is cached by the input's hash (wasm-opt
/// takes minutes on the worker module).
fn optimise(root: &Path, tool: &Path, module: &Path) -> Result<()> {
    let input = std::fs::read(module)?;
    let mut hasher = DefaultHasher::new();
    input.hash(&mut hasher);
    WASM_OPT_FLAGS.hash(&mut hasher);
    let key = format!("{:016x}", hasher.finish());
    let cache = root.join("target").join("web").join("wasm-opt");
    std::fs::create_dir_all(&cache)?;
    let name = module.file_name().context("module file name")?.to_string_lossy().into_owned();
    let cached = cache.join(format!("{name}.{key}"));
    if !cached.is_file() {
        for old in std::fs::read_dir(&cache)? {
            let old = old?.path();
            if old.file_name().is_some_and(|n| n.to_string_lossy().starts_with(&format!("{name}."))) {
                std::fs::remove_file(old)?;
            }
        }
        let partial = cache.join(format!("{name}.partial"));
        cmd::run(Command::new(tool).arg(module).args(WASM_OPT_FLAGS).arg("-o").arg(&partial))?;
        std::fs::rename(&partial, &cached)?;
    }
    std::fs::copy(&cached, module)?;
    Ok(())
}

fn gzipped_len(bytes: &[u8]) -> Result<u64> {
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    encoder.write_all(bytes)?;
    Ok(encoder.finish()?.len() as u64)
}

/// Files of `web/` served at the site's root (everything else is a versioned asset).
const ROOT_FILES: &[&str] = &["index.html", "bench.html", "xr.html", "observe.html", "config.json"];

/// `dist/` as a static site:
///
/// ```text
/// dist/index.html, bench.html,   the pages (no-cache), their asset URLs rewritten to v/<build>/
///      xr.html, observe.html
/// dist/config.json              the page's deployment settings (no-cache, editable in place)
/// dist/v/<build>/               web/ (scripts, styles, icon) + public/ + models/ + pkg/
/// ```
///
/// `<build>` is a hash of every asset, so assets are immutable under their URL (the server
/// says so in `Cache-Control`) and a new build never mixes with an old one in a cache.
fn assemble(root: &Path, models: &Path, pkg: &Path) -> Result<()> {
    let dist = root.join("dist");
    if dist.exists() {
        std::fs::remove_dir_all(&dist).with_context(|| format!("clearing {}", dist.display()))?;
    }
    let staging = dist.join("v").join("staging");
    copy_tree_except(&root.join("web"), &staging, ROOT_FILES)?;
    copy_tree_except(&root.join("public"), &staging, &[])?;
    copy_tree_except(pkg, &staging.join("pkg"), &[])?;
    let manifest = std::fs::read(models.join("manifest.json"))?;
    let listed = model_files(&manifest).with_context(|| format!("reading {}/manifest.json", models.display()))?;
    let out = staging.join("models");
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("manifest.json"), &manifest)?;
    for file in listed {
        let from = models.join(&file);
        let to = out.join(&file);
        std::fs::create_dir_all(to.parent().context("model path")?)?;
        std::fs::copy(&from, &to).with_context(|| format!("copying {} (listed in manifest.json)", from.display()))?;
    }
    for entry in std::fs::read_dir(models)? {
        let path = entry?.path();
        if path.extension().is_some_and(|e| e == "md") {
            std::fs::copy(&path, out.join(path.file_name().context("file name")?))?;
        }
    }
    // onnxruntime-web's wasm backend for the bench page's engine comparison
    // (`web/bench-networks.js`); the app never loads it. From tests/node_modules when installed.
    let ort = root.join("tests").join("node_modules").join("onnxruntime-web").join("dist");
    if ort.is_dir() {
        let vendor = staging.join("vendor").join("onnxruntime-web");
        std::fs::create_dir_all(&vendor)?;
        for file in ORT_FILES {
            std::fs::copy(ort.join(file), vendor.join(file))
                .with_context(|| format!("copying {file} from {}", ort.display()))?;
        }
    }
    let build = tree_hash(&staging)?;
    let assets = dist.join("v").join(&build);
    std::fs::rename(&staging, &assets)?;
    for name in ROOT_FILES {
        let from = root.join("web").join(name);
        let to = dist.join(name);
        if name.ends_with(".html") {
            let html = std::fs::read_to_string(&from).with_context(|| format!("reading {}", from.display()))?;
            std::fs::write(&to, versioned_html(&html, &format!("v/{build}/")))?;
        } else {
            std::fs::copy(&from, &to).with_context(|| format!("copying {}", from.display()))?;
        }
    }
    eprintln!("dist/ assembled, assets under dist/v/{build}/");
    Ok(())
}

/// The files of npm `onnxruntime-web` its wasm-only entry point loads (one-thread SIMD).
const ORT_FILES: [&str; 3] = ["ort.wasm.min.mjs", "ort-wasm-simd-threaded.mjs", "ort-wasm-simd-threaded.wasm"];

/// A hash of every file under `dir` (relative paths and contents), as 16 hex digits.
fn tree_hash(dir: &Path) -> Result<String> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d)? {
            let path = entry?.path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut hasher = DefaultHasher::new();
    for file in files {
        file.strip_prefix(dir)?.to_string_lossy().hash(&mut hasher);
        std::fs::read(&file)?.hash(&mut hasher);
    }
    Ok(format!("{:016x}", hasher.finish()))
}

/// `html` with every relative `src="…"` and `href="…"` prefixed by `prefix`.
fn versioned_html(html: &str, prefix: &str) -> String {
    let mut out = String::with_capacity(html.len() + 256);
    let mut rest = html;
    while let Some(at) = ["src=\"", "href=\""].iter().filter_map(|a| rest.find(a).map(|i| (i, a.len()))).min() {
        let (index, len) = at;
        out.push_str(&rest[..index + len]);
        rest = &rest[index + len..];
        let absolute = ["/", "#", "http:", "https:", "data:", "mailto:"].iter().any(|p| rest.starts_with(p));
        if !absolute {
            out.push_str(prefix);
        }
    }
    out.push_str(rest);
    out
}

/// The model files a manifest lists (`model_sets[].{egonet,gate,fusion}.file`, and the
/// optional `detector.file.file` the worker fetches when a session has observer video);
/// paths must stay inside the models folder.
fn model_files(manifest: &[u8]) -> Result<Vec<String>> {
    let value: serde_json::Value = serde_json::from_slice(manifest)?;
    let sets = value["model_sets"].as_array().context("no `model_sets` array")?;
    let mut files = Vec::new();
    for set in sets {
        // `fusion_ego_only` is optional (sets exported before it have none).
        for network in ["egonet", "gate", "fusion", "fusion_ego_only"] {
            if network == "fusion_ego_only" && set.get(network).is_none() {
                continue;
            }
            let file = set[network]["file"].as_str().with_context(|| format!("no `{network}.file`"))?;
            files.push(file.to_string());
        }
    }
    if let Some(detector) = value.get("detector") {
        let file = detector["file"]["file"].as_str().context("no `detector.file.file`")?;
        files.push(file.to_string());
    }
    for file in &files {
        if file.starts_with('/') || file.split(['/', '\\']).any(|p| p == "..") {
            bail!("model file `{file}` leaves the models folder");
        }
    }
    Ok(files)
}

/// Copies the tree `from` into `to`, leaving out the top-level files named in `except`.
fn copy_tree_except(from: &Path, to: &Path, except: &[&str]) -> Result<()> {
    std::fs::create_dir_all(to)?;
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if except.iter().any(|n| entry.file_name() == *n) {
            continue;
        }
        if entry.file_type()?.is_dir() {
            copy_tree_except(&entry.path(), &target, &[])?;
        } else {
            std::fs::copy(entry.path(), &target)
                .with_context(|| format!("copying {} to {}", entry.path().display(), target.display()))?;
        }
    }
    Ok(())
}

/// Prints the module and model sizes, and the models' total.
pub fn print_sizes(sizes: &[ModuleSize]) {
    let models = sizes.iter().filter(|s| s.file.starts_with("models/"));
    let (raw, gzipped) = models.fold((0, 0), |(r, g), s| (r + s.raw, g + s.gzipped));
    for s in sizes {
        println!(
            "{:<34} {:>6.2} MB raw, {:>5.2} MB gzipped{}",
            s.file,
            s.raw as f64 / 1e6,
            s.gzipped as f64 / 1e6,
            if s.optimised { " (wasm-opt)" } else { "" }
        );
    }
    if raw > 0 {
        println!("{:<34} {:>6.2} MB raw, {:>5.2} MB gzipped", "models (total)", raw as f64 / 1e6, gzipped as f64 / 1e6);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_files_come_from_every_set_and_stay_inside() {
        let manifest = br#"{"model_sets": [
            {"egonet": {"file": "1pt/egonet.onnx"}, "gate": {"file": "1pt/gate.onnx"}, "fusion": {"file": "1pt/fusion.onnx"}},
            {"egonet": {"file": "3pt/egonet.onnx"}, "gate": {"file": "3pt/gate.onnx"}, "fusion": {"file": "3pt/fusion.onnx"},
             "fusion_ego_only": {"file": "3pt/fusion_ego_only.onnx"}}
        ]}"#;
        let files = model_files(manifest).unwrap();
        assert_eq!(files.len(), 7);
        assert_eq!(files[3], "3pt/egonet.onnx");
        assert_eq!(files[6], "3pt/fusion_ego_only.onnx");
        let escaping =
            br#"{"model_sets": [{"egonet": {"file": "../secret"}, "gate": {"file": "g"}, "fusion": {"file": "f"}}]}"#;
        assert!(model_files(escaping).unwrap_err().to_string().contains("leaves the models folder"));
        assert!(model_files(b"{}").is_err());
    }

    #[test]
    fn pages_point_at_the_versioned_assets() {
        let html = r##"<link rel="stylesheet" href="style.css"><link rel="icon" href="favicon.svg">
<a href="https://egoexo.example/">x</a><a href="#top">t</a><script type="module" src="main.js"></script>
<link rel="modulepreload" href="pkg/egoexo_viewer.js">"##;
        let out = versioned_html(html, "v/0123/");
        assert!(out.contains(r#"href="v/0123/style.css""#) && out.contains(r#"href="v/0123/favicon.svg""#));
        assert!(out.contains(r#"src="v/0123/main.js""#) && out.contains(r#"href="v/0123/pkg/egoexo_viewer.js""#));
        assert!(out.contains(r#"href="https://egoexo.example/""#) && out.contains(r##"href="#top""##));
    }

    #[test]
    fn every_page_at_the_root_exists_and_the_xr_page_points_at_versioned_assets() {
        let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("web");
        for name in ROOT_FILES {
            assert!(web.join(name).is_file(), "web/{name} is listed in ROOT_FILES but missing");
        }
        let xr = versioned_html(&std::fs::read_to_string(web.join("xr.html")).unwrap(), "v/0123/");
        assert!(xr.contains(r#"src="v/0123/xr.js""#) && xr.contains(r#"href="v/0123/xr.css""#), "{xr}");
        assert!(xr.contains(r#"href="v/0123/pkg/egoexo_web_worker.js""#), "{xr}");
    }

    #[test]
    fn a_missing_models_folder_says_what_to_do() {
        let err = models_dir(Path::new("/nonexistent"), Some(Path::new("/nonexistent/models"))).unwrap_err();
        let message = err.to_string();
        assert!(message.contains("/nonexistent/models/manifest.json not found (--models)"), "{message}");
        assert!(message.contains("EGOEXO_MODELS"), "{message}");
    }
}
