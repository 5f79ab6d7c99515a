//! Validated accessor reading (glTF 2.0 §3.6.2 "Accessors", §3.7.2.1 for the allowed component
//! types per attribute, `KHR_mesh_quantization` for the quantised ones, §3.6.2.3 for sparse
//! storage).
//!
//! Every accessor is checked as a whole before one byte of it is read: its element type against
//! what its semantic allows, its byte range against its bufferView (which [`super::buffers`]
//! checked against its buffer), its stride, its sparse indices and values, and every float for
//! being finite. A file can make the importer refuse it with a message naming the accessor; it
//! cannot make it panic or read past a buffer.

use super::buffers::Views;
use ::gltf::json;
use json::accessor::{ComponentType, Type};
use json::validation::Checked;

/// What an accessor is read as; decides which component types are allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Semantic {
    /// `POSITION`: VEC3 float (quantised: any 8/16-bit integer, normalized or not).
    Position,
    /// `NORMAL`: VEC3 float (quantised: normalized BYTE or SHORT).
    Normal,
    /// `COLOR_0`: VEC3/VEC4 float, or normalized UNSIGNED_BYTE/UNSIGNED_SHORT.
    Color,
    /// `JOINTS_0`: VEC4 UNSIGNED_BYTE or UNSIGNED_SHORT.
    Joints,
    /// `WEIGHTS_0`: VEC4 float, or normalized UNSIGNED_BYTE/UNSIGNED_SHORT.
    Weights,
    /// Morph target `POSITION`/`NORMAL` displacements: VEC3 float (quantised: BYTE, SHORT).
    Target,
    /// A skin's `inverseBindMatrices`: MAT4 float.
    InverseBind,
    /// Primitive indices: SCALAR UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT.
    Indices,
    /// `TEXCOORD_n`: VEC2 float, or normalized UNSIGNED_BYTE/UNSIGNED_SHORT (quantised: any
    /// 8/16-bit integer).
    TexCoord,
}

impl Semantic {
    fn name(self) -> &'static str {
        match self {
            Semantic::Position => "POSITION",
            Semantic::Normal => "NORMAL",
            Semantic::Color => "COLOR_0",
            Semantic::Joints => "JOINTS_0",
            Semantic::Weights => "WEIGHTS_0",
            Semantic::Target => "morph target",
            Semantic::InverseBind => "inverseBindMatrices",
            Semantic::Indices => "indices",
            Semantic::TexCoord => "TEXCOORD",
        }
    }

    /// Whether the element type is allowed: `Some(false)` when glTF allows it only under
    /// `KHR_mesh_quantization`, `None` when never.
    fn allows(self, ty: Type, c: ComponentType, normalized: bool) -> Option<bool> {
        use ComponentType::*;
        let float = c == F32 && !normalized;
        let unorm = matches!(c, U8 | U16) && normalized;
        let small = matches!(c, I8 | U8 | I16 | U16);
        let (shape, core, quantised) = match self {
            Semantic::Position => (ty == Type::Vec3, float, small),
            Semantic::Normal | Semantic::Target => {
                let q = matches!(c, I8 | I16) && (normalized || self == Semantic::Target);
                (ty == Type::Vec3, float, q)
            }
            Semantic::Color => (matches!(ty, Type::Vec3 | Type::Vec4), float || unorm, false),
            Semantic::Joints => (
                ty == Type::Vec4,
                matches!(c, U8 | U16) && !normalized,
                false,
            ),
            Semantic::Weights => (ty == Type::Vec4, float || unorm, false),
            Semantic::InverseBind => (ty == Type::Mat4, float, false),
            Semantic::TexCoord => (ty == Type::Vec2, float || unorm, small),
            Semantic::Indices => (
                ty == Type::Scalar,
                matches!(c, U8 | U16 | U32) && !normalized,
                false,
            ),
        };
        match (shape, core, quantised) {
            (false, _, _) => None,
            (true, true, _) => Some(true),
            (true, false, true) => Some(false),
            (true, false, false) => None,
        }
    }
}

/// Reads accessors of one document, checking each before reading it.
pub struct Accessors<'a> {
    root: &'a json::Root,
    views: &'a Views,
    /// `KHR_mesh_quantization` is declared: quantised attributes are expected.
    quantization: bool,
    /// Accessors read as quantised without the extension declared (warned about once).
    pub undeclared_quantization: Vec<usize>,
}

impl<'a> Accessors<'a> {
    /// A reader over `root`'s accessors whose bufferViews `views` resolves.
    pub fn new(root: &'a json::Root, views: &'a Views, quantization: bool) -> Self {
        Accessors {
            root,
            views,
            quantization,
            undeclared_quantization: Vec::new(),
        }
    }

