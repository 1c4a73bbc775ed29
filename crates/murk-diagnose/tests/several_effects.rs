//! Issue #13: campaigns hiding two and three effects, a confounded proxy
//! column, a covariate with 25 % empty cells, and nulls with a dozen junk
//! columns, in fog, rain and snow. Each hidden effect must be among the
//! significant findings, every significant finding must be a hidden effect
//! (anything else is explained by one, or turned down for gaining nothing
//! held out), nulls come back clean, and each accepted step gains on
//! held-out recordings. Nothing here or in the diagnosis names a covariate
//! specially.
//!
//! The always-on tests run one seed per case; `sweep` (ignored) runs every
//! case over several seeds and prints the measured table.

mod common;

use common::{Case, cases, check, run, score, summary};

fn case(i: usize) -> Case {
    cases().swap_remove(i)
}

#[test]
fn two_survival_effects_in_rain_both_found_no_echo() {
    let c = case(0);
    check(&c, &run(&c, 31));
}

#[test]
fn three_effects_across_observables_in_fog() {
    let c = case(1);
    check(&c, &run(&c, 32));
}

#[test]
fn a_confounded_proxy_column_is_explained_by_its_cause() {
    let c = case(2);
    let d = run(&c, 33);
    check(&c, &d);
    let gust = d
        .report
        .findings
        .iter()
        .find(|f| f.observable.name() == "survival" && f.covariate == "Gust speed (m/s)")
        .expect("the proxy is tested");
    assert!(!gust.significant, "{gust:?}");
}

#[test]
fn a_cause_with_a_quarter_of_its_cells_empty_and_a_count_effect_in_snow() {
    let c = case(3);
    check(&c, &run(&c, 34));
}

#[test]
fn null_with_junk_columns_in_fog_is_clean() {
    let c = case(4);
    let d = run(&c, 35);
    check(&c, &d);
    assert!(d.report.steps.is_empty(), "{}", summary(&d));
}

#[test]
fn null_with_junk_columns_in_rain_is_clean() {
    let c = case(5);
    let d = run(&c, 36);
    check(&c, &d);
    assert!(d.report.steps.is_empty(), "{}", summary(&d));
}

/// `cargo test --workspace --test several_effects -- --ignored --nocapture`:
/// every case over seeds 1–4, a table of hidden effects found, false
/// findings and held-out gains.
#[test]
#[ignore]
fn sweep() {
    let seeds: Vec<u64> = std::env::var("MURK_SWEEP_SEEDS")
        .ok()
        .map(|s| s.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or_else(|| vec![1, 2, 3, 4]);
    println!(
        "| case | seed | found / hidden | false findings | steps (held-out gain, p) | combined gain |"
    );
    println!("|---|---|---|---|---|---|");
    for c in cases() {
        for &seed in &seeds {
            let t0 = std::time::Instant::now();
            let d = run(&c, seed);
            let s = score(&c, &d);
            println!(
                "| {} | {seed} | {}/{} | {} | {} | {} | ({:.0} s)",
                c.name,
                s.found,
                s.hidden,
                if s.false_findings.is_empty() {
                    "0".to_string()
                } else {
                    format!(
                        "{}: {}",
                        s.false_findings.len(),
                        s.false_findings.join(", ")
                    )
                },
                s.steps
                    .iter()
                    .map(|(n, g, p)| format!("{n} {:+.1} % (p {p:.4})", 100.0 * g))
                    .collect::<Vec<_>>()
                    .join("; "),
                s.combined
                    .iter()
                    .map(|(m, g)| format!("{m} {:+.1} %", 100.0 * g))
                    .collect::<Vec<_>>()
                    .join("; "),
                t0.elapsed().as_secs_f64()
            );
            if !s.missed.is_empty() || !s.false_findings.is_empty() {
                eprintln!("{}{}", c.name, summary(&d));
            }
        }
    }
}
