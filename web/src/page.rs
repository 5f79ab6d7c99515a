//! The page's side: reads the address, loads the model, starts wgpu on the canvas, wires the
//! input events and runs the frame loop on `requestAnimationFrame`; [`Handle`] is what
//! JavaScript (the page, a test) holds.

use crate::input::Input;
use crate::io::Io;
use crate::net::{Remote, js_error};
use crate::viewer::{Model, Stats, Viewer, navigator};
use glam::Vec3;
use portico_client::cache::split_budget;
use portico_client::engine::catalogue::Start;
use portico_client::engine::holdings::Holdings;
use portico_client::engine::pull::Reask;
use portico_client::frame::Decider;
use portico_client::walk::Gait;
use portico_data::cells::CellGraph;
use portico_data::cells::paged::GraphCore;
use portico_data::format::Header;
use portico_data::path::{CameraPath, PathKind};
use portico_protocol::Policy;
use portico_protocol::{CoreManifest, Manifest};
use std::cell::RefCell;
use std::rc::Rc;
use wasm_bindgen::prelude::*;
use web_sys::{HtmlCanvasElement, KeyboardEvent, PointerEvent};

/// The running viewer, as JavaScript holds it (`const viewer = await start("canvas")`).
#[wasm_bindgen]
pub struct Handle {
    viewer: Rc<RefCell<Viewer>>,
    input: Rc<RefCell<Input>>,
}

#[wasm_bindgen]
impl Handle {
    /// The viewer's figures as JSON ([`Stats`]): frames, frame time, resident bytes of the
    /// budget, objects and LODs skipped, bytes received, the first complete frame, errors.
    pub fn stats(&self) -> String {
        serde_json::to_string(&self.viewer.borrow().stats).unwrap_or_default()
    }

    /// Puts the eye at (x, y, z) looking along (dx, dy, dz) and stops the tour.
    pub fn look(&self, x: f32, y: f32, z: f32, dx: f32, dy: f32, dz: f32) {
        if ![x, y, z, dx, dy, dz].iter().all(|c| c.is_finite()) {
            web_sys::console::warn_1(&"portico: look() needs finite numbers".into());
            return;
        }
        let mut v = self.viewer.borrow_mut();
        v.touring = None;
        v.nav = navigator(Vec3::new(x, y, z), Vec3::new(dx, dy, dz));
        v.walker.reset();
    }

    /// Picks the object at (x, y) of the canvas (each -1..1, y up) in the last frame drawn, as
    /// a click there does: its name, class, storey, GUID, tags and what is drawn of it as
    /// JSON ([`portico_client::pick::Picked`]), or `null` where nothing drawn is.
    pub fn pick(&self, x: f32, y: f32) -> String {
        let picked = self.viewer.borrow_mut().pick([x, y]);
        serde_json::to_string(&picked).unwrap_or_default()
    }

    /// Walks (`"walk"`: walls stop the observer, floors carry it) or flies (`"fly"`).
    pub fn gait(&self, name: &str) {
        let mut v = self.viewer.borrow_mut();
        v.gait = match name {
            "fly" => Gait::Fly,
            "walk" => Gait::Walk,
            other => {
                web_sys::console::warn_1(&format!("portico: gait({other:?}): walk or fly").into());
                return;
            }
        };
        v.walker.reset();
    }

    /// Starts (or with `false` stops) the model's standard tour.
    pub fn tour(&self, on: bool) {
        let mut v = self.viewer.borrow_mut();
        let now = v.last_t.unwrap_or(0.0);
        v.touring = (on && v.model.tour.is_some()).then_some(now);
        self.input.borrow_mut().touched = false;
    }
}

/// Reads `name` from the page's query string.
fn param(name: &str) -> Option<String> {
    let search = web_sys::window()?.location().search().ok()?;
    web_sys::UrlSearchParams::new_with_str(&search)
        .ok()?
        .get(name)
}

