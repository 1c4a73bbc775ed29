//! The crate-level invariants of `docs/ARCHITECTURE.md`, checked on the
//! dependency edges `cargo metadata` reports for the workspace members, so
//! a `Cargo.toml` change that breaks one fails here instead of in review.
//!
//! Module-level invariants a dependency edge cannot see ("statistics do no
//! I/O" inside murk-fit) are enforced by clippy (`fit/clippy.toml`); see
//! ARCHITECTURE.md.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// Dependency kinds as `cargo metadata` names them (`null` is normal).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Kind {
    Normal,
    Dev,
    Build,
}

/// `member → {(dependency, kind)}` for every workspace member.
fn edges() -> BTreeMap<String, BTreeSet<(String, Kind)>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(&root)
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo metadata failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).expect("metadata is JSON");
    let members: BTreeSet<&str> = meta["workspace_members"]
        .as_array()
        .expect("workspace_members")
        .iter()
        .map(|m| m.as_str().expect("member id"))
        .collect();
    let mut edges = BTreeMap::new();
    for p in meta["packages"].as_array().expect("packages") {
        if !members.contains(p["id"].as_str().expect("package id")) {
            continue;
        }
        let deps = p["dependencies"]
            .as_array()
            .expect("dependencies")
            .iter()
            .map(|d| {
                let kind = match d["kind"].as_str() {
                    None => Kind::Normal,
                    Some("dev") => Kind::Dev,
                    Some("build") => Kind::Build,
                    Some(k) => panic!("unknown dependency kind {k}"),
                };
                (d["name"].as_str().expect("name").to_string(), kind)
            })
            .collect();
        edges.insert(p["name"].as_str().expect("name").to_string(), deps);
    }
    edges
}

/// The dependencies of `krate` of the given kinds.
fn deps<'a>(
    edges: &'a BTreeMap<String, BTreeSet<(String, Kind)>>,
    krate: &str,
    kinds: &[Kind],
) -> Vec<&'a str> {
    edges
        .get(krate)
        .unwrap_or_else(|| panic!("{krate} is not a workspace member"))
        .iter()
        .filter(|(_, k)| kinds.contains(k))
        .map(|(n, _)| n.as_str())
        .collect()
}

const ALL: &[Kind] = &[Kind::Normal, Kind::Dev, Kind::Build];
const NORMAL: &[Kind] = &[Kind::Normal];

/// What the statistics of murk are built on: a crate that depends on one of
/// these computes statistics itself.
const STATISTICS: &[&str] = &[
    "rand",
    "rand_distr",
    "linfa",
    "linfa-linear",
    "ndarray",
    "argmin",
    "argmin-math",
    "libm",
    "kiddo",
];

#[test]
fn the_workspace_is_what_the_invariants_talk_about() {
    let e = edges();
    for krate in [
        "murk-types",
        "murk-velodyne",
        "murk-io",
        "murk-campaign",
        "murk-figures",
        "murk-fit",
        "murk-infer",
        "murk-fixtures",
        "murk-diagnose",
        "murk-cli",
    ] {
        assert!(e.contains_key(krate), "{krate} is not a workspace member");
    }
}

#[test]
fn murk_types_depends_on_no_murk_crate() {
    let e = edges();
    let bad: Vec<_> = deps(&e, "murk-types", ALL)
        .into_iter()
        .filter(|d| d.starts_with("murk"))
        .collect();
    assert!(bad.is_empty(), "murk-types depends on {bad:?}");
}

#[test]
fn infer_never_depends_on_fit() {
    let e = edges();
    assert!(
        !deps(&e, "murk-infer", ALL).contains(&"murk-fit"),
        "murk-infer depends on murk-fit"
    );
}

#[test]
fn fit_and_infer_never_depend_on_diagnose() {
    let e = edges();
    for krate in ["murk-fit", "murk-infer"] {
        assert!(
            !deps(&e, krate, ALL).contains(&"murk-diagnose"),
            "{krate} depends on murk-diagnose"
        );
    }
}

#[test]
fn the_cli_does_no_statistics() {
    let e = edges();
    let bad: Vec<_> = deps(&e, "murk-cli", NORMAL)
        .into_iter()
        .filter(|d| STATISTICS.contains(d))
        .collect();
    assert!(
        bad.is_empty(),
        "murk-cli depends on statistics crates {bad:?}: statistics belong in the libraries"
    );
}

#[test]
fn anyhow_lives_only_in_the_binary() {
    let e = edges();
    for (krate, d) in &e {
        if krate != "murk-cli" {
            assert!(
                !d.contains(&("anyhow".to_string(), Kind::Normal)),
                "{krate} depends on anyhow: a library has its own thiserror enum"
            );
        }
    }
}

#[test]
fn only_tests_benches_and_the_binary_use_the_generator() {
    let e = edges();
    for (krate, d) in &e {
        if krate != "murk-cli" {
            assert!(
                !d.contains(&("murk-fixtures".to_string(), Kind::Normal)),
                "{krate} depends on murk-fixtures outside its tests"
            );
        }
    }
}

#[test]
fn campaign_reads_no_point_clouds_and_figures_know_only_murk_types() {
    let e = edges();
    let campaign: Vec<_> = deps(&e, "murk-campaign", NORMAL)
        .into_iter()
        .filter(|d| d.starts_with("murk"))
        .collect();
    assert_eq!(
        campaign,
        ["murk-types"],
        "murk-campaign's murk dependencies"
    );
    let figures: Vec<_> = deps(&e, "murk-figures", NORMAL)
        .into_iter()
        .filter(|d| d.starts_with("murk"))
        .collect();
    assert_eq!(figures, ["murk-types"], "murk-figures' murk dependencies");
}
