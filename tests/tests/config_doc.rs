//! docs/CONFIG.md is the config structs rendered, so it cannot drift from them: the tables below its
//! marker line are generated here from the sources, one table per TOML table, each key with its type, its
//! default and its doc comment. The walk starts at `TrainConfig` (the file `factory-train` reads) and
//! follows its fields: a struct field is a sub-table, an enum tagged by `type` is one table per variant, a
//! unit enum is a string with its values listed. The fields, doc comments and serde attributes (`rename`,
//! `rename_all`, `alias`, `default`, `flatten`, `skip`, `tag`, `deny_unknown_fields`) come from parsing the
//! crates' sources with `syn` (structs written by a `macro_rules!` template, as the controller configs are,
//! included); the defaults come from the real structs, by loading a config that names the table and no key
//! in it, so they are what a user gets. A new field or table appears without changes here.
//!
//! `FACTORY_BLESS=1 cargo test --release -p factory-tests --test config_doc` rewrites the generated part
//! (the header above the marker is prose, kept as it is).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use factory_rl::TrainConfig;
use proc_macro2::{Delimiter, Group, Ident, TokenStream, TokenTree};
use quote::ToTokens;
use serde_json::Value;
use syn::parse::{Parse, ParseStream};
use syn::{Attribute, Expr, Item, Lit, Meta, Token, Type};

/// The source folders holding the config types (the crates `factory-train` links).
const SOURCES: &[&str] = &["rl/src", "envs/src", "controllers/src", "engine/src"];
/// The type of a whole config file.
const ROOT: &str = "TrainConfig";
/// The generated document, relative to the workspace root.
const DOC: &str = "docs/CONFIG.md";
/// The command that rewrites the generated part.
macro_rules! bless_command {
    () => {
        "FACTORY_BLESS=1 cargo test --release -p factory-tests --test config_doc"
    };
}
/// The line that separates the hand-written header from the generated tables.
const MARKER: &str = concat!(
    "<!-- Generated from the config structs below this line by tests/tests/config_doc.rs; `",
    bless_command!(),
    "` rewrites it. -->"
);
/// Structs with `deny_unknown_fields` that are not read from a config file: the calibration file's
/// (`factory-calibrate` writes it, an env reads it through `randomize.starts_file`).
const NOT_CONFIG: &[&str] = &["CalibratedStart", "CalibrationFile", "StartDraw"];

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

// ---------------------------------------------------------------------------------------------------------
// The config types, as read from the sources.

/// A field of a config struct, as TOML sees it.
#[derive(Clone)]
struct FieldDef {
    /// Its TOML key (after `rename` / `rename_all`).
    key: String,
    /// Other accepted keys (`alias`).
    aliases: Vec<String>,
    ty: Type,
    doc: String,
    /// It may be left out (`default` on the field or its struct).
    has_default: bool,
    /// Its struct's keys sit in this table (`flatten`).
    flatten: bool,
}

#[derive(Clone)]
struct StructDef {
    name: String,
    doc: String,
    fields: Vec<FieldDef>,
    deny_unknown: bool,
}

#[derive(Clone)]
struct VariantDef {
    /// Its `type` value.
    name: String,
    aliases: Vec<String>,
    doc: String,
    /// The struct of a newtype variant.
    inner: Option<Type>,
}

#[derive(Clone)]
struct EnumDef {
    /// `tag = "..."`: a table whose `tag` key selects the variant.
    tag: Option<String>,
    variants: Vec<VariantDef>,
}

#[derive(Clone)]
enum Def {
    Struct(StructDef),
    Enum(EnumDef),
    /// A type with a hand-written `Deserialize`: what its visitor expects.
    Custom(String),
}

/// Every serde type in the sources, by name (a name defined twice is an error only where the walk meets it).
#[derive(Default)]
struct Defs(HashMap<String, Vec<(PathBuf, Def)>>);

impl Defs {
    fn add(&mut self, name: String, file: &Path, def: Def) {
        self.0.entry(name).or_default().push((file.to_path_buf(), def));
    }

    fn get(&self, name: &str) -> Option<&Def> {
        let defs = self.0.get(name)?;
        if defs.len() > 1 {
            let files: Vec<String> = defs.iter().map(|(f, _)| f.display().to_string()).collect();
            panic!("`{name}` is defined in several files ({}): the generator cannot tell which", files.join(", "));
        }
        Some(&defs[0].1)
    }
}

/// The serde attributes of an item: bare words (`default`, `flatten`) and `name = "value"` pairs.
#[derive(Default)]
struct Serde {
    words: BTreeSet<String>,
    values: Vec<(String, String)>,
}

impl Serde {
    fn of(attrs: &[Attribute]) -> Self {
        let mut s = Serde::default();
        for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
            a.parse_nested_meta(|m| {
                let name = m.path.to_token_stream().to_string();
                if m.input.peek(Token![=]) {
                    let value: Expr = m.value()?.parse()?;
                    let text = match &value {
                        Expr::Lit(syn::ExprLit { lit: Lit::Str(s), .. }) => s.value(),
                        other => other.to_token_stream().to_string(),
                    };
                    s.values.push((name, text));
                } else {
                    if m.input.peek(syn::token::Paren) {
                        let content;
                        syn::parenthesized!(content in m.input);
                        content.parse::<TokenStream>()?;
                    }
                    s.words.insert(name);
                }
                Ok(())
            })
            .unwrap_or_else(|e| panic!("unreadable #[serde(...)]: {e}"));
        }
        s
    }

    fn has(&self, name: &str) -> bool {
        self.words.contains(name) || self.values.iter().any(|(k, _)| k == name)
    }

    fn value(&self, name: &str) -> Option<&str> {
        self.values.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    fn all(&self, name: &str) -> Vec<String> {
        self.values.iter().filter(|(k, _)| k == name).map(|(_, v)| v.clone()).collect()
    }
}

