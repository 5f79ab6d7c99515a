//! Writes a display database atomically: segments stream into a temporary file beside the
//! target, then the header, the index and the prologue; the file is fsynced and renamed over the
//! target, and the directory fsynced. A failed or interrupted build leaves no partial file
//! behind (the temporary file is removed when the writer is dropped), and a server still mapping
//! the old file keeps reading its inode undisturbed.

use super::{
    FLAG_FLATTENED, FORMAT_VERSION, Header, MAGIC, PROLOGUE_SIZE, Prologue, SegmentEntry,
    SegmentKind, alignment_for, bincode_config, checksum,
};
use crate::error::{DataError, Result};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// What a finished write produced.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteSummary {
    /// Final path.
    pub path: PathBuf,
    /// Total bytes.
    pub file_bytes: u64,
    /// Number of segments.
    pub segments: u64,
}

/// Streams segments into a new display database.
pub struct DbWriter {
    path: PathBuf,
    temp: tempfile::TempPath,
    out: BufWriter<File>,
    pos: u64,
    entries: Vec<SegmentEntry>,
}

impl DbWriter {
    /// Starts a new database that will appear at `path` once [`DbWriter::finish`] succeeds.
    pub fn create(path: &Path) -> Result<Self> {
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let temp = tempfile::Builder::new()
            .prefix(&format!(".{name}."))
            .suffix(".tmp")
            .tempfile_in(&dir)
            .map_err(|e| DataError::io(&dir, e))?;
        let (file, temp) = temp.into_parts();
        let mut out = BufWriter::with_capacity(1 << 20, file);
        out.write_all(&[0u8; PROLOGUE_SIZE])
            .map_err(|e| DataError::io(&temp, e))?;
        Ok(DbWriter {
            path: path.to_path_buf(),
            temp,
            out,
            pos: PROLOGUE_SIZE as u64,
            entries: Vec::new(),
        })
    }

    /// Appends a segment and returns its id.
    pub fn add_segment(&mut self, kind: SegmentKind, bytes: &[u8]) -> Result<u32> {
        self.add_segment_flagged(kind, bytes, 0, bytes.len() as u64)
    }

    /// Appends a segment with [`super::segment_flags`] and the length it decodes to.
    pub fn add_segment_flagged(
        &mut self,
        kind: SegmentKind,
        bytes: &[u8],
        flags: u16,
        raw_length: u64,
    ) -> Result<u32> {
        self.pad_to(alignment_for(bytes.len() as u64))?;
        let id = self.entries.len() as u32;
        self.entries.push(SegmentEntry {
            id,
            kind: kind as u16,
            flags,
            offset: self.pos,
            length: bytes.len() as u64,
            raw_length,
            checksum: checksum(bytes),
            reserved: 0,
        });
        self.write(bytes)?;
        Ok(id)
    }

    /// Number of segments written so far.
    pub fn segment_count(&self) -> usize {
        self.entries.len()
    }

    /// Writes the header, the index and the prologue, then fsyncs and renames into place.
    pub fn finish(mut self, header: &Header) -> Result<WriteSummary> {
        header
            .validate(&self.entries)
            .map_err(|e| DataError::corrupt(&self.path, format!("refusing to write: {e}")))?;
        let header_bytes = bincode::serde::encode_to_vec(header, bincode_config())
            .map_err(|e| DataError::corrupt(&self.path, format!("header encoding: {e}")))?;
        self.pad_to(64)?;
        let header_offset = self.pos;
        self.write(&header_bytes)?;
        self.pad_to(64)?;
        let index_offset = self.pos;
        let index_bytes: &[u8] = bytemuck::cast_slice(&self.entries);
        let index_checksum = checksum(index_bytes);
        let index_bytes = index_bytes.to_vec();
        self.write(&index_bytes)?;
        let mut prologue = Prologue {
            magic: MAGIC,
            version: FORMAT_VERSION,
            flags: if header.flattened { FLAG_FLATTENED } else { 0 },
            file_len: self.pos,
            header_offset,
            header_len: header_bytes.len() as u64,
            index_offset,
            index_count: self.entries.len() as u64,
            header_checksum: checksum(&header_bytes),
            index_checksum,
            prologue_checksum: 0,
            reserved: [0; 6],
        };
        prologue.prologue_checksum = prologue.compute_checksum();
        let io = |e| DataError::io(&self.temp, e);
        self.out.seek(SeekFrom::Start(0)).map_err(io)?;
        self.out
            .write_all(bytemuck::bytes_of(&prologue))
            .map_err(io)?;
        let file = self.out.into_inner().map_err(|e| io(e.into_error()))?;
        // Temporary files are private (0600); a database is meant to be read by a server that
        // may run as another user (the Docker image's), so it is world-readable, like any file
        // a build tool writes.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            file.set_permissions(std::fs::Permissions::from_mode(0o644))
                .map_err(io)?;
        }
        file.sync_all().map_err(io)?;
        drop(file);
        self.temp
            .persist(&self.path)
            .map_err(|e| DataError::io(&self.path, e.error))?;
        sync_parent_dir(&self.path);
        Ok(WriteSummary {
            path: self.path,
            file_bytes: prologue.file_len,
            segments: prologue.index_count,
        })
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.out
            .write_all(bytes)
            .map_err(|e| DataError::io(&self.temp, e))?;
        self.pos += bytes.len() as u64;
        Ok(())
    }

    fn pad_to(&mut self, align: u64) -> Result<()> {
        let pad = (align - self.pos % align) % align;
        const ZEROS: [u8; 4096] = [0; 4096];
        self.write(&ZEROS[..pad as usize])
    }
}

/// Makes the rename durable (best effort: not every filesystem supports syncing a directory).
fn sync_parent_dir(path: &Path) {
    if let Some(d) = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .and_then(|dir| File::open(dir).ok())
    {
        let _ = d.sync_all();
    }
}
