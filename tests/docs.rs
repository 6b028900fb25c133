//! The user's guide holds together: every relative link of the README and of
//! `docs/` names a file that exists and, where it names a section
//! (`page.md#section`), a heading of that page as GitHub anchors it. A moved
//! section or a renamed page fails here, not in a reader's browser.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// GitHub's anchor for a heading: lower case, every character that is not a
/// letter, a digit, a space, `-` or `_` dropped, spaces made `-`.
fn anchor(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The text of a page outside fenced code blocks, line by line.
fn prose(text: &str) -> Vec<&str> {
    let mut fenced = false;
    let mut lines = Vec::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            lines.push(line);
        }
    }
    lines
}

/// The anchors of a page's headings; a repeated heading gets `-1`, `-2`, ...
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for line in prose(text) {
        let Some(rest) = line.strip_prefix('#') else { continue };
        let heading = rest.trim_start_matches('#');
        if !heading.starts_with(' ') {
            continue;
        }
        let base = anchor(heading);
        let mut name = base.clone();
        let mut n = 0;
        while seen.contains(&name) {
            n += 1;
            name = format!("{base}-{n}");
        }
        seen.insert(name);
    }
    seen
}

/// The targets of the inline links and images of a page (`](target)`), with
/// any title after a space dropped.
fn link_targets(text: &str) -> Vec<String> {
    let mut targets = Vec::new();
    for line in prose(text) {
        let mut rest = line;
        while let Some(at) = rest.find("](") {
            rest = &rest[at + 2..];
            let Some(end) = rest.find(')') else { break };
            let target = rest[..end].split_whitespace().next().unwrap_or("").to_string();
            targets.push(target);
            rest = &rest[end..];
        }
    }
    targets
}

/// Every broken relative link of `page`: "page: target (why)".
fn broken_links(page: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(page).expect("a page of the guide is readable");
    let dir = page.parent().expect("a page lies in a folder");
    let mut broken = Vec::new();
    for target in link_targets(&text) {
        if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
            continue;
        }
        let (file, section) = match target.split_once('#') {
            Some((file, section)) => (file, Some(section)),
            None => (target.as_str(), None),
        };
        let path = if file.is_empty() { page.to_path_buf() } else { dir.join(file) };
        if !path.exists() {
            broken.push(format!("{}: {target} (no such file)", page.display()));
            continue;
        }
        if let Some(section) = section {
            if path.extension().is_some_and(|e| e == "md") {
                let linked = std::fs::read_to_string(&path).expect("a linked page is readable");
                if !anchors(&linked).contains(section) {
                    broken.push(format!("{}: {target} (no such section)", page.display()));
                }
            }
        }
    }
    broken
}

fn guide_pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    let mut folders = vec![root().join("docs")];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).expect("docs/ is readable") {
            let path = entry.expect("a docs/ entry").path();
            if path.is_dir() {
                folders.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                pages.push(path);
            }
        }
    }
    pages.sort();
    pages
}

#[test]
fn every_relative_link_of_the_guide_resolves() {
    let pages = guide_pages();
    assert!(pages.len() > 10, "the guide's pages were not found: {pages:?}");
    let broken: Vec<String> = pages.iter().flat_map(|p| broken_links(p)).collect();
    assert!(broken.is_empty(), "{} broken link(s):\n{}", broken.len(), broken.join("\n"));
}

#[test]
fn a_dead_section_or_file_is_caught() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("other.md"), "# Other page\n\n## Out of style: the `out_of_style` flag (2026-12-05)\n").unwrap();
    let page = dir.path().join("page.md");
    std::fs::write(
        &page,
        "# Page\n\nGood: [a](other.md#out-of-style-the-out_of_style-flag-2026-12-05), [b](#page).\n\
         Bad: [c](other.md#gone), [d](missing.md), ![e](missing.png).\n\
         ```\n[not a link](nowhere.md)\n```\n",
    )
    .unwrap();
    let broken = broken_links(&page);
    assert_eq!(broken.len(), 3, "{broken:?}");
    assert!(broken[0].ends_with("other.md#gone (no such section)"), "{broken:?}");
    assert!(broken[1].ends_with("missing.md (no such file)"), "{broken:?}");
}
