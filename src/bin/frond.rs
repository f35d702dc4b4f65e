//! `frond`: the command-line interface. Thin: parses arguments, calls the library, reports.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use frond::scene::{ModelFormat, Scene, SceneSource, stats, write_model};

#[derive(Parser)]
#[command(
    name = "frond",
    version,
    about = "Image-based plant modeling from COLMAP reconstructions"
)]
struct Cli {
    /// More log output (-v info, -vv debug); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Summarise a COLMAP reconstruction: cameras, images, points, reprojection error, bounds.
    Info {
        #[command(flatten)]
        scene: SceneArgs,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Convert a COLMAP model between text and binary.
    Convert {
        /// A model folder or any project layout `info` accepts.
        input: PathBuf,
        /// Output model folder (created if needed).
        output: PathBuf,
        #[arg(long, value_enum)]
        format: FormatArg,
    },
}

/// Where the scene is: a folder in any supported layout, or an explicit model (+ images).
#[derive(Args)]
struct SceneArgs {
    /// COLMAP project folder (images/ + sparse/0), dense/0 workspace, or model folder.
    path: Option<PathBuf>,
    /// Explicit model folder (cameras, images, points3D as .bin or .txt).
    #[arg(long, conflicts_with = "path")]
    model: Option<PathBuf>,
    /// Explicit images folder (with --model, or to override the one found).
    #[arg(long)]
    images: Option<PathBuf>,
}

#[derive(Clone, Copy, ValueEnum)]
enum FormatArg {
    Txt,
    Bin,
}

impl From<FormatArg> for ModelFormat {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Txt => ModelFormat::Text,
            FormatArg::Bin => ModelFormat::Binary,
        }
    }
}

impl SceneArgs {
    fn source(&self) -> Result<SceneSource> {
        let mut source = match (&self.path, &self.model) {
            (Some(path), None) => SceneSource::locate(path)
                .with_context(|| format!("finding a COLMAP model in {}", path.display()))?,
            (None, Some(model)) => SceneSource::explicit(model, self.images.as_deref())
                .with_context(|| format!("opening model {}", model.display()))?,
            _ => bail!("give a scene folder or --model"),
        };
        if let Some(images) = &self.images {
            if !images.is_dir() {
                bail!("images folder {} does not exist", images.display());
            }
            source.images_dir = Some(images.clone());
        }
        Ok(source)
    }
}

fn spinner(message: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(message.to_owned());
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

fn load_scene(source: SceneSource) -> Result<Scene> {
    let bar = spinner(&format!("reading {}", source.model_dir.display()));
    let model_dir = source.model_dir.clone();
    let scene = Scene::from_source(source)
        .with_context(|| format!("reading COLMAP model {}", model_dir.display()));
    bar.finish_and_clear();
    scene
}

fn info(scene_args: &SceneArgs, json: bool) -> Result<()> {
    let scene = load_scene(scene_args.source()?)?;
    let bar = spinner("checking images and reprojection errors");
    let summary = stats::summarize(&scene);
    bar.finish_and_clear();
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print!("{}", summary.to_text());
    }
    Ok(())
}

fn convert(input: &Path, output: &Path, format: ModelFormat) -> Result<()> {
    let source = SceneSource::locate(input)
        .with_context(|| format!("finding a COLMAP model in {}", input.display()))?;
    let scene = load_scene(source)?;
    write_model(output, &scene.reconstruction, format)
        .with_context(|| format!("writing {format} model to {}", output.display()))?;
    eprintln!(
        "wrote {} model ({} cameras, {} images, {} points) to {}",
        format,
        scene.reconstruction.cameras().len(),
        scene.reconstruction.images().len(),
        scene.reconstruction.points().len(),
        output.display()
    );
    Ok(())
}

fn init_logging(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    init_logging(cli.verbose);
    match &cli.command {
        Command::Info { scene, json } => info(scene, *json),
        Command::Convert {
            input,
            output,
            format,
        } => convert(input, output, (*format).into()),
    }
}
