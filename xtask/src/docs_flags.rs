//! Every `cargo xtask` command line in `README.md` and `docs/*.md` names a subcommand and
//! flags `cargo xtask` has (asked of its clap definition). The `egoexo` CLI's are checked by
//! `egoexo-cli`'s `cli_tests::docs_flags`.

use clap::CommandFactory;
use egoexo_test_support::{command_words, doc_code_lines, workspace_root};

use crate::Cli;

/// The arguments after `cargo xtask` in a line that runs it.
fn xtask_args(text: &str) -> Option<Vec<String>> {
    let tokens: Vec<&str> = text.split_whitespace().collect();
    let at = tokens.windows(2).position(|w| w == ["cargo", "xtask"])?;
    let args = command_words(&tokens[at + 2..]);
    (!args.is_empty()).then_some(args)
}

#[test]
fn every_xtask_flag_in_the_readme_and_docs_exists() {
    let root = workspace_root();
    let cli = Cli::command();
    let mut lines = 0;
    let mut wrong = Vec::new();
    for line in doc_code_lines(&root) {
        let Some(args) = xtask_args(&line.text) else { continue };
        lines += 1;
        let place = format!("{}:{}", line.file.display(), line.line);
        let Some(sub) = cli.find_subcommand(&args[0]) else {
            wrong.push(format!("{place}: `cargo xtask {}` is no subcommand", args[0]));
            continue;
        };
        for flag in args[1..].iter().filter_map(|a| a.strip_prefix("--")) {
            let flag = flag.split('=').next().unwrap_or_default();
            let known = flag == "help" || sub.get_arguments().any(|a| a.get_long() == Some(flag));
            if !known {
                wrong.push(format!("{place}: `cargo xtask {}` has no --{flag}", args[0]));
            }
        }
    }
    assert!(lines >= 10, "only {lines} `cargo xtask` lines found in the docs");
    assert!(wrong.is_empty(), "the docs name what cargo xtask does not have:\n{}", wrong.join("\n"));
}
