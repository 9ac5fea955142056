//! The code's layout as docs/architecture.md promises it: no file too big to read, one
//! CPU twin file per shader, every file in the module tree, and no import cycle.
//!
//! The import check reads the `crate::` and `super::` paths of every file under src/ and
//! resolves each to the deepest module it names. An arrow from module A to module B counts
//! between the two children of their nearest common ancestor that hold them (a file using
//! its own parent's or child's items is the module tree, not an arrow). Those arrows must
//! form no cycle at any level. Unit tests (`#[cfg(test)] mod tests`, tests.rs) are left
//! out: what they borrow for their data is not part of the library's layering.
//! `cargo test --test layout -- --nocapture` prints the arrows.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Lines a file under src/ may have, tests inside it included.
const MAX_LINES: usize = 900;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every .rs file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(rust_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    out.sort();
    out
}

/// The module path of a file under src/: src/extract/regions/mod.rs is ["extract", "regions"].
fn module_of(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(root().join("src")).unwrap();
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if !matches!(stem, "mod" | "lib" | "main") {
        parts.push(stem.to_string());
    }
    parts
}

/// `use` trees with braces spread into plain paths: `a::{b, c::{d, e}}` is a::b, a::c::d, a::c::e.
fn spread(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else { return vec![tree.to_string()] };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.rfind('}').unwrap()];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts.iter().filter(|p| !p.trim().is_empty()).flat_map(|p| spread(p)).map(|p| format!("{prefix}{p}")).collect()
}

/// The paths a file names that start at `crate::` or `super::`, as module paths from the
/// crate's root (what follows the last module is left for the caller to cut).
fn paths_in(source: &str, module: &[String]) -> Vec<Vec<String>> {
    // Comments out; `use` statements whole (they may span lines and hold brace trees).
    let code: String = source
        .lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let mut raw = Vec::new();
    let mut rest = code.as_str();
    while let Some(i) = rest.find("use ") {
        let before = rest[..i].chars().last();
        let after = &rest[i + 4..];
        let end = after.find(';').unwrap_or(after.len());
        if before.is_none_or(|c| !c.is_alphanumeric() && c != '_') {
            raw.extend(spread(&after[..end].replace(char::is_whitespace, "")));
        }
        rest = &after[end.min(after.len())..];
    }
    // Paths written out in the code (`crate::a::b::f()`).
    for start in ["crate::", "super::"] {
        let mut at = 0;
        while let Some(i) = code[at..].find(start) {
            let i = at + i;
            let prev = code[..i].chars().last();
            if prev.is_none_or(|c| !c.is_alphanumeric() && c != '_' && c != ':') {
                let end = code[i..]
                    .find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .map_or(code.len(), |e| i + e);
                raw.push(code[i..end].to_string());
            }
            at = i + start.len();
        }
    }
    // `super` is the parent of the file's module, whether the file is a.rs or a/mod.rs
    // (a `super` inside an inline module resolves one level too high: to an ancestor,
    // which is no arrow).
    raw.into_iter()
        .filter_map(|p| {
            let segs: Vec<&str> = p.split("::").filter(|s| !s.is_empty()).collect();
            let mut base = module.to_vec();
            let mut k = 0;
            match segs.first() {
                Some(&"crate") => {
                    base.clear();
                    k = 1;
                }
                Some(&"super") => {
                    while segs.get(k) == Some(&"super") {
                        base.pop()?;
                        k += 1;
                    }
                }
                _ => return None,
            }
            base.extend(segs[k..].iter().map(|s| s.to_string()));
            Some(base)
        })
        .collect()
}

/// The deepest module of `known` that `path` names (the crate's root if none).
fn resolve(path: &[String], known: &BTreeSet<Vec<String>>) -> Vec<String> {
    (0..=path.len()).rev().map(|n| path[..n].to_vec()).find(|p| known.contains(p)).unwrap_or_default()
}

/// Arrows between sibling modules: for each use of B in A, the children of A and B's
/// nearest common ancestor that hold them, keyed by that ancestor.
fn sibling_arrows() -> BTreeMap<Vec<String>, BTreeSet<(String, String)>> {
    let files = rust_files(&root().join("src"));
    let modules: BTreeMap<Vec<String>, PathBuf> = files.iter().map(|f| (module_of(f), f.clone())).collect();
    let known: BTreeSet<Vec<String>> = modules.keys().cloned().collect();
    let mut arrows: BTreeMap<Vec<String>, BTreeSet<(String, String)>> = BTreeMap::new();
    for (a, file) in &modules {
        if a.last().is_some_and(|m| m == "tests") {
            continue;
        }
        let source = std::fs::read_to_string(file).unwrap();
        let source = source.split("#[cfg(test)]\nmod tests").next().unwrap();
        for path in paths_in(source, a) {
            let b = resolve(&path, &known);
            let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
            // One holds the other: the module tree itself.
            if common == a.len() || common == b.len() {
                continue;
            }
            arrows.entry(a[..common].to_vec()).or_default().insert((a[common].clone(), b[common].clone()));
        }
    }
    arrows
}

