//! Python exceptions of murk and the mapping from each library crate's error.
//!
//! Every exception derives from `murk.MurkError` and carries the message the
//! CLI prints after `murk: error: ` (the error and its sources joined by
//! `: `, as anyhow's `{:#}` writes them).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    murk,
    MurkError,
    PyException,
    "Base class of every error murk raises."
);
create_exception!(
    murk,
    InputError,
    MurkError,
    "A bad argument: wrong array shape or dtype, non-contiguous array, NaN coordinates, unknown weather, missing column, parameter out of range."
);
create_exception!(
    murk,
    TableError,
    MurkError,
    "A coefficient table that cannot be read or does not have what is asked of it (a weather, a coefficient)."
);
create_exception!(
    murk,
    FileError,
    MurkError,
    "A point-cloud file that cannot be read or written."
);
create_exception!(
    murk,
    CampaignError,
    MurkError,
    "A campaign folder that cannot be opened or checked."
);
create_exception!(
    murk,
    FitError,
    MurkError,
    "A fit that cannot be done on the campaign."
);
create_exception!(
    murk,
    DiagnoseError,
    MurkError,
    "A diagnosis that cannot be done on the campaign."
);

/// The error and its sources joined by `: ` (the CLI's `{:#}`).
pub fn message(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut src = e.source();
    while let Some(c) = src {
        s.push_str(": ");
        s.push_str(&c.to_string());
        src = c.source();
    }
    s
}

/// `InputError(msg)`.
pub fn input(msg: impl Into<String>) -> PyErr {
    InputError::new_err(msg.into())
}

/// A murk-types error.
pub fn types(e: &murk_types::TypesError) -> PyErr {
    let m = message(e);
    match e {
        murk_types::TypesError::Table { .. } => TableError::new_err(m),
        _ => InputError::new_err(m),
    }
}

/// A murk-io error on a file.
pub fn io(e: &murk_io::IoError) -> PyErr {
    FileError::new_err(message(e))
}

/// A murk-io error while decoding an argument (an array): the argument is
/// what is wrong, so it is an [`InputError`].
pub fn io_arg(e: &murk_io::IoError) -> PyErr {
    InputError::new_err(message(e))
}

/// A murk-infer error.
pub fn infer(e: &murk_infer::InferError) -> PyErr {
    use murk_infer::InferError as E;
    let m = message(e);
    match e {
        E::Table(t) => types(t),
        E::WeatherAbsent { .. } | E::MissingCoefficient { .. } => TableError::new_err(m),
        E::Io(_) | E::Fs { .. } | E::OutputIsInput { .. } => FileError::new_err(m),
        E::InvalidParam { .. }
        | E::RainRateOutOfRange { .. }
        | E::Conflict(_)
        | E::BadCloud { .. }
        | E::RingOutsideSpec { .. }
        | E::Input { .. } => InputError::new_err(m),
        _ => MurkError::new_err(m),
    }
}

/// A murk-campaign error.
pub fn campaign(e: &murk_campaign::CampaignError) -> PyErr {
    CampaignError::new_err(message(e))
}

/// A murk-fit error.
pub fn fit(e: &murk_fit::FitError) -> PyErr {
    use murk_fit::FitError as E;
    let m = message(e);
    match e {
        E::InvalidParam { .. } | E::Selection { .. } => InputError::new_err(m),
        E::Campaign(_) => CampaignError::new_err(m),
        E::Read(_) => FileError::new_err(m),
        _ => FitError::new_err(m),
    }
}

/// A murk-diagnose error.
pub fn diagnose(e: &murk_diagnose::DiagnoseError) -> PyErr {
    use murk_diagnose::DiagnoseError as E;
    let m = message(e);
    match e {
        E::InvalidParam { .. } => InputError::new_err(m),
        _ => DiagnoseError::new_err(m),
    }
}

/// Adds the exception classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("MurkError", py.get_type::<MurkError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("TableError", py.get_type::<TableError>())?;
    m.add("FileError", py.get_type::<FileError>())?;
    m.add("CampaignError", py.get_type::<CampaignError>())?;
    m.add("FitError", py.get_type::<FitError>())?;
    m.add("DiagnoseError", py.get_type::<DiagnoseError>())?;
    Ok(())
}
