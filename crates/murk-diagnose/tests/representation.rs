//! What a diagnosis holds per recording (issue #13 item 6): summaries per
//! reference cell, never point clouds. The memory figures themselves are
//! measured by `examples/diagnose_bench.rs`; this checks the representation
//! they come from, on two generated campaigns.

use murk_campaign::Campaign;
use murk_diagnose::data::{ClearRec, Kept, load};
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
        let dir = tempfile::tempdir().unwrap();
        let mut c = GeneratorConfig::preset(Preset::Small);
        c.campaign.recordings = recordings;
        c.weather.mix = PerClass {
            clear: 0.3,
            fog: 0.7,
            rain: 0.0,
            snow: 0.0,
        };
        Generator::new(c)
            .unwrap()
            .write_campaign(seed, &OutputOptions::new(dir.path()))
            .unwrap();
        let campaign = Campaign::open(dir.path()).unwrap();
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
            let bytes = r.units.heap_bytes() + r.kept.len() * std::mem::size_of::<Kept>();
            assert!(bytes <= 14 * present, "{}: {bytes} bytes", r.id);
        }
    }
}
