//! Buffers and bufferViews (glTF 2.0 §3.6.1), including views compressed with
//! `EXT_meshopt_compression` (gltfpack's default output), decoded with meshoptimizer's decoders.
//!
//! Every buffer is loaded once (a `data:` URI, a file beside the glTF, or the GLB's BIN chunk)
//! and checked against its declared length; every view is checked against its buffer, or
//! decoded, before any accessor reads it. A view that is broken only fails the accessors that
//! use it, with a message naming the view.

use ::gltf::json;
use base64::Engine;
use serde_json::Value;
use std::path::Path;

/// The extension that compresses bufferViews.
pub const MESHOPT: &str = "EXT_meshopt_compression";

/// Largest decoded meshopt view we accept (bytes): a bound against tiny files that claim
/// gigabytes.
const MAX_DECODED: u64 = 1 << 30;

/// The loaded buffers: `None` for a buffer without data (a meshopt fallback placeholder).
pub struct Buffers(Vec<Option<Vec<u8>>>);

impl Buffers {
    /// Loads every buffer of `root`. `base` is the directory external URIs are relative to
    /// (`None`: external files are refused, as for bytes that came from no file); `blob` is the
    /// GLB's BIN chunk. A URI found only with `\` read as `/` or without regard to case
    /// ([`crate::import::files::find`]) adds a warning.
    pub fn load(
        root: &json::Root,
        raw: &Value,
        base: Option<&Path>,
        mut blob: Option<Vec<u8>>,
        warnings: &mut Vec<String>,
    ) -> Result<Buffers, String> {
        let mut out = Vec::with_capacity(root.buffers.len());
        for (i, b) in root.buffers.iter().enumerate() {
            let declared = b.byte_length.0;
            let fallback =
                raw["buffers"][i]["extensions"][MESHOPT]["fallback"] == Value::Bool(true);
            let data = match b.uri.as_deref() {
                Some(uri) if uri.starts_with("data:") => {
                    Some(data_uri(uri).map_err(|e| format!("buffer {i}: {e}"))?)
                }
                Some(uri) if uri.contains("://") => {
                    return Err(format!("buffer {i}: URI '{uri}' is not a local file"));
                }
                Some(uri) => {
                    let Some(dir) = base else {
                        return Err(format!(
                            "buffer {i}: external file '{uri}' without a directory to read it from"
                        ));
                    };
                    let name = urlencoding::decode(uri)
                        .map_err(|_| format!("buffer {i}: URI '{uri}' is not valid UTF-8"))?;
                    let found = crate::import::files::find(dir, &name)
                        .map_err(|e| format!("buffer {i}: {e}"))?;
                    warnings.extend(found.warning.map(|w| format!("buffer {i}: {w}")));
                    Some(
                        std::fs::read(&found.path)
                            .map_err(|e| format!("buffer {i}: {}: {e}", found.path.display()))?,
                    )
                }
                None if i == 0 && blob.is_some() => blob.take(),
                None if fallback => None,
                None => {
                    return Err(format!(
                        "buffer {i} has no URI and there is no GLB binary chunk"
                    ));
                }
            };
            if let Some(d) = &data
                && (d.len() as u64) < declared
            {
                return Err(format!(
                    "buffer {i}: {} bytes, but it declares {declared}",
                    d.len()
                ));
            }
            out.push(data);
        }
        Ok(Buffers(out))
    }

    fn get(&self, buffer: usize) -> Option<&[u8]> {
        self.0.get(buffer).and_then(|b| b.as_deref())
    }
}

/// Where a view's bytes are.
enum View {
    /// `len` bytes of buffer `buffer` from `start`.
    Slice {
        buffer: usize,
        start: usize,
        len: usize,
    },
    /// Decoded meshopt data (4-byte aligned storage).
    Decoded(Vec<u32>, usize),
    /// What is wrong with it.
    Broken(String),
}

