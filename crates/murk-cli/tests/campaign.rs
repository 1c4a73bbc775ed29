//! `murk campaign summary` on a small hand-built campaign.

use std::path::Path;
use std::process::Command;

/// A two-point PCD written by hand (murk-io's writers are not used so that
/// this test pins the campaign command alone).
const PCD: &str = "\
# .PCD v0.7 - Point Cloud Data file format
VERSION 0.7
FIELDS x y z intensity ring
SIZE 4 4 4 4 2
TYPE F F F F U
COUNT 1 1 1 1 1
WIDTH 2
HEIGHT 1
VIEWPOINT 0 0 0 1 0 0 0
POINTS 2
DATA ascii
1.0 2.0 0.1 10 1
3.0 -1.0 0.2 50 3
";

const WEATHER: &str = "\
recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),WXT530_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),PWD12_Temperature (°C),wind (m/s)
c1,2023-01-14T00:00:00Z,Clear,0,0,2500,2400,-1,3
c2,2023-01-14T01:00:00Z,Clear,0,0,2600,2700,-1,4
f1,2023-01-14T02:00:00Z,Fog,0,0,60,80,0,1
f2,2023-01-14T03:00:00Z,Fog,0,0,150,170,0,2
f3,2023-01-14T04:00:00Z,Fog,0,,150,170,0,2
r1,2023-01-14T05:00:00Z,Rain,1.5,1.2,120,140,2,6
s1,2023-01-14T06:00:00Z,Snow,0,0,100,110,-3,5
n1,2023-01-14T07:00:00Z,Unknown,0,0,900,900,1,2
";

fn campaign(dir: &Path, weather: &str) {
    std::fs::write(
        dir.join("campaign.toml"),
        "name = \"cli-test\"\nrules = \"pdd-2022-2023\"\n\n[lidar]\nmodel = \"VLP16\"\n\
         elevation_deg = [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0]\n",
    )
    .unwrap();
    std::fs::write(dir.join("weather.csv"), weather).unwrap();
    std::fs::write(
        dir.join("review.csv"),
        "recording,keep,reason\nc1,true,\nc2,false,wet ground\nf1,true,\nf2,true,\nr1,true,\ns1,false,no snow on ground\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("lidar")).unwrap();
    for line in weather.lines().skip(1) {
        let id = line.split(',').next().unwrap();
        std::fs::write(dir.join("lidar").join(format!("{id}.pcd")), PCD).unwrap();
    }
}

fn murk(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_murk"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn summary_prints_the_table() {
    let dir = tempfile::tempdir().unwrap();
    campaign(dir.path(), WEATHER);
    let out = murk(&["campaign", "summary", dir.path().to_str().unwrap()]);
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let row = |class: &str| -> Vec<String> {
        stdout
            .lines()
            .find(|l| l.starts_with(class))
            .unwrap_or_else(|| panic!("no {class} row in\n{stdout}"))
            .split_whitespace()
            .map(String::from)
            .collect()
    };
    // class, before, after, lost to outage, kept without MOR, min, q1, median, q3, max.
    assert_eq!(row("clear")[..5], ["clear", "2", "1", "0", "0"]);
    assert_eq!(row("fog")[..5], ["fog", "2", "2", "1", "0"]);
    // Kept fog MORs are 70 and 160: min 70, median 115, max 160.
    assert_eq!(row("fog")[5..], ["70", "92", "115", "138", "160"]);
    assert_eq!(row("rain")[..3], ["rain", "1", "1"]);
    assert_eq!(row("snow")[..3], ["snow", "1", "0"]);
    assert!(
        stdout.contains("unclassified: 2 (1 lost to sensor outages)"),
        "{stdout}"
    );
}

#[test]
fn summary_json_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    campaign(dir.path(), WEATHER);
    let figs = dir.path().join("figs");
    let out = murk(&[
        "campaign",
        "summary",
        dir.path().to_str().unwrap(),
        "--json",
        "--figures",
        figs.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["campaign"], "cli-test");
    assert_eq!(json["recordings"], 8);
    assert_eq!(json["classes"][1]["class"], "fog");
    assert_eq!(json["classes"][1]["after_review"], 2);
    assert_eq!(json["classes"][1]["mor"]["median"], 115.0);
    assert_eq!(json["lost_to_outage"], 1);
    let png = std::fs::read(figs.join("mor-histogram.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let svg = std::fs::read_to_string(figs.join("mor-histogram.svg")).unwrap();
    assert!(
        svg.contains("fog (n = 2)") && svg.contains("rain (n = 1)"),
        "{svg}"
    );
}

#[test]
fn bad_campaign_fails_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    campaign(
        dir.path(),
        &WEATHER.replace("f2,2023-01-14T03:00:00Z", "f2,yesterday"),
    );
    let out = murk(&["campaign", "summary", dir.path().to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8(out.stderr).unwrap();
    assert!(
        stderr.contains("weather.csv") && stderr.contains("line 5") && stderr.contains("RFC 3339"),
        "{stderr}"
    );
}
