//! MATLAB Level-5 MAT-files (the format of MATLAB's `save` up to `-v7`, and of scipy's
//! `savemat`): read real numeric vectors as signals, write matrices, text and scalar
//! structs.
//!
//! Reader: the 128-byte header (text, version `0x0100`, endian indicator `IM`/`MI`), data
//! elements with little- or big-endian tags and the small-element form, `miMATRIX` of the
//! numeric classes (double, single, signed and unsigned integers of 8–64 bits, stored in
//! any numeric data type), and `miCOMPRESSED` elements (zlib, what MATLAB's default
//! `save` writes). Cell, struct, object, sparse, char, logical and complex arrays are
//! listed by name but not taken as signals. Writer: uncompressed little-endian Level 5,
//! doubles only, which MATLAB's `load` and scipy's `loadmat` read.
//!
//! A signal is a vector: `1×N` or `N×1`. The [`ColumnMap`] names variables instead of
//! CSV columns; the positions in an error (`file:K:`) count samples from 1.
//!
//! Source: MathWorks, "MAT-File Format", version 7 (2019), ch. 1 "Level 5 MAT-File
//! Format": header (Fig. 1-1), data element tags and the small data element format
//! (Fig. 1-3, 1-4), the data types (Table 1-1), the array flags and classes (Table 1-3),
//! compressed elements (§ "Compressed data").

use std::collections::BTreeMap;
use std::fmt;

use super::{ColumnMap, DataError, Record};

/// Data types of a data element tag (MAT-File Format, Table 1-1).
mod mi {
    pub const INT8: u32 = 1;
    pub const UINT8: u32 = 2;
    pub const INT16: u32 = 3;
    pub const UINT16: u32 = 4;
    pub const INT32: u32 = 5;
    pub const UINT32: u32 = 6;
    pub const SINGLE: u32 = 7;
    pub const DOUBLE: u32 = 9;
    pub const INT64: u32 = 12;
    pub const UINT64: u32 = 13;
    pub const MATRIX: u32 = 14;
    pub const COMPRESSED: u32 = 15;
    pub const UTF8: u32 = 16;
}

/// Array classes of the array flags (MAT-File Format, Table 1-3).
mod mx {
    pub const CELL: u8 = 1;
    pub const STRUCT: u8 = 2;
    pub const OBJECT: u8 = 3;
    pub const CHAR: u8 = 4;
    pub const SPARSE: u8 = 5;
    pub const DOUBLE: u8 = 6;
    pub const UINT64: u8 = 15;
}

/// array-flag bits: complex, logical
const FLAG_COMPLEX: u32 = 0x0800;
const FLAG_LOGICAL: u32 = 0x0200;

/// Why a MAT-file cannot be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {reason}")]
pub struct MatError {
    /// file name
    pub file: String,
    /// what is wrong, at which byte or in which variable
    #[source]
    pub reason: MatReason,
}

/// What is wrong with a MAT-file, at which byte or in which variable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatReason {
    /// fewer bytes than the 128 of the header
    #[error("{0} bytes: a MAT-file header has 128")]
    ShortHeader(usize),
    /// the endian indicator at bytes 126–127 (as text) is neither `IM` nor `MI`
    #[error(
        "endian indicator {0:?} at byte 126 is neither `IM` nor `MI`: not a MATLAB Level-5 \
         MAT-file"
    )]
    Endian(String),
    /// the version at bytes 124–125 is not Level 5's
    #[error("version {0:#06x} at byte 124; a Level-5 MAT-file has 0x0100")]
    Version(u16),
    /// a data element that cannot be read, at byte `pos` of the file (`inflated`: in the
    /// content of the compressed element there)
    #[error("byte {pos}{}: {source}", if *.inflated { " (inflated)" } else { "" })]
    Element {
        /// offset of the top-level element [bytes]
        pos: usize,
        /// the fault lies in the element's inflated content
        inflated: bool,
        /// what is wrong with it
        #[source]
        source: ElementError,
    },
    /// a compressed element whose zlib stream does not inflate
    #[error("byte {pos}: compressed element does not inflate ({status:?})")]
    Inflate {
        /// offset of the element [bytes]
        pos: usize,
        /// the inflater's status
        status: miniz_oxide::inflate::TINFLStatus,
    },
    /// a variable asked for is missing or no signal
    #[error(transparent)]
    Variable(#[from] VectorError),
    /// a variable asked for is not as long as the time's
    #[error("variable `{name}` has {len} samples, `{time}` has {time_len}")]
    Length {
        /// the variable
        name: String,
        /// its samples
        len: usize,
        /// the time variable
        time: String,
        /// its samples
        time_len: usize,
    },
}

