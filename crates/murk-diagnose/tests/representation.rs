//! What a diagnosis holds per recording (issue #13 item 6): summaries per
//! reference cell, never point clouds. The memory figures themselves are
//! measured by `examples/diagnose_bench.rs`; this checks the representation
//! they come from, on two generated campaigns, and that kept returns beyond
//! the memory budget spill to a file and come back bit for bit, with the
//! diagnosis unchanged.

use murk_campaign::Campaign;
use murk_diagnose::DiagnoseParams;
use murk_diagnose::data::{ClearRec, Kept, KeptMemory, load, load_with};
use murk_diagnose::evaluate::RecEval;
use murk_fit::FitParams;
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, PerClass, Preset};
use murk_types::WeatherClass;

#[test]
fn a_recording_is_held_as_per_cell_summaries_and_a_clear_one_as_its_path() {
    // A clear recording holds no points: its id, path, order and scans
    // (a `PointCloud` field alone is six vectors, 144 bytes and more).
    assert!(
        std::mem::size_of::<ClearRec>() <= 96,
        "{}",
        std::mem::size_of::<ClearRec>()
    );
    // An evaluation holds its simulations' summaries (a near-range
    // histogram of 24 bins and one per laser, scene metrics) and its
    // table, not per-unit vectors: its keep probabilities and residuals
    // are computed again when read. 512 bytes leaves room for a few more
    // numbers, not for the three per-unit vectors it held before (each
    // 24 bytes here but megabytes on the heap, which this bound cannot
    // see: `RecEval` has no public constructor that could add them).
    assert!(
        std::mem::size_of::<RecEval>() <= 512,
        "{}",
        std::mem::size_of::<RecEval>()
    );
    let params = FitParams::default()
        .require_edge(false)
        .bootstrap_replicates(0)
        .check()
        .unwrap();
    for (seed, recordings) in [(3u64, 16usize), (4, 24)] {
        let (_dir, campaign) = campaign(seed, recordings);
        let loaded = load(&campaign, WeatherClass::Fog, &params).unwrap();
        let present = loaded.reference.present().len();
        assert!(loaded.recs.len() >= 4, "seed {seed}: {}", loaded.recs.len());
        for r in &loaded.recs {
            // One unit per reference cell at most, each kept return paired
            // with one of the units' expected returns.
            assert!(r.units.len() <= present, "{}: {}", r.id, r.units.len());
            let trials: u64 = r.units.iter().map(|u| u.trials as u64).sum();
            let kept: u64 = r.units.iter().map(|u| u.kept as u64).sum();
            assert!(kept <= trials, "{}", r.id);
            assert_eq!(r.kept.len() as u64, kept, "{}", r.id);
            // So a recording's summaries are bounded by its reference cells
            // (times its scans), whatever its points: a bit and a byte per
            // reference cell for its units (a single-scan file's counts fit
            // in a byte), 12 bytes per kept return.
            assert!(
                r.units.heap_bytes() <= present.div_ceil(64) * 8 + present,
                "{}: {} bytes of units for {present} cells",
                r.id,
                r.units.heap_bytes()
            );
            assert_eq!(r.kept.heap_bytes(), r.kept.bytes());
            assert!(r.kept.bytes() <= r.kept.len() * std::mem::size_of::<Kept>());
            let bytes = r.units.heap_bytes() + r.kept.heap_bytes();
            assert!(bytes <= 14 * present, "{}: {bytes} bytes", r.id);
        }
    }
}

/// A generated fog campaign of `recordings` (30 % clear).
fn campaign(seed: u64, recordings: usize) -> (tempfile::TempDir, Campaign) {
    let dir = tempfile::tempdir().unwrap();
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = recordings;
    c.weather.mix = PerClass {
        clear: 0.3,
        fog: 0.7,
        rain: 0.0,
        snow: 0.0,
    };
    // The campaign in a folder of the temporary one: its truth goes beside
    // it (`campaign.truth.json`), inside what the test removes.
    let path = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&path))
        .unwrap();
    let campaign = Campaign::open(&path).unwrap();
    (dir, campaign)
}

