//! Several frames' vertex buffers cut into the same blocks of vertices, a block of every frame
//! handed to one task: work that reads per-vertex data (a blend's shapes, an interpolation's
//! matrix rows) reads each block's data once for all the frames instead of once a frame.

use glam::DVec3;

/// `out` (F × V, frame after frame) as one list per block of `block` vertices, each holding
/// that block of every frame in frame order: block `i` of frame `f` is vertices
/// `i * block..` of frame `f`. `v` must divide `out.len()` (F = out.len() / v; v > 0).
pub(crate) fn frame_blocks(out: &mut [DVec3], v: usize, block: usize) -> Vec<Vec<&mut [DVec3]>> {
    let block = block.max(1);
    let blocks = v.div_ceil(block);
    let mut by_block: Vec<Vec<&mut [DVec3]>> = (0..blocks).map(|_| Vec::new()).collect();
    for frame in out.chunks_mut(v.max(1)) {
        for (i, part) in frame.chunks_mut(block).enumerate() {
            by_block[i].push(part);
        }
    }
    by_block
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_block_holds_the_same_vertices_of_every_frame_in_order() {
        let (f, v, block) = (3, 10, 4);
        let mut out: Vec<DVec3> = (0..f * v).map(|i| DVec3::splat(i as f64)).collect();
        let blocks = frame_blocks(&mut out, v, block);
        assert_eq!(blocks.len(), 3);
        for (i, frames) in blocks.iter().enumerate() {
            assert_eq!(frames.len(), f);
            for (k, part) in frames.iter().enumerate() {
                let first = k * v + i * block;
                let len = block.min(v - i * block);
                let want: Vec<DVec3> = (first..first + len)
                    .map(|j| DVec3::splat(j as f64))
                    .collect();
                assert_eq!(part.to_vec(), want);
            }
        }
    }
}