/// What is wrong with one data element of a MAT-file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ElementError {
    /// fewer bytes left than a tag takes
    #[error("{0} bytes left, a data element tag needs 8")]
    ShortTag(usize),
    /// a small data element claiming more than its 4 bytes
    #[error("small data element of {0} bytes (at most 4)")]
    SmallTooLong(usize),
    /// an element claiming more bytes than are left
    #[error("data element of type {ty} claims {claims} bytes, {left} are left")]
    Overrun {
        /// its data type (MAT-File Format, Table 1-1)
        ty: u32,
        /// bytes it claims
        claims: usize,
        /// bytes left
        left: usize,
    },
    /// numbers where the data type is none
    #[error("data type {0} is not numeric")]
    NotNumeric(u32),
    /// a variable's values of a data type that is not numeric
    #[error("variable `{name}`: data type {ty} is not numeric")]
    VariableNotNumeric {
        /// the variable
        name: String,
        /// the data type (MAT-File Format, Table 1-1)
        ty: u32,
    },
    /// an array's flags element shorter than 8 bytes
    #[error("array flags shorter than 8 bytes")]
    ShortFlags,
    /// a variable with another number of values than its dimensions give
    #[error("variable `{name}`: {values} values for dimensions {}", dims_text(.dims))]
    Count {
        /// the variable
        name: String,
        /// values stored
        values: usize,
        /// its dimensions
        dims: Vec<usize>,
    },
}

/// Why a variable of a MAT-file is no signal ([`MatFile::vector`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum VectorError {
    /// no variable of that name
    #[error("variable `{name}` not found; variables are: {names}")]
    NotFound {
        /// the name asked for
        name: String,
        /// the file's variables, comma separated
        names: String,
    },
    /// a numeric array that is no vector, or empty
    #[error(
        "variable `{name}` is {} {}; expected a real numeric vector (1×N or N×1)",
        dims_text(.dims),
        if .dims.iter().product::<usize>() == 0 { "(empty)" } else { "matrix" }
    )]
    NotVector {
        /// the variable
        name: String,
        /// its dimensions
        dims: Vec<usize>,
    },
    /// not a real numeric array (what it is instead: `char`, `struct`, `complex`, ...)
    #[error("variable `{name}` is {what}; expected a real numeric vector")]
    NotNumeric {
        /// the variable
        name: String,
        /// what it holds ([`MatValue::describe`])
        what: String,
    },
}

/// What a variable of a MAT-file holds.
#[derive(Clone, Debug, PartialEq)]
pub enum MatValue {
    /// a real numeric array, column-major, converted to `f64`
    Numeric {
        /// dimensions (two or more)
        dims: Vec<usize>,
        /// the values, column-major
        data: Vec<f64>,
    },
    /// a character array (its text when it is one row, else empty)
    Text(String),
    /// anything else: what it is (`complex double`, `cell`, `struct`, ...)
    Other(String),
}

impl MatValue {
    /// `rows×cols…` and the kind, for messages (`24841×1 double`).
    pub fn describe(&self) -> String {
        match self {
            MatValue::Numeric { dims, .. } => format!("{} numeric", dims_text(dims)),
            MatValue::Text(_) => "char".into(),
            MatValue::Other(w) => w.clone(),
        }
    }
}

fn dims_text(dims: &[usize]) -> String {
    dims.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join("×")
}

/// The variables of a MAT-file in file order.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct MatFile {
    /// the header text (first 116 bytes, trimmed)
    pub description: String,
    /// name and value of each variable
    pub vars: Vec<(String, MatValue)>,
}

impl MatFile {
    /// The variable `name`, if present.
    pub fn get(&self, name: &str) -> Option<&MatValue> {
        self.vars.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }

