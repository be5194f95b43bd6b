//! Plain text tables in GloVe's own format: `word v1 v2 … vd` per line, separated by spaces (or
//! tabs), with an optional first line `# id: NAME`.

use std::io::{BufRead, BufReader};
use std::path::Path;

use crate::EmbedError;

/// The optional first line that names the table.
const ID_PREFIX: &str = "# id:";

/// A parsed text table: its id (from the header, if any) and its words in file order.
pub(crate) struct TextTable {
    pub(crate) id: Option<String>,
    pub(crate) words: Vec<(String, Vec<f32>)>,
}

/// Reads a text table. Every non-blank line must hold a word and then as many finite numbers as
/// the first such line; the error names the line otherwise. Only the first line can be the
/// `# id:` header: later lines starting with `#` are words (GloVe has a vector for `#`).
pub(crate) fn read_text(path: &Path) -> Result<TextTable, EmbedError> {
    let io = |source| EmbedError::Io {
        path: path.to_owned(),
        source,
    };
    let bad = |line: usize, what: String| EmbedError::Text {
        path: path.to_owned(),
        line,
        what,
    };
    let mut reader = BufReader::new(crate::file::open(path)?);
    let mut id = None;
    let mut words = Vec::new();
    let mut dim = None;
    let mut buf = Vec::new();
    let mut line_no = 0;
    loop {
        buf.clear();
        if reader.read_until(b'\n', &mut buf).map_err(io)? == 0 {
            break;
        }
        line_no += 1;
        let line = std::str::from_utf8(&buf)
            .map_err(|_| bad(line_no, "not UTF-8 text".to_owned()))?
            .trim_end_matches(['\n', '\r']);
        if line_no == 1
            && let Some(name) = line.strip_prefix(ID_PREFIX)
        {
            let name = name.trim();
            if name.is_empty() {
                return Err(bad(line_no, "the `# id:` header names no id".to_owned()));
            }
            id = Some(name.to_owned());
            continue;
        }
        let mut fields = line.split([' ', '\t']).filter(|f| !f.is_empty());
        let Some(word) = fields.next() else {
            continue; // blank line
        };
        let vector = fields
            .enumerate()
            .map(|(i, f)| match f.parse::<f32>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(bad(
                    line_no,
                    format!("value {} of {word:?}, {f:?}, is not a finite number", i + 1),
                )),
            })
            .collect::<Result<Vec<f32>, _>>()?;
        match dim {
            None if vector.is_empty() => {
                return Err(bad(line_no, format!("{word:?} has no values")));
            }
            None => dim = Some(vector.len()),
            Some(d) if d != vector.len() => {
                return Err(bad(
                    line_no,
                    format!(
                        "{word:?} has {} values, but the lines before have {d}",
                        vector.len()
                    ),
                ));
            }
            Some(_) => {}
        }
        words.push((word.to_owned(), vector));
    }
    if words.is_empty() {
        return Err(bad(line_no, "the table holds no vectors".to_owned()));
    }
    Ok(TextTable { id, words })
}
