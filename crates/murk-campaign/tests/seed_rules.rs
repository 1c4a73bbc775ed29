//! The seed report's selection rules, threshold by threshold: for each class
//! of each preset, a row just inside and rows just outside every condition.
//!
//! Rows are `id,type,rain_a,rain_b,PWD12 MOR,VS2K MOR[,temperature]`; the
//! expected class is the id's prefix up to the first `-` (`none` for
//! unclassified).

mod common;

use common::{Builder, H2022, H2023};
use murk_types::WeatherClass;

fn check(b: &Builder) {
    let campaign = b.open().unwrap();
    let selection = campaign.select();
    for r in selection.recordings() {
        let want = r.id().split('-').next().unwrap();
        let got = r.class().map_or("none", WeatherClass::name);
        assert_eq!(got, want, "recording {}", r.id());
    }
}

#[test]
fn pdd_2022_2023_thresholds() {
    let b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            // clear: type Clear, both rain rates 0, both MOR >= 2000.
            "clear-at-edge,Clear,0,0,2000,2000",
            "none-clear-pwd12-mor-below,Clear,0,0,1999.9,2000",
            "none-clear-vs2k-mor-below,Clear,0,0,2000,1999.9",
            "none-clear-wrong-type,Unknown,0,0,2500,2500",
            "none-clear-pwd12-rain,Clear,0.1,0,2500,2500",
            "none-clear-wxt530-rain,Clear,0,0.1,2500,2500",
            "clear-type-any-case,CLEAR,0,0,2500,2500",
            // rain: type Rain and PWD12 rain > 0 (WXT530 is not read).
            "rain-just-above-zero,Rain,0.01,0,900,900",
            "none-rain-zero-rate,Rain,0,0,900,900",
            "none-rain-drizzle,Drizzle,0.5,0.5,900,900",
            // fog: rain rates 0, both MOR < 400, sensors within 60 m.
            "fog-just-below,Fog,0,0,399.9,399.9",
            "none-fog-pwd12-at-400,Fog,0,0,400,380",
            "none-fog-vs2k-at-400,Fog,0,0,380,400",
            "fog-agreement-at-60,Fog,0,0,100,160",
            "fog-agreement-at-minus-60,Fog,0,0,160,100",
            "none-fog-agreement-above-60,Fog,0,0,100,160.1",
            "none-fog-pwd12-rain,Fog,0.1,0,100,100",
            "none-fog-wxt530-rain,Fog,0,0.1,100,100",
            "fog-type-not-read,Unknown,0,0,100,100",
            // snow: type Snow, nothing else.
            "snow-any-mor,Snow,0,0.3,900,900",
            "snow-also-fog,Snow,0,0,100,100",
        ],
    );
    check(&b);
    let s = b.open().unwrap().select();
    assert_eq!(s.summary().ambiguous, 1, "snow-also-fog matches fog too");
    let amb: Vec<_> = s.recordings().iter().filter(|r| r.is_ambiguous()).collect();
    assert_eq!(
        amb[0].matched_classes(),
        [WeatherClass::Snow, WeatherClass::Fog]
    );
}

#[test]
fn pdd_2023_2024_thresholds() {
    let b = Builder::new(
        "pdd-2023-2024",
        H2023,
        &[
            // clear: Parsivel and WXT530 rain 0, both MOR >= 2000; no type test.
            "clear-at-edge,Clear,0,0,2000,2000,3",
            "clear-type-not-read,Unknown,0,0,2500,2500,3",
            "none-clear-pwd12-mor-below,Clear,0,0,1999.9,2000,3",
            "none-clear-vs2k-mor-below,Clear,0,0,2000,1999.9,3",
            "none-clear-parsivel-rain,Clear,0.1,0,2500,2500,3",
            "none-clear-wxt530-rain,Clear,0,0.1,2500,2500,3",
            // rain: WXT530 > 0, Parsivel > 0, Parsivel type != Snow.
            "rain-both-rates,Rain,0.01,0.01,900,900,3",
            "rain-drizzle,Drizzle,0.1,0.1,900,900,3",
            "none-rain-parsivel-zero,Rain,0,0.1,900,900,3",
            "none-rain-wxt530-zero,Rain,0.1,0,900,900,3",
            "none-rain-type-snow-warm,Snow,0.1,0.1,900,900,10",
            // fog: rain rates 0, both MOR < 400; no agreement test.
            "fog-just-below,Fog,0,0,399.9,399.9,3",
            "fog-sensors-disagree,Fog,0,0,50,390,3",
            "none-fog-pwd12-at-400,Fog,0,0,400,300,3",
            "none-fog-vs2k-at-400,Fog,0,0,300,400,3",
            "none-fog-parsivel-rain,Fog,0.1,0,100,100,3",
            "none-fog-wxt530-rain,Fog,0,0.1,100,100,3",
            // snow: Parsivel type Snow and PWD12 temperature < 5 °C.
            "snow-just-below-5,Snow,0,0,900,900,4.9",
            "none-snow-at-5,Snow,0,0,900,900,5",
            "snow-also-clear,Snow,0,0,2500,2500,-2",
        ],
    );
    check(&b);
    assert_eq!(b.open().unwrap().select().summary().ambiguous, 1);
}

#[test]
fn rule_params_move_the_seed_thresholds() {
    // fog_mor_max 300 and clear_mor_min 1000 instead of 400 and 2000.
    let b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            "none-fog-350,Fog,0,0,350,350",
            "fog-299,Fog,0,0,299,299",
            "clear-1000,Clear,0,0,1000,1000",
            "none-clear-999,Clear,0,0,999,1000",
            "fog-agreement-100,Fog,0,0,100,200",
        ],
    )
    .toml_extra(
        "\n[rule_params]\nfog_mor_max = 300\nclear_mor_min = 1000.0\nfog_agreement_max = 100\n",
    );
    check(&b);
    let c = b.open().unwrap();
    assert_eq!(c.rules().params()["fog_mor_max"], 300.0);
    assert_eq!(c.select().summary().rule_params["clear_mor_min"], 1000.0);
}

#[test]
fn snow_temperature_is_a_parameter_of_2023_2024() {
    let b = Builder::new(
        "pdd-2023-2024",
        H2023,
        &[
            "snow-at-0,Snow,0,0,900,900,-0.5",
            "none-snow-at-0,Snow,0,0,900,900,0",
        ],
    )
    .toml_extra("\n[rule_params]\nsnow_temperature_max = 0\n");
    // Ids must be unique: rename the second.
    let mut b = b;
    b.weather = b.weather.replace("none-snow-at-0,", "none-snow-at-zero,");
    check(&b);
}