    /// The variables' names, comma separated.
    pub fn names(&self) -> String {
        self.vars
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The vector `name` (`1×N` or `N×1`, real numeric).
    ///
    /// # Errors
    /// [`VectorError`] naming the variable and what it is instead.
    pub fn vector(&self, name: &str) -> Result<&[f64], VectorError> {
        match self.get(name) {
            None => Err(VectorError::NotFound {
                name: name.to_string(),
                names: self.names(),
            }),
            Some(MatValue::Numeric { dims, data }) => {
                let long = dims.iter().filter(|&&d| d != 1).count();
                if long <= 1 && !data.is_empty() {
                    Ok(data)
                } else {
                    Err(VectorError::NotVector {
                        name: name.to_string(),
                        dims: dims.clone(),
                    })
                }
            }
            Some(v) => Err(VectorError::NotNumeric {
                name: name.to_string(),
                what: v.describe(),
            }),
        }
    }
}

/// Whether `bytes` open like a Level-5 MAT-file (text header, version and endian
/// indicator at bytes 124–127).
pub fn is_mat5(bytes: &[u8]) -> bool {
    bytes.len() >= 128
        && bytes.starts_with(b"MATLAB 5.0 MAT-file")
        && matches!(&bytes[126..128], b"IM" | b"MI")
}

/// Byte order of a file.
#[derive(Clone, Copy)]
struct Order {
    big: bool,
}

impl Order {
    fn u16(self, b: &[u8]) -> u16 {
        let a = [b[0], b[1]];
        if self.big {
            u16::from_be_bytes(a)
        } else {
            u16::from_le_bytes(a)
        }
    }
    fn u32(self, b: &[u8]) -> u32 {
        let a = [b[0], b[1], b[2], b[3]];
        if self.big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        }
    }
    fn u64(self, b: &[u8]) -> u64 {
        let a: [u8; 8] = b[..8].try_into().unwrap_or([0; 8]);
        if self.big {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        }
    }
}

/// One data element: its type and its bytes (padding removed).
struct Element<'a> {
    ty: u32,
    data: &'a [u8],
}

/// Reads the element at the start of `b`; returns it and the bytes it takes with padding.
fn element(b: &[u8], o: Order) -> Result<(Element<'_>, usize), ElementError> {
    if b.len() < 8 {
        return Err(ElementError::ShortTag(b.len()));
    }
    let first = o.u32(&b[0..4]);
    if first >> 16 != 0 {
        // small data element: the size in the upper 16 bits, the data in the next 4 bytes
        let n = (first >> 16) as usize;
        if n > 4 {
            return Err(ElementError::SmallTooLong(n));
        }
        return Ok((
            Element {
                ty: first & 0xffff,
                data: &b[4..4 + n],
            },
            8,
        ));
    }
    let n = o.u32(&b[4..8]) as usize;
    if n > b.len() - 8 {
        return Err(ElementError::Overrun {
            ty: first,
            claims: n,
            left: b.len() - 8,
        });
    }
    // compressed elements are not padded
    let padded = if first == mi::COMPRESSED {
        n
    } else {
        n.div_ceil(8) * 8
    };
    Ok((
        Element {
            ty: first,
            data: &b[8..8 + n],
        },
        8 + padded.min(b.len() - 8),
    ))
}

/// The numbers of a numeric data element as `f64`.
fn numbers(e: &Element<'_>, o: Order) -> Result<Vec<f64>, ElementError> {
    let d = e.data;
    let v: Vec<f64> = match e.ty {
        mi::INT8 => d.iter().map(|&x| f64::from(x as i8)).collect(),
        mi::UINT8 | mi::UTF8 => d.iter().map(|&x| f64::from(x)).collect(),
        mi::INT16 => d
            .chunks_exact(2)
            .map(|c| f64::from(o.u16(c) as i16))
            .collect(),
        mi::UINT16 => d.chunks_exact(2).map(|c| f64::from(o.u16(c))).collect(),
        mi::INT32 => d
            .chunks_exact(4)
            .map(|c| f64::from(o.u32(c) as i32))
            .collect(),
        mi::UINT32 => d.chunks_exact(4).map(|c| f64::from(o.u32(c))).collect(),
        mi::SINGLE => d
            .chunks_exact(4)
            .map(|c| f64::from(f32::from_bits(o.u32(c))))
            .collect(),
        mi::DOUBLE => d
            .chunks_exact(8)
            .map(|c| f64::from_bits(o.u64(c)))
            .collect(),
        mi::INT64 => d.chunks_exact(8).map(|c| o.u64(c) as i64 as f64).collect(),
        mi::UINT64 => d.chunks_exact(8).map(|c| o.u64(c) as f64).collect(),
        t => return Err(ElementError::NotNumeric(t)),
    };
    Ok(v)
}

