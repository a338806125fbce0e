//! The house: in every crate of the workspace, no module imports, directly
//! or through others, a module that imports it; and no source file of the
//! agent, the models or the bench, nor any test file, is longer than
//! [`MAX_LINES`].
//!
//! A module is a file. Module A imports module B when A's code (its `use`
//! items and every `crate::`/`super::`/`self::`/child-module path in it,
//! `#[cfg(test)]` items left out) names something B defines. A re-export
//! (`pub use`) is a door, not a dependency: a name taken through one counts
//! as taken from the module that defines it, and the re-exporting module
//! does not import what it only passes on. Declaring a child (`mod x;`) is
//! not an import either.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use syn::visit::Visit;

use crate::util::root;

/// The longest a Rust file may be, in lines: of the agent's, the models' or
/// the bench's sources, or of the tests (the integration tests under
/// `tests/`, and a crate's own).
const MAX_LINES: usize = 800;

/// One module: its file and what it references.
#[derive(Default)]
struct Module {
    file: PathBuf,
    /// Names it re-exports: name → absolute path of what it stands for.
    reexports: BTreeMap<String, Vec<String>>,
    /// Absolute paths (module path + item) its code references.
    references: Vec<Vec<String>>,
    /// Child module names.
    children: BTreeSet<String>,
}

/// A crate's modules, by absolute module path (`[]` is the root).
struct Crate {
    modules: BTreeMap<Vec<String>, Module>,
}

fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.meta
                .require_list()
                .is_ok_and(|l| l.tokens.to_string().contains("test"))
    })
}

/// The absolute path of `segments` written in module `at`, or `None` for a
/// path into another crate or a local name.
fn absolute(
    at: &[String],
    segments: &[String],
    children: &BTreeSet<String>,
) -> Option<Vec<String>> {
    let (first, rest) = segments.split_first()?;
    match first.as_str() {
        "crate" => Some(rest.to_vec()),
        "self" => Some([at, rest].concat()),
        "super" => {
            let mut base = at.to_vec();
            let mut rest = rest;
            base.pop()?;
            while let Some(("super", tail)) = rest.split_first().map(|(h, t)| (h.as_str(), t)) {
                base.pop()?;
                rest = tail;
            }
            Some([base.as_slice(), rest].concat())
        }
        name if children.contains(name) => Some([at, segments].concat()),
        _ => None,
    }
}

/// Every full path of a `use` tree (`a::{b, c::d}` → `a::b`, `a::c::d`),
/// each with the name it is brought in as (`None` for a glob).
fn use_paths(
    tree: &syn::UseTree,
    prefix: &mut Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>)>,
) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            use_paths(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            if name == "self" {
                out.push((prefix.clone(), prefix.last().cloned()));
            } else {
                out.push((
                    [prefix.as_slice(), std::slice::from_ref(&name)].concat(),
                    Some(name),
                ));
            }
        }
        syn::UseTree::Rename(r) => {
            out.push((
                [prefix.as_slice(), &[r.ident.to_string()]].concat(),
                Some(r.rename.to_string()),
            ));
        }
        syn::UseTree::Glob(_) => out.push((prefix.clone(), None)),
        syn::UseTree::Group(g) => {
            for t in &g.items {
                use_paths(t, prefix, out);
            }
        }
    }
}

/// Collects the paths a file's code uses (not its `use` items).
#[derive(Default)]
struct Paths(Vec<Vec<String>>);

impl<'ast> Visit<'ast> for Paths {
    fn visit_path(&mut self, p: &'ast syn::Path) {
        if p.segments.len() > 1 {
            self.0
                .push(p.segments.iter().map(|s| s.ident.to_string()).collect());
        }
        syn::visit::visit_path(self, p);
    }
    fn visit_item_use(&mut self, _: &'ast syn::ItemUse) {}
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if !is_test(&m.attrs) {
            syn::visit::visit_item_mod(self, m);
        }
    }
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }
    fn visit_item_impl(&mut self, i: &'ast syn::ItemImpl) {
        if !is_test(&i.attrs) {
            syn::visit::visit_item_impl(self, i);
        }
    }
    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        // Paths inside macro calls (`format!`, `tokio::select!`), read as
        // expressions or statements where they parse.
        if let Ok(exprs) = m.parse_body_with(
            syn::punctuated::Punctuated::<syn::Expr, syn::Token![,]>::parse_terminated,
        ) {
            for e in &exprs {
                self.visit_expr(e);
            }
        }
        syn::visit::visit_macro(self, m);
    }
}

