//! The crate's modules as the compiler sees them, read with `syn`: the tree from `mod` items and
//! the file layout, and every `use` and qualified path resolved to the module that defines what
//! it names (through re-exports, renames and globs) or to the external crate it leaves for. The
//! architecture tests check these resolved edges, not words: a word grep missed `super::`,
//! renamed imports and a re-export's real home, and flagged comments.

use proc_macro2::{TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::Visit;

/// A module of the library (`kinepost`) or of the binary (`main.rs`).
pub struct Module {
    /// From its crate's root: `["kinepost", "kinematics", "model"]`, `["main", "cli"]`.
    pub path: Vec<String>,
    pub file: PathBuf,
    pub parent: Option<usize>,
    pub children: BTreeMap<String, usize>,
    /// Names the module defines (types, functions, constants, traits, macros).
    items: BTreeSet<String>,
    /// Names the module brings into scope with `use`, and the path each stands for.
    imports: BTreeMap<String, Vec<String>>,
    globs: Vec<Vec<String>>,
    /// Under `#[cfg(test)]`: the module's tests may use what they test through its callers.
    pub test: bool,
    /// Every path written in the module: `use` leaves and paths of two segments or more.
    pub refs: Vec<Ref>,
    /// Every function with a body: its name, first line and length in lines.
    pub fns: Vec<(String, usize, usize)>,
}

pub struct Ref {
    pub path: Vec<String>,
    pub line: usize,
    /// Inside an item under `#[cfg(test)]`.
    pub test: bool,
}

/// What a path names.
#[derive(Clone, Debug, PartialEq)]
pub enum Target {
    /// An item of this module (or the module itself).
    Module(usize),
    /// Outside the crate: the path as written from the external crate's name, `std::fs::read`.
    External(String),
    /// A local name, a generic parameter, `Self`, the prelude: nothing a rule is about.
    Unknown,
}

pub struct Tree {
    pub modules: Vec<Module>,
    pub lib: usize,
    pub bin: usize,
    /// The crates a path may start with: the dependencies and the standard library.
    externs: BTreeSet<String>,
}

impl Tree {
    /// The library from `src/lib.rs` and the binary from `src/main.rs`.
    pub fn load(root: &Path) -> Tree {
        let mut t = Tree {
            modules: Vec::new(),
            lib: 0,
            bin: 0,
            externs: externs(root),
        };
        let src = root.join("src");
        t.lib = t.file_module(vec!["kinepost".into()], &src.join("lib.rs"), &src, None, false);
        t.bin = t.file_module(vec!["main".into()], &src.join("main.rs"), &src, None, false);
        t
    }

    /// A module whose text is the file `file`; its `mod x;` children live in `dir`.
    fn file_module(&mut self, path: Vec<String>, file: &Path, dir: &Path, parent: Option<usize>, test: bool) -> usize {
        let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let ast = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        self.module(path, file, dir, parent, test, &ast.items)
    }

    fn module(&mut self, path: Vec<String>, file: &Path, dir: &Path, parent: Option<usize>, test: bool, items: &[syn::Item]) -> usize {
        let id = self.modules.len();
        let mut read = Reader {
            test,
            refs: Vec::new(),
            fns: Vec::new(),
            imports: BTreeMap::new(),
            globs: Vec::new(),
        };
        let mut names = BTreeSet::new();
        let mut mods = Vec::new();
        for item in items {
            if let syn::Item::Mod(m) = item {
                mods.push(m);
            } else {
                if let Some(n) = item_name(item) {
                    names.insert(n);
                }
                read.visit_item(item);
            }
        }
        self.modules.push(Module {
            path: path.clone(),
            file: file.to_path_buf(),
            parent,
            children: BTreeMap::new(),
            items: names,
            imports: read.imports,
            globs: read.globs,
            test,
            refs: read.refs,
            fns: read.fns,
        });
        for m in mods {
            let name = m.ident.to_string();
            let test = test || is_test(&m.attrs);
            let mut child_path = path.clone();
            child_path.push(name.clone());
            let child = match &m.content {
                Some((_, inner)) => self.module(child_path, file, &dir.join(&name), Some(id), test, inner),
                None => {
                    let (f, d) = match path_attr(&m.attrs) {
                        Some(p) => (dir.join(&p), dir.join(&p).with_extension("")),
                        None if dir.join(format!("{name}.rs")).exists() => (dir.join(format!("{name}.rs")), dir.join(&name)),
                        None => (dir.join(&name).join("mod.rs"), dir.join(&name)),
                    };
                    self.file_module(child_path, &f, &d, Some(id), test)
                }
            };
            self.modules[id].children.insert(name, child);
        }
        id
    }

    pub fn root_of(&self, mut m: usize) -> usize {
        while let Some(p) = self.modules[m].parent {
            m = p;
        }
        m
    }

    /// Whether `m` is `anc` or inside it.
    pub fn within(&self, mut m: usize, anc: usize) -> bool {
        loop {
            if m == anc {
                return true;
            }
            match self.modules[m].parent {
                Some(p) => m = p,
                None => return false,
            }
        }
    }

    /// The module named by `path` from its crate's root (`["kinepost", "post", "emit"]`).
    pub fn find(&self, path: &[&str]) -> Option<usize> {
        let mut m = [self.lib, self.bin].into_iter().find(|&r| self.modules[r].path[0] == path[0])?;
        for seg in &path[1..] {
            m = *self.modules[m].children.get(*seg)?;
        }
        Some(m)
    }

    pub fn name(&self, m: usize) -> String {
        self.modules[m].path.join("::")
    }

    /// What `path`, written in module `m`, names.
    pub fn resolve(&self, m: usize, path: &[String]) -> Target {
        self.resolve_depth(m, path, 0)
    }

    fn resolve_depth(&self, m: usize, path: &[String], depth: usize) -> Target {
        if path.is_empty() || depth > 16 {
            return Target::Unknown;
        }
        let (start, rest) = match path[0].as_str() {
            "crate" => (self.root_of(m), &path[1..]),
            "self" => (m, &path[1..]),
            "super" => {
                let mut at = m;
                let mut k = 0;
                while path.get(k).is_some_and(|s| s == "super") {
                    at = self.modules[at].parent.unwrap_or(at);
                    k += 1;
                }
                (at, &path[k..])
            }
            "kinepost" => (self.lib, &path[1..]),
            // `::name`: an external crate.
            "" => return self.external(&path[1..]),
            first => match self.lookup(m, first, depth) {
                Some(Found::Module(c)) => (c, &path[1..]),
                Some(Found::Item) => return Target::Module(m),
                Some(Found::Import(to)) => {
                    let mut full = to;
                    full.extend_from_slice(&path[1..]);
                    return self.resolve_depth(m, &full, depth + 1);
                }
                Some(Found::Glob(g)) => return self.resolve_depth(g, path, depth + 1),
                None if self.externs.contains(first) => return self.external(path),
                None => return Target::Unknown,
            },
        };
        self.walk(start, rest, depth)
    }

    /// From module `at`, the rest of a path.
    fn walk(&self, mut at: usize, rest: &[String], depth: usize) -> Target {
        for (k, seg) in rest.iter().enumerate() {
            match self.lookup(at, seg, depth) {
                Some(Found::Module(c)) => at = c,
                Some(Found::Item) | None => return Target::Module(at),
                Some(Found::Import(to)) => {
                    let mut full = to;
                    full.extend_from_slice(&rest[k + 1..]);
                    return self.resolve_depth(at, &full, depth + 1);
                }
                Some(Found::Glob(g)) => return self.walk(g, &rest[k..], depth + 1),
            }
        }
        Target::Module(at)
    }

    /// `name` in the scope of module `m`.
    fn lookup(&self, m: usize, name: &str, depth: usize) -> Option<Found> {
        let md = &self.modules[m];
        if let Some(&c) = md.children.get(name) {
            return Some(Found::Module(c));
        }
        if md.items.contains(name) {
            return Some(Found::Item);
        }
        if let Some(to) = md.imports.get(name) {
            return Some(Found::Import(to.clone()));
        }
        for g in &md.globs {
            if depth > 8 {
                break;
            }
            if let Target::Module(gm) = self.resolve_depth(m, g, depth + 1) {
                if gm != m && self.lookup(gm, name, depth + 1).is_some() {
                    return Some(Found::Glob(gm));
                }
            }
        }
        None
    }

    fn external(&self, path: &[String]) -> Target {
        match path.first() {
            Some(p) if self.externs.contains(p) => Target::External(path.join("::")),
            _ => Target::Unknown,
        }
    }
}

enum Found {
    Module(usize),
    Item,
    Import(Vec<String>),
    Glob(usize),
}

/// The crates a path may name: the package's dependencies of every kind, and the standard library.
fn externs(root: &Path) -> BTreeSet<String> {
    let manifest: toml::Table = std::fs::read_to_string(root.join("Cargo.toml")).unwrap().parse().unwrap();
    let mut out: BTreeSet<String> = ["std", "core", "alloc"].map(String::from).into();
    let mut tables = vec![manifest.clone()];
    if let Some(targets) = manifest.get("target").and_then(|t| t.as_table()) {
        tables.extend(targets.values().filter_map(|t| t.as_table().cloned()));
    }
    for t in tables {
        for kind in ["dependencies", "dev-dependencies", "build-dependencies"] {
            if let Some(deps) = t.get(kind).and_then(|d| d.as_table()) {
                out.extend(deps.keys().map(|k| k.replace('-', "_")));
            }
        }
    }
    out
}

/// Reads one module's items (not its child modules): imports, paths, functions.
struct Reader {
    test: bool,
    refs: Vec<Ref>,
    fns: Vec<(String, usize, usize)>,
    imports: BTreeMap<String, Vec<String>>,
    globs: Vec<Vec<String>>,
}

impl Reader {
    fn push(&mut self, path: Vec<String>, line: usize) {
        self.refs.push(Ref { path, line, test: self.test });
    }

    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &syn::UseTree) {
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => self.use_leaf(prefix, &n.ident, None),
            syn::UseTree::Rename(r) => self.use_leaf(prefix, &r.ident, Some(&r.rename)),
            syn::UseTree::Glob(g) => {
                self.globs.push(prefix.clone());
                self.push(prefix.clone(), g.star_token.spans[0].start().line);
            }
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(prefix, t);
                }
            }
        }
    }

    fn use_leaf(&mut self, prefix: &[String], ident: &syn::Ident, rename: Option<&syn::Ident>) {
        let mut path = prefix.to_vec();
        if ident != "self" {
            path.push(ident.to_string());
        }
        let name = rename.unwrap_or(ident).to_string();
        let name = if ident == "self" && rename.is_none() { path.last().cloned().unwrap_or_default() } else { name };
        if name != "_" {
            // A `use` inside a function is taken as the module's: its names are local, and no
            // module-level name is shadowed by one.
            self.imports.entry(name).or_insert_with(|| path.clone());
        }
        self.push(path, ident.span().start().line);
    }

    /// Paths in tokens no parser reads (macro arguments, attribute arguments): `a::b` sequences.
    fn tokens(&mut self, ts: TokenStream) {
        let toks: Vec<TokenTree> = ts.into_iter().collect();
        let mut i = 0;
        while i < toks.len() {
            match &toks[i] {
                TokenTree::Group(g) => {
                    self.tokens(g.stream());
                    i += 1;
                }
                TokenTree::Ident(id) => {
                    let mut path = vec![id.to_string()];
                    let mut j = i + 1;
                    while let (Some(TokenTree::Punct(a)), Some(TokenTree::Punct(b)), Some(TokenTree::Ident(n))) =
                        (toks.get(j), toks.get(j + 1), toks.get(j + 2))
                    {
                        if a.as_char() != ':' || b.as_char() != ':' {
                            break;
                        }
                        path.push(n.to_string());
                        j += 3;
                    }
                    if path.len() > 1 {
                        self.push(path, id.span().start().line);
                    }
                    i = j;
                }
                _ => i += 1,
            }
        }
    }

    fn function(&mut self, name: &syn::Ident, start: proc_macro2::Span, block: &syn::Block) {
        let (first, last) = (start.start().line, block.brace_token.span.close().end().line);
        self.fns.push((name.to_string(), first, last - first + 1));
    }
}

