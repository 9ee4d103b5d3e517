//! Loading Wavefront OBJ files for examples, tests, benches and the C helper `rq_obj_load`.
//!
//! A parser of its own rather than `tobj`: every refusal has to name the file and the line, and tell
//! an unreadable file from a malformed line from an index out of range (docs/shipping.md). It reads
//! only what a ray query needs: vertex positions (`v`) and polygonal faces (`f`).
//!
//! # Guarantees of a loaded [`MeshData`]
//! - Vertex `i` is the file's `i`-th `v` line (counting from 0), every coordinate finite. Vertices no
//!   face uses are kept, so indices keep their meaning in the file.
//! - Every index is below the vertex count (which fits in `u32`): a face may only name vertices defined
//!   on earlier lines, as the OBJ format says; negative indices count back from the last of those.
//! - Triangles are in file order; a face of `n` vertices `a b c d …` becomes the `n − 2` triangles
//!   `(a, b, c), (a, c, d), …` (a fan, as `tobj` triangulates).
//! - Texture and normal indices (`v/vt`, `v//vn`, `v/vt/vn`) must be integers and are otherwise
//!   ignored; so are `vt`, `vn`, `o`, `g`, `s`, `l`, `p`, materials, comments (`#` to the end of a
//!   line) and statements the format has but a ray query does not need.
//! - The optional fourth value of `v x y z [w]` and the colour of `v x y z r g b` must be numbers and
//!   are otherwise ignored.
//! - Growth of the vertex and index arrays is fallible: exhausted memory is
//!   [`ObjErrorKind::OutOfMemory`], not an abort.

extern crate std;

use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::string::{String, ToString};
use std::vec::Vec;

use crate::mesh::MeshData;

/// Why an OBJ file was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjErrorKind {
    /// The file could not be opened or read (missing, a directory, no permission, an I/O error).
    Unreadable,
    /// A `v` or `f` line is not what the format allows (too few values, a token that is not a
    /// number or an index, a coordinate that is not finite).
    Malformed,
    /// A face names vertex 0, or a vertex that is not defined on an earlier line.
    IndexOutOfRange,
    /// More vertices than a `u32` index can name.
    TooLarge,
    /// Memory for the vertices or triangles could not be reserved.
    OutOfMemory,
}

/// An OBJ file refused, with the file and (once reading started) the 1-based line that caused it.
/// Displays as `path:line: detail` (or `path: detail`), the form compilers use, so editors can jump
/// to it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjError {
    /// What went wrong.
    pub kind: ObjErrorKind,
    /// The file, as the caller named it.
    pub path: PathBuf,
    /// The 1-based line, `None` when the file could not be opened.
    pub line: Option<u64>,
    /// A sentence about the line, quoting the offending token (escaped, at most 32 bytes of it).
    pub detail: String,
}

impl fmt::Display for ObjError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(line) => write!(f, "{}:{line}: {}", self.path.display(), self.detail),
            None => write!(f, "{}: {}", self.path.display(), self.detail),
        }
    }
}

impl std::error::Error for ObjError {}

/// So that callers collecting errors as text can keep using `?`.
impl From<ObjError> for String {
    fn from(e: ObjError) -> String {
        e.to_string()
    }
}

/// Loads an OBJ file into one indexed triangle mesh (all objects and groups merged); see the module
/// documentation for what the result guarantees and what is refused.
pub fn load_obj(path: impl AsRef<Path>) -> Result<MeshData, ObjError> {
    let path = path.as_ref();
    let file = File::open(path).map_err(|e| ObjError {
        kind: ObjErrorKind::Unreadable,
        path: path.to_path_buf(),
        line: None,
        detail: std::format!("cannot open: {e}"),
    })?;
    parse_obj(BufReader::with_capacity(1 << 16, file), path)
}

/// Parses OBJ text from `reader`; `path` only names the source in errors. Same result and errors as
/// [`load_obj`] once the file is open.
pub fn parse_obj(mut reader: impl BufRead, path: &Path) -> Result<MeshData, ObjError> {
    let mut mesh = MeshData::default();
    let mut line = Vec::new();
    let mut line_no = 0u64;
    loop {
        line_no += 1;
        let fail = |kind, detail: String| ObjError {
            kind,
            path: path.to_path_buf(),
            line: Some(line_no),
            detail,
        };
        line.clear();
        match reader.read_until(b'\n', &mut line) {
            Ok(0) => return Ok(mesh),
            Ok(_) => {}
            Err(e) => {
                return Err(fail(
                    ObjErrorKind::Unreadable,
                    std::format!("cannot read: {e}"),
                ))
            }
        }
        // A UTF-8 byte-order mark (editors on Windows write one) is not part of the first line's
        // keyword: read as one, it hid the first `v` and shifted every index after it.
        let start = if line_no == 1 && line.starts_with(b"\xEF\xBB\xBF") {
            3
        } else {
            0
        };
        let text = match line[start..].iter().position(|&b| b == b'#') {
            Some(hash) => &line[start..start + hash],
            None => &line[start..],
        };
        let mut words = text
            .split(u8::is_ascii_whitespace)
            .filter(|w| !w.is_empty());
        let parsed = match words.next() {
            Some(b"v") => vertex(words, &mut mesh),
            Some(b"f") => face(words, &mut mesh),
            _ => Ok(()),
        };
        parsed.map_err(|(kind, detail)| fail(kind, detail))?;
    }
}

