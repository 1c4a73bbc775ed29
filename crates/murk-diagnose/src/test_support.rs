//! Generated campaigns for the crate's unit tests (test builds only).

use murk_fixtures::{
    EffectFunction, EffectSpec, Generator, GeneratorConfig, Observable, OutputOptions, PerClass,
    Preset,
};

use crate::data::Loaded;

/// A generated campaign of `recordings` small-preset recordings (a quarter
/// clear, the rest fog), loaded for fog with the default fit parameters.
/// With `lower_beams_less_far`, the lower beams see less far (a factor 0.8
/// on the vanishing distance below −10° elevation, against 1 above).
pub(crate) fn fog_campaign(
    recordings: usize,
    seed: u64,
    lower_beams_less_far: bool,
) -> (tempfile::TempDir, Loaded) {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = recordings;
    c.weather.mix = PerClass {
        clear: 0.25,
        fog: 0.75,
        rain: 0.0,
        snow: 0.0,
    };
    if lower_beams_less_far {
        c.effects = vec![EffectSpec {
            name: "lower beams see less far".into(),
            observable: Observable::Survival,
            survival_mode: None,
            covariate: "elevation".into(),
            weathers: vec![murk_types::WeatherClass::Fog],
            function: EffectFunction::Step {
                threshold: -10.0,
                below: 0.8,
                above: 1.0,
            },
            returns: None,
        }];
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("campaign");
    Generator::new(c)
        .unwrap()
        .write_campaign(seed, &OutputOptions::new(&out))
        .unwrap();
    let campaign = murk_campaign::Campaign::open(&out).unwrap();
    let params = murk_fit::FitParams::default().check().unwrap();
    let loaded = crate::data::load(&campaign, murk_types::WeatherClass::Fog, &params).unwrap();
    (dir, loaded)
}