    /// Reads an accessor as floats: `count × components` values, dequantised (normalized
    /// integers mapped to [0, 1] or [-1, 1] as glTF §3.11 says, plain integers as their value).
    /// Errors name the accessor and say what is wrong with it.
    pub fn floats(&mut self, index: usize, sem: Semantic) -> Result<(Vec<f32>, usize), String> {
        let raw = self.checked(index, sem)?;
        let n = raw.components;
        let mut out = Vec::with_capacity(raw.count * n);
        for i in 0..raw.count {
            for k in 0..n {
                out.push(raw.get(i, k));
            }
        }
        if let Some(sparse) = raw.sparse {
            let (idx, vals) = self.sparse_parts(index, sem, &raw, sparse)?;
            for (j, &at) in idx.iter().enumerate() {
                for k in 0..n {
                    out[at as usize * n + k] = vals.get(j, k);
                }
            }
        }
        if let Some(bad) = out.iter().position(|x| !x.is_finite()) {
            return Err(format!(
                "accessor {index} ({}): element {} is not a finite number",
                sem.name(),
                bad / n
            ));
        }
        Ok((out, n))
    }

    /// Reads an index accessor (UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT).
    pub fn indices(&mut self, index: usize) -> Result<Vec<u32>, String> {
        let (values, _) = self.floats_exact(index, Semantic::Indices)?;
        Ok(values)
    }

    /// Reads an integer accessor (indices, joints) without converting through f32.
    pub fn integers(&mut self, index: usize, sem: Semantic) -> Result<(Vec<u32>, usize), String> {
        self.floats_exact(index, sem)
    }

    fn floats_exact(&mut self, index: usize, sem: Semantic) -> Result<(Vec<u32>, usize), String> {
        let raw = self.checked(index, sem)?;
        let n = raw.components;
        let mut out = Vec::with_capacity(raw.count * n);
        for i in 0..raw.count {
            for k in 0..n {
                out.push(raw.get_uint(i, k));
            }
        }
        if let Some(sparse) = raw.sparse {
            let (idx, vals) = self.sparse_parts(index, sem, &raw, sparse)?;
            for (j, &at) in idx.iter().enumerate() {
                for k in 0..n {
                    out[at as usize * n + k] = vals.get_uint(j, k);
                }
            }
        }
        Ok((out, n))
    }

    /// The accessor's checked layout: type allowed for `sem`, bytes inside its view.
    fn checked(&mut self, index: usize, sem: Semantic) -> Result<Raw<'a>, String> {
        let what = || format!("accessor {index} ({})", sem.name());
        let acc = self
            .root
            .accessors
            .get(index)
            .ok_or_else(|| format!("{} does not exist", what()))?;
        let (Checked::Valid(c), Checked::Valid(ty)) = (&acc.component_type, &acc.type_) else {
            return Err(format!(
                "{}: unknown component type or element type",
                what()
            ));
        };
        let (c, ty) = (c.0, *ty);
        match sem.allows(ty, c, acc.normalized) {
            None => {
                return Err(format!(
                    "{}: {}{} {} is not allowed for {}",
                    what(),
                    if acc.normalized { "normalized " } else { "" },
                    component_name(c),
                    type_name(ty),
                    sem.name()
                ));
            }
            Some(false) if !self.quantization => self.undeclared_quantization.push(index),
            _ => {}
        }
        let count = acc.count.0 as usize;
        let components = ty.multiplicity();
        let csize = c.size();
        let elem = csize * components;
        let (bytes, stride) = match acc.buffer_view {
            Some(v) => {
                let view = self.views.bytes(v.value())?;
                let stride = self.views.stride(v.value()).unwrap_or(elem);
                if stride < elem {
                    return Err(format!(
                        "{}: bufferView {} has a byteStride of {stride}, less than one {elem}-byte element",
                        what(),
                        v.value()
                    ));
                }
                let offset = acc.byte_offset.map_or(0, |o| o.0) as usize;
                if count > 0 {
                    let end = (count as u64 - 1)
                        .checked_mul(stride as u64)
                        .and_then(|x| x.checked_add(offset as u64 + elem as u64));
                    match end {
                        Some(end) if end <= view.len() as u64 => {}
                        _ => {
                            return Err(format!(
                                "{}: {count} elements of {elem} bytes from offset {offset} overrun bufferView {} ({} bytes)",
                                what(),
                                v.value(),
                                view.len()
                            ));
                        }
                    }
                }
                (Some(&view[offset.min(view.len())..]), stride)
            }
            None => {
                // No bufferView: zeros (then sparse values), glTF §3.6.2.3. Bound the count so
                // a tiny file cannot ask for gigabytes of zeros.
                if count > MAX_ZERO_ELEMENTS {
                    return Err(format!(
                        "{}: {count} elements without a bufferView (at most {MAX_ZERO_ELEMENTS})",
                        what()
                    ));
                }
                (None, elem)
            }
        };
        Ok(Raw {
            bytes,
            count,
            components,
            stride,
            component: c,
            normalized: acc.normalized,
            sparse: acc.sparse.as_ref(),
        })
    }

    /// The sparse indices (checked: increasing, below the count) and the values' layout.
    fn sparse_parts(
        &self,
        index: usize,
        sem: Semantic,
        raw: &Raw<'a>,
        sparse: &'a json::accessor::sparse::Sparse,
    ) -> Result<(Vec<u32>, Raw<'a>), String> {
        let what = || format!("accessor {index} ({}) sparse", sem.name());
        let n = sparse.count.0 as usize;
        let Checked::Valid(ic) = &sparse.indices.component_type else {
            return Err(format!("{}: unknown index component type", what()));
        };
        let ic = ic.0;
        if !matches!(
            ic,
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32
        ) {
            return Err(format!("{}: indices must be unsigned", what()));
        }
        let iv = sparse.indices.buffer_view.value();
        let ibytes = slice_of(
            self.views.bytes(iv)?,
            sparse.indices.byte_offset.0,
            n,
            ic.size(),
        )
        .ok_or_else(|| format!("{}: indices overrun bufferView {iv}", what()))?;
        let idx_raw = Raw {
            bytes: Some(ibytes),
            count: n,
            components: 1,
            stride: ic.size(),
            component: ic,
            normalized: false,
            sparse: None,
        };
        let idx: Vec<u32> = (0..n).map(|j| idx_raw.get_uint(j, 0)).collect();
        if idx.windows(2).any(|w| w[0] >= w[1])
            || idx.last().is_some_and(|&l| l as usize >= raw.count)
        {
            return Err(format!(
                "{}: indices must increase strictly and stay below the count {}",
                what(),
                raw.count
            ));
        }
        let vv = sparse.values.buffer_view.value();
        let elem = raw.component.size() * raw.components;
        let vbytes = slice_of(self.views.bytes(vv)?, sparse.values.byte_offset.0, n, elem)
            .ok_or_else(|| format!("{}: values overrun bufferView {vv}", what()))?;
        let vals = Raw {
            bytes: Some(vbytes),
            count: n,
            components: raw.components,
            stride: elem,
            component: raw.component,
            normalized: raw.normalized,
            sparse: None,
        };
        Ok((idx, vals))
    }
}

