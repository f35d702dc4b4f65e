//! Structure from motion speed (issue 24): Frond's matcher (preemptive pair retrieval, blocked
//! SIMD descriptor matching, COLMAP's geometric verification, a second pass for photos left
//! unregistered) against COLMAP's own exhaustive matcher, the baseline, in the same run on the
//! same photos: 24 synthetic photos of a broadleaf at 640×480 (two rings, 30° apart within a
//! ring, so Frond's second pass runs too). Whole `run_sfm` runs without undistortion; feature
//! extraction and mapping are in both. Needs COLMAP (scripts/setup.sh); skipped without it.
//! `scripts/sfm_speed.py` measures the larger targets (36 photos at 800×600, the 60
//! Arabidopsis photos, the curve up to 200 photos) with accuracy.

use std::hint::black_box;
use std::process::Command;

use criterion::{Criterion, criterion_group, criterion_main};
use frond::sfm::{Matcher, SfmOptions, run_sfm};
use frond::synth::{Preset, SynthOptions, write_dataset};
use frond::util::progress::NoProgress;

fn sfm(c: &mut Criterion) {
    if Command::new("colmap").arg("-h").output().is_err() {
        eprintln!("colmap is not installed: sfm benchmark skipped");
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let dataset = dir.path().join("plant");
    let options = SynthOptions {
        preset: Preset::Broadleaf,
        seed: 3,
        views: 24,
        width: 640,
        height: 480,
        with_points: false,
        ..SynthOptions::default()
    };
    write_dataset(&options, &dataset, &NoProgress).expect("synthetic dataset");
    let photos = dataset.join("images");
    let mut group = c.benchmark_group("sfm_broadleaf_24x640x480");
    group.sample_size(10);
    for (name, matcher) in [
        ("frond", Matcher::Auto),
        ("colmap_exhaustive", Matcher::Exhaustive),
    ] {
        let sfm_options = SfmOptions {
            matcher,
            undistort: false,
            ..SfmOptions::default()
        };
        let mut run = 0;
        group.bench_function(name, |b| {
            b.iter(|| {
                run += 1;
                let out = dir.path().join(format!("{name}_{run}"));
                let report = run_sfm(&photos, &out, &sfm_options, &NoProgress).expect("sfm");
                assert_eq!(report.registered, 24, "{report:?}");
                black_box(report)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, sfm);
criterion_main!(benches);
