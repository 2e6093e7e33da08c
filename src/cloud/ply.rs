//! PLY input and output for point clouds.
//!
//! # Reading
//!
//! [`read_ply`] / [`read_ply_with`] (and [`read_ply_bytes`] for bytes already in memory) read
//! the `vertex` element of a PLY file into a [`PointCloud`]:
//!
//! * **Formats**: `ascii`, `binary_little_endian` and `binary_big_endian` (version 1.0). Lines
//!   may end in `\n` or `\r\n`.
//! * **Positions**: the vertex properties `x`, `y`, `z`, of any scalar type (`float`,
//!   `double`, or an integer type); they are stored as `f32`.
//! * **Normals**: `nx`, `ny`, `nz` (or `normal_x`, `normal_y`, `normal_z`) when all three are
//!   present. A normal whose length differs from 1 by more than 1e-4 is rescaled to unit length;
//!   normals that are already unit are kept bit for bit (so a write/read round trip is exact).
//! * **Colours**: `red`, `green`, `blue` (or `r`, `g`, `b`, or `diffuse_red`, ...) when all three
//!   are present: integer types are clamped to 0..=255, floating-point types are taken as 0..1
//!   and scaled to 0..=255.
//! * **Everything else is skipped**: other vertex properties (`confidence`, `intensity`, ...,
//!   including list properties), `comment` and `obj_info` lines, and other elements (faces,
//!   edges, ...) whether they come before or after the vertex element. A mesh PLY therefore gives
//!   its vertices. Elements that come *before* the vertex element are walked record by record
//!   (binary list properties included) to find where the vertices start; data *after* the vertex
//!   element is never examined, so a mesh whose face data is damaged still gives its vertices.
//!   Element names, and property names within an element, must be unique (a header that
//!   repeats one is a [`PlyProblem::BadHeader`]).
//!
//! ## What ply-rs does, and what this module does
//!
//! The header is parsed by [ply-rs](https://crates.io/crates/ply-rs)
//! (`ply_rs::parser::Parser::read_header`); the `Header` it returns (encoding, and the
//! elements with their counts and property types, in file order) is the only source of the
//! layout the payload is decoded with. Around it:
//!
//! 1. **Byte-level checks first**: an empty file ([`PlyProblem::EmptyFile`]), a first line
//!    that is not `ply` ([`PlyProblem::NotPly`]), and the header lines up to the first
//!    `end_header` line, looked for in at most the first 1 MiB. Blank lines are dropped, lines
//!    are trimmed and invalid UTF-8 (in comments) is replaced before ply-rs sees them: ply-rs
//!    rejects blank or indented lines, and fails on a file that is not UTF-8 throughout. Counts
//!    and version numbers too large for `u64` are refused here, because ply-rs's grammar
//!    `unwrap`s their parse (it would panic), and the version must be 1.0, because ply-rs
//!    casts it to `u16`/`u8` (`256.0` would pass as `0.0`). The parse is also wrapped in
//!    `catch_unwind`, so a ply-rs panic that slipped through would still be a `BadHeader`.
//! 2. **ply-rs parses the header.** When it rejects a line, the error gives that line's number
//!    in the file and, where one can be given, a more specific reason than ply-rs's "Couldn't
//!    parse line" (an unknown type or format, a count that is not a whole number, a property
//!    before any element, data where the `end_header` line is missing), followed by ply-rs's
//!    own message in brackets. This explanation is only a diagnosis of a line ply-rs refused;
//!    it never decides what a header means.
//! 3. **Checks ply-rs does not make**: ply-rs keys elements and properties by name in a map,
//!    so a repeated name would silently replace (or move) the earlier declaration and shift the
//!    record layout; the number of `element`/`property` lines is compared with what ply-rs
//!    returned, and a repeat is a `BadHeader`. A list whose count type is `float` or `double`
//!    (which ply-rs's grammar accepts) is a `BadHeader` too.
//!
//! The **payload is decoded by this module**, not by ply-rs's `read_payload`, which
//! (version 0.1.3) builds one `DefaultElement` (a linked hash map with one `String` key per
//! property) for every record of every element in the file: several heap allocations per
//! point, far too slow and memory-hungry for millions of points, and the faces after the
//! vertices must be intact too. It does not preallocate by the header's counts, but it loops
//! over them unchecked (a negative binary list length becomes an enormous `usize`), its
//! ascii reader wants exactly one record per line and refuses `nan`/`inf`, and its errors do
//! not say which element or record failed. The decoder here works on the bytes in memory,
//! checks every count against the bytes left before allocating, and reports the problems
//! below.
//!
//! ## Options ([`ReadOptions`])
//!
//! * Points whose coordinates (or normals) are NaN or infinite — including `double` values too
//!   large for `f32` — are an error ([`PlyProblem::NonFinite`], which says how many) unless
//!   `drop_non_finite` is set, in which case exactly those points are left out.
//! * **Zero-length normals** (length below 1e-12) are common from some exporters (all-zero
//!   normal columns). They are an error ([`PlyProblem::ZeroNormals`]) only when
//!   `require_normals` is set; otherwise the whole normal array is discarded
//!   (`normals: None`) so that the caller re-estimates normals for every point rather than
//!   mixing estimated and stored ones.
//! * With `require_normals`, a file without `nx`, `ny`, `nz` is an error
//!   ([`PlyProblem::MissingNormals`]).
//!
//! ## Safety against hostile or damaged files
//!
//! The reader never panics, and never allocates by a header count before checking that the
//! bytes left in the file can hold that many records: a binary record takes at least the sizes
//! of its scalar properties plus one count per list property, an ascii record at least two bytes
//! (one character and one separator) per property. A header that declares four billion vertices
//! in a 200-byte file fails at once with [`PlyProblem::CountExceedsData`].
//!
//! ## Errors
//!
//! Every error is a [`PlyError`]: the file's path and a [`PlyProblem`], displayed as
//! `"{path}: {problem}"`. The problems are:
//!
//! | problem | when |
//! |---|---|
//! | [`Unreadable`](PlyProblem::Unreadable) | the file is missing or cannot be read (permission, I/O error) |
//! | [`IsDirectory`](PlyProblem::IsDirectory) | the path is a directory |
//! | [`EmptyFile`](PlyProblem::EmptyFile) | the file has 0 bytes |
//! | [`NotPly`](PlyProblem::NotPly) | the first line is not `ply` |
//! | [`BadHeader`](PlyProblem::BadHeader) | ply-rs rejects the header, or it is unsupported (a garbled line, unknown format, version other than 1.0, unknown keyword or type, a count that is not a whole number or is too large, a property before any element, no `format` line, no `end_header` line, a repeated element or property name, a list with a floating-point count type) |
//! | [`NoVertexElement`](PlyProblem::NoVertexElement) | the header declares no `vertex` element |
//! | [`MissingCoordinate`](PlyProblem::MissingCoordinate) | the vertex element has no `x`, `y` or `z` scalar property |
//! | [`CountExceedsData`](PlyProblem::CountExceedsData) | an element's declared count cannot fit in the bytes that remain (checked before reading) |
//! | [`Truncated`](PlyProblem::Truncated) | the data ends in the middle of an element while it is read (variable-size records: lists, ascii) |
//! | [`BadListLength`](PlyProblem::BadListLength) | a list property has a negative length |
//! | [`BadValue`](PlyProblem::BadValue) | an ascii value that should be a number is not one (with its line number) |
//! | [`NonFinite`](PlyProblem::NonFinite) | points with NaN or infinite coordinates or normals (without `drop_non_finite`) |
//! | [`Empty`](PlyProblem::Empty) | no point is left (`element vertex 0`, or every point dropped) |
//! | [`ZeroNormals`](PlyProblem::ZeroNormals) | zero-length normals with `require_normals` |
//! | [`MissingNormals`](PlyProblem::MissingNormals) | no normals with `require_normals` |
//! | [`MissingProperty`](PlyProblem::MissingProperty) | [`read_ply_with_property`] asked for a vertex property the file lacks |
//! | [`Inconsistent`](PlyProblem::Inconsistent) | writing: the cloud's arrays or the labels do not match, or a label is unusable |
//! | [`Write`](PlyProblem::Write) | writing: the file cannot be created, written or renamed into place |
//!
//! # Writing
//!
//! [`write_ply`] writes a `binary_little_endian` PLY with one `vertex` element: `float x, y, z`;
//! `float nx, ny, nz` when the cloud has normals; `uchar red, green, blue` when the cloud has
//! colours and [`WriteOptions::colors`] is set; and optionally one `int` property per point
//! named by [`WriteOptions::labels`] (e.g. `bone` labels of a registration, where `u32::MAX`,
//! "no bone", is written as `-1`; the name must be a PLY identifier that ply-rs reads back: a letter or `_`, then letters, digits, `_` or `-`).
//! The header is written by ply-rs (`ply_rs::writer::Writer::write_header`, into memory,
//! then passed on with one `write_all`: ply-rs uses `Write::write`, which may write only part
//! of its input on other writers); the records are written by this module in chunks of about
//! 1 MiB (ply-rs's payload writer would need one `DefaultElement` per point, and version
//! 0.1.3 writes the element count as the length of every binary list). The file is
//! written to a temporary sibling and renamed into place, so a failed write never leaves a half
//! file where a good one was. [`write_ply_to`] writes the same bytes to any writer.

