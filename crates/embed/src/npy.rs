//! A reader for NumPy `.npy` files holding one 2-D little-endian float32 matrix, in C (row-major)
//! or Fortran (column-major) order, returned row-major.
//!
//! The format: the magic `\x93NUMPY`, a major and a minor version byte, the header length (a
//! little-endian u16 in version 1, u32 in versions 2 and 3), then the header, a Python dict
//! literal such as `{'descr': '<f4', 'fortran_order': True, 'shape': (400000, 50), }`, then the
//! raw values.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::EmbedError;

/// The first bytes of every `.npy` file.
const MAGIC: &[u8] = b"\x93NUMPY";

/// The only dtype read: little-endian float32, what embedding matrices are shipped in.
const DESCR_F32: &str = "<f4";

/// Values converted per read: large enough that reading is not dominated by calls, small enough
/// that the file is never held twice in memory.
const CHUNK_VALUES: usize = 1 << 18;

/// Headers longer than this are refused rather than allocated (NumPy writes a few hundred bytes).
const MAX_HEADER: usize = 1 << 20;

/// A row-major float32 matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Matrix {
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// `rows × cols` values, row after row.
    pub data: Vec<f32>,
}

/// Most values a matrix may hold: 2^30 float32s, 4 GiB (GloVe's largest table, 2.2 M words of
/// 300 numbers, is 0.6 of it). A header claiming more is refused before anything is allocated.
pub const MAX_VALUES: usize = 1 << 30;

/// Reads a 2-D `<f4` matrix from an `.npy` file, converting Fortran order to row-major.
///
/// Refuses other dtypes, other numbers of dimensions, a malformed header, a matrix of more than
/// [`MAX_VALUES`] numbers and a file whose length is not exactly header plus `rows × cols × 4`
/// bytes, all before reading the values.
pub fn read_npy(path: &Path) -> Result<Matrix, EmbedError> {
    read_npy_checked(path, |_| Ok(()))
}

/// [`read_npy`], with `check` run on the header's shape (rows, columns) before the values are
/// read: a matrix that does not fit what is beside it costs no more than its header.
pub(crate) fn read_npy_checked(
    path: &Path,
    check: impl FnOnce((usize, usize)) -> Result<(), EmbedError>,
) -> Result<Matrix, EmbedError> {
    let io = |source| EmbedError::Io {
        path: path.to_owned(),
        source,
    };
    let mut file = crate::file::open(path)?;
    let header = read_header(&mut file, path)?;
    let (rows, cols) = (header.rows, header.cols);
    check((rows, cols))?;
    let values = rows * cols;
    let mut data = Vec::new();
    data.try_reserve_exact(values)
        .map_err(|_| EmbedError::Npy {
            path: path.to_owned(),
            what: format!(
                "shape ({rows}, {cols}): {} MB of memory could not be had",
                values.saturating_mul(4) / 1_000_000
            ),
        })?;
    data.resize(values, 0f32);
    let mut bytes = vec![0u8; CHUNK_VALUES.min(values) * 4];
    // `k` counts values in file order. In C order that is the row-major index already; in
    // Fortran order value k is column k / rows, row k % rows.
    let mut k = 0;
    while k < values {
        let n = CHUNK_VALUES.min(values - k);
        let chunk = &mut bytes[..n * 4];
        file.read_exact(chunk).map_err(io)?;
        let floats = chunk
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        if header.fortran_order {
            let (mut col, mut row) = (k / rows, k % rows);
            for v in floats {
                data[row * cols + col] = v;
                row += 1;
                if row == rows {
                    row = 0;
                    col += 1;
                }
            }
        } else {
            for (slot, v) in data[k..k + n].iter_mut().zip(floats) {
                *slot = v;
            }
        }
        k += n;
    }
    Ok(Matrix { rows, cols, data })
}

/// What the header of a float32 matrix says, checked against the file's length.
struct Shape {
    rows: usize,
    cols: usize,
    fortran_order: bool,
}

