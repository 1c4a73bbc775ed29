//! A builder of small campaign folders in temporary directories.

#![allow(dead_code)]

use std::path::Path;

use murk_campaign::{Campaign, CampaignError};

/// The VLP-16 `[lidar]` section.
pub const LIDAR: &str = r#"
[lidar]
model = "VLP16"
elevation_deg = [-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0,
                 -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0]
"#;

/// Header of a 2022-2023 weather table.
pub const H2022: &str = "recording,timestamp,PWD12_Weather Type,PWD12_Rain intensity (mm/h),WXT530_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m)";

/// Header of a 2023-2024 weather table.
pub const H2023: &str = "recording,timestamp,Parsivel_Weather Type,Parsivel_Rain intensity (mm/h),WXT530_Rain intensity (mm/h),PWD12_MOR (m),VS2K_MOR (m),PWD12_Temperature (°C)";

/// A campaign folder under construction.
pub struct Builder {
    pub dir: tempfile::TempDir,
    pub toml: String,
    pub weather: String,
    pub review: Option<String>,
    pub rules_file: Option<(String, String)>,
    /// Lidar files to create; `None` means one `.pcd` per weather row.
    pub lidar: Option<Vec<String>>,
    pub radar: Vec<String>,
}

impl Builder {
    /// A campaign with `rules` and a weather table of `header` and `rows`
    /// (each row without the timestamp, which is filled in).
    pub fn new(rules: &str, header: &str, rows: &[&str]) -> Builder {
        let mut weather = String::from(header);
        weather.push('\n');
        for (i, row) in rows.iter().enumerate() {
            let (id, rest) = row.split_once(',').unwrap_or((row, ""));
            weather.push_str(&format!(
                "{id},2023-01-{:02}T{:02}:00:00Z,{rest}\n",
                1 + i / 24,
                i % 24
            ));
        }
        Builder {
            dir: tempfile::tempdir().unwrap(),
            toml: format!("name = \"test\"\nrules = \"{rules}\"\n{LIDAR}"),
            weather,
            review: None,
            rules_file: None,
            lidar: None,
            radar: Vec::new(),
        }
    }

    /// A campaign whose weather.csv is exactly `weather`.
    pub fn raw(rules: &str, weather: &str) -> Builder {
        let mut b = Builder::new(rules, "", &[]);
        b.weather = weather.to_string();
        b
    }

    pub fn review(mut self, text: &str) -> Builder {
        self.review = Some(text.to_string());
        self
    }

    pub fn rules_file(mut self, name: &str, text: &str) -> Builder {
        self.rules_file = Some((name.to_string(), text.to_string()));
        self
    }

    pub fn lidar_files(mut self, names: &[&str]) -> Builder {
        self.lidar = Some(names.iter().map(|s| s.to_string()).collect());
        self
    }

    pub fn toml_extra(mut self, text: &str) -> Builder {
        self.toml.push_str(text);
        self
    }

    /// Writes the folder and returns its path.
    pub fn write(&self) -> &Path {
        let d = self.dir.path();
        std::fs::write(d.join("campaign.toml"), &self.toml).unwrap();
        std::fs::write(d.join("weather.csv"), &self.weather).unwrap();
        if let Some(r) = &self.review {
            std::fs::write(d.join("review.csv"), r).unwrap();
        }
        if let Some((name, text)) = &self.rules_file {
            std::fs::write(d.join(name), text).unwrap();
        }
        let lidar = d.join("lidar");
        std::fs::create_dir_all(&lidar).unwrap();
        let names: Vec<String> = match &self.lidar {
            Some(n) => n.clone(),
            None => self
                .weather
                .lines()
                .skip(1)
                .filter_map(|l| l.split(',').next())
                .filter(|id| !id.trim().is_empty())
                .map(|id| format!("{}.pcd", id.trim()))
                .collect(),
        };
        for n in names {
            std::fs::write(lidar.join(n), "").unwrap();
        }
        if !self.radar.is_empty() {
            std::fs::create_dir_all(d.join("radar")).unwrap();
            for n in &self.radar {
                std::fs::write(d.join("radar").join(n), "").unwrap();
            }
        }
        d
    }

    pub fn open(&self) -> Result<Campaign, CampaignError> {
        Campaign::open(self.write())
    }

    /// Opens, expecting an error; returns its message.
    pub fn error(&self) -> (CampaignError, String) {
        match self.open() {
            Ok(_) => panic!("campaign opened but an error was expected"),
            Err(e) => {
                let msg = e.to_string();
                (e, msg)
            }
        }
    }
}
