//! One test per bad input: each must fail with the file, the line (and
//! column) and the reason.

mod common;

use common::{Builder, H2022, H2023};
use murk_campaign::{CampaignError, Location};

fn pdd(rows: &[&str]) -> Builder {
    Builder::new("pdd-2022-2023", H2022, rows)
}

/// Asserts that `msg` mentions every needle.
fn says(msg: &str, needles: &[&str]) {
    for n in needles {
        assert!(msg.contains(n), "error message lacks {n:?}: {msg}");
    }
}

// ---------------------------------------------------------------- weather.csv

#[test]
fn duplicate_recording_id_names_both_lines() {
    let (e, msg) = pdd(&[
        "a,Clear,0,0,2500,2500",
        "b,Clear,0,0,2500,2500",
        "a,Fog,0,0,100,100",
    ])
    .lidar_files(&["a.pcd", "b.pcd"])
    .error();
    assert!(
        matches!(e, CampaignError::DuplicateRecording { first_line: 2, second_line: 4, ref id, .. } if id == "a"),
        "{e:?}"
    );
    says(&msg, &["weather.csv", "line 4", "line 2", "`a`"]);
}

#[test]
fn weather_row_without_lidar_file() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500", "b,Clear,0,0,2500,2500"])
        .lidar_files(&["a.pcd"])
        .error();
    assert!(
        matches!(e, CampaignError::MissingLidar { line: 3, .. }),
        "{e:?}"
    );
    says(&msg, &["weather.csv", "line 3", "`b`", "lidar"]);
}

#[test]
fn lidar_file_without_weather_row() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .lidar_files(&["a.pcd", "zz.pcd"])
        .error();
    assert!(
        matches!(e, CampaignError::OrphanFile { ref stem, .. } if stem == "zz"),
        "{e:?}"
    );
    says(&msg, &["zz.pcd", "weather.csv", "`zz`"]);
}

#[test]
fn two_lidar_files_with_the_same_stem() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .lidar_files(&["a.bin", "a.pcd"])
        .error();
    assert!(
        matches!(e, CampaignError::DuplicateStem { ref stem, .. } if stem == "a"),
        "{e:?}"
    );
    says(&msg, &["a.bin", "a.pcd", "`a`"]);
}

#[test]
fn unknown_extension_in_lidar_folder() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .lidar_files(&["a.pcd", "a.las"])
        .error();
    assert!(matches!(e, CampaignError::UnexpectedFile { .. }), "{e:?}");
    says(&msg, &["a.las", "unknown point-cloud format", "las"]);
}

#[test]
fn folder_inside_lidar_folder() {
    let b = pdd(&["a,Clear,0,0,2500,2500"]);
    let d = b.write();
    std::fs::create_dir(d.join("lidar").join("extra")).unwrap();
    let e = murk_campaign::Campaign::open(d).unwrap_err();
    assert!(matches!(e, CampaignError::UnexpectedFile { .. }), "{e:?}");
    says(&e.to_string(), &["extra", "folder"]);
}

#[test]
fn radar_file_without_weather_row() {
    let mut b = pdd(&["a,Clear,0,0,2500,2500"]);
    b.radar = vec!["a.csv".into(), "q.csv".into()];
    let (e, msg) = b.error();
    assert!(
        matches!(e, CampaignError::OrphanFile { ref stem, .. } if stem == "q"),
        "{e:?}"
    );
    says(&msg, &["radar", "q.csv"]);
}

#[test]
fn radar_file_that_is_not_csv() {
    let mut b = pdd(&["a,Clear,0,0,2500,2500"]);
    b.radar = vec!["a.pcd".into()];
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::UnexpectedFile { .. }), "{e:?}");
    says(&msg, &["a.pcd", ".csv"]);
}

