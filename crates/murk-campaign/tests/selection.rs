//! Outage accounting, review filtering, custom rules, priority, MOR and rain
//! rate, covariates and files.

mod common;

use common::{Builder, H2022};
use murk_campaign::{Cell, ColumnRole, NOT_REVIEWED};
use murk_types::{PointFormat, WeatherClass};

#[test]
fn outages_are_counted_per_class_only_when_nothing_else_failed() {
    let b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            // WXT530 empty, every other fog condition holds: lost to fog.
            "wxt-out,Fog,0,,100,100",
            // VS2K empty: its threshold and the agreement cannot be read.
            "vs2k-out,Fog,0,0,100,",
            // PWD12 MOR empty, every other clear condition holds: lost to clear.
            "pwd-mor-out,Clear,0,0,,2500",
            // WXT530 empty but PWD12 MOR fails clear: not an outage loss.
            "fails-anyway,Clear,0,,1500,1500",
            // Snow matches on type alone: classified, so not lost.
            "snow-with-outages,Snow,,,,",
            // Rain with no visibility at all: classified, no MOR.
            "rain-no-mor,Rain,0.5,0.5,,",
        ],
    );
    let s = b.open().unwrap().select();
    let by_id = |id: &str| s.recordings().iter().find(|r| r.id() == id).unwrap();

    assert!(by_id("wxt-out").lost_to_outage());
    assert_eq!(
        by_id("wxt-out").outages(),
        [(
            WeatherClass::Fog,
            vec!["WXT530_Rain intensity (mm/h)".to_string()]
        )]
    );
    assert_eq!(
        by_id("vs2k-out").outages(),
        [(WeatherClass::Fog, vec!["VS2K_MOR (m)".to_string()])]
    );
    assert_eq!(
        by_id("vs2k-out").mor(),
        Some(100.0),
        "mean of the present sensors"
    );
    assert!(by_id("pwd-mor-out").lost_to_outage());
    assert!(!by_id("fails-anyway").lost_to_outage());
    assert_eq!(by_id("fails-anyway").class(), None);
    assert_eq!(by_id("snow-with-outages").class(), Some(WeatherClass::Snow));
    assert!(!by_id("snow-with-outages").lost_to_outage());
    assert_eq!(by_id("rain-no-mor").mor(), None);
    assert_eq!(by_id("rain-no-mor").rain_rate(), Some(0.5));

    let sum = s.summary();
    assert_eq!(sum.class(WeatherClass::Fog).unwrap().lost_to_outage, 2);
    assert_eq!(sum.class(WeatherClass::Clear).unwrap().lost_to_outage, 1);
    assert_eq!(sum.class(WeatherClass::Rain).unwrap().lost_to_outage, 0);
    assert_eq!(sum.lost_to_outage, 3);
    assert_eq!(sum.unclassified, 4);
    assert_eq!(sum.class(WeatherClass::Rain).unwrap().kept_without_mor, 1);
    assert!(sum.class(WeatherClass::Rain).unwrap().mor.is_none());
}

#[test]
fn review_is_an_allowlist_and_counts_before_and_after() {
    let b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            "c1,Clear,0,0,2500,2500",
            "c2,Clear,0,0,2600,2600",
            "c3,Clear,0,0,2700,2700",
            "f1,Fog,0,0,100,110",
            "f2,Fog,0,0,200,210",
            "r1,Rain,1,1,800,800",
            "n1,Unknown,0,0,900,900",
        ],
    )
    .review(
        "recording,keep,reason\n\
         c1,true,\n\
         c2,false,wet ground\n\
         f1,TRUE,\n\
         f2,false,\n\
         r1,true,rain and wet ground\n\
         n1,true,\n",
    );
    let s = b.open().unwrap().select();
    let by_id = |id: &str| s.recordings().iter().find(|r| r.id() == id).unwrap();
    assert!(by_id("c1").kept());
    assert!(!by_id("c2").kept());
    assert_eq!(by_id("c2").exclusion_reason(), Some("wet ground"));
    assert_eq!(by_id("c3").exclusion_reason(), Some(NOT_REVIEWED));
    assert_eq!(
        by_id("f2").exclusion_reason(),
        Some("keep = false in review.csv")
    );
    assert!(!by_id("n1").kept(), "unclassified is never kept");
    assert_eq!(by_id("r1").recording().review().unwrap().line, 6);

    let sum = s.summary();
    assert!(sum.reviewed);
    let counts: Vec<(WeatherClass, usize, usize)> = sum
        .classes
        .iter()
        .map(|c| (c.class, c.before_review, c.after_review))
        .collect();
    assert_eq!(
        counts,
        [
            (WeatherClass::Clear, 3, 1),
            (WeatherClass::Fog, 2, 1),
            (WeatherClass::Rain, 1, 1),
            (WeatherClass::Snow, 0, 0),
        ]
    );
    assert_eq!(sum.excluded_by_review, 3);
    // MOR statistics are over kept recordings only: f1 = (100 + 110) / 2.
    let fog = sum.class(WeatherClass::Fog).unwrap().mor.as_ref().unwrap();
    assert_eq!((fog.recordings, fog.min, fog.max), (1, 105.0, 105.0));
    let kept: Vec<&str> = s.kept(WeatherClass::Clear).map(|r| r.id()).collect();
    assert_eq!(kept, ["c1"]);
}