/// Every bufferView of a document, checked or decoded.
pub struct Views {
    buffers: Buffers,
    views: Vec<View>,
    strides: Vec<Option<usize>>,
}

impl Views {
    /// Checks every view against its buffer and decodes the meshopt-compressed ones.
    pub fn new(root: &json::Root, raw: &Value, buffers: Buffers) -> Views {
        let mut views = Vec::with_capacity(root.buffer_views.len());
        let mut strides = Vec::with_capacity(root.buffer_views.len());
        for (i, v) in root.buffer_views.iter().enumerate() {
            let ext = &raw["bufferViews"][i]["extensions"][MESHOPT];
            // A decoded vertex view is `count` elements of the extension's byteStride.
            let ext_stride = (ext["mode"] == "ATTRIBUTES")
                .then(|| ext["byteStride"].as_u64())
                .flatten();
            strides.push(
                v.byte_stride
                    .map(|s| s.0)
                    .or(ext_stride.map(|s| s as usize)),
            );
            let view = if ext.is_object() {
                match decode_meshopt(ext, &buffers) {
                    Ok((data, len)) => View::Decoded(data, len),
                    Err(e) => View::Broken(format!("bufferView {i} ({MESHOPT}): {e}")),
                }
            } else {
                let (buffer, start, len) = (
                    v.buffer.value(),
                    v.byte_offset.map_or(0, |o| o.0),
                    v.byte_length.0,
                );
                match buffers.get(buffer) {
                    None => View::Broken(format!("bufferView {i}: buffer {buffer} has no data")),
                    Some(b)
                        if start
                            .checked_add(len)
                            .is_none_or(|end| end > b.len() as u64) =>
                    {
                        View::Broken(format!(
                            "bufferView {i}: bytes {start}..{} overrun buffer {buffer} ({} bytes)",
                            start.saturating_add(len),
                            b.len()
                        ))
                    }
                    Some(_) => View::Slice {
                        buffer,
                        start: start as usize,
                        len: len as usize,
                    },
                }
            };
            views.push(view);
        }
        Views {
            buffers,
            views,
            strides,
        }
    }

    /// The bytes of view `i`, or what is wrong with it.
    pub fn bytes(&self, i: usize) -> Result<&[u8], String> {
        match self.views.get(i) {
            Some(View::Slice { buffer, start, len }) => {
                Ok(&self.buffers.get(*buffer).unwrap_or(&[])[*start..*start + *len])
            }
            Some(View::Decoded(data, len)) => Ok(&bytemuck::cast_slice(data)[..*len]),
            Some(View::Broken(e)) => Err(e.clone()),
            None => Err(format!("bufferView {i} does not exist")),
        }
    }

    /// The byteStride of view `i`, when it has one.
    pub fn stride(&self, i: usize) -> Option<usize> {
        self.strides.get(i).copied().flatten()
    }
}

/// Decodes a `data:` URI with base64 content.
pub(super) fn data_uri(uri: &str) -> Result<Vec<u8>, String> {
    let (_, payload) = uri.split_once(";base64,").ok_or("data URI is not base64")?;
    base64::engine::general_purpose::STANDARD
        .decode(payload.trim())
        .map_err(|e| format!("data URI: {e}"))
}

