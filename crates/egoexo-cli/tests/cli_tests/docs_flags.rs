//! Every `egoexo` command line in `README.md` and `docs/*.md` names subcommands and flags the
//! CLI has: the docs are parsed for command lines (fenced blocks and inline code), and each
//! subcommand's `--help` is asked for its flags.

use std::collections::BTreeMap;
use std::path::PathBuf;

use egoexo_test_support::{command_words, doc_code_lines, workspace_root};

use crate::common::egoexo;

/// The arguments after the program in a command line that runs `egoexo`: `egoexo …`,
/// `…/egoexo …` or `cargo run … -p egoexo-cli -- …`; `None` for any other text.
fn egoexo_args(text: &str) -> Option<Vec<String>> {
    let tokens: Vec<&str> = text.split_whitespace().collect();
    let start = if let Some(i) = tokens.iter().position(|t| *t == "egoexo-cli") {
        // `cargo run --release -p egoexo-cli -- <args>`
        tokens[i..].iter().position(|t| *t == "--").map(|d| i + d + 1)?
    } else {
        let i = tokens.iter().position(|t| *t == "egoexo" || t.ends_with("/egoexo"))?;
        // Only as the program: at the start, or after a shell's `$`, `&&`, `;` or `|`.
        let program = i == 0 || matches!(tokens[i - 1], "$" | "&&" | ";" | "|");
        if !program {
            return None;
        }
        i + 1
    };
    let args = command_words(&tokens[start..]);
    (!args.is_empty()).then_some(args)
}

/// One `egoexo …` command line of a document.
#[derive(Debug)]
struct DocCommand {
    file: PathBuf,
    line: usize,
    args: Vec<String>,
}

/// What `egoexo <path> --help` says: its subcommands and its flags.
#[derive(Debug, Default)]
struct Help {
    subcommands: Vec<String>,
    flags: Vec<String>,
}

fn help<'c>(path: &[String], cache: &'c mut BTreeMap<Vec<String>, Option<Help>>) -> Option<&'c Help> {
    cache
        .entry(path.to_vec())
        .or_insert_with(|| {
            let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
            args.push("--help");
            let out = egoexo(&args);
            if !out.status.success() {
                return None;
            }
            let text = String::from_utf8_lossy(&out.stdout).into_owned();
            let mut help = Help::default();
            let mut in_commands = false;
            for line in text.lines() {
                if line.starts_with("Commands:") {
                    in_commands = true;
                    continue;
                }
                if !line.starts_with(' ') {
                    in_commands = false;
                }
                if in_commands && let Some(name) = line.split_whitespace().next() {
                    help.subcommands.push(name.to_string());
                }
                for word in line.split(|c: char| c.is_whitespace() || c == ',' || c == '[' || c == ']') {
                    if let Some(flag) = word.strip_prefix("--") {
                        let flag = flag.split(['=', '<']).next().unwrap_or_default();
                        if !flag.is_empty() {
                            help.flags.push(flag.to_string());
                        }
                    }
                }
            }
            Some(help)
        })
        .as_ref()
}

#[test]
fn every_egoexo_flag_in_the_readme_and_docs_exists() {
    let root = workspace_root();
    let commands: Vec<DocCommand> = doc_code_lines(&root)
        .into_iter()
        .filter_map(|l| egoexo_args(&l.text).map(|args| DocCommand { file: l.file, line: l.line, args }))
        .collect();
    assert!(commands.len() >= 30, "only {} egoexo command lines found in the docs", commands.len());
    let mut cache = BTreeMap::new();
    let mut wrong = Vec::new();
    let mut flags_checked = 0;
    for command in &commands {
        // The subcommand path: leading words the CLI knows as subcommands.
        let mut path: Vec<String> = Vec::new();
        for arg in &command.args {
            let known = help(&path, &mut cache).is_some_and(|h| h.subcommands.iter().any(|s| s == arg));
            if !known {
                break;
            }
            path.push(arg.clone());
        }
        let place = format!("{}:{}", command.file.display(), command.line);
        let Some(first) = command.args.first() else { continue };
        if path.is_empty() && !first.starts_with('-') && !first.starts_with('<') {
            wrong.push(format!("{place}: `egoexo {first}` is no subcommand"));
            continue;
        }
        let known_flags = help(&path, &mut cache).map(|h| h.flags.clone()).unwrap_or_default();
        for arg in &command.args[path.len()..] {
            let Some(flag) = arg.strip_prefix("--") else { continue };
            let flag = flag.split('=').next().unwrap_or_default();
            if flag.is_empty() || !flag.chars().all(|c| c.is_ascii_alphanumeric() || c == '-') {
                continue;
            }
            flags_checked += 1;
            if !known_flags.iter().any(|k| k == flag) {
                wrong.push(format!("{place}: `egoexo {}` has no --{flag}", path.join(" ")));
            }
        }
    }
    eprintln!("{} command lines, {flags_checked} flags checked", commands.len());
    assert!(wrong.is_empty(), "the docs name what the CLI does not have:\n{}", wrong.join("\n"));
}
