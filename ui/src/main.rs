//! `frond-ui`: opens the Frond GUI, optionally on a COLMAP folder given on the command line.
//! Parses the arguments (overlays, layout, benchmark) and starts eframe with `FrondApp`; draws
//! nothing itself and calls no library algorithm.

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
    /// Photo overlays to hide at start, comma-separated menu names in lower case with
    /// dashes (photo, points-by-segment, graph-edges, gradient-image, segment-boundaries,
    /// leaf-outlines, branches); the View menu turns them back on.
    #[arg(long, value_name = "OVERLAYS", value_delimiter = ',')]
    hide: Vec<String>,
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
    let names: Vec<String> = frond_ui::image_view::Overlays::default()
        .toggles()
        .iter()
        .map(|(menu, _)| overlay_flag(menu))
        .collect();
    let hidden = args.hide.clone();
    if let Some(unknown) = hidden.iter().find(|h| !names.contains(h)) {
        anyhow::bail!("--hide {unknown}: expected some of {}", names.join(", "));
    }
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
        // The UI is flat colours and the photo panel 8-bit already: dithering adds a noise
        // term to every fragment of every frame for no visible gain (a cost on llvmpipe).
        dithering: false,
        ..Default::default()
    };
    eframe::run_native(
        "Frond",
        options,
        Box::new(move |cc| {
            let mut app = frond_ui::FrondApp::new(args.path);
            app.layout = layout;
            for name in &hidden {
                if let Some((_, shown)) = app
                    .panel
                    .overlays
                    .toggles()
                    .into_iter()
                    .find(|(menu, _)| overlay_flag(menu) == *name)
                {
                    *shown = false;
                }
            }
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

/// An overlay's menu name as a flag value: "Points by segment" → "points-by-segment".
fn overlay_flag(menu: &str) -> String {
    menu.to_lowercase().replace(' ', "-")
}
