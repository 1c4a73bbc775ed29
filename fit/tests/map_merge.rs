//! Fit as map and merge (issue #14): random shardings of a campaign, mapped
//! in two phases and merged in random orders and trees, give the table of
//! one fit byte for byte; states that cannot be merged or finished are
//! refused with errors that say why.

// These tests write and damage state files and campaigns on disk.
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

use std::path::{Path, PathBuf};

use murk_campaign::Campaign;
use murk_fit::{FitError, FitInputs, FitParams, FitState, FitValidParams, Selection};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};
use murk_types::WeatherClass;
use rand::rngs::ChaCha8Rng as StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};

fn default_campaign() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/default-campaign")
}

fn params() -> FitValidParams {
    FitParams::default()
        .bootstrap_replicates(50)
        .check()
        .unwrap()
}

fn generated(dir: &Path, seed: u64, recordings: usize) -> PathBuf {
    let path = dir.join(format!("campaign-{seed}"));
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = recordings;
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    path
}

/// Splits `ids` into `n` random non-empty-or-empty groups.
fn random_groups(ids: &[String], n: usize, rng: &mut StdRng) -> Vec<Vec<String>> {
    let mut groups = vec![Vec::new(); n];
    for id in ids {
        groups[rng.random_range(0..n)].push(id.clone());
    }
    groups
}

/// Merges `states` in a random tree (random pairs until one is left),
/// sometimes round-tripping a state through its bytes on the way.
fn merge_randomly(mut states: Vec<FitState>, rng: &mut StdRng) -> FitState {
    assert!(!states.is_empty());
    while states.len() > 1 {
        states.shuffle(rng);
        let a = states.pop().unwrap();
        let b = states.pop().unwrap();
        let mut m = a.merge(b).unwrap();
        if rng.random_bool(0.3) {
            m = FitState::from_bytes(&m.to_bytes().unwrap(), "round trip").unwrap();
        }
        states.push(m);
    }
    states.pop().unwrap()
}

fn ids_of(inputs: &FitInputs, clear: bool) -> Vec<String> {
    inputs
        .recordings
        .iter()
        .filter(|r| (r.class == WeatherClass::Clear) == clear)
        .map(|r| r.id.clone())
        .collect()
}

/// One random sharding into `nc` clear and `nd` degraded groups; the table.
fn sharded_table(
    inputs: &FitInputs,
    p: &FitValidParams,
    nc: usize,
    nd: usize,
    rng: &mut StdRng,
) -> String {
    let clear: Vec<FitState> = random_groups(&ids_of(inputs, true), nc, rng)
        .into_iter()
        .map(|g| {
            p.fit_partial(inputs, &Selection::Recordings(g), None)
                .unwrap()
        })
        .collect();
    let reference = merge_randomly(clear.clone(), rng);
    let reference = FitState::from_bytes(&reference.to_bytes().unwrap(), "clear").unwrap();
    let mut all: Vec<FitState> = random_groups(&ids_of(inputs, false), nd, rng)
        .into_iter()
        .map(|g| {
            p.fit_partial(inputs, &Selection::Recordings(g), Some(&reference))
                .unwrap()
        })
        .collect();
    // The clear shards themselves (not their merge) join the final tree.
    all.extend(clear);
    let merged = merge_randomly(all, rng);
    merged.finish().unwrap().to_json().unwrap()
}

fn check_shardings(dir: &Path, seeds: &[u64]) {
    let inputs = FitInputs::from_campaign(&Campaign::open(dir).unwrap());
    let p = params();
    let one = p.fit_inputs(&inputs).unwrap().to_json().unwrap();
    let (c, d) = (ids_of(&inputs, true).len(), ids_of(&inputs, false).len());
    for &seed in seeds {
        let mut rng = StdRng::seed_from_u64(seed);
        // 1 shard, one recording per shard, and random counts.
        let (nc, nd) = match seed % 3 {
            0 => (1, 1),
            1 => (c, d),
            _ => (
                rng.random_range(2..=c.max(2)),
                rng.random_range(2..=d.max(2)),
            ),
        };
        let t = sharded_table(&inputs, &p, nc, nd, &mut rng);
        assert!(
            t == one,
            "{}: seed {seed}, {nc} clear and {nd} degraded shards: table differs from one fit",
            dir.display()
        );
    }
}

#[test]
fn default_campaign_random_shardings_give_the_same_bytes() {
    check_shardings(&default_campaign(), &[0, 1, 2, 5]);
}

#[test]
fn generated_campaign_random_shardings_give_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = generated(tmp.path(), 11, 40);
    let inputs = FitInputs::from_campaign(&Campaign::open(&dir).unwrap());
    let table = params().fit_inputs(&inputs).unwrap();
    assert!(
        table.table().weathers.len() >= 2,
        "the generated campaign should hold several weathers"
    );
    check_shardings(&dir, &[3, 4, 7]);
}

