//! A frame's per-pixel stages recorded into one submit, and its one readback.

use super::*;
use crate::extract::params::{Stage, ran};

impl Gpu {
    /// Copies `outputs` one after another into the readback buffer (and, for a `timed`
    /// submit on an adapter with timestamps, the stages' timestamps after them), submits,
    /// runs `beside` on the CPU while the GPU works, and hands the words read back to `read`.
    pub(super) fn submit_and_read<T, B>(
        &self,
        mut encoder: wgpu::CommandEncoder,
        scope: wgpu::ErrorScopeGuard,
        outputs: &[(&wgpu::Buffer, u64)],
        timed: bool,
        beside: impl FnOnce() -> B,
        read: impl FnOnce(&[u32], Option<&[u64]>) -> T,
    ) -> Result<(T, B), GpuError> {
        let f = self.frame.as_ref().expect("frame_for before");
        let mut at = 0;
        for (buffer, bytes) in outputs {
            encoder.copy_buffer_to_buffer(buffer, 0, &f.readback, at, *bytes);
            at += bytes;
        }
        let stamped = f.timestamps.as_ref().filter(|_| timed).map(|(set, resolved)| {
            encoder.resolve_query_set(set, 0..2 * TIMED_STAGES, resolved, 0);
            encoder.copy_buffer_to_buffer(resolved, 0, &f.readback, at, TIMESTAMP_BYTES);
        });
        self.submit(encoder, scope)?;
        let beside = beside();
        let bytes = at + if stamped.is_some() { TIMESTAMP_BYTES } else { 0 };
        let out = self.map(&f.readback, bytes, |data| {
            let (words, stamps) = data.split_at(at as usize);
            // The stamps sit at a multiple of 4 bytes: copy them out rather than cast in place.
            let stamps: Vec<u64> =
                stamps.chunks_exact(8).map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes"))).collect();
            read(bytemuck::cast_slice(words), stamped.map(|_| stamps.as_slice()))
        })?;
        Ok((out, beside))
    }

    /// The per-pixel stages of one depth image, in one submit: the raw depth to metres,
    /// diffusion, normals, Canny with hysteresis, the closed boundary, and the connected
    /// regions inside it. One readback: the region roots, numbered where they lie, and with
    /// `images` the intermediate images too. `beside` runs on the CPU while the GPU works
    /// (the frame's conversion to metres for the CPU's own stages), and its result comes back.
    pub fn image_stages<B>(
        &mut self,
        depth: DepthUpload,
        intr: &Intrinsics,
        cfg: &PipelineConfig,
        images: bool,
        beside: impl FnOnce() -> B,
    ) -> Result<(ImageStages, B), GpuError> {
        let (w, h) = depth.size()?;
        if w.max(h) > DIFFUSION_MAX_LINE {
            return Err(GpuError::TooLarge { width: w, height: h });
        }
        let n = w as u64 * h as u64;
        let mut lap = crate::extract::stopwatch();
        self.frame_for(w, h);
        let f = self.frame.as_ref().expect("made above");
        match depth {
            DepthUpload::Raw(frame) => self.upload_raw(frame),
            DepthUpload::Metres(depth) => self.queue.write_buffer(&f.depth[0], 0, bytemuck::cast_slice(&depth.data)),
        }
        self.write_uniforms(w, h, Some(intr), cfg);
        let upload = lap();

        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&f.strong, 0, None);
        let g = &f.groups;
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let set = f.timestamps.as_ref().map(|(set, _)| set);
        // A diffusion step: rows from depth a into b, then columns from b back into a, a
        // workgroup a line.
        let diffuse = self.diffusion.entry("main");
        let steps: Vec<Dispatch> = (0..DiffusionSchedule::of(cfg).steps)
            .flat_map(|_| [(diffuse, &g.diffusion[0], [h, 1]), (diffuse, &g.diffusion[1], [w, 1])])
            .collect();
        // Metres uploaded: an empty pass, so that every timestamp is written.
        let metres = [(self.metres.entry("main"), &g.metres, size)];
        let raw = matches!(depth, DepthUpload::Raw(_));
        if raw {
            ran(Stage::Metres);
        }
        Self::pass(&mut encoder, set, 0, if raw { &metres } else { &[] });
        ran(Stage::Diffusion);
        Self::pass(&mut encoder, set, 1, &steps);
        ran(Stage::Normals);
        Self::pass(&mut encoder, set, 2, &[(self.normals.entry("main"), &g.normals, size)]);
        // One timed pass for the edges' four stages.
        let mut edges = Vec::new();
        ran(Stage::Gradient);
        edges.push((self.gradient.entry("main"), &g.gradient, size));
        ran(Stage::Classify);
        edges.push((self.classify.entry("main"), &g.classify, size));
        ran(Stage::Hysteresis);
        edges.extend(self.hysteresis_dispatches(size));
        ran(Stage::Boundary);
        edges.extend(self.boundary_dispatches(size));
        Self::pass(&mut encoder, set, 3, &edges);
        ran(Stage::Regions);
        Self::pass(&mut encoder, set, 4, &self.components_dispatches(&g.regions, size));

        let mut outputs = vec![(&f.regions, n * 4)];
        if images {
            outputs.extend([(&f.depth[0], n * 4), (&f.normals, n * 12), (&f.edges, n * 4), (&f.boundary, n * 4)]);
        }
        let (w, h, n) = (w as usize, h as usize, n as usize);
        fn grid<T>(w: usize, h: usize, data: Vec<T>) -> Grid<T> {
            Grid { width: w, height: h, data }
        }
        let period_ms = self.queue.get_timestamp_period() as f64 * 1e-6;
        let mut times = GpuTimes { upload, ..Default::default() };
        let ((regions, images), beside) =
            self.submit_and_read(encoder, scope, &outputs, true, beside, |words, stamps| {
                if let Some(ticks) = stamps {
                    let ms = |k: usize| ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period_ms;
                    [times.metres, times.diffusion, times.normals, times.edges, times.regions] =
                        [ms(0), ms(1), ms(2), ms(3), ms(4)];
                    times.busy = ticks[2 * TIMED_STAGES as usize - 1].saturating_sub(ticks[0]) as f64 * period_ms;
                }
                let floats = |k: usize, per: usize| bytemuck::cast_slice::<u32, f32>(&words[k * n..(k + per) * n]);
                let bytes = |k: usize| words[k * n..(k + 1) * n].iter().map(|&b| b as u8).collect::<Vec<u8>>();
                let images = images.then(|| Images {
                    smoothed: grid(w, h, floats(1, 1).to_vec()),
                    normals: NormalPlanes::of(&grid(
                        w,
                        h,
                        floats(2, 3).chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
                    )),
                    canny: grid(w, h, bytes(5)),
                    boundary: grid(w, h, bytes(6)),
                });
                let mut lap = crate::extract::stopwatch();
                let regions = Segmentation::from_roots(&words[..n], w, MIN_REGION_PIXELS);
                times.numbering = lap();
                (regions, images)
            })?;
        Ok((ImageStages { regions, images, times }, beside))
    }
}