/// What a line is refused for, before the file and line are attached.
type LineError = (ObjErrorKind, String);

/// A token for a message: lossy UTF-8, escaped (no NUL or control character reaches C), at most 32
/// bytes of it.
fn quoted(token: &[u8]) -> String {
    let cut = &token[..token.len().min(32)];
    let more = if cut.len() < token.len() { "…" } else { "" };
    std::format!("{:?}{more}", String::from_utf8_lossy(cut))
}

fn number<T: core::str::FromStr>(token: &[u8]) -> Option<T> {
    core::str::from_utf8(token).ok()?.parse().ok()
}

fn out_of_memory(what: &str) -> LineError {
    (
        ObjErrorKind::OutOfMemory,
        std::format!("out of memory for the {what}"),
    )
}

/// `v x y z [w]` or `v x y z r g b`: appends (x, y, z).
fn vertex<'a>(words: impl Iterator<Item = &'a [u8]>, mesh: &mut MeshData) -> Result<(), LineError> {
    let mut values = [0f32; 6];
    let mut count = 0;
    for word in words {
        let value: f32 = number(word).ok_or_else(|| {
            (
                ObjErrorKind::Malformed,
                std::format!("malformed vertex: {} is not a number", quoted(word)),
            )
        })?;
        if count < 3 && !value.is_finite() {
            return Err((
                ObjErrorKind::Malformed,
                std::format!("vertex coordinate {} is not finite", quoted(word)),
            ));
        }
        if count < values.len() {
            values[count] = value;
        }
        count += 1;
    }
    if !matches!(count, 3 | 4 | 6) {
        return Err((
            ObjErrorKind::Malformed,
            std::format!(
                "malformed vertex: expected x y z, x y z w or x y z r g b, got {count} values"
            ),
        ));
    }
    if mesh.vertices.len() >= u32::MAX as usize {
        return Err((
            ObjErrorKind::TooLarge,
            std::format!("more than {} vertices", u32::MAX),
        ));
    }
    mesh.vertices
        .try_reserve(1)
        .map_err(|_| out_of_memory("vertices"))?;
    mesh.vertices.push([values[0], values[1], values[2]]);
    Ok(())
}

/// The position index of one face vertex (`v`, `v/vt`, `v//vn`, `v/vt/vn`), resolved against the
/// `defined` vertices before this line.
fn face_vertex(word: &[u8], defined: usize) -> Result<u32, LineError> {
    let malformed = || {
        (
            ObjErrorKind::Malformed,
            std::format!("malformed face: {} is not a vertex reference", quoted(word)),
        )
    };
    let mut parts = word.split(|&b| b == b'/');
    let position: i64 = parts.next().and_then(number).ok_or_else(malformed)?;
    let mut others = 0;
    for part in parts {
        others += 1;
        if others > 2 || (!part.is_empty() && number::<i64>(part).is_none()) {
            return Err(malformed());
        }
    }
    let defined_i = defined as i64;
    let index = if position < 0 {
        defined_i + position
    } else {
        position - 1
    };
    if position == 0 || index < 0 || index >= defined_i {
        return Err((
            ObjErrorKind::IndexOutOfRange,
            std::format!(
                "face vertex index {position} is out of range: {defined} vertices are defined before this line"
            ),
        ));
    }
    // In range of `defined`, which never exceeds u32::MAX (see `vertex`).
    Ok(index as u32)
}

