//! Splitting a batch into row tiles spread over the cores, and the per-thread
//! buffers a tile works in.

use std::cell::RefCell;
use std::thread::LocalKey;

use rayon::prelude::*;

/// Most rows in one tile: a 256-row tile's hidden activations (2 × 256 KiB)
/// stay in L2 next to one layer's weights.
pub const MAX_TILE_ROWS: usize = 256;

/// Rows per tile for `batch` rows: every core gets work, no tile exceeds
/// [`MAX_TILE_ROWS`].
pub fn tile_rows(batch: usize) -> usize {
    batch
        .div_ceil(rayon::current_num_threads())
        .clamp(1, MAX_TILE_ROWS)
}

/// Runs `work` on every tile, in parallel when there are several.
pub fn run_tiles<T: Send>(mut tiles: Vec<T>, work: impl Fn(T) + Sync + Send) {
    if tiles.len() == 1 {
        work(tiles.remove(0));
    } else {
        tiles.into_par_iter().for_each(work);
    }
}

/// `values` cut into consecutive tiles of `rows` rows, each `width` wide.
pub fn row_chunks(values: &mut [f32], rows: usize, width: usize) -> std::slice::ChunksMut<'_, f32> {
    values.chunks_mut((rows * width).max(1))
}

/// Runs `f` with this thread's buffers from `key`. They are taken out for the
/// call, not borrowed: a thread waiting inside `f` on other rayon work may run
/// another step that wants them (it then starts with fresh buffers).
pub fn with_buffers<T: Default, R>(
    key: &'static LocalKey<RefCell<T>>,
    f: impl FnOnce(&mut T) -> R,
) -> R {
    let mut buffers = key.take();
    let result = f(&mut buffers);
    key.set(buffers);
    result
}