/// Reads the module in `file` at `path`, and its children, into `modules`.
fn read(file: &Path, path: Vec<String>, modules: &mut BTreeMap<Vec<String>, Module>) {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let ast = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    // Where its children's files are.
    let dir = match file.file_name().and_then(|n| n.to_str()) {
        Some("lib.rs" | "main.rs" | "mod.rs") => file.parent().unwrap().to_path_buf(),
        _ => file.with_extension(""),
    };
    let mut module = Module {
        file: file.to_path_buf(),
        ..Module::default()
    };
    let mut uses = Vec::new();
    for item in &ast.items {
        match item {
            syn::Item::Mod(m) if !is_test(&m.attrs) && m.content.is_none() => {
                let name = m.ident.to_string();
                let explicit = m.attrs.iter().find_map(|a| {
                    let nv = a.meta.require_name_value().ok()?;
                    if !nv.path.is_ident("path") {
                        return None;
                    }
                    match &nv.value {
                        syn::Expr::Lit(syn::ExprLit {
                            lit: syn::Lit::Str(s),
                            ..
                        }) => Some(dir.join(s.value())),
                        _ => None,
                    }
                });
                let child = explicit.unwrap_or_else(|| {
                    let flat = dir.join(format!("{name}.rs"));
                    if flat.exists() {
                        flat
                    } else {
                        dir.join(&name).join("mod.rs")
                    }
                });
                module.children.insert(name.clone());
                read(&child, [path.as_slice(), &[name]].concat(), modules);
            }
            syn::Item::Use(u) if !is_test(&u.attrs) => {
                let reexport = !matches!(u.vis, syn::Visibility::Inherited);
                let mut found = Vec::new();
                use_paths(&u.tree, &mut Vec::new(), &mut found);
                uses.extend(found.into_iter().map(|(p, name)| (p, name, reexport)));
            }
            _ => {}
        }
    }
    for (p, name, reexport) in uses {
        let Some(abs) = absolute(&path, &p, &module.children) else {
            continue;
        };
        match (reexport, name) {
            (true, Some(name)) => {
                module.reexports.insert(name, abs);
            }
            (true, None) => {}
            (false, _) => module.references.push(abs),
        }
    }
    let mut paths = Paths::default();
    paths.visit_file(&ast);
    for p in paths.0 {
        if let Some(abs) = absolute(&path, &p, &module.children) {
            module.references.push(abs);
        }
    }
    modules.insert(path, module);
}

impl Crate {
    fn read(root_file: &Path) -> Crate {
        let mut modules = BTreeMap::new();
        read(root_file, Vec::new(), &mut modules);
        Crate { modules }
    }

    /// The module that defines what `path` names: the longest module
    /// prefix, followed through re-exports.
    fn definer(&self, path: &[String]) -> Option<Vec<String>> {
        let mut path = path.to_vec();
        for _ in 0..16 {
            let k = (0..=path.len())
                .rev()
                .find(|&k| self.modules.contains_key(&path[..k]))?;
            let module = &self.modules[&path[..k]];
            match path.get(k).and_then(|name| module.reexports.get(name)) {
                Some(target) if target.as_slice() != path.as_slice() => {
                    path = [target.as_slice(), &path[k + 1..]].concat();
                }
                _ => return Some(path[..k].to_vec()),
            }
        }
        None
    }