use std::fmt;
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::PointCloud;
use crate::math::Vec3;

// ------------------------------------------------------------------------------------------
// Errors
// ------------------------------------------------------------------------------------------

/// A PLY file could not be read or written: the file and the problem.
#[derive(Debug)]
pub struct PlyError {
    /// The file (or the name given to [`read_ply_bytes`]).
    pub path: PathBuf,
    /// What is wrong with it.
    pub problem: PlyProblem,
}

impl PlyError {
    /// An error about `path`.
    pub fn new(path: impl Into<PathBuf>, problem: PlyProblem) -> Self {
        PlyError {
            path: path.into(),
            problem,
        }
    }
}

impl fmt::Display for PlyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.problem)
    }
}

impl std::error::Error for PlyError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match &self.problem {
            PlyProblem::Unreadable(e) | PlyProblem::Write(e) => Some(e),
            _ => None,
        }
    }
}

/// What is wrong with a PLY file (see the [module documentation](self) for when each occurs).
#[derive(Debug)]
pub enum PlyProblem {
    /// The file is missing or cannot be read.
    Unreadable(io::Error),
    /// The path names a directory.
    IsDirectory,
    /// The file has no bytes at all.
    EmptyFile,
    /// The file does not start with the line `ply`.
    NotPly,
    /// A header line is garbled or unsupported; the text says which line and why.
    BadHeader(String),
    /// The header declares no `vertex` element.
    NoVertexElement,
    /// The vertex element lacks the named coordinate property (`"x"`, `"y"` or `"z"`).
    MissingCoordinate(&'static str),
    /// The header declares more records of `element` than the remaining bytes can hold
    /// (`available` is the most they could hold).
    CountExceedsData {
        element: String,
        declared: u64,
        available: u64,
    },
    /// The data ended after `read` of the `declared` records of `element`.
    Truncated {
        element: String,
        read: u64,
        declared: u64,
    },
    /// Record `index` (0-based) of `element` has a list property of negative length.
    BadListLength {
        element: String,
        index: u64,
        length: i64,
    },
    /// An ascii value is not a number (line numbers count from 1, header included).
    BadValue { line: usize, detail: String },
    /// `count` points have NaN or infinite coordinates or normals.
    NonFinite { count: usize },
    /// No point at all (or none left after dropping non-finite ones).
    Empty,
    /// `count` points have zero-length normals (only an error with `require_normals`).
    ZeroNormals { count: usize },
    /// Normals were required but the file has none.
    MissingNormals,
    /// The vertex element has no property of this name (see [`read_ply_with_property`]).
    MissingProperty(String),
    /// The cloud or the options given to a writer are inconsistent.
    Inconsistent(String),
    /// The file could not be written.
    Write(io::Error),
}

impl fmt::Display for PlyProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PlyProblem::Unreadable(e) => write!(f, "cannot read the file: {e}"),
            PlyProblem::IsDirectory => write!(f, "is a directory, not a PLY file"),
            PlyProblem::EmptyFile => write!(f, "the file is empty (0 bytes), not a PLY file"),
            PlyProblem::NotPly => {
                write!(
                    f,
                    "not a PLY file (it does not start with the line \"ply\")"
                )
            }
            PlyProblem::BadHeader(why) => write!(f, "bad PLY header: {why}"),
            PlyProblem::NoVertexElement => {
                write!(
                    f,
                    "the PLY header declares no \"vertex\" element, so there are no points"
                )
            }
            PlyProblem::MissingCoordinate(c) => {
                write!(f, "the vertex element has no \"{c}\" coordinate property")
            }
            PlyProblem::CountExceedsData {
                element,
                declared,
                available,
            } => write!(
                f,
                "header declares {declared} {element} records but the data can hold at most \
                 {available} (file truncated?)"
            ),
            PlyProblem::Truncated {
                element,
                read,
                declared,
            } => write!(
                f,
                "the data ends after {read} of the {declared} {element} records the header \
                 declares (file truncated?)"
            ),
            PlyProblem::BadListLength {
                element,
                index,
                length,
            } => write!(
                f,
                "{element} record {index} has a list of negative length {length} (corrupt data)"
            ),
            PlyProblem::BadValue { line, detail } => write!(f, "line {line}: {detail}"),
            PlyProblem::NonFinite { count } => write!(
                f,
                "{count} point{} NaN or infinite coordinates or normals (they can be dropped \
                 with the drop-non-finite option)",
                if *count == 1 { " has" } else { "s have" }
            ),
            PlyProblem::Empty => write!(f, "the file holds no points"),
            PlyProblem::ZeroNormals { count } => write!(
                f,
                "{count} point{} a zero-length normal, and normals are required",
                if *count == 1 { " has" } else { "s have" }
            ),
            PlyProblem::MissingNormals => write!(
                f,
                "normals are required but the vertex element has no nx, ny, nz properties"
            ),
            PlyProblem::MissingProperty(name) => {
                write!(f, "the vertex element has no \"{name}\" property")
            }
            PlyProblem::Inconsistent(why) => write!(f, "cannot write: {why}"),
            PlyProblem::Write(e) => write!(f, "cannot write the file: {e}"),
        }
    }
}