/// Takes `token` out of the address once it is read, so that the address people share for the
/// viewpoint never carries it (a reload then needs it again).
fn forget_token() {
    let Some(w) = web_sys::window() else { return };
    let loc = w.location();
    let (Ok(path), Ok(search), Ok(hash)) = (loc.pathname(), loc.search(), loc.hash()) else {
        return;
    };
    let Ok(params) = web_sys::UrlSearchParams::new_with_str(&search) else {
        return;
    };
    params.delete("token");
    let rest = String::from(params.to_string());
    let query = if rest.is_empty() {
        String::new()
    } else {
        format!("?{rest}")
    };
    if let Ok(h) = w.history() {
        let _ = h.replace_state_with_url(&JsValue::NULL, "", Some(&format!("{path}{query}{hash}")));
    }
}

/// The viewpoint in the fragment (`#eye=x,y,z&dir=x,y,z`), if it has one.
fn viewpoint_from_hash() -> Option<(Vec3, Vec3)> {
    let hash = web_sys::window()?.location().hash().ok()?;
    let params = web_sys::UrlSearchParams::new_with_str(hash.trim_start_matches('#')).ok()?;
    let vec = |key: &str| -> Option<Vec3> {
        let v: Vec<f32> = params
            .get(key)?
            .split(',')
            .map(|s| s.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .ok()?;
        (v.len() == 3 && v.iter().all(|c| c.is_finite())).then(|| Vec3::new(v[0], v[1], v[2]))
    };
    let dir = vec("dir")?;
    (dir.length() > 1e-6).then_some((vec("eye")?, dir))
}

/// Loads the model from the server and starts the viewer on the canvas with id `canvas_id`;
/// writes its figures four times a second into the element with id `overlay_id`, if any, and
/// draws the mini-map on the canvas with id `map`, if the page has one.
///
/// # Errors
/// A one-line message (shown by the page) when the server cannot be reached, the manifest does
/// not decode, or the browser has neither WebGPU nor WebGL2.
#[wasm_bindgen]
pub async fn start(canvas_id: String, overlay_id: String) -> Result<Handle, JsValue> {
    console_error_panic_hook::set_once();
    let window = web_sys::window().ok_or("no window")?;
    let document = window.document().ok_or("no document")?;
    let canvas: HtmlCanvasElement = document
        .get_element_by_id(&canvas_id)
        .ok_or_else(|| format!("no element #{canvas_id}"))?
        .dyn_into()
        .map_err(|_| format!("#{canvas_id} is not a canvas"))?;
    let server = param("server").unwrap_or_default();
    let token = param("token").filter(|t| !t.is_empty());
    if token.is_some() {
        forget_token();
    }
    let cache_mb: u64 = param("cache_mb")
        .and_then(|s| s.parse().ok())
        .unwrap_or(portico_client::defaults::CACHE_MB)
        .clamp(1, 1 << 16);
    let budget_ms: f64 = param("budget_ms")
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|b| b.is_finite())
        .unwrap_or(portico_client::defaults::FRAME_BUDGET_MS)
        .clamp(5.0, 1000.0);
    let backend = param("backend").unwrap_or_else(|| "auto".into());
    let push = param("transport").as_deref() != Some("pull");
    // `?reask=always`: a prefetch request after every answer, as before the pull engine
    // waited for the observer to move on (for measuring what that saves).
    let reask = match param("reask").as_deref() {
        Some("always") => Reask::ALWAYS,
        _ => Reask::DEFAULT,
    };

    let remote = Rc::new(Remote::new(&server, token));
    let loaded = load(&remote, param("manifest").as_deref() != Some("whole"))
        .await
        .map_err(|e| JsValue::from_str(&format!("{e:#}")))?;

    // WebGL2 guarantees 2048-pixel textures; the device's own limit applies from then on.
    let (width, height) = canvas_size(&canvas, 2048);
    let backends = match backend.as_str() {
        "webgl" => wgpu::Backends::GL,
        "webgpu" => wgpu::Backends::BROWSER_WEBGPU,
        _ => wgpu::Backends::BROWSER_WEBGPU | wgpu::Backends::GL,
    };
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backends;
    let instance = wgpu::util::new_instance_with_webgpu_detection(desc).await;
    let surface = instance
        .create_surface(wgpu::SurfaceTarget::Canvas(canvas.clone()))
        .map_err(|e| {
            format!(
                "cannot draw on the canvas ({backend} asked): {e}; without ?backend= the viewer \
                 uses WebGPU where the browser has an adapter and WebGL2 otherwise"
            )
        })?;
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            compatible_surface: Some(&surface),
            ..Default::default()
        })
        .await
        .map_err(|e| format!("this browser offers neither WebGPU nor WebGL2: {e}"))?;
    let backend_name = format!("{:?}", adapter.get_info().backend);
    let renderer = portico_render::Renderer::on_adapter(instance, &adapter, width, height, Some(1))
        .await
        .map_err(|e| format!("starting the renderer: {e}"))?;
    // wgpu's default handler panics on a GPU error; a page logs it and goes on.
    renderer
        .device()
        .on_uncaptured_error(std::sync::Arc::new(|e: wgpu::Error| {
            web_sys::console::error_1(&format!("portico: GPU error: {e}").into());
        }));
    let formats = surface.get_capabilities(&adapter).formats;
    let want = portico_render::COLOR_FORMAT;
    // The frames' format, or its linear twin viewed as sRGB (WebGPU canvases offer
    // `bgra8unorm` or `rgba8unorm`, never an sRGB format).
    let (format, view_formats) = if formats.contains(&want) {
        (want, vec![])
    } else if formats.contains(&want.remove_srgb_suffix()) {
        (want.remove_srgb_suffix(), vec![want])
    } else {
        let plain = want.remove_srgb_suffix();
        return Err(format!("the canvas offers none of {want:?}, {plain:?}").into());
    };
    let mut config = surface
        .get_default_config(&adapter, width, height)
        .ok_or("the canvas offers no surface format")?;
    config.format = format;
    config.view_formats = view_formats;
    config.present_mode = wgpu::PresentMode::AutoVsync;
    surface.configure(renderer.device(), &config);

    // What a texture costs the cache follows what the GPU holds it as (BC where offered).
    let texels = renderer.texel_format();
    let (start, tour, startup) = loaded;
    let start = match start {
        Loaded::Paged(core) => Start::paged(core, texels),
        Loaded::Whole(m, graph) => Start::whole(m, graph, texels),
    }
    .map_err(|e| format!("{server}: {e}"))?;
    let parts = portico_client::parts::Parts::new(&start.header.textures);
    let (cache_bytes, window_bytes) = split_budget(cache_mb.max(1) << 20);
    let elision = match param("elision").as_deref() {
        None | Some("") => crate::viewer::ELISION,
        Some(e) => e
            .parse::<portico_client::elision::Algorithm>()
            .map_err(|e| format!("?elision=: {e}"))?,
    };
    let policy = Policy {
        impostors: elision == portico_client::elision::Algorithm::Impostors,
        cache_bytes,
        block_textures: texels == portico_data::texture::TexelFormat::Block,
        screen: [width, height],
        frame_time_s: (budget_ms / 1e3) as f32,
        ..Policy::default()
    };
    let start_view = viewpoint_from_hash().or_else(|| tour.as_ref().map(|t| t.sample(0.0)));
    let (eye, dir) = start_view.unwrap_or((Vec3::ZERO, Vec3::X));
    let viewer = Viewer {
        renderer,
        surface,
        config,
        held: Holdings::new(cache_bytes),
        decider: Decider::new(elision, budget_ms / 1e3, Some(policy.size_threshold_px)),
        cost: Default::default(),
        stand_ins: Default::default(),
        io: Io::new(
            remote,
            start.catalogue,
            start.pages,
            policy,
            window_bytes,
            push,
            reask,
        ),
        nav: navigator(eye, dir),
        gait: Gait::Walk,
        walker: Default::default(),
        pages_learned: 0,
        view_proj: glam::Mat4::IDENTITY,
        touring: None,
        drawn: Vec::new(),
        stats: Stats {
            cache_budget: cache_bytes,
            budget_bytes: cache_mb << 20,
            backend: backend_name,
            texel_format: format!("{texels:?}"),
            manifest: startup.0.into(),
            elision: elision.to_string(),
            startup_bytes: startup.1,
            ..Stats::default()
        },
        recent: Default::default(),
        last_t: None,
        model: Model {
            header: start.header,
            graph: start.graph,
            bounds: start.bounds,
            parts,
            tour,
        },
    };
    let handle = Handle {
        viewer: Rc::new(RefCell::new(viewer)),
        input: Rc::new(RefCell::new(Input::default())),
    };
    listen(&window, &canvas, &handle.input)?;
    follow_address(&window, &handle.viewer)?;
    let overlay = document.get_element_by_id(&overlay_id);
    let panel = document.get_element_by_id("pick");
    let map = crate::minimap::MiniMap::find(&document, "map");
    run_frames(
        handle.viewer.clone(),
        handle.input.clone(),
        canvas,
        overlay,
        panel,
        map,
    );
    Ok(Handle {
        viewer: handle.viewer,
        input: handle.input,
    })
}