/// Decodes one `EXT_meshopt_compression` view into `count × byteStride` bytes
/// (the extension's specification: modes ATTRIBUTES, TRIANGLES, INDICES; filters NONE,
/// OCTAHEDRAL, QUATERNION, EXPONENTIAL, COLOR).
#[allow(unsafe_code)] // meshoptimizer's C decoders: see the SAFETY notes below.
fn decode_meshopt(ext: &Value, buffers: &Buffers) -> Result<(Vec<u32>, usize), String> {
    let num = |k: &str| ext[k].as_u64();
    let (Some(buffer), Some(length), Some(stride), Some(count)) = (
        num("buffer"),
        num("byteLength"),
        num("byteStride"),
        num("count"),
    ) else {
        return Err("buffer, byteLength, byteStride and count are required".into());
    };
    let offset = num("byteOffset").unwrap_or(0);
    let src = buffers
        .get(buffer as usize)
        .ok_or_else(|| format!("buffer {buffer} has no data"))?;
    let end = offset
        .checked_add(length)
        .filter(|&e| e <= src.len() as u64)
        .ok_or_else(|| {
            format!(
                "bytes {offset}..{} overrun buffer {buffer} ({} bytes)",
                offset.saturating_add(length),
                src.len()
            )
        })?;
    let src = &src[offset as usize..end as usize];
    let size = count
        .checked_mul(stride)
        .filter(|&s| s <= MAX_DECODED)
        .ok_or_else(|| format!("{count} × {stride} bytes decoded is more than {MAX_DECODED}"))?;
    let (count, stride) = (count as usize, stride as usize);
    let mode = ext["mode"].as_str().unwrap_or("");
    let filter = ext["filter"].as_str().unwrap_or("NONE");
    let mut out = vec![0u32; (size as usize).div_ceil(4)];
    let dst = out.as_mut_ptr().cast::<std::ffi::c_void>();
    // SAFETY: `out` holds at least `count * stride` bytes, exactly what each decoder writes for
    // `count` elements of `stride` bytes; `src` is a bounds-checked slice. The decoders are
    // documented as safe on untrusted input (they return < 0 on malformed data).
    let rc = unsafe {
        match mode {
            "ATTRIBUTES" if stride % 4 == 0 && stride <= 256 => {
                meshopt::ffi::meshopt_decodeVertexBuffer(
                    dst,
                    count,
                    stride,
                    src.as_ptr(),
                    src.len(),
                )
            }
            "TRIANGLES" if (stride == 2 || stride == 4) && count % 3 == 0 => {
                meshopt::ffi::meshopt_decodeIndexBuffer(dst, count, stride, src.as_ptr(), src.len())
            }
            "INDICES" if stride == 2 || stride == 4 => meshopt::ffi::meshopt_decodeIndexSequence(
                dst,
                count,
                stride,
                src.as_ptr(),
                src.len(),
            ),
            _ => {
                return Err(format!(
                    "mode '{mode}' with byteStride {stride} and count {count} is not valid"
                ));
            }
        }
    };
    if rc < 0 {
        // Every meshopt stream starts with a header byte: 0xa? for vertices, 0xe? for indices.
        let header = if mode == "ATTRIBUTES" { 0xa0 } else { 0xe0 };
        return Err(match src.first() {
            Some(b) if b & 0xf0 != header => format!(
                "the data is not meshopt-encoded (it starts with byte 0x{b:02x}, not a meshopt header 0x{header:02x})"
            ),
            _ => format!("the compressed data is malformed (decoder returned {rc})"),
        });
    }
    if mode == "ATTRIBUTES" {
        // SAFETY: as above; each filter rewrites `count` elements of `stride` bytes in place,
        // with the strides the extension allows for it (checked here).
        unsafe {
            match filter {
                "NONE" => {}
                "OCTAHEDRAL" if stride == 4 || stride == 8 => {
                    meshopt::ffi::meshopt_decodeFilterOct(dst, count, stride)
                }
                "QUATERNION" if stride == 8 => {
                    meshopt::ffi::meshopt_decodeFilterQuat(dst, count, stride)
                }
                "EXPONENTIAL" => meshopt::ffi::meshopt_decodeFilterExp(dst, count, stride),
                "COLOR" if stride == 4 || stride == 8 => {
                    meshopt::ffi::meshopt_decodeFilterColor(dst, count, stride)
                }
                other => {
                    return Err(format!(
                        "filter '{other}' with byteStride {stride} is not valid"
                    ));
                }
            }
        }
    } else if filter != "NONE" {
        return Err(format!(
            "filter '{filter}' is only valid with mode ATTRIBUTES"
        ));
    }
    Ok((out, size as usize))
}
