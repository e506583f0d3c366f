//! The tests' seeded generator: the crate's own SplitMix64, so a seed means the same numbers
//! in the library, the tests and the benchmarks.

pub use bronchosim::rng::SplitMix64 as Rng;