/// serde's `rename_all` applied to a Rust name.
fn rename(name: &str, rule: Option<&str>) -> String {
    let name = name.strip_prefix("r#").unwrap_or(name);
    match rule {
        None => name.to_owned(),
        Some("lowercase") => name.to_lowercase(),
        Some("snake_case") => {
            let mut out = String::new();
            for (i, c) in name.chars().enumerate() {
                if c.is_uppercase() && i > 0 {
                    out.push('_');
                }
                out.extend(c.to_lowercase());
            }
            out
        }
        Some(other) => panic!("rename_all = \"{other}\" is not handled by the generator; add it to `rename`"),
    }
}

/// A doc comment as one line: its lines joined, rustdoc's `[`link`]` brackets dropped.
fn doc_of(attrs: &[Attribute]) -> String {
    let mut lines = Vec::new();
    for a in attrs.iter().filter(|a| a.path().is_ident("doc")) {
        if let Meta::NameValue(nv) = &a.meta {
            if let Expr::Lit(syn::ExprLit { lit: Lit::Str(s), .. }) = &nv.value {
                lines.push(s.value().trim().to_owned());
            }
        }
    }
    let text = lines.into_iter().filter(|l| !l.is_empty()).collect::<Vec<_>>().join(" ");
    let mut out = String::new();
    let mut rest = text.as_str();
    while let Some(start) = rest.find("[`") {
        let Some(len) = rest[start + 2..].find("`]") else { break };
        let end = start + 2 + len;
        out.push_str(&rest[..start]);
        out.push_str(&rest[start + 1..end + 1]);
        rest = &rest[end + 2..];
        // A link with a target, `[`x`](url)`, keeps the text only.
        if rest.starts_with('(') {
            if let Some(close) = rest.find(')') {
                rest = &rest[close + 1..];
            }
        }
    }
    out.push_str(rest);
    out
}

fn derives_deserialize(attrs: &[Attribute]) -> bool {
    attrs.iter().any(|a| a.path().is_ident("derive") && a.meta.to_token_stream().to_string().contains("Deserialize"))
}

fn is_cfg_test(attrs: &[Attribute]) -> bool {
    attrs.iter().any(|a| a.path().is_ident("cfg") && a.meta.to_token_stream().to_string().contains("test"))
}

fn struct_def<'a>(
    name: String,
    attrs: &[Attribute],
    fields: impl IntoIterator<Item = (&'a [Attribute], &'a syn::Ident, &'a Type)>,
) -> StructDef {
    let serde = Serde::of(attrs);
    let rule = serde.value("rename_all");
    let fields = fields
        .into_iter()
        .filter_map(|(attrs, ident, ty)| {
            let f = Serde::of(attrs);
            if f.has("skip") || f.has("skip_deserializing") {
                return None;
            }
            let key = f.value("rename").map(str::to_owned).unwrap_or_else(|| rename(&ident.to_string(), rule));
            Some(FieldDef {
                key,
                aliases: f.all("alias"),
                ty: ty.clone(),
                doc: doc_of(attrs),
                has_default: serde.has("default") || f.has("default"),
                flatten: f.has("flatten"),
            })
        })
        .collect();
    StructDef { name, doc: doc_of(attrs), fields, deny_unknown: serde.has("deny_unknown_fields") }
}

fn enum_def(e: &syn::ItemEnum) -> EnumDef {
    let serde = Serde::of(&e.attrs);
    let rule = serde.value("rename_all");
    let variants = e
        .variants
        .iter()
        .filter(|v| !Serde::of(&v.attrs).has("skip"))
        .map(|v| {
            let s = Serde::of(&v.attrs);
            let inner = match &v.fields {
                syn::Fields::Unit => None,
                syn::Fields::Unnamed(u) if u.unnamed.len() == 1 => Some(u.unnamed[0].ty.clone()),
                _ => panic!("`{}::{}`: only unit and newtype variants are handled by the generator", e.ident, v.ident),
            };
            VariantDef {
                name: s.value("rename").map(str::to_owned).unwrap_or_else(|| rename(&v.ident.to_string(), rule)),
                aliases: s.all("alias"),
                doc: doc_of(&v.attrs),
                inner,
            }
        })
        .collect();
    EnumDef { tag: serde.value("tag").map(str::to_owned), variants }
}

/// The string a hand-written visitor's `expecting` writes (`f.write_str("...")`).
fn expecting(tokens: TokenStream) -> Option<String> {
    let trees: Vec<TokenTree> = tokens.into_iter().collect();
    for (i, t) in trees.iter().enumerate() {
        match t {
            TokenTree::Ident(id) if id == "write_str" => {
                if let Some(TokenTree::Group(g)) = trees.get(i + 1) {
                    if let Ok(s) = syn::parse2::<syn::LitStr>(g.stream()) {
                        return Some(s.value());
                    }
                }
            }
            TokenTree::Group(g) => {
                if let Some(s) = expecting(g.stream()) {
                    return Some(s);
                }
            }
            _ => {}
        }
    }
    None
}

