//! The lookahead/IO stage (Funkhouser Ch. 6 and §5.2.3), on its own thread with its own tokio
//! runtime: it takes the latest observer the render stage published and has the server push
//! the read set ([`crate::stream`], the default) or asks for it and keeps a few segment
//! fetches going from the top of the latest one ([`crate::drive::drive`]); it checks every
//! segment against the manifest's checksum, uploads geometry to the GPU (the upload stage) and
//! hands the results to the render stage through a bounded queue. The render stage never
//! waits for it.
use crate::drive::{Ask, Event, Fetcher, Items};
use crate::net::Remote;
use crate::pages::PageBook;
use portico_client::engine::catalogue::{Kind, decode_stab, plain_geometry};
use portico_client::parts::{Joined, Parts};
use portico_data::cells::StabList;
use portico_protocol::{Policy, PrefetchRequest, PrefetchResponse, SegmentInfo};
use portico_render::{GpuImpostor, GpuMesh, GpuTexture, Uploader};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, RwLock};
use tokio::sync::{mpsc, watch};

/// A segment's contents, ready for the cache.
pub enum Payload {
    /// Geometry already on the GPU.
    Mesh(GpuMesh),
    /// A decoded stab list, with its cell's page when the client started from the core
    /// manifest and the page came with it ([`crate::pages`]).
    Stab(Arc<StabList>, Option<crate::pages::TakenPage>),
    /// A cluster's textured box, on the GPU.
    Impostor(GpuImpostor),
    /// A material texture's mip chain, on the GPU.
    Texture(GpuTexture),
    /// The last part of a texture segment cut into parts: the whole segment's mip chain, on
    /// the GPU, to be held under its head's id.
    Joined(u32, GpuTexture),
    /// A part of a texture segment (or its head) waiting for the rest.
    Piece,
    /// A texture segment joined from its parts that does not decode (its head's id and why):
    /// held as unusable, so that its parts are not fetched again and again.
    Unusable(u32, String),
}

/// One message from the IO stage.
pub type Arrival = Event<Payload>;

/// Settings of the IO stage.
#[derive(Debug, Clone, Copy)]
pub struct IoConfig {
    /// Prefetch policy sent to the server.
    pub policy: Policy,
    /// Concurrent segment fetches.
    pub parallel: usize,
    /// Most bytes in flight or delivered and not yet taken by the frame loop.
    pub window: u64,
    /// Server push (falling back to pull) or pull.
    pub transport: crate::stream::Transport,
}

pub use portico_client::engine::catalogue::Catalogue;

/// The real client's [`Fetcher`]: HTTP, checksum, decode, GPU upload.
#[derive(Clone)]
struct Http {
    remote: Remote,
    uploader: Uploader,
    catalogue: Arc<RwLock<Catalogue>>,
    /// Texture segments cut into parts, and the parts that came: shared with the frame loop,
    /// which asks for and reports them.
    parts: Arc<Mutex<Parts>>,
    /// Started from the core manifest: the pages.
    pages: Option<Arc<PageBook>>,
}

impl Fetcher for Http {
    type Body = Payload;

