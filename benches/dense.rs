//! Dense stereo speed (issue target: densify a synthetic broadleaf in ≤ 3 minutes on this
//! 2-core machine). A 36-view 800×600 broadleaf with sparse-like points (true poses); the full
//! `densify` beside its two halves measured in the same run: the depth maps alone
//! (rectification + semi-global matching, the baseline every pairwise-stereo method pays) and
//! the fusion alone on those maps, and the full `densify` with the short-bar option, with
//! two stereo partners per view and without the fill partner (the default fuses one partner's
//! maps, then both partners' maps for the gap fills). The halo checks (the free-space check and
//! the backdrop carving) are measured by the full run without them, and by the same plant
//! photographed against the studio's plain cloth, where the carving has a backdrop to carve
//! against (on the patterned default it learns that the backdrop is not plain and stops).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::mvs::{DensifyOptions, densify, depth_maps, fusion};
use frond::scene::Scene;
use frond::synth::{Backdrop, Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

fn dense(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("temp dir");
    let root = dir.path().join("plant");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 30,
        target_points: 5_000,
        ..SynthOptions::default()
    };
    write_dataset(&options, &root, &NoProgress).expect("synthetic dataset");
    let scene = Scene::open(&root).expect("scene");
    let densify_options = DensifyOptions::default();
    let studio_root = dir.path().join("studio");
    let studio_options = SynthOptions {
        backdrop: Backdrop::Studio,
        ..options.clone()
    };
    write_dataset(&studio_options, &studio_root, &NoProgress).expect("studio dataset");
    let studio = Scene::open(&studio_root).expect("studio scene");
    let (maps, report) = depth_maps(&scene, &densify_options, &NoProgress).expect("depth maps");

    let mut group = c.benchmark_group("densify_broadleaf_36x800x600");
    group.sample_size(10);
    group.bench_function("full", |b| {
        b.iter(|| black_box(densify(&scene, &densify_options, &NoProgress).expect("densify")))
    });
    // The short-bar option (`--thin-short-bars 4`) against the default in the same run.
    let mut short_bars = densify_options;
    short_bars.thin.min_short_curve_pixels = 4;
    group.bench_function("full_short_bars_4", |b| {
        b.iter(|| black_box(densify(&scene, &short_bars, &NoProgress).expect("densify")))
    });
    // Two stereo partners per view (`--partners 2`: leaves sampled more completely, see the
    // README's trait accuracy) against the default in the same run.
    let mut two_partners = densify_options;
    two_partners.pairs.partners_per_view = 2;
    two_partners.pairs.fill_partners_per_view = 0;
    group.bench_function("full_partners_2", |b| {
        b.iter(|| black_box(densify(&scene, &two_partners, &NoProgress).expect("densify")))
    });
    // Without the fill partner (`--fill-partners 0`): one depth map per view, one fusion.
    let mut no_fill = densify_options;
    no_fill.pairs.fill_partners_per_view = 0;
    group.bench_function("full_no_fill", |b| {
        b.iter(|| black_box(densify(&scene, &no_fill, &NoProgress).expect("densify")))
    });
    // Neither halo check (`--free-space-maps 0 --backdrop-views 0`): what the two cost.
    let mut no_halo_checks = densify_options;
    no_halo_checks.free_space.min_maps = 0;
    no_halo_checks.backdrop.min_views = 0;
    group.bench_function("full_no_halo_checks", |b| {
        b.iter(|| black_box(densify(&scene, &no_halo_checks, &NoProgress).expect("densify")))
    });
    // The same plant before the studio's plain cloth: the backdrop carving runs.
    group.bench_function("studio_full", |b| {
        b.iter(|| black_box(densify(&studio, &densify_options, &NoProgress).expect("densify")))
    });
    group.bench_function("studio_no_halo_checks", |b| {
        b.iter(|| black_box(densify(&studio, &no_halo_checks, &NoProgress).expect("densify")))
    });
    // The depth maps of both partners (the default's) and their fusion in one.
    group.bench_function("depth_maps_only", |b| {
        b.iter(|| black_box(depth_maps(&scene, &densify_options, &NoProgress).expect("maps")))
    });
    group.bench_function("fusion_only", |b| {
        b.iter(|| {
            black_box(fusion::fuse(
                &maps,
                &densify_options.fusion,
                report.region_of_interest.as_ref(),
                &NoProgress,
            ))
        })
    });
    group.finish();
}

criterion_group!(benches, dense);
criterion_main!(benches);