#[test]
fn without_review_everything_classified_is_kept() {
    let b = Builder::new("pdd-2022-2023", H2022, &["c1,Clear,0,0,2500,2500"]);
    let s = b.open().unwrap().select();
    assert!(s.recordings()[0].kept());
    assert_eq!(s.recordings()[0].exclusion_reason(), None);
    let c = s.summary().class(WeatherClass::Clear).unwrap();
    assert_eq!((c.before_review, c.after_review), (1, 1));
}

const CUSTOM: &str = r#"
name = "hilltop"
intensity = ["vis (m)"]
rain_rate = ["rr (mm/h)"]
priority = ["fog", "snow", "clear"]

[params]
fog_vis = 500

[[class.clear]]
column = "state"
op = "=="
value = "dry"
[[class.clear]]
column = "vis (m)"
op = ">"
value = 5000

[[class.fog]]
column = "vis (m)"
op = "<"
param = "fog_vis"

[[class.snow]]
column = "temp"
op = "<="
value = 0
[[class.snow]]
column = "state"
op = "!="
value = "dry"
"#;

fn custom_campaign(priority: Option<&str>) -> Builder {
    let rules = match priority {
        Some(p) => CUSTOM.replace(r#"priority = ["fog", "snow", "clear"]"#, p),
        None => CUSTOM.to_string(),
    };
    Builder::raw(
        "hilltop.toml",
        "recording,timestamp,vis (m),rr (mm/h),state,temp,wind,note\n\
         a,2024-01-01T00:00:00Z,6000,0,dry,5,3.5,ok\n\
         b,2024-01-01T01:00:00+01:00,300,0,wet,-1,,gusty\n\
         c,2024-01-01T02:00:00Z,450,0.2,damp,3,7,\n\
         d,2024-01-01T03:00:00Z,2000,,snowy,-4,1e1,x\n",
    )
    .rules_file("hilltop.toml", &rules)
}

#[test]
fn a_custom_rules_file_classifies_by_its_own_vocabulary() {
    // The rules path in campaign.toml is relative to the campaign folder.
    let b = custom_campaign(None);
    let c = b.open().unwrap();
    assert_eq!(c.rules().name(), "hilltop");
    let s = c.select();
    let classes: Vec<Option<WeatherClass>> = s.recordings().iter().map(|r| r.class()).collect();
    assert_eq!(
        classes,
        [
            Some(WeatherClass::Clear),
            Some(WeatherClass::Fog), // fog and snow match; fog first
            Some(WeatherClass::Fog),
            Some(WeatherClass::Snow),
        ]
    );
    assert!(s.recordings()[1].is_ambiguous());
    assert_eq!(s.summary().ambiguous, 1);
    assert_eq!(s.recordings()[2].rain_rate(), Some(0.2));
    assert_eq!(s.recordings()[3].rain_rate(), None);
    assert_eq!(s.recordings()[3].mor(), Some(2000.0));
    // The +01:00 timestamp is stored in UTC.
    assert_eq!(
        c.recordings()[1].timestamp().to_rfc3339(),
        "2024-01-01T00:00:00+00:00"
    );
    // Rain is not defined by these rules, so the summary has no rain row.
    assert!(s.summary().class(WeatherClass::Rain).is_none());
    assert_eq!(s.summary().classes.len(), 3);
}

#[test]
fn priority_decides_between_matching_classes() {
    let b = custom_campaign(Some(r#"priority = ["snow", "fog", "clear"]"#));
    let s = b.open().unwrap().select();
    let r = &s.recordings()[1];
    assert_eq!(r.class(), Some(WeatherClass::Snow));
    assert_eq!(r.matched_classes(), [WeatherClass::Snow, WeatherClass::Fog]);
    assert_eq!(
        s.summary().priority,
        [WeatherClass::Snow, WeatherClass::Fog, WeatherClass::Clear]
    );
}

#[test]
fn custom_rule_params_are_overridable_from_campaign_toml() {
    let b = custom_campaign(None).toml_extra("\n[rule_params]\nfog_vis = 400\n");
    let s = b.open().unwrap().select();
    // c (450 m) is no longer fog.
    assert_eq!(s.recordings()[2].class(), None);
}

#[test]
fn covariates_keep_every_further_column_in_header_order() {
    let b = custom_campaign(None);
    let c = b.open().unwrap();
    assert_eq!(c.covariate_columns(), ["wind", "note"]);
    let roles: Vec<(&str, ColumnRole, bool)> = c
        .columns()
        .iter()
        .map(|col| (col.name.as_str(), col.role, col.numeric))
        .collect();
    assert_eq!(roles[4], ("wind", ColumnRole::Covariate, true));
    assert_eq!(roles[5], ("note", ColumnRole::Covariate, false));
    assert_eq!(c.columns()[0].number, 3, "1-based column in the file");

    let s = c.select();
    let b_rec = &s.recordings()[1];
    let covs: Vec<(&str, Option<&Cell>)> = b_rec.covariates().collect();
    assert_eq!(
        covs,
        [
            ("wind", None),
            ("note", Some(&Cell::Categorical("gusty".into())))
        ]
    );
    assert_eq!(s.recordings()[3].value("wind"), Some(&Cell::Numeric(10.0)));
    assert_eq!(
        s.recordings()[0].value("state").and_then(Cell::as_str),
        Some("dry")
    );
    assert_eq!(s.recordings()[0].value("no such column"), None);
}

#[test]
fn files_are_paired_with_their_format_and_radar() {
    let mut b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            "a,Clear,0,0,2500,2500",
            "b,Fog,0,0,100,100",
            "c,Fog,0,0,100,100",
            "d,Fog,0,0,100,100",
        ],
    )
    .lidar_files(&["a.pcd", "b.bin", "c.pcd.bin", "d.csv"]);
    b.radar = vec!["a.csv".into(), "c.csv".into()];
    let c = b.open().unwrap();
    let formats: Vec<PointFormat> = c.recordings().iter().map(|r| r.lidar().format).collect();
    assert_eq!(
        formats,
        [
            PointFormat::Pcd,
            PointFormat::KittiBin,
            PointFormat::NuscenesBin,
            PointFormat::Csv
        ]
    );
    assert!(c.recordings()[2].lidar().path.ends_with("lidar/c.pcd.bin"));
    assert!(
        c.recording("a")
            .unwrap()
            .radar()
            .unwrap()
            .ends_with("radar/a.csv")
    );
    assert!(c.recording("b").unwrap().radar().is_none());
}

#[test]
fn summary_serializes_and_prints_an_aligned_table() {
    let b = Builder::new(
        "pdd-2022-2023",
        H2022,
        &[
            "c1,Clear,0,0,2500,2500",
            "f1,Fog,0,0,52,60",
            "f2,Fog,0,0,170,180",
            "r1,Rain,1,1,,",
        ],
    );
    let s = b.open().unwrap().select();
    let json = serde_json::to_value(s.summary()).unwrap();
    assert_eq!(json["classes"][1]["class"], "fog");
    assert_eq!(json["classes"][1]["mor"]["min"], 56.0);
    assert_eq!(json["classes"][1]["mor"]["max"], 175.0);
    assert!(json["classes"][2]["mor"].is_null());
    assert_eq!(json["classes"][2]["kept_without_mor"], 1);
    let back: murk_campaign::Summary = serde_json::from_value(json).unwrap();
    assert_eq!(&back, s.summary());

    let text = s.summary().to_string();
    let lines: Vec<&str> = text.lines().collect();
    let header = lines.iter().position(|l| l.starts_with("class")).unwrap();
    let table = &lines[header..header + 5];
    // Every row of the table has the same width: columns are aligned.
    assert!(
        table
            .iter()
            .all(|l| l.chars().count() == table[0].chars().count()),
        "{text}"
    );
    assert!(table[2].starts_with("fog"), "{text}");
    assert!(text.contains("unclassified: 0"), "{text}");
}
