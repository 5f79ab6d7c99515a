//! OBJ and MTL text as real exporters write it, made into what a strict parser reads.
//!
//! Wavefront OBJ has no specification beyond Wavefront's 1992 appendix, and files in the wild
//! (Debian's assimp test models are a fair sample) carry UTF-16 with a byte-order mark, Latin-1
//! material names, `\` line continuations, numbers like `3.1+e2`, and materials with empty names.
//! This pass decodes the bytes, joins continued lines, checks every number of the vertex
//! statements (reading the longest number a malformed token starts with, with a warning) and
//! names unnamed materials, keeping for each line the source line it came from, so that every
//! error names a line of the file the user has.

/// Name given to materials whose name is empty (`newmtl` / `usemtl` with nothing after them).
pub const UNNAMED: &str = "unnamed";

/// Normalised text and where each of its lines came from.
#[derive(Debug, Clone, Default)]
pub struct Text {
    /// The text, one statement per line, `\n`-terminated.
    pub text: String,
    /// For line `i` of `text`, its 1-based line number in the source.
    pub source_line: Vec<usize>,
    /// What was read leniently, one line each ("line 12: ...").
    pub warnings: Vec<String>,
}

impl Text {
    /// The source line number of normalised line `i` (0-based).
    pub fn line(&self, i: usize) -> usize {
        self.source_line
            .get(i)
            .copied()
            .unwrap_or_else(|| self.source_line.last().map_or(1, |l| l + 1))
    }
}

/// Decodes bytes as UTF-8, UTF-16 (with a byte-order mark) or, failing those, Latin-1; returns
/// the text and the name of the encoding when it was not UTF-8.
pub fn decode(bytes: &[u8]) -> (String, Option<&'static str>) {
    let utf16 = |be: bool| {
        let units = bytes[2..].chunks_exact(2).map(|c| {
            if be {
                u16::from_be_bytes([c[0], c[1]])
            } else {
                u16::from_le_bytes([c[0], c[1]])
            }
        });
        char::decode_utf16(units)
            .map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER))
            .collect::<String>()
    };
    match bytes {
        [0xEF, 0xBB, 0xBF, rest @ ..] => (String::from_utf8_lossy(rest).into_owned(), None),
        [0xFE, 0xFF, ..] => (utf16(true), Some("UTF-16BE")),
        [0xFF, 0xFE, ..] => (utf16(false), Some("UTF-16LE")),
        _ => match std::str::from_utf8(bytes) {
            Ok(s) => (s.to_string(), None),
            Err(_) => (bytes.iter().map(|&b| b as char).collect(), Some("Latin-1")),
        },
    }
}

/// Normalises OBJ text (see the module documentation). Errors name the source line.
pub fn obj(src: &str) -> Result<Text, String> {
    let mut out = Text::default();
    // Vertices, texture coordinates and normals so far: face indices are checked against them.
    let mut counts = [0i64; 3];
    for (line_no, line) in logical_lines(src, OBJ_KEYWORDS) {
        let mut words = line.split_whitespace();
        let normalised = match words.next() {
            Some(kw @ ("v" | "vn" | "vt" | "vp")) => {
                let mut fields = vec![kw.to_string()];
                for (k, w) in words.enumerate() {
                    let x = number(w, line_no, &mut out.warnings)?;
                    if kw == "v" && k < 3 && !x.is_finite() {
                        return Err(format!(
                            "line {line_no}: vertex position '{w}' is not a finite number"
                        ));
                    }
                    // Rust prints f64 so that it reads back exactly.
                    fields.push(if x.is_finite() {
                        format!("{x}")
                    } else {
                        "NaN".into()
                    });
                }
                match kw {
                    "v" => counts[0] += 1,
                    "vt" => counts[1] += 1,
                    "vn" => counts[2] += 1,
                    _ => {}
                }
                fields.join(" ")
            }
            Some(kw @ ("f" | "l" | "p")) => {
                let mut fields = vec![kw.to_string()];
                for w in words {
                    fields
                        .push(face_vertex(w, &counts).map_err(|e| format!("line {line_no}: {e}"))?);
                }
                if fields.len() == 1 {
                    out.warnings
                        .push(format!("line {line_no}: '{kw}' without vertices, skipped"));
                    String::new()
                } else if kw == "f" {
                    fields.join(" ")
                } else {
                    // Points and lines are never drawn; dropped here, because tobj reads a
                    // polyline of three or more points as a face even with `ignore_lines`.
                    String::new()
                }
            }
            Some("usemtl") if words.next().is_none() => {
                out.warnings.push(format!(
                    "line {line_no}: 'usemtl' without a name: material '{UNNAMED}'"
                ));
                format!("usemtl {UNNAMED}")
            }
            _ => line.trim().to_string(),
        };
        out.text.push_str(&normalised);
        out.text.push('\n');
        out.source_line.push(line_no);
    }
    Ok(out)
}