/// Reads and checks the preamble and header of the `.npy` file open as `file`, leaving it at
/// the first value.
fn read_header(file: &mut File, path: &Path) -> Result<Shape, EmbedError> {
    let io = |source| EmbedError::Io {
        path: path.to_owned(),
        source,
    };
    let bad = |what: String| EmbedError::Npy {
        path: path.to_owned(),
        what,
    };
    let actual = file.metadata().map_err(io)?.len();
    let mut preamble = [0u8; 8];
    read_prefix(file, &mut preamble, path, "the magic and version")?;
    if &preamble[..6] != MAGIC {
        return Err(bad(format!(
            "not an NPY file: it starts with {:?}, not \\x93NUMPY",
            String::from_utf8_lossy(&preamble[..6])
        )));
    }
    let (major, minor) = (preamble[6], preamble[7]);
    let header_len = match major {
        1 => {
            let mut len = [0u8; 2];
            read_prefix(file, &mut len, path, "the header length")?;
            usize::from(u16::from_le_bytes(len))
        }
        2 | 3 => {
            let mut len = [0u8; 4];
            read_prefix(file, &mut len, path, "the header length")?;
            usize::try_from(u32::from_le_bytes(len)).unwrap_or(usize::MAX)
        }
        _ => {
            return Err(bad(format!(
                "NPY format version {major}.{minor} is not supported (1, 2 or 3)"
            )));
        }
    };
    if header_len > MAX_HEADER {
        return Err(bad(format!(
            "the header claims {header_len} bytes; NPY headers are a few hundred"
        )));
    }
    let mut header = vec![0u8; header_len];
    read_prefix(file, &mut header, path, "the header")?;
    // Versions 1 and 2 use latin-1, 3 UTF-8; a float32 matrix header is plain ASCII in all.
    let header = std::str::from_utf8(&header)
        .map_err(|_| bad("the header is not ASCII/UTF-8 text".to_owned()))?;
    let header = parse_header(header).map_err(|what| bad(format!("header: {what}")))?;
    if header.descr != DESCR_F32 {
        return Err(bad(format!(
            "dtype {:?} is not supported: expected {DESCR_F32:?} (little-endian float32)",
            header.descr
        )));
    }
    let [rows, cols] = header.shape[..] else {
        return Err(bad(format!(
            "shape {:?} is not supported: expected a 2-D matrix (words, dimensions)",
            header.shape
        )));
    };
    if rows == 0 || cols == 0 {
        return Err(bad(format!("the matrix is empty (shape ({rows}, {cols}))")));
    }
    let values = rows.checked_mul(cols).filter(|v| *v <= MAX_VALUES);
    let Some(values) = values else {
        return Err(bad(format!(
            "shape ({rows}, {cols}) is more than the {MAX_VALUES} numbers (4 GiB) ferret reads"
        )));
    };
    let preamble_len = (8 + if major == 1 { 2 } else { 4 } + header_len) as u64;
    let expected = values as u64 * 4 + preamble_len;
    if actual != expected {
        return Err(EmbedError::NpySize {
            path: path.to_owned(),
            rows,
            dim: cols,
            expected,
            actual,
        });
    }
    Ok(Shape {
        rows,
        cols,
        fortran_order: header.fortran_order,
    })
}

/// Fills `buf` from the start of the file, naming the part that is missing on a short file.
fn read_prefix(file: &mut File, buf: &mut [u8], path: &Path, part: &str) -> Result<(), EmbedError> {
    file.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            EmbedError::Npy {
                path: path.to_owned(),
                what: format!("not an NPY file: it ends before {part}"),
            }
        } else {
            EmbedError::Io {
                path: path.to_owned(),
                source: e,
            }
        }
    })
}

/// The three keys of an NPY header.
#[derive(Debug, PartialEq)]
struct Header {
    descr: String,
    fortran_order: bool,
    shape: Vec<usize>,
}

/// A Python literal, as far as NPY headers use them.
#[derive(Debug)]
enum Lit {
    Str(String),
    Bool(bool),
    Int(usize),
    None,
    Seq(Vec<Lit>),
    Dict(Vec<(Lit, Lit)>),
}

