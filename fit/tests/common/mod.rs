//! Campaign set-ups shared by murk-fit's integration tests.

use murk_fixtures::{GeneratorConfig, PerClass, Preset};

/// The generator's small preset at 40 recordings, 30 % clear and 70 % fog,
/// fired every 2° (a campaign that fits in seconds): the generated fog
/// campaign of the slope, interval and edge tests, which then set its MOR
/// noise or slopes.
pub fn fog_campaign() -> GeneratorConfig {
    let mut c = GeneratorConfig::preset(Preset::Small);
    c.campaign.recordings = 40;
    c.lidar.azimuth_resolution_deg = 2.0;
    c.weather.mix = PerClass {
        clear: 0.3,
        fog: 0.7,
        rain: 0.0,
        snow: 0.0,
    };
    c
}
