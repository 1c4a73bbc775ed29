//! Selection rules: which weather class each recording belongs to.
//!
//! A rule set is a small TOML vocabulary. Each class (`clear`, `fog`, `rain`,
//! `snow`) has a list of conditions that must all hold; a condition compares
//! one column, or the absolute difference of two numeric columns, with a
//! number or a text, using `==`, `!=`, `<`, `<=`, `>` or `>=`. Thresholds can
//! be named parameters so that a campaign can move them without rewriting
//! the rules:
//!
//! ```toml
//! name      = "my-site"
//! intensity = ["PWD12_MOR (m)", "VS2K_MOR (m)"]   # MOR = mean of these
//! rain_rate = ["PWD12_Rain intensity (mm/h)"]     # first non-empty of these
//! priority  = ["snow", "rain", "fog", "clear"]    # when several classes match
//!
//! [params]
//! fog_mor_max = 400
//!
//! [[class.clear]]
//! column = "PWD12_Weather Type"
//! op = "=="
//! value = "Clear"
//!
//! [[class.fog]]
//! column = "VS2K_MOR (m)"
//! op = "<"
//! param = "fog_mor_max"
//!
//! [[class.fog]]
//! abs_diff = ["PWD12_MOR (m)", "VS2K_MOR (m)"]
//! op = "<="
//! value = 60
//! ```
//!
//! A condition that reads an empty cell (a sensor outage) is not satisfied;
//! the class is then reported as *lost to outage* when every condition that
//! could be evaluated held. Text comparisons ignore ASCII case, since site
//! loggers disagree on `Clear` / `CLEAR`. When several classes match, the
//! first of `priority` wins and the recording counts as ambiguous.
//!
//! The two rule sets of the seed report (Puy-de-Dôme winters 2022-2023, §3.3,
//! and 2023-2024, §4.2) are built-in presets written in this same vocabulary
//! ([`PDD_2022_2023`], [`PDD_2023_2024`]) with their thresholds as parameters
//! ([`PddParams`]).

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use murk_types::WeatherClass;
use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::error::CampaignError;
use crate::vocabulary::{Cell, KNOWN_SENSOR_COLUMNS, SensorKind, columns};

/// A comparison operator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Op {
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
}

impl Op {
    /// Every operator, in the order they are listed in error messages.
    pub const ALL: [Op; 6] = [Op::Eq, Op::Ne, Op::Lt, Op::Le, Op::Gt, Op::Ge];

    /// The operator's symbol as written in a rules file.
    pub fn symbol(self) -> &'static str {
        match self {
            Op::Eq => "==",
            Op::Ne => "!=",
            Op::Lt => "<",
            Op::Le => "<=",
            Op::Gt => ">",
            Op::Ge => ">=",
        }
    }

    /// Parses a symbol.
    pub fn from_symbol(s: &str) -> Option<Op> {
        Op::ALL.into_iter().find(|op| op.symbol() == s)
    }

    /// True for `==` and `!=`, the only operators that apply to text.
    pub fn is_equality(self) -> bool {
        matches!(self, Op::Eq | Op::Ne)
    }

    fn holds(self, ord: std::cmp::Ordering) -> bool {
        use std::cmp::Ordering::*;
        match self {
            Op::Eq => ord == Equal,
            Op::Ne => ord != Equal,
            Op::Lt => ord == Less,
            Op::Le => ord != Greater,
            Op::Gt => ord == Greater,
            Op::Ge => ord != Less,
        }
    }
}

impl std::fmt::Display for Op {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// What a condition reads.
#[derive(Debug, Clone, PartialEq)]
pub enum Operand {
    /// One column, by exact header.
    Column(String),
    /// `|a − b|` of two numeric columns.
    AbsDiff(String, String),
}

impl std::fmt::Display for Operand {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Operand::Column(c) => write!(f, "`{c}`"),
            Operand::AbsDiff(a, b) => write!(f, "|`{a}` - `{b}`|"),
        }
    }
}

/// The right-hand side of a condition.
#[derive(Debug, Clone, PartialEq)]
pub enum RuleValue {
    /// A number.
    Number(f64),
    /// A text, compared without regard to ASCII case.
    Text(String),
}