#[test]
fn malformed_timestamp() {
    let mut b = pdd(&["a,Clear,0,0,2500,2500"]);
    b.weather = b
        .weather
        .replace("2023-01-01T00:00:00Z", "14/01/2023 05:00");
    let (e, msg) = b.error();
    assert!(
        matches!(
            e,
            CampaignError::BadValue {
                at: Location {
                    line: 2,
                    column: Some(2),
                    ..
                },
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "line 2",
            "column 2",
            "timestamp",
            "RFC 3339",
            "14/01/2023 05:00",
        ],
    );
}

#[test]
fn missing_required_column_suggests_the_near_miss() {
    let b = Builder::raw(
        "pdd-2022-2023",
        &format!("{}\n", H2022.replace("recording,", "Recording,")),
    );
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::MissingColumn { .. }), "{e:?}");
    says(
        &msg,
        &[
            "weather.csv",
            "line 1",
            "missing column `recording`",
            "did you mean `recording`?",
        ],
    );
}

#[test]
fn misspelt_column_read_by_the_rules() {
    let b = Builder::raw(
        "pdd-2022-2023",
        &format!(
            "{}\na,2023-01-01T00:00:00Z,Clear,0,0,2500,2500\n",
            H2022.replace("PWD12_MOR (m)", "PWD12_MOR(m)")
        ),
    );
    let (e, msg) = b.error();
    assert!(
        matches!(
            e,
            CampaignError::MissingColumn {
                suggestion: Some((6, _)),
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "line 1",
            "missing column `PWD12_MOR (m)`",
            "pdd-2022-2023",
            "column 6 is `PWD12_MOR(m)`",
            "did you mean `PWD12_MOR (m)`?",
        ],
    );
}

#[test]
fn missing_column_read_by_the_rules_without_near_miss() {
    let b = Builder::raw(
        "pdd-2023-2024",
        &format!("{}\n", H2023.replace(",PWD12_Temperature (°C)", "")),
    );
    let (e, msg) = b.error();
    assert!(
        matches!(
            e,
            CampaignError::MissingColumn {
                suggestion: None,
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "missing column `PWD12_Temperature (°C)`",
            "pdd-2023-2024",
        ],
    );
}

#[test]
fn misspelt_known_sensor_column_not_read_by_the_rules() {
    // The 2022-2023 rules do not read the temperature, but the header is a
    // misspelling of a sensor column of the campaign format.
    let b = Builder::raw(
        "pdd-2022-2023",
        &format!("{H2022},pwd12_temperature (°C)\n"),
    );
    let (e, msg) = b.error();
    assert!(
        matches!(e, CampaignError::MisspeltColumn { column: 8, .. }),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "line 1",
            "column 8",
            "did you mean `PWD12_Temperature (°C)`?",
        ],
    );
}

#[test]
fn duplicate_header() {
    let b = Builder::raw("pdd-2022-2023", &format!("{H2022},wind,wind\n"));
    let (e, msg) = b.error();
    assert!(
        matches!(
            e,
            CampaignError::DuplicateColumn {
                first: 8,
                second: 9,
                ..
            }
        ),
        "{e:?}"
    );
    says(&msg, &["weather.csv", "`wind`", "8", "9"]);
}

#[test]
fn text_in_a_numeric_sensor_column() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500", "b,Fog,0,0,1OO,100"]).error();
    assert!(
        matches!(
            e,
            CampaignError::BadValue {
                at: Location {
                    line: 3,
                    column: Some(6),
                    ..
                },
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "line 3",
            "column 6",
            "PWD12_MOR (m)",
            "`1OO` is not a number",
        ],
    );
}

#[test]
fn text_in_a_numeric_column_read_by_custom_rules() {
    let rules = "intensity = []\n[[class.fog]]\ncolumn = \"vis\"\nop = \"<\"\nvalue = 400\n";
    let b = Builder::raw(
        "r.toml",
        "recording,timestamp,vis\na,2023-01-01T00:00:00Z,300\nb,2023-01-01T01:00:00Z,low\n",
    )
    .rules_file("r.toml", rules);
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(
        &msg,
        &["weather.csv", "line 3", "column 3", "`low` is not a number"],
    );
}

#[test]
fn non_finite_number_in_a_sensor_column() {
    let (e, msg) = pdd(&["a,Clear,0,0,NaN,2500"]).error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(&msg, &["line 2", "column 6", "`NaN` is not a number"]);
}

#[test]
fn negative_rain_rate() {
    let (e, msg) = pdd(&["a,Rain,-0.2,0,900,900"]).error();
    assert!(
        matches!(
            e,
            CampaignError::BadValue {
                at: Location {
                    line: 2,
                    column: Some(4),
                    ..
                },
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "weather.csv",
            "line 2",
            "PWD12_Rain intensity (mm/h)",
            "negative rain rate",
        ],
    );
}

#[test]
fn zero_mor() {
    let (e, msg) = pdd(&["a,Fog,0,0,100,100", "b,Fog,0,0,100,0"]).error();
    assert!(
        matches!(
            e,
            CampaignError::BadValue {
                at: Location {
                    line: 3,
                    column: Some(7),
                    ..
                },
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &["weather.csv", "line 3", "VS2K_MOR (m)", "not positive"],
    );
}

#[test]
fn negative_mor() {
    let (e, msg) = pdd(&["a,Fog,0,0,-5,100"]).error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(&msg, &["line 2", "PWD12_MOR (m)", "not positive"]);
}

#[test]
fn unknown_weather_type() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500", "b,Sunny,0,0,2500,2500"]).error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(
        &msg,
        &[
            "weather.csv",
            "line 3",
            "column 3",
            "`Sunny` is not a weather type",
        ],
    );
}

#[test]
fn empty_recording_id() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500", ",Clear,0,0,2500,2500"])
        .lidar_files(&["a.pcd"])
        .error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(
        &msg,
        &["weather.csv", "line 3", "column 1", "empty recording id"],
    );
}

#[test]
fn row_with_too_few_fields() {
    let mut b = pdd(&["a,Clear,0,0,2500,2500", "b,Clear,0,0,2500,2500"]);
    b.weather = b.weather.replace(
        "b,2023-01-01T01:00:00Z,Clear,0,0,2500,2500",
        "b,2023-01-01T01:00:00Z,Clear,0",
    );
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Csv { line: 3, .. }), "{e:?}");
    says(&msg, &["weather.csv", "line 3", "4 fields", "7"]);
}

