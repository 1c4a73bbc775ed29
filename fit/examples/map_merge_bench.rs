//! Fit as map and merge against one fit (issue #14's benchmark): prints
//! figures, it is not a timed test.
//!
//! Generates a campaign of `RECORDINGS` small-preset recordings (seed 1)
//! into `DIR/campaign-RECORDINGS` unless it is there already, fits it once,
//! then as `SHARDS` shards mapped one after another in this process (each
//! map uses every rayon thread, as one fit does): the clear shards, their
//! merge, the degraded shards against it, the merge of everything, the
//! finish. Every state goes through its bytes (what a cluster ships). The
//! merged table must equal the one fit's byte for byte.
//!
//! `cargo test --workspace --no-run` builds it; run
//! `target/debug/examples/map_merge_bench DIR [RECORDINGS] [SHARDS]`
//! (`cargo run --release --example map_merge_bench -- DIR 1000 8` for a
//! release build).

use std::path::PathBuf;
use std::time::Instant;

use murk_campaign::Campaign;
use murk_fit::{FitInputs, FitParams, FitState, Selection};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};

fn secs(t: Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let dir: PathBuf = args
        .next()
        .map(PathBuf::from)
        .ok_or("usage: map_merge_bench DIR [RECORDINGS] [SHARDS]")?;
    let recordings: usize = args.next().map_or(Ok(1000), |s| s.parse())?;
    let shards: usize = args.next().map_or(Ok(8), |s| s.parse())?;
    let path = dir.join(format!("campaign-{recordings}"));
    if !path.join("campaign.toml").is_file() {
        let t = Instant::now();
        let mut c = GeneratorConfig::preset(Preset::Small);
        c.campaign.recordings = recordings;
        Generator::new(c)?.write_campaign(1, &OutputOptions::new(&path))?;
        println!("generated {} in {:.1} s", path.display(), secs(t));
    }
    let inputs = FitInputs::from_campaign(&Campaign::open(&path)?);
    let clear = inputs
        .recordings
        .iter()
        .filter(|r| r.class == murk_types::WeatherClass::Clear)
        .count();
    println!(
        "{} recordings ({} clear, {} degraded), {} rayon threads",
        inputs.recordings.len(),
        clear,
        inputs.recordings.len() - clear,
        rayon::current_num_threads()
    );
    let params = FitParams::default().check()?;

    let t = Instant::now();
    let one = params.fit_inputs(&inputs)?.to_json()?;
    let t_one = secs(t);
    // The same fit's two halves: everything it reads (map_all) and the
    // statistics of the table (finish), which the shards share unchanged.
    let t = Instant::now();
    let all = FitState::map_all(&inputs, &params)?;
    let t_map_all = secs(t);
    let t = Instant::now();
    all.finish()?;
    let t_finish_one = secs(t);
    println!(
        "one fit: {t_one:.2} s (again as its two halves: map {t_map_all:.2} s, finish {t_finish_one:.2} s)"
    );

    let total = Instant::now();
    let ship = |s: FitState| -> Result<(FitState, usize), murk_fit::FitError> {
        let b = s.to_bytes()?;
        Ok((FitState::from_bytes(&b, "shipped")?, b.len()))
    };
    let (mut t_map, mut t_merge, mut bytes_clear, mut bytes_degraded) = (0.0, 0.0, 0, 0);
    let mut states = Vec::new();
    for k in 1..=shards {
        let t = Instant::now();
        let (s, n) =
            ship(params.fit_partial(&inputs, &Selection::Shard { k, n: shards }, None)?)?;
        t_map += secs(t);
        bytes_clear += n;
        states.push(s);
    }
    let t = Instant::now();
    let mut reference = states.remove(0);
    for s in states.drain(..) {
        reference = reference.merge(s)?;
    }
    let (reference, ref_bytes) = ship(reference)?;
    let t_merge_clear = secs(t);
    t_merge += t_merge_clear;
    for k in 1..=shards {
        let t = Instant::now();
        let (s, n) = ship(params.fit_partial(
            &inputs,
            &Selection::Shard { k, n: shards },
            Some(&reference),
        )?)?;
        t_map += secs(t);
        bytes_degraded += n;
        states.push(s);
    }
    let t = Instant::now();
    let mut whole = reference;
    for s in states {
        whole = whole.merge(s)?;
    }
    let t_merge_degraded = secs(t);
    t_merge += t_merge_degraded;
    let t = Instant::now();
    let merged = whole.finish()?.to_json()?;
    let t_finish = secs(t);
    let t_total = secs(total);
    println!(
        "{shards} shards: {t_total:.2} s in all ({:+.1} % against one fit): maps {t_map:.2} s, merges {t_merge:.3} s (clear {t_merge_clear:.3} s incl. shipping the clear state, degraded {t_merge_degraded:.3} s), finish {t_finish:.2} s",
        100.0 * (t_total / t_one - 1.0)
    );
    println!(
        "state sizes: clear shards {:.1} MB in all ({:.2} MB each on average), merged clear state {:.1} MB, degraded shards {:.1} MB in all",
        bytes_clear as f64 / 1e6,
        bytes_clear as f64 / 1e6 / shards as f64,
        ref_bytes as f64 / 1e6,
        bytes_degraded as f64 / 1e6
    );
    println!(
        "map side: {shards} shards {:.2} s (maps + merges, states shipped as bytes) against one map {t_map_all:.2} s: {:+.1} %",
        t_map + t_merge,
        100.0 * ((t_map + t_merge) / t_map_all - 1.0)
    );
    if merged != one {
        return Err("the merged table differs from the one fit's".into());
    }
    println!("merged table byte-identical to the one fit's");
    Ok(())
}
