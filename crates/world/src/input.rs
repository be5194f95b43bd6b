//! Reading input files, one way for every kind of file ferret is given (houses, scenes, maps,
//! priors, configs, templates, a previous run's outputs).
//!
//! Only regular files are read: a FIFO would block forever and a device (`/dev/zero`, a symlink
//! to it named `z.json`) never ends, so both are refused before a byte is read, naming the path.
//! A regular file is read up to a limit and refused past it, so a wrong path cannot exhaust
//! memory. Text formats that nest (YAML, JSON) are refused past [`MAX_NESTING`] levels of
//! brackets before they reach a parser, because libyaml takes time quadratic in flow nesting,
//! and YAML is refused past [`MAX_YAML_NODES`] values once its aliases are expanded, because an
//! alias repeats everything its anchor holds (a 110 KB file can stand for millions of values).

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;

/// Largest input file read whole, bytes (64 MiB; ProcTHOR's largest house is under 1 MiB, an
/// asset database about 20 MiB).
pub const MAX_INPUT_BYTES: u64 = 64 << 20;

/// Deepest bracket nesting (`[` and `{`) accepted in YAML or JSON text. Scene files nest five
/// deep; serde_json stops at 128 on its own, libyaml has no limit.
pub const MAX_NESTING: usize = 64;

/// Most values (scalars, lists, maps) a YAML text may hold once its aliases are expanded. A
/// scene file with 2 000 containers holding 50 objects each has about 150 000.
pub const MAX_YAML_NODES: usize = 1_000_000;

/// Checks YAML text before it is deserialized: bracket nesting ([`check_nesting`] with
/// [`MAX_NESTING`]) and values after alias expansion ([`check_yaml_nodes`] with
/// [`MAX_YAML_NODES`]).
///
/// # Errors
/// A message saying which limit was passed.
pub fn check_yaml(text: &str) -> Result<(), String> {
    check_nesting(text, MAX_NESTING)?;
    check_yaml_nodes(text, MAX_YAML_NODES)
}

/// Counts the values of YAML text as a deserializer sees them, every alias expanded to what its
/// anchor holds, and refuses the text past `max`. Nothing is kept while counting, and counting
/// stops at the limit, so memory stays constant and time bounded by `max` whatever the aliases
/// multiply. Text that is not valid YAML passes: the real parse reports it with its field.
///
/// # Errors
/// A message naming the limit.
pub fn check_yaml_nodes(text: &str, max: usize) -> Result<(), String> {
    use serde::de::DeserializeSeed;
    let counter = NodeCounter {
        seen: std::cell::Cell::new(0),
        max,
    };
    for document in serde_yaml_ng::Deserializer::from_str(text) {
        let counted = (&counter).deserialize(document);
        if counter.seen.get() > max {
            return Err(format!(
                "more than {max} values once YAML aliases (`*name`) are expanded; write the values out or use fewer aliases"
            ));
        }
        // Other errors are left to the real parse, which names the field. The iterator keeps
        // yielding the same error after a syntax error, so counting stops at the first.
        if counted.is_err() {
            break;
        }
    }
    Ok(())
}

/// Counts every value it is given and stops the deserializer past `max`.
struct NodeCounter {
    seen: std::cell::Cell<usize>,
    max: usize,
}

impl NodeCounter {
    fn count<E: serde::de::Error>(&self) -> Result<(), E> {
        self.seen.set(self.seen.get().saturating_add(1));
        if self.seen.get() > self.max {
            return Err(E::custom("too many values"));
        }
        Ok(())
    }
}

impl<'de> serde::de::DeserializeSeed<'de> for &NodeCounter {
    type Value = ();

    fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> serde::de::Visitor<'de> for &NodeCounter {
    type Value = ();

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("any YAML value")
    }

    fn visit_bool<E: serde::de::Error>(self, _: bool) -> Result<(), E> {
        self.count()
    }
    fn visit_i64<E: serde::de::Error>(self, _: i64) -> Result<(), E> {
        self.count()
    }
    fn visit_i128<E: serde::de::Error>(self, _: i128) -> Result<(), E> {
        self.count()
    }
    fn visit_u64<E: serde::de::Error>(self, _: u64) -> Result<(), E> {
        self.count()
    }
    fn visit_u128<E: serde::de::Error>(self, _: u128) -> Result<(), E> {
        self.count()
    }
    fn visit_f64<E: serde::de::Error>(self, _: f64) -> Result<(), E> {
        self.count()
    }
    fn visit_str<E: serde::de::Error>(self, _: &str) -> Result<(), E> {
        self.count()
    }
    fn visit_bytes<E: serde::de::Error>(self, _: &[u8]) -> Result<(), E> {
        self.count()
    }
    fn visit_unit<E: serde::de::Error>(self) -> Result<(), E> {
        self.count()
    }
    fn visit_none<E: serde::de::Error>(self) -> Result<(), E> {
        self.count()
    }
    fn visit_some<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        serde::de::DeserializeSeed::deserialize(self, d)
    }
    fn visit_newtype_struct<D: serde::Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        serde::de::DeserializeSeed::deserialize(self, d)
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        self.count()?;
        while seq.next_element_seed(self)?.is_some() {}
        Ok(())
    }
    fn visit_map<A: serde::de::MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        self.count()?;
        while map.next_key_seed(self)?.is_some() {
            map.next_value_seed(self)?;
        }
        Ok(())
    }
    fn visit_enum<A: serde::de::EnumAccess<'de>>(self, data: A) -> Result<(), A::Error> {
        use serde::de::VariantAccess;
        self.count()?;
        let ((), variant) = data.variant_seed(self)?;
        variant.newtype_variant_seed(self)
    }
}

/// Opens `path` for reading if it is a regular file (symlinks followed); anything else is an
/// [`io::ErrorKind::InvalidInput`] error.
///
/// # Errors
/// The file cannot be opened, or is a FIFO, socket, device or directory.
pub fn open_file(path: &Path) -> io::Result<File> {
    let file = open_nonblocking(path)?;
    let kind = file.metadata()?.file_type();
    if !kind.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "not a regular file ({}); ferret reads only regular files",
                describe(&kind)
            ),
        ));
    }
    restore_blocking(&file)?;
    Ok(file)
}

/// The whole of `path`, at most `limit` bytes (see [`open_file`]).
///
/// # Errors
/// Those of [`open_file`], read errors, and [`io::ErrorKind::InvalidData`] for a file larger than
/// `limit`.
pub fn read_file(path: &Path, limit: u64) -> io::Result<Vec<u8>> {
    let file = open_file(path)?;
    let mut bytes = Vec::new();
    file.take(limit.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(limit));
    }
    Ok(bytes)
}

/// The whole of `path` as UTF-8 text, at most `limit` bytes (see [`read_file`]).
///
/// # Errors
/// Those of [`read_file`], and [`io::ErrorKind::InvalidData`] for text that is not UTF-8.
pub fn read_text(path: &Path, limit: u64) -> io::Result<String> {
    String::from_utf8(read_file(path, limit)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// The error for a file or stream over `limit` bytes.
pub fn too_large(limit: u64) -> io::Error {
    let size = if limit >= 1 << 20 {
        format!("{} MiB", limit >> 20)
    } else {
        format!("{limit} bytes")
    };
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!("larger than the limit of {size}"),
    )
}

/// Refuses YAML or JSON text whose brackets nest deeper than `max` (outside quoted strings and
/// comments). Counting can only overestimate the real depth, never miss it.
///
/// # Errors
/// A message with the line where the limit was passed.
pub fn check_nesting(text: &str, max: usize) -> Result<(), String> {
    let mut depth = 0usize;
    let mut line = 1usize;
    let mut quote: Option<u8> = None;
    let mut comment = false;
    let mut prev = b'\n';
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        if b == b'\n' {
            line += 1;
            comment = false;
        }
        match quote {
            _ if comment => {}
            Some(b'"') if b == b'\\' => i += 1,
            // YAML doubles a single quote inside a single-quoted string.
            Some(b'\'') if b == b'\'' && bytes.get(i + 1) == Some(&b'\'') => i += 1,
            Some(q) if b == q => quote = None,
            Some(_) => {}
            None => match b {
                b'"' | b'\'' => quote = Some(b),
                b'#' if prev.is_ascii_whitespace() => comment = true,
                b'[' | b'{' => {
                    depth += 1;
                    if depth > max {
                        return Err(format!("line {line}: brackets nest more than {max} deep"));
                    }
                }
                b']' | b'}' => depth = depth.saturating_sub(1),
                _ => {}
            },
        }
        prev = b;
        i += 1;
    }
    Ok(())
}