/// Parses the header dict and picks out `descr`, `fortran_order` and `shape`; other keys are
/// ignored (NumPy writes none).
fn parse_header(text: &str) -> Result<Header, String> {
    let mut p = Parser {
        s: text.as_bytes(),
        i: 0,
    };
    let lit = p.value(0)?;
    p.ws();
    if p.i != p.s.len() {
        return Err(format!("unexpected text after the dict at byte {}", p.i));
    }
    let Lit::Dict(entries) = lit else {
        return Err("not a dict".to_owned());
    };
    let (mut descr, mut fortran_order, mut shape) = (None, None, None);
    for (key, value) in entries {
        let Lit::Str(key) = key else {
            continue;
        };
        match (key.as_str(), value) {
            ("descr", Lit::Str(s)) => descr = Some(s),
            ("descr", other) => {
                return Err(format!(
                    "descr {other:?} is a structured dtype; only \"{DESCR_F32}\" is supported"
                ));
            }
            ("fortran_order", Lit::Bool(b)) => fortran_order = Some(b),
            ("shape", Lit::Seq(dims)) => {
                let dims = dims
                    .into_iter()
                    .map(|d| match d {
                        Lit::Int(n) => Ok(n),
                        other => Err(format!("shape entry {other:?} is not a whole number")),
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                shape = Some(dims);
            }
            ("fortran_order" | "shape", other) => {
                return Err(format!("{key} has the unexpected value {other:?}"));
            }
            _ => {}
        }
    }
    Ok(Header {
        descr: descr.ok_or("no 'descr' key")?,
        fortran_order: fortran_order.ok_or("no 'fortran_order' key")?,
        shape: shape.ok_or("no 'shape' key")?,
    })
}

/// A recursive-descent parser over the header bytes.
struct Parser<'a> {
    s: &'a [u8],
    i: usize,
}

impl Parser<'_> {
    /// Nesting beyond this is refused, so a hostile header cannot overflow the stack.
    const MAX_DEPTH: usize = 8;

    fn ws(&mut self) {
        while self.s.get(self.i).is_some_and(u8::is_ascii_whitespace) {
            self.i += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.ws();
        self.s.get(self.i).copied()
    }

    fn expect(&mut self, b: u8) -> Result<(), String> {
        if self.peek() == Some(b) {
            self.i += 1;
            Ok(())
        } else {
            Err(format!("expected '{}' at byte {}", b as char, self.i))
        }
    }

    fn value(&mut self, depth: usize) -> Result<Lit, String> {
        if depth > Self::MAX_DEPTH {
            return Err("nested too deeply".to_owned());
        }
        match self.peek() {
            Some(b'{') => {
                self.i += 1;
                let mut entries = Vec::new();
                while self.peek() != Some(b'}') {
                    let key = self.value(depth + 1)?;
                    self.expect(b':')?;
                    let value = self.value(depth + 1)?;
                    entries.push((key, value));
                    if self.peek() == Some(b',') {
                        self.i += 1;
                    } else {
                        break;
                    }
                }
                self.expect(b'}')?;
                Ok(Lit::Dict(entries))
            }
            Some(open @ (b'(' | b'[')) => {
                let close = if open == b'(' { b')' } else { b']' };
                self.i += 1;
                let mut items = Vec::new();
                while self.peek() != Some(close) {
                    items.push(self.value(depth + 1)?);
                    if self.peek() == Some(b',') {
                        self.i += 1;
                    } else {
                        break;
                    }
                }
                self.expect(close)?;
                Ok(Lit::Seq(items))
            }
            Some(quote @ (b'\'' | b'"')) => {
                self.i += 1;
                let start = self.i;
                while self.s.get(self.i).is_some_and(|&b| b != quote) {
                    // NPY headers hold no escapes; refusing them keeps the parser honest.
                    if self.s[self.i] == b'\\' {
                        return Err(format!("escape in a string at byte {}", self.i));
                    }
                    self.i += 1;
                }
                let text = String::from_utf8_lossy(&self.s[start..self.i]).into_owned();
                self.expect(quote)?;
                Ok(Lit::Str(text))
            }
            Some(b'0'..=b'9') => {
                let start = self.i;
                while self.s.get(self.i).is_some_and(u8::is_ascii_digit) {
                    self.i += 1;
                }
                // Python 2 era files may write `50L`.
                if self.s.get(self.i) == Some(&b'L') {
                    self.i += 1;
                }
                let digits = String::from_utf8_lossy(&self.s[start..self.i]);
                digits
                    .trim_end_matches('L')
                    .parse()
                    .map(Lit::Int)
                    .map_err(|_| format!("number {digits} at byte {start} is too large"))
            }
            Some(_) => {
                for (word, lit) in [
                    ("True", Lit::Bool(true)),
                    ("False", Lit::Bool(false)),
                    ("None", Lit::None),
                ] {
                    if self.s[self.i..].starts_with(word.as_bytes()) {
                        self.i += word.len();
                        return Ok(lit);
                    }
                }
                Err(format!("unexpected character at byte {}", self.i))
            }
            None => Err("the header ends early".to_owned()),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::io::Write;

    /// Writes an NPY v1 file from raw parts; `values` are written in the given order as is.
    pub(crate) fn write_npy(path: &Path, header: &str, values: &[f32]) {
        write_npy_version(path, 1, header, values);
    }

    pub(crate) fn write_npy_version(path: &Path, major: u8, header: &str, values: &[f32]) {
        let mut bytes = MAGIC.to_vec();
        bytes.extend([major, 0]);
        let len_bytes = if major == 1 { 2 } else { 4 };
        // Pad with spaces and a newline to a multiple of 64, as NumPy does.
        let mut header = header.to_owned();
        while !(8 + len_bytes + header.len() + 1).is_multiple_of(64) {
            header.push(' ');
        }
        header.push('\n');
        if major == 1 {
            bytes.extend(
                u16::try_from(header.len())
                    .expect("short header")
                    .to_le_bytes(),
            );
        } else {
            bytes.extend(
                u32::try_from(header.len())
                    .expect("short header")
                    .to_le_bytes(),
            );
        }
        bytes.extend(header.as_bytes());
        for v in values {
            bytes.extend(v.to_le_bytes());
        }
        File::create(path)
            .and_then(|mut f| f.write_all(&bytes))
            .expect("write npy");
    }

    /// The 3×2 matrix [[1, 2], [3, 4], [5, 6]] in both orders.
    const ROW_MAJOR: [f32; 6] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
    const COL_MAJOR: [f32; 6] = [1.0, 3.0, 5.0, 2.0, 4.0, 6.0];

    #[test]
    fn c_and_fortran_order_give_the_same_matrix() {
        let dir = tempfile::tempdir().expect("tempdir");
        let c = dir.path().join("c.npy");
        let f = dir.path().join("f.npy");
        let f3 = dir.path().join("f3.npy");
        write_npy(
            &c,
            "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 2), }",
            &ROW_MAJOR,
        );
        write_npy(
            &f,
            "{'descr': '<f4', 'fortran_order': True, 'shape': (3, 2), }",
            &COL_MAJOR,
        );
        write_npy_version(
            &f3,
            3,
            "{\"descr\": \"<f4\", \"shape\": (3,2), \"fortran_order\": True}",
            &COL_MAJOR,
        );
        let want = Matrix {
            rows: 3,
            cols: 2,
            data: ROW_MAJOR.to_vec(),
        };
        assert_eq!(read_npy(&c).expect("C order"), want);
        assert_eq!(read_npy(&f).expect("Fortran order"), want);
        assert_eq!(read_npy(&f3).expect("version 3"), want);
    }

    /// Fortran order across chunk boundaries: a matrix larger than one chunk, with values that
    /// encode their own row and column.
    #[test]
    fn fortran_order_across_chunks() {
        let (rows, cols) = (CHUNK_VALUES / 3 + 7, 5);
        let value = |r: usize, c: usize| (r * 10 + c) as f32;
        let mut col_major = Vec::with_capacity(rows * cols);
        for c in 0..cols {
            for r in 0..rows {
                col_major.push(value(r, c));
            }
        }
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("big.npy");
        let header =
            format!("{{'descr': '<f4', 'fortran_order': True, 'shape': ({rows}, {cols}), }}");
        write_npy(&path, &header, &col_major);
        let m = read_npy(&path).expect("read");
        assert_eq!((m.rows, m.cols), (rows, cols));
        for r in [0, 1, rows / 2, rows - 1] {
            for c in 0..cols {
                assert_eq!(m.data[r * cols + c], value(r, c), "row {r} col {c}");
            }
        }
    }

    fn error_of(header: &str, values: &[f32], edit: impl FnOnce(&mut Vec<u8>)) -> String {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("m.npy");
        write_npy(&path, header, values);
        let mut bytes = std::fs::read(&path).expect("read back");
        edit(&mut bytes);
        std::fs::write(&path, &bytes).expect("rewrite");
        let err = read_npy(&path).expect_err("must fail").to_string();
        assert!(err.contains("m.npy"), "error names the file: {err}");
        err
    }

    const GOOD: &str = "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 2), }";

    #[test]
    fn truncated_file_says_expected_and_actual_bytes() {
        let err = error_of(GOOD, &ROW_MAJOR, |b| b.truncate(b.len() - 5));
        assert!(err.contains("should be 152 bytes"), "{err}");
        assert!(err.contains("it is 147 bytes"), "{err}");
        let err = error_of(GOOD, &ROW_MAJOR, |b| b.push(0));
        assert!(err.contains("it is 153 bytes"), "{err}");
    }

    #[test]
    fn wrong_dtype_is_refused() {
        let header = "{'descr': '<f8', 'fortran_order': False, 'shape': (3, 1), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("dtype \"<f8\" is not supported"), "{err}");
        let header = "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (6,), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("structured dtype"), "{err}");
    }

    #[test]
    fn wrong_shape_is_refused() {
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (6,), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("expected a 2-D matrix"), "{err}");
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 3), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("expected a 2-D matrix"), "{err}");
    }

    #[test]
    fn bad_magic_version_and_header_are_refused() {
        let err = error_of(GOOD, &ROW_MAJOR, |b| b[1] = b'X');
        assert!(err.contains("not an NPY file"), "{err}");
        let err = error_of(GOOD, &ROW_MAJOR, |b| b[6] = 9);
        assert!(err.contains("version 9.0 is not supported"), "{err}");
        let err = error_of(GOOD, &ROW_MAJOR, |b| b.truncate(4));
        assert!(err.contains("ends before the magic"), "{err}");
        let header = "{'descr': '<f4', 'shape': (3, 2), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("no 'fortran_order' key"), "{err}");
        let header = "{'descr': '<f4', 'fortran_order': Maybe, 'shape': (3, 2), }";
        let err = error_of(header, &ROW_MAJOR, |_| {});
        assert!(err.contains("unexpected character"), "{err}");
    }
}