    fn prefetch(
        &self,
        req: PrefetchRequest,
    ) -> impl Future<Output = anyhow::Result<PrefetchResponse>> + Send + 'static {
        let remote = self.remote.clone();
        async move { remote.prefetch(&req).await }
    }

    fn batch(
        &self,
        ids: Vec<u32>,
    ) -> impl Future<Output = anyhow::Result<Items<Payload>>> + Send + 'static {
        let me = self.clone();
        async move {
            let Some(book) = me.pages.clone() else {
                let got = me.remote.batch(&ids).await?;
                return Ok(got
                    .into_iter()
                    .map(|(id, bytes)| {
                        let item = bytes.and_then(|b| me.load(id, &b).map(|p| (p, b.len() as u64)));
                        (id, item)
                    })
                    .collect());
            };
            // Each stab list's page is fetched beside the batch that brings the list and taken
            // as soon as it comes; a list whose page failed fails too (both are asked again).
            let cells: Vec<(u32, u32)> = ids
                .iter()
                .filter_map(|&s| book.claim(s).map(|c| (s, c)))
                .collect();
            // A task aborted mid-way (push took over) releases what it claimed, or those
            // pages would count as on their way for ever.
            let _claims = Claims(book.clone(), cells.iter().map(|&(_, c)| c).collect());
            let pages = futures_util::future::join_all(
                cells
                    .iter()
                    .map(|&(seg, cell)| me.fetch_page(&book, seg, cell)),
            );
            let (got, pages) = tokio::join!(me.remote.batch(&ids), pages);
            let mut failed: HashMap<u32, anyhow::Error> =
                pages.into_iter().filter_map(|r| r.err()).collect();
            let deadline = tokio::time::Instant::now() + crate::pages::ROW_WAIT;
            let mut out = Vec::new();
            for (id, bytes) in got? {
                let item = match failed.remove(&id) {
                    Some(e) => Err(e),
                    None if !book.ready(&me.catalogue, id, deadline).await => Err(anyhow::anyhow!(
                        "segment {id}: no page has brought its row (or its cell's page) yet"
                    )),
                    None => bytes.and_then(|b| me.load(id, &b).map(|p| (p, b.len() as u64))),
                };
                out.push((id, item));
            }
            Ok(out)
        }
    }

    fn decode(&self, id: u32, bytes: &[u8]) -> anyhow::Result<Payload> {
        self.load(id, bytes)
    }

    fn stream_url(&self) -> anyhow::Result<String> {
        self.remote.stream_url()
    }

    fn paged(&self) -> bool {
        self.pages.is_some()
    }

    fn take_page(&self, deflated: &[u8]) -> anyhow::Result<()> {
        match &self.pages {
            Some(book) => book.take_frame(&self.catalogue, deflated),
            None => anyhow::bail!("a page came, but this client read the whole manifest"),
        }
    }

    fn settle(&self, id: u32) -> impl Future<Output = anyhow::Result<()>> + Send + 'static {
        let me = self.clone();
        async move {
            let Some(book) = me.pages.clone() else {
                return Ok(());
            };
            // A pushed stab list whose page did not come first (the server could not make it,
            // or it was refused here) has its page read over HTTP.
            if let Some(cell) = book.claim(id) {
                let _claim = Claims(book.clone(), vec![cell]);
                me.fetch_page(&book, id, cell).await.map_err(|(_, e)| e)?;
            }
            let deadline = tokio::time::Instant::now() + crate::pages::ROW_WAIT;
            if book.ready(&me.catalogue, id, deadline).await {
                Ok(())
            } else {
                Err(Unready(id).into())
            }
        }
    }

    fn bytes(&self, id: u32) -> u64 {
        self.catalogue().wire(id)
    }

    fn held_bytes(&self, id: u32) -> u64 {
        self.catalogue().held(id)
    }
}

/// Cells whose pages a read task claimed: released when the task ends however it ends (a
/// page taken is no longer asked for, so releasing it changes nothing).
struct Claims(Arc<PageBook>, Vec<u32>);

impl Drop for Claims {
    fn drop(&mut self) {
        for &c in &self.1 {
            self.0.release(c);
        }
    }
}

/// A pushed segment whose row no page has brought: the stream gives it back (`Evicted`) so
/// that the server pushes it again once the page has come.
#[derive(Debug, thiserror::Error)]
#[error("segment {0}: no page has brought its row yet")]
pub struct Unready(pub u32);

impl Http {
    /// Fetches and takes cell `cell`'s page (for stab list segment `seg`); on failure the cell
    /// is released to be asked again, and the error is keyed by the stab list.
    async fn fetch_page(
        &self,
        book: &PageBook,
        seg: u32,
        cell: u32,
    ) -> Result<(), (u32, anyhow::Error)> {
        let r = match self.remote.page(cell).await {
            Ok(p) => book.take(&self.catalogue, p, Some(cell)),
            Err(e) => Err(e),
        };
        r.map_err(|e| {
            book.release(cell);
            (seg, e)
        })
    }