/// What the page read before its first frame.
enum Loaded {
    /// The core manifest: the rest comes page by page with the stab lists.
    Paged(CoreManifest<Header, GraphCore>),
    /// The whole manifest and cell graph.
    Whole(Manifest<Header>, Option<CellGraph>),
}

/// The core manifest and the standard tour (both at once), or, from a server without a core
/// (a model without cells, an older server) or with `paged` false, the whole manifest and cell
/// graph, the tour made here. Also how it started and the bytes it decoded.
async fn load(
    remote: &Remote,
    paged: bool,
) -> anyhow::Result<(Loaded, Option<CameraPath>, (&'static str, u64))> {
    if paged {
        let (core, tour) = futures_util::future::join(remote.core(), remote.tour()).await;
        if let Some(core) = core? {
            let bytes = portico_protocol::to_bincode(&core).map_or(0, |b| b.len() as u64);
            // A tour the server cannot give leaves the page without one, not without a model.
            let tour = tour.unwrap_or_else(|e| {
                web_sys::console::warn_1(&format!("portico: {e:#}").into());
                None
            });
            return Ok((Loaded::Paged(core), tour, ("paged", bytes)));
        }
    }
    let (manifest, graph) = remote.model().await?;
    let bytes = portico_protocol::to_bincode(&manifest).map_or(0, |b| b.len() as u64)
        + graph
            .as_ref()
            .map_or(0, |g| portico_data::format::encode_segment(g).len() as u64);
    let h = &manifest.header;
    let bounds: Vec<_> = h.instances.iter().map(|i| i.bounds).collect();
    // The server's tour, made the same way.
    let tour = portico_data::path::standard(
        graph.as_ref(),
        &h.bounds,
        &bounds,
        PathKind::Tour,
        TOUR_LEGS,
        1,
        portico_data::person::WALK_SPEED,
        portico_data::person::TURN_DEGREES.to_radians(),
    );
    Ok((Loaded::Whole(manifest, graph), tour, ("whole", bytes)))
}

/// Legs of the standard tour (as the server's `/v1/db/{id}/tour`).
const TOUR_LEGS: usize = 6;

/// The canvas's drawing-buffer size for its CSS size at the device's pixel ratio, at most
/// `max` pixels a side (the GPU's texture limit); sets it on the canvas when it changed.
fn canvas_size(canvas: &HtmlCanvasElement, max: u32) -> (u32, u32) {
    let ratio = web_sys::window().map_or(1.0, |w| w.device_pixel_ratio().max(1.0));
    let side = |css: i32| ((f64::from(css.max(16)) * ratio).round() as u32).min(max);
    let (w, h) = (side(canvas.client_width()), side(canvas.client_height()));
    if (w, h) != (canvas.width(), canvas.height()) {
        canvas.set_width(w);
        canvas.set_height(h);
    }
    (w, h)
}

/// The pointer's position on the canvas, each coordinate -1..1 (y up).
fn cursor(canvas: &HtmlCanvasElement, e: &PointerEvent) -> [f32; 2] {
    let r = canvas.get_bounding_client_rect();
    let x = ((e.client_x() as f64 - r.left()) / r.width().max(1.0)) * 2.0 - 1.0;
    let y = 1.0 - ((e.client_y() as f64 - r.top()) / r.height().max(1.0)) * 2.0;
    [x as f32, y as f32]
}

/// Keys on the window, the pointer (mouse, pen, touch) on the canvas.
fn listen(
    window: &web_sys::Window,
    canvas: &HtmlCanvasElement,
    input: &Rc<RefCell<Input>>,
) -> Result<(), JsValue> {
    let i = input.clone();
    let down = Closure::<dyn FnMut(KeyboardEvent)>::new(move |e: KeyboardEvent| {
        // Ctrl+R, Ctrl+F, Alt+…, ⌘… are the browser's.
        if e.ctrl_key() || e.meta_key() || e.alt_key() {
            return;
        }
        if i.borrow_mut().key_down(&e.code()) {
            e.prevent_default();
        }
    });
    window.add_event_listener_with_callback("keydown", down.as_ref().unchecked_ref())?;
    down.forget();
    let i = input.clone();
    let up = Closure::<dyn FnMut(KeyboardEvent)>::new(move |e: KeyboardEvent| {
        i.borrow_mut().key_up(&e.code());
    });
    window.add_event_listener_with_callback("keyup", up.as_ref().unchecked_ref())?;
    up.forget();
    // A key released while the page had no focus never sends keyup: let go of everything.
    let i = input.clone();
    let blur = Closure::<dyn FnMut(web_sys::Event)>::new(move |_e: web_sys::Event| {
        let mut i = i.borrow_mut();
        i.keys.clear();
        i.pointer_up(f64::INFINITY);
    });
    window.add_event_listener_with_callback("blur", blur.as_ref().unchecked_ref())?;
    blur.forget();

    let (i, c) = (input.clone(), canvas.clone());
    let pdown = Closure::<dyn FnMut(PointerEvent)>::new(move |e: PointerEvent| {
        let _ = c.set_pointer_capture(e.pointer_id());
        i.borrow_mut()
            .pointer_down(e.button(), cursor(&c, &e), e.ctrl_key(), e.time_stamp());
        e.prevent_default();
    });
    canvas.add_event_listener_with_callback("pointerdown", pdown.as_ref().unchecked_ref())?;
    pdown.forget();
    let (i, c) = (input.clone(), canvas.clone());
    let pmove = Closure::<dyn FnMut(PointerEvent)>::new(move |e: PointerEvent| {
        i.borrow_mut().pointer_move(cursor(&c, &e), e.ctrl_key());
    });
    canvas.add_event_listener_with_callback("pointermove", pmove.as_ref().unchecked_ref())?;
    pmove.forget();
    let i = input.clone();
    let pup = Closure::<dyn FnMut(web_sys::Event)>::new(move |e: web_sys::Event| {
        i.borrow_mut().pointer_up(e.time_stamp());
    });
    for ev in ["pointerup", "pointercancel", "lostpointercapture"] {
        canvas.add_event_listener_with_callback(ev, pup.as_ref().unchecked_ref())?;
    }
    pup.forget();
    let menu = Closure::<dyn FnMut(web_sys::Event)>::new(|e: web_sys::Event| e.prevent_default());
    canvas.add_event_listener_with_callback("contextmenu", menu.as_ref().unchecked_ref())?;
    menu.forget();
    Ok(())
}

/// A viewpoint pasted into the address of an open page (`hashchange`: the page's own
/// `replaceState` does not fire it) moves the observer there.
fn follow_address(window: &web_sys::Window, viewer: &Rc<RefCell<Viewer>>) -> Result<(), JsValue> {
    let v = viewer.clone();
    let moved = Closure::<dyn FnMut(web_sys::Event)>::new(move |_e: web_sys::Event| {
        if let Some((eye, dir)) = viewpoint_from_hash() {
            let mut v = v.borrow_mut();
            v.touring = None;
            v.nav = navigator(eye, dir);
            v.walker.reset();
        }
    });
    window.add_event_listener_with_callback("hashchange", moved.as_ref().unchecked_ref())?;
    moved.forget();
    Ok(())
}

/// Runs one frame per animation frame, forever; refreshes the overlay and the address's
/// viewpoint a few times a second.
fn run_frames(
    viewer: Rc<RefCell<Viewer>>,
    input: Rc<RefCell<Input>>,
    canvas: HtmlCanvasElement,
    overlay: Option<web_sys::Element>,
    panel: Option<web_sys::Element>,
    map: Option<crate::minimap::MiniMap>,
) {
    type Tick = Closure<dyn FnMut(f64)>;
    let tick: Rc<RefCell<Option<Tick>>> = Rc::new(RefCell::new(None));
    let again = tick.clone();
    let mut last_overlay = 0.0f64;
    *tick.borrow_mut() = Some(Closure::new(move |now: f64| {
        {
            let mut v = viewer.borrow_mut();
            let max = v.renderer.device().limits().max_texture_dimension_2d;
            let (w, h) = canvas_size(&canvas, max);
            v.resize(w, h);
            v.frame(now, &mut input.borrow_mut());
            if now - last_overlay > 250.0 {
                last_overlay = now;
                if let Some(o) = &overlay {
                    o.set_text_content(Some(&overlay_text(&v.stats)));
                }
                // The pick panel: what the last click or tap named (hidden after a click on
                // nothing).
                if let Some(p) = &panel {
                    match &v.stats.picked {
                        Some(picked) => {
                            p.set_text_content(Some(&picked.lines()));
                            let _ = p.set_attribute("style", "display: block");
                        }
                        None => {
                            let _ = p.set_attribute("style", "display: none");
                        }
                    }
                }
                if let Some(m) = &map {
                    m.draw(&v);
                }
                share_viewpoint(&v.stats);
            }
        }
        if let (Some(w), Some(cb)) = (web_sys::window(), again.borrow().as_ref()) {
            if let Err(e) = w.request_animation_frame(cb.as_ref().unchecked_ref()) {
                web_sys::console::error_1(&format!("portico: {}", js_error(&e)).into());
            }
        }
    }));
    if let (Some(w), Some(cb)) = (web_sys::window(), tick.borrow().as_ref()) {
        let _ = w.request_animation_frame(cb.as_ref().unchecked_ref());
    }
}

/// The overlay's lines.
fn overlay_text(s: &Stats) -> String {
    let mb = |b: u64| b as f64 / 1_048_576.0;
    let mut t = format!(
        "{:.1} ms/frame ({}, {})\nresident {:.1} of {:.0} MB (budget {:.0} MB with the IO stage)\nvisible {} objects, {} skipped, {} LODs coarser\n{} triangles\nreceived {} segments, {:.2} MB",
        s.mean_frame_ms,
        s.backend,
        s.transport,
        mb(s.resident_bytes),
        mb(s.cache_budget),
        mb(s.budget_bytes),
        s.visible_objects,
        s.objects_skipped,
        s.lods_skipped,
        s.drawn_triangles,
        s.segments_received,
        s.bytes_received as f64 / 1e6,
    );
    if let Some(f) = s.first_complete_ms {
        t += &format!("\nfirst complete frame after {:.0} ms", f);
    }
    if s.touring {
        t += "\ntour (T stops)";
    } else {
        t += match s.gait {
            "walk" => "\nwalking (G: fly)",
            _ => "\nflying (G: walk)",
        };
    }
    if let Some(e) = &s.last_error {
        t += &format!("\n{} errors; last: {e}", s.failures);
    }
    t
}

/// Keeps the address's fragment at the viewpoint (without adding history entries).
fn share_viewpoint(s: &Stats) {
    let f = |v: [f32; 3]| format!("{:.2},{:.2},{:.2}", v[0], v[1], v[2]);
    let hash = format!("#eye={}&dir={}", f(s.eye), f(s.dir));
    if let Some(w) = web_sys::window()
        && let Ok(h) = w.history()
    {
        let _ = h.replace_state_with_url(&JsValue::NULL, "", Some(&hash));
    }
}
