//! docs/configuration.md's table of keys is generated from `TrackConfig`, so that it cannot drift:
//! each key's text is its field's doc comment (read through `TrackConfig`'s JSON Schema, which
//! schemars derives from the doc comments), with the doc comments of an enum's values; the
//! `default` column is `TrackConfig::default()` and the `paper` column the `paper` preset, both
//! as the TOML that `TrackConfig::to_toml` writes. The rows are in that TOML's order.
//!
//! The table sits between the `BEGIN` and `END` markers below; the page's text around them is
//! written by hand. `ACTRACK_BLESS=1 cargo test -p actrack --test configuration_doc` rewrites the
//! table.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::PathBuf;

use actrack::TrackConfig;
use serde_json::Value;
use toml::de::{DeTable, DeValue};

const BEGIN: &str = "<!-- BEGIN generated from TrackConfig (crates/actrack/src/config.rs) by \
                     crates/actrack/tests/configuration_doc.rs: edit the doc comments there, not \
                     this table -->";
const END: &str = "<!-- END generated -->";
const BLESS: &str = "ACTRACK_BLESS";
const COMMAND: &str = "ACTRACK_BLESS=1 cargo test -p actrack --test configuration_doc";

fn doc_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/configuration.md")
}

/// The leaf keys of a TOML document (`filter.particles`, …) in the order they are written, each
/// with its value's TOML text.
fn toml_keys(text: &str) -> Vec<(String, String)> {
    fn walk(prefix: &str, table: &DeTable, text: &str, out: &mut Vec<(String, String)>) {
        let mut entries: Vec<_> = table.iter().collect();
        entries.sort_by_key(|(k, _)| k.span().start);
        for (k, v) in entries {
            let key = if prefix.is_empty() {
                k.get_ref().to_string()
            } else {
                format!("{prefix}.{}", k.get_ref())
            };
            match v.get_ref() {
                DeValue::Table(sub) => walk(&key, sub, text, out),
                _ => out.push((key, text[v.span()].trim().to_string())),
            }
        }
    }
    let table = DeTable::parse(text).expect("TrackConfig::to_toml writes valid TOML");
    let mut out = Vec::new();
    walk("", table.get_ref(), text, &mut out);
    out
}

/// `TrackConfig`'s JSON Schema.
struct Schema(Value);

impl Schema {
    fn new() -> Self {
        Self(schemars::schema_for!(TrackConfig).to_value())
    }

    /// `s`, or the definition it refers to.
    fn resolve<'a>(&'a self, s: &'a Value) -> &'a Value {
        match s.get("$ref").and_then(Value::as_str) {
            Some(r) => {
                let name = r
                    .strip_prefix("#/$defs/")
                    .unwrap_or_else(|| panic!("unexpected $ref {r}"));
                &self.0["$defs"][name]
            }
            None => s,
        }
    }

    /// The schema of the field at the dotted `key`.
    fn field(&self, key: &str) -> &Value {
        let mut node = &self.0;
        for part in key.split('.') {
            node = self
                .resolve(node)
                .get("properties")
                .and_then(|p| p.get(part))
                .unwrap_or_else(|| panic!("`{key}`: TrackConfig's schema has no field `{part}`"));
        }
        node
    }

    /// The dotted keys of every field that is not itself a table.
    fn leaves(&self) -> BTreeSet<String> {
        fn walk(schema: &Schema, prefix: &str, node: &Value, out: &mut BTreeSet<String>) {
            let Some(props) = schema
                .resolve(node)
                .get("properties")
                .and_then(Value::as_object)
            else {
                out.insert(prefix.to_string());
                return;
            };
            for (name, sub) in props {
                let key = if prefix.is_empty() {
                    name.clone()
                } else {
                    format!("{prefix}.{name}")
                };
                walk(schema, &key, sub, out);
            }
        }
        let mut out = BTreeSet::new();
        walk(self, "", &self.0, &mut out);
        out
    }

    /// The text of `key`'s row: its field's doc comment, then one line per value of an enum
    /// with that value's doc comment.
    fn description(&self, key: &str) -> String {
        let field = self.field(key);
        let mut text = field
            .get("description")
            .and_then(Value::as_str)
            .map_or_else(
                || panic!("`{key}` has no doc comment in crates/actrack/src/config.rs"),
                one_line,
            );
        let def = self.resolve(field);
        if let Some(values) = def.get("oneOf").and_then(Value::as_array) {
            for v in values {
                let name = match (v.get("const"), v.get("type").and_then(Value::as_str)) {
                    (Some(Value::String(s)), _) => format!("`{}`", toml::Value::from(s.as_str())),
                    (Some(other), _) => format!("`{other}`"),
                    (None, Some("number")) => "a number".to_string(),
                    (None, Some("integer")) => "an integer".to_string(),
                    (None, t) => panic!("`{key}`: a value of unexpected type {t:?}"),
                };
                let what = v.get("description").and_then(Value::as_str).map_or_else(
                    || panic!("`{key}`: the value {name} has no doc comment"),
                    one_line,
                );
                write!(text, "<br>{name}: {what}").expect("writing to a String");
            }
        } else if let Some(values) = def.get("enum").and_then(Value::as_array) {
            let names: Vec<String> = values.iter().map(|v| format!("`{v}`")).collect();
            write!(text, "<br>One of {}.", names.join(", ")).expect("writing to a String");
        }
        text.replace('|', "\\|")
    }
}

