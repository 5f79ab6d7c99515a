//! The bird's-eye mini-map: the cells of the observer's storey (the live cells whose height
//! range holds the eye) seen from above, the eye's cell filled, the objects drawn in the last
//! frame as dots, and the observer with its view direction. Drawn a few times a second on a
//! small 2D canvas over the view.

use crate::viewer::Viewer;
use glam::Vec3;
use portico_data::geometry::Aabb;
use wasm_bindgen::JsCast;
use web_sys::{CanvasRenderingContext2d, HtmlCanvasElement};

/// A mini-map on a canvas.
pub struct MiniMap {
    canvas: HtmlCanvasElement,
    ctx: CanvasRenderingContext2d,
}

/// World XZ to map pixels: the model's footprint fitted into the canvas with a margin.
struct Fit {
    min: (f32, f32),
    scale: f32,
    offset: (f32, f32),
}

impl Fit {
    fn new(bounds: &Aabb, width: f32, height: f32) -> Fit {
        let margin = 6.0;
        let (w, d) = (
            (bounds.max[0] - bounds.min[0]).max(1e-3),
            (bounds.max[2] - bounds.min[2]).max(1e-3),
        );
        let scale = ((width - 2.0 * margin) / w).min((height - 2.0 * margin) / d);
        Fit {
            min: (bounds.min[0], bounds.min[2]),
            scale,
            offset: ((width - w * scale) / 2.0, (height - d * scale) / 2.0),
        }
    }

    fn at(&self, x: f32, z: f32) -> (f64, f64) {
        (
            f64::from(self.offset.0 + (x - self.min.0) * self.scale),
            f64::from(self.offset.1 + (z - self.min.1) * self.scale),
        )
    }
}

impl MiniMap {
    /// The mini-map on the canvas with id `id`, if the page has one.
    pub fn find(document: &web_sys::Document, id: &str) -> Option<MiniMap> {
        let canvas: HtmlCanvasElement = document.get_element_by_id(id)?.dyn_into().ok()?;
        let ctx = canvas.get_context("2d").ok()??.dyn_into().ok()?;
        Some(MiniMap { canvas, ctx })
    }

    /// Draws the map for the viewer's last frame.
    pub fn draw(&self, v: &Viewer) {
        let (w, h) = (self.canvas.width() as f32, self.canvas.height() as f32);
        let ctx = &self.ctx;
        ctx.clear_rect(0.0, 0.0, f64::from(w), f64::from(h));
        ctx.set_fill_style_str("rgba(0, 0, 0, 0.55)");
        ctx.fill_rect(0.0, 0.0, f64::from(w), f64::from(h));
        let fit = Fit::new(&v.model.header.bounds, w, h);
        let eye = Vec3::from(v.stats.eye);
        let rect = |b: &Aabb| {
            let (x0, z0) = fit.at(b.min[0], b.min[2]);
            let (x1, z1) = fit.at(b.max[0], b.max[2]);
            (x0, z0, (x1 - x0).max(0.5), (z1 - z0).max(0.5))
        };
        if let Some(g) = &v.model.graph {
            let eye_cell = g.locate(eye);
            ctx.set_line_width(0.5);
            ctx.set_stroke_style_str("rgba(255, 255, 255, 0.35)");
            for (i, c) in g.cells.iter().enumerate() {
                let storey = c.bounds.min[1] <= eye.y && eye.y <= c.bounds.max[1];
                if !c.live || !storey {
                    continue;
                }
                let (x, z, cw, cd) = rect(&c.bounds);
                if Some(i as u32) == eye_cell {
                    ctx.set_fill_style_str("rgba(255, 214, 90, 0.45)");
                    ctx.fill_rect(x, z, cw, cd);
                }
                ctx.stroke_rect(x, z, cw, cd);
            }
        } else {
            ctx.set_stroke_style_str("rgba(255, 255, 255, 0.5)");
            let (x, z, cw, cd) = rect(&v.model.header.bounds);
            ctx.stroke_rect(x, z, cw, cd);
        }
        ctx.set_fill_style_str("rgba(120, 220, 255, 0.9)");
        for &(o, _, _) in &v.drawn {
            if let Some(b) = v.model.bounds.get(o as usize) {
                let c = b.center();
                let (x, z) = fit.at(c.x, c.z);
                ctx.fill_rect(x - 1.0, z - 1.0, 2.0, 2.0);
            }
        }
        let (ex, ez) = fit.at(eye.x, eye.z);
        let dir = Vec3::from(v.stats.dir);
        let flat = Vec3::new(dir.x, 0.0, dir.z).normalize_or(Vec3::X) * 14.0;
        ctx.set_stroke_style_str("rgb(255, 80, 60)");
        ctx.set_line_width(2.0);
        ctx.begin_path();
        ctx.move_to(ex, ez);
        ctx.line_to(ex + f64::from(flat.x), ez + f64::from(flat.z));
        ctx.stroke();
        ctx.set_fill_style_str("rgb(255, 80, 60)");
        ctx.begin_path();
        let _ = ctx.arc(ex, ez, 3.5, 0.0, std::f64::consts::TAU);
        ctx.fill();
    }
}