impl std::fmt::Display for RuleValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RuleValue::Number(v) => write!(f, "{v}"),
            RuleValue::Text(s) => write!(f, "\"{s}\""),
        }
    }
}

/// One condition of a class rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Condition {
    operand: Operand,
    op: Op,
    value: RuleValue,
    param: Option<String>,
    line: usize,
}

/// The result of evaluating one condition or one class on a recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Every condition held.
    Satisfied,
    /// At least one condition that could be evaluated did not hold.
    Failed,
    /// Every condition that could be evaluated held, but these columns
    /// (in rule order) were empty.
    Outage(Vec<String>),
}

impl Condition {
    /// What the condition reads.
    pub fn operand(&self) -> &Operand {
        &self.operand
    }

    /// The operator.
    pub fn op(&self) -> Op {
        self.op
    }

    /// The threshold or text (after parameters are applied).
    pub fn value(&self) -> &RuleValue {
        &self.value
    }

    /// The parameter the value comes from, when it is one.
    pub fn param(&self) -> Option<&str> {
        self.param.as_deref()
    }

    /// 1-based line of the condition in its rules file.
    pub fn line(&self) -> usize {
        self.line
    }

    /// Evaluates the condition on the cells returned by `value`.
    pub fn evaluate<'c>(&self, value: &impl Fn(&str) -> Option<&'c Cell>) -> Outcome {
        match &self.operand {
            Operand::Column(c) => match value(c) {
                None => Outcome::Outage(vec![c.clone()]),
                Some(cell) => self.compare_cell(cell),
            },
            Operand::AbsDiff(a, b) => {
                let (va, vb) = (value(a), value(b));
                let mut missing = Vec::new();
                if va.is_none() {
                    missing.push(a.clone());
                }
                if vb.is_none() {
                    missing.push(b.clone());
                }
                if !missing.is_empty() {
                    return Outcome::Outage(missing);
                }
                match (va.and_then(Cell::as_f64), vb.and_then(Cell::as_f64)) {
                    (Some(x), Some(y)) => self.compare_cell(&Cell::Numeric((x - y).abs())),
                    _ => Outcome::Failed,
                }
            }
        }
    }

    fn compare_cell(&self, cell: &Cell) -> Outcome {
        let holds = match (cell, &self.value) {
            (Cell::Numeric(x), RuleValue::Number(t)) => {
                x.partial_cmp(t).is_some_and(|o| self.op.holds(o))
            }
            (Cell::Categorical(s), RuleValue::Text(t)) => {
                let eq = s.eq_ignore_ascii_case(t);
                match self.op {
                    Op::Eq => eq,
                    Op::Ne => !eq,
                    _ => false,
                }
            }
            // Open-time checks make a rule compare like with like; a
            // mismatched cell can only come from a hand-built lookup.
            _ => false,
        };
        if holds {
            Outcome::Satisfied
        } else {
            Outcome::Failed
        }
    }
}

impl std::fmt::Display for Condition {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {} {}", self.operand, self.op, self.value)?;
        if let Some(p) = &self.param {
            write!(f, " ({p})")?;
        }
        Ok(())
    }
}

/// The class decided for one recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Classification {
    /// The class after `priority`, `None` when no class matched.
    pub class: Option<WeatherClass>,
    /// Every class whose conditions all held, in priority order.
    pub matched: Vec<WeatherClass>,
    /// Classes that failed only because of empty cells, with those columns.
    pub outages: Vec<(WeatherClass, Vec<String>)>,
}

impl Classification {
    /// True when more than one class matched.
    pub fn is_ambiguous(&self) -> bool {
        self.matched.len() > 1
    }
}

/// Thresholds of the two Puy-de-Dôme rule sets.
///
/// | Name | Default | Purpose | Range |
/// |---|---|---|---|
/// | `clear_mor_min` | 2000 m | both visibility sensors at least this for clear weather | > 0 |
/// | `fog_mor_max` | 400 m | both visibility sensors below this for fog (NF P 99-320) | > 0 |
/// | `fog_agreement_max` | 60 m | largest `\|PWD12 − VS2K\|` MOR gap for fog (2022-2023 only) | ≥ 0 |
/// | `snow_temperature_max` | 5 °C | PWD12 temperature below this for snow (2023-2024 only) | finite |
///
/// In `campaign.toml` they are overridden by name under `[rule_params]`; a
/// parameter the chosen preset does not use is an error there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PddParams {
    /// Minimum MOR of both visibility sensors in clear weather, metres.
    pub clear_mor_min: f64,
    /// MOR of both visibility sensors must be below this in fog, metres.
    pub fog_mor_max: f64,
    /// Largest disagreement of the two visibility sensors in fog, metres.
    pub fog_agreement_max: f64,
    /// Temperature must be below this for snow, °C.
    pub snow_temperature_max: f64,
}

