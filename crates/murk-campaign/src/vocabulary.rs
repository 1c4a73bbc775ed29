//! The vocabulary of `weather.csv` shared by the file reader
//! ([`crate::weather`]) and the rule sets ([`crate::rules`]): the column
//! names of the campaign contract, what each sensor column measures, and a
//! cell's value. Both read it; neither reads the other for it.

use serde::Serialize;

/// Column names of the campaign contract (`campaign-format.md`).
pub mod columns {
    /// Recording id: the stem of the files in `lidar/` and `radar/`.
    pub const RECORDING: &str = "recording";
    /// RFC 3339 time of the recording.
    pub const TIMESTAMP: &str = "timestamp";
    /// Vaisala PWD12 present-weather code.
    pub const PWD12_WEATHER_TYPE: &str = "PWD12_Weather Type";
    /// Vaisala PWD12 rain rate, mm/h.
    pub const PWD12_RAIN: &str = "PWD12_Rain intensity (mm/h)";
    /// Vaisala PWD12 meteorological optical range, m.
    pub const PWD12_MOR: &str = "PWD12_MOR (m)";
    /// Vaisala PWD12 air temperature, °C.
    pub const PWD12_TEMPERATURE: &str = "PWD12_Temperature (°C)";
    /// Lufft VS2K meteorological optical range, m.
    pub const VS2K_MOR: &str = "VS2K_MOR (m)";
    /// Vaisala WXT530 rain rate, mm/h.
    pub const WXT530_RAIN: &str = "WXT530_Rain intensity (mm/h)";
    /// OTT Parsivel rain rate, mm/h (2023-2024 campaign).
    pub const PARSIVEL_RAIN: &str = "Parsivel_Rain intensity (mm/h)";
    /// OTT Parsivel present-weather code (2023-2024 campaign).
    pub const PARSIVEL_WEATHER_TYPE: &str = "Parsivel_Weather Type";

    /// The values a present-weather column may hold (compared without
    /// regard to ASCII case).
    pub const WEATHER_TYPES: [&str; 6] = ["Clear", "Rain", "Snow", "Fog", "Drizzle", "Unknown"];
}

/// What a known sensor column measures, which fixes its type and range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
#[non_exhaustive]
pub enum SensorKind {
    /// A present-weather code, one of [`columns::WEATHER_TYPES`].
    WeatherType,
    /// A rain rate in mm/h, ≥ 0.
    RainRate,
    /// A meteorological optical range in metres, > 0.
    Mor,
    /// A temperature in °C.
    Temperature,
    /// A number with no range of its own (a column a rule set compares with
    /// a number).
    Number,
    /// Text (a column a rule set compares with text).
    Text,
}

/// The sensor columns of the campaign contract and what they hold.
pub const KNOWN_SENSOR_COLUMNS: [(&str, SensorKind); 8] = [
    (columns::PWD12_WEATHER_TYPE, SensorKind::WeatherType),
    (columns::PWD12_RAIN, SensorKind::RainRate),
    (columns::PWD12_MOR, SensorKind::Mor),
    (columns::PWD12_TEMPERATURE, SensorKind::Temperature),
    (columns::VS2K_MOR, SensorKind::Mor),
    (columns::WXT530_RAIN, SensorKind::RainRate),
    (columns::PARSIVEL_RAIN, SensorKind::RainRate),
    (columns::PARSIVEL_WEATHER_TYPE, SensorKind::WeatherType),
];

/// One non-empty cell of `weather.csv`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Cell {
    /// A number (every cell of a numeric column).
    Numeric(f64),
    /// Text (every cell of a categorical column), trimmed.
    Categorical(String),
}

/// A scan-level covariate: a cell of a column that no rule reads.
pub type Covariate = Cell;

impl Cell {
    /// The number, when the cell is numeric.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Cell::Numeric(v) => Some(*v),
            Cell::Categorical(_) => None,
        }
    }

    /// The text, when the cell is categorical.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            Cell::Numeric(_) => None,
            Cell::Categorical(s) => Some(s),
        }
    }
}

impl std::fmt::Display for Cell {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Cell::Numeric(v) => write!(f, "{v}"),
            Cell::Categorical(s) => f.write_str(s),
        }
    }
}
