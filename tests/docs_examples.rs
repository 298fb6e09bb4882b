//! The command examples of README.md and docs/*.md: each is either run here, as a `trycmd` case
//! of `tests/cmd/` (its output checked where it is stable), or listed in `tests/cmd/not-run.txt`
//! with the reason it cannot run on a test machine (hardware, a peer, a program running until
//! Ctrl-C). A page that adds or changes an example fails here until its case or its reason is
//! written; a case or reason no page has any more fails too.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn the_runnable_examples_run_as_the_pages_say() {
    trycmd::TestCases::new()
        .register_bin("seabus", Path::new(env!("CARGO_BIN_EXE_seabus")))
        .case("tests/cmd/*.toml");
}

/// The `seabus …` command lines in the fenced code blocks of `page`: continuation lines joined,
/// comments (` # …`) and surrounding space taken off.
fn examples(page: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(page).expect("the page reads");
    let mut out = Vec::new();
    let mut fenced = false;
    let mut pending: Option<String> = None;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            continue;
        }
        let line = match pending.take() {
            Some(start) => format!("{start} {}", line.trim()),
            None if line.trim_start().starts_with("seabus ") => line.trim().to_string(),
            None => continue,
        };
        if let Some(start) = line.strip_suffix('\\') {
            pending = Some(start.trim_end().to_string());
            continue;
        }
        let command = match line.find(" #") {
            Some(at) => &line[..at],
            None => &line[..],
        };
        let command = command.split_whitespace().collect::<Vec<_>>().join(" ");
        // a command, not a name in a diagram (`seabus  (src/: …)`)
        if command
            .split(' ')
            .nth(1)
            .is_some_and(|w| w.chars().all(|c| c.is_ascii_lowercase()))
        {
            out.push(command);
        }
    }
    out
}

/// A case's command: the program and its arguments.
fn command_of(case: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(case).expect("the case reads");
    let doc: toml_like::Case = toml_like::parse(&text);
    std::iter::once("seabus".to_string())
        .chain(doc.args)
        .collect()
}

/// The words of a command line as a shell splits them: at spaces outside quotes, the quotes
/// (`'…'`, `"…"`) taken off.
fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word: Option<String> = None;
    let mut quote: Option<char> = None;
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => word.get_or_insert_with(String::new).push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                word.get_or_insert_with(String::new);
            }
            (None, c) if c.is_whitespace() => out.extend(word.take()),
            (None, c) => word.get_or_insert_with(String::new).push(c),
        }
    }
    out.extend(word);
    out
}

/// Just enough of a case file to know its arguments: the `args = [ … ]` line.
mod toml_like {
    pub struct Case {
        pub args: Vec<String>,
    }

    pub fn parse(text: &str) -> Case {
        let line = text
            .lines()
            .find_map(|l| l.strip_prefix("args = "))
            .expect("a case names its args on one line");
        let args: Vec<String> = serde_json::from_str(line).expect("args as a list of strings");
        Case { args }
    }
}

#[test]
fn every_example_of_the_pages_is_run_or_says_why_not() {
    let mut pages: Vec<PathBuf> = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.expect("an entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    pages.extend(docs);
    let mut wanted: Vec<(String, String)> = Vec::new();
    for page in &pages {
        for c in examples(page) {
            wanted.push((c, page.display().to_string()));
        }
    }
    assert!(wanted.len() >= 40, "{wanted:?}");

    let cases: BTreeSet<Vec<String>> = std::fs::read_dir(root().join("tests/cmd"))
        .expect("tests/cmd")
        .map(|e| e.expect("an entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| command_of(&p))
        .collect();
    let not_run = std::fs::read_to_string(root().join("tests/cmd/not-run.txt")).expect("reasons");
    let mut reasons: BTreeSet<Vec<String>> = BTreeSet::new();
    for line in not_run
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
    {
        let (command, why) = line
            .split_once('\t')
            .unwrap_or_else(|| panic!("`{line}`: a command, a tab, and why it is not run"));
        assert!(!why.trim().is_empty(), "`{command}` says no reason");
        assert!(
            !cases.contains(&words(command)),
            "`{command}` is run and said not to be"
        );
        reasons.insert(words(command));
    }
    let missing: Vec<String> = wanted
        .iter()
        .filter(|(c, _)| !cases.contains(&words(c)) && !reasons.contains(&words(c)))
        .map(|(c, page)| format!("{page}: {c}"))
        .collect();
    assert!(
        missing.is_empty(),
        "examples neither run (tests/cmd/*.toml) nor said not to be (tests/cmd/not-run.txt):\n{}",
        missing.join("\n")
    );
    let on_pages: BTreeSet<Vec<String>> = wanted.iter().map(|(c, _)| words(c)).collect();
    let stale: Vec<&Vec<String>> = cases
        .iter()
        .chain(&reasons)
        .filter(|c| !on_pages.contains(*c))
        .collect();
    assert!(
        stale.is_empty(),
        "no page has these examples any more: {stale:?}"
    );
}

#[test]
fn the_readme_system_is_the_one_checked() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("the README");
    let start = readme
        .find("<seabus node=\"auv1\">")
        .expect("the README's system");
    let end = start + readme[start..].find("</seabus>").expect("its end") + "</seabus>".len();
    let case = std::fs::read_to_string(root().join("tests/cmd/auv1.xml")).expect("the case's");
    assert_eq!(&readme[start..end], case.trim_end());
}
