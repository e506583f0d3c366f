//! Texture atlas of a ~200k-triangle branching airway: build_atlas and rasterize_texels.

#[path = "../tests/common/airway_mesh.rs"]
mod airway_mesh;

use bronchosim::texture::atlas::{build_atlas, rasterize_texels, AtlasOptions};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

fn bench_atlas(c: &mut Criterion) {
    // 0.59 mm grid spacing gives about 200k triangles.
    let mesh = airway_mesh::airway_mesh(0.59);
    let opts = AtlasOptions::default();
    let atlas = build_atlas(&mesh, &opts).expect("atlas");
    eprintln!(
        "airway: {} triangles, {:.0} mm², {} charts, {}x{} texels, {:?}",
        mesh.triangles.len(),
        mesh.area(),
        atlas.chart_count,
        atlas.width,
        atlas.height,
        atlas.stats
    );
    let mut g = c.benchmark_group("atlas");
    g.sample_size(10);
    g.bench_function("build_atlas_200k", |b| {
        b.iter(|| build_atlas(black_box(&mesh), &opts).expect("atlas"))
    });
    g.bench_function("rasterize_texels_200k", |b| {
        b.iter(|| rasterize_texels(black_box(&atlas), &mesh).expect("texels"))
    });
    g.finish();
}

criterion_group!(benches, bench_atlas);
criterion_main!(benches);
