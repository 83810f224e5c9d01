//! Limits only shrink: every bound of `tests/census-bounds.toml` (the robust law's known failures,
//! as the censuses count them) is compared with the file's previous version in git — the committed
//! one when the working copy differs from it, else the version before the last commit that changed
//! it. A bound that rises fails; one that falls or goes (its failure fixed) passes.

mod common;

use std::path::Path;
use std::process::Command;

/// Every `(table.key, value)` of a bounds file.
fn flatten(t: &toml::Table, prefix: &str, out: &mut Vec<(String, f64)>) {
    for (k, v) in t {
        let name = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(t) => flatten(t, &name, out),
            toml::Value::Integer(i) => out.push((name, *i as f64)),
            toml::Value::Float(f) => out.push((name, *f)),
            v => panic!("census bound {name} is not a number: {v}"),
        }
    }
}

fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The file's previous version: `(which, text)`, `None` when it has none (its first version).
fn previous(dir: &Path) -> Option<(String, String)> {
    let rel = git(
        dir,
        &["ls-files", "--full-name", "tests/census-bounds.toml"],
    )
    .expect("the census bounds are checked against the git history: run from a git clone");
    let rel = rel.trim();
    if rel.is_empty() {
        return None; // not committed yet: its first version
    }
    let changed = !Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(["diff", "--quiet", "HEAD", "--", "tests/census-bounds.toml"])
        .status()
        .expect("git")
        .success();
    if changed {
        return git(dir, &["show", &format!("HEAD:{rel}")]).map(|t| ("HEAD".into(), t));
    }
    let log = git(
        dir,
        &[
            "log",
            "-n",
            "2",
            "--format=%H",
            "--",
            "tests/census-bounds.toml",
        ],
    )?;
    let before = log.lines().nth(1)?;
    git(dir, &["show", &format!("{before}:{rel}")]).map(|t| (before.to_string(), t))
}

/// The bounds of `now` above their value in `then`, one line each.
fn risen(now: &[(String, f64)], then: &[(String, f64)]) -> Vec<String> {
    now.iter()
        .filter_map(|(name, v)| {
            let (_, old) = then.iter().find(|(n, _)| n == name)?;
            (v > old).then(|| format!("{name}: {old} → {v}"))
        })
        .collect()
}

#[test]
fn a_risen_bound_is_caught_and_a_lowered_or_fixed_one_is_not() {
    let table = |text: &str| {
        let mut v = Vec::new();
        flatten(&text.parse().unwrap(), "", &mut v);
        v
    };
    let then = table("[a]\nx = 3\ny = 1.5\n[b.c]\nz = 2\n");
    let now = table("[a]\nx = 2\ny = 1.6\n[b.c]\nnew = 9\n");
    assert_eq!(risen(&now, &then), ["a.y: 1.5 → 1.6"]);
    assert!(risen(&then, &then).is_empty());
}

#[test]
fn bounds_only_shrink() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut now = Vec::new();
    flatten(&common::bounds(), "", &mut now);
    assert!(
        now.len() > 50,
        "every census has its bounds here ({} found)",
        now.len()
    );
    for (name, v) in &now {
        assert!(v.is_finite() && *v >= 0.0, "{name} = {v}");
    }
    let Some((at, text)) = previous(dir) else {
        println!("tests/census-bounds.toml has no earlier version: nothing to compare");
        return;
    };
    let mut then = Vec::new();
    flatten(
        &text.parse().expect("the earlier version is TOML"),
        "",
        &mut then,
    );
    let risen = risen(&now, &then);
    assert!(
        risen.is_empty(),
        "census bounds may only go down (against {at}):\n{}",
        risen.join("\n")
    );
    let new: Vec<&String> = now
        .iter()
        .filter(|(n, _)| !then.iter().any(|(m, _)| m == n))
        .map(|(n, _)| n)
        .collect();
    println!("compared with {at}; new bounds: {new:?}");
}