/// Normalises MTL text: encodings and continuations as for OBJ, unnamed materials named,
/// colours with one value expanded to three (the MTL format says `g` and `b` default to `r`),
/// and statements whose values cannot be read dropped with a warning (that property keeps its
/// default; the rest of the material stays).
pub fn mtl(src: &str) -> Text {
    let mut out = Text::default();
    for (line_no, line) in logical_lines(src, MTL_KEYWORDS) {
        let mut words = line.split_whitespace();
        let kw = words.next();
        let values: Vec<&str> = words.collect();
        let mut drop = |why: &str| {
            out.warnings.push(format!("line {line_no}: {why}: ignored"));
            String::new()
        };
        let normalised = match (kw, values.len()) {
            (Some("newmtl"), 0) => {
                out.warnings.push(format!(
                    "line {line_no}: 'newmtl' without a name: material '{UNNAMED}'"
                ));
                format!("newmtl {UNNAMED}")
            }
            (Some(k @ ("Ka" | "Kd" | "Ks" | "Ke" | "Tf")), n) => {
                let xs: Option<Vec<f64>> = values
                    .iter()
                    .map(|v| v.parse::<f64>().ok().filter(|x| x.is_finite()))
                    .collect();
                match xs {
                    Some(xs) if n >= 1 => {
                        let rgb = [
                            xs[0],
                            *xs.get(1).unwrap_or(&xs[0]),
                            *xs.get(2).or(xs.get(1)).unwrap_or(&xs[0]),
                        ];
                        format!("{k} {} {} {}", rgb[0], rgb[1], rgb[2])
                    }
                    _ => drop(&format!("'{k}' is not one to three numbers")),
                }
            }
            (Some(k @ ("Ns" | "Ni" | "d" | "Tr")), _) => match values
                .first()
                .and_then(|v| v.parse::<f64>().ok())
                .filter(|x| x.is_finite())
            {
                Some(x) => format!("{k} {x}"),
                None => drop(&format!("'{k}' is not a number")),
            },
            (Some("illum"), _) => match values.first().and_then(|v| v.parse::<u8>().ok()) {
                Some(x) => format!("illum {x}"),
                None => drop("'illum' is not a small integer"),
            },
            (Some(k), 0) if k.starts_with("map_") || k == "bump" => {
                drop(&format!("'{k}' without a file"))
            }
            _ => line.trim().to_string(),
        };
        out.text.push_str(&normalised);
        out.text.push('\n');
        out.source_line.push(line_no);
    }
    out
}

/// OBJ statement keywords: a line starting with one begins a statement of its own, even after
/// a line ending in `\` (writers that end every face line with a stray `\` exist).
const OBJ_KEYWORDS: &[&str] = &[
    "v", "vt", "vn", "vp", "f", "l", "p", "o", "g", "s", "usemtl", "mtllib",
];
/// MTL statement keywords, likewise (and every `map_*`).
const MTL_KEYWORDS: &[&str] = &[
    "newmtl", "Ka", "Kd", "Ks", "Ke", "Tf", "Ns", "Ni", "d", "Tr", "illum", "bump",
];

/// Lines with `\`-continuations joined, each with the 1-based number of its first source line.
fn logical_lines(src: &str, keywords: &[&str]) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut pending: Option<(usize, String)> = None;
    for (i, raw) in src.split('\n').enumerate() {
        let line = raw.strip_suffix('\r').unwrap_or(raw);
        let starts_statement = line
            .split_whitespace()
            .next()
            .is_some_and(|w| keywords.contains(&w) || w.starts_with('#') || w.starts_with("map_"));
        if starts_statement && let Some(p) = pending.take() {
            out.push(p);
        }
        let (start, mut text) = pending.take().unwrap_or((i + 1, String::new()));
        let trimmed = line.trim_end();
        if let Some(head) = trimmed.strip_suffix('\\') {
            text.push_str(head);
            text.push(' ');
            pending = Some((start, text));
        } else {
            text.push_str(line);
            out.push((start, text));
        }
    }
    if let Some(p) = pending {
        out.push(p);
    }
    out
}

