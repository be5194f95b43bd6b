//! The word index of an embeddings package: a parquet file with one string column (`index`) whose
//! row i is the word of row i of the matrix.

use std::path::Path;

use parquet::basic::Type as PhysicalType;
use parquet::column::reader::ColumnReader;
use parquet::data_type::ByteArray;
use parquet::file::reader::{FileReader, SerializedFileReader};

use crate::EmbedError;

/// The column that holds the words (pandas writes a `Series` index under this name).
const WORD_COLUMN: &str = "index";

/// The most words reserved up front (GloVe 6B has 400 000; larger vocabularies still load, by
/// growing).
const MAX_RESERVE: usize = 1 << 22;

/// Records decoded per call; the words of a row group are read in a few dozen calls.
const BATCH: usize = 8192;

/// Reads the words of a parquet word index, in row order.
///
/// The words are the column named `index`, or the only column when there is just one. It must
/// be a flat (non-repeated) byte-array column of UTF-8 strings without nulls: a null or
/// non-UTF-8 word is an error naming its row.
pub(crate) fn read_words(path: &Path) -> Result<Vec<String>, EmbedError> {
    let pq = |source| EmbedError::Parquet {
        path: path.to_owned(),
        source,
    };
    let bad = |what: String| EmbedError::Index {
        path: path.to_owned(),
        what,
    };
    let file = crate::file::open(path)?;
    let reader = SerializedFileReader::new(file).map_err(pq)?;
    let meta = reader.metadata();
    let schema = meta.file_metadata().schema_descr();
    let columns = schema.columns();
    let column = match columns.iter().position(|c| c.name() == WORD_COLUMN) {
        Some(i) => i,
        None if columns.len() == 1 => 0,
        None => {
            let names: Vec<&str> = columns.iter().map(|c| c.name()).collect();
            return Err(bad(format!(
                "no column {WORD_COLUMN:?} among {names:?} to take the words from"
            )));
        }
    };
    let descr = &columns[column];
    if descr.physical_type() != PhysicalType::BYTE_ARRAY || descr.max_rep_level() != 0 {
        return Err(bad(format!(
            "column {:?} is not a column of strings (physical type {}, repetition level {})",
            descr.name(),
            descr.physical_type(),
            descr.max_rep_level()
        )));
    }
    let max_def = descr.max_def_level();
    let total = usize::try_from(meta.file_metadata().num_rows()).unwrap_or(0);
    tracing::debug!(file = %path.display(), rows = total, "reading word index");

    // The row count only sizes the allocation; capped so a corrupt footer cannot ask for more
    // memory than a real vocabulary needs.
    let mut words = Vec::with_capacity(total.min(MAX_RESERVE));
    let mut values: Vec<ByteArray> = Vec::with_capacity(BATCH);
    let mut defs: Vec<i16> = Vec::with_capacity(BATCH);
    for group in 0..meta.num_row_groups() {
        let group_reader = reader.get_row_group(group).map_err(pq)?;
        let ColumnReader::ByteArrayColumnReader(mut column_reader) =
            group_reader.get_column_reader(column).map_err(pq)?
        else {
            // The physical type was checked above; the reader follows it.
            return Err(bad("the word column is not a byte-array column".to_owned()));
        };
        loop {
            values.clear();
            defs.clear();
            let (records, read, _levels) = column_reader
                .read_records(BATCH, (max_def > 0).then_some(&mut defs), None, &mut values)
                .map_err(pq)?;
            if records == 0 {
                break;
            }
            // Only non-null values are returned: fewer values than records means a null word.
            if read != records {
                let first_null = defs.iter().position(|&d| d < max_def).unwrap_or(0);
                return Err(bad(format!(
                    "row {} holds no word (null)",
                    words.len() + first_null
                )));
            }
            for value in &values {
                let word = std::str::from_utf8(value.data())
                    .map_err(|_| bad(format!("row {} is not UTF-8 text", words.len())))?;
                words.push(word.to_owned());
            }
        }
    }
    Ok(words)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use std::sync::Arc;

    use parquet::data_type::ByteArrayType;
    use parquet::file::properties::WriterProperties;
    use parquet::file::writer::SerializedFileWriter;
    use parquet::schema::parser::parse_message_type;

    /// Writes a parquet file with one optional string column `name`; `None` writes a null.
    pub(crate) fn write_index(path: &Path, name: &str, words: &[Option<&str>]) {
        let schema = parse_message_type(&format!(
            "message schema {{ optional binary {name} (STRING); }}"
        ))
        .expect("schema");
        let props = Arc::new(
            WriterProperties::builder()
                .set_compression(parquet::basic::Compression::SNAPPY)
                .build(),
        );
        let file = std::fs::File::create(path).expect("create");
        let mut writer = SerializedFileWriter::new(file, Arc::new(schema), props).expect("writer");
        let mut group = writer.next_row_group().expect("row group");
        let mut column = group.next_column().expect("column").expect("one column");
        let values: Vec<ByteArray> = words
            .iter()
            .flatten()
            .map(|w| ByteArray::from(*w))
            .collect();
        let defs: Vec<i16> = words.iter().map(|w| i16::from(w.is_some())).collect();
        column
            .typed::<ByteArrayType>()
            .write_batch(&values, Some(&defs), None)
            .expect("write");
        column.close().expect("close column");
        group.close().expect("close group");
        writer.close().expect("close file");
    }

    #[test]
    fn reads_words_in_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("w_index.parquet");
        write_index(&path, "index", &[Some("the"), Some(","), Some("fridge")]);
        assert_eq!(read_words(&path).expect("read"), ["the", ",", "fridge"]);
    }

    #[test]
    fn a_null_word_is_an_error_naming_its_row() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("w_index.parquet");
        write_index(&path, "index", &[Some("the"), None, Some("fridge")]);
        let err = read_words(&path).expect_err("null").to_string();
        assert!(err.contains("w_index.parquet"), "{err}");
        assert!(err.contains("row 1 holds no word"), "{err}");
    }

    #[test]
    fn not_parquet_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("w_index.parquet");
        std::fs::write(&path, b"not a parquet file at all").expect("write");
        let err = read_words(&path).expect_err("garbage").to_string();
        assert!(err.contains("w_index.parquet"), "{err}");
    }
}