/// A struct written by a `macro_rules!` template: `NAME! { #[doc] pub struct X { pub f: T = default, ... } }`.
struct MacroStruct {
    attrs: Vec<Attribute>,
    ident: syn::Ident,
    fields: Vec<(Vec<Attribute>, syn::Ident, Type)>,
}

impl Parse for MacroStruct {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        input.parse::<syn::Visibility>()?;
        input.parse::<Token![struct]>()?;
        let ident = input.parse()?;
        let content;
        syn::braced!(content in input);
        let mut fields = Vec::new();
        while !content.is_empty() {
            let attrs = content.call(Attribute::parse_outer)?;
            content.parse::<syn::Visibility>()?;
            let name = content.parse()?;
            content.parse::<Token![:]>()?;
            let ty = content.parse()?;
            content.parse::<Token![=]>()?;
            content.parse::<Expr>()?;
            if !content.is_empty() {
                content.parse::<Token![,]>()?;
            }
            fields.push((attrs, name, ty));
        }
        if !input.is_empty() {
            return Err(input.error("tokens after the struct"));
        }
        Ok(Self { attrs, ident, fields })
    }
}

/// The struct a `macro_rules!` writes, with its repetitions (`$(...)*`, the invocation's own fields and
/// attributes) left out and its `$name` made a plain name: the attributes and fields every invocation gets.
fn macro_template(body: TokenStream) -> Option<syn::ItemStruct> {
    let trees: Vec<TokenTree> = body.into_iter().collect();
    let punct = |t: &TokenTree, c: char| matches!(t, TokenTree::Punct(p) if p.as_char() == c);
    let arrow = trees.windows(2).position(|w| punct(&w[0], '=') && punct(&w[1], '>'))?;
    let TokenTree::Group(transcriber) = trees.get(arrow + 2)? else { return None };
    let t: Vec<TokenTree> = transcriber.stream().into_iter().collect();
    let at = t.iter().position(|x| matches!(x, TokenTree::Ident(i) if i == "struct"))?;
    let end =
        at + t[at..].iter().position(|x| matches!(x, TokenTree::Group(g) if g.delimiter() == Delimiter::Brace))?;
    syn::parse2(without_repetitions(t[..=end].iter().cloned().collect())).ok()
}

fn without_repetitions(tokens: TokenStream) -> TokenStream {
    let t: Vec<TokenTree> = tokens.into_iter().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < t.len() {
        match (&t[i], t.get(i + 1)) {
            (TokenTree::Punct(p), Some(TokenTree::Group(g)))
                if p.as_char() == '$' && g.delimiter() == Delimiter::Parenthesis =>
            {
                // `$( ... ) sep? op`: skip up to and including the repetition operator.
                i += 2;
                while let Some(TokenTree::Punct(p)) = t.get(i) {
                    i += 1;
                    if matches!(p.as_char(), '*' | '+' | '?') {
                        break;
                    }
                }
            }
            (TokenTree::Punct(p), Some(TokenTree::Ident(id))) if p.as_char() == '$' => {
                out.push(TokenTree::Ident(Ident::new("MacroStruct", id.span())));
                i += 2;
            }
            (TokenTree::Group(g), _) => {
                let mut group = Group::new(g.delimiter(), without_repetitions(g.stream()));
                group.set_span(g.span());
                out.push(TokenTree::Group(group));
                i += 1;
            }
            (other, _) => {
                out.push(other.clone());
                i += 1;
            }
        }
    }
    out.into_iter().collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Every serde type in [`SOURCES`].
fn read_sources() -> Defs {
    let mut files = Vec::new();
    for dir in SOURCES {
        rust_files(&workspace().join(dir), &mut files);
    }
    let mut defs = Defs::default();
    let mut templates = HashMap::new();
    let mut invocations = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let parsed = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        read_items(file, &parsed.items, &mut defs, &mut templates, &mut invocations);
    }
    for (file, name, tokens) in invocations {
        let Some(template) = templates.get(&name) else { continue };
        let template: &syn::ItemStruct = template;
        if !derives_deserialize(&template.attrs) {
            continue;
        }
        let Ok(m) = syn::parse2::<MacroStruct>(tokens) else { continue };
        let attrs: Vec<Attribute> = template.attrs.iter().chain(&m.attrs).cloned().collect();
        let own = m.fields.iter().map(|(a, i, t)| (a.as_slice(), i, t));
        let shared = template.fields.iter().map(|f| (f.attrs.as_slice(), f.ident.as_ref().unwrap(), &f.ty));
        let def = struct_def(m.ident.to_string(), &attrs, own.chain(shared));
        defs.add(m.ident.to_string(), &file, Def::Struct(def));
    }
    defs
}