// ------------------------------------------------------------------------------------------
// Reading: public API
// ------------------------------------------------------------------------------------------

/// Options of [`read_ply_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadOptions {
    /// Leave out points with NaN or infinite coordinates or normals instead of failing with
    /// [`PlyProblem::NonFinite`].
    pub drop_non_finite: bool,
    /// Fail when the file has no normals ([`PlyProblem::MissingNormals`]) or has zero-length
    /// ones ([`PlyProblem::ZeroNormals`]); without it, zero-length normals make the reader
    /// discard all normals (`normals: None`).
    pub require_normals: bool,
}

/// Reads the points of a PLY file with the default [`ReadOptions`].
pub fn read_ply(path: impl AsRef<Path>) -> Result<PointCloud, PlyError> {
    read_ply_with(path, &ReadOptions::default())
}

/// Reads the points of a PLY file.
pub fn read_ply_with(
    path: impl AsRef<Path>,
    options: &ReadOptions,
) -> Result<PointCloud, PlyError> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    read_ply_bytes(path, &bytes, options)
}

/// Reads the points of PLY data already in memory; `name_for_errors` is the path errors name.
pub fn read_ply_bytes(
    name_for_errors: &Path,
    bytes: &[u8],
    options: &ReadOptions,
) -> Result<PointCloud, PlyError> {
    parse(bytes, options, None)
        .map(|(cloud, _)| cloud)
        .map_err(|problem| PlyError::new(name_for_errors, problem))
}

/// Reads the points of a PLY file together with one more scalar vertex property (e.g. the
/// `bone` labels written by [`write_ply`]), one value per returned point (points dropped by
/// `drop_non_finite` are dropped from the values too). Fails with
/// [`PlyProblem::MissingProperty`] when the vertex element has no such scalar property.
pub fn read_ply_with_property(
    path: impl AsRef<Path>,
    options: &ReadOptions,
    property: &str,
) -> Result<(PointCloud, Vec<f64>), PlyError> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    match parse(&bytes, options, Some(property)) {
        Ok((cloud, Some(values))) => Ok((cloud, values)),
        Ok((_, None)) => Err(PlyError::new(
            path,
            PlyProblem::MissingProperty(property.into()),
        )),
        Err(problem) => Err(PlyError::new(path, problem)),
    }
}

fn read_file(path: &Path) -> Result<Vec<u8>, PlyError> {
    if fs::metadata(path).is_ok_and(|m| m.is_dir()) {
        return Err(PlyError::new(path, PlyProblem::IsDirectory));
    }
    fs::read(path).map_err(|e| PlyError::new(path, PlyProblem::Unreadable(e)))
}

// ------------------------------------------------------------------------------------------
// Header
// ------------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one binary value at `at`; `None` when the bytes are not there.
    #[inline]
    fn decode(self, bytes: &[u8], at: usize, big: bool) -> Option<f64> {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let raw: [u8; $n] = bytes.get(at..at.checked_add($n)?)?.try_into().ok()?;
                (if big {
                    <$t>::from_be_bytes(raw)
                } else {
                    <$t>::from_le_bytes(raw)
                }) as f64
            }};
        }
        Some(match self {
            Scalar::I8 => get!(i8, 1),
            Scalar::U8 => get!(u8, 1),
            Scalar::I16 => get!(i16, 2),
            Scalar::U16 => get!(u16, 2),
            Scalar::I32 => get!(i32, 4),
            Scalar::U32 => get!(u32, 4),
            Scalar::F32 => get!(f32, 4),
            Scalar::F64 => get!(f64, 8),
        })
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
}

impl Element {
    /// Smallest binary record: scalars plus one count per list.
    fn min_binary_size(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum()
    }

    fn has_lists(&self) -> bool {
        self.props
            .iter()
            .any(|p| matches!(p.kind, Kind::List { .. }))
    }

    fn scalar(&self, name: &str) -> Option<(usize, Scalar)> {
        self.props
            .iter()
            .enumerate()
            .find_map(|(i, p)| match p.kind {
                Kind::Scalar(s) if p.name == name => Some((i, s)),
                _ => None,
            })
    }

    /// The first of `names` that is a scalar property.
    fn scalar_any(&self, names: &[&str]) -> Option<(usize, Scalar)> {
        names.iter().find_map(|n| self.scalar(n))
    }
}

#[derive(Debug)]
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset of the data.
    body_start: usize,
    /// Line number (1-based) of the first data line.
    body_line: usize,
}

fn bad_header(line: usize, why: impl fmt::Display) -> PlyProblem {
    PlyProblem::BadHeader(format!("line {line}: {why}"))
}

/// Shortens a header line for an error message (control characters escaped).
fn quote(line: &str) -> String {
    let mut short = String::new();
    for c in line.chars().take(60) {
        if c.is_control() {
            short.extend(c.escape_default());
        } else {
            short.push(c);
        }
    }
    if line.chars().nth(60).is_some() {
        format!("\"{short}...\"")
    } else {
        format!("\"{short}\"")
    }
}

/// The most bytes looked at for the header (real headers are a few hundred bytes; this bounds
/// the work on a binary file that has no `end_header` line).
const MAX_HEADER_BYTES: usize = 1 << 20;

/// One non-blank header line after the `ply` line: its number in the file (1-based) and its
/// text, trimmed, with invalid UTF-8 replaced (only comments can hold such bytes usefully).
struct HeaderLine {
    number: usize,
    text: String,
}

impl HeaderLine {
    /// The words as ply-rs separates them (spaces and tabs).
    fn words(&self) -> Vec<&str> {
        self.text
            .split([' ', '\t'])
            .filter(|w| !w.is_empty())
            .collect()
    }

    fn keyword(&self) -> &str {
        self.words().first().copied().unwrap_or("")
    }
}

/// The header lines, cut by byte-level checks only.
struct HeaderText {
    lines: Vec<HeaderLine>,
    /// Byte offset and line number of the data, when an `end_header` line was found.
    body: Option<(usize, usize)>,
    /// Whether the search for `end_header` stopped at [`MAX_HEADER_BYTES`].
    capped: bool,
}

