//! Where a command's input comes from, and how its messages name it: a file, or `-` for
//! standard input, wherever a command reads a capture, a data file or a model file.
//!
//! A path is named losslessly ([`path_text`]): a file name on Unix is bytes, not always
//! UTF-8 text (a Latin-1 `messé.csv`), and `--json`'s `file` gave such a name with U+FFFD
//! in place of each byte, which names no file. The text keeps every byte: one that is not
//! printable UTF-8 is written `\xHH`, and a backslash `\\`, so the name can be turned
//! back into its bytes; a printable UTF-8 name without a backslash, nearly every name,
//! reads as itself.
//!
//! Standard input is read whole, once per process: its bytes are kept, so that every
//! input given as `-` reads the same bytes (`fit - --validation -` takes the same data
//! twice, as a file named twice would be; a second read of the stream would find it at
//! its end). A file is read whole on each call.

use std::io::{self, Read};
use std::path::Path;
use std::sync::{Arc, Mutex};

/// The path that names standard input.
pub const STDIN: &str = "-";

/// How messages and `--json` documents name standard input.
pub const STDIN_NAME: &str = "standard input";

/// Whether `path` is `-`, standard input.
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == STDIN
}

/// How messages and `--json` documents name the input `path`: [`STDIN_NAME`] for `-`,
/// else [`path_text`].
pub fn input_name(path: &Path) -> String {
    if is_stdin(path) {
        STDIN_NAME.to_string()
    } else {
        path_text(path)
    }
}

/// The bytes of a name [`path_text`] wrote: `\\` a backslash, `\xHH` a byte, anything else
/// itself (for a caller that reads a name back from `--json`); `None` when an escape is
/// cut short or not hexadecimal.
pub fn path_bytes(text: &str) -> Option<Vec<u8>> {
    let (mut out, b) = (Vec::new(), text.as_bytes());
    let mut i = 0;
    while i < b.len() {
        match (b[i], b.get(i + 1)) {
            (b'\\', Some(b'\\')) => {
                out.push(b'\\');
                i += 2;
            }
            (b'\\', Some(b'x')) => {
                out.push(u8::from_str_radix(text.get(i + 2..i + 4)?, 16).ok()?);
                i += 4;
            }
            (c, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    Some(out)
}

/// `path` as text, losslessly: as given, with a backslash written `\\` and each byte that
/// is not printable UTF-8 text (not UTF-8, or a control character such as a newline)
/// written `\xHH`, so that the name's bytes can be recovered and a message stays on one
/// line. On systems whose names are not bytes (Windows) it is [`Path::display`].
pub fn path_text(path: &Path) -> String {
    #[cfg(unix)]
    {
        use std::fmt::Write as _;
        use std::os::unix::ffi::OsStrExt;
        let mut out = String::new();
        let mut rest = path.as_os_str().as_bytes();
        while !rest.is_empty() {
            let (valid, bad) = match std::str::from_utf8(rest) {
                Ok(s) => (s, 0),
                Err(e) => (
                    // valid up to there by the error's own account
                    std::str::from_utf8(&rest[..e.valid_up_to()]).unwrap_or_default(),
                    e.error_len().unwrap_or(rest.len() - e.valid_up_to()),
                ),
            };
            for c in valid.chars() {
                match c {
                    '\\' => out.push_str("\\\\"),
                    c if c.is_control() && (c as u32) < 0x80 => {
                        let _ = write!(out, "\\x{:02X}", c as u32);
                    }
                    c => out.push(c),
                }
            }
            let bytes = &rest[valid.len()..valid.len() + bad];
            for b in bytes {
                let _ = write!(out, "\\x{b:02X}");
            }
            rest = &rest[valid.len() + bad..];
        }
        out
    }
    #[cfg(not(unix))]
    {
        path.display().to_string()
    }
}

/// Standard input's bytes once read ([`read_input`]).
static STDIN_BYTES: Mutex<Option<Arc<Vec<u8>>>> = Mutex::new(None);

/// The whole content of the input `path`: standard input to its end for `-` (read on
/// the first call, the same bytes on every later one), else the file.
///
/// # Errors
/// What the operating system says when the file or standard input cannot be read.
pub fn read_input(path: &Path) -> io::Result<Vec<u8>> {
    if !is_stdin(path) {
        return std::fs::read(path);
    }
    let mut kept = STDIN_BYTES.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(bytes) = kept.as_ref() {
        return Ok(bytes.to_vec());
    }
    let mut bytes = Vec::new();
    io::stdin().lock().read_to_end(&mut bytes)?;
    let bytes = Arc::new(bytes);
    *kept = Some(Arc::clone(&bytes));
    Ok(bytes.to_vec())
}

/// [`read_input`] as UTF-8 text (a model file, a JSON configuration).
///
/// # Errors
/// As [`read_input`]; [`io::ErrorKind::InvalidData`] when the content is not UTF-8.
pub fn read_input_text(path: &Path) -> io::Result<String> {
    String::from_utf8(read_input(path)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("not UTF-8 text (byte {})", e.utf8_error().valid_up_to()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_read_whole_and_named_by_its_path_standard_input_by_its_name() {
        let p = std::env::temp_dir().join(format!("jointid-input-{}.txt", std::process::id()));
        std::fs::write(&p, "héllo").unwrap();
        assert_eq!(read_input(&p).unwrap(), "héllo".as_bytes());
        assert_eq!(read_input_text(&p).unwrap(), "héllo");
        assert_eq!(input_name(&p), p.display().to_string());
        std::fs::write(&p, [0x68, 0xe9]).unwrap();
        let e = read_input_text(&p).unwrap_err();
        assert_eq!(e.to_string(), "not UTF-8 text (byte 1)");
        std::fs::remove_file(&p).unwrap();
        assert!(is_stdin(Path::new("-")) && !is_stdin(Path::new("./-")));
        assert_eq!(input_name(Path::new("-")), "standard input");
    }

    #[cfg(unix)]
    #[test]
    fn a_name_is_given_as_itself_or_escaped_so_that_its_bytes_come_back() {
        use std::ffi::OsStr;
        use std::os::unix::ffi::OsStrExt;
        let text = |b: &[u8]| path_text(Path::new(OsStr::from_bytes(b)));
        assert_eq!(text(b"data/run 1.csv"), "data/run 1.csv");
        assert_eq!(text("données/µ.csv".as_bytes()), "données/µ.csv");
        // Latin-1 `messé.csv`: before, `mess\u{fffd}.csv`
        assert_eq!(text(b"mess\xe9.csv"), "mess\\xE9.csv");
        // a literal backslash is doubled, so it cannot be read as an escape
        assert_eq!(text(b"a\\xE9.csv"), "a\\\\xE9.csv");
        assert_eq!(text(b"two\nlines\x7f"), "two\\x0Alines\\x7F");
        // a cut sequence at the end, and invalid bytes in a row
        assert_eq!(text(b"x\xc3"), "x\\xC3");
        assert_eq!(text(b"\xff\xfe\xc3\xa9"), "\\xFF\\xFEé");
        // the bytes come back: the inverse of the escapes
        let back = |s: &str| path_bytes(s).expect("an escaped name");
        for name in [
            &b"mess\xe9.csv"[..],
            b"a\\xE9.csv",
            b"two\nlines\x7f",
            b"\xff\xfe\xc3\xa9",
            "données".as_bytes(),
        ] {
            assert_eq!(back(&text(name)), name, "{}", text(name));
        }
    }
}
