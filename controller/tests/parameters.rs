//! The parameter table of `docs/robust-law.md` is the shipped `robust` tuning's: every parameter the
//! tuning has is a row, every row is a parameter, and the row's shipped value is the tuning's.

use scenario::scenario::{load_tuning, tuning_from_toml};

/// Every numeric leaf of `t` as `(dotted key, value)`, the law's keys without their `law.` prefix.
fn flatten(t: &toml::Table, prefix: &str, out: &mut Vec<(String, f64)>) {
    for (k, v) in t {
        let name = match prefix {
            "" => k.clone(),
            p => format!("{p}.{k}"),
        };
        let key = name.strip_prefix("law.").unwrap_or(&name).to_string();
        match v {
            toml::Value::Table(t) => flatten(t, &name, out),
            toml::Value::Float(f) => out.push((key, *f)),
            toml::Value::Integer(i) => out.push((key, *i as f64)),
            // A switch: 0 off, 1 on (the table writes `false`, `true`).
            toml::Value::Boolean(b) => out.push((key, f64::from(u8::from(*b)))),
            // The law's kind, the tuning's name and description: not parameters.
            toml::Value::String(_) => {}
            v => panic!("{name}: {v}"),
        }
    }
}

/// The Parameters section of `docs/robust-law.md`.
fn section() -> String {
    let doc = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/robust-law.md"),
    )
    .unwrap();
    let start = doc.find("## Parameters").expect("a Parameters section");
    doc[start..].to_string()
}

/// The table's rows: `(parameter, shipped value as written, kind)`.
fn rows() -> Vec<(String, String, String)> {
    section()
        .lines()
        .skip_while(|l| !l.starts_with("| parameter"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                cells[1].trim_matches('`').to_string(),
                cells[3].to_string(),
                cells[5].to_string(),
            )
        })
        .collect()
}

/// The table's rows: `(parameter, shipped value as written)`.
fn table() -> Vec<(String, String)> {
    rows().into_iter().map(|(k, v, _)| (k, v)).collect()
}

#[test]
fn the_docs_parameter_table_is_the_shipped_tuning() {
    let tuning = load_tuning("robust").unwrap();
    let text = toml::to_string(&tuning).unwrap();
    let mut params = Vec::new();
    flatten(&text.parse().unwrap(), "", &mut params);
    let rows = table();
    let mut wrong = Vec::new();
    for (key, value) in &params {
        match rows.iter().find(|(k, _)| k == key) {
            None => wrong.push(format!("{key} = {value} has no row")),
            Some((_, written)) => {
                let v: f64 = match written.as_str() {
                    "false" => 0.0,
                    "true" => 1.0,
                    w => w
                        .replace('−', "-")
                        .parse()
                        .unwrap_or_else(|_| panic!("{key}: shipped {written:?} is not a number")),
                };
                if v != *value {
                    wrong.push(format!(
                        "{key}: the table says {written}, the tuning {value}"
                    ));
                }
            }
        }
    }
    for (key, _) in &rows {
        if !params.iter().any(|(k, _)| k == key) {
            wrong.push(format!("row {key} is no parameter of the tuning"));
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    println!("{} parameters", params.len());
}

/// The section's count ("Of the N: a cell properties, b process choices, c advanced") is the table's.
#[test]
fn the_docs_parameter_count_is_the_table_s() {
    let rows = rows();
    let kind = |k: &str| rows.iter().filter(|(_, _, kind)| kind == k).count();
    let said = format!(
        "Of the {}: {} cell properties, {} process choices, {} advanced",
        rows.len(),
        kind("cell"),
        kind("process"),
        kind("advanced")
    );
    let text = section().replace('\n', " ");
    assert!(text.contains(&said), "the section should say {said:?}");
}

/// The parameters that left the tuning ("Fewer parameters" in docs/robust-law.md): a tuning that
/// still sets one is refused, and the error names the key.
#[test]
fn a_removed_parameter_is_refused_by_name() {
    for (section, key) in [
        ("response", "integral_limit"),
        ("contact", "lift_time"),
        ("contact", "retract_speed"),
        ("contact", "retract_distance"),
        ("observer", "deadband_floor"),
        ("estimator", "dead_zone"),
    ] {
        let text =
            format!("extends = \"robust\"\nname = \"old\"\n[law.{section}]\n{key} = 0.001\n");
        let err = format!("{:#}", tuning_from_toml(&text, "old.toml").unwrap_err());
        assert!(
            err.contains(&format!("unknown field `{key}`")),
            "{section}.{key}: {err}"
        );
    }
}