/// Byte-level checks: not empty, first line `ply`, and the lines up to the first
/// `end_header` line (or [`MAX_HEADER_BYTES`], or the end of the file).
fn split_header(bytes: &[u8]) -> Result<HeaderText, PlyProblem> {
    if bytes.is_empty() {
        return Err(PlyProblem::EmptyFile);
    }
    let head = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let mut lines = Vec::new();
    let mut pos = 0usize;
    let mut number = 0usize;
    while pos < head.len() {
        let rest = &head[pos..];
        let (raw, next, whole) = match rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&rest[..i], pos + i + 1, true),
            // The last line of the file, or a line cut by the byte limit.
            None => (rest, head.len(), head.len() == bytes.len()),
        };
        pos = next;
        number += 1;
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        if number == 1 {
            if raw.trim_ascii() == b"ply" {
                continue;
            }
            if raw.starts_with(b"ply\r") {
                return Err(bad_header(
                    1,
                    "lines end in a bare carriage return (unsupported)",
                ));
            }
            return Err(PlyProblem::NotPly);
        }
        let trimmed = raw.trim_ascii();
        if trimmed.is_empty() {
            continue;
        }
        lines.push(HeaderLine {
            number,
            text: String::from_utf8_lossy(trimmed).into_owned(),
        });
        if whole && trimmed == b"end_header" {
            return Ok(HeaderText {
                lines,
                body: Some((pos, number + 1)),
                capped: false,
            });
        }
    }
    if number == 0 {
        return Err(PlyProblem::NotPly);
    }
    Ok(HeaderText {
        lines,
        body: None,
        capped: head.len() < bytes.len(),
    })
}