/// Parses one `miMATRIX` element's content into a name and a value.
fn matrix(d: &[u8], o: Order) -> Result<(String, MatValue), ElementError> {
    let (flags, n1) = element(d, o)?;
    if flags.data.len() < 8 {
        return Err(ElementError::ShortFlags);
    }
    let f = o.u32(&flags.data[0..4]);
    let class = (f & 0xff) as u8;
    let (dims_e, n2) = element(&d[n1..], o)?;
    let dims: Vec<usize> = numbers(&dims_e, o)?
        .into_iter()
        .map(|x| x.max(0.0) as usize)
        .collect();
    let (name_e, n3) = element(&d[n1 + n2..], o)?;
    let name = String::from_utf8_lossy(name_e.data).into_owned();
    let rest = &d[n1 + n2 + n3..];
    let kind = match class {
        mx::CELL => "cell",
        mx::STRUCT => "struct",
        mx::OBJECT => "object",
        mx::SPARSE => "sparse",
        mx::CHAR => "char",
        mx::DOUBLE..=mx::UINT64 => "",
        _ => "of an unknown class",
    };
    if class == mx::CHAR {
        let text = if rest.is_empty() {
            String::new()
        } else {
            let (e, _) = element(rest, o)?;
            match e.ty {
                mi::UTF8 | mi::UINT8 | mi::INT8 => String::from_utf8_lossy(e.data).into_owned(),
                _ => numbers(&e, o)?
                    .into_iter()
                    .filter_map(|c| char::from_u32(c as u32))
                    .collect(),
            }
        };
        // one row only reads as text; a block of rows is column-major
        let rows = dims.first().copied().unwrap_or(1);
        return Ok((
            name,
            MatValue::Text(if rows == 1 { text } else { String::new() }),
        ));
    }
    if !kind.is_empty() {
        return Ok((name, MatValue::Other(kind.into())));
    }
    if f & FLAG_COMPLEX != 0 {
        return Ok((name, MatValue::Other("complex".into())));
    }
    if f & FLAG_LOGICAL != 0 {
        return Ok((name, MatValue::Other("logical".into())));
    }
    let count: usize = dims.iter().product();
    let data = if count == 0 {
        Vec::new()
    } else {
        let (re, _) = element(rest, o)?;
        numbers(&re, o).map_err(|e| match e {
            ElementError::NotNumeric(ty) => ElementError::VariableNotNumeric {
                name: name.clone(),
                ty,
            },
            e => e,
        })?
    };
    if data.len() != count {
        return Err(ElementError::Count {
            name,
            values: data.len(),
            dims,
        });
    }
    Ok((name, MatValue::Numeric { dims, data }))
}

/// Reads a Level-5 MAT-file; `file` names it in errors.
///
/// # Errors
/// [`MatError`] naming the byte offset and what was expected there.
pub fn read_mat(bytes: &[u8], file: &str) -> Result<MatFile, MatError> {
    let err = |reason: MatReason| MatError {
        file: file.to_string(),
        reason,
    };
    let at = |pos: usize, inflated: bool| {
        move |source: ElementError| {
            err(MatReason::Element {
                pos,
                inflated,
                source,
            })
        }
    };
    if bytes.len() < 128 {
        return Err(err(MatReason::ShortHeader(bytes.len())));
    }
    let o = match &bytes[126..128] {
        b"IM" => Order { big: false },
        b"MI" => Order { big: true },
        other => {
            return Err(err(MatReason::Endian(
                String::from_utf8_lossy(other).into_owned(),
            )))
        }
    };
    let version = o.u16(&bytes[124..126]);
    if version != 0x0100 {
        return Err(err(MatReason::Version(version)));
    }
    let description = String::from_utf8_lossy(&bytes[..116])
        .trim_end_matches([' ', '\0'])
        .to_string();
    let mut out = MatFile {
        description,
        vars: Vec::new(),
    };
    let mut pos = 128;
    while pos + 8 <= bytes.len() {
        let (e, used) = element(&bytes[pos..], o).map_err(at(pos, false))?;
        match e.ty {
            // an empty matrix element holds no variable
            mi::MATRIX if !e.data.is_empty() => {
                out.vars.push(matrix(e.data, o).map_err(at(pos, false))?);
            }
            mi::COMPRESSED => {
                let inner = miniz_oxide::inflate::decompress_to_vec_zlib(e.data).map_err(|x| {
                    err(MatReason::Inflate {
                        pos,
                        status: x.status,
                    })
                })?;
                let (ie, _) = element(&inner, o).map_err(at(pos, true))?;
                if ie.ty == mi::MATRIX && !ie.data.is_empty() {
                    out.vars.push(matrix(ie.data, o).map_err(at(pos, true))?);
                }
            }
            // other top-level elements carry no variable
            _ => {}
        }
        pos += used;
    }
    Ok(out)
}