/// Largest accessor without a bufferView we fill with zeros.
const MAX_ZERO_ELEMENTS: usize = 1 << 24;

/// `n` tightly packed elements of `elem` bytes at `offset` in `view`, if they fit.
fn slice_of(view: &[u8], offset: u64, n: usize, elem: usize) -> Option<&[u8]> {
    let len = (n as u64).checked_mul(elem as u64)?;
    let end = offset.checked_add(len)?;
    (end <= view.len() as u64).then(|| &view[offset as usize..end as usize])
}

/// A checked accessor: every element lies inside `bytes`.
#[derive(Clone, Copy)]
struct Raw<'a> {
    /// The bytes from the accessor's first element on; `None` = all zeros.
    bytes: Option<&'a [u8]>,
    count: usize,
    components: usize,
    stride: usize,
    component: ComponentType,
    normalized: bool,
    sparse: Option<&'a json::accessor::sparse::Sparse>,
}

impl Raw<'_> {
    fn at(&self, i: usize, k: usize) -> Option<&[u8]> {
        let size = self.component.size();
        let start = i * self.stride + k * size;
        self.bytes.map(|b| &b[start..start + size])
    }

    /// Component `k` of element `i` as an unsigned integer (0 for floats and zero-filled).
    fn get_uint(&self, i: usize, k: usize) -> u32 {
        let Some(b) = self.at(i, k) else { return 0 };
        match self.component {
            ComponentType::U8 | ComponentType::I8 => b[0] as u32,
            ComponentType::U16 | ComponentType::I16 => u16::from_le_bytes([b[0], b[1]]) as u32,
            ComponentType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            ComponentType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u32,
        }
    }

    /// Component `k` of element `i`, dequantised.
    fn get(&self, i: usize, k: usize) -> f32 {
        let Some(b) = self.at(i, k) else { return 0.0 };
        let norm = self.normalized;
        match self.component {
            ComponentType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            ComponentType::I8 => {
                let v = b[0] as i8 as f32;
                if norm { (v / 127.0).max(-1.0) } else { v }
            }
            ComponentType::U8 => {
                let v = b[0] as f32;
                if norm { v / 255.0 } else { v }
            }
            ComponentType::I16 => {
                let v = i16::from_le_bytes([b[0], b[1]]) as f32;
                if norm { (v / 32767.0).max(-1.0) } else { v }
            }
            ComponentType::U16 => {
                let v = u16::from_le_bytes([b[0], b[1]]) as f32;
                if norm { v / 65535.0 } else { v }
            }
            ComponentType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        }
    }
}

fn component_name(c: ComponentType) -> &'static str {
    match c {
        ComponentType::I8 => "BYTE",
        ComponentType::U8 => "UNSIGNED_BYTE",
        ComponentType::I16 => "SHORT",
        ComponentType::U16 => "UNSIGNED_SHORT",
        ComponentType::U32 => "UNSIGNED_INT",
        ComponentType::F32 => "FLOAT",
    }
}

fn type_name(t: Type) -> &'static str {
    match t {
        Type::Scalar => "SCALAR",
        Type::Vec2 => "VEC2",
        Type::Vec3 => "VEC3",
        Type::Vec4 => "VEC4",
        Type::Mat2 => "MAT2",
        Type::Mat3 => "MAT3",
        Type::Mat4 => "MAT4",
    }
}