impl Default for PddParams {
    fn default() -> Self {
        PddParams {
            clear_mor_min: 2000.0,
            fog_mor_max: 400.0,
            fog_agreement_max: 60.0,
            snow_temperature_max: 5.0,
        }
    }
}

impl PddParams {
    /// The parameters by name, as a rule set's `[params]` names them.
    pub fn to_map(&self) -> BTreeMap<String, f64> {
        [
            ("clear_mor_min", self.clear_mor_min),
            ("fog_mor_max", self.fog_mor_max),
            ("fog_agreement_max", self.fog_agreement_max),
            ("snow_temperature_max", self.snow_temperature_max),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }
}

/// Checks a parameter value: finite, and within the range a PDD threshold
/// needs when it is one. Returns the reason when it is not acceptable.
fn check_param(name: &str, v: f64) -> Result<(), String> {
    if !v.is_finite() {
        return Err(format!("parameter `{name}` = {v} is not a finite number"));
    }
    match name {
        "clear_mor_min" | "fog_mor_max" if v <= 0.0 => Err(format!(
            "parameter `{name}` = {v} must be > 0 (a MOR in metres)"
        )),
        "fog_agreement_max" if v < 0.0 => Err(format!(
            "parameter `{name}` = {v} must be >= 0 (a MOR difference in metres)"
        )),
        _ => Ok(()),
    }
}

/// Name of the winter 2022-2023 preset (seed report §3.3).
pub const PDD_2022_2023: &str = "pdd-2022-2023";
/// Name of the winter 2023-2024 preset (seed report §4.2).
pub const PDD_2023_2024: &str = "pdd-2023-2024";

/// The seed's §3.3 rules (LiDAR campaign, winter 2022-2023), verbatim in the
/// rules vocabulary.
const PDD_2022_2023_TOML: &str = r#"
name      = "pdd-2022-2023"
intensity = ["PWD12_MOR (m)", "VS2K_MOR (m)"]
rain_rate = ["PWD12_Rain intensity (mm/h)", "WXT530_Rain intensity (mm/h)"]
priority  = ["snow", "rain", "fog", "clear"]

[params]
clear_mor_min     = 2000.0
fog_mor_max       = 400.0
fog_agreement_max = 60.0

[[class.clear]]
column = "PWD12_Weather Type"
op = "=="
value = "Clear"
[[class.clear]]
column = "PWD12_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.clear]]
column = "WXT530_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.clear]]
column = "VS2K_MOR (m)"
op = ">="
param = "clear_mor_min"
[[class.clear]]
column = "PWD12_MOR (m)"
op = ">="
param = "clear_mor_min"

[[class.rain]]
column = "PWD12_Weather Type"
op = "=="
value = "Rain"
[[class.rain]]
column = "PWD12_Rain intensity (mm/h)"
op = ">"
value = 0

[[class.fog]]
column = "PWD12_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.fog]]
column = "WXT530_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.fog]]
column = "VS2K_MOR (m)"
op = "<"
param = "fog_mor_max"
[[class.fog]]
column = "PWD12_MOR (m)"
op = "<"
param = "fog_mor_max"
[[class.fog]]
abs_diff = ["PWD12_MOR (m)", "VS2K_MOR (m)"]
op = "<="
param = "fog_agreement_max"

[[class.snow]]
column = "PWD12_Weather Type"
op = "=="
value = "Snow"
"#;

/// The seed's §4.2 rules (RADAR campaign, winter 2023-2024), verbatim in the
/// rules vocabulary. Unlike 2022-2023 there is no sensor-agreement test for
/// fog and no weather-type test for clear; snow needs PWD12 below 5 °C.
const PDD_2023_2024_TOML: &str = r#"
name      = "pdd-2023-2024"
intensity = ["PWD12_MOR (m)", "VS2K_MOR (m)"]
rain_rate = ["Parsivel_Rain intensity (mm/h)", "WXT530_Rain intensity (mm/h)"]
priority  = ["snow", "rain", "fog", "clear"]

[params]
clear_mor_min        = 2000.0
fog_mor_max          = 400.0
snow_temperature_max = 5.0

[[class.clear]]
column = "Parsivel_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.clear]]
column = "WXT530_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.clear]]
column = "VS2K_MOR (m)"
op = ">="
param = "clear_mor_min"
[[class.clear]]
column = "PWD12_MOR (m)"
op = ">="
param = "clear_mor_min"

[[class.rain]]
column = "WXT530_Rain intensity (mm/h)"
op = ">"
value = 0
[[class.rain]]
column = "Parsivel_Rain intensity (mm/h)"
op = ">"
value = 0
[[class.rain]]
column = "Parsivel_Weather Type"
op = "!="
value = "Snow"

[[class.fog]]
column = "Parsivel_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.fog]]
column = "WXT530_Rain intensity (mm/h)"
op = "=="
value = 0
[[class.fog]]
column = "VS2K_MOR (m)"
op = "<"
param = "fog_mor_max"
[[class.fog]]
column = "PWD12_MOR (m)"
op = "<"
param = "fog_mor_max"

[[class.snow]]
column = "Parsivel_Weather Type"
op = "=="
value = "Snow"
[[class.snow]]
column = "PWD12_Temperature (°C)"
op = "<"
param = "snow_temperature_max"
"#;

/// A checked set of selection rules.
#[derive(Debug, Clone, PartialEq)]
pub struct RuleSet {
    name: String,
    origin: PathBuf,
    intensity: Vec<String>,
    rain_rate: Vec<String>,
    priority: Vec<WeatherClass>,
    classes: Vec<(WeatherClass, Vec<Condition>)>,
    params: BTreeMap<String, f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRules {
    name: Option<String>,
    intensity: Vec<String>,
    #[serde(default)]
    rain_rate: Vec<String>,
    priority: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    params: BTreeMap<Spanned<String>, Spanned<f64>>,
    class: BTreeMap<Spanned<String>, Vec<Spanned<RawCondition>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCondition {
    column: Option<String>,
    abs_diff: Option<Vec<String>>,
    op: String,
    value: Option<toml::Value>,
    param: Option<String>,
}

/// 1-based line of byte `offset` in `text`.
pub(crate) fn line_of(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// Maps a TOML parse error to ours, with its line.
pub(crate) fn toml_error(path: &Path, text: &str, e: &toml::de::Error) -> CampaignError {
    CampaignError::Toml {
        path: path.to_path_buf(),
        line: e.span().map_or(1, |s| line_of(text, s.start)),
        reason: e.message().trim().to_string(),
    }
}

impl RuleSet {
    /// Names of the built-in presets.
    pub const PRESETS: [&'static str; 2] = [PDD_2022_2023, PDD_2023_2024];

    /// A built-in preset with the given thresholds (parameters the preset
    /// does not use are ignored).
    pub fn preset(name: &str, params: &PddParams) -> Result<RuleSet, CampaignError> {
        let text = match name {
            PDD_2022_2023 => PDD_2022_2023_TOML,
            PDD_2023_2024 => PDD_2023_2024_TOML,
            other => {
                return Err(CampaignError::Rules {
                    path: PathBuf::from(other),
                    line: 1,
                    reason: format!(
                        "`{other}` is not a built-in rule set; presets are {}",
                        RuleSet::PRESETS.join(", ")
                    ),
                });
            }
        };
        let mut rules = RuleSet::parse(text, Path::new(name))?;
        for (k, v) in params.to_map() {
            if rules.params.contains_key(&k) {
                rules
                    .set_param(&k, v)
                    .map_err(|reason| CampaignError::Rules {
                        path: PathBuf::from(name),
                        line: 1,
                        reason,
                    })?;
            }
        }
        Ok(rules)
    }

    /// The winter 2022-2023 rules of the seed report (§3.3).
    pub fn pdd_2022_2023(params: &PddParams) -> Result<RuleSet, CampaignError> {
        RuleSet::preset(PDD_2022_2023, params)
    }

    /// The winter 2023-2024 rules of the seed report (§4.2).
    pub fn pdd_2023_2024(params: &PddParams) -> Result<RuleSet, CampaignError> {
        RuleSet::preset(PDD_2023_2024, params)
    }

    /// The source text of a built-in preset, a starting point for a custom
    /// rules file.
    pub fn preset_source(name: &str) -> Option<&'static str> {
        match name {
            PDD_2022_2023 => Some(PDD_2022_2023_TOML),
            PDD_2023_2024 => Some(PDD_2023_2024_TOML),
            _ => None,
        }
    }

    /// Reads and checks a rules file.
    pub fn from_file(path: &Path) -> Result<RuleSet, CampaignError> {
        let text = std::fs::read_to_string(path).map_err(|source| CampaignError::Io {
            path: path.to_path_buf(),
            reason: "cannot read rules file".into(),
            source,
        })?;
        RuleSet::parse(&text, path)
    }

    /// Parses and checks rules from TOML text; `path` names the text in
    /// errors (and gives the rule set its default name, the file stem).
    pub fn parse(text: &str, path: &Path) -> Result<RuleSet, CampaignError> {
        let raw: RawRules = toml::from_str(text).map_err(|e| toml_error(path, text, &e))?;
        let err = |line: usize, reason: String| CampaignError::Rules {
            path: path.to_path_buf(),
            line,
            reason,
        };

        let mut params = BTreeMap::new();
        let mut param_line = HashMap::new();
        for (k, v) in &raw.params {
            let line = line_of(text, k.span().start);
            check_param(k.get_ref(), *v.get_ref()).map_err(|r| err(line, r))?;
            params.insert(k.get_ref().clone(), *v.get_ref());
            param_line.insert(k.get_ref().clone(), line);
        }

        let mut classes = Vec::new();
        let mut used_params = std::collections::BTreeSet::new();
        for (key, conds) in &raw.class {
            let line = line_of(text, key.span().start);
            let class: WeatherClass = key.get_ref().parse().map_err(|_| {
                err(
                    line,
                    format!(
                        "unknown class `{}`; expected clear, fog, rain or snow",
                        key.get_ref()
                    ),
                )
            })?;
            if conds.is_empty() {
                return Err(err(line, format!("class `{class}` has no condition")));
            }
            let mut out = Vec::with_capacity(conds.len());
            for c in conds {
                let line = line_of(text, c.span().start);
                let cond = condition(c.get_ref(), line, &params).map_err(|r| err(line, r))?;
                if let Some(p) = &cond.param {
                    used_params.insert(p.clone());
                }
                out.push(cond);
            }
            classes.push((class, out));
        }
        if classes.is_empty() {
            return Err(err(1, "no class is defined ([[class.<name>]])".into()));
        }
        if let Some(unused) = params.keys().find(|k| !used_params.contains(*k)) {
            return Err(err(
                param_line[unused],
                format!("parameter `{unused}` is declared but no condition uses it"),
            ));
        }

        let defined: Vec<WeatherClass> = classes.iter().map(|(c, _)| *c).collect();
        let priority = match &raw.priority {
            None => [
                WeatherClass::Snow,
                WeatherClass::Rain,
                WeatherClass::Fog,
                WeatherClass::Clear,
            ]
            .into_iter()
            .filter(|c| defined.contains(c))
            .collect(),
            Some(p) => {
                let line = line_of(text, p.span().start);
                let mut out: Vec<WeatherClass> = Vec::new();
                for name in p.get_ref() {
                    let c: WeatherClass = name
                        .parse()
                        .map_err(|_| err(line, format!("priority names unknown class `{name}`")))?;
                    if out.contains(&c) {
                        return Err(err(line, format!("priority names `{c}` twice")));
                    }
                    if !defined.contains(&c) {
                        return Err(err(
                            line,
                            format!("priority names `{c}`, which has no [[class.{c}]] rule"),
                        ));
                    }
                    out.push(c);
                }
                if let Some(c) = defined.iter().find(|c| !out.contains(c)) {
                    return Err(err(line, format!("priority does not list class `{c}`")));
                }
                out
            }
        };
        classes.sort_by_key(|(c, _)| priority.iter().position(|p| p == c));

        let name = raw.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        });
        let rules = RuleSet {
            name,
            origin: path.to_path_buf(),
            intensity: raw.intensity,
            rain_rate: raw.rain_rate,
            priority,
            classes,
            params,
        };
        rules
            .check_column_types()
            .map_err(|(line, r)| err(line, r))?;
        Ok(rules)
    }

    /// Rejects a column read both as text and as a number, or read against
    /// its known type (text compared with a MOR, a number with a weather
    /// type, a weather type that no sensor reports).
    fn check_column_types(&self) -> Result<(), (usize, String)> {
        let known: HashMap<&str, SensorKind> = KNOWN_SENSOR_COLUMNS.iter().copied().collect();
        let mut numeric: HashMap<&str, usize> = HashMap::new();
        let mut text: HashMap<&str, usize> = HashMap::new();
        for name in self.intensity.iter().chain(&self.rain_rate) {
            numeric.entry(name).or_insert(1);
        }
        for cond in self.conditions() {
            match (&cond.operand, &cond.value) {
                (Operand::Column(c), RuleValue::Text(t)) => {
                    text.entry(c).or_insert(cond.line);
                    if known.get(c.as_str()) == Some(&SensorKind::WeatherType)
                        && !columns::WEATHER_TYPES
                            .iter()
                            .any(|w| w.eq_ignore_ascii_case(t))
                    {
                        return Err((
                            cond.line,
                            format!(
                                "`{c}` never holds \"{t}\"; its values are {}",
                                columns::WEATHER_TYPES.join(", ")
                            ),
                        ));
                    }
                }
                (Operand::Column(c), RuleValue::Number(_)) => {
                    numeric.entry(c).or_insert(cond.line);
                }
                (Operand::AbsDiff(a, b), _) => {
                    numeric.entry(a).or_insert(cond.line);
                    numeric.entry(b).or_insert(cond.line);
                }
            }
        }
        for (c, &line) in &text {
            if let Some(&nline) = numeric.get(c) {
                return Err((
                    line.max(nline),
                    format!("column `{c}` is compared both with text and with a number"),
                ));
            }
            if let Some(kind) = known.get(c).filter(|k| **k != SensorKind::WeatherType) {
                return Err((
                    line,
                    format!("column `{c}` holds numbers ({kind:?}) but is compared with text"),
                ));
            }
        }
        for (c, &line) in &numeric {
            if known.get(c) == Some(&SensorKind::WeatherType) {
                return Err((
                    line,
                    format!("column `{c}` holds weather types (text) but is read as a number"),
                ));
            }
        }
        Ok(())
    }

    /// Sets a parameter and every condition that uses it. Returns the reason
    /// when the rule set has no such parameter or the value is unusable.
    pub(crate) fn set_param(&mut self, name: &str, value: f64) -> Result<(), String> {
        if !self.params.contains_key(name) {
            let known: Vec<&str> = self.params.keys().map(String::as_str).collect();
            return Err(format!(
                "rule set `{}` has no parameter `{name}`; its parameters are: {}",
                self.name,
                if known.is_empty() {
                    "(none)".to_string()
                } else {
                    known.join(", ")
                }
            ));
        }
        check_param(name, value)?;
        self.params.insert(name.to_string(), value);
        for (_, conds) in &mut self.classes {
            for c in conds
                .iter_mut()
                .filter(|c| c.param.as_deref() == Some(name))
            {
                c.value = RuleValue::Number(value);
            }
        }
        Ok(())
    }

    /// This rule set with some parameters replaced by name.
    pub fn with_params(mut self, params: &BTreeMap<String, f64>) -> Result<RuleSet, CampaignError> {
        for (k, v) in params {
            self.set_param(k, *v)
                .map_err(|reason| CampaignError::Rules {
                    path: self.origin.clone(),
                    line: 1,
                    reason,
                })?;
        }
        Ok(self)
    }

    /// The rule set's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Where the rules came from: the rules file, or the preset's name.
    pub fn origin(&self) -> &Path {
        &self.origin
    }

    /// Visibility columns whose mean is a recording's MOR.
    pub fn intensity(&self) -> &[String] {
        &self.intensity
    }

    /// Rain-rate columns; a recording's rain rate is the first non-empty.
    pub fn rain_rate(&self) -> &[String] {
        &self.rain_rate
    }

    /// Classes in priority order (first wins when several match).
    pub fn priority(&self) -> &[WeatherClass] {
        &self.priority
    }

    /// The parameters and their current values.
    pub fn params(&self) -> &BTreeMap<String, f64> {
        &self.params
    }

    /// The conditions of `class`, or `None` when the rule set does not
    /// define it.
    pub fn class(&self, class: WeatherClass) -> Option<&[Condition]> {
        self.classes
            .iter()
            .find(|(c, _)| *c == class)
            .map(|(_, v)| v.as_slice())
    }

    fn conditions(&self) -> impl Iterator<Item = &Condition> {
        self.classes.iter().flat_map(|(_, v)| v)
    }

    /// Every column the rule set reads (conditions, `intensity`,
    /// `rain_rate`), once each, in first-use order, with `true` when it is
    /// read as a number.
    pub fn columns(&self) -> Vec<(&str, bool)> {
        let mut out: Vec<(&str, bool)> = Vec::new();
        for cond in self.conditions() {
            match &cond.operand {
                Operand::Column(c) => {
                    let numeric = matches!(cond.value, RuleValue::Number(_));
                    if !out.iter().any(|(n, _)| *n == c) {
                        out.push((c, numeric));
                    }
                }
                Operand::AbsDiff(a, b) => {
                    for c in [a, b] {
                        if !out.iter().any(|(n, _)| *n == c) {
                            out.push((c, true));
                        }
                    }
                }
            }
        }
        for c in self.intensity.iter().chain(&self.rain_rate) {
            if !out.iter().any(|(n, _)| *n == c) {
                out.push((c, true));
            }
        }
        out
    }

    /// Decides the class of one recording whose cells `value` returns by
    /// column (`None` for an empty cell or an unknown column).
    pub fn classify<'c>(&self, value: impl Fn(&str) -> Option<&'c Cell>) -> Classification {
        let mut matched = Vec::new();
        let mut outages = Vec::new();
        for (class, conds) in &self.classes {
            match class_outcome(conds, &value) {
                Outcome::Satisfied => matched.push(*class),
                Outcome::Failed => {}
                Outcome::Outage(cols) => outages.push((*class, cols)),
            }
        }
        Classification {
            class: matched.first().copied(),
            matched,
            outages,
        }
    }