/// Parses a MAT-file's variables into a record through `map` (variable names instead of
/// columns), checked like a CSV: increasing uniform time, gaps split into pieces.
///
/// # Errors
/// [`DataError::Loader`] wrapping a [`MatError`] when the file does not parse or a mapped
/// variable is missing or not a real vector of the time's length; otherwise as
/// [`super::csv::parse_csv_record`], positions counted in samples from 1.
pub fn parse_mat_record(bytes: &[u8], name: &str, map: &ColumnMap) -> Result<Record, DataError> {
    let wrap = |e: MatError| DataError::Loader {
        file: name.to_string(),
        source: Box::new(e),
    };
    let mat = read_mat(bytes, name).map_err(wrap)?;
    let mut wanted = vec![map.time.as_str(), map.input.as_str(), map.output.as_str()];
    if let Some(r) = &map.reference {
        wanted.push(r.as_str());
    }
    let mut columns = Vec::new();
    for v in &wanted {
        let x = mat.vector(v).map_err(|e| {
            wrap(MatError {
                file: name.to_string(),
                reason: e.into(),
            })
        })?;
        if let Some(first) = columns.first().map(Vec::len) {
            if x.len() != first {
                return Err(wrap(MatError {
                    file: name.to_string(),
                    reason: MatReason::Length {
                        name: v.to_string(),
                        len: x.len(),
                        time: map.time.clone(),
                        time_len: first,
                    },
                }));
            }
        }
        if let Some(k) = x.iter().position(|x| !x.is_finite()) {
            return Err(DataError::NotFinite {
                file: name.to_string(),
                line: k + 1,
                column: v.to_string(),
                cell: x[k].to_string(),
            });
        }
        columns.push(x.to_vec());
    }
    // the capture CSV's `# key=value` comments, when the file carries them
    let mut meta = BTreeMap::new();
    if let Some(MatValue::Text(text)) = mat.get(COMMENTS_VAR) {
        for (i, l) in text.lines().enumerate() {
            if let Some((k, v)) = l.trim().trim_start_matches('#').split_once('=') {
                meta.insert(k.trim().to_string(), (i + 1, v.trim().to_string()));
            }
        }
    }
    let excitation = if meta.contains_key("kind") {
        super::csv::parse_excitation(&meta, &format!("{name}: `{COMMENTS_VAR}`"))?
    } else {
        None
    };
    let rows = super::csv::RowLines::counting(1, columns[0].len());
    super::csv::record_from_columns(name, map, meta, excitation, Vec::new(), columns, rows)
        .map(|(r, _)| r)
}

/// The text variable holding the capture CSV's `# key=value` comment lines (written by
/// `jointid export --mat`), read back as a CSV's comments.
pub const COMMENTS_VAR: &str = "comments";

/// What [`MatWriter`] writes for one variable.
#[derive(Clone, Debug, PartialEq)]
pub enum MatOut {
    /// a real double matrix `rows×cols`, column-major
    Matrix {
        /// rows
        rows: usize,
        /// columns
        cols: usize,
        /// values, column-major
        data: Vec<f64>,
    },
    /// one row of text, written as ASCII ([`ascii_text`])
    Text(String),
    /// a 1×1 struct of these fields (names valid MATLAB identifiers, ≤ 31 characters)
    Struct(Vec<(String, MatOut)>),
}