#[test]
fn kept_returns_beyond_the_budget_spill_and_read_back_bit_for_bit() {
    let params = FitParams::default()
        .require_edge(false)
        .bootstrap_replicates(0)
        .check()
        .unwrap();
    let (_dir, campaign) = campaign(5, 20);
    let held = load(&campaign, WeatherClass::Fog, &params).unwrap();
    assert!(held.spill.is_none());
    let bytes: Vec<u64> = held.recs.iter().map(|r| r.kept.bytes() as u64).collect();
    // A budget that holds the first three recordings: the rest spill.
    let budget = bytes[..3].iter().sum::<u64>();
    let spill_dir = tempfile::tempdir().unwrap();
    let memory = KeptMemory {
        budget_bytes: budget,
        spill_dir: Some(spill_dir.path().to_path_buf()),
    };
    let spilled = load_with(&campaign, WeatherClass::Fog, &params, &[], &memory).unwrap();
    assert!(spilled.spill.is_some());
    assert_eq!(spilled.recs.len(), held.recs.len());
    let mut in_memory = 0u64;
    for (i, (a, b)) in held.recs.iter().zip(&spilled.recs).enumerate() {
        assert_eq!(a.id, b.id);
        assert_eq!(b.kept.is_spilled(), i >= 3, "{}", b.id);
        assert_eq!(b.kept.len(), a.kept.len());
        // The same returns, bit for bit, in the same order.
        assert_eq!(a.kept.get(), b.kept.get(), "{}", b.id);
        if b.kept.is_spilled() {
            assert_eq!(b.kept.heap_bytes(), 0);
        } else {
            in_memory += b.kept.bytes() as u64;
        }
    }
    assert!(in_memory <= budget);
    assert!(spilled.spill_error().is_ok());
    // The spill file has no name: the folder stays empty.
    assert_eq!(std::fs::read_dir(spill_dir.path()).unwrap().count(), 0);
}

/// A quick fog diagnosis of `campaign` holding `kept_mb` of kept returns
/// in memory: the report and the extended table as JSON.
fn diagnose_json(campaign: &Campaign, kept_mb: f64) -> (String, Option<String>) {
    let d = DiagnoseParams::new(WeatherClass::Fog)
        .folds(2)
        .permutations(99)
        .sims(1)
        .detectable(false)
        .kept_memory_mb(kept_mb)
        .check()
        .unwrap()
        .run(campaign)
        .unwrap();
    (
        d.report.to_json(),
        d.extended_table.map(|t| t.to_json().unwrap()),
    )
}

#[test]
fn a_diagnosis_is_the_same_bytes_with_its_kept_returns_spilled() {
    let (_dir, campaign) = campaign(6, 24);
    let (held, spilled) = (
        diagnose_json(&campaign, 256.0),
        diagnose_json(&campaign, 0.0),
    );
    assert!(held.0.contains("\"findings\""));
    assert_eq!(held, spilled);
}

#[test]
fn bad_spill_settings_are_refused_with_the_reason() {
    let e = DiagnoseParams::new(WeatherClass::Fog)
        .kept_memory_mb(f64::NAN)
        .check()
        .unwrap_err()
        .to_string();
    assert!(e.contains("kept_memory_mb") && e.contains("≥ 0"), "{e}");
    let e = DiagnoseParams::new(WeatherClass::Fog)
        .spill_dir(Some("/nonexistent/murk-spill".into()))
        .check()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("spill_dir") && e.contains("/nonexistent/murk-spill"),
        "{e}"
    );
}