fn read_items(
    file: &Path,
    items: &[Item],
    defs: &mut Defs,
    templates: &mut HashMap<String, syn::ItemStruct>,
    invocations: &mut Vec<(PathBuf, String, TokenStream)>,
) {
    for item in items {
        match item {
            Item::Struct(s) if derives_deserialize(&s.attrs) => {
                if let syn::Fields::Named(named) = &s.fields {
                    let fields = named.named.iter().map(|f| (f.attrs.as_slice(), f.ident.as_ref().unwrap(), &f.ty));
                    defs.add(s.ident.to_string(), file, Def::Struct(struct_def(s.ident.to_string(), &s.attrs, fields)));
                }
            }
            Item::Enum(e) if derives_deserialize(&e.attrs) => {
                defs.add(e.ident.to_string(), file, Def::Enum(enum_def(e)))
            }
            Item::Impl(i) => {
                let is_deserialize = i
                    .trait_
                    .as_ref()
                    .is_some_and(|(_, p, _)| p.segments.last().is_some_and(|s| s.ident == "Deserialize"));
                if let (true, Type::Path(p)) = (is_deserialize, &*i.self_ty) {
                    let name = p.path.segments.last().unwrap().ident.to_string();
                    let expects = expecting(i.to_token_stream()).unwrap_or_else(|| format!("see `{name}`"));
                    defs.add(name, file, Def::Custom(expects));
                }
            }
            Item::Mod(m) if !is_cfg_test(&m.attrs) => {
                if let Some((_, items)) = &m.content {
                    read_items(file, items, defs, templates, invocations);
                }
            }
            Item::Macro(m) if m.mac.path.is_ident("macro_rules") => {
                if let (Some(name), Some(t)) = (&m.ident, macro_template(m.mac.tokens.clone())) {
                    templates.insert(name.to_string(), t);
                }
            }
            Item::Macro(m) => {
                let name = m.mac.path.segments.last().unwrap().ident.to_string();
                invocations.push((file.to_path_buf(), name, m.mac.tokens.clone()));
            }
            _ => {}
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// The defaults, from the real structs.

/// The config a user gets from a file that selects `selections` (`type` of each tagged table, by path)
/// and writes the tables `tables` with no key in them, as JSON.
fn loaded_defaults(defs: &Defs, selections: &[(Vec<String>, String)], tables: &[Vec<String>]) -> Value {
    let mut root = toml::Table::new();
    fn table_at<'a>(root: &'a mut toml::Table, path: &[String]) -> &'a mut toml::Table {
        let mut t = root;
        for p in path {
            t = t
                .entry(p.clone())
                .or_insert_with(|| toml::Value::Table(Default::default()))
                .as_table_mut()
                .expect("a table on the path");
        }
        t
    }
    for (path, ty) in selections {
        table_at(&mut root, path).insert("type".into(), toml::Value::String(ty.clone()));
    }
    for path in tables {
        table_at(&mut root, path);
    }
    // A required tagged table the walk is not inside gets its first type.
    let Some(Def::Struct(top)) = defs.get(ROOT) else { panic!("`{ROOT}` not found in the sources") };
    for f in top.fields.iter().filter(|f| !f.has_default) {
        if let Some(Def::Enum(e @ EnumDef { tag: Some(tag), .. })) = type_name(&f.ty).and_then(|n| defs.get(&n)) {
            let t = table_at(&mut root, std::slice::from_ref(&f.key));
            t.entry(tag.clone()).or_insert_with(|| toml::Value::String(e.variants[0].name.clone()));
        }
    }
    let text = toml::to_string(&root).unwrap();
    let cfg = TrainConfig::from_str_with(&text, "the defaults", &[])
        .unwrap_or_else(|e| panic!("a config naming only the tables loads:\n{text}\n{e}"));
    serde_json::to_value(&cfg).unwrap()
}

fn value_at<'a>(v: &'a Value, path: &[String]) -> Option<&'a Value> {
    path.iter().try_fold(v, |v, k| v.get(k))
}

// ---------------------------------------------------------------------------------------------------------
// Rendering.

/// The last path segment of a type without generic arguments.
fn type_name(ty: &Type) -> Option<String> {
    match ty {
        Type::Path(p) => {
            let s = p.path.segments.last()?;
            matches!(s.arguments, syn::PathArguments::None).then(|| s.ident.to_string())
        }
        _ => None,
    }
}

/// The first generic argument of `Option<T>`, `Vec<T>`.
fn type_argument(ty: &Type, outer: &str) -> Option<Type> {
    let Type::Path(p) = ty else { return None };
    let s = p.path.segments.last()?;
    if s.ident != outer {
        return None;
    }
    let syn::PathArguments::AngleBracketed(a) = &s.arguments else { return None };
    a.args.iter().find_map(|g| match g {
        syn::GenericArgument::Type(t) => Some(t.clone()),
        _ => None,
    })
}

/// A float as written in TOML: an f32's shortest form (a default of `1.0 / 60.0` is `0.016666668`).
fn float_text(x: f64) -> String {
    let s = if (x as f32) as f64 == x { format!("{}", x as f32) } else { format!("{x}") };
    if s.contains(['.', 'e', 'E', 'i', 'N']) {
        s
    } else {
        format!("{s}.0")
    }
}

fn table_id(segments: &[String]) -> String {
    if segments.is_empty() {
        "top-level".into()
    } else {
        segments.join("-")
    }
}

/// A walk position: the TOML path of the table, and the `type` chosen for each tagged table on it.
#[derive(Clone, Default)]
struct Place {
    path: Vec<String>,
    selections: Vec<(Vec<String>, String)>,
    /// The path with each selected type after its table: `env.franka_nut_bolt.controller.osc`.
    qualified: Vec<String>,
}

impl Place {
    fn child(&self, key: &str) -> Place {
        let mut p = self.clone();
        p.path.push(key.into());
        p.qualified.push(key.into());
        p
    }

    fn select(&self, ty: &str) -> Place {
        let mut p = self.clone();
        p.selections.push((p.path.clone(), ty.into()));
        p.qualified.push(ty.into());
        p
    }