impl MatOut {
    /// a column vector
    pub fn column(x: &[f64]) -> MatOut {
        MatOut::Matrix {
            rows: x.len(),
            cols: 1,
            data: x.to_vec(),
        }
    }

    /// a row vector
    pub fn row(x: &[f64]) -> MatOut {
        MatOut::Matrix {
            rows: 1,
            cols: x.len(),
            data: x.to_vec(),
        }
    }

    /// a 1×1 double
    pub fn scalar(x: f64) -> MatOut {
        MatOut::Matrix {
            rows: 1,
            cols: 1,
            data: vec![x],
        }
    }

    /// a matrix from its rows (all of one length)
    pub fn from_rows(rows: &[Vec<f64>]) -> MatOut {
        let r = rows.len();
        let c = rows.first().map_or(0, Vec::len);
        MatOut::Matrix {
            rows: r,
            cols: c,
            data: (0..c)
                .flat_map(|j| rows.iter().map(move |row| row[j]))
                .collect(),
        }
    }
}

/// `text` in ASCII, as MAT-file text is written (scipy's `loadmat` decodes 16-bit
/// characters with the system's codec, which garbles the rest): `·` a space, `²` `^2`,
/// `σ` `sigma`, `±` `+-`, any other non-ASCII character `?`.
pub fn ascii_text(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            c if c.is_ascii() => s.push(c),
            '·' => s.push(' '),
            '²' => s.push_str("^2"),
            'σ' => s.push_str("sigma"),
            '±' => s.push_str("+-"),
            _ => s.push('?'),
        }
    }
    s
}

/// `name` made a valid MATLAB identifier: letters, digits and `_`, starting with a
/// letter, at most 31 characters (`J_m` stays; `Fv-` becomes `Fv_`, `1x` `v_1x`).
pub fn mat_identifier(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if !s.starts_with(|c: char| c.is_ascii_alphabetic()) {
        s.insert_str(0, "v_");
    }
    s.truncate(31);
    s
}

impl fmt::Display for MatOut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MatOut::Matrix { rows, cols, .. } => write!(f, "{rows}×{cols} double"),
            MatOut::Text(_) => f.write_str("char"),
            MatOut::Struct(_) => f.write_str("struct"),
        }
    }
}

/// Writes a little-endian, uncompressed Level-5 MAT-file.
#[derive(Clone, Debug)]
pub struct MatWriter {
    buf: Vec<u8>,
}

fn push_u32(b: &mut Vec<u8>, x: u32) {
    b.extend_from_slice(&x.to_le_bytes());
}

/// an element `ty` holding `data`, padded to 8 bytes
fn push_element(b: &mut Vec<u8>, ty: u32, data: &[u8]) {
    push_u32(b, ty);
    push_u32(b, data.len() as u32);
    b.extend_from_slice(data);
    b.resize(b.len().div_ceil(8) * 8, 0);
}

/// the content of a `miMATRIX` element: flags, dimensions, name, data
fn matrix_bytes(name: &str, v: &MatOut) -> Vec<u8> {
    let mut b = Vec::new();
    let (class, dims): (u8, [usize; 2]) = match v {
        MatOut::Matrix { rows, cols, .. } => (mx::DOUBLE, [*rows, *cols]),
        MatOut::Text(t) => (mx::CHAR, [1, ascii_text(t).len()]),
        MatOut::Struct(_) => (mx::STRUCT, [1, 1]),
    };
    let mut flags = Vec::new();
    push_u32(&mut flags, u32::from(class));
    push_u32(&mut flags, 0);
    push_element(&mut b, mi::UINT32, &flags);
    let mut d = Vec::new();
    for x in dims {
        d.extend_from_slice(&(x as i32).to_le_bytes());
    }
    push_element(&mut b, mi::INT32, &d);
    push_element(&mut b, mi::INT8, name.as_bytes());
    match v {
        MatOut::Matrix { data, .. } => {
            let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
            push_element(&mut b, mi::DOUBLE, &bytes);
        }
        MatOut::Text(t) => {
            let bytes: Vec<u8> = ascii_text(t)
                .bytes()
                .flat_map(|c| u16::from(c).to_le_bytes())
                .collect();
            push_element(&mut b, mi::UINT16, &bytes);
        }
        MatOut::Struct(fields) => {
            const FIELD_LEN: usize = 32;
            push_element(&mut b, mi::INT32, &(FIELD_LEN as i32).to_le_bytes());
            let mut names = Vec::new();
            for (n, _) in fields {
                let mut f = mat_identifier(n).into_bytes();
                f.resize(FIELD_LEN, 0);
                names.extend_from_slice(&f);
            }
            push_element(&mut b, mi::INT8, &names);
            for (_, fv) in fields {
                let inner = matrix_bytes("", fv);
                push_element(&mut b, mi::MATRIX, &inner);
            }
        }
    }
    b
}

