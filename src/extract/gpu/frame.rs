//! A frame size's buffers, uniforms and bind groups, made once and reused, and the
//! dispatch lists of the stages that chain several passes.

use super::*;

impl Gpu {
    /// Writes a raw depth frame (16-bit values, two a word, the first in the low half on
    /// the little-endian hosts wgpu runs on) and its scale for shaders/metres.wgsl. A
    /// write is whole words: an odd pixel count's last word is padded.
    pub(super) fn upload_raw(&self, frame: &DepthFrame) {
        let f = self.frame.as_ref().expect("frame_for before");
        let bytes: &[u8] = bytemuck::cast_slice(&frame.pixels);
        let (whole, last) = bytes.split_at(bytes.len() / 4 * 4);
        self.queue.write_buffer(&f.raw, 0, whole);
        if !last.is_empty() {
            let mut word = [0u8; 4];
            word[..last.len()].copy_from_slice(last);
            self.queue.write_buffer(&f.raw, whole.len() as u64, &word);
        }
        let params = MetresParams { width: frame.width, height: frame.height, scale: frame.depth_scale as f32, pad: 0 };
        self.queue.write_buffer(&f.metres_params, 0, bytemuck::bytes_of(&params));
    }

    /// The dispatches of shaders/components.wgsl over one bind group.
    pub(super) fn components_dispatches<'a>(&'a self, group: &'a wgpu::BindGroup, size: [u32; 2]) -> [Dispatch<'a>; 3] {
        let c = &self.components;
        [(c.entry("init"), group, size), (c.entry("merge"), group, size), (c.entry("flatten"), group, size)]
    }

    pub(super) fn frame_for(&mut self, width: u32, height: u32) {
        if self.frame.as_ref().is_some_and(|f| f.width == width && f.height == height) {
            return;
        }
        let n = width as u64 * height as u64;
        let image = |label: &str, bytes_per_pixel: u64| self.buffer(label, n * bytes_per_pixel, IMAGE);
        let depth = [image("depth a", 4), image("depth b", 4)];
        let raw = self.buffer("raw depth", n.div_ceil(2) * 4, IMAGE);
        let normals = image("normals", 12);
        let (magnitude, sector, class) = (image("magnitude", 4), image("sector", 4), image("class", 4));
        let (parent, edge_labels, strong, edges) =
            (image("parent", 4), image("edge labels", 4), image("strong", 4), image("edges", 4));
        let (lines, closed, holes, sealed, boundary) =
            (image("lines", 4), image("closed", 4), image("holes", 4), image("sealed", 4), image("boundary", 4));
        let scratch = [image("morphology a", 4), image("morphology b", 4)];
        let regions = image("regions", 4);
        // Regions, smoothed depth, normals (3), edges, boundary: 7 words a pixel at most.
        let readback = self.buffer(
            "readback",
            n * 4 * 7 + TIMESTAMP_BYTES,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let zeros = |bytes: usize| self.uniform(&vec![0u8; bytes]);
        let metres_params = zeros(size_of::<MetresParams>());
        let diffusion_params = [zeros(size_of::<DiffusionParams>()), zeros(size_of::<DiffusionParams>())];
        let normals_params = zeros(size_of::<NormalsParams>());
        let canny_params = zeros(size_of::<CannyParams>());
        let morphology_params: Vec<wgpu::Buffer> = (0..8).map(|_| zeros(size_of::<MorphologyParams>())).collect();
        let boundary_params = zeros(size_of::<BoundaryParams>());
        let components_params = |inside_nonzero| {
            self.uniform(bytemuck::bytes_of(&ComponentsParams { width, height, inside_nonzero, pad: 0 }))
        };
        let (edge_params, region_params) = (components_params(1), components_params(0));
        let sobel = self.buffer("sobel", 14 * 4, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        // Closing: lines -> a -> b -> a -> closed; sealing: holes -> a -> b -> a -> sealed.
        let [a, b] = &scratch;
        let morphology_io = [(&lines, a), (a, b), (b, a), (a, &closed), (&holes, a), (a, b), (b, a), (a, &sealed)];
        let groups = FrameGroups {
            metres: self.bind(&self.metres, &[&metres_params, &raw, &depth[0]]),
            diffusion: [
                self.bind(&self.diffusion, &[&diffusion_params[0], &depth[0], &depth[1]]),
                self.bind(&self.diffusion, &[&diffusion_params[1], &depth[1], &depth[0]]),
            ],
            normals: self.bind(&self.normals, &[&normals_params, &depth[0], &sobel, &normals]),
            gradient: self.bind(&self.gradient, &[&canny_params, &normals, &magnitude, &sector]),
            classify: self.bind(&self.classify, &[&canny_params, &magnitude, &sector, &class]),
            edge_components: self.bind(&self.components, &[&edge_params, &class, &parent, &edge_labels]),
            hysteresis: self.bind(&self.hysteresis, &[&canny_params, &class, &edge_labels, &strong, &edges]),
            lines: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &lines]),
            morphology: morphology_io
                .iter()
                .zip(&morphology_params)
                .map(|((src, dst), params)| self.bind(&self.morphology, &[params, src, dst]))
                .collect(),
            holes: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &holes]),
            seal: self
                .bind(&self.boundary, &[&boundary_params, &depth[0], &normals, &edges, &closed, &sealed, &boundary]),
            regions: self.bind(&self.components, &[&region_params, &boundary, &parent, &regions]),
        };
        let timestamps = self.timestamps.then(|| {
            let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * TIMED_STAGES,
            });
            let resolved = self.buffer(
                "timestamps",
                TIMESTAMP_BYTES,
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            );
            (set, resolved)
        });
        self.frame = Some(Frame {
            width,
            height,
            raw,
            depth,
            normals,
            magnitude,
            sector,
            class,
            edges,
            lines,
            closed,
            boundary,
            regions,
            strong,
            readback,
            metres_params,
            diffusion_params,
            normals_params,
            canny_params,
            morphology_params,
            boundary_params,
            sobel,
            groups,
            timestamps,
        });
    }

    /// Writes every stage's uniform from the config and the image's size.
    pub(super) fn write_uniforms(&self, w: u32, h: u32, intr: Option<&Intrinsics>, cfg: &PipelineConfig) {
        let f = self.frame.as_ref().expect("frame_for before");
        let q = &self.queue;
        let DiffusionSchedule { step, inv_kappa, .. } = DiffusionSchedule::of(cfg);
        let rows = DiffusionParams { len: w, lines: h, line_stride: w, elem_stride: 1, step, inv_kappa };
        let columns = DiffusionParams { len: h, lines: w, line_stride: 1, elem_stride: w, step, inv_kappa };
        q.write_buffer(&f.diffusion_params[0], 0, bytemuck::bytes_of(&rows));
        q.write_buffer(&f.diffusion_params[1], 0, bytemuck::bytes_of(&columns));
        let (smooth, deriv, norm) = sobel_kernel(cfg.normal_kernel);
        let mut weights = [0.0f32; 14];
        weights[..smooth.len()].copy_from_slice(smooth);
        weights[7..7 + deriv.len()].copy_from_slice(deriv);
        q.write_buffer(&f.sobel, 0, bytemuck::cast_slice(&weights));
        if let Some(intr) = intr {
            let normals = NormalsParams {
                width: w,
                height: h,
                radius: cfg.normal_kernel / 2,
                norm,
                fx: intr.fx as f32,
                fy: intr.fy as f32,
                cx: intr.cx as f32,
                cy: intr.cy as f32,
            };
            q.write_buffer(&f.normals_params, 0, bytemuck::bytes_of(&normals));
        }
        let canny = CannyParams { width: w, height: h, low: cfg.canny_low as f32, high: cfg.canny_high as f32 };
        q.write_buffer(&f.canny_params, 0, bytemuck::bytes_of(&canny));
        // The lines are closed with the closing square, the pixels without normals sealed with the normal kernel's.
        let closing = closing_passes(w, h, cfg.closing_kernel_px);
        let seal = closing_passes(w, h, cfg.normal_kernel);
        for (buffer, params) in f.morphology_params.iter().zip(closing.iter().chain(&seal)) {
            q.write_buffer(buffer, 0, bytemuck::bytes_of(params));
        }
        let boundary = BoundaryParams { width: w, height: h, depth_edge_ratio: cfg.depth_edge_ratio as f32, pad: 0 };
        q.write_buffer(&f.boundary_params, 0, bytemuck::bytes_of(&boundary));
    }

    /// Hysteresis from the classes: edge components, strong ones marked, their pixels kept.
    pub(super) fn hysteresis_dispatches(&self, size: [u32; 2]) -> Vec<Dispatch<'_>> {
        let g = &self.frame.as_ref().expect("frame_for before").groups;
        let mut out = self.components_dispatches(&g.edge_components, size).to_vec();
        out.push((self.hysteresis.entry("mark_strong"), &g.hysteresis, size));
        out.push((self.hysteresis.entry("keep"), &g.hysteresis, size));
        out
    }

    /// The boundary from the edges, the smoothed depth and the normals: lines, closing,
    /// holes, sealing, the 4-neighbour growth.
    pub(super) fn boundary_dispatches(&self, size: [u32; 2]) -> Vec<Dispatch<'_>> {
        let g = &self.frame.as_ref().expect("frame_for before").groups;
        let morph = self.morphology.entry("main");
        let mut out = vec![(self.boundary.entry("lines"), &g.lines, size)];
        out.extend(g.morphology[..4].iter().map(|group| (morph, group, size)));
        out.push((self.boundary.entry("holes"), &g.holes, size));
        out.extend(g.morphology[4..].iter().map(|group| (morph, group, size)));
        out.push((self.boundary.entry("seal"), &g.seal, size));
        out
    }
}