    /// Module → the modules it imports.
    fn imports(&self) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
        let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
        for (at, module) in &self.modules {
            let targets = edges.entry(at.clone()).or_default();
            for r in &module.references {
                if let Some(to) = self.definer(r) {
                    if &to != at {
                        targets.insert(to);
                    }
                }
            }
        }
        edges
    }

    fn file(&self, m: &[String]) -> String {
        let file = &self.modules[m].file;
        file.strip_prefix(root())
            .unwrap_or(file)
            .display()
            .to_string()
    }
}

/// The circles of `edges`: its strongly connected components of more than
/// one module (Tarjan).
fn circles(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<Vec<String>>> {
    struct Tarjan<'a> {
        edges: &'a BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'a Vec<String>, usize>,
        low: BTreeMap<&'a Vec<String>, usize>,
        stack: Vec<&'a Vec<String>>,
        on_stack: BTreeSet<&'a Vec<String>>,
        found: Vec<Vec<Vec<String>>>,
    }
    impl<'a> Tarjan<'a> {
        fn visit(&mut self, v: &'a Vec<String>) {
            let i = self.index.len();
            self.index.insert(v, i);
            self.low.insert(v, i);
            self.stack.push(v);
            self.on_stack.insert(v);
            for w in self.edges.get(v).into_iter().flatten() {
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let lw = self.low[w];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(lw);
                } else if self.on_stack.contains(w) {
                    let iw = self.index[w];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(iw);
                }
            }
            if self.low[v] == self.index[v] {
                let mut component = Vec::new();
                while let Some(w) = self.stack.pop() {
                    self.on_stack.remove(w);
                    component.push(w.clone());
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    component.sort();
                    self.found.push(component);
                }
            }
        }
    }
    let mut t = Tarjan {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        found: Vec::new(),
    };
    for v in edges.keys() {
        if !t.index.contains_key(v) {
            t.visit(v);
        }
    }
    t.found
}