/// Numbers ply-rs would get wrong: its grammar `unwrap`s the parse of every count and version
/// number as `u64` (a panic on a 20-digit count) and then casts them (`as usize`, `as u16`,
/// `as u8`), which would silently turn `format ascii 256.0` into version 0.0.
fn check_numbers(lines: &[HeaderLine]) -> Result<(), PlyProblem> {
    let leading_digits =
        |s: &str| -> String { s.chars().take_while(char::is_ascii_digit).collect() };
    let fits = |digits: &str| digits.is_empty() || digits.parse::<u64>().is_ok();
    for line in lines {
        let words = line.words();
        match (words.first().copied(), words.get(2)) {
            (Some("element"), Some(count)) => {
                let digits = leading_digits(count);
                if !fits(&digits) || usize::try_from(digits.parse::<u64>().unwrap_or(0)).is_err() {
                    return Err(bad_header(
                        line.number,
                        format!(
                            "the count of element {} is too large: {}",
                            words[1],
                            quote(count)
                        ),
                    ));
                }
            }
            (Some("format"), Some(version)) => {
                let major = leading_digits(version);
                let minor = version
                    .get(major.len()..)
                    .and_then(|r| r.strip_prefix('.'))
                    .map(leading_digits)
                    .unwrap_or_default();
                let parsed = (major.parse::<u64>(), minor.parse::<u64>());
                let digit_form = !major.is_empty() && !minor.is_empty();
                if !fits(&major) || !fits(&minor) || (digit_form && parsed != (Ok(1), Ok(0))) {
                    return Err(bad_header(
                        line.number,
                        format!("unsupported PLY version {} (expected 1.0)", quote(version)),
                    ));
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Parses the header: byte-level checks, then ply-rs, then the mapping to [`Header`].
fn parse_header(bytes: &[u8]) -> Result<Header, PlyProblem> {
    let text = split_header(bytes)?;
    check_numbers(&text.lines)?;
    let mut joined = String::from("ply\n");
    for line in &text.lines {
        joined.push_str(&line.text);
        joined.push('\n');
    }
    // ply-rs's grammar unwraps number parses; check_numbers keeps those inputs away from it,
    // and a panic that slipped through anyway is reported, not propagated.
    let parsed = std::panic::catch_unwind(|| {
        let mut reader = joined.as_bytes();
        ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new().read_header(&mut reader)
    });
    let header = match parsed {
        Ok(Ok(header)) => header,
        Ok(Err(e)) => return Err(explain_rejection(&text, &e.to_string())),
        Err(_) => {
            return Err(PlyProblem::BadHeader(
                "ply-rs failed (panicked) on this header".into(),
            ));
        }
    };
    let Some((body_start, body_line)) = text.body else {
        // ply-rs reads up to an end_header line; it cannot have accepted a header without one.
        return Err(no_end_header(&text));
    };
    let elements = map_elements(&text.lines, &header)?;
    let format = match header.encoding {
        ply_rs::ply::Encoding::Ascii => Format::Ascii,
        ply_rs::ply::Encoding::BinaryLittleEndian => Format::BinaryLittleEndian,
        ply_rs::ply::Encoding::BinaryBigEndian => Format::BinaryBigEndian,
    };
    Ok(Header {
        format,
        elements,
        body_start,
        body_line,
    })
}

fn no_end_header(text: &HeaderText) -> PlyProblem {
    PlyProblem::BadHeader(if text.capped {
        format!(
            "no end_header line in the first {} MiB (the header has no end_header line, or \
             is far too long)",
            MAX_HEADER_BYTES >> 20
        )
    } else {
        "the header has no end_header line".into()
    })
}

/// The [`PlyProblem`] for a header ply-rs rejected with `message`: ply-rs's reason, and the
/// offending line with a more specific reason where one can be given.
fn explain_rejection(text: &HeaderText, message: &str) -> PlyProblem {
    let first = message.lines().next().unwrap_or("").trim();
    // ply-rs reports "Line N: reason", N counting the lines it was given (ours, from "ply").
    let (line_index, reason) = match first
        .strip_prefix("Line ")
        .and_then(|r| r.split_once(": "))
        .and_then(|(n, reason)| Some((n.parse::<usize>().ok()?, reason)))
    {
        Some((n, reason)) => (Some(n), reason),
        None => (None, first),
    };
    // "Property 'PropertyDef { .. }' found ...": leave out the Debug dump.
    let reason = match reason.split_once(" '") {
        Some((head, rest)) if rest.starts_with("PropertyDef") => {
            let tail = rest.rsplit_once("' ").map_or("", |(_, t)| t);
            format!("{head} {tail}")
        }
        _ => reason.to_string(),
    };
    let mut summary: String = reason.chars().take(80).collect();
    if summary.len() < reason.len() {
        summary.push_str("...");
    }
    if let Some(column) = message
        .split_once("column: ")
        .and_then(|(_, r)| r.split(|c: char| !c.is_ascii_digit()).next())
        .filter(|c| !c.is_empty())
    {
        summary.push_str(&format!(" (column {column})"));
    }
    let Some(index) = line_index else {
        if message.contains("No format line") {
            return PlyProblem::BadHeader(format!(
                "the header has no format line [ply-rs: {summary}]"
            ));
        }
        return PlyProblem::BadHeader(format!("[ply-rs: {summary}]"));
    };
    match index.checked_sub(2).map(|i| (i, text.lines.get(i))) {
        Some((i, Some(line))) => bad_header(
            line.number,
            format!(
                "{} [ply-rs: {summary}]",
                describe_bad_line(&text.lines[..i], line)
            ),
        ),
        // ply-rs ran out of lines: there is no end_header line.
        Some((_, None)) => no_end_header(text),
        None => PlyProblem::BadHeader(format!("[ply-rs: {summary}]")),
    }
}

/// Why ply-rs rejected `line` (with `before` the header lines above it), in words: a more
/// specific reason than ply-rs's "Couldn't parse line". Only used for error messages: the
/// header structures come from ply-rs.
fn describe_bad_line(before: &[HeaderLine], line: &HeaderLine) -> String {
    let words = line.words();
    let text = &line.text;
    let unknown_type = |t: &str| {
        (Scalar::parse(t).is_none()).then(|| format!("unknown property type {}", quote(t)))
    };
    let specific = match words.first().copied().unwrap_or("") {
        "ply" => Some("a second \"ply\" line".to_string()),
        "end_header" => Some(format!("garbled line {}", quote(text))),
        "comment" | "obj_info" => Some(format!(
            "garbled {} line {} (a carriage return inside it?)",
            words[0],
            quote(text)
        )),
        "format" => {
            if words.len() != 3 {
                Some(format!("garbled format line {}", quote(text)))
            } else if !matches!(
                words[1],
                "ascii" | "binary_little_endian" | "binary_big_endian"
            ) {
                Some(format!(
                    "unknown format {} (expected ascii, binary_little_endian or \
                     binary_big_endian)",
                    quote(words[1])
                ))
            } else if words[2] != "1.0" {
                Some(format!(
                    "unsupported PLY version {} (expected 1.0)",
                    quote(words[2])
                ))
            } else {
                Some("a second format line that contradicts the first".to_string())
            }
        }
        "element" => {
            if words.len() != 3 {
                Some(format!(
                    "garbled element line {} (expected: element NAME COUNT)",
                    quote(text)
                ))
            } else if words[2].parse::<u64>().is_err() {
                Some(format!(
                    "the count of element {} is not a whole number: {}",
                    words[1],
                    quote(words[2])
                ))
            } else {
                Some(format!(
                    "element name {} is not an identifier (a letter or _, then letters, \
                     digits, _ or -)",
                    quote(words[1])
                ))
            }
        }
        "property" => {
            if !before.iter().any(|l| l.keyword() == "element") {
                Some("a property line before any element line".to_string())
            } else if words.get(1) == Some(&"list") {
                if words.len() != 5 {
                    Some(format!(
                        "garbled list property line {} (expected: property list COUNT_TYPE \
                         ITEM_TYPE NAME)",
                        quote(text)
                    ))
                } else {
                    unknown_type(words[2]).or_else(|| unknown_type(words[3]))
                }
            } else if words.len() != 3 {
                Some(format!(
                    "garbled property line {} (expected: property TYPE NAME)",
                    quote(text)
                ))
            } else {
                unknown_type(words[1])
            }
        }
        _ => Some(format!(
            "unrecognised header line {} (a garbled keyword, or data where the end_header \
             line is missing)",
            quote(text)
        )),
    };
    specific.unwrap_or_else(|| format!("ply-rs cannot parse the header line {}", quote(text)))
}

/// Maps ply-rs's element definitions to [`Element`]s, checking what ply-rs does not: that no
/// two elements, and no two properties of an element, share a name (ply-rs keys them by name,
/// so a repeated name would silently replace the earlier declaration and shift the record
/// layout) and that list counts have an integer type.
fn map_elements(
    lines: &[HeaderLine],
    header: &ply_rs::ply::Header,
) -> Result<Vec<Element>, PlyProblem> {
    use ply_rs::ply::{PropertyType, ScalarType};
    // The element and property lines, in order: ply-rs accepted the header, so each is one
    // declaration.
    let declarations: Vec<&HeaderLine> = lines
        .iter()
        .filter(|l| matches!(l.keyword(), "element" | "property"))
        .collect();
    let declared = header.elements.len()
        + header
            .elements
            .values()
            .map(|e| e.properties.len())
            .sum::<usize>();
    if declared != declarations.len() {
        return Err(duplicate_name(&declarations));
    }
    let scalar = |t: &ScalarType| match t {
        ScalarType::Char => Scalar::I8,
        ScalarType::UChar => Scalar::U8,
        ScalarType::Short => Scalar::I16,
        ScalarType::UShort => Scalar::U16,
        ScalarType::Int => Scalar::I32,
        ScalarType::UInt => Scalar::U32,
        ScalarType::Float => Scalar::F32,
        ScalarType::Double => Scalar::F64,
    };
    let mut lines = declarations.iter();
    let mut elements = Vec::with_capacity(header.elements.len());
    for def in header.elements.values() {
        lines.next();
        let mut props = Vec::with_capacity(def.properties.len());
        for prop in def.properties.values() {
            let line = lines.next().map_or(0, |l| l.number);
            let kind = match &prop.data_type {
                PropertyType::Scalar(t) => Kind::Scalar(scalar(t)),
                PropertyType::List(count, item) => {
                    let count = scalar(count);
                    if count.is_float() {
                        return Err(bad_header(
                            line,
                            format!(
                                "the count type of list {} is not an integer type",
                                prop.name
                            ),
                        ));
                    }
                    Kind::List {
                        count,
                        item: scalar(item),
                    }
                }
            };
            props.push(Property {
                name: prop.name.clone(),
                kind,
            });
        }
        elements.push(Element {
            name: def.name.clone(),
            count: def.count as u64,
            props,
        });
    }
    Ok(elements)
}

/// The problem for a header that repeats an element name, or a property name in an element.
fn duplicate_name(declarations: &[&HeaderLine]) -> PlyProblem {
    let mut elements: Vec<&str> = Vec::new();
    let mut properties: Vec<&str> = Vec::new();
    for line in declarations {
        let words = line.words();
        let name = words.last().copied().unwrap_or("");
        if words[0] == "element" {
            let name = words.get(1).copied().unwrap_or("");
            if elements.contains(&name) {
                return bad_header(
                    line.number,
                    format!(
                        "a second element named {} (element names must be unique)",
                        quote(name)
                    ),
                );
            }
            elements.push(name);
            properties.clear();
        } else {
            if properties.contains(&name) {
                return bad_header(
                    line.number,
                    format!(
                        "a second property named {} in element {} (property names must be \
                         unique)",
                        quote(name),
                        elements.last().copied().unwrap_or("")
                    ),
                );
            }
            properties.push(name);
        }
    }
    PlyProblem::BadHeader("ply-rs merged header declarations that share a name".into())
}

// ------------------------------------------------------------------------------------------
// Reading the data
// ------------------------------------------------------------------------------------------

/// Where a vertex property's value goes: indices into the value array of one point.
const SLOT_X: usize = 0;
const SLOT_N: usize = 3;
const SLOT_C: usize = 6;
const SLOT_EXTRA: usize = 9;
const SLOTS: usize = 10;

/// Per-property destination slot in the vertex element (`None`: skipped).
struct VertexPlan {
    slots: Vec<Option<usize>>,
    has_normals: bool,
    has_colors: bool,
    color_is_float: [bool; 3],
    /// Slot of the extra property asked for, when the vertex element has it.
    extra_slot: Option<usize>,
}

fn plan_vertex(vertex: &Element, extra: Option<&str>) -> Result<VertexPlan, PlyProblem> {
    let mut slots = vec![None; vertex.props.len()];
    for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
        match vertex.scalar(name) {
            Some((i, _)) => slots[i] = Some(SLOT_X + k),
            None if vertex.props.iter().any(|p| p.name == name) => {
                return Err(PlyProblem::BadHeader(format!(
                    "the vertex property \"{name}\" is a list, not a number"
                )));
            }
            None => return Err(PlyProblem::MissingCoordinate(name)),
        }
    }
    let normals = [["nx", "normal_x"], ["ny", "normal_y"], ["nz", "normal_z"]]
        .map(|names| vertex.scalar_any(&names));
    let has_normals = normals.iter().all(Option::is_some);
    if has_normals {
        for (k, found) in normals.iter().enumerate() {
            if let Some((i, _)) = found {
                slots[*i] = Some(SLOT_N + k);
            }
        }
    }
    let colors = [
        ["red", "r", "diffuse_red"],
        ["green", "g", "diffuse_green"],
        ["blue", "b", "diffuse_blue"],
    ]
    .map(|names| vertex.scalar_any(&names));
    let has_colors = colors.iter().all(Option::is_some);
    let mut color_is_float = [false; 3];
    if has_colors {
        for (k, found) in colors.iter().enumerate() {
            if let Some((i, ty)) = found {
                slots[*i] = Some(SLOT_C + k);
                color_is_float[k] = ty.is_float();
            }
        }
    }
    // The extra property reuses the slot of a property read anyway (e.g. "x"), else its own.
    let extra_slot = extra
        .and_then(|name| vertex.scalar(name))
        .map(|(i, _)| *slots[i].get_or_insert(SLOT_EXTRA));
    Ok(VertexPlan {
        slots,
        has_normals,
        has_colors,
        color_is_float,
        extra_slot,
    })
}

/// Accumulates points, counting the non-finite ones and the zero normals.
struct Builder {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    colors: Option<Vec<[u8; 3]>>,
    extra: Option<(usize, Vec<f64>)>,
    color_is_float: [bool; 3],
    non_finite: usize,
    zero_normals: usize,
}

impl Builder {
    fn new(plan: &VertexPlan, capacity: usize) -> Self {
        Builder {
            positions: Vec::with_capacity(capacity),
            normals: plan.has_normals.then(|| Vec::with_capacity(capacity)),
            colors: plan.has_colors.then(|| Vec::with_capacity(capacity)),
            extra: plan
                .extra_slot
                .map(|slot| (slot, Vec::with_capacity(capacity))),
            color_is_float: plan.color_is_float,
            non_finite: 0,
            zero_normals: 0,
        }
    }

    #[inline]
    fn push(&mut self, v: &[f64; SLOTS]) {
        let p = Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32);
        let n = Vec3::new(v[3] as f32, v[4] as f32, v[5] as f32);
        if !p.is_finite() || (self.normals.is_some() && !n.is_finite()) {
            self.non_finite += 1;
            return;
        }
        self.positions.push(p);
        if let Some(normals) = self.normals.as_mut() {
            let (x, y, z) = (n.x as f64, n.y as f64, n.z as f64);
            let len = (x * x + y * y + z * z).sqrt();
            if len < 1e-12 {
                self.zero_normals += 1;
                normals.push(Vec3::ZERO);
            } else if (len - 1.0).abs() > 1e-4 {
                normals.push(Vec3::new(
                    (x / len) as f32,
                    (y / len) as f32,
                    (z / len) as f32,
                ));
            } else {
                normals.push(n);
            }
        }
        if let Some(colors) = self.colors.as_mut() {
            let c = |k: usize| {
                let raw = v[SLOT_C + k];
                let value = if self.color_is_float[k] {
                    (raw * 255.0).round()
                } else {
                    raw
                };
                value.clamp(0.0, 255.0) as u8
            };
            colors.push([c(0), c(1), c(2)]);
        }
        if let Some((slot, extra)) = self.extra.as_mut() {
            extra.push(v[*slot]);
        }
    }

    fn finish(self, options: &ReadOptions) -> Result<(PointCloud, Option<Vec<f64>>), PlyProblem> {
        if self.non_finite > 0 && !options.drop_non_finite {
            return Err(PlyProblem::NonFinite {
                count: self.non_finite,
            });
        }
        if self.positions.is_empty() {
            return Err(PlyProblem::Empty);
        }
        let mut normals = self.normals;
        if options.require_normals && normals.is_none() {
            return Err(PlyProblem::MissingNormals);
        }
        if self.zero_normals > 0 {
            if options.require_normals {
                return Err(PlyProblem::ZeroNormals {
                    count: self.zero_normals,
                });
            }
            normals = None;
        }
        let cloud = PointCloud {
            positions: self.positions,
            normals,
            colors: self.colors,
        };
        Ok((cloud, self.extra.map(|(_, values)| values)))
    }
}

fn parse(
    bytes: &[u8],
    options: &ReadOptions,
    extra: Option<&str>,
) -> Result<(PointCloud, Option<Vec<f64>>), PlyProblem> {
    let header = parse_header(bytes)?;
    let vertex_index = header
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or(PlyProblem::NoVertexElement)?;
    let vertex = &header.elements[vertex_index];
    let plan = plan_vertex(vertex, extra)?;
    let body = bytes.get(header.body_start..).unwrap_or(&[]);
    let before = &header.elements[..vertex_index];
    let builder = match header.format {
        Format::Ascii => {
            let mut tokens = Tokens {
                bytes: body,
                pos: 0,
                line: header.body_line,
            };
            for element in before {
                skip_ascii(&mut tokens, element)?;
            }
            read_ascii_vertices(&mut tokens, vertex, &plan)?
        }
        Format::BinaryLittleEndian | Format::BinaryBigEndian => {
            let big = header.format == Format::BinaryBigEndian;
            let mut pos = 0usize;
            for element in before {
                pos = skip_binary(body, pos, element, big)?;
            }
            read_binary_vertices(body, pos, vertex, &plan, big)?
        }
    };
    let (cloud, values) = builder.finish(options)?;
    Ok((cloud, if extra.is_some() { values } else { None }))
}

/// Checks `element.count` against the records `remaining` bytes can hold at `min_size` bytes
/// each; returns the count as `usize`.
fn check_count(element: &Element, remaining: usize, min_size: usize) -> Result<usize, PlyProblem> {
    let available = (remaining / min_size.max(1)) as u64;
    if element.count > available {
        return Err(PlyProblem::CountExceedsData {
            element: element.name.clone(),
            declared: element.count,
            available,
        });
    }
    usize::try_from(element.count).map_err(|_| PlyProblem::CountExceedsData {
        element: element.name.clone(),
        declared: element.count,
        available,
    })
}

fn truncated(element: &Element, read: usize) -> PlyProblem {
    PlyProblem::Truncated {
        element: element.name.clone(),
        read: read as u64,
        declared: element.count,
    }
}

/// Reads a binary list length at `pos`.
fn binary_list_len(
    body: &[u8],
    pos: usize,
    count: Scalar,
    big: bool,
    element: &Element,
    index: usize,
) -> Result<u64, PlyProblem> {
    let value = count
        .decode(body, pos, big)
        .ok_or_else(|| truncated(element, index))?;
    if value < 0.0 {
        return Err(PlyProblem::BadListLength {
            element: element.name.clone(),
            index: index as u64,
            length: value as i64,
        });
    }
    Ok(value as u64)
}

/// Walks one binary record with list properties from `pos`; calls `scalar(property, at)` for
/// every scalar property and returns the position after the record.
fn walk_binary_record(
    body: &[u8],
    mut pos: usize,
    element: &Element,
    index: usize,
    big: bool,
    mut scalar: impl FnMut(usize, Scalar, usize),
) -> Result<usize, PlyProblem> {
    for (k, prop) in element.props.iter().enumerate() {
        let size = match prop.kind {
            Kind::Scalar(s) => {
                scalar(k, s, pos);
                s.size()
            }
            Kind::List { count, item } => {
                let n = binary_list_len(body, pos, count, big, element, index)?;
                usize::try_from(n)
                    .ok()
                    .and_then(|n| n.checked_mul(item.size()))
                    .and_then(|b| b.checked_add(count.size()))
                    .ok_or_else(|| truncated(element, index))?
            }
        };
        pos = pos
            .checked_add(size)
            .filter(|&p| p <= body.len())
            .ok_or_else(|| truncated(element, index))?;
    }
    Ok(pos)
}

/// Skips a binary element that precedes the vertices; returns the position after it.
fn skip_binary(body: &[u8], pos: usize, element: &Element, big: bool) -> Result<usize, PlyProblem> {
    let remaining = body.len().saturating_sub(pos);
    let min_size = element.min_binary_size();
    if min_size == 0 {
        return Ok(pos);
    }
    let count = check_count(element, remaining, min_size)?;
    if !element.has_lists() {
        // Fixed-size records: checked above to fit.
        return Ok(pos + count * min_size);
    }
    let mut pos = pos;
    for index in 0..count {
        pos = walk_binary_record(body, pos, element, index, big, |_, _, _| {})?;
    }
    Ok(pos)
}

fn read_binary_vertices(
    body: &[u8],
    pos: usize,
    vertex: &Element,
    plan: &VertexPlan,
    big: bool,
) -> Result<Builder, PlyProblem> {
    let remaining = body.len().saturating_sub(pos);
    let min_size = vertex.min_binary_size();
    let count = check_count(vertex, remaining, min_size)?;
    let mut builder = Builder::new(plan, count);
    let mut values = [0.0f64; SLOTS];
    if !vertex.has_lists() {
        // Fixed layout: (offset in record, type, slot) of every wanted property.
        let mut fields = Vec::new();
        let mut offset = 0;
        for (prop, slot) in vertex.props.iter().zip(&plan.slots) {
            if let Kind::Scalar(s) = prop.kind {
                if let Some(slot) = slot {
                    fields.push((offset, s, *slot));
                }
                offset += s.size();
            }
        }
        let data = body.get(pos..pos + count * min_size).unwrap_or(&[]);
        for record in data.chunks_exact(min_size.max(1)) {
            for &(offset, ty, slot) in &fields {
                values[slot] = ty.decode(record, offset, big).unwrap_or(f64::NAN);
            }
            builder.push(&values);
        }
        return Ok(builder);
    }
    let mut pos = pos;
    for index in 0..count {
        pos = walk_binary_record(body, pos, vertex, index, big, |k, ty, at| {
            if let Some(Some(slot)) = plan.slots.get(k) {
                values[*slot] = ty.decode(body, at, big).unwrap_or(f64::NAN);
            }
        })?;
        builder.push(&values);
    }
    Ok(builder)
}

/// Whitespace-separated tokens of an ascii body, with line numbers.
struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self) -> Option<&'a [u8]> {
        while let Some(&b) = self.bytes.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            if b == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        let start = self.pos;
        while self
            .bytes
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        (self.pos > start).then(|| &self.bytes[start..self.pos])
    }

    fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }
}