    /// The key id used to match config files against the doc: `env[franka_nut_bolt].controller[osc]`.
    fn key_id(&self, key: &str) -> String {
        let mut s = String::new();
        let mut sel = self.selections.iter().peekable();
        for (i, p) in self.path.iter().enumerate() {
            if i > 0 {
                s.push('.');
            }
            s.push_str(p);
            if let Some((path, ty)) = sel.peek() {
                if path.len() == i + 1 {
                    let _ = write!(s, "[{ty}]");
                    sel.next();
                }
            }
        }
        if s.is_empty() {
            key.to_owned()
        } else {
            format!("{s}.{key}")
        }
    }
}

struct Section {
    id: String,
    title: String,
    intro: Vec<String>,
    rows: Vec<[String; 4]>,
}

struct Walk<'a> {
    defs: &'a Defs,
    sections: Vec<Section>,
    /// Every documented key, as [`Place::key_id`] spells it.
    keys: BTreeSet<String>,
    /// `type` aliases to their names.
    type_aliases: BTreeMap<String, String>,
    /// The structs documented.
    visited: BTreeSet<String>,
}

/// What a field's value is in TOML.
enum Kind<'a> {
    Value,
    Table(&'a StructDef),
    Tagged(&'a EnumDef),
}

fn cell(s: &str) -> String {
    s.replace('|', "\\|")
}

impl<'a> Walk<'a> {
    fn kind(&self, ty: &Type) -> Kind<'a> {
        match type_name(ty).and_then(|n| self.defs.get(&n)) {
            Some(Def::Struct(s)) => Kind::Table(s),
            Some(Def::Enum(e)) if e.tag.is_some() => Kind::Tagged(e),
            Some(Def::Enum(e)) if e.variants.iter().any(|v| v.inner.is_some()) => {
                panic!("`{}`: an enum with data but no `tag` is not handled by the generator", ty.to_token_stream())
            }
            _ => Kind::Value,
        }
    }

    /// A value's type in words: `float`, `[float; 3]`, `"auto", "wgpu" or "cpu"`.
    fn type_text(&self, ty: &Type) -> String {
        if let Type::Array(a) = ty {
            return format!("`[{}; {}]`", self.type_text(&a.elem).trim_matches('`'), a.len.to_token_stream());
        }
        if let Some(inner) = type_argument(ty, "Option") {
            return self.type_text(&inner);
        }
        if let Some(inner) = type_argument(ty, "Vec") {
            return format!("`[{}, ...]`", self.type_text(&inner).trim_matches('`'));
        }
        let name = type_name(ty).unwrap_or_else(|| panic!("no TOML type for `{}`", ty.to_token_stream()));
        let plain = match name.as_str() {
            "bool" => "boolean",
            "f32" | "f64" => "float",
            "u8" | "u16" | "u32" | "u64" | "usize" | "i8" | "i16" | "i32" | "i64" | "isize" => "integer",
            "String" | "PathBuf" => "string",
            _ => "",
        };
        if !plain.is_empty() {
            return format!("`{plain}`");
        }
        match self.defs.get(&name) {
            Some(Def::Enum(e)) if e.tag.is_none() => {
                let names: Vec<String> = e.variants.iter().map(|v| format!("`\"{}\"`", v.name)).collect();
                match names.split_last() {
                    Some((last, [])) => last.clone(),
                    Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
                    None => panic!("`{name}` has no variants"),
                }
            }
            Some(Def::Custom(expects)) => expects.clone(),
            _ => panic!("no TOML type for `{name}`: teach `type_text` about it"),
        }
    }

    /// A default value as inline TOML, tables' keys in their fields' order.
    fn value_text(&self, v: &Value, ty: Option<&Type>) -> String {
        match v {
            Value::Null => "unset".into(),
            Value::Bool(b) => b.to_string(),
            Value::Number(n) => match (n.as_u64(), n.as_i64()) {
                (Some(u), _) => u.to_string(),
                (_, Some(i)) => i.to_string(),
                _ => float_text(n.as_f64().unwrap()),
            },
            Value::String(s) => format!("{s:?}"),
            Value::Array(a) => {
                let elem = ty.and_then(|t| match t {
                    Type::Array(a) => Some((*a.elem).clone()),
                    _ => type_argument(t, "Vec"),
                });
                let items: Vec<String> = a.iter().map(|x| self.value_text(x, elem.as_ref())).collect();
                format!("[{}]", items.join(", "))
            }
            Value::Object(m) => {
                let mut order: Vec<(String, Option<Type>)> = Vec::new();
                match ty.map(|t| self.kind(t)) {
                    Some(Kind::Table(s)) => order.extend(self.fields(s).into_iter().map(|f| (f.key, Some(f.ty)))),
                    Some(Kind::Tagged(e)) => {
                        let tag = e.tag.clone().unwrap();
                        let chosen = m.get(&tag).and_then(Value::as_str).unwrap_or_default();
                        order.push((tag, None));
                        let inner = e.variants.iter().find(|v| v.name == chosen).and_then(|v| v.inner.as_ref());
                        if let Some(Kind::Table(s)) = inner.map(|t| self.kind(t)) {
                            order.extend(self.fields(s).into_iter().map(|f| (f.key, Some(f.ty))));
                        }
                    }
                    _ => {}
                }
                for k in m.keys() {
                    if !order.iter().any(|(o, _)| o == k) {
                        order.push((k.clone(), None));
                    }
                }
                let items: Vec<String> = order
                    .iter()
                    .filter_map(|(k, t)| m.get(k).map(|x| format!("{k} = {}", self.value_text(x, t.as_ref()))))
                    .collect();
                format!("{{ {} }}", items.join(", "))
            }
        }
    }

    /// A struct's fields with the flattened ones' fields in their place.
    fn fields(&self, s: &StructDef) -> Vec<FieldDef> {
        let mut out = Vec::new();
        for f in &s.fields {
            match (f.flatten, self.kind(&f.ty)) {
                (true, Kind::Table(inner)) => out.extend(self.fields(inner)),
                (true, _) => panic!("`{}`: flatten of a non-struct is not handled", f.key),
                (false, _) => out.push(f.clone()),
            }
        }
        out
    }

    fn link(&self, place: &Place, title: &str) -> String {
        format!("[{title}](#{})", table_id(&place.qualified))
    }

    fn table_title(place: &Place) -> String {
        if place.path.is_empty() {
            "top level".into()
        } else {
            format!("`[{}]`", place.path.join("."))
        }
    }

    /// The section of a struct's table at `place`, then the sections of its sub-tables.
    fn struct_section(
        &mut self,
        place: &Place,
        title: String,
        mut intro: Vec<String>,
        s: &StructDef,
        type_row: Option<[String; 4]>,
    ) {
        self.visited.insert(s.name.clone());
        let here = loaded_defaults(self.defs, &place.selections, std::slice::from_ref(&place.path));
        let here = value_at(&here, &place.path).cloned().unwrap_or(Value::Null);
        if !s.doc.is_empty() {
            intro.insert(0, s.doc.clone());
        }
        if !s.deny_unknown {
            intro.push("Unknown keys in this table are ignored.".into());
        }
        let mut rows: Vec<[String; 4]> = type_row.into_iter().collect();
        let mut subs: Vec<(Place, FieldDef)> = Vec::new();
        for f in self.fields(s) {
            self.keys.insert(place.key_id(&f.key));
            for a in &f.aliases {
                self.keys.insert(place.key_id(a));
            }
            let mut key = format!("`{}`", f.key);
            for a in &f.aliases {
                let _ = write!(key, " (or `{a}`)");
            }
            let sub = place.child(&f.key);
            let omitted = here.get(&f.key);
            let (ty, default) = match self.kind(&f.ty) {
                Kind::Value => {
                    let default = match (f.has_default, omitted) {
                        (false, _) => "required".into(),
                        (true, None | Some(Value::Null)) => "unset".into(),
                        (true, Some(v)) => format!("`{}`", self.value_text(v, Some(&f.ty))),
                    };
                    (self.type_text(&f.ty), default)
                }
                Kind::Table(_) => {
                    subs.push((sub.clone(), f.clone()));
                    let ty = format!("table, {}", self.link(&sub, &Self::table_title(&sub)));
                    (ty, self.table_default(&f, &sub, omitted))
                }
                Kind::Tagged(e) => {
                    subs.push((sub.clone(), f.clone()));
                    let tag = e.tag.as_deref().unwrap();
                    let links: Vec<String> = e
                        .variants
                        .iter()
                        .map(|v| self.link(&sub.select(&v.name), &format!("`\"{}\"`", v.name)))
                        .collect();
                    let ty = format!("table selected by `{tag}`: {}", links.join(", "));
                    (ty, self.table_default(&f, &sub, omitted))
                }
            };
            rows.push([key, cell(&ty), cell(&default), cell(&f.doc)]);
        }
        self.sections.push(Section { id: table_id(&place.qualified), title, intro, rows });
        for (sub, f) in subs {
            match self.kind(&f.ty) {
                Kind::Table(inner) => {
                    let title = Self::table_title(&sub);
                    let intro = self.context(&sub);
                    self.struct_section(&sub, title, intro, inner, None);
                }
                Kind::Tagged(e) => self.tagged_sections(&sub, e),
                Kind::Value => unreachable!(),
            }
        }
    }

    /// "Within `env.type = "franka_nut_bolt"`." for a table inside a selected one.
    fn context(&self, place: &Place) -> Vec<String> {
        place.selections.iter().map(|(path, ty)| format!("In `[{}]` with `type = \"{ty}\"`.", path.join("."))).collect()
    }

    /// The default column of a sub-table's row: the defaults of its own section when leaving the table out
    /// gives the same as writing it with no keys, else the value leaving it out gives.
    fn table_default(&self, f: &FieldDef, sub: &Place, omitted: Option<&Value>) -> String {
        let Some(omitted) = omitted.filter(|_| f.has_default) else { return "required".into() };
        let keyless = match self.kind(&f.ty) {
            Kind::Tagged(e) => {
                let tag = e.tag.as_deref().unwrap();
                let chosen = omitted.get(tag).and_then(Value::as_str).unwrap_or_default();
                let sub = sub.select(chosen);
                let v = loaded_defaults(self.defs, &sub.selections, &[]);
                value_at(&v, &sub.path).cloned()
            }
            _ => {
                let v = loaded_defaults(self.defs, &sub.selections, std::slice::from_ref(&sub.path));
                value_at(&v, &sub.path).cloned()
            }
        };
        if keyless.as_ref() == Some(omitted) {
            match self.kind(&f.ty) {
                Kind::Tagged(e) => {
                    let chosen = omitted.get(e.tag.as_deref().unwrap()).and_then(Value::as_str).unwrap_or_default();
                    format!("{}'s defaults", self.link(&sub.select(chosen), &format!("`type = \"{chosen}\"`")))
                }
                _ => "each key's default".into(),
            }
        } else {
            format!("`{}`", self.value_text(omitted, Some(&f.ty)))
        }
    }

    /// One section per variant of a table tagged by `type`.
    fn tagged_sections(&mut self, place: &Place, e: &EnumDef) {
        let tag = e.tag.as_deref().unwrap();
        let names: Vec<String> = e.variants.iter().map(|v| format!("`\"{}\"`", v.name)).collect();
        for v in &e.variants {
            for a in &v.aliases {
                self.type_aliases.insert(a.clone(), v.name.clone());
            }
            let chosen = place.select(&v.name);
            let title = format!("{} `{tag} = \"{}\"`", Self::table_title(place), v.name);
            let mut intro = self.context(place);
            let mut type_doc = format!("Selects this table, one of {}.", names.join(", "));
            for a in &v.aliases {
                let _ = write!(type_doc, " `\"{a}\"` is the same as `\"{}\"`.", v.name);
            }
            let type_row = [format!("`{tag}`"), "`string`".into(), "required".into(), cell(&type_doc)];
            self.keys.insert(chosen.key_id(tag));
            match v.inner.as_ref().map(|t| self.kind(t)) {
                Some(Kind::Table(s)) => {
                    if s.doc.is_empty() && !v.doc.is_empty() {
                        intro.insert(0, v.doc.clone());
                    }
                    self.struct_section(&chosen, title, intro, s, Some(type_row));
                }
                None => {
                    if !v.doc.is_empty() {
                        intro.insert(0, v.doc.clone());
                    }
                    self.sections.push(Section { id: table_id(&chosen.qualified), title, intro, rows: vec![type_row] });
                }
                _ => panic!("`type = \"{}\"`: a variant must hold a struct", v.name),
            }
        }
    }
}