/// A serde error message with every value it quotes from the input blanked out (`"…"`), for
/// files the user did not name themselves: serde repeats what it found (`invalid type: string
/// "OPENAI_API_KEY=sk-…"`), which for a mistaken path can be a secret. What was expected is kept.
pub fn without_values(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut chars = message.chars().peekable();
    // serde quotes found strings with Debug (`"..."`, escapes inside) and other found values,
    // unknown fields and variants with backticks, right after these words.
    let backticked = [
        "integer ",
        "point ",
        "character ",
        "boolean ",
        "field ",
        "variant ",
    ];
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                while let Some(d) = chars.next() {
                    match d {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
                out.push_str("\"…\"");
            }
            '`' if backticked.iter().any(|w| out.ends_with(w))
                && !out.ends_with("missing field ") =>
            {
                for d in chars.by_ref() {
                    if d == '`' {
                        break;
                    }
                }
                out.push_str("`…`");
            }
            _ => out.push(c),
        }
    }
    out
}

fn describe(kind: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_fifo() {
            return "a FIFO";
        }
        if kind.is_char_device() || kind.is_block_device() {
            return "a device";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    if kind.is_dir() {
        "a directory"
    } else {
        "not a plain file"
    }
}

/// Opening a FIFO for reading blocks until a writer appears; non-blocking, it returns at once and
/// the type check refuses it.
#[cfg(unix)]
fn open_nonblocking(path: &Path) -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
}

#[cfg(not(unix))]
fn open_nonblocking(path: &Path) -> io::Result<File> {
    File::open(path)
}

#[cfg(unix)]
fn restore_blocking(file: &File) -> io::Result<()> {
    use std::os::fd::AsRawFd;
    let fd = file.as_raw_fd();
    // SAFETY: fcntl on a descriptor this function's caller owns, with no pointers involved.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    if flags < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: as above.
    if unsafe { libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

#[cfg(not(unix))]
fn restore_blocking(_: &File) -> io::Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nesting_counts_brackets_outside_strings_and_comments() {
        assert!(check_nesting("a: [[1, 2], {b: [3]}]", 3).is_ok());
        assert!(check_nesting("a: [[[1]]]", 2).is_err());
        assert!(check_nesting("a: '[[[[' # [[[[\nb: \"[[[\\\"[[\"", 1).is_ok());
        assert!(check_nesting("a: 'it''s [[[['", 1).is_ok());
        let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
        let e = check_nesting(&deep, MAX_NESTING).unwrap_err();
        assert!(e.contains("64"), "{e}");
    }

    #[test]
    fn yaml_values_are_counted_with_aliases_expanded() {
        // The map, its key, the list and its three items.
        assert!(check_yaml_nodes("a: [1, 2, 3]", 6).is_ok());
        assert!(check_yaml_nodes("a: [1, 2, 3]", 5).is_err());
        let aliased = "a: &x [1, 2, 3, 4]\nb: *x\nc: *x\n";
        // The map, three keys, three lists of four.
        assert!(check_yaml_nodes(aliased, 19).is_ok());
        let e = check_yaml_nodes(aliased, 18).unwrap_err();
        assert!(e.contains("aliases"), "{e}");
        // Not YAML at all: left to the parser.
        assert!(check_yaml_nodes("a: [1, 2", 100).is_ok());
    }

    #[test]
    fn values_are_blanked_and_expectations_kept() {
        assert_eq!(
            without_values(r#"invalid type: string "KEY=sk-\"x", expected struct RosMapYaml"#),
            r#"invalid type: string "…", expected struct RosMapYaml"#
        );
        assert_eq!(
            without_values("unknown field `sk-live`, expected one of `image`, `origin`"),
            "unknown field `…`, expected one of `image`, `origin`"
        );
        assert_eq!(
            without_values("invalid type: integer `123456`, expected f64"),
            "invalid type: integer `…`, expected f64"
        );
        assert_eq!(
            without_values("missing field `image`"),
            "missing field `image`"
        );
    }

    #[test]
    fn a_file_over_the_limit_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.json");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_file(&p, 10).unwrap().len(), 10);
        let e = read_file(&p, 9).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(e.to_string().contains("9 bytes"), "{e}");
    }

    #[test]
    fn a_directory_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_file(dir.path(), 10).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
    }
}
