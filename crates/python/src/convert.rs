//! Values to Python: serialisable rows (the run files' rows) as dictionaries with the files'
//! column names, and keyword arguments that take several forms.

use ferret_world::procthor::HouseRange;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyRange};
use serde::Serialize;

use crate::errors;

/// Rows as dictionaries whose keys are the rows' CSV columns, in order: the rows' own serde
/// serialisation (the one that writes the CSV files, so the names cannot drift apart), read by
/// Python's `json`, which keeps the fields' order.
pub fn rows_to_py<T: Serialize>(py: Python<'_>, rows: &[T]) -> PyResult<Py<PyList>> {
    let text = serde_json::to_string(rows)
        .map_err(|e| errors::FerretError::new_err(format!("converting rows: {e}")))?;
    let list = py.import("json")?.call_method1("loads", (text,))?;
    Ok(list.downcast_into::<PyList>()?.unbind())
}

/// The houses of a file to read: `"0..150"`, `"7"`, `"3.."` as on the command line, or a
/// Python `range` with step 1.
pub fn house_range(arg: &Bound<'_, PyAny>) -> PyResult<HouseRange> {
    if let Ok(s) = arg.extract::<String>() {
        return s
            .parse::<HouseRange>()
            .map_err(|e| errors::config(format!("range: {e}")));
    }
    if let Ok(r) = arg.downcast::<PyRange>() {
        let (start, stop, step): (i64, i64, i64) = (
            r.getattr("start")?.extract()?,
            r.getattr("stop")?.extract()?,
            r.getattr("step")?.extract()?,
        );
        if step != 1 || start < 0 || stop <= start {
            return Err(errors::config(format!(
                "range: range({start}, {stop}, {step}) is not a non-empty range of house indices with step 1"
            )));
        }
        return Ok(HouseRange::new(start as usize, Some(stop as usize)));
    }
    Err(errors::config(
        "range: expected a string such as \"0..150\" or a Python range",
    ))
}

/// A list of strategy specs from a list of strings or one comma-separated string.
pub fn spec_list(arg: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<String>> {
    let specs: Vec<String> = if let Ok(s) = arg.extract::<String>() {
        s.split(',').map(|x| x.trim().to_string()).collect()
    } else if let Ok(v) = arg.extract::<Vec<String>>() {
        v.into_iter().map(|x| x.trim().to_string()).collect()
    } else {
        return Err(errors::config(format!(
            "{name}: expected a list of strategy specs or one comma-separated string"
        )));
    };
    if specs.is_empty() || specs.iter().any(String::is_empty) {
        return Err(errors::config(format!("{name}: an empty strategy spec")));
    }
    Ok(specs)
}

/// A string as Python's `repr` writes it (single quotes unless the text holds one).
pub fn quote(s: &str) -> String {
    if s.contains('\'') && !s.contains('"') {
        format!("\"{}\"", s.replace('\\', "\\\\"))
    } else {
        format!("'{}'", s.replace('\\', "\\\\").replace('\'', "\\'"))
    }
}

/// An optional string as Python's `repr` writes it.
pub fn quote_opt(s: Option<&str>) -> String {
    s.map_or_else(|| "None".to_string(), quote)
}

/// `rows` (dicts) as a `pandas.DataFrame`, with `columns` in order when given; pandas is not a
/// dependency of ferret, so its absence is an `ImportError` saying how to install it.
pub fn data_frame<'py>(
    py: Python<'py>,
    what: &str,
    rows: Py<PyList>,
    columns: Option<Vec<String>>,
) -> PyResult<Bound<'py, PyAny>> {
    let pandas = py.import("pandas").map_err(|e| {
        if e.is_instance_of::<pyo3::exceptions::PyImportError>(py) {
            pyo3::exceptions::PyImportError::new_err(format!(
                "{what}.to_pandas() needs pandas, which is not installed: pip install pandas"
            ))
        } else {
            e
        }
    })?;
    let kwargs = pyo3::types::PyDict::new(py);
    if let Some(columns) = columns {
        kwargs.set_item("columns", columns)?;
    }
    pandas.call_method("DataFrame", (rows,), Some(&kwargs))
}

/// A count keyword that takes a number or `"all"` (`trials_per_house`, `targets_per_house`),
/// parsed as the command line parses the option.
pub fn count_or_all<T>(arg: &Bound<'_, PyAny>, name: &str) -> PyResult<T>
where
    T: std::str::FromStr,
    T::Err: std::fmt::Display,
{
    let text = if let Ok(n) = arg.extract::<i64>() {
        n.to_string()
    } else if let Ok(s) = arg.extract::<String>() {
        s
    } else {
        return Err(errors::config(format!(
            "{name}: expected a number ≥ 1 or \"all\""
        )));
    };
    text.parse::<T>()
        .map_err(|e| errors::config(format!("{name}={text}: {e}")))
}
