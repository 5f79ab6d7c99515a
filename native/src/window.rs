//! `portico walk --window` (cargo feature `window`): the same client in a window, driven by the
//! mouse and keyboard as Funkhouser §3.3.1 describes ([`portico_client::navigate`]), optionally recording
//! the walk as a path (`--record`) that `portico walk --path` and `portico bench` replay.
//! The observer walks as a person by default ([`portico_client::walk`]: walls, floors, stairs,
//! holes); G switches to flying and back.
//!
//! Frames are drawn by the same [`portico_render::Renderer`] as headless walks, straight into
//! the window's wgpu surface ([`Session::frame_into`]: no read-back). Where no surface works
//! (no adapter can present to this window) they are drawn offscreen, read back and shown
//! through a software framebuffer (softbuffer), so the window works wherever the headless
//! client does. The frame loop never waits for the network, exactly as in [`crate::walk`];
//! frames are paced to the budget.

use crate::walk::{Session, WalkConfig, WalkSummary};
use anyhow::{Context as _, Result};
use glam::Vec3;
use portico_client::navigate::{Controls, Navigator, Recorder, Step};
use portico_client::walk::Gait;
use portico_render::wgpu;
use portico_render::{COLOR_FORMAT, Renderer};
use std::num::NonZeroU32;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

/// What the window adds to a walk's settings.
#[derive(Debug, Clone, Default)]
pub struct WindowOptions {
    /// Save the walk as a path (JSON keyframes) here when the window closes.
    pub record: Option<PathBuf>,
}

/// Opens a window and walks where the user steers until the window is closed, Escape is pressed
/// or `cfg.max_frames` frames are drawn. Starts at the first keyframe of `cfg.path`.
pub fn run(cfg: &WalkConfig, opts: &WindowOptions) -> Result<WalkSummary> {
    if let Some(out) = &cfg.out {
        std::fs::create_dir_all(out.join("frames"))
            .with_context(|| format!("creating {}", out.display()))?;
    }
    let (eye, dir) = cfg.path.sample(0.0);
    let nav = Navigator::new(eye, dir, cfg.max_speed, cfg.max_turn);
    let event_loop = EventLoop::new().context("opening the display (is DISPLAY set?)")?;
    let mut app = App {
        cfg,
        session: None,
        eye: nav.eye,
        nav,
        gait: Gait::Walk,
        controls: Controls::default(),
        recorder: Recorder::default(),
        view: None,
        started: Instant::now(),
        last: Instant::now(),
        next_frame: Instant::now(),
        frames: 0,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .context("the window's event loop")?;
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    if let Some(path) = &opts.record {
        let json = serde_json::to_vec_pretty(&app.recorder.path())?;
        std::fs::write(path, json).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("recorded the walk to {}", path.display());
    }
    app.session
        .take()
        .context("the window closed before the walk started")?
        .finish()
}

/// How frames reach the window.
enum Show {
    /// Drawn straight into the window's surface.
    Surface {
        surface: wgpu::Surface<'static>,
        config: wgpu::SurfaceConfiguration,
    },
    /// Drawn offscreen, read back and copied into a software framebuffer.
    Framebuffer {
        surface: softbuffer::Surface<Arc<Window>, Arc<Window>>,
        _context: softbuffer::Context<Arc<Window>>,
    },
}

/// The window and what shows the frames in it.
struct View {
    window: Arc<Window>,
    show: Show,
}

struct App<'a> {
    cfg: &'a WalkConfig,
    session: Option<Session<'a>>,
    nav: Navigator,
    /// Walking (the default: [`portico_client::walk`]) or flying (G switches), and the eye
    /// after the last frame (where a walk goes on from).
    gait: Gait,
    eye: Vec3,
    controls: Controls,
    recorder: Recorder,
    view: Option<View>,
    started: Instant,
    last: Instant,
    next_frame: Instant,
    frames: u64,
    error: Option<anyhow::Error>,
}

