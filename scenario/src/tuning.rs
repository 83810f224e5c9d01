//! Tunings: built-in by name (`tunings/*.toml`, embedded) or a TOML file by path, validated.
//!
//! A tuning may start from another: `extends = "robust"` (a built-in name, or a file, relative to the
//! extending file) takes every value of that tuning and the file's own over them, table by table, so
//! a cell's tuning says only what differs (`tunings/robust-gentle.toml` is three lines and a table).
//! The extending tuning names itself; its description is its own or says what it extends.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use controller::Tuning;
use toml::{Table, Value};

use crate::scenario::{builtin, builtin_text, names_a_file, one_line, read_toml_file};

/// How many tunings an `extends` chain may hold: a loop of files ends here with the chain named.
pub const MAX_EXTENDS: usize = 8;

/// Load a built-in tuning by name or a TOML file by path (anything ending in `.toml` or containing a
/// path separator), resolve its `extends`, and validate it.
pub fn load_tuning(spec: &str) -> Result<Tuning> {
    let source = Source::find(spec, None)?;
    let table = source.table(&mut Vec::new())?;
    tuning_from_table(table, &source.origin)
}

/// Parse, resolve `extends` (a relative file from the working directory) and validate a tuning's
/// TOML text; `origin` names it in errors.
pub fn tuning_from_toml(text: &str, origin: &str) -> Result<Tuning> {
    let source = Source {
        origin: origin.to_string(),
        text: text.to_string(),
        dir: None,
    };
    let table = source.table(&mut Vec::new())?;
    tuning_from_table(table, origin)
}

/// Names of the built-in tunings.
pub fn builtin_tuning_names() -> Vec<&'static str> {
    builtin::TUNINGS.iter().map(|(n, _)| *n).collect()
}

fn tuning_from_table(table: Table, origin: &str) -> Result<Tuning> {
    let t: Tuning = Value::Table(table)
        .try_into()
        .map_err(|e: toml::de::Error| anyhow!("{origin}: {}", one_line(&e.to_string())))?;
    t.validate()
        .map_err(|e| anyhow!("{origin}: invalid tuning: {e}"))?;
    Ok(t)
}

/// One tuning's text and where it came from.
struct Source {
    /// The name or path it was asked for by, for errors.
    origin: String,
    text: String,
    /// The directory of a file, for the relative paths it extends.
    dir: Option<PathBuf>,
}

impl Source {
    /// A built-in by name or a file by path (relative to `dir` when given).
    fn find(spec: &str, dir: Option<&Path>) -> Result<Self> {
        if names_a_file(spec) {
            let path = match dir {
                Some(d) if Path::new(spec).is_relative() => d.join(spec),
                _ => PathBuf::from(spec),
            };
            return Ok(Self {
                origin: path.display().to_string(),
                text: read_toml_file(&path, "tuning")?,
                dir: path.parent().map(Path::to_path_buf),
            });
        }
        Ok(Self {
            origin: spec.to_string(),
            text: builtin_text(builtin::TUNINGS, "tuning", spec)?.to_string(),
            dir: None,
        })
    }

    /// The TOML table, with what it extends merged under it; `chain` holds the tunings that extend
    /// this one.
    fn table(&self, chain: &mut Vec<String>) -> Result<Table> {
        let o = &self.origin;
        let mut table: Table = self
            .text
            .parse()
            .map_err(|e: toml::de::Error| anyhow!("{o}: {}", one_line(&e.to_string())))?;
        chain.push(o.clone());
        let Some(base) = table.remove("extends") else {
            return Ok(table);
        };
        let Value::String(base) = base else {
            bail!("{o}: extends must name a tuning (a built-in name or a .toml file), got {base}");
        };
        if chain.len() >= MAX_EXTENDS {
            bail!(
                "{o}: extends {base:?}: more than {MAX_EXTENDS} tunings extend each other ({} → …): a loop?",
                chain.join(" → ")
            );
        }
        if !table.contains_key("name") {
            bail!("{o}: a tuning that extends {base:?} needs a name of its own");
        }
        let source =
            Source::find(&base, self.dir.as_deref()).with_context(|| format!("{o}: extends"))?;
        let mut merged = source.table(chain)?;
        if !table.contains_key("description") {
            table.insert(
                "description".into(),
                Value::String(format!("{base} with the changes of {o}")),
            );
        }
        merge(&mut merged, table);
        Ok(merged)
    }
}

