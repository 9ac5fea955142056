//! The batched RANSAC's scoring: every region's hypotheses in one dispatch.

use super::*;

impl Gpu {
    /// Inlier counts of every (region, hypothesis), row-major by region: one dispatch
    /// for the whole frame, the same numbers as `cpu::ransac::score_hypotheses`.
    pub fn score_hypotheses(
        &mut self,
        batch: &PointBatch,
        hypotheses: u32,
        inlier_distance: f32,
    ) -> Result<Vec<u32>, GpuError> {
        let regions = batch.ranges.len() as u32;
        let total = regions * hypotheses;
        if total == 0 {
            return Ok(Vec::new());
        }
        // The scoring subsets and the planes, not every point: a few hundred kB where the
        // regions' points are megabytes.
        let scoring = ScoringBatch::new(batch, hypotheses);
        let points = scoring.coords.len() as u64 / 3;
        let fits = |b: &RansacBuffers| b.points >= points && b.regions >= regions as u64 && b.hypotheses >= hypotheses;
        if !self.ransac_buffers.as_ref().is_some_and(fits) {
            let (points, regions) =
                (points.next_power_of_two().max(4096), (regions as u64).next_power_of_two().max(64));
            let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
            let params = self.uniform(bytemuck::bytes_of(&<RansacParams as bytemuck::Zeroable>::zeroed()));
            let coords = self.buffer("scoring points", points * 12, storage);
            let ranges = self.buffer("ranges", regions * 8, storage);
            let planes = self.buffer("planes", regions * hypotheses as u64 * 16, storage);
            let score_bytes = regions * hypotheses as u64 * 4;
            let scores = self.buffer("scores", score_bytes, IMAGE);
            let staging =
                self.buffer("scores read", score_bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
            let group = self.bind(&self.ransac, &[&params, &coords, &ranges, &planes, &scores]);
            self.ransac_buffers = Some(RansacBuffers {
                points,
                regions,
                hypotheses,
                params,
                coords,
                ranges,
                planes,
                scores,
                staging,
                group,
            });
        }
        let b = self.ransac_buffers.as_ref().expect("made above");
        let params = RansacParams { hypotheses, regions, inlier_distance, points: points as u32 };
        self.queue.write_buffer(&b.params, 0, bytemuck::bytes_of(&params));
        if points > 0 {
            self.queue.write_buffer(&b.coords, 0, bytemuck::cast_slice(&scoring.coords));
        }
        self.queue.write_buffer(&b.ranges, 0, bytemuck::cast_slice(&scoring.ranges));
        self.queue.write_buffer(&b.planes, 0, bytemuck::cast_slice(&scoring.planes));
        let bytes = total as u64 * 4;
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        // At most 65535 workgroups per dimension: wrap into y.
        Self::pass(
            &mut encoder,
            None,
            0,
            &[(self.ransac.entry("main"), &b.group, [total.min(65535), total.div_ceil(65535)])],
        );
        encoder.copy_buffer_to_buffer(&b.scores, 0, &b.staging, 0, bytes);
        self.submit(encoder, scope)?;
        self.map(&b.staging, bytes, |data| bytemuck::cast_slice(data).to_vec())
    }
}
