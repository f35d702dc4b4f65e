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
    /// COLMAP project folder, dense/0 workspace or model folder to open.
    path: Option<PathBuf>,
}

fn main() -> Result<()> {
    let args = Args::parse();
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
        Box::new(move |_cc| Ok(Box::new(frond_ui::FrondApp::new(args.path)))),
    )
    .map_err(|e| anyhow::anyhow!("could not start the GUI: {e}"))
}
