//! Criterion benches of murk-fit.
//!
//! - `fit_campaign/<recordings>`: the whole fit (read, pair, accumulate,
//!   every estimator, provenance) of a generated campaign at the VLP-16's
//!   native 0.2° step, over a grid of campaign sizes. The campaigns are
//!   written once, outside the timed code, with fixed seeds.
//! - `survival_ml`: the survival-boundary likelihood fit alone on a fixed
//!   histogram (the heaviest estimator).
//!
//! The 1,000-recording end-to-end figure of the issue (< 30 s, < 1 GB) is
//! measured on the release binary with `/usr/bin/time -v murk fit …`; see the
//! crate report.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use murk_campaign::Campaign;
use murk_fit::EdgeShape;
use murk_fit::FitParams;
use murk_fit::{Obs, SurvivalOptions, fit_survival};
use murk_fixtures::{Generator, GeneratorConfig, OutputOptions, Preset};

fn campaigns(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut group = c.benchmark_group("fit_campaign");
    group.sample_size(10);
    for recordings in [20usize, 60] {
        let mut config = GeneratorConfig::preset(Preset::Default);
        config.campaign.recordings = recordings;
        let path = dir.path().join(format!("c{recordings}"));
        Generator::new(config)
            .expect("config")
            .write_campaign(1, &OutputOptions::new(&path))
            .expect("campaign");
        let params = FitParams::default().check().expect("params");
        group.bench_function(recordings.to_string(), |b| {
            b.iter(|| {
                let campaign = Campaign::open(&path).expect("campaign");
                black_box(params.fit(&campaign).expect("fit"))
            })
        });
    }
    group.finish();
}

fn survival(c: &mut Criterion) {
    // Two bands, 4 000 occupied ln-u bins each, a probit edge at 0.3 / 0.35.
    let bands: Vec<Vec<Obs>> = [0.3, 0.35]
        .iter()
        .map(|&s: &f64| {
            (0..4000)
                .map(|k| {
                    let u = 0.01 * (1.0 + k as f64 * 0.0025).exp();
                    let p =
                        0.99 * 0.5 * libm::erfc((u - s) / (0.08 * s) / std::f64::consts::SQRT_2);
                    Obs {
                        u,
                        kept: (200.0 * p).round(),
                        total: 200.0,
                    }
                })
                .collect()
        })
        .collect();
    let opts = SurvivalOptions {
        edge: EdgeShape::Probit,
        shared_width: true,
        fixed_dropout: None,
        dropout_init: 0.01,
        min_trials: 50,
        min_beyond: 10,
    };
    c.bench_function("survival_ml", |b| {
        b.iter(|| black_box(fit_survival(black_box(&bands), &opts)))
    });
}

criterion_group!(benches, campaigns, survival);
criterion_main!(benches);