#[test]
fn contiguous_shards_cover_the_campaign_once() {
    let inputs = FitInputs::from_campaign(&Campaign::open(default_campaign()).unwrap());
    let p = params();
    let n = 3;
    let clear = (1..=n)
        .map(|k| p.fit_partial(&inputs, &Selection::Shard { k, n }, None))
        .collect::<Result<Vec<_>, _>>()
        .unwrap();
    let mut rng = StdRng::seed_from_u64(9);
    let reference = merge_randomly(clear, &mut rng);
    assert!(!reference.is_complete());
    let mut all = vec![reference.clone()];
    for k in 1..=n {
        all.push(
            p.fit_partial(&inputs, &Selection::Shard { k, n }, Some(&reference))
                .unwrap(),
        );
    }
    let t = merge_randomly(all, &mut rng).finish().unwrap();
    assert_eq!(
        t.to_json().unwrap(),
        p.fit_inputs(&inputs).unwrap().to_json().unwrap()
    );
}

fn err_text(r: Result<FitState, FitError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn states_of_another_campaign_or_other_params_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let other = generated(tmp.path(), 5, 20);
    let a_in = FitInputs::from_campaign(&Campaign::open(default_campaign()).unwrap());
    let b_in = FitInputs::from_campaign(&Campaign::open(&other).unwrap());
    let p = params();
    let a = p
        .fit_partial(&a_in, &Selection::Shard { k: 1, n: 4 }, None)
        .unwrap()
        .with_label("a.state");
    let b = p
        .fit_partial(&b_in, &Selection::Shard { k: 1, n: 4 }, None)
        .unwrap()
        .with_label("b.state");
    let e = err_text(a.clone().merge(b));
    assert!(
        e.contains("a.state") && e.contains("b.state") && e.contains("different campaigns"),
        "{e}"
    );

    let q = FitParams::default()
        .bootstrap_replicates(50)
        .seed(7)
        .check()
        .unwrap();
    let c = q
        .fit_partial(&a_in, &Selection::Shard { k: 2, n: 4 }, None)
        .unwrap()
        .with_label("c.state");
    let e = err_text(a.clone().merge(c));
    assert!(
        e.contains("a.state") && e.contains("c.state") && e.contains("seed = 0 vs 7"),
        "{e}"
    );

    // The same recording twice would be counted twice.
    let e = err_text(a.clone().merge(a.clone().with_label("again.state")));
    assert!(e.contains("mapped once"), "{e}");
}

#[test]
fn truncated_and_corrupted_state_files_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let inputs = FitInputs::from_campaign(&Campaign::open(default_campaign()).unwrap());
    let s = params()
        .fit_partial(&inputs, &Selection::Shard { k: 1, n: 8 }, None)
        .unwrap();
    let path = tmp.path().join("a.state");
    s.write(&path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let back = FitState::read(&path).unwrap();
    assert_eq!(
        back.to_bytes().unwrap(),
        bytes,
        "a state round-trips exactly"
    );

    for (name, damaged, says) in [
        ("cut.state", bytes[..bytes.len() / 2].to_vec(), "truncated"),
        (
            "short.state",
            bytes[..bytes.len() - 1].to_vec(),
            "truncated",
        ),
        (
            "flipped.state",
            {
                let mut b = bytes.clone();
                let i = b.len() / 2;
                b[i] ^= 0x40;
                b
            },
            "corrupted",
        ),
        ("empty.state", Vec::new(), "not a murk fit state"),
        (
            "future.state",
            {
                let mut b = bytes.clone();
                b[8] = 99;
                b
            },
            "state format 99",
        ),
    ] {
        let p = tmp.path().join(name);
        std::fs::write(&p, damaged).unwrap();
        let e = err_text(FitState::read(&p));
        assert!(e.contains(name) && e.contains(says), "{name}: {e}");
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let t = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &t);
        } else {
            std::fs::copy(e.path(), t).unwrap();
        }
    }
}