fn show(token: &[u8]) -> String {
    quote(&String::from_utf8_lossy(token))
}

/// Reads an ascii list length.
fn ascii_list_len(
    tokens: &mut Tokens,
    element: &Element,
    index: usize,
    prop: &str,
) -> Result<u64, PlyProblem> {
    let token = tokens.next().ok_or_else(|| truncated(element, index))?;
    let text = std::str::from_utf8(token).unwrap_or("");
    match text.parse::<i64>() {
        Ok(n) if n < 0 => Err(PlyProblem::BadListLength {
            element: element.name.clone(),
            index: index as u64,
            length: n,
        }),
        Ok(n) => Ok(n as u64),
        Err(_) => Err(PlyProblem::BadValue {
            line: tokens.line,
            detail: format!(
                "the length of list {prop} of {} record {index} is not a whole number: {}",
                element.name,
                show(token)
            ),
        }),
    }
}

/// Smallest ascii record, in values (a list is at least its length).
fn check_ascii_count(tokens: &Tokens, element: &Element) -> Result<usize, PlyProblem> {
    // n values take at least 2n - 1 bytes: a character each and a separator between them.
    let max_values = tokens.remaining().saturating_add(1) / 2;
    check_count(element, max_values, element.props.len())
}

fn skip_ascii(tokens: &mut Tokens, element: &Element) -> Result<(), PlyProblem> {
    if element.props.is_empty() {
        return Ok(());
    }
    let count = check_ascii_count(tokens, element)?;
    for index in 0..count {
        for prop in &element.props {
            let n = match prop.kind {
                Kind::Scalar(_) => 1,
                Kind::List { .. } => ascii_list_len(tokens, element, index, &prop.name)?,
            };
            for _ in 0..n {
                tokens.next().ok_or_else(|| truncated(element, index))?;
            }
        }
    }
    Ok(())
}