    fn catalogue(&self) -> std::sync::RwLockReadGuard<'_, Catalogue> {
        self.catalogue.read().unwrap_or_else(|e| e.into_inner())
    }

    /// Rejects a segment whose bytes do not match the manifest (it is counted and asked for
    /// again later), and turns the rest into cache entries by their kind.
    fn load(&self, id: u32, bytes: &[u8]) -> anyhow::Result<Payload> {
        let catalogue = self.catalogue();
        catalogue.verify(id, bytes).map_err(anyhow::Error::msg)?;
        let kind = catalogue.kind(id);
        drop(catalogue);
        let parts = self.parts.clone();
        if parts.lock().unwrap_or_else(|e| e.into_inner()).is_piece(id) {
            let joined = parts
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .join(id, bytes.to_vec());
            let Joined::Complete(head, whole) = joined else {
                return Ok(Payload::Piece);
            };
            let wrap = match self.catalogue().kind(head) {
                Kind::Texture(wrap) => wrap,
                _ => Default::default(),
            };
            return Ok(match self.uploader.upload_texture(&whole, wrap) {
                Ok(t) => Payload::Joined(head, t),
                Err(e) => Payload::Unusable(head, format!("segment {head} (joined): {e}")),
            });
        }
        let gpu = |e: portico_render::RenderError| anyhow::anyhow!("segment {id}: {e}");
        Ok(match kind {
            Kind::Impostor(bounds, tile) => Payload::Impostor(
                self.uploader
                    .upload_impostor(bytes, &bounds, tile)
                    .map_err(gpu)?,
            ),
            Kind::Texture(wrap) => {
                Payload::Texture(self.uploader.upload_texture(bytes, wrap).map_err(gpu)?)
            }
            Kind::Stab => {
                let list = decode_stab(id, bytes).map_err(anyhow::Error::msg)?;
                let page = self.pages.as_ref().and_then(|b| b.handed(id));
                Payload::Stab(Arc::new(list), page)
            }
            // A compressed segment is decoded here, on the IO thread, into the layout GPUs
            // bind (after its counts are checked against its LOD record).
            Kind::Geometry(expected) => {
                let plain = plain_geometry(id, bytes, expected).map_err(anyhow::Error::msg)?;
                Payload::Mesh(self.uploader.upload(&plain).map_err(gpu)?)
            }
        })
    }
}

/// Checks a segment's bytes against its row of the manifest (size and xxh3, the strong ETag):
/// a segment damaged on the way is rejected, never uploaded or decoded.
pub fn verify(info: Option<&SegmentInfo>, id: u32, bytes: &[u8]) -> anyhow::Result<()> {
    portico_protocol::verify_segment(info, id, bytes).map_err(anyhow::Error::msg)
}

/// A running IO stage.
pub struct IoStage {
    /// Publish the latest frame state here.
    pub state: watch::Sender<Option<Ask>>,
    /// Arrivals come out here.
    pub arrivals: mpsc::Receiver<Arrival>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl IoStage {
    /// Starts the stage on its own thread.
    pub fn start(
        remote: Remote,
        uploader: Uploader,
        catalogue: Catalogue,
        parts: Arc<Mutex<Parts>>,
        pages: Option<PageBook>,
        cfg: IoConfig,
    ) -> std::io::Result<IoStage> {
        let (state_tx, state_rx) = watch::channel(None);
        let (tx, rx) = mpsc::channel(1024);
        let fetcher = Http {
            remote,
            uploader,
            catalogue: Arc::new(RwLock::new(catalogue)),
            parts,
            pages: pages.map(Arc::new),
        };
        let thread = std::thread::Builder::new()
            .name("portico-io".into())
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        let _ = tx.blocking_send(Event::Failed(format!("IO runtime: {e}")));
                        return;
                    }
                };
                // The real link's rate is not known: the server paces at its own cap.
                rt.block_on(crate::stream::run(
                    fetcher,
                    cfg.policy,
                    cfg.transport,
                    u64::MAX / 2,
                    cfg.parallel,
                    cfg.window,
                    state_rx,
                    tx,
                ));
            })?;
        Ok(IoStage {
            state: state_tx,
            arrivals: rx,
            thread: Some(thread),
        })
    }

    /// Stops the stage and waits for its thread.
    pub fn stop(mut self) {
        drop(self.state);
        self.arrivals.close();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn damaged_or_unknown_segments_are_rejected() {
        let bytes = b"segment bytes".to_vec();
        let info = SegmentInfo {
            kind: 1,
            bytes: bytes.len() as u64,
            checksum: xxhash_rust::xxh3::xxh3_64(&bytes),
        };
        assert!(verify(Some(&info), 3, &bytes).is_ok());
        let mut flipped = bytes.clone();
        flipped[4] ^= 1;
        let e = verify(Some(&info), 3, &flipped).unwrap_err().to_string();
        assert!(e.contains("segment 3: corrupt"), "{e}");
        assert!(verify(Some(&info), 3, &bytes[..5]).is_err(), "truncated");
        assert!(
            verify(None, 9, &bytes)
                .unwrap_err()
                .to_string()
                .contains("not in the manifest")
        );
    }
}