/// What each circle is made of, file by file.
fn describe(krate: &Crate, edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<String> {
    circles(edges)
        .iter()
        .map(|circle| {
            let members: BTreeSet<&Vec<String>> = circle.iter().collect();
            let arrows: Vec<String> = circle
                .iter()
                .flat_map(|from| {
                    edges[from]
                        .iter()
                        .filter(|to| members.contains(to))
                        .map(move |to| format!("  {} -> {}", krate.file(from), krate.file(to)))
                })
                .collect();
            format!(
                "a circle of {} modules:\n{}",
                circle.len(),
                arrows.join("\n")
            )
        })
        .collect()
}

#[test]
fn no_module_imports_a_module_that_imports_it() {
    let mut found = Vec::new();
    for root_file in ["models/src/lib.rs", "agent/src/lib.rs", "bench/src/main.rs"] {
        let krate = Crate::read(&root().join(root_file));
        let edges = krate.imports();
        found.extend(describe(&krate, &edges));
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

/// The checker sees a circle where there is one: two modules naming each
/// other's items, one of them through a re-export.
#[test]
fn the_circle_check_finds_a_circle() {
    let d = tempfile::tempdir().unwrap();
    let src = d.path();
    std::fs::write(src.join("lib.rs"), "pub mod a;\npub mod b;\npub mod c;\n").unwrap();
    std::fs::write(src.join("a.rs"), "pub use crate::c::Deep;\npub struct A;\n").unwrap();
    std::fs::write(
        src.join("b.rs"),
        "pub fn b() -> crate::a::A { crate::a::A }\n",
    )
    .unwrap();
    std::fs::write(
        src.join("c.rs"),
        "use super::b;\npub struct Deep;\nfn f() { let _ = b::b(); }\n",
    )
    .unwrap();
    let krate = Crate::read(&src.join("lib.rs"));
    let edges = krate.imports();
    // b uses a's own item; c uses b; a only re-exports c's: no circle.
    assert!(circles(&edges).is_empty(), "{:?}", describe(&krate, &edges));
    // b now names Deep through a's door: c -> b -> c.
    std::fs::write(
        src.join("b.rs"),
        "pub fn b() -> crate::a::Deep { crate::a::Deep }\n",
    )
    .unwrap();
    let krate = Crate::read(&src.join("lib.rs"));
    let edges = krate.imports();
    assert_eq!(circles(&edges).len(), 1, "{:?}", describe(&krate, &edges));
}

/// Every `.rs` file of the agent's, the models' and the bench's sources, of
/// their own tests, and of the integration tests under `tests/` (their data
/// and the interop clients' `node_modules` left out) holds to [`MAX_LINES`].
#[test]
fn no_source_or_test_file_is_longer_than_the_limit() {
    let mut wrong = Vec::new();
    let mut dirs: Vec<_> = [
        "agent/src",
        "agent/tests",
        "models/src",
        "models/tests",
        "bench/src",
        "bench/tests",
        "tests",
    ]
    .iter()
    .map(|d| root().join(d))
    .filter(|d| d.is_dir())
    .collect();
    let skipped = [root().join("tests/data")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).unwrap().map_while(Result::ok) {
            let path = entry.path();
            if path.is_dir() {
                if path.file_name().is_some_and(|n| n != "node_modules") && !skipped.contains(&path)
                {
                    dirs.push(path);
                }
                continue;
            }
            if path.extension().is_none_or(|e| e != "rs") {
                continue;
            }
            let lines = std::fs::read_to_string(&path).unwrap().lines().count();
            let name = path.strip_prefix(root()).unwrap().display().to_string();
            if lines > MAX_LINES {
                wrong.push(format!("{name}: {lines} lines, more than {MAX_LINES}"));
            }
        }
    }
    wrong.sort();
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// Errors that are strings: a `Result` whose error is a `String`, an
/// `Err(format!(…))`, an error mapped to its text. The CLI (`commands/`,
/// the outermost layer, which prints them) and clap's `FromStr` are left
/// out, and so is test code (a file's `#[cfg(test)]` module onwards, test
/// folders).
const STRING_ERRORS: [&str; 4] = [
    ", String>",
    "Err(format!(",
    "map_err(|e| e.to_string())",
    "map_err(|e| format!(",
];

/// The string errors outside the CLI in `dir`, as `file:line`.
fn string_errors(dir: &std::path::Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap().map_while(Result::ok) {
        let path = entry.path();
        let name = path.file_name().unwrap().to_string_lossy().to_string();
        if path.is_dir() {
            if name != "tests" && name != "commands" {
                string_errors(&path, out);
            }
            continue;
        }
        if !name.ends_with(".rs") || name == "tests.rs" {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("#[cfg(test)]") {
                break;
            }
            let result_of_string = line.contains("Result<") && line.contains(", String>");
            let other = STRING_ERRORS[1..].iter().any(|p| line.contains(p));
            if (result_of_string || other) && !line.contains("fn from_str") {
                let shown = path.strip_prefix(root()).unwrap_or(&path).display();
                out.push(format!("{shown}:{}: {}", n + 1, line.trim()));
            }
        }
    }
}

/// Errors are typed (an enum per component, each variant carrying what
/// the operator needs) everywhere but the CLI: fewer than 10 string errors
/// in the agent's and the models' sources together.
#[test]
fn errors_are_typed_outside_the_command_line() {
    let mut found = Vec::new();
    for dir in ["agent/src", "models/src"] {
        string_errors(&root().join(dir), &mut found);
    }
    found.sort();
    assert!(
        found.len() < 10,
        "{} string errors:\n{}",
        found.len(),
        found.join("\n")
    );
    // The check finds what it looks for.
    let probe = tempfile::tempdir().unwrap();
    std::fs::write(
        probe.path().join("a.rs"),
        "fn f() -> Result<(), String> { Err(format!(\"x\")) }\n#[cfg(test)]\nfn g() -> Result<(), String> { Ok(()) }\n",
    )
    .unwrap();
    let mut seen = Vec::new();
    string_errors(probe.path(), &mut seen);
    assert_eq!(seen.len(), 1, "{seen:?}");
}