// ---------------------------------------------------------------- review.csv

#[test]
fn review_row_naming_an_unknown_recording() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .review("recording,keep\na,true\nghost,false\n")
        .error();
    assert!(
        matches!(e, CampaignError::UnknownReviewRecording { line: 3, ref id, .. } if id == "ghost"),
        "{e:?}"
    );
    says(&msg, &["review.csv", "line 3", "`ghost`", "weather.csv"]);
}

#[test]
fn review_keep_not_true_or_false() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .review("recording,keep,reason\na,yes,\n")
        .error();
    assert!(
        matches!(
            e,
            CampaignError::BadValue {
                at: Location {
                    line: 2,
                    column: Some(2),
                    ..
                },
                ..
            }
        ),
        "{e:?}"
    );
    says(
        &msg,
        &[
            "review.csv",
            "line 2",
            "keep must be true or false",
            "`yes`",
        ],
    );
}

#[test]
fn review_duplicate_row() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .review("recording,keep\na,true\na,false\n")
        .error();
    assert!(
        matches!(
            e,
            CampaignError::DuplicateRecording {
                first_line: 2,
                second_line: 3,
                ..
            }
        ),
        "{e:?}"
    );
    says(&msg, &["review.csv", "line 3", "line 2"]);
}

#[test]
fn review_missing_keep_column() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .review("recording,kep\na,true\n")
        .error();
    assert!(matches!(e, CampaignError::MissingColumn { .. }), "{e:?}");
    says(
        &msg,
        &[
            "review.csv",
            "missing column `keep`",
            "did you mean `keep`?",
        ],
    );
}