/// A cycle among `arrows`, if there is one.
fn find_cycle(arrows: &BTreeSet<(String, String)>) -> Option<Vec<String>> {
    let nodes: BTreeSet<&String> = arrows.iter().flat_map(|(a, b)| [a, b]).collect();
    // 0 unseen, 1 on the walk, 2 done.
    let mut state: BTreeMap<&String, u8> = nodes.iter().map(|n| (*n, 0)).collect();
    fn walk<'a>(
        n: &'a String,
        arrows: &'a BTreeSet<(String, String)>,
        state: &mut BTreeMap<&'a String, u8>,
        stack: &mut Vec<&'a String>,
    ) -> Option<Vec<String>> {
        state.insert(n, 1);
        stack.push(n);
        for (_, m) in arrows.iter().filter(|(a, _)| a == n) {
            match state[m] {
                1 => {
                    let at = stack.iter().position(|s| *s == m).unwrap();
                    return Some(stack[at..].iter().map(|s| s.to_string()).chain([m.clone()]).collect());
                }
                0 => {
                    if let Some(c) = walk(m, arrows, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(n, 2);
        None
    }
    for n in &nodes {
        if state[*n] == 0
            && let Some(c) = walk(n, arrows, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn no_import_cycle_at_any_level_of_the_module_tree() {
    let arrows = sibling_arrows();
    // The check sees arrows where they are: the extraction's children use each other.
    let extract = &arrows[&vec!["extract".to_string()]];
    assert!(extract.contains(&("regions".into(), "cpu".into())), "{extract:?}");
    let mut cycles = Vec::new();
    for (parent, arrows) in &arrows {
        let name = if parent.is_empty() { "crate".to_string() } else { parent.join("::") };
        println!("{name}:");
        for (a, b) in arrows {
            println!("  {a} -> {b}");
        }
        if let Some(cycle) = find_cycle(arrows) {
            cycles.push(format!("in {name}: {}", cycle.join(" -> ")));
        }
    }
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

#[test]
fn the_cycle_check_finds_a_cycle() {
    let arrows: BTreeSet<(String, String)> =
        [("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    assert_eq!(find_cycle(&arrows).unwrap(), ["a", "b", "c", "a"]);
    let no: BTreeSet<(String, String)> =
        [("a", "b"), ("b", "c"), ("a", "c")].iter().map(|(a, b)| (a.to_string(), b.to_string())).collect();
    assert_eq!(find_cycle(&no), None);
    assert_eq!(spread("crate::a::{b, c::{d, e}}"), ["crate::a::b", "crate::a::c::d", "crate::a::c::e"]);
}

#[test]
fn no_file_under_src_is_over_900_lines() {
    let long: Vec<String> = rust_files(&root().join("src"))
        .iter()
        .map(|f| (f, std::fs::read_to_string(f).unwrap().lines().count()))
        .filter(|(_, n)| *n > MAX_LINES)
        .map(|(f, n)| format!("{}: {n}", f.display()))
        .collect();
    assert!(long.is_empty(), "over {MAX_LINES} lines: {long:?}");
}

#[test]
fn every_shader_has_one_cpu_twin_file_named_after_it() {
    let shaders: Vec<String> = std::fs::read_dir(root().join("shaders"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    assert!(shaders.len() >= 10, "{shaders:?}");
    for name in &shaders {
        let twin = root().join(format!("src/extract/cpu/{name}.rs"));
        let text = std::fs::read_to_string(&twin).unwrap_or_else(|_| panic!("{name}.wgsl has no {}", twin.display()));
        assert!(text.contains(&format!("{name}.wgsl")), "{} does not name the shader it twins", twin.display());
    }
}

#[test]
fn every_file_under_src_has_its_line_in_the_architecture_s_module_tree() {
    let doc = std::fs::read_to_string(root().join("docs/architecture.md")).unwrap();
    let missing: Vec<String> = rust_files(&root().join("src"))
        .iter()
        .map(|f| f.strip_prefix(root()).unwrap().to_string_lossy().into_owned())
        .filter(|f| {
            // A file, or the folder that holds it as one line (src/cli/).
            let folder = &f[..f.rfind('/').unwrap() + 1];
            !doc.lines()
                .any(|l| l.starts_with(&format!("{f} ")) || l.trim_end() == *f || l.starts_with(&format!("{folder} ")))
        })
        .collect();
    assert!(missing.is_empty(), "not in docs/architecture.md's module tree: {missing:?}");
}