    /// The MOR of a recording: the mean of the non-empty `intensity`
    /// columns, `None` when all are empty.
    pub fn mor<'c>(&self, value: impl Fn(&str) -> Option<&'c Cell>) -> Option<f64> {
        let vals: Vec<f64> = self
            .intensity
            .iter()
            .filter_map(|c| value(c).and_then(Cell::as_f64))
            .collect();
        (!vals.is_empty()).then(|| vals.iter().sum::<f64>() / vals.len() as f64)
    }

    /// The rain rate of a recording: the first non-empty `rain_rate`
    /// column, mm/h.
    pub fn rain_rate_of<'c>(&self, value: impl Fn(&str) -> Option<&'c Cell>) -> Option<f64> {
        self.rain_rate
            .iter()
            .find_map(|c| value(c).and_then(Cell::as_f64))
    }
}

/// All conditions of a class: failed if any evaluable one fails, outage if
/// none fails but some read an empty cell.
fn class_outcome<'c>(conds: &[Condition], value: &impl Fn(&str) -> Option<&'c Cell>) -> Outcome {
    let mut missing: Vec<String> = Vec::new();
    for c in conds {
        match c.evaluate(value) {
            Outcome::Satisfied => {}
            Outcome::Failed => return Outcome::Failed,
            Outcome::Outage(cols) => {
                for col in cols {
                    if !missing.contains(&col) {
                        missing.push(col);
                    }
                }
            }
        }
    }
    if missing.is_empty() {
        Outcome::Satisfied
    } else {
        Outcome::Outage(missing)
    }
}