impl<'ast> Visit<'ast> for Reader {
    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        let mut prefix = if u.leading_colon.is_some() { vec![String::new()] } else { Vec::new() };
        self.use_tree(&mut prefix, &u.tree);
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        if p.segments.len() > 1 && p.segments[0].ident != "Self" {
            let mut path: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
            if p.leading_colon.is_some() {
                path.insert(0, String::new());
            }
            self.push(path, p.segments[0].ident.span().start().line);
        }
        syn::visit::visit_path(self, p);
    }

    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        self.visit_path(&m.path);
        self.tokens(m.tokens.clone());
    }

    fn visit_attribute(&mut self, a: &'ast syn::Attribute) {
        if let syn::Meta::List(l) = &a.meta {
            self.visit_path(&l.path);
            self.tokens(l.tokens.clone());
        } else if !a.path().is_ident("doc") {
            syn::visit::visit_attribute(self, a);
        }
    }

    fn visit_item(&mut self, i: &'ast syn::Item) {
        let was = self.test;
        self.test |= is_test(attrs(i));
        syn::visit::visit_item(self, i);
        self.test = was;
    }

    fn visit_item_mod(&mut self, _: &'ast syn::ItemMod) {
        // A module inside a function: rare enough to leave unread.
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        self.function(&f.sig.ident, f.sig.fn_token.span, &f.block);
        syn::visit::visit_item_fn(self, f);
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        let was = self.test;
        self.test |= is_test(&f.attrs);
        self.function(&f.sig.ident, f.sig.fn_token.span, &f.block);
        syn::visit::visit_impl_item_fn(self, f);
        self.test = was;
    }

    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(b) = &f.default {
            self.function(&f.sig.ident, f.sig.fn_token.span, b);
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

fn item_name(item: &syn::Item) -> Option<String> {
    let id = match item {
        syn::Item::Const(i) => &i.ident,
        syn::Item::Enum(i) => &i.ident,
        syn::Item::Fn(i) => &i.sig.ident,
        syn::Item::Macro(i) => i.ident.as_ref()?,
        syn::Item::Static(i) => &i.ident,
        syn::Item::Struct(i) => &i.ident,
        syn::Item::Trait(i) => &i.ident,
        syn::Item::TraitAlias(i) => &i.ident,
        syn::Item::Type(i) => &i.ident,
        syn::Item::Union(i) => &i.ident,
        _ => return None,
    };
    Some(id.to_string())
}

fn attrs(item: &syn::Item) -> &[syn::Attribute] {
    match item {
        syn::Item::Const(i) => &i.attrs,
        syn::Item::Enum(i) => &i.attrs,
        syn::Item::Fn(i) => &i.attrs,
        syn::Item::Impl(i) => &i.attrs,
        syn::Item::Macro(i) => &i.attrs,
        syn::Item::Mod(i) => &i.attrs,
        syn::Item::Static(i) => &i.attrs,
        syn::Item::Struct(i) => &i.attrs,
        syn::Item::Trait(i) => &i.attrs,
        syn::Item::Type(i) => &i.attrs,
        syn::Item::Union(i) => &i.attrs,
        syn::Item::Use(i) => &i.attrs,
        _ => &[],
    }
}

/// `#[cfg(test)]`, or a `cfg` that holds only with it.
fn is_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && matches!(&a.meta, syn::Meta::List(l) if {
                let t = l.tokens.to_string();
                t == "test" || (t.starts_with("all") && t.contains("test") && !t.contains("not"))
            })
    })
}

fn path_attr(attrs: &[syn::Attribute]) -> Option<String> {
    attrs.iter().find(|a| a.path().is_ident("path")).and_then(|a| match &a.meta {
        syn::Meta::NameValue(nv) => match &nv.value {
            syn::Expr::Lit(syn::ExprLit { lit: syn::Lit::Str(s), .. }) => Some(s.value()),
            _ => None,
        },
        _ => None,
    })
}