#[test]
fn degraded_states_of_another_reference_and_incomplete_merges_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("campaign");
    copy_dir(&default_campaign(), &dir);
    let p = params();
    let inputs = FitInputs::from_campaign(&Campaign::open(&dir).unwrap());
    let clear_a = p
        .fit_partial(&inputs, &Selection::All, None)
        .unwrap()
        .with_label("clear-a.state");
    let deg = p
        .fit_partial(&inputs, &Selection::Shard { k: 1, n: 2 }, Some(&clear_a))
        .unwrap()
        .with_label("deg.state");

    // An incomplete merge asked for a table says what is missing.
    let half = clear_a.clone().merge(deg.clone()).unwrap();
    let e = match half.finish() {
        Ok(_) => panic!("an incomplete state gave a table"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("degraded recordings not mapped"), "{e}");
    let missing = ids_of(&inputs, false);
    let last = missing.last().unwrap();
    assert!(e.contains("more") || e.contains(last.as_str()), "{e}");
    let e = match deg.finish() {
        Ok(_) => panic!("a degraded state alone gave a table"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("clear recordings not mapped"), "{e}");

    // Degraded recordings need a complete clear reference.
    let part = p
        .fit_partial(&inputs, &Selection::Shard { k: 1, n: 2 }, None)
        .unwrap();
    let e = err_text(p.fit_partial(&inputs, &Selection::All, Some(&part)));
    assert!(e.contains("a reference needs every clear recording"), "{e}");

    // A clear recording changes on disk: the new clear part is another
    // reference, and the degraded state paired against the old one is refused.
    let clear: Vec<_> = inputs
        .recordings
        .iter()
        .filter(|r| r.class == WeatherClass::Clear)
        .collect();
    std::fs::copy(&clear[1].lidar, &clear[0].lidar).unwrap();
    let clear_b = p
        .fit_partial(&inputs, &Selection::All, None)
        .unwrap()
        .with_label("clear-b.state");
    let e = err_text(clear_b.merge(deg));
    assert!(
        e.contains("clear-b.state")
            && e.contains("deg.state")
            && e.contains("different clear reference"),
        "{e}"
    );
}

/// A clear part mapped once (`map_clear`, its images released) serves fits
/// of the same clear recordings with any subset of the degraded ones: each
/// table is byte for byte the one of mapping and merging that subset with
/// its images kept; other clear recordings or parameters are refused, but
/// for the two only a fit's finish reads.
#[test]
fn a_clear_part_serves_fits_of_any_degraded_subset_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let p = params();
    let mut rng = StdRng::seed_from_u64(21);
    for dir in [default_campaign(), generated(tmp.path(), 5, 40)] {
        let inputs = FitInputs::from_campaign(&Campaign::open(&dir).unwrap());
        let clear = p.map_clear(&inputs).unwrap();
        let mut subsets = vec![inputs.clone()];
        for _ in 0..3 {
            let mut sub = inputs.clone();
            sub.recordings
                .retain(|r| r.class == WeatherClass::Clear || rng.random_bool(0.6));
            subsets.push(sub);
        }
        for sub in &subsets {
            let kept = FitState::map_all(sub, &p).unwrap().finish().unwrap();
            let with = p.fit_inputs_with(sub, &clear).unwrap();
            assert_eq!(
                with.to_json().unwrap(),
                kept.to_json().unwrap(),
                "{} with {} recordings",
                dir.display(),
                sub.recordings.len()
            );
        }
        let mut fewer = inputs.clone();
        let first = fewer
            .recordings
            .iter()
            .position(|r| r.class == WeatherClass::Clear)
            .unwrap();
        fewer.recordings.remove(first);
        let e = p.fit_inputs_with(&fewer, &clear).unwrap_err().to_string();
        assert!(e.contains("different clear recordings"), "{e}");
        let other = FitParams::default()
            .bootstrap_replicates(60)
            .check()
            .unwrap();
        let e = other
            .fit_inputs_with(&inputs, &clear)
            .unwrap_err()
            .to_string();
        assert!(e.contains("different parameters"), "{e}");
        assert!(!clear.serves(&other));
        // Parameters that only a fit's finish reads (the law comparison,
        // the bend) may differ: the part serves them, byte for byte.
        for q in [
            FitParams::default()
                .bootstrap_replicates(50)
                .compare_laws(false),
            FitParams::default()
                .bootstrap_replicates(50)
                .apply_bend(true),
        ] {
            let q = q.check().unwrap();
            assert!(clear.serves(&q));
            let with = q.fit_inputs_with(&inputs, &clear).unwrap();
            let kept = FitState::map_all(&inputs, &q).unwrap().finish().unwrap();
            assert_eq!(with.to_json().unwrap(), kept.to_json().unwrap());
        }
    }
}

/// Fits and clear states with every clear image spilled to the temporary
/// file ([`murk_fit::set_clear_image_memory`] 0) against every image in
/// memory: the same table and state bytes, and sharded maps of spilled
/// images merge to the same table. (The setting is the process's; another
/// test running meanwhile only changes where its images sit, not its
/// result.)
#[test]
fn spilled_clear_images_give_the_same_table_and_state_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let generated = generated(tmp.path(), 12, 40);
    let p = params();
    for dir in [default_campaign(), generated] {
        let inputs = FitInputs::from_campaign(&Campaign::open(&dir).unwrap());
        let run = |bytes: u64| {
            murk_fit::set_clear_image_memory(bytes);
            let table = p.fit_inputs(&inputs).unwrap().to_json().unwrap();
            let state = p
                .fit_partial(&inputs, &Selection::All, None)
                .unwrap()
                .to_bytes()
                .unwrap();
            (table, state)
        };
        let memory = run(u64::MAX);
        let spilled = run(0);
        assert!(memory.0 == spilled.0, "{}: tables differ", dir.display());
        assert!(memory.1 == spilled.1, "{}: states differ", dir.display());
        murk_fit::set_clear_image_memory(0);
        let mut rng = StdRng::seed_from_u64(5);
        let (c, d) = (ids_of(&inputs, true).len(), ids_of(&inputs, false).len());
        let sharded = sharded_table(&inputs, &p, c.min(3), d.min(3), &mut rng);
        assert!(
            sharded == memory.0,
            "{}: spilled shards differ",
            dir.display()
        );
    }
    murk_fit::set_clear_image_memory(murk_fit::DEFAULT_CLEAR_IMAGE_MEMORY);
}
