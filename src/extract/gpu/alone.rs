//! Each stage alone on inputs written into the frame's buffers: the GPU-vs-CPU tests'
//! entry points (tests/gpu.rs).

use super::*;

impl Gpu {
    /// Runs `dispatches` alone on inputs written into the frame's buffers, and reads
    /// `outputs` back, one after another.
    pub(super) fn stage_alone(
        &self,
        inputs: &[(&wgpu::Buffer, &[u8])],
        dispatches: &[Dispatch],
        outputs: &[(&wgpu::Buffer, u64)],
    ) -> Result<Vec<u32>, GpuError> {
        let f = self.frame.as_ref().expect("frame_for before");
        for (buffer, data) in inputs {
            self.queue.write_buffer(buffer, 0, data);
        }
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&f.strong, 0, None);
        Self::pass(&mut encoder, None, 0, dispatches);
        let (words, ()) = self.submit_and_read(encoder, scope, outputs, false, || (), |words, _| words.to_vec())?;
        Ok(words)
    }

    /// The raw depth's conversion to metres alone on the GPU: the stage's GPU-vs-CPU test.
    pub fn metres_alone(&mut self, frame: &DepthFrame) -> Result<Grid<f32>, GpuError> {
        let (w, h) = DepthUpload::Raw(frame).size()?;
        self.frame_for(w, h);
        self.upload_raw(frame);
        let f = self.frame.as_ref().expect("made above");
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[],
            &[(self.metres.entry("main"), &f.groups.metres, size)],
            &[(&f.depth[0], frame.pixels.len() as u64 * 4)],
        )?;
        Ok(Grid { width: w as usize, height: h as usize, data: words.into_iter().map(f32::from_bits).collect() })
    }

    /// Hysteresis alone on the GPU, from classify's classes: the stage's GPU-vs-CPU test.
    pub fn hysteresis_alone(&mut self, class: &Grid<u8>, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (class.width as u32, class.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let class32: Vec<u32> = class.data.iter().map(|&c| c as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.class, bytemuck::cast_slice(&class32))],
            &self.hysteresis_dispatches(size),
            &[(&f.edges, class.data.len() as u64 * 4)],
        )?;
        Ok(Grid { width: class.width, height: class.height, data: words.into_iter().map(|e| e as u8).collect() })
    }

    /// The closed boundary alone on the GPU, from Canny's edges, the smoothed depth and the normals.
    pub fn boundary_alone(
        &mut self,
        canny: &Grid<u8>,
        smoothed: &Grid<f32>,
        normals: &Grid<[f32; 3]>,
        cfg: &PipelineConfig,
    ) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (canny.width as u32, canny.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let edges: Vec<u32> = canny.data.iter().map(|&c| c as u32).collect();
        let inputs: [(&wgpu::Buffer, &[u8]); 3] = [
            (&f.edges, bytemuck::cast_slice(&edges)),
            (&f.depth[0], bytemuck::cast_slice(&smoothed.data)),
            (&f.normals, bytemuck::cast_slice(&normals.data)),
        ];
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words =
            self.stage_alone(&inputs, &self.boundary_dispatches(size), &[(&f.boundary, canny.data.len() as u64 * 4)])?;
        Ok(Grid { width: canny.width, height: canny.height, data: words.into_iter().map(|b| b as u8).collect() })
    }

    /// The regions' components alone on the GPU, from a boundary: root + 1 labels.
    pub fn regions_alone(&mut self, boundary: &Grid<u8>) -> Result<Grid<u32>, GpuError> {
        let (w, h) = (boundary.width as u32, boundary.height as u32);
        self.frame_for(w, h);
        let f = self.frame.as_ref().expect("made above");
        let mask: Vec<u32> = boundary.data.iter().map(|&b| b as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let dispatches = self.components_dispatches(&f.groups.regions, size);
        let words = self.stage_alone(
            &[(&f.boundary, bytemuck::cast_slice(&mask))],
            &dispatches,
            &[(&f.regions, mask.len() as u64 * 4)],
        )?;
        Ok(Grid { width: boundary.width, height: boundary.height, data: words })
    }

    /// The diffusion's steps alone on the GPU, from depth in metres: the stage's GPU-vs-CPU test.
    pub fn diffusion_alone(&mut self, depth: &Grid<f32>, cfg: &PipelineConfig) -> Result<Grid<f32>, GpuError> {
        let (w, h) = (depth.width as u32, depth.height as u32);
        if w.max(h) > DIFFUSION_MAX_LINE {
            return Err(GpuError::TooLarge { width: w, height: h });
        }
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let diffuse = self.diffusion.entry("main");
        let steps: Vec<Dispatch> = (0..DiffusionSchedule::of(cfg).steps)
            .flat_map(|_| [(diffuse, &f.groups.diffusion[0], [h, 1]), (diffuse, &f.groups.diffusion[1], [w, 1])])
            .collect();
        let words = self.stage_alone(
            &[(&f.depth[0], bytemuck::cast_slice(&depth.data))],
            &steps,
            &[(&f.depth[0], depth.data.len() as u64 * 4)],
        )?;
        Ok(Grid { width: depth.width, height: depth.height, data: words.into_iter().map(f32::from_bits).collect() })
    }

    /// The normal field's gradient alone on the GPU, from interleaved normals.
    pub fn gradient_alone(&mut self, normals: &Grid<[f32; 3]>, cfg: &PipelineConfig) -> Result<Gradient, GpuError> {
        let (w, h) = (normals.width as u32, normals.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let n = normals.data.len();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.normals, bytemuck::cast_slice(&normals.data))],
            &[(self.gradient.entry("main"), &f.groups.gradient, size)],
            &[(&f.magnitude, n as u64 * 4), (&f.sector, n as u64 * 4)],
        )?;
        let (magnitude, sector) = words.split_at(n);
        let grid = |data| Grid { width: normals.width, height: normals.height, data };
        Ok(Gradient {
            magnitude: grid(magnitude.iter().map(|&m| f32::from_bits(m)).collect()),
            sector: Grid {
                width: normals.width,
                height: normals.height,
                data: sector.iter().map(|&s| s as u8).collect(),
            },
        })
    }

    /// Non-maximum suppression and the double threshold alone on the GPU, from a gradient.
    pub fn classify_alone(&mut self, grad: &Gradient, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (grad.magnitude.width as u32, grad.magnitude.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let sectors: Vec<u32> = grad.sector.data.iter().map(|&s| s as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let words = self.stage_alone(
            &[(&f.magnitude, bytemuck::cast_slice(&grad.magnitude.data)), (&f.sector, bytemuck::cast_slice(&sectors))],
            &[(self.classify.entry("main"), &f.groups.classify, size)],
            &[(&f.class, sectors.len() as u64 * 4)],
        )?;
        Ok(Grid {
            width: grad.magnitude.width,
            height: grad.magnitude.height,
            data: words.into_iter().map(|c| c as u8).collect(),
        })
    }

    /// The morphology alone on the GPU: the boundary's closing of a mask (its first four
    /// passes, `closing_passes` of `closing_kernel_px`).
    pub fn closing_alone(&mut self, mask: &Grid<u8>, cfg: &PipelineConfig) -> Result<Grid<u8>, GpuError> {
        let (w, h) = (mask.width as u32, mask.height as u32);
        self.frame_for(w, h);
        self.write_uniforms(w, h, None, cfg);
        let f = self.frame.as_ref().expect("made above");
        let words32: Vec<u32> = mask.data.iter().map(|&m| m as u32).collect();
        let size = [w.div_ceil(16), h.div_ceil(16)];
        let morph = self.morphology.entry("main");
        let passes: Vec<Dispatch> = f.groups.morphology[..4].iter().map(|group| (morph, group, size)).collect();
        let words = self.stage_alone(
            &[(&f.lines, bytemuck::cast_slice(&words32))],
            &passes,
            &[(&f.closed, words32.len() as u64 * 4)],
        )?;
        Ok(Grid { width: mask.width, height: mask.height, data: words.into_iter().map(|m| m as u8).collect() })
    }
}