/// `f a b c …`: appends the fan (a, b, c), (a, c, d), ….
fn face<'a>(words: impl Iterator<Item = &'a [u8]>, mesh: &mut MeshData) -> Result<(), LineError> {
    let defined = mesh.vertices.len();
    let mut corners = [0u32; 2];
    let mut count = 0usize;
    for word in words {
        // A refused line refuses the file, so what this face already appended does not matter.
        let v = face_vertex(word, defined)?;
        match count {
            0 | 1 => corners[count] = v,
            _ => {
                mesh.indices
                    .try_reserve(1)
                    .map_err(|_| out_of_memory("triangles"))?;
                mesh.indices.push([corners[0], corners[1], v]);
                corners[1] = v;
            }
        }
        count += 1;
    }
    if count < 3 {
        return Err((
            ObjErrorKind::Malformed,
            std::format!("malformed face: expected at least 3 vertices, got {count}"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<MeshData, ObjError> {
        parse_obj(text.as_bytes(), Path::new("t.obj"))
    }

    fn refused(text: &str) -> ObjError {
        parse(text).expect_err("the text was accepted")
    }

    #[test]
    fn positions_faces_and_fans() {
        let m = parse(
            "# comment\r\nv 0 0 0\r\nv 1 0 0 1\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n\
             vt 0 0\nvn 0 0 1\no quad\ng part\ns off\nusemtl none\nf 1/1/1 2/1/1 3//1 4 # fan\n\
             l 1 2\nv 0 0 1\nf -1 -5 -4\n",
        )
        .unwrap();
        assert_eq!(m.vertices.len(), 5);
        assert_eq!(m.vertices[1], [1.0, 0.0, 0.0], "w is ignored");
        assert_eq!(m.vertices[4], [0.0, 0.0, 1.0]);
        assert_eq!(m.indices, [[0, 1, 2], [0, 2, 3], [4, 0, 1]]);
    }

    /// A byte-order mark before the first line is not part of its keyword (a review's file lost
    /// its first vertex to it and shifted every index); elsewhere it is no keyword.
    #[test]
    fn a_byte_order_mark_is_skipped() {
        let m = parse("\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.vertices[0], [0.0, 0.0, 0.0]);
        assert_eq!(m.indices, [[0, 1, 2]]);
        let later = parse("v 0 0 0\n\u{feff}v 1 0 0\n").unwrap();
        assert_eq!(later.vertices.len(), 1);
    }

    #[test]
    fn empty_text_is_an_empty_mesh() {
        let m = parse("").unwrap();
        assert!(m.vertices.is_empty() && m.indices.is_empty());
        let m = parse("# only a comment\n\n   \n").unwrap();
        assert!(m.vertices.is_empty() && m.indices.is_empty());
    }

    #[test]
    fn refusals_name_the_line_and_the_reason() {
        let cases: [(&str, ObjErrorKind, u64, &str); 12] = [
            ("v 0 0\n", ObjErrorKind::Malformed, 1, "got 2 values"),
            (
                "v 0 0 0\nv 0 x 0\n",
                ObjErrorKind::Malformed,
                2,
                "\"x\" is not a number",
            ),
            ("v 0 0 0 1 1\n", ObjErrorKind::Malformed, 1, "got 5 values"),
            (
                "v 0 nan 0\n",
                ObjErrorKind::Malformed,
                1,
                "\"nan\" is not finite",
            ),
            ("v 0 0 inf\n", ObjErrorKind::Malformed, 1, "not finite"),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n",
                ObjErrorKind::Malformed,
                4,
                "got 2",
            ),
            (
                "v 0 0 0\nf 1 1/x 1\n",
                ObjErrorKind::Malformed,
                2,
                "\"1/x\"",
            ),
            (
                "v 0 0 0\nf 1 1/1/1/1 1\n",
                ObjErrorKind::Malformed,
                2,
                "\"1/1/1/1\"",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
                ObjErrorKind::IndexOutOfRange,
                4,
                "index 9",
            ),
            (
                "v 0 0 0\nv 1 0 0\nf 0 1 2\n",
                ObjErrorKind::IndexOutOfRange,
                3,
                "index 0",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n",
                ObjErrorKind::IndexOutOfRange,
                4,
                "index -4",
            ),
            // Only earlier vertices count: a forward reference is out of range.
            (
                "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n",
                ObjErrorKind::IndexOutOfRange,
                3,
                "2 vertices",
            ),
        ];
        for (text, kind, line, needle) in cases {
            let e = refused(text);
            assert_eq!((e.kind, e.line), (kind, Some(line)), "{text:?}: {e}");
            assert!(e.detail.contains(needle), "{text:?}: {e}");
            assert!(
                e.to_string().starts_with(&std::format!("t.obj:{line}: ")),
                "{e}"
            );
        }
    }

    #[test]
    fn quoted_tokens_are_escaped_and_short() {
        let e = refused("v 0 0 \0\x01\n");
        assert!(e.detail.contains(r#""\0\u{1}""#), "{e}");
        let long = "9".repeat(40) + "x";
        let e = refused(&std::format!("v 0 0 {long}\n"));
        assert!(
            e.detail.contains(&std::format!("\"{}\"…", &long[..32])),
            "{e}"
        );
    }

    #[test]
    fn bytes_that_are_not_utf8_are_fine_outside_numbers() {
        let mut text = b"o caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".to_vec();
        let m = parse_obj(&text[..], Path::new("t.obj")).unwrap();
        assert_eq!(m.indices.len(), 1);
        text.extend_from_slice(b"v 0 0 \xff\n");
        let e = parse_obj(&text[..], Path::new("t.obj")).unwrap_err();
        assert_eq!((e.kind, e.line), (ObjErrorKind::Malformed, Some(6)));
    }

    #[test]
    fn a_missing_file_is_unreadable_without_a_line() {
        let e = load_obj("no/such/file.obj").unwrap_err();
        assert_eq!((e.kind, e.line), (ObjErrorKind::Unreadable, None));
        assert!(
            e.to_string().starts_with("no/such/file.obj: cannot open: "),
            "{e}"
        );
    }

    #[test]
    #[cfg(unix)]
    fn a_directory_is_unreadable_at_line_1() {
        let e = load_obj(".").unwrap_err();
        assert_eq!((e.kind, e.line), (ObjErrorKind::Unreadable, Some(1)), "{e}");
    }
}