impl MatWriter {
    /// A file whose header text says what wrote it and what it holds.
    pub fn new(description: &str) -> MatWriter {
        let mut text = format!("MATLAB 5.0 MAT-file, written by jointid: {description}")
            .chars()
            .filter(char::is_ascii)
            .collect::<String>()
            .into_bytes();
        text.resize(116, b' ');
        let mut buf = text;
        // no subsystem data
        buf.extend_from_slice(&[0; 8]);
        buf.extend_from_slice(&0x0100u16.to_le_bytes());
        buf.extend_from_slice(b"IM");
        MatWriter { buf }
    }

    /// Adds the variable `name` (made a MATLAB identifier, [`mat_identifier`]).
    pub fn var(&mut self, name: &str, v: &MatOut) -> &mut Self {
        let m = matrix_bytes(&mat_identifier(name), v);
        push_element(&mut self.buf, mi::MATRIX, &m);
        self
    }

    /// The file's bytes.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_vectors_text_and_structs_read_back_bit_for_bit() {
        let x = [0.1, -2.5e-300, f64::MAX, 1.0 / 3.0];
        let mut w = MatWriter::new("test");
        w.var("x", &MatOut::column(&x))
            .var("row", &MatOut::row(&x[..3]))
            .var("Ts", &MatOut::scalar(1e-3))
            .var("note", &MatOut::Text("u [N·m] -> J [kg·m²]".into()))
            .var(
                "p",
                &MatOut::Struct(vec![("J_m".into(), MatOut::scalar(2.0))]),
            )
            .var(
                "A",
                &MatOut::from_rows(&[vec![1.0, 2.0, 3.0], vec![4.0, 5.0, 6.0]]),
            );
        let bytes = w.finish();
        assert!(is_mat5(&bytes));
        let m = read_mat(&bytes, "t.mat").unwrap();
        assert_eq!(m.vector("x").unwrap(), &x);
        assert_eq!(m.vector("row").unwrap(), &x[..3]);
        assert_eq!(m.vector("Ts").unwrap(), &[1e-3]);
        assert_eq!(
            m.get("note"),
            Some(&MatValue::Text("u [N m] -> J [kg m^2]".into()))
        );
        assert_eq!(m.get("p"), Some(&MatValue::Other("struct".into())));
        assert_eq!(
            m.get("A"),
            Some(&MatValue::Numeric {
                dims: vec![2, 3],
                data: vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0]
            })
        );
        assert_eq!(
            m.vector("A").unwrap_err().to_string(),
            "variable `A` is 2×3 matrix; expected a real numeric vector (1×N or N×1)"
        );
        assert_eq!(
            m.vector("qm").unwrap_err().to_string(),
            "variable `qm` not found; variables are: x, row, Ts, note, p, A"
        );
        assert_eq!(
            m.vector("p").unwrap_err(),
            VectorError::NotNumeric {
                name: "p".into(),
                what: "struct".into()
            }
        );
        assert_eq!(
            m.vector("p").unwrap_err().to_string(),
            "variable `p` is struct; expected a real numeric vector"
        );
    }

    /// A big-endian file with a small element (the name), single-precision and int16
    /// data and a compressed element, built by hand from the format's tables.
    #[test]
    fn big_endian_small_elements_narrow_types_and_compression_are_read() {
        fn be_matrix(name: &[u8], ty: u32, data: &[u8], n: i32) -> Vec<u8> {
            let mut m = Vec::new();
            // flags: miUINT32, 8 bytes, class double
            m.extend_from_slice(&6u32.to_be_bytes());
            m.extend_from_slice(&8u32.to_be_bytes());
            m.extend_from_slice(&6u32.to_be_bytes());
            m.extend_from_slice(&0u32.to_be_bytes());
            // dims n×1
            m.extend_from_slice(&5u32.to_be_bytes());
            m.extend_from_slice(&8u32.to_be_bytes());
            m.extend_from_slice(&n.to_be_bytes());
            m.extend_from_slice(&1i32.to_be_bytes());
            // small element: the name (≤ 4 bytes)
            m.extend_from_slice(&(((name.len() as u32) << 16) | 1).to_be_bytes());
            let mut nm = name.to_vec();
            nm.resize(4, 0);
            m.extend_from_slice(&nm);
            m.extend_from_slice(&ty.to_be_bytes());
            m.extend_from_slice(&(data.len() as u32).to_be_bytes());
            m.extend_from_slice(data);
            m.resize(m.len().div_ceil(8) * 8, 0);
            let mut e = Vec::new();
            e.extend_from_slice(&14u32.to_be_bytes());
            e.extend_from_slice(&(m.len() as u32).to_be_bytes());
            e.extend_from_slice(&m);
            e
        }
        let mut f = b"MATLAB 5.0 MAT-file, big endian test".to_vec();
        f.resize(124, b' ');
        f.extend_from_slice(&0x0100u16.to_be_bytes());
        f.extend_from_slice(b"MI");
        let single: Vec<u8> = [0.5f32, -1.25, 3.0]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        f.extend(be_matrix(b"u", 7, &single, 3));
        let ints: Vec<u8> = [-7i16, 300, 2]
            .iter()
            .flat_map(|x| x.to_be_bytes())
            .collect();
        let inner = be_matrix(b"y", 3, &ints, 3);
        let z = miniz_oxide::deflate::compress_to_vec_zlib(&inner, 6);
        f.extend_from_slice(&15u32.to_be_bytes());
        f.extend_from_slice(&(z.len() as u32).to_be_bytes());
        f.extend_from_slice(&z);
        let m = read_mat(&f, "be.mat").unwrap();
        assert_eq!(m.vector("u").unwrap(), &[0.5, -1.25, 3.0]);
        assert_eq!(m.vector("y").unwrap(), &[-7.0, 300.0, 2.0]);
        // a truncated file names the byte where it breaks
        let e = read_mat(&f[..f.len() - 5], "be.mat").unwrap_err();
        assert!(e.to_string().starts_with("be.mat: byte "), "{e}");
        assert!(
            matches!(
                e.reason,
                MatReason::Element {
                    inflated: false,
                    source: ElementError::Overrun { .. },
                    ..
                }
            ),
            "{e:?}"
        );
    }

    #[test]
    fn variables_map_like_csv_columns_and_errors_name_the_variable() {
        let t: Vec<f64> = (0..50).map(|k| f64::from(k) * 0.01).collect();
        let u: Vec<f64> = (0..50).map(|k| f64::from(k).sin()).collect();
        let y: Vec<f64> = (0..50).map(|k| f64::from(k).cos()).collect();
        let mut w = MatWriter::new("map");
        w.var("time", &MatOut::column(&t))
            .var("vir", &MatOut::row(&u))
            .var("qm", &MatOut::column(&y))
            .var("short", &MatOut::column(&y[..10]));
        let bytes = w.finish();
        let map = ColumnMap {
            time: "time".into(),
            input: "vir".into(),
            output: "qm".into(),
            reference: None,
            delimiter: None,
        };
        let ds = parse_mat_record(&bytes, "e.mat", &map)
            .unwrap()
            .into_single()
            .unwrap();
        assert_eq!(ds.data.u, u);
        assert_eq!(ds.data.y, y);
        assert!((ds.data.ts - 0.01).abs() < 1e-15);
        let e = parse_mat_record(&bytes, "e.mat", &ColumnMap::capture()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "e.mat: variable `t` not found; variables are: time, vir, qm, short"
        );
        let e = parse_mat_record(
            &bytes,
            "e.mat",
            &ColumnMap {
                output: "short".into(),
                ..map
            },
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "e.mat: variable `short` has 10 samples, `time` has 50"
        );
    }

    #[test]
    fn identifiers_are_made_valid() {
        assert_eq!(mat_identifier("J_m"), "J_m");
        assert_eq!(mat_identifier("Fv-"), "Fv_");
        assert_eq!(mat_identifier("1x"), "v_1x");
        assert_eq!(mat_identifier(&"a".repeat(40)).len(), 31);
    }
}