/// The generated part of docs/CONFIG.md, and the walk that made it.
fn generate() -> (String, Walk<'static>) {
    let defs: &'static Defs = Box::leak(Box::new(read_sources()));
    let Some(Def::Struct(root)) = defs.get(ROOT) else { panic!("`{ROOT}` not found in {SOURCES:?}") };
    let mut walk = Walk {
        defs,
        sections: Vec::new(),
        keys: BTreeSet::new(),
        type_aliases: BTreeMap::new(),
        visited: BTreeSet::new(),
    };
    walk.struct_section(&Place::default(), "Top level".into(), Vec::new(), root, None);
    let mut out = String::new();
    let contents: Vec<String> = walk.sections.iter().map(|s| format!("[{}](#{})", s.title, s.id)).collect();
    let _ = writeln!(out, "Tables: {}.\n", contents.join(" · "));
    for s in &walk.sections {
        let _ = writeln!(out, "<a id=\"{}\"></a>\n\n## {}\n", s.id, s.title);
        for line in &s.intro {
            let _ = writeln!(out, "{line}\n");
        }
        let _ = writeln!(out, "| Key | Type | Default | Description |\n|---|---|---|---|");
        for r in &s.rows {
            let _ = writeln!(out, "| {} | {} | {} | {} |", r[0], r[1], r[2], r[3]);
        }
        out.push('\n');
    }
    (out.trim_end().to_owned() + "\n", walk)
}

