//! Parallel sums whose value does not depend on the threads.
//!
//! rayon's `reduce` and `sum` combine partial results in a tree whose shape follows the work
//! stealing, so a float sum can differ in its last bits from one run to the next. A build
//! should give the same model twice, so sums that reach an output are taken over fixed
//! blocks, in parallel, and the blocks' results are added in order.

use rayon::prelude::*;
use std::ops::Range;

/// `block(range)` over the consecutive ranges of `block_len` indices covering `0..n`, computed
/// in parallel, then combined with `add` from `zero` in block order.
pub fn ordered_block_sum<T, B, A>(n: usize, block_len: usize, zero: T, block: B, add: A) -> T
where
    T: Send,
    B: Fn(Range<usize>) -> T + Sync,
    A: Fn(T, T) -> T,
{
    let block_len = block_len.max(1);
    let parts: Vec<T> = (0..n.div_ceil(block_len))
        .into_par_iter()
        .map(|b| block(b * block_len..((b + 1) * block_len).min(n)))
        .collect();
    parts.into_iter().fold(zero, add)
}

/// Per-channel sums and a weight sum, the partial result of a weighted RMS over samples.
pub type ChannelSums = ([f64; 3], f64);

/// [`ordered_block_sum`]'s `add` for [`ChannelSums`].
pub fn add_channel_sums((a, wa): ChannelSums, (b, wb): ChannelSums) -> ChannelSums {
    ([a[0] + b[0], a[1] + b[1], a[2] + b[2]], wa + wb)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Terms of very different sizes, so the order of the additions shows in the last bits:
    /// the parallel sum is the same every time and equals the sequential sum of the blocks.
    #[test]
    fn same_bits_every_time_and_equal_to_the_blocks_in_order() {
        let x: Vec<f64> = (0..100_003)
            .map(|i| (i as f64 * 0.7548776662466927).fract() * 10f64.powi(i % 13 - 6))
            .collect();
        let sum = |r: Range<usize>| x[r].iter().sum::<f64>();
        let expected = (0..x.len().div_ceil(1000))
            .map(|b| sum(b * 1000..((b + 1) * 1000).min(x.len())))
            .fold(0.0, |a, b| a + b);
        for _ in 0..20 {
            let got = ordered_block_sum(x.len(), 1000, 0.0, sum, |a, b| a + b);
            assert_eq!(got.to_bits(), expected.to_bits());
        }
        assert_eq!(ordered_block_sum(0, 1000, 1.5, sum, |a, b| a + b), 1.5);
    }
}