#[test]
fn review_unexpected_column() {
    let (e, msg) = pdd(&["a,Clear,0,0,2500,2500"])
        .review("recording,keep,camera\na,true,north\n")
        .error();
    assert!(matches!(e, CampaignError::BadValue { .. }), "{e:?}");
    says(
        &msg,
        &["review.csv", "line 1", "column 3", "unexpected column"],
    );
}

// ------------------------------------------------------------- campaign.toml

#[test]
fn campaign_toml_missing() {
    let b = pdd(&["a,Clear,0,0,2500,2500"]);
    let d = b.write();
    std::fs::remove_file(d.join("campaign.toml")).unwrap();
    let e = murk_campaign::Campaign::open(d).unwrap_err();
    assert!(matches!(e, CampaignError::Io { .. }), "{e:?}");
    says(&e.to_string(), &["campaign.toml", "cannot read"]);
}

#[test]
fn campaign_toml_unknown_lidar_key() {
    let mut b = pdd(&["a,Clear,0,0,2500,2500"]);
    b.toml = b
        .toml
        .replace("model = \"VLP16\"", "model = \"VLP16\"\nrnage_scale = 1.0");
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Toml { line: 6, .. }), "{e:?}");
    says(&msg, &["campaign.toml", "line 6", "rnage_scale"]);
}

#[test]
fn campaign_toml_invalid_lidar() {
    let b = pdd(&["a,Clear,0,0,2500,2500"]).toml_extra("range_scale = 0.0\n");
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Lidar { line: 4, .. }), "{e:?}");
    says(&msg, &["campaign.toml", "line 4", "range_scale"]);
}

#[test]
fn rules_neither_preset_nor_file() {
    let (e, msg) = Builder::new("pdd-2022-2032", H2022, &[]).error();
    assert!(matches!(e, CampaignError::Toml { line: 2, .. }), "{e:?}");
    says(
        &msg,
        &[
            "campaign.toml",
            "line 2",
            "pdd-2022-2032",
            "pdd-2022-2023, pdd-2023-2024",
            "not found",
        ],
    );
}

#[test]
fn rule_param_the_preset_does_not_use() {
    let b = Builder::new("pdd-2023-2024", H2023, &[])
        .toml_extra("\n[rule_params]\nfog_agreement_max = 50\n");
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Rules { line: 10, .. }), "{e:?}");
    says(
        &msg,
        &[
            "campaign.toml",
            "line 10",
            "no parameter `fog_agreement_max`",
            "clear_mor_min, fog_mor_max, snow_temperature_max",
        ],
    );
}

#[test]
fn rule_param_out_of_range() {
    let b =
        Builder::new("pdd-2022-2023", H2022, &[]).toml_extra("\n[rule_params]\nfog_mor_max = -1\n");
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Rules { .. }), "{e:?}");
    says(&msg, &["campaign.toml", "fog_mor_max", "must be > 0"]);
}

// ---------------------------------------------------------------- rules file

fn with_rules(rules: &str) -> Builder {
    Builder::raw(
        "r.toml",
        "recording,timestamp,vis,state\na,2023-01-01T00:00:00Z,300,wet\n",
    )
    .rules_file("r.toml", rules)
}

const OK_HEAD: &str = "intensity = [\"vis\"]\n";

#[test]
fn rules_unknown_op() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.fog]]\ncolumn = \"vis\"\nop = \"=<\"\nvalue = 400\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { line: 2, .. }), "{e:?}");
    says(
        &msg,
        &[
            "r.toml",
            "line 2",
            "unknown op `=<`",
            "==, !=, <, <=, >, >=",
        ],
    );
}

#[test]
fn rules_column_absent_from_weather() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.fog]]\ncolumn = \"visibility\"\nop = \"<\"\nvalue = 400\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::MissingColumn { .. }), "{e:?}");
    says(
        &msg,
        &["weather.csv", "missing column `visibility`", "rule set `r`"],
    );
}

