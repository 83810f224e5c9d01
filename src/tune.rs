//! `forcecell tune`: judge a tuning, or propose impedance parameters, for a stiffness range and the
//! robot's loop (period, lag, delay). The analysis is `controller::tune`'s; this module only chooses what
//! to analyse and formats it.

use anyhow::{Result, anyhow};
use controller::LawConfig;
use controller::tune::{LoopModel, analyse_impedance, analyse_robust, propose_impedance};
use sim::InnerLoopModel;

use crate::scenario::load_tuning;

/// What to analyse.
#[derive(Clone, Debug, PartialEq)]
pub struct TuneRequest {
    /// Softest expected surface, N/m.
    pub k_min: f64,
    /// Stiffest expected surface, N/m.
    pub k_max: f64,
    /// The robot's loop.
    pub model: LoopModel,
    /// A tuning to judge (built-in name or file); `None`: propose impedance parameters.
    pub tuning: Option<String>,
    /// Force set-point for a proposal, N.
    pub f_r: f64,
}

/// The loop of a named plant (`p0`, `p1`, `p2`).
pub fn loop_of_plant(name: &str) -> Result<LoopModel> {
    let m = InnerLoopModel::by_name(name)
        .ok_or_else(|| anyhow!("unknown plant {name:?}: choose p0, p1 or p2"))?;
    Ok(LoopModel {
        period: m.period,
        lag: m.tau,
        delay: m.delay(),
    })
}

/// The report, as text. `Ok((text, safe))`.
pub fn report(req: &TuneRequest) -> Result<(String, bool)> {
    let Some(name) = &req.tuning else {
        let r =
            propose_impedance(req.f_r, &req.model, req.k_min, req.k_max).map_err(|e| anyhow!(e))?;
        return Ok((
            format!(
                "proposed for k_c in [{:.0}, {:.0}] N/m:\n{r}",
                req.k_min, req.k_max
            ),
            true,
        ));
    };
    let t = load_tuning(name)?;
    match &t.law {
        LawConfig::Robust(p) => {
            let r = analyse_robust(p, req.k_min, req.k_max).map_err(|e| anyhow!(e))?;
            let covered = req.k_max < r.delay_independent_up_to;
            let verdict = if covered {
                format!(
                    "SAFE: the loop gain stays below 2 up to {:.0} N/m: stable for any delay and lag \
                     before the estimator has learnt anything",
                    req.k_max
                )
            } else {
                format!(
                    "UNSAFE without the estimator above {:.0} N/m (the loop gain reaches {:.2} at \
                     {:.0} N/m): there the law relies on k̂_c learnt at first contact; \
                     --k-max {:.0} or below gives an unconditional verdict",
                    r.delay_independent_up_to,
                    r.gain_max,
                    req.k_max,
                    (r.delay_independent_up_to * 0.999).floor()
                )
            };
            Ok((format!("tuning {}:\n{r}\n{verdict}", t.name), covered))
        }
        law => {
            let imp = law
                .impedance()
                .ok_or_else(|| anyhow!("tuning {} has no impedance filter", t.name))?;
            let r =
                analyse_impedance(imp, &req.model, req.k_min, req.k_max).map_err(|e| anyhow!(e))?;
            let mut text = format!("tuning {}:\n{r}", t.name);
            if !r.is_safe()
                && let Ok(p) = propose_impedance(imp.f_r, &req.model, req.k_min, req.k_max)
            {
                text.push_str(&format!(
                    "\n\ninstead, for the same range and loop:\n{p}\nUNSAFE: tuning {} as it \
                     stands (above); the proposal is for the same range and loop",
                    t.name
                ));
            }
            Ok((text, r.is_safe()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_is_unsafe_on_p2_and_a_proposal_follows() {
        let req = TuneRequest {
            k_min: 70_000.0,
            k_max: 70_000.0,
            model: loop_of_plant("p2").unwrap(),
            tuning: Some("paper".into()),
            f_r: 5.0,
        };
        let (text, safe) = report(&req).unwrap();
        assert!(!safe);
        assert!(
            text.contains("UNSAFE") && text.contains("instead"),
            "{text}"
        );
    }

    #[test]
    fn robust_tuning_states_its_condition() {
        let req = TuneRequest {
            k_min: 10_000.0,
            k_max: 500_000.0,
            model: loop_of_plant("p1").unwrap(),
            tuning: Some("robust".into()),
            f_r: 5.0,
        };
        let (text, safe) = report(&req).unwrap();
        assert!(text.contains("below 2"), "{text}");
        assert!(!safe);
        assert!(
            text.lines()
                .last()
                .unwrap()
                .starts_with("UNSAFE without the estimator above 125000"),
            "{text}"
        );
        let req = TuneRequest {
            k_max: 100_000.0,
            ..req
        };
        let (text, safe) = report(&req).unwrap();
        assert!(safe);
        assert!(
            text.lines()
                .last()
                .unwrap()
                .starts_with("SAFE: the loop gain"),
            "{text}"
        );
    }

    /// Every shipped tuning ends its report with a verdict line.
    #[test]
    fn every_tuning_gets_a_verdict() {
        for name in crate::scenario::builtin_tuning_names() {
            let req = TuneRequest {
                k_min: 10_000.0,
                k_max: 500_000.0,
                model: loop_of_plant("p1").unwrap(),
                tuning: Some(name.into()),
                f_r: 5.0,
            };
            let (text, safe) = report(&req).unwrap_or_else(|e| panic!("{name}: {e}"));
            let last = text.lines().last().unwrap();
            assert!(
                last.starts_with(if safe { "SAFE" } else { "UNSAFE" }),
                "{name}: {last}"
            );
        }
    }
}
