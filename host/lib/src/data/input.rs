//! Where a command's input comes from, and how its messages name it: a file, or `-` for
//! standard input, wherever a command reads a capture, a data file or a model file.
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
/// else the path.
pub fn input_name(path: &Path) -> String {
    if is_stdin(path) {
        STDIN_NAME.to_string()
    } else {
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
}
