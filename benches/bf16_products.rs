//! Criterion benchmark of the host kernels' matrix products on one thread: f32 by the `gemm`
//! crate against bf16 (f32 sums) on every bf16 unit the processor has, on the shapes of the
//! default model's products (a tile of 128 output pixels of im2col layers, the Winograd bands'
//! products over 384 tiles). The throughput is in FLOP (two per multiply-add).
#![allow(missing_docs)] // criterion_group! generates undocumented items.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use dgstereo_kernels::testing::{Bf16Product, bf16_units, f32_product};

fn values(len: usize, seed: usize) -> Vec<f32> {
    (0..len).map(|i| ((i * 7919 + seed * 104_729) % 2001) as f32 / 1000.0 - 1.0).collect()
}

fn products(c: &mut Criterion) {
    let shapes: [(&str, [usize; 3]); 4] = [
        ("im2col 3x3 64->64, 128 px", [64, 128, 576]),
        ("im2col 3x3 128->128, 128 px", [128, 128, 1152]),
        ("winograd GRU 384->256, 384 tiles", [256, 384, 384]),
        ("winograd 128->128, 384 tiles", [128, 384, 128]),
    ];
    let units = bf16_units();
    if units.is_empty() {
        eprintln!("no bf16 unit on this processor: only the f32 products run");
    }
    let mut group = c.benchmark_group("products");
    group.sample_size(20);
    for (name, [rows, cols, depth]) in shapes {
        let (lhs, rhs) = (values(rows * depth, 1), values(depth * cols, 2));
        group.throughput(Throughput::Elements(2 * (rows * cols * depth) as u64));
        let mut dst = vec![0.0f32; rows * cols];
        group.bench_function(format!("{name} f32"), |b| {
            b.iter(|| {
                f32_product(&mut dst, &lhs, &rhs, [rows, cols, depth]);
                black_box(dst[0])
            })
        });
        for &unit in &units {
            let mut product = Bf16Product::new(unit, &lhs, [rows, cols, depth]).expect("an available unit");
            group.bench_function(format!("{name} bf16 {unit}"), |b| b.iter(|| black_box(product.run(&rhs)[0])));
        }
    }
    group.finish();
}

criterion_group!(benches, products);
criterion_main!(benches);