/// One vertex of a face (`v`, `v/vt`, `v//vn`, `v/vt/vn`), with each index checked against the
/// elements defined so far (1-based; negative counts back from the last) and written as an
/// absolute index.
fn face_vertex(w: &str, counts: &[i64; 3]) -> Result<String, String> {
    const WHAT: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    let parts: Vec<&str> = w.split('/').collect();
    if parts.len() > 3 || parts[0].is_empty() {
        return Err(format!(
            "'{w}' is not a face vertex (v, v/vt, v//vn or v/vt/vn)"
        ));
    }
    let mut out = Vec::with_capacity(parts.len());
    for (k, p) in parts.iter().enumerate() {
        if p.is_empty() {
            out.push(String::new());
            continue;
        }
        let i: i64 = p
            .parse()
            .map_err(|_| format!("'{w}': '{p}' is not an index"))?;
        let abs = if i < 0 { counts[k] + 1 + i } else { i };
        if i == 0 || abs < 1 || abs > counts[k] {
            return Err(format!(
                "'{w}': {} index {i} is out of range (1 to {} so far)",
                WHAT[k], counts[k]
            ));
        }
        out.push(abs.to_string());
    }
    Ok(out.join("/"))
}

/// A number as OBJ writers write it; a token that is not one is read as the longest number it
/// starts with (as assimp and most readers do: `3.1+e2` is 3.1), with a warning.
fn number(w: &str, line_no: usize, warnings: &mut Vec<String>) -> Result<f64, String> {
    if let Ok(x) = w.parse::<f64>() {
        return Ok(x);
    }
    let prefix = (1..w.len())
        .rev()
        .filter(|&n| w.is_char_boundary(n))
        .find_map(|n| w[..n].parse::<f64>().ok().map(|x| (n, x)));
    match prefix {
        Some((n, x)) if !w[..n].eq_ignore_ascii_case("inf") => {
            warnings.push(format!("line {line_no}: '{w}' read as {x}"));
            Ok(x)
        }
        _ => Err(format!("line {line_no}: '{w}' is not a number")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn continued_lines_join_and_keep_their_first_line_number() {
        let t = obj("v 1 2 \\\n 3\nf 1 1 1\n").unwrap();
        assert_eq!(t.text, "v 1 2 3\nf 1 1 1\n\n");
        assert_eq!(t.source_line, vec![1, 3, 4]);
    }

    #[test]
    fn a_stray_backslash_before_a_new_statement_does_not_join_it() {
        let t = mtl("Kd 1 \\\nKs 1 2 3\n");
        assert_eq!(t.text, "Kd 1 1 1\nKs 1 2 3\n\n");
    }

    #[test]
    fn malformed_numbers_read_their_longest_number_with_a_warning() {
        let t = obj("v 1e+2 2.e1 3.1+e2\n").unwrap();
        assert!(t.text.starts_with("v 100 20 3.1\n"), "{}", t.text);
        assert_eq!(t.warnings.len(), 1);
        let e = obj("\n\nv 1 x 2\n").unwrap_err();
        assert_eq!(e, "line 3: 'x' is not a number");
    }

    #[test]
    fn utf16_and_latin1_decode() {
        let be: Vec<u8> = [0xFE, 0xFF]
            .into_iter()
            .chain("v 1".encode_utf16().flat_map(u16::to_be_bytes))
            .collect();
        assert_eq!(decode(&be), ("v 1".to_string(), Some("UTF-16BE")));
        assert_eq!(decode(b"usemtl Terraind\xe4k").0, "usemtl Terraindäk");
    }

    #[test]
    fn face_indices_are_checked_and_made_absolute() {
        let t = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n").unwrap();
        assert!(t.text.contains("f 1 2 3\n"), "{}", t.text);
        assert_eq!(
            obj("v 0 0 0\nf 1 0 1\n").unwrap_err(),
            "line 2: '0': vertex index 0 is out of range (1 to 1 so far)"
        );
        assert!(
            obj("v 0 0 0\nf 1 -5 1\n")
                .unwrap_err()
                .starts_with("line 2: '-5'")
        );
        assert!(
            obj("v 0 0 0\nf 1/1 1 1\n")
                .unwrap_err()
                .contains("texture coordinate index 1")
        );
    }

    #[test]
    fn short_and_unreadable_mtl_values_are_expanded_or_dropped() {
        let t = mtl("newmtl a\nKs 0\nKd 0.5 x 1\nNs high\nmap_Kd\n");
        assert!(
            t.text.starts_with("newmtl a\nKs 0 0 0\n\n\n\n"),
            "{}",
            t.text
        );
        assert_eq!(t.warnings.len(), 3, "{:?}", t.warnings);
    }

    #[test]
    fn unnamed_materials_get_a_name_in_obj_and_mtl() {
        assert!(
            obj("usemtl \n")
                .unwrap()
                .text
                .starts_with("usemtl unnamed\n")
        );
        assert!(
            mtl("newmtl \nKd 1 1 1\n")
                .text
                .starts_with("newmtl unnamed\n")
        );
    }
}