fn read_ascii_vertices(
    tokens: &mut Tokens,
    vertex: &Element,
    plan: &VertexPlan,
) -> Result<Builder, PlyProblem> {
    let count = check_ascii_count(tokens, vertex)?;
    let mut builder = Builder::new(plan, count);
    let mut values = [0.0f64; SLOTS];
    for index in 0..count {
        for (prop, slot) in vertex.props.iter().zip(&plan.slots) {
            match prop.kind {
                Kind::Scalar(_) => {
                    let token = tokens.next().ok_or_else(|| truncated(vertex, index))?;
                    if let Some(slot) = slot {
                        let value = std::str::from_utf8(token)
                            .ok()
                            .and_then(|t| t.parse::<f64>().ok());
                        values[*slot] = value.ok_or_else(|| PlyProblem::BadValue {
                            line: tokens.line,
                            detail: format!(
                                "property {} of vertex {index} is not a number: {}",
                                prop.name,
                                show(token)
                            ),
                        })?;
                    }
                }
                Kind::List { .. } => {
                    let n = ascii_list_len(tokens, vertex, index, &prop.name)?;
                    for _ in 0..n {
                        tokens.next().ok_or_else(|| truncated(vertex, index))?;
                    }
                }
            }
        }
        builder.push(&values);
    }
    Ok(builder)
}