#[test]
fn rules_unknown_class() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.haze]]\ncolumn = \"vis\"\nop = \"<\"\nvalue = 400\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { line: 2, .. }), "{e:?}");
    says(&msg, &["r.toml", "unknown class `haze`"]);
}

#[test]
fn rules_unknown_key() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.fog]]\ncolumn = \"vis\"\nop = \"<\"\nvalu = 400\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Toml { .. }), "{e:?}");
    says(&msg, &["r.toml", "valu"]);
}

#[test]
fn rules_unknown_param() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[params]\nfog_max = 400\n[[class.fog]]\ncolumn = \"vis\"\nop = \"<\"\nparam = \"fog_mx\"\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { line: 4, .. }), "{e:?}");
    says(
        &msg,
        &["r.toml", "line 4", "unknown parameter `fog_mx`", "fog_max"],
    );
}

#[test]
fn rules_unused_param() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[params]\nfog_max = 400\n[[class.fog]]\ncolumn = \"vis\"\nop = \"<\"\nvalue = 400\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { line: 3, .. }), "{e:?}");
    says(
        &msg,
        &[
            "r.toml",
            "line 3",
            "`fog_max` is declared but no condition uses it",
        ],
    );
}

#[test]
fn rules_order_op_on_text() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.fog]]\ncolumn = \"state\"\nop = \"<\"\nvalue = \"wet\"\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { .. }), "{e:?}");
    says(&msg, &["r.toml", "line 2", "op `<` compares numbers"]);
}

#[test]
fn rules_text_compared_with_a_mor_column() {
    let b = Builder::new("r.toml", H2022, &[]).rules_file(
        "r.toml",
        "intensity = []\n[[class.fog]]\ncolumn = \"PWD12_MOR (m)\"\nop = \"==\"\nvalue = \"low\"\n",
    );
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Rules { .. }), "{e:?}");
    says(
        &msg,
        &[
            "r.toml",
            "line 2",
            "`PWD12_MOR (m)` holds numbers",
            "compared with text",
        ],
    );
}

#[test]
fn rules_weather_type_no_sensor_reports() {
    let b = Builder::new("r.toml", H2022, &[]).rules_file(
        "r.toml",
        "intensity = []\n[[class.clear]]\ncolumn = \"PWD12_Weather Type\"\nop = \"==\"\nvalue = \"Claer\"\n",
    );
    let (e, msg) = b.error();
    assert!(matches!(e, CampaignError::Rules { .. }), "{e:?}");
    says(&msg, &["r.toml", "never holds \"Claer\""]);
}

#[test]
fn rules_class_without_condition() {
    let (e, msg) = with_rules(&format!("{OK_HEAD}class.fog = []\n")).error();
    assert!(matches!(e, CampaignError::Rules { line: 2, .. }), "{e:?}");
    says(&msg, &["r.toml", "class `fog` has no condition"]);
}

#[test]
fn rules_priority_missing_a_class() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}priority = [\"fog\"]\n[[class.fog]]\ncolumn = \"vis\"\nop = \"<\"\nvalue = 400\n\
         [[class.clear]]\ncolumn = \"vis\"\nop = \">\"\nvalue = 2000\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { line: 2, .. }), "{e:?}");
    says(&msg, &["r.toml", "priority does not list class `clear`"]);
}

#[test]
fn rules_abs_diff_with_one_column() {
    let (e, msg) = with_rules(&format!(
        "{OK_HEAD}[[class.fog]]\nabs_diff = [\"vis\"]\nop = \"<\"\nvalue = 60\n"
    ))
    .error();
    assert!(matches!(e, CampaignError::Rules { .. }), "{e:?}");
    says(
        &msg,
        &["r.toml", "abs_diff takes exactly two columns, got 1"],
    );
}

#[test]
fn rules_file_is_not_toml() {
    let (e, msg) = with_rules("intensity = [\"vis\"\n[[class.fog]]\n").error();
    assert!(matches!(e, CampaignError::Toml { .. }), "{e:?}");
    says(&msg, &["r.toml", "line"]);
}
