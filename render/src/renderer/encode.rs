//! Encoding one frame: the globals and per-instance data written to their buffers, and the
//! draws recorded into the render pass, grouped by pipeline and texture.

use super::*;

impl Renderer {
    pub(super) fn write_globals(&self, view_proj: Mat4) {
        let g = Globals {
            view_proj: view_proj.to_cols_array_2d(),
            light_dir: self.light_dir.extend(0.0).to_array(),
            ambient: [self.ambient, 0.0, 0.0, 0.0],
        };
        self.queue
            .write_buffer(&self.globals, 0, bytemuck::bytes_of(&g));
    }

    /// Writes one [`InstanceData`] per draw, growing the buffer to a power of two if needed.
    pub(super) fn write_instances(&mut self, draws: &[Draw<'_>]) -> Result<(), RenderError> {
        let needed = draws.len() as u64;
        let stride = std::mem::size_of::<InstanceData>() as u64;
        if needed * stride > self.instances.size() {
            let capacity = needed.next_power_of_two();
            let limit = self.device.limits().max_buffer_size;
            if capacity * stride > limit {
                return Err(RenderError::TooLarge {
                    size: capacity * stride,
                    limit,
                });
            }
            self.instances = create_instance_buffer(&self.device, capacity);
        }
        let data: Vec<InstanceData> = draws
            .iter()
            .map(|d| InstanceData {
                model: d.transform.to_cols_array_2d(),
                color: d.color,
                params: [
                    match d.alpha {
                        AlphaMode::Mask(c) => c.max(1e-3),
                        _ => 0.0,
                    },
                    if d.alpha == AlphaMode::Blend {
                        1.0
                    } else {
                        0.0
                    },
                    crate::pipeline::flags(&d.surface, &d.transform) as f32,
                    0.0,
                ],
                emissive: [
                    d.surface.emissive[0],
                    d.surface.emissive[1],
                    d.surface.emissive[2],
                    0.0,
                ],
            })
            .collect();
        if !data.is_empty() {
            self.queue
                .write_buffer(&self.instances, 0, bytemuck::cast_slice(&data));
        }
        Ok(())
    }

    /// Records one instanced draw per non-empty mesh — plain opaque ones, then textured and
    /// cut-out ones, then the textured boxes, then blended ones in the order given — into an
    /// open pass.
    pub(super) fn encode_draws(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> FrameTiming {
        let mut timing = FrameTiming::default();
        let blended = |d: &Draw<'_>| d.alpha == AlphaMode::Blend;
        let m = &self.materials;
        self.encode_group(pass, draws, &mut timing, |d| {
            (!blended(d) && !d.textured()).then_some(if d.surface.double_sided {
                &self.pipeline
            } else if d.transform.determinant() < 0.0 {
                &m.plain_culled_mirrored
            } else {
                &m.plain_culled
            })
        });
        self.encode_group(pass, draws, &mut timing, |d| {
            (!blended(d) && d.textured()).then_some(&m.textured)
        });
        self.textured.draw(pass, &self.bind_group, boxes);
        self.encode_group(pass, draws, &mut timing, |d| {
            blended(d).then_some(if d.textured() {
                &m.textured_over
            } else {
                &m.plain_over
            })
        });
        timing.triangles += 12 * boxes.len() as u64;
        timing.vertices += 24 * boxes.len() as u64;
        timing.draws += boxes.len() as u32;
        timing
    }

    /// Records, in order, the draws `pipeline_of` gives a pipeline, each with it (a textured
    /// one binds the draw's texture and coordinates); instance `i` is the draw's index in the
    /// frame's draws.
    fn encode_group<'p>(
        &'p self,
        pass: &mut wgpu::RenderPass<'_>,
        draws: &[Draw<'_>],
        timing: &mut FrameTiming,
        pipeline_of: impl Fn(&Draw<'_>) -> Option<&'p wgpu::RenderPipeline>,
    ) {
        let mut current: Option<&wgpu::RenderPipeline> = None;
        let mut bound: Option<&GpuMesh> = None;
        let mut texture: Option<&GpuTexture> = None;
        for (i, d) in (0u32..).zip(draws) {
            let Some(pipeline) = pipeline_of(d).filter(|_| d.mesh.index_count > 0) else {
                continue;
            };
            if !current.is_some_and(|c| std::ptr::eq(c, pipeline)) {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.set_vertex_buffer(1, self.instances.slice(..));
                current = Some(pipeline);
                (bound, texture) = (None, None);
            }
            let instance = i;
            if !bound.is_some_and(|b| std::ptr::eq(b, d.mesh)) {
                pass.set_vertex_buffer(0, d.mesh.vertex.slice(..));
                pass.set_index_buffer(d.mesh.index.slice(..), d.mesh.index_format);
                if let (true, Some(uv)) = (d.textured(), &d.mesh.uv) {
                    pass.set_vertex_buffer(2, uv.slice(..));
                }
                bound = Some(d.mesh);
            }
            if let Some(t) = d.texture.filter(|_| d.textured())
                && !texture.is_some_and(|b| std::ptr::eq(b, t))
            {
                pass.set_bind_group(1, &t.bind_group, &[]);
                texture = Some(t);
            }
            pass.draw_indexed(0..d.mesh.index_count, 0, instance..instance + 1);
            timing.triangles += u64::from(d.mesh.triangles());
            timing.vertices += u64::from(d.mesh.vertex_count);
            timing.draws += 1;
        }
    }

    /// A pass that clears and draws into the multisampled target resolved into `target`, or
    /// into `target` itself with one sample per pixel.
    pub(super) fn begin_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
    ) -> wgpu::RenderPass<'e> {
        let msaa = self.targets.msaa_view.as_ref();
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frame"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: msaa.unwrap_or(target),
                depth_slice: None,
                resolve_target: msaa.map(|_| target),
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(self.clear),
                    store: if msaa.is_some() {
                        wgpu::StoreOp::Discard
                    } else {
                        wgpu::StoreOp::Store
                    },
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.targets.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }
}