// ------------------------------------------------------------------------------------------
// Writing
// ------------------------------------------------------------------------------------------

/// Options of [`write_ply`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WriteOptions {
    /// Write the cloud's colours (`uchar red, green, blue`) when it has some. Default: true.
    pub colors: bool,
    /// One extra `int` vertex property: its name (e.g. `"bone"`) and one value per point
    /// (each at most `i32::MAX`, or `u32::MAX` for "none", written as `-1`).
    pub labels: Option<(String, Vec<u32>)>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            colors: true,
            labels: None,
        }
    }
}

/// Property names a label may not take (they are written already or read as such).
const RESERVED: [&str; 9] = ["x", "y", "z", "nx", "ny", "nz", "red", "green", "blue"];

/// Writes `cloud` as a binary little-endian PLY to `path`, through a temporary sibling file
/// renamed into place (a failed write leaves any previous file untouched).
pub fn write_ply(
    path: impl AsRef<Path>,
    cloud: &PointCloud,
    options: &WriteOptions,
) -> Result<(), PlyError> {
    let path = path.as_ref();
    let fail = |problem| PlyError::new(path, problem);
    if path.is_dir() {
        return Err(fail(PlyProblem::IsDirectory));
    }
    validate(cloud, options).map_err(fail)?;
    let Some(file_name) = path.file_name() else {
        return Err(fail(PlyProblem::Write(io::Error::new(
            io::ErrorKind::InvalidInput,
            "the path has no file name",
        ))));
    };
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let tmp_name = format!(
        ".{}.{}-{}.tmp",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    let tmp = path.with_file_name(tmp_name);
    let result = (|| -> Result<(), PlyProblem> {
        let file = fs::File::create(&tmp).map_err(PlyProblem::Write)?;
        let mut writer = io::BufWriter::with_capacity(1 << 20, file);
        write_ply_to(&mut writer, cloud, options)?;
        writer
            .into_inner()
            .map_err(|e| PlyProblem::Write(e.into_error()))?;
        fs::rename(&tmp, path).map_err(PlyProblem::Write)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result.map_err(fail)
}

fn validate(cloud: &PointCloud, options: &WriteOptions) -> Result<(), PlyProblem> {
    let n = cloud.positions.len();
    let mismatch = |what: &str, len: usize| {
        PlyProblem::Inconsistent(format!("the cloud has {n} positions but {len} {what}"))
    };
    if let Some(normals) = &cloud.normals
        && normals.len() != n
    {
        return Err(mismatch("normals", normals.len()));
    }
    if let Some(colors) = &cloud.colors
        && options.colors
        && colors.len() != n
    {
        return Err(mismatch("colours", colors.len()));
    }
    if let Some((name, values)) = &options.labels {
        if values.len() != n {
            return Err(mismatch(&format!("\"{name}\" labels"), values.len()));
        }
        // A PLY identifier as ply-rs reads it: a letter or _, then letters, digits, _ or -.
        if !name
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            || RESERVED.contains(&name.as_str())
        {
            return Err(PlyProblem::Inconsistent(format!(
                "\"{name}\" cannot name a label property (use a letter or _, then letters, \
                 digits, _ or -, and not a coordinate, normal or colour name)"
            )));
        }
        if let Some(bad) = values
            .iter()
            .find(|&&v| v > i32::MAX as u32 && v != u32::MAX)
        {
            return Err(PlyProblem::Inconsistent(format!(
                "label {bad} does not fit the PLY int type"
            )));
        }
    }
    Ok(())
}

/// The header of [`write_ply`]'s files, written by ply-rs: `binary_little_endian 1.0`, one
/// comment, and one `vertex` element of `count` records with the properties asked for.
fn header_bytes(
    count: usize,
    normals: bool,
    colors: bool,
    label: Option<&str>,
) -> Result<Vec<u8>, PlyProblem> {
    use ply_rs::ply::{
        Addable, ElementDef, Encoding, Header, PropertyDef, PropertyType, ScalarType,
    };
    let mut vertex = ElementDef::new("vertex".to_string());
    vertex.count = count;
    let mut add = |name: &str, ty: ScalarType| {
        vertex
            .properties
            .add(PropertyDef::new(name.to_string(), PropertyType::Scalar(ty)));
    };
    for name in ["x", "y", "z"] {
        add(name, ScalarType::Float);
    }
    if normals {
        for name in ["nx", "ny", "nz"] {
            add(name, ScalarType::Float);
        }
    }
    if colors {
        for name in ["red", "green", "blue"] {
            add(name, ScalarType::UChar);
        }
    }
    if let Some(name) = label {
        add(name, ScalarType::Int);
    }
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.comments.push("written by pygmalion".to_string());
    header.elements.add(vertex);
    // Into memory first: ply-rs writes with `Write::write`, not `write_all`, which is only
    // complete for writers such as `Vec` (the caller's writer gets one `write_all`).
    let mut bytes = Vec::with_capacity(256);
    ply_rs::writer::Writer::<ply_rs::ply::DefaultElement>::new()
        .write_header(&mut bytes, &header)
        .map_err(PlyProblem::Write)?;
    Ok(bytes)
}

/// Writes `cloud` as a binary little-endian PLY to `writer` (see [`write_ply`]). The writer
/// should be buffered or take large writes well: the data goes out in chunks of about 1 MiB.
pub fn write_ply_to(
    writer: &mut impl Write,
    cloud: &PointCloud,
    options: &WriteOptions,
) -> Result<(), PlyProblem> {
    validate(cloud, options)?;
    let normals = cloud.normals.as_deref();
    let colors = cloud.colors.as_deref().filter(|_| options.colors);
    let labels = options.labels.as_ref();

    writer
        .write_all(&header_bytes(
            cloud.positions.len(),
            normals.is_some(),
            colors.is_some(),
            labels.map(|(name, _)| name.as_str()),
        )?)
        .map_err(PlyProblem::Write)?;

    let record = 12
        + if normals.is_some() { 12 } else { 0 }
        + if colors.is_some() { 3 } else { 0 }
        + if labels.is_some() { 4 } else { 0 };
    const CHUNK: usize = 1 << 20;
    let mut buf: Vec<u8> = Vec::with_capacity(CHUNK + record);
    for (i, p) in cloud.positions.iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            buf.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(n) = normals.and_then(|n| n.get(i)) {
            for v in [n.x, n.y, n.z] {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            buf.extend_from_slice(c);
        }
        if let Some(label) = labels.and_then(|(_, l)| l.get(i)) {
            // `u32::MAX` ("none") becomes -1; the others fit (checked above).
            buf.extend_from_slice(&(*label as i32).to_le_bytes());
        }
        if buf.len() >= CHUNK {
            writer.write_all(&buf).map_err(PlyProblem::Write)?;
            buf.clear();
        }
    }
    writer.write_all(&buf).map_err(PlyProblem::Write)?;
    writer.flush().map_err(PlyProblem::Write)
}
