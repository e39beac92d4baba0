//! What the workspace's integration tests share (a dev-dependency only): where the repository,
//! the test tools and the CMU data are.
//!
//! The tools come from `cargo xtask setup` (run by `cargo xtask test`): the venv `target/py`
//! from `tests/requirements.txt` and `tests/node_modules` from `tests/package-lock.json`,
//! passed in as `EGOEXO_PYTHON` and `EGOEXO_NODE_MODULES`. A test that needs one and finds
//! none fails and says how to install it; it never passes silently. The CMU data is the
//! exception: tests of it are skipped, with a message, where `shared/data/cmu` is absent.

use std::path::{Path, PathBuf};
use std::process::Command;

/// What a failing test says about the missing tools.
pub const SETUP_HINT: &str = "run `cargo xtask setup` (or `cargo xtask test`, which runs it) to install the test tools";

/// The repository root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The test venv's Python: `EGOEXO_PYTHON`, else `target/py` if `cargo xtask setup` made it.
/// Fails the test when there is none.
pub fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("EGOEXO_PYTHON") {
        return p.into();
    }
    let venv = workspace_root().join("target/py/bin/python");
    assert!(venv.exists(), "the Python test environment (target/py) is missing: {SETUP_HINT}");
    venv
}

/// `tests/node_modules` (`EGOEXO_NODE_MODULES`, else the default location), which must hold
/// the npm package `package`. Fails the test otherwise.
pub fn node_modules(package: &str) -> PathBuf {
    let dir = std::env::var_os("EGOEXO_NODE_MODULES")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("tests/node_modules"));
    assert!(dir.join(package).exists(), "{} has no {package}: {SETUP_HINT}", dir.display());
    dir
}

/// Runs a tool and returns its standard output; fails the test with the tool's standard
/// error when it cannot start or exits unsuccessfully.
pub fn run_tool(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}; {SETUP_HINT}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}):\n{}\n{}\n(if a module or package is missing: {SETUP_HINT})",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("UTF-8 output")
}

/// The CMU ASF/AMC folder with `CMU_data.csv` (`EGOEXO_CMU_DIR`, else `shared/data/cmu`
/// beside the repository), or `None` with a SKIPPED message when it is absent.
pub fn cmu_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("EGOEXO_CMU_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/data/cmu"));
    if dir.join("CMU_data.csv").is_file() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED: the CMU data is not at {} (set EGOEXO_CMU_DIR to the folder with CMU_data.csv)",
            dir.display()
        );
        None
    }
}

/// The extra CMU subjects (`EGOEXO_CMU_EXTRA_DIR`, else `shared/data/cmu-extra` beside the
/// repository: ASF/AMC and cgspeed BVH), or `None` with a SKIPPED message when absent.
pub fn cmu_extra_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("EGOEXO_CMU_EXTRA_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("../shared/data/cmu-extra"));
    if dir.join("bvh").is_dir() && dir.join("asfamc").is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED: the extra CMU data is not at {} (set EGOEXO_CMU_EXTRA_DIR to the folder with asfamc/ and bvh/)",
            dir.display()
        );
        None
    }
}

/// `len` deterministic pseudo-random bytes (xorshift64 from `seed`): test payloads that do
/// not compress and differ per seed.
pub fn pseudo_random_bytes(len: usize, seed: u64) -> Vec<u8> {
    let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..len)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect()
}

/// A line of code shown in `README.md` or `docs/*.md`.
#[derive(Clone, Debug)]
pub struct DocCodeLine {
    /// The document, relative to the repository root.
    pub file: PathBuf,
    /// Its line number (the first, for a line continued with `\`).
    pub line: usize,
    pub text: String,
}

/// Every line of a fenced code block (joined across `\` continuations) and every inline code
/// span of `README.md` and `docs/*.md` (in that order, `docs/` sorted): what the docs tell a
/// reader to type, for tests that check the commands exist.
pub fn doc_code_lines(root: &Path) -> Vec<DocCodeLine> {
    let mut files = vec![PathBuf::from("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|e| e.expect("a docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .filter_map(|p| p.strip_prefix(root).ok().map(Path::to_path_buf))
        .collect();
    docs.sort();
    files.extend(docs);
    let mut out = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(root.join(&file)).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let mut fenced = false;
        let mut pending: Option<(usize, String)> = None;
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                fenced = !fenced;
                continue;
            }
            if fenced {
                let (at, joined) = match pending.take() {
                    Some((at, before)) => (at, format!("{before} {}", line.trim())),
                    None => (n + 1, line.trim().to_string()),
                };
                match joined.strip_suffix('\\') {
                    Some(head) => pending = Some((at, head.to_string())),
                    None => out.push(DocCodeLine { file: file.clone(), line: at, text: joined }),
                }
            } else {
                for span in line.split('`').skip(1).step_by(2) {
                    out.push(DocCodeLine { file: file.clone(), line: n + 1, text: span.to_string() });
                }
            }
        }
    }
    out
}

/// The words of one command in a doc's code line, from `tokens` (already split on white
/// space, starting after the program): up to a shell separator, a comment or a redirection,
/// with backticks and trailing `,` / `)` of the surrounding prose trimmed.
pub fn command_words(tokens: &[&str]) -> Vec<String> {
    tokens
        .iter()
        .take_while(|t| !matches!(**t, "&&" | ";" | "|" | "#" | ">" | "2>&1"))
        .map(|t| t.trim_matches(|c| c == '`' || c == ',' || c == ')').to_string())
        .collect()
}
