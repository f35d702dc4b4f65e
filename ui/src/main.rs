//! `frond-ui`: opens the Frond GUI, optionally on a COLMAP folder given on the command line.

use std::path::PathBuf;

use anyhow::Result;
use clap::Parser;

#[derive(Parser)]
#[command(
    name = "frond-ui",
    version,
    about = "Frond's interactive plant modeling GUI"
)]
struct Args {
    /// COLMAP project folder, dense/0 workspace, model folder or .frond project to open.
    path: Option<PathBuf>,
    /// Fit the leaves once the scene is open.
    #[arg(long)]
    fit_leaves: bool,
    /// Benchmark: once open (and fitted with --fit-leaves), orbit the 3D view for this many
    /// frames, print the frame times as JSON and quit.
    #[arg(long, value_name = "FRAMES")]
    benchmark_frames: Option<usize>,
    /// What the central area shows: photo, 3d or both.
    #[arg(long, value_name = "LAYOUT", default_value = "both")]
    layout: String,
    /// Where the benchmark's JSON goes (also printed).
    #[arg(long, value_name = "FILE", requires = "benchmark_frames")]
    benchmark_out: Option<PathBuf>,
}

fn main() -> Result<()> {
    let args = Args::parse();
    let layout = match args.layout.as_str() {
        "photo" => frond_ui::CentralLayout::Photo,
        "3d" => frond_ui::CentralLayout::ThreeD,
        "both" => frond_ui::CentralLayout::Both,
        other => anyhow::bail!("--layout {other}: expected photo, 3d or both"),
    };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .init();
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_inner_size([1280.0, 800.0])
            .with_title("Frond"),
        ..Default::default()
    };
    eframe::run_native(
        "Frond",
        options,
        Box::new(move |cc| {
            let mut app = frond_ui::FrondApp::new(args.path);
            app.layout = layout;
            if let Some(frames) = args.benchmark_frames {
                app.benchmark = Some(frond_ui::Benchmark::new(
                    frames,
                    args.fit_leaves,
                    args.benchmark_out,
                ));
            } else if args.fit_leaves {
                app.fit_leaves_when_open = true;
            }
            if let Some(render_state) = cc.wgpu_render_state.as_ref() {
                app.install_gpu(render_state);
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| anyhow::anyhow!("could not start the GUI: {e}"))
}