/// Recordings of many revolutions (`.pcap`) keep one return per revolution
/// in a cell: those are held as the cell's sums, so what a recording holds
/// does not grow with its revolutions, and the diagnosis is the same bytes
/// spilled or not. The real VLP-16 capture cut into `.pcap` parts, half of
/// them relabelled fog (a weather that does nothing), beside the semi-real
/// source's single-revolution fog recordings. Skips, saying so, without
/// `../shared/data/real`.
#[test]
fn pcap_recordings_are_held_as_cell_sums() {
    use murk_fixtures::semi_real::{self, SemiRealConfig};
    let Some(capture) = semi_real::vlp16_capture(env!("CARGO_MANIFEST_DIR")) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cfg = SemiRealConfig {
        clear_pcap_parts: 4,
        degraded: 12,
        ..SemiRealConfig::default()
    };
    semi_real::vlp16_campaign(&capture, dir.path(), &cfg, 8).unwrap();
    // Relabel every other clear part (two of four, about six revolutions
    // each) fog of MOR 150 m.
    let csv_path = dir.path().join("weather.csv");
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let mut clear_seen = 0;
    let mut out = String::new();
    for l in csv.lines() {
        if l.contains(",Clear,") {
            clear_seen += 1;
            if clear_seen % 2 == 0 {
                out.push_str(&l.replace(",Clear,", ",Fog,").replace("10000.0", "150.0"));
                out.push('\n');
                continue;
            }
        }
        out.push_str(l);
        out.push('\n');
    }
    assert_eq!(clear_seen, 4, "{csv}");
    std::fs::write(&csv_path, out).unwrap();
    let campaign = Campaign::open(dir.path()).unwrap();
    let params = FitParams::default()
        .require_edge(false)
        .bootstrap_replicates(0)
        .check()
        .unwrap();
    let loaded = load(&campaign, WeatherClass::Fog, &params).unwrap();
    let pcaps: Vec<_> = loaded
        .recs
        .iter()
        .filter(|r| r.lidar.extension().is_some_and(|e| e == "pcap"))
        .collect();
    assert_eq!(pcaps.len(), 2);
    let present = loaded.reference.present().len();
    for r in &pcaps {
        let v = r.kept.get();
        let in_cells: u32 = v.cells.iter().map(|c| c.n).sum();
        eprintln!(
            "{}: {} kept returns, {} listed, {} summed in {} cells: {} bytes (12 per return: {})",
            r.id,
            r.kept.len(),
            v.singles.len(),
            in_cells,
            v.cells.len(),
            r.kept.bytes(),
            12 * r.kept.len()
        );
        assert_eq!(v.singles.len() + in_cells as usize, r.kept.len());
        assert_eq!(r.kept.heap_bytes(), r.kept.bytes());
        // Several revolutions each: most returns share their cell, and what
        // the recording holds is bounded by the reference's cells (40 bytes
        // each at most: three listed returns take 36), not by its
        // revolutions.
        assert!(
            r.kept.bytes() < 12 * r.kept.len() && r.kept.bytes() <= 40 * present,
            "{}: {} bytes for {} returns, {present} reference cells",
            r.id,
            r.kept.bytes(),
            r.kept.len()
        );
    }
    assert_eq!(
        diagnose_json(&campaign, 256.0),
        diagnose_json(&campaign, 0.0)
    );
}

/// The baselines' clear part serves the diagnosis's own reference and the
/// folds' parameters (which differ from the full fit's only in the law
/// comparison): loading with it gives the reference, clear recordings and
/// recordings a load without it builds itself, and one part for both
/// parameter sets.
#[test]
fn the_clear_part_gives_the_reference_a_load_builds_itself() {
    let (_dir, campaign) = campaign(7, 16);
    let full = FitParams::default().check().unwrap();
    let folds = FitParams::default().compare_laws(false).check().unwrap();
    let own = load(&campaign, WeatherClass::Fog, &full).unwrap();
    let with = load_with(
        &campaign,
        WeatherClass::Fog,
        &full,
        &[folds, full.clone()],
        &KeptMemory::default(),
    )
    .unwrap();
    // Compared as text: cells outside the reference hold NaN, which `==`
    // never equals.
    assert_eq!(
        format!("{:?}", with.reference),
        format!("{:?}", own.reference)
    );
    assert_eq!(with.clear, own.clear);
    assert_eq!(with.cells, own.cells);
    assert_eq!(with.recs, own.recs);
    assert_eq!(with.clear_parts.len(), 2);
    assert!(std::sync::Arc::ptr_eq(
        &with.clear_parts[0],
        &with.clear_parts[1]
    ));
}
