//! Weather classes.

use serde::{Deserialize, Serialize};

use crate::TypesError;

/// The weather class of a recording, as decided by a campaign's rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WeatherClass {
    /// Clear weather: the reference.
    Clear,
    /// Fog.
    Fog,
    /// Rain.
    Rain,
    /// Snow.
    Snow,
}

impl WeatherClass {
    /// All classes, clear first.
    pub const ALL: [WeatherClass; 4] = [
        WeatherClass::Clear,
        WeatherClass::Fog,
        WeatherClass::Rain,
        WeatherClass::Snow,
    ];
    /// The degraded classes a model is fitted for.
    pub const DEGRADED: [WeatherClass; 3] =
        [WeatherClass::Fog, WeatherClass::Rain, WeatherClass::Snow];

    /// Lower-case name (`clear`, `fog`, `rain`, `snow`).
    pub fn name(self) -> &'static str {
        match self {
            WeatherClass::Clear => "clear",
            WeatherClass::Fog => "fog",
            WeatherClass::Rain => "rain",
            WeatherClass::Snow => "snow",
        }
    }
}

impl std::fmt::Display for WeatherClass {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for WeatherClass {
    type Err = TypesError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "clear" => Ok(WeatherClass::Clear),
            "fog" => Ok(WeatherClass::Fog),
            "rain" => Ok(WeatherClass::Rain),
            "snow" => Ok(WeatherClass::Snow),
            other => Err(TypesError::UnknownWeather(other.to_string())),
        }
    }
}