fn condition(
    raw: &RawCondition,
    line: usize,
    params: &BTreeMap<String, f64>,
) -> Result<Condition, String> {
    let op = Op::from_symbol(raw.op.trim()).ok_or_else(|| {
        format!(
            "unknown op `{}`; expected one of {}",
            raw.op,
            Op::ALL.map(Op::symbol).join(", ")
        )
    })?;
    let operand = match (&raw.column, &raw.abs_diff) {
        (Some(c), None) => Operand::Column(c.trim().to_string()),
        (None, Some(pair)) => match pair.as_slice() {
            [a, b] => Operand::AbsDiff(a.trim().to_string(), b.trim().to_string()),
            _ => {
                return Err(format!(
                    "abs_diff takes exactly two columns, got {}",
                    pair.len()
                ));
            }
        },
        (Some(_), Some(_)) => return Err("a condition has `column` or `abs_diff`, not both".into()),
        (None, None) => return Err("a condition needs `column` or `abs_diff`".into()),
    };
    let (value, param) = match (&raw.value, &raw.param) {
        (Some(v), None) => (rule_value(v)?, None),
        (None, Some(p)) => {
            let v = params.get(p).ok_or_else(|| {
                format!(
                    "unknown parameter `{p}`; declare it under [params] (declared: {})",
                    if params.is_empty() {
                        "none".to_string()
                    } else {
                        params.keys().cloned().collect::<Vec<_>>().join(", ")
                    }
                )
            })?;
            (RuleValue::Number(*v), Some(p.clone()))
        }
        (Some(_), Some(_)) => return Err("a condition has `value` or `param`, not both".into()),
        (None, None) => return Err("a condition needs `value` or `param`".into()),
    };
    if let RuleValue::Text(_) = value {
        if !op.is_equality() {
            return Err(format!("op `{op}` compares numbers, but the value is text"));
        }
        if matches!(operand, Operand::AbsDiff(..)) {
            return Err("abs_diff is a number and cannot be compared with text".into());
        }
    }
    Ok(Condition {
        operand,
        op,
        value,
        param,
        line,
    })
}