/// A renderer on an adapter that can present to `window`, and the window's surface configured
/// for it.
fn surface_renderer(
    window: &Arc<Window>,
    (w, h): (u32, u32),
) -> Result<(Renderer, wgpu::Surface<'static>, wgpu::SurfaceConfiguration)> {
    let desc = wgpu::InstanceDescriptor::new_with_display_handle_from_env(Box::new(window.clone()));
    let instance = wgpu::Instance::new(desc);
    let surface = instance.create_surface(window.clone())?;
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        compatible_surface: Some(&surface),
        ..Default::default()
    }))?;
    let mut config = surface
        .get_default_config(&adapter, w, h)
        .context("the adapter cannot present to this window")?;
    let formats = surface.get_capabilities(&adapter).formats;
    if !formats.contains(&COLOR_FORMAT) {
        let plain = COLOR_FORMAT.remove_srgb_suffix();
        anyhow::ensure!(
            formats.contains(&plain),
            "the window offers none of {COLOR_FORMAT:?}, {plain:?}"
        );
        config.format = plain;
        config.view_formats = vec![COLOR_FORMAT];
    } else {
        config.format = COLOR_FORMAT;
    }
    let renderer = pollster::block_on(Renderer::on_adapter(instance, &adapter, w, h, None))?;
    surface.configure(renderer.device(), &config);
    Ok((renderer, surface, config))
}