/// The header (prose) and the generated part of the file on disk.
fn on_disk() -> (String, Option<String>) {
    let text = std::fs::read_to_string(workspace().join(DOC)).unwrap_or_default();
    match text.split_once(MARKER) {
        Some((header, body)) => (header.to_owned(), Some(body.trim_start_matches('\n').to_owned())),
        None => (text, None),
    }
}

/// The sections of a generated text by their `## ` headings.
fn sections_of(text: &str) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = vec![("(before the first table)".into(), String::new())];
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            out.push((h.to_owned(), String::new()));
        }
        let last = out.last_mut().unwrap();
        last.1.push_str(line);
        last.1.push('\n');
    }
    out
}

/// Where two generated texts first differ: the section and the two lines.
fn first_difference(doc: &str, generated: &str) -> String {
    let (a, b) = (sections_of(doc), sections_of(generated));
    for i in 0..a.len().max(b.len()) {
        match (a.get(i), b.get(i)) {
            (Some(x), Some(y)) if x == y => continue,
            (Some(x), Some(y)) => {
                let (xl, yl): (Vec<&str>, Vec<&str>) = (x.1.lines().collect(), y.1.lines().collect());
                let k = (0..xl.len().max(yl.len())).find(|&k| xl.get(k) != yl.get(k)).unwrap_or(0);
                let end = "(the section ends)";
                let (p, q) = (xl.get(k).copied().unwrap_or(end), yl.get(k).copied().unwrap_or(end));
                return format!(
                    "first in the section headed {} (generated: {}):\n  {DOC}: {p}\n  generated:      {q}",
                    x.0, y.0
                );
            }
            (Some(x), None) => return format!("the doc has a section the structs do not: {}", x.0),
            (None, Some(y)) => return format!("the structs have a section the doc does not: {}", y.0),
            (None, None) => unreachable!(),
        }
    }
    "only in whitespace".into()
}

