//! Writing a model's textures into a database: each mip chain coded ([`super::code_segments`])
//! and written coarsest first, a segment longer than a part cut into its head and parts.

use super::{MipSegment, TextureImage, TextureRecord};
use crate::build::Observer;
use crate::error::Result;
use crate::format::SegmentKind;
use crate::format::writer::DbWriter;

/// Writes each texture's mip chain as coded segments, coarsest first ([`crate::texture`]:
/// PNG, or JPEG within [`super::MIN_PSNR`]), and returns their header records.
pub(crate) fn write_textures(
    w: &mut DbWriter,
    textures: &[TextureImage],
    part: usize,
    obs: &dyn Observer,
) -> Result<Vec<TextureRecord>> {
    if textures.is_empty() {
        return Ok(Vec::new());
    }
    obs.stage("textures", textures.len() as u64);
    textures
        .iter()
        .map(|t| {
            let chain = super::mip_chain(t.width, t.height, &t.rgba);
            let coded = super::code_segments(t.width, t.height, &chain);
            let psnr = coded.iter().map(|c| c.psnr).fold(f64::INFINITY, f64::min);
            let segments = coded
                .into_iter()
                .map(|c| {
                    // Per segment, as the client finds it in the texels it decodes: a coarse
                    // level can average a few translucent texels away.
                    let first = chain.len() - c.levels as usize;
                    let opaque = super::is_opaque(&chain[first]);
                    // Longer than a part: the rest in parts of their own, right after it.
                    let mut pieces = c.bytes.chunks(part);
                    let head = pieces.next().unwrap_or_default();
                    let segment = w.add_segment(SegmentKind::Mips, head)?;
                    let mut parts = 0;
                    for piece in pieces {
                        let id = w.add_segment(SegmentKind::MipPart, piece)?;
                        parts += 1;
                        debug_assert_eq!(id, segment + parts);
                    }
                    Ok(MipSegment {
                        segment,
                        width: c.width,
                        height: c.height,
                        levels: c.levels,
                        opaque,
                        parts,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            obs.advance(1);
            Ok(TextureRecord {
                name: t.name.clone(),
                width: t.width,
                height: t.height,
                segments,
                average: super::average_color(&t.rgba),
                wrap: t.wrap,
                psnr: psnr.is_finite().then_some(psnr as f32),
            })
        })
        .collect()
}