/// Doc-comment text on one line (a table cell).
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A TOML value as the table shows it: strings and arrays as code, numbers and booleans plain.
fn cell(toml: &str) -> String {
    if toml.starts_with(['"', '[', '{']) {
        format!("`{toml}`")
    } else {
        toml.to_string()
    }
}

/// The generated block, markers included.
fn generate() -> String {
    let defaults = toml_keys(&TrackConfig::default().to_toml());
    let paper = toml_keys(
        &TrackConfig::preset("paper")
            .expect("the paper preset loads")
            .to_toml(),
    );
    let schema = Schema::new();

    let keys: Vec<&str> = defaults.iter().map(|(k, _)| k.as_str()).collect();
    let unique: BTreeSet<String> = keys.iter().map(ToString::to_string).collect();
    assert_eq!(unique.len(), keys.len(), "a key is written twice: {keys:?}");
    assert_eq!(
        unique,
        schema.leaves(),
        "the keys of TrackConfig::to_toml against the fields of TrackConfig's schema"
    );
    let paper_keys: Vec<&str> = paper.iter().map(|(k, _)| k.as_str()).collect();
    assert_eq!(
        paper_keys, keys,
        "the paper preset's keys against the default's"
    );

    let mut out =
        format!("{BEGIN}\n\n| key | default | paper | what it does |\n|---|---|---|---|\n");
    for ((key, default), (_, paper)) in defaults.iter().zip(&paper) {
        writeln!(
            out,
            "| `{key}` | {} | {} | {} |",
            cell(default),
            cell(paper),
            schema.description(key)
        )
        .expect("writing to a String");
    }
    write!(out, "\n{END}\n").expect("writing to a String");
    out
}

/// docs/configuration.md with its generated block replaced by `block`.
fn with_block(page: &str, block: &str) -> String {
    let missing = |m: &str| {
        panic!(
            "docs/configuration.md has no line `{m}`: the generated table goes between the \
             markers\n{BEGIN}\nand\n{END}"
        )
    };
    let start = page.find(BEGIN).unwrap_or_else(|| missing(BEGIN));
    let end = page[start..].find(END).unwrap_or_else(|| missing(END)) + start;
    let after = page[end + END.len()..].trim_start_matches('\n');
    let gap = if after.is_empty() { "" } else { "\n" };
    format!("{}{block}{gap}{after}", &page[..start])
}

/// The table of docs/configuration.md is what `TrackConfig` generates; `ACTRACK_BLESS=1`
/// rewrites it.
#[test]
fn configuration_md_is_generated_from_track_config() {
    let path = doc_path();
    let page = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let want = with_block(&page, &generate());
    if want == page {
        return;
    }
    if std::env::var(BLESS).is_ok_and(|v| v == "1") {
        std::fs::write(&path, &want)
            .unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
        eprintln!("{BLESS}=1: rewrote {}", path.display());
        return;
    }
    let (line, (have, should)) = page
        .lines()
        .zip(want.lines().chain(std::iter::repeat("<end of file>")))
        .enumerate()
        .find(|(_, (a, b))| a != b)
        .unwrap_or((page.lines().count(), ("<end of file>", "<more lines>")));
    panic!(
        "docs/configuration.md is out of date with TrackConfig (its doc comments in \
         crates/actrack/src/config.rs, its defaults or the paper preset).\n\
         Regenerate it with\n\n    {COMMAND}\n\nand commit the result.\n\
         First difference, line {}:\n  file:      {have}\n  generated: {should}",
        line + 1
    );
}

/// Every key of `TrackConfig` has exactly one row in docs/configuration.md, and no other key
/// has one.
#[test]
fn configuration_md_lists_every_key_once() {
    let page = std::fs::read_to_string(doc_path()).expect("docs/configuration.md");
    let rows: Vec<&str> = page
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .collect();
    let mut seen = BTreeSet::new();
    for key in &rows {
        assert!(
            seen.insert(key.to_string()),
            "docs/configuration.md has `{key}` twice"
        );
    }
    let keys: BTreeSet<String> = toml_keys(&TrackConfig::default().to_toml())
        .into_iter()
        .map(|(k, _)| k)
        .collect();
    assert_eq!(
        seen, keys,
        "the rows of docs/configuration.md against TrackConfig's keys (regenerate with {COMMAND})"
    );
}