fn rule_value(v: &toml::Value) -> Result<RuleValue, String> {
    match v {
        toml::Value::Integer(i) => Ok(RuleValue::Number(*i as f64)),
        toml::Value::Float(f) if f.is_finite() => Ok(RuleValue::Number(*f)),
        toml::Value::Float(f) => Err(format!("value {f} is not a finite number")),
        toml::Value::String(s) => Ok(RuleValue::Text(s.trim().to_string())),
        other => Err(format!(
            "value must be a number or a string, got {}",
            other.type_str()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_read_the_seed_columns() {
        let r = RuleSet::pdd_2022_2023(&PddParams::default()).unwrap();
        assert_eq!(r.priority().len(), 4);
        assert_eq!(r.class(WeatherClass::Fog).unwrap().len(), 5);
        assert_eq!(r.class(WeatherClass::Clear).unwrap().len(), 5);
        let r = RuleSet::pdd_2023_2024(&PddParams::default()).unwrap();
        assert_eq!(r.class(WeatherClass::Fog).unwrap().len(), 4);
        assert_eq!(r.class(WeatherClass::Snow).unwrap().len(), 2);
        assert!(r.params().get("fog_agreement_max").is_none());
    }

    #[test]
    fn params_move_thresholds() {
        let p = PddParams {
            fog_mor_max: 300.0,
            ..PddParams::default()
        };
        let r = RuleSet::pdd_2022_2023(&p).unwrap();
        let fog = r.class(WeatherClass::Fog).unwrap();
        let with_param: Vec<_> = fog
            .iter()
            .filter(|c| c.param() == Some("fog_mor_max"))
            .collect();
        assert_eq!(with_param.len(), 2);
        assert!(
            with_param
                .iter()
                .all(|c| c.value() == &RuleValue::Number(300.0))
        );
    }

    #[test]
    fn ops_known_answers() {
        use std::cmp::Ordering::*;
        let table = [
            (Op::Eq, [false, true, false]),
            (Op::Ne, [true, false, true]),
            (Op::Lt, [true, false, false]),
            (Op::Le, [true, true, false]),
            (Op::Gt, [false, false, true]),
            (Op::Ge, [false, true, true]),
        ];
        for (op, want) in table {
            assert_eq!(
                [op.holds(Less), op.holds(Equal), op.holds(Greater)],
                want,
                "{op}"
            );
            assert_eq!(Op::from_symbol(op.symbol()), Some(op));
        }
    }
}