impl App<'_> {
    /// Opens the window, then the session on a renderer that presents to it (or, failing
    /// that, on an offscreen one with a software framebuffer).
    fn open(&mut self, el: &ActiveEventLoop) -> Result<()> {
        let (w, h) = self.cfg.size;
        let attrs = Window::default_attributes()
            .with_title("Portico")
            .with_inner_size(PhysicalSize::new(w, h))
            .with_resizable(false);
        let window = Arc::new(el.create_window(attrs).context("creating the window")?);
        // `PORTICO_WINDOW_READBACK=1` asks for the read-back (to compare, or to work around a
        // driver whose surfaces misbehave).
        let presented = match std::env::var_os("PORTICO_WINDOW_READBACK") {
            Some(_) => Err(anyhow::anyhow!("PORTICO_WINDOW_READBACK is set")),
            None => surface_renderer(&window, (w, h)),
        };
        let (session, show) = match presented {
            Ok((renderer, surface, config)) => (
                Session::open_on(self.cfg, renderer)?,
                Show::Surface { surface, config },
            ),
            Err(e) => {
                eprintln!("no wgpu surface for the window ({e:#}): frames are read back instead");
                let context = softbuffer::Context::new(window.clone())
                    .map_err(|e| anyhow::anyhow!("window framebuffer: {e}"))?;
                let mut surface = softbuffer::Surface::new(&context, window.clone())
                    .map_err(|e| anyhow::anyhow!("window framebuffer: {e}"))?;
                if let (Some(nw), Some(nh)) = (NonZeroU32::new(w.max(1)), NonZeroU32::new(h.max(1)))
                {
                    surface
                        .resize(nw, nh)
                        .map_err(|e| anyhow::anyhow!("window framebuffer: {e}"))?;
                }
                (
                    Session::open(self.cfg)?,
                    Show::Framebuffer {
                        surface,
                        _context: context,
                    },
                )
            }
        };
        self.session = Some(session);
        self.view = Some(View { window, show });
        Ok(())
    }

    /// One frame: move the observer, draw, show. Returns the frames drawn so far.
    fn draw(&mut self) -> Result<u64> {
        let now = Instant::now();
        let dt = now.duration_since(self.last).as_secs_f32().min(0.25);
        self.last = now;
        let before = self.nav.dir();
        let mut velocity = self.nav.update(&self.controls, dt);
        if self.gait == Gait::Walk
            && let Some(session) = self.session.as_mut()
        {
            self.nav.eye = session.walk(self.eye, self.nav.eye, dt);
            // Along the floor: a step taken in one frame is not a climb at metres a second.
            let moved = self.nav.eye - self.eye;
            velocity = if dt > 0.0 {
                Vec3::new(moved.x, 0.0, moved.z) / dt
            } else {
                Vec3::ZERO
            };
        }
        self.eye = self.nav.eye;
        let motion = portico_client::view::Motion {
            velocity,
            turn: portico_client::view::Motion::between(
                self.nav.eye,
                before,
                self.nav.eye,
                self.nav.dir(),
                dt,
            )
            .turn,
        };
        let t = now.duration_since(self.started).as_secs_f64();
        self.recorder.note(t as f32, self.nav.eye, self.nav.dir());
        let session = self.session.as_mut().context("no session")?;
        let obs = session.observer(self.nav.eye, self.nav.dir(), motion);
        let frame = self.frames;
        let png = self.cfg.png_every > 0 && frame.is_multiple_of(self.cfg.png_every);
        if png {
            session.want_picture();
        }
        let view = self.view.as_mut().context("no window")?;
        match &mut view.show {
            Show::Surface { surface, config } => {
                let texture = match surface.get_current_texture() {
                    wgpu::CurrentSurfaceTexture::Success(t)
                    | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
                    // Lost, outdated or timed out: configure again and draw the next frame.
                    _ => {
                        surface.configure(session.renderer().device(), config);
                        return Ok(frame);
                    }
                };
                let target = texture.texture.create_view(&wgpu::TextureViewDescriptor {
                    format: Some(COLOR_FORMAT),
                    ..Default::default()
                });
                session.frame_into(t, &obs, &target)?;
                session.renderer().queue().present(texture);
            }
            Show::Framebuffer { surface, .. } => {
                session.frame(t, &obs)?;
                let img = session.image()?;
                let mut buf = surface
                    .buffer_mut()
                    .map_err(|e| anyhow::anyhow!("window framebuffer: {e}"))?;
                for (dst, p) in buf.iter_mut().zip(img.pixels()) {
                    *dst = u32::from(p[0]) << 16 | u32::from(p[1]) << 8 | u32::from(p[2]);
                }
                buf.present()
                    .map_err(|e| anyhow::anyhow!("window framebuffer: {e}"))?;
            }
        }
        if png {
            session.save_png(frame)?;
        }
        self.frames += 1;
        Ok(self.frames)
    }

    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        self.error = Some(e);
        el.exit();
    }
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.view.is_none()
            && let Err(e) = self.open(el)
        {
            self.fail(el, e);
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::RedrawRequested => match self.draw() {
                Err(e) => self.fail(el, e),
                // `--max-frames` ends an interactive walk too (handy for scripted runs).
                Ok(frames) if self.cfg.max_frames.is_some_and(|m| frames >= m) => el.exit(),
                Ok(_) => {}
            },
            WindowEvent::CursorMoved { position, .. } => self.cursor(position),
            WindowEvent::MouseInput { state, button, .. } => {
                let down = state == ElementState::Pressed;
                match button {
                    MouseButton::Left => self.controls.forward = down,
                    MouseButton::Right => self.controls.backward = down,
                    MouseButton::Middle => self.controls.spin = down,
                    _ => {}
                }
            }
            WindowEvent::ModifiersChanged(m) => self.controls.pitch = m.state().control_key(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                let PhysicalKey::Code(code) = event.physical_key else {
                    return;
                };
                if code == KeyCode::Escape {
                    el.exit();
                } else if code == KeyCode::KeyG {
                    self.gait = match self.gait {
                        Gait::Walk => Gait::Fly,
                        Gait::Fly => Gait::Walk,
                    };
                    if let Some(session) = self.session.as_mut() {
                        session.reset_walk();
                    }
                } else if let Some(step) = key_step(code) {
                    self.nav.step(step);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        // One frame per budget: the same pace as a headless walk.
        let now = Instant::now();
        if now >= self.next_frame {
            self.next_frame = now + Duration::from_secs_f64(self.cfg.budget_s.max(1e-3));
            if let Some(v) = &self.view {
                v.window.request_redraw();
            }
        }
        el.set_control_flow(ControlFlow::WaitUntil(self.next_frame));
    }
}

impl App<'_> {
    fn cursor(&mut self, p: PhysicalPosition<f64>) {
        let (w, h) = self.cfg.size;
        self.controls.cursor = [
            (p.x as f32 / w.max(1) as f32) * 2.0 - 1.0,
            1.0 - (p.y as f32 / h.max(1) as f32) * 2.0,
        ];
    }
}

/// Funkhouser's arrow and keypad keys.
fn key_step(code: KeyCode) -> Option<Step> {
    Some(match code {
        KeyCode::ArrowLeft => Step::SpinLeft,
        KeyCode::ArrowRight => Step::SpinRight,
        KeyCode::ArrowUp => Step::SpinUp,
        KeyCode::ArrowDown => Step::SpinDown,
        KeyCode::Numpad4 => Step::Left,
        KeyCode::Numpad6 => Step::Right,
        KeyCode::Numpad8 => Step::Up,
        KeyCode::Numpad2 => Step::Down,
        KeyCode::Numpad5 => Step::Forward,
        KeyCode::NumpadDivide => Step::Back,
        _ => return None,
    })
}