#[test]
fn config_doc_is_the_config_structs_rendered() {
    let (generated, _) = generate();
    let (header, body) = on_disk();
    if std::env::var("FACTORY_BLESS").is_ok_and(|v| v == "1") {
        let header = if header.trim().is_empty() { "# Configuration\n\n".to_owned() } else { header };
        let text = format!("{}{MARKER}\n\n{generated}", header.trim_end().to_owned() + "\n\n");
        std::fs::write(workspace().join(DOC), text).unwrap();
        eprintln!("wrote {DOC}");
        return;
    }
    let Some(body) = body else {
        panic!("{DOC} has no generated part (the marker line); write it with {}", bless_command!())
    };
    if body != generated {
        panic!(
            "{DOC} is not the config structs rendered, {}\nIf the structs are right, rewrite the doc with {}",
            first_difference(&body, &generated),
            bless_command!()
        );
    }
}

/// The keys of a config, each as [`Place::key_id`] spells it: a table with a `type` is qualified by it
/// (an alias by the name it stands for).
fn keys_of(table: &toml::Table, id: &str, aliases: &BTreeMap<String, String>, out: &mut Vec<String>) {
    for (k, v) in table {
        let key = if id.is_empty() { k.clone() } else { format!("{id}.{k}") };
        out.push(key.clone());
        if let Some(t) = v.as_table() {
            let sub = match t.get("type").and_then(toml::Value::as_str) {
                Some(ty) => format!("{key}[{}]", aliases.get(ty).map(String::as_str).unwrap_or(ty)),
                None => key,
            };
            keys_of(t, &sub, aliases, out);
        }
    }
}

/// The keys of a config's text that the doc does not document.
fn undocumented(walk: &Walk, text: &str) -> Vec<String> {
    let table: toml::Table = toml::from_str(text).unwrap();
    let mut keys = Vec::new();
    keys_of(&table, "", &walk.type_aliases, &mut keys);
    keys.retain(|k| !walk.keys.contains(k));
    keys
}

/// Every key the shipped configs write is documented, in the table of the env or controller its file
/// selects (a key of another type's table does not count).
#[test]
fn every_key_of_the_shipped_configs_is_documented() {
    let (_, walk) = generate();
    let dir = workspace().join("configs");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().path()).collect();
    files.retain(|p| p.extension().is_some_and(|e| e == "toml"));
    files.sort();
    assert!(files.len() >= 3, "only {} configs in {}", files.len(), dir.display());
    let mut missing = Vec::new();
    for f in &files {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        missing.extend(
            undocumented(&walk, &std::fs::read_to_string(f).unwrap()).into_iter().map(|k| format!("{name}: {k}")),
        );
    }
    assert!(missing.is_empty(), "keys written in configs/ that {DOC} does not document:\n  {}", missing.join("\n  "));
    // The check itself: a key of the other env's table, a misspelt key and an unknown controller key are
    // caught; an alias of a controller type is not.
    let text = "seed = 1\n[env]\ntype = \"franka_nut_bolt\"\narena = 1.0\n[env.controller]\n\
                type = \"operational_space_motion\"\nkp = 1\nkpp = 2\n[ppo]\nhorizn = 3\n";
    assert_eq!(
        undocumented(&walk, text),
        ["env[franka_nut_bolt].arena", "env[franka_nut_bolt].controller[osc].kpp", "ppo.horizn"]
    );
}

/// Every struct that refuses unknown keys is a config table the doc reaches from `TrainConfig` (or is
/// listed in `NOT_CONFIG`), so a config type cannot sit outside the doc.
#[test]
fn every_strict_serde_struct_is_documented() {
    let (_, walk) = generate();
    let mut strict: Vec<&str> = walk
        .defs
        .0
        .iter()
        .filter(|(_, defs)| defs.iter().any(|(_, d)| matches!(d, Def::Struct(s) if s.deny_unknown)))
        .map(|(name, _)| name.as_str())
        .collect();
    strict.sort();
    assert!(strict.len() >= 10, "only {} strict structs found: {strict:?}", strict.len());
    let missing: Vec<&&str> =
        strict.iter().filter(|n| !walk.visited.contains(**n) && !NOT_CONFIG.contains(n)).collect();
    assert!(missing.is_empty(), "structs with deny_unknown_fields that {DOC} does not reach from {ROOT}: {missing:?}");
}

/// The header's prose names keys (`ppo.horizon`, `env.controller.type`): each is one the doc documents.
#[test]
fn keys_named_in_the_header_exist() {
    let (_, walk) = generate();
    let (header, _) = on_disk();
    // The documented keys with the `[type]` selections dropped.
    let plain: BTreeSet<String> = walk
        .keys
        .iter()
        .map(|k| {
            let mut s = String::new();
            let mut depth = 0;
            for c in k.chars() {
                match c {
                    '[' => depth += 1,
                    ']' => depth -= 1,
                    c if depth == 0 => s.push(c),
                    _ => {}
                }
            }
            s
        })
        .collect();
    let tops: BTreeSet<&str> = plain.iter().map(|k| k.split('.').next().unwrap()).collect();
    let mut named = 0;
    // Code fences are not spans.
    let header = header.replace("```", "");
    for (i, span) in header.split('`').enumerate() {
        let is_key = i % 2 == 1
            && span.contains('.')
            && span.split('.').all(|p| !p.is_empty() && p.chars().all(|c| c.is_ascii_lowercase() || c == '_'))
            && tops.contains(span.split('.').next().unwrap());
        if is_key {
            named += 1;
            assert!(plain.contains(span), "{DOC}'s header names `{span}`, which no config table has");
        }
    }
    assert!(named >= 5, "the header names only {named} keys");
}