/// `over`'s values into `base`: tables merged key by key, anything else replaced.
fn merge(base: &mut Table, over: Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(Value::Table(b)), Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller::LawConfig;

    fn robust(t: &Tuning) -> &controller::robust::RobustParams {
        let LawConfig::Robust(p) = &t.law else {
            panic!("robust")
        };
        p
    }

    #[test]
    fn an_extending_tuning_takes_its_base_and_overrides_only_what_it_says() {
        let base = load_tuning("robust").unwrap();
        let t = tuning_from_toml(
            "extends = \"robust\"\nname = \"mine\"\n[law.contact]\nreacquire_margin = 2.0\n[loop]\nmax_hold = 0.05\n",
            "mine.toml",
        )
        .unwrap();
        assert_eq!(t.name, "mine");
        assert!(t.description.contains("robust"), "{}", t.description);
        let (p, b) = (robust(&t), robust(&base));
        assert_eq!(p.contact.reacquire_margin, 2.0);
        assert_eq!(t.loop_cfg.max_hold, 0.05);
        // Everything else is the base's: the rest of the table it changed, and the other tables.
        let mut same = *p;
        same.contact.reacquire_margin = b.contact.reacquire_margin;
        assert_eq!(&same, b);
        assert_eq!(t.loop_cfg.max_step, base.loop_cfg.max_step);
    }

    #[test]
    fn the_shipped_variants_are_the_robust_tuning_with_their_changes() {
        let (g, r) = (
            load_tuning("robust-gentle").unwrap(),
            load_tuning("robust").unwrap(),
        );
        let (mut pg, pr) = (*robust(&g), robust(&r));
        assert!(pg.contact.reacquire_margin.is_infinite());
        pg.contact.reacquire_margin = pr.contact.reacquire_margin;
        assert_eq!(&pg, pr);
        assert_eq!(g.loop_cfg, r.loop_cfg);
        assert_eq!(g.name, "robust-gentle");
        // The 100 Hz sensor's: the cell's delay and the correction per command.
        let h = load_tuning("robust-100hz").unwrap();
        let mut ph = *robust(&h);
        assert_eq!((ph.cell.delay, ph.response.kappa), (0.012, 0.5));
        (ph.cell.delay, ph.response.kappa) = (pr.cell.delay, pr.response.kappa);
        assert_eq!(&ph, pr);
        assert_eq!(h.loop_cfg, r.loop_cfg);
    }

    #[test]
    fn a_file_extends_a_file_beside_it_and_errors_name_the_chain() {
        let dir = std::env::temp_dir().join(format!("forcecell-extends-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |n: &str, s: &str| std::fs::write(dir.join(n), s).unwrap();
        write(
            "cell.toml",
            "extends = \"robust\"\nname = \"cell\"\n[law.cell]\ndelay = 0.012\n",
        );
        write(
            "pass.toml",
            "extends = \"cell.toml\"\nname = \"pass\"\n[law]\nf_r = 20.0\n",
        );
        let t = load_tuning(dir.join("pass.toml").to_str().unwrap()).unwrap();
        assert_eq!((robust(&t).f_r, robust(&t).cell.delay), (20.0, 0.012));
        // A loop of files.
        write("a.toml", "extends = \"b.toml\"\nname = \"a\"\n");
        write("b.toml", "extends = \"a.toml\"\nname = \"b\"\n");
        let e = format!(
            "{:#}",
            load_tuning(dir.join("a.toml").to_str().unwrap()).unwrap_err()
        );
        assert!(e.contains("a loop") && e.contains("b.toml"), "{e}");
        // No name of its own, an unknown base, a base that is no name, an unknown key.
        for (text, says) in [
            ("extends = \"robust\"\n", "name of its own"),
            (
                "extends = \"robustt\"\nname = \"x\"\n",
                "unknown tuning \"robustt\"",
            ),
            ("extends = 3\nname = \"x\"\n", "extends must name a tuning"),
            ("extends = \"/dev/zero\"\nname = \"x\"\n", "no tuning file"),
            ("extends = \"/\"\nname = \"x\"\n", "no tuning file"),
            (
                "extends = \"robust\"\nname = \"x\"\n[law.contact]\nreacquire_margn = 1.0\n",
                "reacquire_margn",
            ),
            (
                "extends = \"robust\"\nname = \"x\"\n[law.contact]\nreacquire_margin = -1.0\n",
                "reacquire_margin",
            ),
        ] {
            let e = format!("{:#}", tuning_from_toml(text, "x.toml").unwrap_err());
            assert!(e.contains(says) && e.starts_with("x.toml"), "{text:?}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
